//! `pprz-gateway`: serve a fleet on a Zenoh bus from several links at once, redundant
//! links merged, commands routed to the link each aircraft is heard on.
//!
//! Exit status: 0 after a complete run (all inputs ended, `--duration`, Ctrl-C), 1
//! when the bus or a link failed to open, 2 for invalid options.

use std::io::ErrorKind;
use std::net::UdpSocket;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use pprz_ground::bus::Bus;
use pprz_ground::device::Source;
use pprz_ground::device::Uplink;
use pprz_ground::escape;
use pprz_ground::gateway::options::GatewayArgs;
use pprz_ground::gateway::serve::Service;
use pprz_ground::gateway::{Gateway, GatewayLink};
use pprz_ground::input::{DATAGRAM_BUFFER, End, InputQueue, Pop};
use pprz_ground::monitor::Monitor;
use pprz_ground::set::RuntimeSet;
use pprz_ground::settings::SettingsTable;
use pprz_transports::PprzV2;

/// Requests from the bus handled per loop turn at most (the links' input comes
/// between).
const REQUESTS_PER_TURN: usize = 64;

/// How often the figures are published, in seconds.
const TICK: f64 = 1.0;

/// How long the loop sleeps when no input came: the latency it may add.
const IDLE_SLEEP: Duration = Duration::from_micros(200);

/// Datagrams read from one UDP link per loop turn at most.
const DATAGRAMS_PER_TURN: usize = 64;

/// A link's input as the loop reads it.
enum Input {
    /// A UDP socket read by the loop itself (non-blocking): no thread between the
    /// socket and the gateway, no hand-over per datagram.
    Udp(UdpSocket, Vec<u8>),
    /// A stream read by a thread of its own into a queue.
    Queue(InputQueue),
    /// The input ended.
    Ended,
}

impl Input {
    fn of(source: Source) -> Result<Self, String> {
        match source {
            Source::Udp(socket) => {
                socket
                    .set_nonblocking(true)
                    .map_err(|e| format!("UDP socket: {e}"))?;
                Ok(Self::Udp(socket, vec![0; DATAGRAM_BUFFER]))
            }
            stream => Ok(Self::Queue(stream.start())),
        }
    }

    /// Feeds what arrived on link `i` to the service; whether anything did.
    fn poll(&mut self, service: &mut Service, i: usize, now: f64, name: &str) -> bool {
        match self {
            Self::Udp(socket, buf) => {
                for n in 0..DATAGRAMS_PER_TURN {
                    match socket.recv_from(buf) {
                        Ok((len, _)) => service.feed(i, now, &buf[..len]),
                        Err(e) if e.kind() == ErrorKind::WouldBlock => return n > 0,
                        Err(e) if e.kind() == ErrorKind::Interrupted => {}
                        Err(e) => {
                            eprintln!("pprz-gateway: link {name}: {e}");
                            *self = Self::Ended;
                            return n > 0;
                        }
                    }
                }
                true
            }
            Self::Queue(q) => match q.pop(Duration::ZERO) {
                Pop::Data {
                    bytes,
                    dropped_before,
                } => {
                    service.input_gap(i, now, dropped_before);
                    service.feed(i, now, &bytes);
                    true
                }
                Pop::Idle => false,
                Pop::End(end) => {
                    if let End::Error(e) = end {
                        eprintln!("pprz-gateway: link {name}: {e}");
                    }
                    *self = Self::Ended;
                    false
                }
            },
            Self::Ended => false,
        }
    }
}

fn main() -> ExitCode {
    let args: GatewayArgs = pprz_codegen::cli::parse();
    let links = match args.links() {
        Ok(l) => l,
        Err(e) => {
            eprintln!("pprz-gateway: {e}");
            return ExitCode::from(2);
        }
    };
    // The diagnostics of the messages and settings files escape the text they quote
    // (their `Display`, see `pprz_codegen::escape`): printed as they are.
    let set = match RuntimeSet::load(&args.link.messages) {
        Ok(s) => s,
        Err(e) => {
            for d in e.diagnostics() {
                eprintln!("pprz-gateway: {d}");
            }
            eprintln!("pprz-gateway: give the messages.xml of the aircraft with --messages");
            return ExitCode::from(2);
        }
    };
    let table = if args.settings_files.is_empty() {
        None
    } else {
        match SettingsTable::load(&args.settings_files) {
            Ok(t) => Some(Arc::new(t)),
            Err(e) => {
                for d in e.diagnostics() {
                    eprintln!("pprz-gateway: {d}");
                }
                return ExitCode::from(2);
            }
        }
    };
    match run(&args, set, table, &links) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pprz-gateway: {}", escape::lines(&e));
            ExitCode::FAILURE
        }
    }
}

fn run(
    args: &GatewayArgs,
    set: RuntimeSet,
    table: Option<Arc<SettingsTable>>,
    specs: &[pprz_ground::device::LinkSpec],
) -> Result<(), String> {
    let mut inputs: Vec<Input> = Vec::new();
    let mut uplinks: Vec<Uplink> = Vec::new();
    let mut links = Vec::new();
    for spec in specs {
        let (source, uplink) = spec
            .endpoint
            .open()
            .map_err(|e| format!("link {}: {e}", spec.name))?;
        links.push(GatewayLink::new(
            &spec.name,
            set,
            spec.transport.any(),
            uplink.can_send(),
        ));
        inputs.push(Input::of(source)?);
        uplinks.push(uplink);
    }
    // Nobody reads the messages' text here: the bus carries their JSON.
    let fleet = Monitor::new(set, PprzV2::new().into())
        .without_text()
        .with_stale_after(args.stale_after)
        .map_err(|e| e.to_string())?;
    let fleet = match &table {
        Some(t) => fleet.with_settings(t.clone()),
        None => fleet,
    };
    let gateway = Gateway::new(*fleet.set(), links)
        .with_fleet_monitor(fleet)
        .with_window(
            args.dedup_window,
            pprz_ground::gateway::dedup::DEFAULT_CAPACITY,
        )
        .with_policy(args.uplink_policy.into());
    let bus_config = args.bus();
    let bus = Bus::open(&bus_config)?
        .serving()?
        .serving_schemas(*gateway.fleet().set())?;
    for endpoint in &bus_config.listen {
        eprintln!("zenoh: listening on {endpoint}");
    }
    let mut service =
        Service::new(&args.name, gateway, uplinks, bus).with_uplink_rate(args.uplink_rate);
    if let Some(t) = table {
        service = service.with_settings(t);
    }
    let stop = pprz_ground::cli::stop_on_ctrl_c();
    let start = Instant::now();
    let mut next_tick = 0.0;
    loop {
        let now = start.elapsed().as_secs_f64();
        let mut busy = false;
        for (i, input) in inputs.iter_mut().enumerate() {
            busy |= input.poll(&mut service, i, now, &specs[i].name);
        }
        service.serve_requests(now, REQUESTS_PER_TURN);
        if now >= next_tick {
            service.tick(now);
            next_tick = now + TICK;
        }
        let ended = inputs.iter().all(|i| matches!(i, Input::Ended));
        let timed_out = args.duration.is_some_and(|d| now >= d);
        if ended || timed_out || stop.load(Ordering::SeqCst) {
            service.tick(now);
            break;
        }
        if !busy {
            std::thread::sleep(IDLE_SLEEP);
        }
    }
    let summary = service.stats_json();
    eprintln!("pprz-gateway: {summary}");
    if let Some(path) = &args.summary_json {
        std::fs::write(path, format!("{summary:#}\n"))
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    }
    Ok(())
}
