//! The command line: the options, each checked alone as it is parsed (the radio they
//! describe together is checked in [`crate::radio::RadioPlan::new`]).

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::{Parser, ValueEnum};
use pprz_ground::cli;
use pprz_telemetry::delivery::MAX_IN_MODEM;
use pprz_telemetry::pprz_transports::{AnyTransport, PprzV2, XBee24};

/// A simulated aircraft and its ground station, over a simulated radio.
///
/// The aircraft runs the Paparazzi telemetry stack on the host and talks through a
/// simulated radio modem. The ground end of the radio is bridged to UDP (telemetry to
/// `--ground`, uplink from `--uplink`), so Paparazzi's ground tools or `pprz-monitor` can
/// listen. Without `--headless`, this process also is the ground: it shows the live
/// telemetry, PINGs the aircraft, changes a setting, and ends with a summary per
/// priority level.
#[derive(Debug, Parser)]
#[command(name = "sitl", version)]
pub struct Args {
    /// Stop after this many (simulated) seconds, more than 0 and at most a year; Ctrl-C
    /// stops too.
    #[arg(long, default_value_t = 20.0, value_parser = cli::parse_duration)]
    pub duration: f64,
    /// Flood the radio with low-priority payload at 10x its capacity (the slower of the
    /// UART and the air).
    #[arg(long)]
    pub overload: bool,
    /// Simulated seconds per wall-clock second (0.01 to 100).
    #[arg(long, default_value_t = 1.0, value_parser = parse_speed)]
    pub speed: f64,
    /// Baud rate (8N1) of the UART between the autopilot and its radio modem, 300 to
    /// 4000000: the UART carries `baud / 10` bytes per second.
    #[arg(long, default_value_t = 57_600, value_parser = parse_radio_baud)]
    pub baud: u32,
    /// The radio modem's buffer, in bytes (1 to 8192; XBee: at least one whole frame,
    /// 109 bytes) [default: 64, XBee: 202].
    #[arg(long, value_name = "BYTES", value_parser = parse_modem_buffer)]
    pub modem_buffer: Option<usize>,
    /// What the modem does when its buffer is full: `cts` stops the UART (hardware flow
    /// control), `none` drops the bytes that arrive.
    #[arg(long, value_enum, default_value_t = FlowControl::Cts)]
    pub flow_control: FlowControl,
    /// The modem's over-the-air throughput, bytes per second (10 to 1000000)
    /// [default: baud / 10; XBee 802.15.4: 31250].
    #[arg(long, value_name = "BYTES_PER_S", value_parser = parse_air_rate)]
    pub air_rate: Option<u32>,
    /// `on`: the radio device paces its writes to the air rate, keeping at most the
    /// pacing budget in the modem, so frames wait (and are shed) in the priority queue.
    #[arg(long, value_enum, default_value_t = OnOff::Off)]
    pub pacing: OnOff,
    /// The pacing budget, in bytes (1 to the modem buffer; needs `--pacing on`)
    /// [default: half the modem buffer, at most 192].
    #[arg(long, value_name = "BYTES", value_parser = parse_modem_buffer)]
    pub pacing_budget: Option<usize>,
    /// What the radio speaks: PPRZ v2 through a transparent modem, or XBee 802.15.4 API
    /// frames with transmit statuses.
    #[arg(long, value_enum, default_value_t = TransportArg::Pprz2)]
    pub transport: TransportArg,
    /// XBee: frames awaiting their transmit status at most, 1 to 8 (needs `--transport
    /// xbee`) [default: 1].
    #[arg(long, value_name = "K", value_parser = parse_in_modem)]
    pub in_modem: Option<u8>,
    /// Also write the end summary as JSON to this file (schema in the README).
    #[arg(long, value_name = "PATH")]
    pub summary_json: Option<PathBuf>,
    /// PINGs the ground sends per (simulated) second, 0.1 to 10000: above the aircraft's
    /// reply limit (20/s) the extra PONGs are refused and counted, and telemetry flows on.
    #[arg(long, default_value_t = 1.0, value_parser = parse_ping_rate)]
    pub ping_rate: f64,
    /// Where the ground listens for telemetry (Paparazzi's link uses port 4242).
    #[arg(long, default_value = "127.0.0.1:4242")]
    pub ground: SocketAddr,
    /// Where the aircraft's radio bridge listens for uplink frames (port 4243).
    #[arg(long, default_value = "127.0.0.1:4243")]
    pub uplink: SocketAddr,
    /// No monitor: only the aircraft, for Paparazzi's ground tools or `pprz-monitor`.
    #[arg(long)]
    pub headless: bool,
    /// One line per received message instead of the live table.
    #[arg(long)]
    pub lines: bool,
    /// Secure the radio with Paparazzi's secure PPRZ link, keys from this key file (see
    /// pprz-secure's keygen; `secure/keys/INSECURE-TEST-ONLY.keys` for a try): the
    /// aircraft sends nothing but its key exchange until a ground completes the
    /// handshake; the in-process ground uses the same file (with `--headless`, an
    /// external ground such as `pprz-monitor --secure` does the handshake over UDP).
    /// PPRZ v2 only.
    #[arg(long, value_name = "KEYFILE")]
    pub secure: Option<PathBuf>,
    /// Aircraft in the simulation, 1 to 32: aircraft 7, 8, ... up to 7 + N - 1, each on a
    /// simulated radio of its own to the ground (the same radio as aircraft 7's: the
    /// options above, `--outage`, `--bit-error-rate`; each radio's errors seeded apart
    /// from `--seed`). The ground sees every aircraft on the same UDP port and PINGs
    /// and sets each. PPRZ v2 without `--secure` when more than one.
    #[arg(long, default_value_t = 1, value_parser = parse_fleet)]
    pub fleet: u8,
    /// With `--fleet 2` only: aircraft 8 flies out of the ground's reach, its radio
    /// joins it to aircraft 7, and 7 relays between its two radios.
    #[arg(long)]
    pub relay: bool,
    /// Radios from each aircraft to the ground, 1 or 2: with 2, each aircraft sends its
    /// telemetry on both (radio A to `--ground`/`--uplink`, radio B to
    /// `--ground-b`/`--uplink-b`), each radio with its own seeded errors and losses, and
    /// the in-process ground merges them with the gateway. PPRZ v2, without `--relay`
    /// or `--secure`.
    #[arg(long, default_value_t = 1, value_parser = parse_radios)]
    pub radios: u8,
    /// Probability that a frame is lost, 0 to 0.9, on every radio to the ground and in
    /// each direction, each frame drawn apart (seeded from `--seed` and the radio):
    /// the in-process ground then merges its radios with the gateway. PPRZ v2.
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = parse_frame_loss)]
    pub frame_loss: f64,
    /// With `--radios 2`: where the ground listens for radio B's telemetry.
    #[arg(long, default_value = "127.0.0.1:4244")]
    pub ground_b: SocketAddr,
    /// With `--radios 2`: where radio B's bridge listens for uplink frames.
    #[arg(long, default_value = "127.0.0.1:4245")]
    pub uplink_b: SocketAddr,
    /// Serve the simulated fleet on a Zenoh bus: the in-process ground runs the gateway
    /// service on a peer session listening on this endpoint (e.g. `tcp/127.0.0.1:7447`;
    /// multicast scouting off), publishing `pprz/<ac>/telemetry/<MSG>` and taking
    /// commands on `pprz/<ac>/uplink/<MSG>`. Needs the in-process ground, PPRZ v2 and no
    /// `--secure`.
    #[arg(long, value_name = "ENDPOINT", value_parser = cli::parse_zenoh_endpoint)]
    pub zenoh: Option<String>,
    /// Seed of the simulated radios' errors (bit errors, XBee failures): each radio's
    /// seed is derived from it and the radio's index, so runs are reproducible and the
    /// radios independent.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Probability that a bit on the air is flipped, 0 to 0.01, on every simulated
    /// radio: damaged PPRZ v2 frames fail their checksum, damaged XBee transmissions
    /// are retried.
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = parse_bit_error_rate)]
    pub bit_error_rate: f64,
    /// Serve the ground's decoded telemetry to Foxglove or Lichtblick over the Foxglove
    /// WebSocket protocol at this address (e.g. `127.0.0.1:8765`; port 0: any free port,
    /// printed), with the aircraft's own per-level figures on `/ac/<id>/link`. Needs the
    /// in-process ground (not `--headless`).
    #[arg(long, value_name = "ADDR")]
    pub foxglove: Option<SocketAddr>,
    /// Cut the radios to the ground from START to END seconds of simulated time
    /// (decimals allowed): DIR `up` cuts the uplink (ground to aircraft), `down` the
    /// downlink, `both` both. Every radio to the ground is cut (with `--relay`, aircraft
    /// 7's, which also carries 8's frames). What is sent in the window is lost, counted
    /// by the simulated radio. Repeat for several windows (at most 8 per direction).
    #[arg(long, value_name = "DIR:START..END", value_parser = parse_outage)]
    pub outage: Vec<Outage>,
    /// The aircraft's link health: Lost (and the failsafe flies home) after this many
    /// seconds without a frame from the ground, 0.1 to 3600 (Degraded after 2 s).
    #[arg(long, value_name = "SECONDS", default_value_t = 5.0, value_parser = parse_lost_timeout)]
    pub lost_timeout: f64,
    /// At this simulated time the ground sets every aircraft's `ap_mode` back to NAV
    /// (SETTING index 3, value 13): after a link-loss failsafe, the aircraft stays in
    /// HOME until the ground sets the mode again. Needs the in-process ground.
    #[arg(long, value_name = "SECONDS", value_parser = parse_instant)]
    pub resume_nav: Option<f64>,
    /// At simulated time AT (seconds) the ground sends SETTING INDEX = VALUE to every
    /// aircraft, once (e.g. `4:4=1` sets the store flag: the aircraft stores its
    /// persistent settings). Repeat for several, at most 16. Needs the in-process
    /// ground.
    #[arg(long, value_name = "AT:INDEX=VALUE", value_parser = parse_timed_setting)]
    pub setting: Vec<TimedSetting>,
    /// Keep the aircraft's persistent settings (the gain) in this file: a simulated
    /// flash of three 16 KiB pages, created erased when absent. They are loaded at start
    /// and stored when the ground sets setting 4 (the store flag) to 1. Without it,
    /// nothing persists from run to run. One aircraft only.
    #[arg(long, value_name = "PATH")]
    pub settings_flash: Option<PathBuf>,
    /// The messages.xml the monitor decodes with.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../messages.xml"))]
    pub messages: PathBuf,
    /// The aircraft's settings files (Paparazzi settings.xml), in order: the in-process
    /// ground names the settings after them (live view, `--lines`, Foxglove parameters)
    /// [default: the example application's examples/app/settings.xml, when it exists].
    #[arg(long = "settings", value_name = "FILE", num_args = 1..)]
    pub settings: Vec<PathBuf>,
}

/// The example application's settings file, the default of `--settings`.
pub const APP_SETTINGS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/app/settings.xml");

impl Args {
    /// The settings files of the run: `--settings`, else the example application's
    /// file when it exists, else none (the ground shows indices).
    pub fn settings_files(&self) -> Vec<PathBuf> {
        if !self.settings.is_empty() {
            return self.settings.clone();
        }
        let app = PathBuf::from(APP_SETTINGS);
        if app.is_file() { vec![app] } else { Vec::new() }
    }
}

/// `--flow-control`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FlowControl {
    /// Hardware flow control: the modem stops the UART while its buffer is full.
    Cts,
    /// None: the modem drops the bytes that arrive while its buffer is full.
    None,
}

/// `--pacing`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

/// `--transport`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TransportArg {
    /// PPRZ v2 frames through a transparent modem.
    Pprz2,
    /// XBee 802.15.4 API frames (TX16/RX16) with transmit statuses.
    Xbee,
}

impl TransportArg {
    /// The name in the summary: `pprz2` or `xbee`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Pprz2 => "pprz2",
            Self::Xbee => "xbee",
        }
    }

    /// The transport it names.
    pub fn any(self) -> AnyTransport {
        match self {
            Self::Pprz2 => PprzV2::new().into(),
            Self::Xbee => XBee24::new().into(),
        }
    }
}

/// The directions an outage cuts (`--outage`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cut {
    /// The uplink: ground to aircraft.
    Up,
    /// The downlink: aircraft to ground.
    Down,
    /// Both.
    Both,
}

impl Cut {
    /// The name on the command line and in the summary: `up`, `down` or `both`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Up => "up",
            Self::Down => "down",
            Self::Both => "both",
        }
    }

    /// Whether it cuts the uplink.
    pub fn up(self) -> bool {
        self != Self::Down
    }

    /// Whether it cuts the downlink.
    pub fn down(self) -> bool {
        self != Self::Up
    }
}

/// One `--outage`: a window of simulated time in which the radio to the ground carries
/// nothing in the directions of `cut`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outage {
    /// What it cuts.
    pub cut: Cut,
    /// Its start, simulated seconds.
    pub from_s: f64,
    /// Its end (after the start), simulated seconds.
    pub until_s: f64,
}

/// `--outage DIR:START..END`.
fn parse_outage(s: &str) -> Result<Outage, String> {
    const FORM: &str = "DIR:START..END, e.g. up:10..20";
    let (dir, window) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}` is not {FORM}"))?;
    let cut = match dir.trim() {
        "up" => Cut::Up,
        "down" => Cut::Down,
        "both" => Cut::Both,
        other => {
            return Err(format!(
                "`{other}` is not a direction: up, down or both ({FORM})"
            ));
        }
    };
    let (from, until) = window
        .split_once("..")
        .ok_or_else(|| format!("`{window}` has no `..` ({FORM})"))?;
    let from_s = parse_instant(from)?;
    let until_s = parse_instant(until)?;
    if until_s <= from_s {
        return Err(format!(
            "the outage `{s}` ends at or before it starts ({FORM})"
        ));
    }
    Ok(Outage {
        cut,
        from_s,
        until_s,
    })
}

/// One `--setting`: the ground sends SETTING `index` = `value` at `at_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedSetting {
    /// When, simulated seconds.
    pub at_s: f64,
    /// The setting's index.
    pub index: u8,
    /// Its new value (finite).
    pub value: f64,
}

/// `--setting AT:INDEX=VALUE`.
fn parse_timed_setting(s: &str) -> Result<TimedSetting, String> {
    const FORM: &str = "AT:INDEX=VALUE, e.g. 4:4=1";
    let (at, rest) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}` is not {FORM}"))?;
    let (index, value) = rest
        .split_once('=')
        .ok_or_else(|| format!("`{rest}` has no `=` ({FORM})"))?;
    let index = integer_in(index, 0, u64::from(u8::MAX))? as u8;
    let value = number_in(value, -f64::from(f32::MAX), f64::from(f32::MAX))?;
    Ok(TimedSetting {
        at_s: parse_instant(at)?,
        index,
        value,
    })
}

/// A time in the run: simulated seconds from 0 to a year (`--outage`, `--resume-nav`,
/// `--setting`).
fn parse_instant(s: &str) -> Result<f64, String> {
    number_in(s, 0.0, cli::MAX_DURATION)
}

/// `--lost-timeout`: from 0.1 s to an hour.
fn parse_lost_timeout(s: &str) -> Result<f64, String> {
    number_in(s, 0.1, 3600.0)
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

/// `--fleet`: 1 to [`MAX_FLEET`](crate::fleet::MAX_FLEET) aircraft.
fn parse_fleet(s: &str) -> Result<u8, String> {
    integer_in(s, 1, u64::from(crate::fleet::MAX_FLEET))
        .map(|n| n as u8)
        .map_err(|e| format!("{e} aircraft"))
}

/// `--bit-error-rate`: 0 (no errors) to one bit in a hundred.
fn parse_bit_error_rate(s: &str) -> Result<f64, String> {
    number_in(s, 0.0, 0.01)
}

/// `--radios`: 1 or 2 radios per aircraft.
fn parse_radios(s: &str) -> Result<u8, String> {
    integer_in(s, 1, 2)
        .map(|n| n as u8)
        .map_err(|e| format!("{e} radios"))
}

/// `--frame-loss`: 0 (none) to 0.9.
fn parse_frame_loss(s: &str) -> Result<f64, String> {
    number_in(s, 0.0, 0.9)
}

impl Args {
    /// Whether the in-process ground merges its radios with the gateway: two radios,
    /// a frame loss or a bus (one plain radio keeps the monitor of one byte stream).
    pub fn gateway(&self) -> bool {
        self.radios > 1 || self.frame_loss > 0.0 || self.zenoh.is_some()
    }
}

/// `--ping-rate`: at most 10 kHz (a flood), at least one PING every 10 s.
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
/// ([`RADIO_RING`](crate::radio::RADIO_RING)), which also holds the bytes on the air and those not yet read.
pub const MAX_MODEM_BUFFER: usize = 8192;

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
