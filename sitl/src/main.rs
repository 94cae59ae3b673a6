//! The simulated aircraft (SITL) with a live ground monitor: the project's main example.
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
//! telemetry live, PINGs the aircraft every second and changes a SETTING, and at the
//! end prints, per priority level, what was sent, shed, received and how old it was
//! (`--summary-json` writes the same figures as JSON).
//!
//! Time: the aircraft runs on embassy-time's mock clock, advanced by a pacer thread to
//! follow wall-clock time (`--speed` runs it faster), so the same binary is also
//! reproducible in tests. Ages and round trips in the summary are measured on that
//! clock ([`record`]).

mod record;
mod summary;

use std::fs::File;
use std::io::Write as _;
use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration as StdDuration, Instant as StdInstant};

use clap::error::ErrorKind;
use clap::{CommandFactory, Parser, ValueEnum};
use embassy_executor::Executor;
use embassy_sync::pipe::Pipe;
use embassy_time::{Duration, Instant, MockDriver, Ticker, Timer};
use embedded_io_async::{Read, Write};
use pprz_default::messages::MESSAGES;
use pprz_default::messages::datalink::Ping;
use pprz_default::messages::telemetry::Payload;
use pprz_devices::host::{HostConfig, HostDevice};
use pprz_devices::sim::{
    Direction, Overflow, SimConfig, SimEnd, SimLink, SimRx, SimTx, XBeeModem, XBeeVariant,
};
use pprz_example_app::{AC_ID, Config, M};
use pprz_ground::cli;
use pprz_ground::monitor::Monitor;
use pprz_ground::secure::{GroundSecure, key_file_from_path};
use pprz_ground::set::RuntimeSet;
use pprz_ground::uplink;
use pprz_ground::viewer::{LevelFigures, Viewer, unix_ns};
use pprz_messages::{Message, VarArray};
use pprz_secure::Responder;
use pprz_secure::link::SecureLink;
use pprz_secure::rand_core::{OsRng, TryRngCore};
use pprz_telemetry::delivery::MAX_IN_MODEM;
use pprz_telemetry::pprz_messages::priority;
use pprz_telemetry::pprz_transports::{
    AnyTransport, Decoder, Encoder, Framing, MAX_FRAME_LEN, PprzV2, XBee24,
};
use pprz_telemetry::{
    DeliveryWindow, Device, DeviceConfig, DeviceStats, Downlink, FrameArena, Pacing, Port, Routes,
    Sender, Targets, run_writer, run_writer_with,
};
use static_cell::StaticCell;

use crate::summary::{
    AircraftFigures, AircraftLevel, DeliveryFigures, DownlinkFigures, FleetFigures, Level, Levels,
    MessageFigures, ModemFigures, PingFigures, RouteFigures, RunConfig, SecureFigures, Summary,
};

/// Simulate an aircraft on a radio link and watch it with a live ground monitor.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// Stop after this many (simulated) seconds, more than 0 and at most a year; Ctrl-C
    /// stops too.
    #[arg(long, default_value_t = 20.0, value_parser = cli::parse_duration)]
    duration: f64,
    /// Flood the radio with low-priority payload at 10x its capacity (the slower of the
    /// UART and the air).
    #[arg(long)]
    overload: bool,
    /// Simulated seconds per wall-clock second (0.01 to 100).
    #[arg(long, default_value_t = 1.0, value_parser = parse_speed)]
    speed: f64,
    /// Baud rate (8N1) of the UART between the autopilot and its radio modem, 300 to
    /// 4000000: the UART carries `baud / 10` bytes per second.
    #[arg(long, default_value_t = 57_600, value_parser = parse_radio_baud)]
    baud: u32,
    /// The radio modem's buffer, in bytes (1 to 8192; XBee: at least one whole frame,
    /// 109 bytes) [default: 64, XBee: 202].
    #[arg(long, value_name = "BYTES", value_parser = parse_modem_buffer)]
    modem_buffer: Option<usize>,
    /// What the modem does when its buffer is full: `cts` stops the UART (hardware flow
    /// control), `none` drops the bytes that arrive.
    #[arg(long, value_enum, default_value_t = FlowControl::Cts)]
    flow_control: FlowControl,
    /// The modem's over-the-air throughput, bytes per second (10 to 1000000)
    /// [default: baud / 10; XBee 802.15.4: 31250].
    #[arg(long, value_name = "BYTES_PER_S", value_parser = parse_air_rate)]
    air_rate: Option<u32>,
    /// `on`: the radio device paces its writes to the air rate, keeping at most the
    /// pacing budget in the modem, so frames wait (and are shed) in the priority queue.
    #[arg(long, value_enum, default_value_t = OnOff::Off)]
    pacing: OnOff,
    /// The pacing budget, in bytes (1 to the modem buffer; needs `--pacing on`)
    /// [default: half the modem buffer, at most 192].
    #[arg(long, value_name = "BYTES", value_parser = parse_modem_buffer)]
    pacing_budget: Option<usize>,
    /// What the radio speaks: PPRZ v2 through a transparent modem, or XBee 802.15.4 API
    /// frames with transmit statuses.
    #[arg(long, value_enum, default_value_t = TransportArg::Pprz2)]
    transport: TransportArg,
    /// XBee: frames awaiting their transmit status at most, 1 to 8 (needs `--transport
    /// xbee`) [default: 1].
    #[arg(long, value_name = "K", value_parser = parse_in_modem)]
    in_modem: Option<u8>,
    /// Also write the end summary as JSON to this file (schema in the README).
    #[arg(long, value_name = "PATH")]
    summary_json: Option<PathBuf>,
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
    /// Secure the radio with Paparazzi's secure PPRZ link, keys from this key file (see
    /// pprz-secure's keygen; `secure/keys/INSECURE-TEST-ONLY.keys` for a try): the
    /// aircraft sends nothing but its key exchange until a ground completes the
    /// handshake; the in-process ground uses the same file (with `--headless`, an
    /// external ground such as `pprz-monitor --secure` does the handshake over UDP).
    /// PPRZ v2 only.
    #[arg(long, value_name = "KEYFILE")]
    secure: Option<PathBuf>,
    /// Aircraft in the simulation, 1 or 2. With 2, aircraft 8 flies beside aircraft 7,
    /// out of the ground's reach: a second simulated radio (the same as the first) joins
    /// 7 and 8, and 7 relays between its two radios (PPRZ v2 only). The ground sees both
    /// aircraft on the same UDP port and PINGs both.
    #[arg(long, default_value_t = 1, value_parser = parse_fleet)]
    fleet: u8,
    /// Serve the ground's decoded telemetry to Foxglove or Lichtblick over the Foxglove
    /// WebSocket protocol at this address (e.g. `127.0.0.1:8765`; port 0: any free port,
    /// printed), with the aircraft's own per-level figures on `/ac/<id>/link`. Needs the
    /// in-process ground (not `--headless`).
    #[arg(long, value_name = "ADDR")]
    foxglove: Option<SocketAddr>,
    /// The messages.xml the monitor decodes with.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../default/messages.xml"))]
    messages: PathBuf,
}

/// `--flow-control`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum FlowControl {
    /// Hardware flow control: the modem stops the UART while its buffer is full.
    Cts,
    /// None: the modem drops the bytes that arrive while its buffer is full.
    None,
}

/// `--pacing`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum OnOff {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

/// `--transport`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum TransportArg {
    /// PPRZ v2 frames through a transparent modem.
    Pprz2,
    /// XBee 802.15.4 API frames (TX16/RX16) with transmit statuses.
    Xbee,
}

impl TransportArg {
    fn name(self) -> &'static str {
        match self {
            Self::Pprz2 => "pprz2",
            Self::Xbee => "xbee",
        }
    }

    fn any(self) -> AnyTransport {
        match self {
            Self::Pprz2 => PprzV2::new().into(),
            Self::Xbee => XBee24::new().into(),
        }
    }
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

/// A whole number within `min..=max`.
fn integer_in(s: &str, min: u64, max: u64) -> Result<u64, String> {
    let v: u64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a whole number"))?;
    if !(min..=max).contains(&v) {
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
fn parse_fleet(s: &str) -> Result<u8, String> {
    integer_in(s, 1, 2).map(|n| n as u8)
}

fn parse_ping_rate(s: &str) -> Result<f64, String> {
    number_in(s, 0.1, 10_000.0)
}

/// `--baud`: the simulated UART carries `baud / 10` bytes per second.
fn parse_radio_baud(s: &str) -> Result<u32, String> {
    let baud = cli::parse_baud(s)?;
    if !(300..=4_000_000).contains(&baud) {
        return Err(format!("{baud} is out of range: 300 to 4000000"));
    }
    Ok(baud)
}

/// Largest `--modem-buffer`: well inside the simulated link's receive ring
/// ([`RADIO_RING`]), which also holds the bytes on the air and those not yet read.
const MAX_MODEM_BUFFER: usize = 8192;

/// `--modem-buffer` and `--pacing-budget`: 1 to [`MAX_MODEM_BUFFER`] bytes.
fn parse_modem_buffer(s: &str) -> Result<usize, String> {
    integer_in(s, 1, MAX_MODEM_BUFFER as u64).map(|v| v as usize)
}

/// `--air-rate`: 10 B/s (below any real radio) to 1 MB/s (above any UART's rate).
fn parse_air_rate(s: &str) -> Result<u32, String> {
    integer_in(s, 10, 1_000_000).map(|v| v as u32)
}

/// `--in-modem`: 1 to the telemetry crate's [`MAX_IN_MODEM`].
fn parse_in_modem(s: &str) -> Result<u8, String> {
    integer_in(s, 1, MAX_IN_MODEM as u64).map(|v| v as u8)
}

/// Receive ring of each direction of the simulated radio: bytes in the modem, on the
/// air and received but not yet read.
const RADIO_RING: usize = 16_384;

/// The modem buffer without `--modem-buffer` for a transparent modem (what the SITL
/// always had).
const DEFAULT_MODEM_BUFFER: usize = 64;
/// The modem buffer without `--modem-buffer` for an XBee: the serial receive buffer of an
/// XBee Series 1.
const DEFAULT_XBEE_BUFFER: usize = 202;

/// The over-the-air rate of XBee 802.15.4 (250 kbit/s), the default with
/// `--transport xbee`.
const XBEE_AIR_RATE: u32 = 31_250;

/// Most bytes the derived pacing budget allows: one and a half of the largest frame the
/// example sends (its 129-byte PAYLOAD frames), so the air stays busy while an
/// acknowledgement waits at most about two such frame times.
const MAX_DERIVED_BUDGET: usize = 192;

/// Time after which the radio device stops waiting for a transmit status: far above the
/// 802.15.4 transmission, retries and acknowledgement waits of a frame (about 25 ms),
/// and above the pacer's clock steps at `--speed 100`.
const DELIVERY_TIMEOUT_MS: u32 = 500;

/// The PAYLOAD fields the flood sends over XBee 802.15.4 (the application's 120-byte
/// flood frames exceed its 96 field bytes).
const XBEE_FLOOD_FIELDS: usize = 90;

/// Aircraft 7's downlink: device 0 its radio to the ground, device 1 its radio to
/// aircraft 8 (`--fleet 2`; unused otherwise).
type Dl = Downlink<'static, M, 2, 32>;
/// Aircraft 8's downlink: its radio to aircraft 7.
type Dl8 = Downlink<'static, M, 1, 32>;
type Radio = SimLink<M, RADIO_RING>;

/// The id of the fleet's second aircraft (`--fleet 2`), reachable only through
/// aircraft 7 ([`AC_ID`]).
pub const SECOND_AC_ID: u8 = 8;

/// Aircraft 7's routes with `--fleet 2`: aircraft 8 through its second radio, the ground
/// (and any other) through the first, broadcast on both.
static FLEET_ROUTES: [(u8, Targets); 1] = [(SECOND_AC_ID, Targets::only(1))];

static ARENA: FrameArena<M, 8192> = FrameArena::new();
static ARENA_8: FrameArena<M, 8192> = FrameArena::new();
static DOWNLINK_8: StaticCell<Dl8> = StaticCell::new();
/// The radio between aircraft 7 and 8 (side A: 7, side B: 8).
static LINK_78: StaticCell<Radio> = StaticCell::new();
/// The downlink, built at start-up from the options (its device configuration is not
/// known at compile time).
static DOWNLINK: StaticCell<Dl> = StaticCell::new();
static RADIO: StaticCell<Radio> = StaticCell::new();
static EXECUTOR: StaticCell<Executor> = StaticCell::new();
/// `--secure`: the radio's secure link (its writer seals, the application's reader
/// opens, the application runs its handshake).
static SECURE: SecureLink<M> = SecureLink::aircraft(AC_ID);
/// XBee: the uplink messages, re-framed as PPRZ v2 for the application's reader.
static UPLINK_PIPE: Pipe<M, 1024> = Pipe::new();

/// A radio device's writer (sealing every frame with `secure`, if given).
#[embassy_executor::task(pool_size = 3)]
async fn radio_writer(
    mut port: Port<'static>,
    tx: SimTx<'static, M, RADIO_RING>,
    secure: Option<&'static SecureLink<M>>,
) {
    match secure {
        Some(layer) => run_writer_with(&mut port, tx, layer).await,
        None => run_writer(&mut port, tx).await,
    }
}

/// The application on a secure radio (PPRZ v2), with its handshake.
#[embassy_executor::task]
async fn secure_aircraft(
    radio: Device<'static>,
    rx: SimRx<'static, M, RADIO_RING>,
    config: Config,
    responder: Responder,
) {
    let rng = OsRng.unwrap_err();
    let Err(e) =
        pprz_example_app::run_secure_aircraft(radio, rx, config, &SECURE, responder, rng).await;
    panic!("the aircraft application cannot start: {e}");
}

/// Aircraft 7 relaying for aircraft 8 (`--fleet 2`): its radio to the ground and its
/// radio to 8, both read by one relaying datalink.
#[embassy_executor::task]
async fn relay_aircraft(
    radio: Device<'static>,
    rx: SimRx<'static, M, RADIO_RING>,
    link: Device<'static>,
    link_rx: SimRx<'static, M, RADIO_RING>,
    config: Config,
) {
    let Err(e) = pprz_example_app::run_relay_aircraft(
        radio,
        rx,
        link,
        link_rx,
        RELAY_PRIORITY,
        Some(&MESSAGES),
        config,
    )
    .await;
    panic!("the aircraft application cannot start: {e}");
}

/// Priority of the frames aircraft 7 forwards whose message it does not know.
const RELAY_PRIORITY: u8 = priority::LOW;

/// The application reading its uplink from the radio (PPRZ v2).
#[embassy_executor::task(pool_size = 2)]
async fn aircraft(radio: Device<'static>, rx: SimRx<'static, M, RADIO_RING>, config: Config) {
    let Err(e) = pprz_example_app::run_aircraft(radio, rx, config).await;
    panic!("the aircraft application cannot start: {e}");
}

/// The application reading its uplink from [`UPLINK_PIPE`] (XBee).
#[embassy_executor::task]
async fn aircraft_piped(radio: Device<'static>, config: Config) {
    let Err(e) = pprz_example_app::run_aircraft(radio, &UPLINK_PIPE, config).await;
    panic!("the aircraft application cannot start: {e}");
}

/// The aircraft's XBee API reader: transmit statuses go to the radio device's writer
/// (its delivery window), received frames go on to the application's reader as PPRZ v2
/// (the example application reads PPRZ v2).
#[embassy_executor::task]
async fn xbee_reader(mut rx: SimRx<'static, M, RADIO_RING>, radio: Device<'static>) {
    let mut decoder: Decoder<XBee24> = Decoder::new(XBee24::new());
    let v2 = PprzV2::new();
    let mut buf = [0u8; 64];
    let mut frame = [0u8; MAX_FRAME_LEN];
    loop {
        let Ok(n) = rx.read(&mut buf).await;
        let mut input = &buf[..n];
        loop {
            // `feed` returns `None` once the chunk is used up.
            let encoded = decoder
                .feed(&mut input)
                .map(|f| v2.encode(&f.tx_meta(), f.payload(), &mut frame));
            while let Some(status) = decoder.take_tx_status() {
                radio.tx_status(&status);
            }
            match encoded {
                Some(Ok(len)) => UPLINK_PIPE.write_all(&frame[..len]).await,
                Some(Err(_)) => {}
                None => break,
            }
        }
    }
}

/// The payload flood over XBee: PAYLOAD frames that fit 802.15.4, `bytes_per_s` API
/// bytes per second, recorded as the application's submissions are.
#[embassy_executor::task]
async fn xbee_flood(downlink: Sender<'static>, bytes_per_s: u32) {
    let fields = [0xA5u8; XBEE_FLOOD_FIELDS];
    let payload = Payload {
        values: VarArray::new(&fields),
    };
    let transport = TransportArg::Xbee.any();
    let frame_len = transport
        .frame_len(payload.encoded_len())
        .unwrap_or(MAX_FRAME_LEN);
    let period_us = (frame_len as u64 * 1_000_000 / u64::from(bytes_per_s.max(1))).max(100);
    let mut encoded = [0u8; MAX_FRAME_LEN];
    let len = payload.encode(&mut encoded).unwrap_or(0);
    let mut ticker = Ticker::every(Duration::from_micros(period_us));
    loop {
        ticker.next().await;
        record::submitted(
            Payload::CLASS_ID,
            Payload::ID,
            &encoded[..len],
            Instant::now(),
        );
        let _ = downlink.send(&payload);
    }
}

/// The ground end of the radio, bridged to UDP both ways: decodes what comes down (for
/// the record, and to re-frame XBee as PPRZ v2 for UDP) and what goes up (PINGs, and
/// XBee framing of the uplink).
#[embassy_executor::task]
async fn ground_bridge(
    ground: SimEnd<'static, M, RADIO_RING>,
    udp: HostDevice,
    xbee: bool,
    secure: bool,
) {
    let (mut radio_rx, mut radio_tx) = ground.split();
    let (mut udp_rx, mut udp_tx) = udp.split();
    let radio_transport = if xbee {
        TransportArg::Xbee
    } else {
        TransportArg::Pprz2
    }
    .any();
    let down = async {
        let mut decoder: Decoder<AnyTransport> = Decoder::new(radio_transport);
        let v2 = PprzV2::new();
        let mut buf = [0u8; 256];
        let mut frame = [0u8; MAX_FRAME_LEN];
        let mut out = Vec::new();
        loop {
            let Ok(n) = radio_rx.read(&mut buf).await;
            let now = Instant::now();
            let mut input = &buf[..n];
            out.clear();
            while let Some(f) = decoder.feed(&mut input) {
                // Secure frames are opened by the ground, which records them.
                if !secure {
                    record::received(f.source(), f.class(), f.msg_id(), f.payload(), now);
                }
                if xbee && let Ok(len) = v2.encode(&f.tx_meta(), f.payload(), &mut frame) {
                    out.extend_from_slice(&frame[..len]);
                }
            }
            // PPRZ v2 goes on as it came (damaged frames too, for the ground to count).
            let bytes = if xbee { &out[..] } else { &buf[..n] };
            if !bytes.is_empty() {
                let _ = udp_tx.write_all(bytes).await;
            }
        }
    };
    let up = async {
        let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
        let mut buf = [0u8; 256];
        let mut frame = [0u8; MAX_FRAME_LEN];
        let mut out = Vec::new();
        loop {
            match udp_rx.read(&mut buf).await {
                Ok(n) if n > 0 => {
                    let now = Instant::now();
                    let mut input = &buf[..n];
                    out.clear();
                    while let Some(f) = decoder.feed(&mut input) {
                        if !secure {
                            let to = f.destination().unwrap_or(AC_ID);
                            record::uplink(to, f.class(), f.msg_id(), now);
                        }
                        if xbee
                            && let Ok(len) =
                                radio_transport.encode(&f.tx_meta(), f.payload(), &mut frame)
                        {
                            out.extend_from_slice(&frame[..len]);
                        }
                    }
                    let bytes = if xbee { &out[..] } else { &buf[..n] };
                    let _ = radio_tx.write_all(bytes).await;
                }
                _ => Timer::after(Duration::from_millis(10)).await,
            }
        }
    };
    embassy_futures::join::join(down, up).await;
}

/// Advances the mock clock to follow wall-clock time times `speed`.
///
/// The clock moves in steps (about 0.5 ms of simulated time up to `--speed 5`, more
/// above), and a task woken within a step runs at its end: a writer whose write ended
/// early in a step starts its next write late, so a UART that the writer alone keeps
/// busy idles up to a step per frame (a few percent of its time at `--speed 5` or less).
fn pace(speed: f64) {
    // Wall-clock time between steps: 500 µs at normal speed, down to 100 µs.
    let nap = StdDuration::from_micros((500.0 / speed).clamp(100.0, 500.0) as u64);
    std::thread::spawn(move || {
        let start = StdInstant::now();
        let mut simulated_us: u64 = 0;
        loop {
            std::thread::sleep(nap);
            let target = (start.elapsed().as_secs_f64() * speed * 1e6) as u64;
            if target > simulated_us {
                MockDriver::get().advance(Duration::from_micros(target - simulated_us));
                simulated_us = target;
            }
        }
    });
}

/// The radio as the options describe it, checked together (each option alone was
/// checked when parsed).
#[derive(Debug, Clone, Copy)]
struct RadioPlan {
    transport: TransportArg,
    serial_rate: u32,
    air_rate: u32,
    modem_buffer: usize,
    pacing: Option<Pacing>,
    window: Option<DeliveryWindow>,
    flood_bytes_per_s: u32,
    /// `--secure`: the radio reserves the secure overhead after every frame.
    secure: bool,
}

impl RadioPlan {
    /// The plan of `args`, or the message of a usage error.
    fn new(args: &Args) -> Result<Self, String> {
        let xbee = args.transport == TransportArg::Xbee;
        let serial_rate = args.baud / 10;
        let air_rate = args
            .air_rate
            .unwrap_or(if xbee { XBEE_AIR_RATE } else { serial_rate });
        let min_xbee_buffer = XBeeVariant::XBee24.max_api_frame();
        let modem_buffer = match args.modem_buffer {
            Some(b) if xbee && b < min_xbee_buffer => {
                return Err(format!(
                    "--modem-buffer {b} is too small for --transport xbee: an XBee modem holds at least one whole API frame, {min_xbee_buffer} bytes"
                ));
            }
            Some(b) => b,
            None if xbee => DEFAULT_XBEE_BUFFER,
            None => DEFAULT_MODEM_BUFFER,
        };
        if args.headless && args.foxglove.is_some() {
            return Err("--foxglove serves the in-process ground's telemetry: drop --headless (or run pprz-monitor --foxglove beside it)".into());
        }
        if args.fleet > 1 && (xbee || args.secure.is_some()) {
            return Err(
                "--fleet 2 needs --transport pprz2 without --secure (the relay forwards PPRZ v2 frames; the secure link is between one aircraft and the ground)"
                    .to_owned(),
            );
        }
        if args.secure.is_some() && xbee {
            return Err(
                "--secure needs --transport pprz2 (the secure link is Paparazzi's secure PPRZ v2)"
                    .to_owned(),
            );
        }
        if args.in_modem.is_some() && !xbee {
            return Err(
                "--in-modem needs --transport xbee (only XBee API frames have transmit statuses)"
                    .into(),
            );
        }
        let pacing = match (args.pacing, args.pacing_budget) {
            (OnOff::Off, Some(_)) => {
                return Err("--pacing-budget needs --pacing on".into());
            }
            (OnOff::On, Some(budget)) if budget > modem_buffer => {
                return Err(format!(
                    "--pacing-budget {budget} is larger than the modem buffer ({modem_buffer} bytes): the modem would overflow"
                ));
            }
            (OnOff::On, budget) => {
                let budget = budget.unwrap_or((modem_buffer / 2).clamp(1, MAX_DERIVED_BUDGET));
                Some(Pacing::new(air_rate, budget as u16))
            }
            (OnOff::Off, None) => None,
        };
        let window =
            xbee.then(|| DeliveryWindow::new(args.in_modem.unwrap_or(1), DELIVERY_TIMEOUT_MS));
        // 10x the link's capacity: the slower of the UART and the air.
        let flood_bytes_per_s = if args.overload {
            serial_rate.min(air_rate) * 10
        } else {
            0
        };
        Ok(Self {
            transport: args.transport,
            serial_rate,
            air_rate,
            modem_buffer,
            pacing,
            window,
            flood_bytes_per_s,
            secure: args.secure.is_some(),
        })
    }

    fn xbee(&self) -> bool {
        self.transport == TransportArg::Xbee
    }

    /// The simulated radio.
    fn sim_config(&self, flow_control: FlowControl) -> SimConfig {
        let config = SimConfig::new(self.air_rate)
            .serial_rate(self.serial_rate)
            .latency(Duration::from_millis(5))
            .buffer(self.modem_buffer)
            .overflow(match flow_control {
                FlowControl::Cts => Overflow::Wait,
                FlowControl::None => Overflow::Drop,
            })
            .seed(7);
        if self.xbee() {
            // An XBee 802.15.4 (module docs of `pprz_devices::sim`): MAC framing and
            // acknowledgement on the air, 1 ms ACK wait, 3 retries; the ground writes API
            // frames too; a frame the modem drops is answered with "purged".
            config.xbee(
                XBeeModem::new(XBeeVariant::XBee24)
                    .air_overhead(20)
                    .ack_delay(Duration::from_millis(1))
                    .retries(3)
                    .api_uplink(true)
                    .purge_status(true),
            )
        } else {
            config
        }
    }

    /// The radio device of the downlink.
    fn device_config(&self) -> DeviceConfig {
        let reserve = if self.secure {
            SecureLink::<M>::DEVICE.reserve
        } else {
            0
        };
        DeviceConfig::new(self.transport.any())
            .pacing(self.pacing)
            .delivery(self.window)
            .reserve(reserve)
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    let plan = match RadioPlan::new(&args) {
        Ok(plan) => plan,
        Err(message) => Args::command()
            .error(ErrorKind::ArgumentConflict, message)
            .exit(),
    };
    // Open the JSON file now: a bad path fails before the run, not after it.
    let mut summary_file = match &args.summary_json {
        Some(path) => match File::create(path) {
            Ok(f) => Some((path, f)),
            Err(e) => {
                eprintln!("sitl: cannot write the summary to {}: {e}", path.display());
                return ExitCode::FAILURE;
            }
        },
        None => None,
    };
    // The key file: both ends' keys (the aircraft's only with --headless).
    let keys = match &args.secure {
        Some(path) => match load_keys(path, args.headless) {
            Ok(keys) => Some(keys),
            Err(e) => {
                eprintln!("sitl: --secure {}: {e}", path.display());
                return ExitCode::from(2);
            }
        },
        None => None,
    };
    let config = Config {
        flood_bytes_per_s: if plan.xbee() {
            0 // the flood task below sends frames that fit XBee 802.15.4
        } else {
            plan.flood_bytes_per_s
        },
        observer: Some(record::submitted),
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
    let radio: &'static Radio = RADIO.init(SimLink::new(plan.sim_config(args.flow_control)));
    let fleet = args.fleet > 1;
    let routes = if fleet {
        Routes::new(&FLEET_ROUTES, Targets::only(0))
    } else {
        // One aircraft: everything on the radio (device 1 stays idle).
        Routes::new(&[], Targets::only(0)).broadcast(Targets::only(0))
    };
    let downlink: &'static Dl = DOWNLINK.init(
        Downlink::new(&ARENA, AC_ID, [plan.device_config(), plan.device_config()])
            .with_routes(routes),
    );
    let [radio_port, link_port] = match downlink.ports() {
        Ok(ports) => ports,
        Err(e) => {
            eprintln!("sitl: {e}");
            return ExitCode::FAILURE;
        }
    };
    let radio_device = radio_port.device();
    // `--fleet 2`: aircraft 8, its radio to 7, its application.
    let second = fleet.then(|| {
        let link: &'static Radio = LINK_78.init(SimLink::new(plan.sim_config(args.flow_control)));
        let downlink_8: &'static Dl8 = DOWNLINK_8.init(Downlink::new(
            &ARENA_8,
            SECOND_AC_ID,
            [plan.device_config()],
        ));
        (link, downlink_8)
    });
    let second_parts = match second {
        Some((link, downlink_8)) => match downlink_8.ports() {
            Ok([port_8]) => Some((link, downlink_8, port_8)),
            Err(e) => {
                eprintln!("sitl: {e}");
                return ExitCode::FAILURE;
            }
        },
        None => None,
    };
    let fleet_8: Option<(&'static Radio, &'static Dl8)> = second_parts
        .as_ref()
        .map(|(link, downlink_8, _)| (*link, *downlink_8));
    let config_8 = Config {
        observer: Some(record::submitted_by_second),
        ..config
    };
    let (air, ground) = radio.endpoints();
    let (air_rx, air_tx) = air.split();
    pace(args.speed);
    let xbee = plan.xbee();
    let flood = plan.flood_bytes_per_s;
    let (responder, ground_keys) = match keys {
        Some(k) => (Some(Responder::new(AC_ID, k.aircraft)), k.ground),
        None => (None, None),
    };
    let secure = responder.is_some();
    std::thread::spawn(move || {
        let executor = EXECUTOR.init(Executor::new());
        executor.run(|spawner| {
            let layer = secure.then_some(&SECURE);
            spawner.spawn(radio_writer(radio_port, air_tx, layer).unwrap());
            if let Some((link, _, port_8)) = second_parts {
                let (side_7, side_8) = link.endpoints();
                let (rx_7, tx_7) = side_7.split();
                let (rx_8, tx_8) = side_8.split();
                let link_device = link_port.device();
                let device_8 = port_8.device();
                spawner.spawn(radio_writer(link_port, tx_7, None).unwrap());
                spawner.spawn(radio_writer(port_8, tx_8, None).unwrap());
                spawner.spawn(
                    relay_aircraft(radio_device, air_rx, link_device, rx_7, config).unwrap(),
                );
                spawner.spawn(aircraft(device_8, rx_8, config_8).unwrap());
            } else if let Some(responder) = responder {
                spawner.spawn(secure_aircraft(radio_device, air_rx, config, responder).unwrap());
            } else if xbee {
                spawner.spawn(xbee_reader(air_rx, radio_device).unwrap());
                spawner.spawn(aircraft_piped(radio_device, config).unwrap());
                if flood > 0 {
                    spawner.spawn(xbee_flood(radio_device.sender(), flood).unwrap());
                }
            } else {
                spawner.spawn(aircraft(radio_device, air_rx, config).unwrap());
            }
            spawner.spawn(ground_bridge(ground, udp, xbee, secure).unwrap());
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

    let monitor = match (ground_socket, set) {
        (Some(socket), Some(set)) => {
            let transport = PprzV2::new().into();
            let monitor = Monitor::new(set, transport);
            let monitor = match ground_keys {
                Some(keys) => match monitor.with_secure(GroundSecure::new(AC_ID, keys)) {
                    Ok(m) => m,
                    Err(e) => {
                        eprintln!("sitl: {e}");
                        return ExitCode::FAILURE;
                    }
                },
                None => monitor,
            };
            let viewer = match args.foxglove {
                Some(addr) => {
                    let mut viewer = Viewer::new();
                    match viewer.serve(addr, "pprz sitl", true) {
                        Ok(bound) => eprintln!("foxglove: serving ws://{bound}"),
                        Err(e) => {
                            eprintln!("sitl: {e}");
                            return ExitCode::FAILURE;
                        }
                    }
                    Some(viewer)
                }
                None => None,
            };
            let side = |ac: u8| aircraft_levels(ac, downlink, fleet_8.map(|(_, d)| d));
            Some(run_ground(
                &args, socket, monitor, viewer, &side, &stop, start,
            ))
        }
        _ => {
            let who = if args.fleet > 1 {
                format!("aircraft {AC_ID} and {SECOND_AC_ID} (through {AC_ID})")
            } else {
                format!("aircraft {AC_ID}")
            };
            println!(
                "{who} running: telemetry to UDP {}, uplink on UDP {} (Ctrl-C to stop)",
                args.ground, args.uplink
            );
            while !stop.load(Ordering::SeqCst) && start.elapsed().as_secs_f64() < wall_limit {
                std::thread::sleep(StdDuration::from_millis(100));
            }
            None
        }
    };
    if let Some(m) = &monitor
        && !args.lines
    {
        print!("\x1b[2J\x1b[H{}", m.render(sim_now(args.speed)));
    }
    let summary = collect_summary(&args, &plan, downlink, radio_device, radio, fleet_8);
    print!("{}", summary.text());
    if let Some(m) = &monitor {
        for ac in m.aircraft() {
            if let Some(pings) = m.pings_of(ac) {
                println!(
                    "  ground station, aircraft {ac}: PINGs sent {}, answered {}, lost {}",
                    pings.sent_count(),
                    pings.answered(),
                    pings.lost()
                );
            }
        }
        for line in m.secure_lines() {
            println!("  ground station {line}");
        }
    }
    if let Some((path, file)) = &mut summary_file
        && let Err(e) = file.write_all(summary.json().as_bytes())
    {
        eprintln!("sitl: cannot write the summary to {}: {e}", path.display());
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

/// The keys of `--secure`: the aircraft's, and the ground's unless `headless`.
struct SitlKeys {
    aircraft: pprz_secure::AircraftKeys,
    ground: Option<pprz_secure::GroundKeys>,
}

/// Reads the key file (`pprz_ground::secure::key_file_from_path`: bounded, UTF-8,
/// cleared after parsing) and takes the keys each end needs.
fn load_keys(path: &std::path::Path, headless: bool) -> Result<SitlKeys, String> {
    let file = key_file_from_path(path).map_err(|e| e.to_string())?;
    let aircraft = file.aircraft().map_err(|e| format!("aircraft keys: {e}"))?;
    let ground = if headless {
        None
    } else {
        Some(file.ground().map_err(|e| format!("ground keys: {e}"))?)
    };
    Ok(SitlKeys { aircraft, ground })
}

/// The ground station in this process, until the end of the run: PINGs, one SETTING,
/// the live table or one line per message.
fn run_ground(
    args: &Args,
    socket: UdpSocket,
    mut monitor: Monitor,
    mut viewer: Option<Viewer>,
    aircraft_side: &dyn Fn(u8) -> Option<[LevelFigures; 3]>,
    stop: &AtomicBool,
    start: StdInstant,
) -> Monitor {
    let sim_now = |speed: f64| start.elapsed().as_secs_f64() * speed;
    let wall_limit = args.duration / args.speed;
    let transport = PprzV2::new().into();
    let fleet: &[u8] = if args.fleet > 1 {
        &[AC_ID, SECOND_AC_ID]
    } else {
        &[AC_ID]
    };
    let secure = monitor.secure_status().is_some();
    let _ = socket.set_read_timeout(Some(StdDuration::from_millis(20)));
    let mut buf = [0u8; 2048];
    let ping_period = 1.0 / args.ping_rate;
    let mut next_ping = 1.0;
    let mut setting_sent = false;
    let mut next_render = 0.0;
    let mut next_link = 0.0;
    while !stop.load(Ordering::SeqCst) && start.elapsed().as_secs_f64() < wall_limit {
        let t = sim_now(args.speed);
        // The key exchange (--secure): message 1 until answered, message 3.
        for frame in monitor.poll_secure(t) {
            let _ = socket.send_to(&frame, args.uplink);
        }
        // Every PING due by now (a flood sends many per pass; a slow pass skips none);
        // on a secure link, from the session on, sealed.
        // Every aircraft of the fleet is PINGed and gets the SETTING.
        while t >= next_ping {
            for &ac in fleet {
                if monitor.uplink_ready()
                    && let Ok(frame) = uplink::frame(monitor.set(), transport, ac, "PING", &[])
                    && let Ok(frame) = monitor.seal_uplink(&frame)
                    && socket.send_to(&frame, args.uplink).is_ok()
                {
                    monitor.ping_sent_to(t, ac);
                    if secure {
                        record::uplink(ac, Ping::CLASS_ID, Ping::ID, Instant::now());
                    }
                }
            }
            next_ping += ping_period;
        }
        if !setting_sent && t >= 3.0 && monitor.uplink_ready() {
            for &ac in fleet {
                // Setting 2 is the example's `gain`.
                let values = [("index", 2.0), ("ac_id", f64::from(ac)), ("value", 2.5)];
                if let Ok(frame) = uplink::frame(monitor.set(), transport, ac, "SETTING", &values)
                    && let Ok(frame) = monitor.seal_uplink(&frame)
                    && socket.send_to(&frame, args.uplink).is_ok()
                {
                    monitor.setting_value_sent_to(t, ac, 2, 2.5);
                }
            }
            setting_sent = true;
        }
        // Settings read and written from the viewer.
        let requests = match viewer.as_mut() {
            Some(v) => v.setting_requests(t),
            None => Vec::new(),
        };
        for request in requests {
            let (name, values) = request.message();
            if monitor.uplink_ready()
                && let Ok(frame) =
                    uplink::frame(monitor.set(), transport, request.ac_id(), name, &values)
                && let Ok(frame) = monitor.seal_uplink(&frame)
                && socket.send_to(&frame, args.uplink).is_ok()
            {
                request.sent(&mut monitor, t);
            }
        }
        if let Ok((n, _)) = socket.recv_from(&mut buf) {
            monitor.feed(sim_now(args.speed), &buf[..n], |m| {
                if args.lines {
                    println!("{}", m.line);
                }
                if let Some(v) = viewer.as_mut() {
                    v.message(unix_ns(), m);
                }
                // A secure link's frames are recorded here, opened (the radio's bridge
                // sees them encrypted).
                if secure && let Ok(f) = PprzV2::new().view(m.raw) {
                    record::received(
                        f.source(),
                        f.class(),
                        f.msg_id(),
                        f.payload(),
                        Instant::now(),
                    );
                }
            });
        }
        if !args.lines && t >= next_render {
            print!("\x1b[2J\x1b[H{}", monitor.render(t));
            next_render = t + 0.5 * args.speed.max(1.0);
        }
        if let Some(v) = viewer.as_mut()
            && t >= next_link
        {
            v.link_stats(unix_ns(), &monitor, aircraft_side);
            next_link = t + args.speed;
        }
    }
    if let Some(v) = viewer {
        eprintln!("{}", v.counts());
        if let Err(e) = v.finish() {
            eprintln!("sitl: {e}");
        }
    }
    monitor
}

/// The aircraft's own figures per priority level (what it submitted, sent and shed of
/// its own messages; frames it relays are the other aircraft's), for the viewer's link
/// statistics.
fn aircraft_levels(ac: u8, downlink: &Dl, second: Option<&Dl8>) -> Option<[LevelFigures; 3]> {
    let figures = |f: &dyn Fn(usize) -> (u32, u32, u32)| {
        [0, 1, 2].map(|i| {
            let (submitted, sent, shed) = f(i);
            LevelFigures {
                submitted: submitted.into(),
                sent: sent.into(),
                shed: shed.into(),
            }
        })
    };
    if ac == AC_ID {
        let s = downlink.stats(0)?;
        Some(figures(&|i| {
            let (all, relayed) = (s.levels[i], s.relayed.levels[i]);
            (
                all.submitted.saturating_sub(relayed.submitted),
                all.sent.saturating_sub(relayed.sent),
                all.lost.saturating_sub(relayed.lost),
            )
        }))
    } else if ac == SECOND_AC_ID {
        let s = second?.stats(0)?;
        Some(figures(&|i| {
            let l = s.levels[i];
            (l.submitted, l.sent, l.lost)
        }))
    } else {
        None
    }
}

/// The figures of the run so far.
fn collect_summary(
    args: &Args,
    plan: &RadioPlan,
    downlink: &Dl,
    radio_device: Device<'static>,
    radio: &Radio,
    fleet: Option<(&'static Radio, &'static Dl8)>,
) -> Summary {
    let elapsed_us = Instant::now().as_micros();
    let fleet = fleet.map(|(_, downlink_8)| fleet_figures(downlink, downlink_8));
    let stats: DeviceStats = downlink.stats(0).unwrap_or_default();
    let sim = radio.stats(Direction::AToB);
    let fraction = |busy_us: u64| {
        if elapsed_us == 0 {
            0.0
        } else {
            busy_us as f64 / elapsed_us as f64
        }
    };
    // Copied out of the record before anything else is locked.
    let (received, ping, messages) = {
        let record = record::lock();
        let level = |i: usize| {
            let r = &record.levels[i];
            (
                r.received,
                r.ages.count(),
                r.ages.percentile_ms(50.0),
                r.ages.percentile_ms(99.0),
                r.ambiguous,
            )
        };
        let messages = record
            .types
            .iter()
            .filter_map(|(&(class, id), t)| {
                let desc = MESSAGES.find(class, id)?;
                Some(MessageFigures {
                    class: desc.class_name,
                    name: desc.name,
                    level: priority::LEVEL_NAMES[priority::level(desc.priority)],
                    submitted: t.submitted,
                    received: t.received,
                    max_gap_ms: (t.received > 1).then(|| t.max_gap_us as f64 / 1000.0),
                })
            })
            .collect::<Vec<_>>();
        let ping = PingFigures {
            sent: record.pings.sent_count(),
            answered: record.pings.answered(),
            lost: record.pings.lost(),
            rtt_p50_ms: record.rtt.percentile_ms(50.0),
            rtt_p99_ms: record.rtt.percentile_ms(99.0),
        };
        ([level(0), level(1), level(2)], ping, messages)
    };
    let level = |i: usize| {
        let s = stats.levels[i];
        let (received, aged, p50, p99, ambiguous) = received[i];
        Level {
            submitted: s.submitted,
            sent: s.sent,
            shed: s.lost,
            superseded: s.superseded,
            received,
            aged,
            age_p50_ms: p50,
            age_p99_ms: p99,
            ambiguous,
        }
    };
    let delivery = plan.xbee().then(|| {
        let d = radio_device.delivery_stats();
        DeliveryFigures {
            delivered: d.delivered,
            failed: d.failed,
            timeouts: d.timeouts,
            unexpected: d.unexpected,
        }
    });
    Summary {
        schema: 1,
        config: RunConfig {
            transport: plan.transport.name(),
            baud: args.baud,
            serial_rate_bytes_per_s: plan.serial_rate,
            air_rate_bytes_per_s: plan.air_rate,
            modem_buffer_bytes: plan.modem_buffer,
            flow_control: match args.flow_control {
                FlowControl::Cts => "cts",
                FlowControl::None => "none",
            },
            pacing: plan.pacing.is_some(),
            pacing_budget_bytes: plan.pacing.map(|p| p.modem_budget),
            in_modem: plan.window.map(|w| w.in_modem),
            overload: args.overload,
            flood_bytes_per_s: plan.flood_bytes_per_s,
            speed: args.speed,
            duration_s: args.duration,
        },
        simulated_s: elapsed_us as f64 / 1e6,
        levels: Levels {
            high: level(0),
            normal: level(1),
            low: level(2),
        },
        downlink: DownlinkFigures {
            sent: stats.sent,
            dropped: stats.dropped.total(),
            queue_full: stats.dropped.queue_full,
            arena_full: stats.dropped.arena_full,
            too_large: stats.dropped.too_large,
            rate_limited: stats.dropped.rate_limited,
            refused: stats.dropped.refused,
            evicted: stats.evicted.total(),
            superseded: stats.superseded,
            queued: stats.queued,
        },
        modem: ModemFigures {
            dropped_bytes: sim.dropped_bytes,
            frames_dropped: sim.frames_dropped,
            overrun_bytes: sim.overrun_bytes,
            uart_busy: fraction(sim.serial_busy_us),
            air_busy: fraction(sim.air_busy_us),
        },
        delivery,
        ping,
        messages,
        secure: plan.secure.then(|| {
            let k = SECURE.stats().secure;
            SecureFigures {
                session: k.session,
                handshakes_started: k.handshake.started,
                handshakes_completed: k.handshake.completed,
                handshakes_refused: k.handshake.refused(),
                encrypted: k.channel.encrypted,
                decrypted: k.channel.decrypted,
                rejected: k.channel.rejected(),
                counter_space_left: k.counter_space_left,
            }
        }),
        fleet,
    }
}

/// `--fleet 2`: aircraft 7 (relay) and 8 per level, from their downlinks' statistics
/// (7's radio device counts 8's frames apart: `DeviceStats::relayed`) and the record of
/// what reached the ground.
fn fleet_figures(downlink_7: &Dl, downlink_8: &Dl8) -> FleetFigures {
    let radio_7 = downlink_7.stats(0).unwrap_or_default();
    let link_7 = downlink_7.stats(1).unwrap_or_default();
    let radio_8 = downlink_8.stats(0).unwrap_or_default();
    let record = record::lock();
    let received = |ac: u8, i: usize| record.aircraft.get(&ac).map_or(0, |a| a.received[i]);
    let ping = |ac: u8| {
        record
            .aircraft
            .get(&ac)
            .map_or_else(PingFigures::default, |a| PingFigures {
                sent: a.pings.sent_count(),
                answered: a.pings.answered(),
                lost: a.pings.lost(),
                rtt_p50_ms: a.rtt.percentile_ms(50.0),
                rtt_p99_ms: a.rtt.percentile_ms(99.0),
            })
    };
    let names = priority::LEVEL_NAMES;
    let own_7 = |i: usize| {
        let (all, relayed) = (radio_7.levels[i], radio_7.relayed.levels[i]);
        AircraftLevel {
            level: names[i],
            submitted: all.submitted - relayed.submitted,
            sent: all.sent - relayed.sent,
            shed: all.lost - relayed.lost,
            forwarded: 0,
            shed_by_relay: 0,
            received: received(AC_ID, i),
        }
    };
    let of_8 = |i: usize| {
        let (own, relayed) = (radio_8.levels[i], radio_7.relayed.levels[i]);
        AircraftLevel {
            level: names[i],
            submitted: own.submitted,
            sent: own.sent,
            shed: own.lost,
            forwarded: relayed.submitted,
            shed_by_relay: relayed.lost,
            received: received(SECOND_AC_ID, i),
        }
    };
    let route = |to: String, s: &DeviceStats| {
        let r = &s.relayed;
        RouteFigures {
            relay: AC_ID,
            to,
            forwarded: r.levels.map(|l| l.submitted),
            sent: r.sent,
            shed: r.levels.map(|l| l.lost),
            queue_full: r.dropped.queue_full,
            arena_full: r.dropped.arena_full,
            evicted: r.evicted.total(),
        }
    };
    FleetFigures {
        aircraft: vec![
            AircraftFigures {
                ac_id: AC_ID,
                relayed_by: None,
                levels: [own_7(0), own_7(1), own_7(2)],
                ping: ping(AC_ID),
            },
            AircraftFigures {
                ac_id: SECOND_AC_ID,
                relayed_by: Some(AC_ID),
                levels: [of_8(0), of_8(1), of_8(2)],
                ping: ping(SECOND_AC_ID),
            },
        ],
        routes: vec![
            route("ground".to_owned(), &radio_7),
            route(format!("aircraft {SECOND_AC_ID}"), &link_7),
        ],
    }
}
