//! `sitl`: a simulated aircraft and its ground station, over a simulated radio; the
//! project's main command.
//!
//! The aircraft runs the real stack on the Embassy std executor: the example application
//! (`pprz-example-app`: simulated rotorcraft, periodic telemetry, datalink services)
//! sends through the downlink over a simulated radio (`pprz-devices` `SimLink`: a UART
//! at `--baud`, a modem with a buffer of `--modem-buffer` bytes that stops the UART when
//! full (`--flow-control cts`) or drops bytes (`none`), and an air rate of
//! `--air-rate`), speaking PPRZ v2 or XBee 802.15.4 API with transmit statuses
//! (`--transport`); `--pacing on` makes the radio device pace its writes to the air
//! rate. The ground end of the radio is bridged to UDP like Paparazzi's link agent
//! (telemetry to port 4242, uplink from port 4243, PPRZ v2 on UDP whatever the radio
//! speaks), so Paparazzi ground tools or `pprz-monitor` can listen. With the monitor
//! view on (the default), this process also is the ground: it decodes the UDP
//! telemetry live, PINGs the aircraft every second (which keeps their link health Up)
//! and changes a SETTING, and at the end prints, per priority level, what was sent,
//! shed, received and how old it was, and each aircraft's link health and failsafe
//! (`--summary-json` writes the same figures as JSON).
//!
//! Time: the aircraft runs on embassy-time's mock clock, advanced by a pacer thread to
//! follow wall-clock time (`--speed` runs it faster), so the same binary is also
//! reproducible in tests. The ground in this process reads the same clock. Ages, round
//! trips and link health changes in the summary are measured on it ([`record`]).
//!
//! The modules follow a run: [`options`] (the command line) and [`radio`] (the radio
//! they describe, checked as a whole); [`aircraft`] (the application, its downlink and
//! tasks) with [`clock`] and [`fleet`] (`--fleet N`: more aircraft, each on a radio of
//! its own, or with `--relay` a second one behind the first); [`bridge`] (the radios'
//! ground ends on one UDP socket); [`ground`] (the ground station in this process,
//! with [`keys`] for `--secure`); [`link`] (the outages of `--outage`, each aircraft's
//! link health and its failsafe); [`persist`] (`--settings-flash`, the persistent
//! settings, and `--setting`); [`record`], [`report`] and [`summary`] (the figures);
//! [`merge`] (`--radios 2`, `--frame-loss`, `--zenoh`: the ground's radios merged by
//! the gateway).

mod aircraft;
mod bridge;
mod clock;
mod figures;
mod fleet;
mod ground;
mod keys;
mod link;
mod merge;
mod options;
mod persist;
mod radio;
mod record;
mod report;
mod summary;

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant as StdInstant;

use clap::CommandFactory;
use clap::error::ErrorKind;
use pprz_devices::host::{HostConfig, HostDevice};
use pprz_example_app::AC_ID;
use pprz_secure::Responder;

use crate::aircraft::Aircraft;
use crate::ground::Station;
use crate::keys::SitlKeys;
use crate::merge::Merge;
use crate::options::Args;
use crate::radio::RadioPlan;
use crate::report::JsonFile;

fn main() -> ExitCode {
    let args: Args = pprz_codegen::cli::parse();
    let plan = plan_or_exit(&args);
    match run(&args, &plan) {
        Ok(()) => ExitCode::SUCCESS,
        Err(failure) => {
            eprintln!("{}", failure.message);
            ExitCode::from(failure.code)
        }
    }
}

/// Why a run failed: the message for standard error and the exit code.
struct Failure {
    message: String,
    code: u8,
}

impl Failure {
    /// A failure with exit code 1.
    fn new(message: String) -> Self {
        Self { message, code: 1 }
    }

    /// A failure with exit code 1, its message prefixed with the command's name.
    fn sitl(message: impl std::fmt::Display) -> Self {
        Self::new(format!("sitl: {message}"))
    }
}

/// The radio the options describe, or exit with a usage error naming the options.
fn plan_or_exit(args: &Args) -> RadioPlan {
    match RadioPlan::new(args) {
        Ok(plan) => plan,
        Err(message) => Args::command()
            .error(ErrorKind::ArgumentConflict, message)
            .exit(),
    }
}

/// The run: what can fail is opened first, then the aircraft start, the ground runs
/// until the end, and the summary is printed.
fn run(args: &Args, plan: &RadioPlan) -> Result<(), Failure> {
    for warning in link::after_the_end(args)
        .into_iter()
        .chain(persist::after_the_end(args))
    {
        eprintln!("sitl: {warning}");
    }
    let json = JsonFile::create(args).map_err(Failure::sitl)?;
    let keys = load_keys(args)?;
    let store = persist::open(args).map_err(Failure::sitl)?;
    // The ground listens for telemetry before the aircraft starts.
    let station = if args.headless {
        None
    } else {
        Some(Station::open(args).map_err(Failure::new)?)
    };
    let mut udp = Vec::new();
    for (uplink, ground) in merge::uplink_addresses(args)
        .into_iter()
        .zip(merge::ground_addresses(args))
    {
        let device = HostDevice::udp_bind(uplink, ground, HostConfig::default()).map_err(|e| {
            Failure::new(format!(
                "cannot bind the aircraft's uplink port {uplink}: {e}"
            ))
        })?;
        udp.push(device);
    }
    let (responder, ground_keys) = match keys {
        Some(k) => (Some(Responder::new(AC_ID, k.aircraft)), k.ground),
        None => (None, None),
    };
    let aircraft = aircraft::start(args, plan, responder, store, udp).map_err(Failure::sitl)?;
    let stop = stop_on_ctrl_c();
    let start = StdInstant::now();
    let merge = match station {
        Some(station) => Some(run_ground(
            args,
            station,
            ground_keys,
            &aircraft,
            &stop,
            start,
        )?),
        None => {
            ground::wait_headless(args, &stop, start);
            None
        }
    };
    let now = start.elapsed().as_secs_f64() * args.speed;
    let summary = report::print(args, plan, &aircraft, merge.as_ref(), now);
    match json {
        Some(file) => file.write(&summary).map_err(Failure::sitl),
        None => Ok(()),
    }
}

/// The keys of `--secure`, if given (exit code 2 when they cannot be read).
fn load_keys(args: &Args) -> Result<Option<SitlKeys>, Failure> {
    let Some(path) = &args.secure else {
        return Ok(None);
    };
    keys::load(path, args.headless)
        .map(Some)
        .map_err(|e| Failure {
            message: format!("sitl: --secure {}: {e}", path.display()),
            code: 2,
        })
}

/// A flag that Ctrl-C sets.
fn stop_on_ctrl_c() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let _ = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst));
    stop
}

/// The ground station in this process, from `start` to the end of the run.
fn run_ground(
    args: &Args,
    station: Station,
    keys: Option<pprz_secure::GroundKeys>,
    aircraft: &Aircraft,
    stop: &AtomicBool,
    start: StdInstant,
) -> Result<Merge, Failure> {
    let ground = station.start(args, keys).map_err(Failure::sitl)?;
    let side = |ac: u8| figures::aircraft_levels(ac, aircraft);
    Ok(ground.run(&side, stop, start))
}
