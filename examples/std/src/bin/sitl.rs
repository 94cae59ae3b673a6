//! The simulated aircraft (SITL) with a live ground monitor: the project's main example.
//!
//! The aircraft runs the real stack on the Embassy std executor: the example application
//! (`pprz-example-app`: simulated rotorcraft, periodic telemetry, datalink services)
//! sends through the downlink over a simulated 57600-baud radio link (`pprz-devices`
//! `SimLink`, with hardware flow control so the queue sheds by priority); the ground end
//! of the radio is bridged to UDP like Paparazzi's link agent (telemetry to port 4242,
//! uplink from port 4243), so Paparazzi ground tools or `pprz-monitor` can listen. With
//! the monitor view on (the default), this process also is the ground: it decodes the
//! UDP telemetry live, PINGs the aircraft every second and changes a SETTING, and at
//! the end prints, per priority level, what was sent and what was shed.
//!
//! Time: the aircraft runs on embassy-time's mock clock, advanced by a pacer thread to
//! follow wall-clock time (`--speed` runs it faster), so the same binary is also
//! reproducible in tests.

use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration as StdDuration, Instant as StdInstant};

use clap::Parser;
use embassy_executor::Executor;
use embassy_time::{Duration, MockDriver};
use embedded_io_async::{Read, Write};
use pprz_devices::host::{HostConfig, HostDevice};
use pprz_devices::sim::{Overflow, SimConfig, SimEnd, SimLink, SimRx, SimTx};
use pprz_example_app::{AC_ID, Config, M};
use pprz_ground::cli;
use pprz_ground::monitor::Monitor;
use pprz_ground::set::RuntimeSet;
use pprz_ground::uplink;
use pprz_telemetry::pprz_messages::priority;
use pprz_telemetry::pprz_transports::{AnyTransport, PprzV2};
use pprz_telemetry::{Device, DeviceConfig, DeviceStats, Downlink, FrameArena, Port, run_writer};
use static_cell::StaticCell;

/// Simulate an aircraft on a 57600-baud radio and watch it with a live ground monitor.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// Stop after this many (simulated) seconds, more than 0 and at most a year; Ctrl-C
    /// stops too.
    #[arg(long, default_value_t = 20.0, value_parser = cli::parse_duration)]
    duration: f64,
    /// Flood the radio with low-priority payload at 10x its capacity.
    #[arg(long)]
    overload: bool,
    /// Simulated seconds per wall-clock second (0.01 to 100).
    #[arg(long, default_value_t = 1.0, value_parser = parse_speed)]
    speed: f64,
    /// Radio baud rate (8N1), 300 to 4000000.
    #[arg(long, default_value_t = 57_600, value_parser = parse_radio_baud)]
    baud: u32,
    /// PINGs the ground sends per (simulated) second, 0.1 to 10000: above the aircraft's
    /// reply limit (20/s) the extra PONGs are refused and counted, and telemetry flows on.
    #[arg(long, default_value_t = 1.0, value_parser = parse_ping_rate)]
    ping_rate: f64,
    /// Where the ground listens for telemetry (Paparazzi's link uses port 4242).
    #[arg(long, default_value = "127.0.0.1:4242")]
    ground: SocketAddr,
    /// Where the aircraft's radio bridge listens for uplink frames (port 4243).
    #[arg(long, default_value = "127.0.0.1:4243")]
    uplink: SocketAddr,
    /// No monitor: only the aircraft, for Paparazzi's ground tools or `pprz-monitor`.
    #[arg(long)]
    headless: bool,
    /// One line per received message instead of the live table.
    #[arg(long)]
    lines: bool,
    /// The messages.xml the monitor decodes with.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../../default/messages.xml"))]
    messages: PathBuf,
}

/// A finite number within `min..=max`, for the options below.
fn number_in(s: &str, min: f64, max: f64) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if !(min..=max).contains(&v) {
        // NaN is in no range.
        return Err(format!("`{s}` is out of range: {min} to {max}"));
    }
    Ok(v)
}

/// `--speed`: faster than 100x, the pacer's time steps outrun the simulated radio and the
/// executor (nothing would be sent); 0 would never end.
fn parse_speed(s: &str) -> Result<f64, String> {
    number_in(s, 0.01, 100.0)
}

/// `--ping-rate`: at most 10 kHz (a flood), at least one PING every 10 s.
fn parse_ping_rate(s: &str) -> Result<f64, String> {
    number_in(s, 0.1, 10_000.0)
}

/// `--baud`: the simulated radio carries `baud / 10` bytes per second.
fn parse_radio_baud(s: &str) -> Result<u32, String> {
    let baud = cli::parse_baud(s)?;
    if !(300..=4_000_000).contains(&baud) {
        return Err(format!("{baud} is out of range: 300 to 4000000"));
    }
    Ok(baud)
}

/// Radio buffer: bytes in flight plus received, per direction.
const RADIO_RING: usize = 4096;

type Dl = Downlink<'static, M, 1, 32>;

static ARENA: FrameArena<M, 8192> = FrameArena::new();
static DOWNLINK: Dl = Downlink::new(
    &ARENA,
    AC_ID,
    [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()))],
);
static RADIO: StaticCell<SimLink<M, RADIO_RING>> = StaticCell::new();
static EXECUTOR: StaticCell<Executor> = StaticCell::new();

#[embassy_executor::task]
async fn radio_writer(mut port: Port<'static>, tx: SimTx<'static, M, RADIO_RING>) {
    run_writer(&mut port, tx).await
}

#[embassy_executor::task]
async fn aircraft(radio: Device<'static>, rx: SimRx<'static, M, RADIO_RING>, config: Config) {
    let Err(e) = pprz_example_app::run_aircraft(radio, rx, config).await;
    panic!("the aircraft application cannot start: {e}");
}

/// The ground end of the radio, bridged to UDP both ways.
#[embassy_executor::task]
async fn ground_bridge(ground: SimEnd<'static, M, RADIO_RING>, udp: HostDevice) {
    let (mut radio_rx, mut radio_tx) = ground.split();
    let (mut udp_rx, mut udp_tx) = udp.split();
    let down = async {
        let mut buf = [0u8; 256];
        loop {
            if let Ok(n) = radio_rx.read(&mut buf).await
                && n > 0
            {
                let _ = udp_tx.write_all(&buf[..n]).await;
            }
        }
    };
    let up = async {
        let mut buf = [0u8; 256];
        loop {
            match udp_rx.read(&mut buf).await {
                Ok(n) if n > 0 => {
                    let _ = radio_tx.write_all(&buf[..n]).await;
                }
                _ => embassy_time::Timer::after(Duration::from_millis(10)).await,
            }
        }
    };
    embassy_futures::join::join(down, up).await;
}

/// Advances the mock clock to follow wall-clock time times `speed`.
fn pace(speed: f64) {
    std::thread::spawn(move || {
        let start = StdInstant::now();
        let mut simulated_us: u64 = 0;
        loop {
            std::thread::sleep(StdDuration::from_micros(500));
            let target = (start.elapsed().as_secs_f64() * speed * 1e6) as u64;
            if target > simulated_us {
                MockDriver::get().advance(Duration::from_micros(target - simulated_us));
                simulated_us = target;
            }
        }
    });
}

fn main() -> ExitCode {
    let args = Args::parse();
    let byte_rate = args.baud / 10;
    let config = Config {
        flood_bytes_per_s: if args.overload { byte_rate * 10 } else { 0 },
    };

    // The ground: listen for telemetry before the aircraft starts.
    let ground_socket = if args.headless {
        None
    } else {
        match UdpSocket::bind(args.ground) {
            Ok(s) => Some(s),
            Err(e) => {
                eprintln!(
                    "cannot listen on {} ({e}); is another ground station running? Use --ground/--uplink or --headless",
                    args.ground
                );
                return ExitCode::FAILURE;
            }
        }
    };
    let set = if args.headless {
        None
    } else {
        match RuntimeSet::load(&args.messages) {
            Ok(set) => Some(set),
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::FAILURE;
            }
        }
    };
    let udp = match HostDevice::udp_bind(args.uplink, args.ground, HostConfig::default()) {
        Ok(d) => d,
        Err(e) => {
            eprintln!(
                "cannot bind the aircraft's uplink port {}: {e}",
                args.uplink
            );
            return ExitCode::FAILURE;
        }
    };

    // The aircraft.
    let radio = RADIO.init(SimLink::new(
        SimConfig::new(byte_rate)
            .latency(Duration::from_millis(5))
            .buffer(64)
            .overflow(Overflow::Wait)
            .seed(7),
    ));
    let downlink: &'static Dl = &DOWNLINK;
    let [radio_port] = match downlink.ports() {
        Ok(ports) => ports,
        Err(e) => {
            eprintln!("sitl: {e}");
            std::process::exit(1);
        }
    };
    let radio_device = radio_port.device();
    let (air, ground) = radio.endpoints();
    let (air_rx, air_tx) = air.split();
    pace(args.speed);
    std::thread::spawn(move || {
        let executor = EXECUTOR.init(Executor::new());
        executor.run(|spawner| {
            spawner.spawn(radio_writer(radio_port, air_tx).unwrap());
            spawner.spawn(aircraft(radio_device, air_rx, config).unwrap());
            spawner.spawn(ground_bridge(ground, udp).unwrap());
        })
    });

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst));
    }
    let start = StdInstant::now();
    let sim_now = |speed: f64| start.elapsed().as_secs_f64() * speed;
    let wall_limit = args.duration / args.speed;

    let (Some(socket), Some(set)) = (ground_socket, set) else {
        println!(
            "aircraft {AC_ID} running: telemetry to UDP {}, uplink on UDP {} (Ctrl-C to stop)",
            args.ground, args.uplink
        );
        while !stop.load(Ordering::SeqCst) && start.elapsed().as_secs_f64() < wall_limit {
            std::thread::sleep(StdDuration::from_millis(100));
        }
        print_summary(downlink, None);
        return ExitCode::SUCCESS;
    };

    // The ground station in this process.
    let transport = PprzV2::new().into();
    let mut monitor = Monitor::new(set, transport);
    let _ = socket.set_read_timeout(Some(StdDuration::from_millis(20)));
    let mut buf = [0u8; 2048];
    let ping_period = 1.0 / args.ping_rate;
    let mut next_ping = 1.0;
    let mut setting_sent = false;
    let mut next_render = 0.0;
    while !stop.load(Ordering::SeqCst) && start.elapsed().as_secs_f64() < wall_limit {
        let t = sim_now(args.speed);
        // Every PING due by now (a flood sends many per pass; a slow pass skips none).
        while t >= next_ping {
            if let Ok(frame) = uplink::frame(&set, transport, AC_ID, "PING", &[])
                && socket.send_to(&frame, args.uplink).is_ok()
            {
                monitor.ping_sent(t);
            }
            next_ping += ping_period;
        }
        if !setting_sent && t >= 3.0 {
            // Setting 2 is the example's `gain`.
            let values = [("index", 2.0), ("ac_id", f64::from(AC_ID)), ("value", 2.5)];
            if let Ok(frame) = uplink::frame(&set, transport, AC_ID, "SETTING", &values)
                && socket.send_to(&frame, args.uplink).is_ok()
            {
                monitor.setting_value_sent(t, 2, 2.5);
            }
            setting_sent = true;
        }
        if let Ok((n, _)) = socket.recv_from(&mut buf) {
            monitor.feed(sim_now(args.speed), &buf[..n], |line, _| {
                if args.lines {
                    println!("{line}");
                }
            });
        }
        if !args.lines && t >= next_render {
            print!("\x1b[2J\x1b[H{}", monitor.render(t));
            next_render = t + 0.5 * args.speed.max(1.0);
        }
    }
    if !args.lines {
        print!("\x1b[2J\x1b[H{}", monitor.render(sim_now(args.speed)));
    }
    print_summary(downlink, Some(&monitor));
    ExitCode::SUCCESS
}

/// Per priority level: submitted to the radio, sent, shed, superseded (and received by
/// the ground).
fn print_summary(downlink: &Dl, monitor: Option<&Monitor>) {
    let mut received = [0u64; 3];
    if let Some(m) = monitor {
        for (priority, count) in m.per_priority() {
            received[priority::level(priority.0)] += count;
        }
    }
    let stats: DeviceStats = downlink.stats(0).unwrap_or_default();
    println!();
    println!("Priority shedding on the radio:");
    println!(
        "  {:<8} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "level", "submitted", "sent", "shed", "superseded", "received"
    );
    for (i, level) in stats.levels.iter().enumerate() {
        let received = if monitor.is_some() {
            received[i].to_string()
        } else {
            "-".to_owned()
        };
        println!(
            "  {:<8} {:>10} {:>10} {:>10} {:>10} {:>10}",
            priority::LEVEL_NAMES[i],
            level.submitted,
            level.sent,
            level.lost,
            level.superseded,
            received
        );
    }
    println!(
        "  (high: acknowledgements PONG/DL_VALUE; normal: flight status; low: payload and debug;\n   superseded: state samples replaced, while waiting, by a newer sample)"
    );
    println!(
        "  downlink: sent {}, dropped {} (queue full {}, arena full {}, replies over the rate limit {}), evicted {}, still queued {}",
        stats.sent,
        stats.dropped.total(),
        stats.dropped.queue_full,
        stats.dropped.arena_full,
        stats.dropped.rate_limited,
        stats.evicted.total(),
        stats.queued
    );
    if let Some(m) = monitor {
        let pings = m.pings();
        print!(
            "  PINGs: sent {}, answered {}, lost {}",
            pings.sent_count(),
            pings.answered(),
            pings.lost()
        );
        match m.last_rtt() {
            Some(rtt) => println!(", last round trip {:.1} ms", rtt * 1e3),
            None => println!(),
        }
    }
}
