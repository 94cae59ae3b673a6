//! The command line of `pprz-monitor`, with every value checked when it is parsed: a
//! value out of range is an error with a clear message (and exit status 2), never a
//! run that does not end (`--duration NaN`) or floods the link (`--ping 0`).
//!
//! ```
//! use clap::Parser as _;
//! use pprz_ground::cli::Args;
//! let args = Args::try_parse_from(["pprz-monitor", "--stdin", "--duration", "2.5"]).unwrap();
//! assert_eq!(args.duration, Some(2.5));
//! let e = Args::try_parse_from(["pprz-monitor", "--duration", "NaN"]).unwrap_err();
//! assert!(e.to_string().contains("not a finite number"));
//! ```

use std::net::SocketAddr;
use std::path::PathBuf;

use crate::settings::SettingsTable;
use clap::{Parser, ValueEnum};
use pprz_transports::{
    AnyTransport, BROADCAST_ID, GROUND_ID, PprzLog, PprzV1, PprzV2, XBee24, XBee868,
};

/// Longest `--duration`: one year, in seconds.
pub const MAX_DURATION: f64 = 366.0 * 24.0 * 3600.0;

/// Shortest `--ping` period, in seconds (20 PINGs per second).
pub const MIN_PING_PERIOD: f64 = 0.05;

/// Longest `--ping` period, in seconds (one hour).
pub const MAX_PING_PERIOD: f64 = 3600.0;

/// Highest `--baud` rate accepted.
pub const MAX_BAUD: u32 = 20_000_000;

/// Transports the monitor can decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Transport {
    /// PPRZ protocol v2 (source, destination, class, id).
    Pprz2,
    /// PPRZ protocol v1 (sender, id); messages are taken as telemetry.
    Pprz1,
    /// XBee API, 802.15.4 modules.
    Xbee,
    /// XBee API, 868 MHz modules.
    Xbee868,
    /// PPRZLOG records (SD card logs, recordings of this tool).
    Pprzlog,
}

impl Transport {
    /// The transport, with its default settings.
    pub fn any(self) -> AnyTransport {
        match self {
            Self::Pprz2 => PprzV2::new().into(),
            Self::Pprz1 => PprzV1::new(1).into(),
            Self::Xbee => XBee24::default().into(),
            Self::Xbee868 => XBee868::default().into(),
            Self::Pprzlog => PprzLog::TELEMETRY.into(),
        }
    }
}

/// One link to the aircraft, as `pprz-monitor` and `pprz-gateway` take it: where to
/// read (one of `--udp`, `--tcp`, `--serial`, `--file`, `--stdin`), where the uplink
/// goes, the framing and the messages.
#[derive(Debug, Clone, clap::Args)]
pub struct LinkArgs {
    /// The messages.xml to decode with (any Paparazzi file, e.g. the full PPRZLINK one).
    #[arg(long, default_value = "messages.xml")]
    pub messages: PathBuf,
    /// Framing of the byte stream.
    #[arg(long, value_enum, default_value = "pprz2")]
    pub transport: Transport,
    /// Listen for UDP datagrams on this address (Paparazzi's ground link uses port 4242).
    #[arg(long, value_name = "ADDR", group = "input")]
    pub udp: Option<SocketAddr>,
    /// Connect to a TCP server.
    #[arg(long, value_name = "ADDR", group = "input")]
    pub tcp: Option<SocketAddr>,
    /// Read a serial port (e.g. /dev/ttyUSB0).
    #[arg(long, value_name = "DEVICE", group = "input")]
    pub serial: Option<String>,
    /// Serial port baud rate.
    #[arg(long, default_value_t = 57_600, value_parser = parse_baud)]
    pub baud: u32,
    /// Read (replay) a file, e.g. a PPRZLOG recording with `--transport pprzlog`.
    #[arg(long, value_name = "PATH", group = "input")]
    pub file: Option<PathBuf>,
    /// Read standard input.
    #[arg(long, group = "input")]
    pub stdin: bool,
    /// Where uplink frames go with --udp (the aircraft's datalink port, e.g. 127.0.0.1:4243).
    /// With --tcp or --serial they go back on the same stream.
    #[arg(long, value_name = "ADDR")]
    pub uplink: Option<SocketAddr>,
}

impl LinkArgs {
    /// Where the link reads (standard input when no input option is given).
    pub fn endpoint(&self) -> crate::device::Endpoint {
        use crate::device::Endpoint;
        if let Some(listen) = self.udp {
            Endpoint::Udp {
                listen,
                uplink: self.uplink,
            }
        } else if let Some(addr) = self.tcp {
            Endpoint::Tcp(addr)
        } else if let Some(device) = &self.serial {
            Endpoint::Serial {
                device: device.clone(),
                baud: self.baud,
            }
        } else if let Some(path) = &self.file {
            Endpoint::File(path.clone())
        } else {
            Endpoint::Stdin
        }
    }

    /// Whether an input option was given.
    pub fn given(&self) -> bool {
        self.udp.is_some()
            || self.tcp.is_some()
            || self.serial.is_some()
            || self.file.is_some()
            || self.stdin
    }
}

/// Watch Paparazzi-compatible aircraft: decode their telemetry live with any
/// messages.xml (a section per aircraft), measure PING round trips, send SETTINGs and
/// see them acknowledged.
#[derive(Debug, Parser)]
#[command(name = "pprz-monitor", version, about)]
pub struct Args {
    /// The link to the aircraft and its messages.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Read a whole fleet from a pprz-gateway on the Zenoh bus: a client session to this
    /// endpoint (e.g. tcp/127.0.0.1:7447) receives every message the gateway delivers
    /// (`pprz/*/frame`, PPRZ v2), and PINGs and SETTINGs go as commands on
    /// `pprz/<ac_id>/uplink/<MESSAGE>`. The gateway must be up: nothing listening there is
    /// an error. Not with --secure nor another --transport than pprz2.
    #[arg(long, value_name = "ENDPOINT", group = "input", value_parser = parse_zenoh_endpoint)]
    pub zenoh: Option<String>,
    /// Aircraft id for PING/SETTING (the frames' destination and the SETTING's ac_id
    /// field); repeat it or separate ids with commas to PING and SET several aircraft
    /// (each PONG and DL_VALUE is matched to its source). With --secure, one aircraft
    /// only (1 to 254: not the ground's 0 nor broadcast 255): the only one accepted.
    #[arg(long = "ac-id", value_name = "ID", default_values_t = [7u8], value_delimiter = ',')]
    pub ac_id: Vec<u8>,
    /// Secure link: encrypted and authenticated PPRZ v2 (Paparazzi's secure transport)
    /// with the ground keys (GCS_PRIVATE, UAV_PUBLIC) of this key file. The monitor
    /// performs the key exchange with --ac-id (again every second until it completes),
    /// decrypts the telemetry, rejects and counts every frame that is not authenticated,
    /// and encrypts its PINGs and SETTINGs (sent once the session is up); --record stores
    /// the decrypted messages. Needs --transport pprz2 and a link to the aircraft.
    #[arg(long, value_name = "KEYFILE")]
    pub secure: Option<PathBuf>,
    /// Send a PING every this many seconds (0.05 to 3600) and show the round-trip time.
    #[arg(long, value_name = "SECONDS", value_parser = parse_ping_period, allow_negative_numbers = true)]
    pub ping: Option<f64>,
    /// The aircraft's settings files (Paparazzi settings.xml), in the order its settings
    /// were generated from: they name the indices. Settings are then shown by name, with
    /// their values, bounds and units, and checked against their bounds before they are
    /// sent.
    #[arg(long = "settings", value_name = "FILE", num_args = 1..)]
    pub settings_files: Vec<PathBuf>,
    /// Send a SETTING at start (repeatable) and show the DL_VALUE acknowledgement. NAME is
    /// an index, or with --settings a var or a short name; VALUE a number (in the
    /// setting's display unit, its alt_unit, with --settings) or, with --settings, one of
    /// its labels. A value outside the bounds is refused before anything is sent.
    #[arg(long = "setting", value_name = "NAME=VALUE", value_parser = parse_setting)]
    pub setting: Vec<SettingArg>,
    /// Read every setting of the --settings files from each aircraft (GET_SETTING,
    /// paced, lost requests sent again) and show the progress.
    #[arg(long)]
    pub read_settings: bool,
    /// One line per message instead of the live table (for scripts).
    #[arg(long)]
    pub lines: bool,
    /// Record every received frame to this PPRZLOG file (replay it with --file and
    /// --transport pprzlog). It must not be one of the inputs. Its time stamps count
    /// 100 µs in 32 bits, as PPRZLOG does: they wrap to 0 every 429 497 s (about 5 days)
    /// of recording, and a replay unwraps them.
    #[arg(long, value_name = "PATH")]
    pub record: Option<PathBuf>,
    /// Serve the decoded telemetry to Foxglove or Lichtblick over the Foxglove WebSocket
    /// protocol at this address (e.g. `127.0.0.1:8765`; port 0: any free port, printed).
    #[arg(long, value_name = "ADDR")]
    pub foxglove: Option<SocketAddr>,
    /// The most Foxglove clients served at once (1 to 256); further connections are
    /// refused and counted.
    #[arg(long, value_name = "N", default_value_t = crate::viewer::DEFAULT_MAX_CLIENTS, value_parser = parse_clients)]
    pub foxglove_clients: usize,
    /// Record the decoded telemetry to this MCAP file (same topics and schemas as
    /// `--foxglove`), timestamped with the reception time, or with the log's time stamps
    /// when replaying a PPRZLOG file. It must not be one of the inputs.
    #[arg(long, value_name = "PATH")]
    pub mcap: Option<PathBuf>,
    /// Mark an aircraft stale when no frame came from it for this many seconds (0.1 to
    /// 3600), as Paparazzi's link agent does after 5 s: one notice when it goes stale,
    /// one when it is heard again.
    #[arg(long, value_name = "SECONDS", default_value_t = crate::monitor::DEFAULT_STALE_AFTER, value_parser = parse_stale_after, allow_negative_numbers = true)]
    pub stale_after: f64,
    /// Stop after this many seconds (more than 0, at most a year).
    #[arg(long, value_name = "SECONDS", value_parser = parse_duration, allow_negative_numbers = true)]
    pub duration: Option<f64>,
}

impl Args {
    /// The aircraft addressed (`--ac-id`), in the order given, each once.
    pub fn aircraft(&self) -> Vec<u8> {
        let mut out: Vec<u8> = Vec::with_capacity(self.ac_id.len());
        for id in &self.ac_id {
            if !out.contains(id) {
                out.push(*id);
            }
        }
        out
    }

    /// Checks the combinations of options that clap cannot: PINGs, SETTINGs and the
    /// secure link need a link to the aircraft, and the secure link PPRZ v2 and one
    /// aircraft (not broadcast, not the ground's id 0); `--zenoh` takes PPRZ v2 only and
    /// no secure link.
    ///
    /// # Errors
    /// A message naming the problem.
    pub fn check(&self) -> Result<(), String> {
        if self.zenoh.is_some() {
            if self.secure.is_some() {
                return Err("--secure does not apply to --zenoh: the gateway holds the links to the aircraft (run the secure link on a monitor with a link of its own)".into());
            }
            if self.link.transport != Transport::Pprz2 {
                return Err(
                    "--zenoh carries PPRZ v2 frames: leave out --transport (or give pprz2)".into(),
                );
            }
        }
        let wants_uplink = self.ping.is_some() || !self.setting.is_empty() || self.read_settings;
        let has_uplink = self.zenoh.is_some()
            || self.link.tcp.is_some()
            || self.link.serial.is_some()
            || (self.link.udp.is_some() && self.link.uplink.is_some());
        if wants_uplink && !has_uplink {
            return Err(
                "--ping, --setting and --read-settings need a link to the aircraft: --tcp, --serial, --udp with --uplink, or --zenoh"
                    .into(),
            );
        }
        if self.read_settings && self.settings_files.is_empty() {
            return Err(
                "--read-settings reads the settings of the --settings files: give them".into(),
            );
        }
        if self.secure.is_some() {
            match self.aircraft().as_slice() {
                [BROADCAST_ID] => {
                    return Err(format!(
                        "--secure talks to one aircraft: --ac-id {BROADCAST_ID} is broadcast, give the aircraft's id (1 to 254)"
                    ));
                }
                [GROUND_ID] => {
                    return Err(format!(
                        "--secure talks to one aircraft: --ac-id {GROUND_ID} is the ground itself, give the aircraft's id (1 to 254)"
                    ));
                }
                [_] => {}
                _ => {
                    return Err("--secure talks to one aircraft: give a single --ac-id".into());
                }
            }
            if self.link.transport != Transport::Pprz2 {
                return Err(
                    "--secure needs --transport pprz2 (the secure link is PPRZ v2 only)".into(),
                );
            }
            if !has_uplink {
                return Err(
                    "--secure needs a link to the aircraft for the key exchange: --tcp, --serial, or --udp with --uplink"
                        .into(),
                );
            }
        }
        if self.link.uplink.is_some() && self.link.udp.is_none() {
            return Err("--uplink goes with --udp (with --tcp or --serial, uplink frames go back on the same stream)".into());
        }
        Ok(())
    }
}

/// A number of seconds: finite, more than 0, at most `max`.
fn seconds(s: &str, min: f64, min_inclusive: bool, max: f64) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if !v.is_finite() {
        return Err(format!("`{s}` is not a finite number"));
    }
    let above = if min_inclusive { v >= min } else { v > min };
    if !above || v > max {
        let lo = if min_inclusive {
            "at least"
        } else {
            "more than"
        };
        return Err(format!(
            "{v} s is out of range: {lo} {min} s, at most {max} s"
        ));
    }
    Ok(v)
}

/// `--duration`: finite, more than 0 s, at most [`MAX_DURATION`].
///
/// # Errors
/// A message for the user.
pub fn parse_duration(s: &str) -> Result<f64, String> {
    seconds(s, 0.0, false, MAX_DURATION)
}

/// `--ping`: finite, from [`MIN_PING_PERIOD`] to [`MAX_PING_PERIOD`].
///
/// # Errors
/// A message for the user.
pub fn parse_ping_period(s: &str) -> Result<f64, String> {
    seconds(s, MIN_PING_PERIOD, true, MAX_PING_PERIOD)
}

/// `--stale-after`: finite, from
/// [`MIN_STALE_AFTER`](crate::monitor::MIN_STALE_AFTER) to
/// [`MAX_STALE_AFTER`](crate::monitor::MAX_STALE_AFTER).
///
/// # Errors
/// A message for the user.
pub fn parse_stale_after(s: &str) -> Result<f64, String> {
    use crate::monitor::{MAX_STALE_AFTER, MIN_STALE_AFTER};
    seconds(s, MIN_STALE_AFTER, true, MAX_STALE_AFTER)
}

/// `--zenoh`: a TCP endpoint of Zenoh, `tcp/HOST:PORT` (the only transport built in).
///
/// # Errors
/// A message for the user.
pub fn parse_zenoh_endpoint(s: &str) -> Result<String, String> {
    let ok = s
        .strip_prefix("tcp/")
        .is_some_and(|rest| !rest.is_empty() && rest.contains(':'))
        && s.bytes().all(|b| b.is_ascii_graphic());
    if ok {
        Ok(s.to_owned())
    } else {
        Err(format!(
            "`{}` is not a Zenoh TCP endpoint (e.g. tcp/127.0.0.1:7447)",
            crate::escape::token(s)
        ))
    }
}

/// `--baud`: from 1 to [`MAX_BAUD`].
///
/// # Errors
/// A message for the user.
pub fn parse_baud(s: &str) -> Result<u32, String> {
    let v: u32 = s
        .trim()
        .parse()
        .map_err(|e| format!("`{s}` is not a baud rate: {e}"))?;
    if v == 0 || v > MAX_BAUD {
        return Err(format!("{v} is out of range: 1 to {MAX_BAUD}"));
    }
    Ok(v)
}

/// `--foxglove-clients`: from 1 to [`MAX_MAX_CLIENTS`](crate::viewer::MAX_MAX_CLIENTS).
///
/// # Errors
/// A message for the user.
pub fn parse_clients(s: &str) -> Result<usize, String> {
    let max = crate::viewer::MAX_MAX_CLIENTS;
    let v: usize = s
        .trim()
        .parse()
        .map_err(|e| format!("`{s}` is not a number of clients: {e}"))?;
    if v == 0 || v > max {
        return Err(format!("{v} is out of range: 1 to {max}"));
    }
    Ok(v)
}

/// One `--setting NAME=VALUE`, as written: resolved with the settings files
/// ([`SettingArg::resolve`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SettingArg {
    /// An index, a var or a short name.
    pub name: String,
    /// A number or a label.
    pub value: String,
}

/// A `--setting` resolved: the index and the value to send, in the aircraft's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettingValue {
    /// The setting's index.
    pub index: u8,
    /// The value, checked against the setting's bounds when the settings files are
    /// known.
    pub value: f32,
}

impl SettingArg {
    /// The index and value to send. With `table`, NAME is an index, a var or a short
    /// name, and VALUE a label or a number in the display unit, checked against the
    /// bounds; without, NAME must be an index and VALUE a number.
    ///
    /// # Errors
    /// A message for the user naming the option.
    pub fn resolve(&self, table: Option<&SettingsTable>) -> Result<SettingValue, String> {
        let fail = |e: &dyn std::fmt::Display| {
            format!(
                "--setting {}={}: {e}",
                crate::settings::text(&self.name),
                crate::settings::text(&self.value)
            )
        };
        let Some(table) = table else {
            let index = self
                .name
                .parse::<u8>()
                .map_err(|_| fail(&"a name needs the settings files (--settings FILE)"))?;
            let value = number(&self.value)
                .ok_or_else(|| fail(&"a label needs the settings files (--settings FILE)"))?
                .map_err(|e| fail(&e))?;
            return Ok(SettingValue { index, value });
        };
        let index = table.resolve(&self.name).map_err(|e| fail(&e))?;
        let value = table.value(index, &self.value).map_err(|e| fail(&e))?;
        Ok(SettingValue { index, value })
    }
}

/// `text` as a SETTING value, if it is a number: a finite number that fits a `float`
/// ([`setting_value`](crate::settings::setting_value)), or why not.
fn number(text: &str) -> Option<Result<f32, String>> {
    let v = text.parse::<f64>().ok()?;
    Some(crate::settings::setting_value(v).map_err(|e| e.to_string()))
}

/// `--setting NAME=VALUE`: a name (an index 0..=255, or a var or short name resolved
/// later with the settings files) and a value: a number that fits a `float`
/// ([`setting_value`](crate::settings::setting_value), the rule the viewer's settings
/// follow too), or a label, resolved later.
///
/// # Errors
/// A message for the user.
pub fn parse_setting(s: &str) -> Result<SettingArg, String> {
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=VALUE or INDEX=VALUE, got `{s}`"))?;
    let (name, value) = (name.trim(), value.trim());
    if name.is_empty() {
        return Err(format!("`{s}` has no name or index before `=`"));
    }
    if value.is_empty() {
        return Err(format!("`{s}` has no value after `=`"));
    }
    if name.bytes().all(|b| b.is_ascii_digit()) {
        name.parse::<u8>()
            .map_err(|e| format!("index `{name}`: {e} (0 to 255)"))?;
    }
    if let Some(Err(e)) = number(value) {
        return Err(format!("value `{value}`: {e}"));
    }
    Ok(SettingArg {
        name: name.to_owned(),
        value: value.to_owned(),
    })
}

/// A flag that Ctrl-C sets, for the tools' main loops (which end when it is set); a
/// warning on standard error if the handler cannot be installed.
pub fn stop_on_ctrl_c() -> std::sync::Arc<std::sync::atomic::AtomicBool> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)) {
        eprintln!("warning: Ctrl-C handler not installed: {e}");
    }
    stop
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str]) -> Result<Args, String> {
        Args::try_parse_from(std::iter::once("pprz-monitor").chain(args.iter().copied()))
            .map_err(|e| e.to_string())
    }

    /// Issue: `--duration NaN` never ended, `--ping 0` sent PINGs continuously.
    #[test]
    fn invalid_numbers_are_refused() {
        for bad in ["NaN", "nan", "inf", "-inf", "0", "-1", "1e300", "x", ""] {
            let e = parse(&["--stdin", &format!("--duration={bad}")]).unwrap_err();
            assert!(e.contains("--duration"), "{bad}: {e}");
        }
        for bad in ["0", "0.0", "NaN", "inf", "-0.2", "0.001", "1e9", "abc"] {
            let e = parse(&["--tcp", "127.0.0.1:1", &format!("--ping={bad}")]).unwrap_err();
            assert!(e.contains("--ping"), "{bad}: {e}");
        }
        for bad in ["0", "99999999999", "-5"] {
            assert!(parse(&[&format!("--baud={bad}")]).is_err(), "{bad}");
        }
        for bad in ["0", "257", "-1", "x", ""] {
            let e = parse(&[&format!("--foxglove-clients={bad}")]).unwrap_err();
            assert!(e.contains("--foxglove-clients"), "{bad}: {e}");
        }
        for bad in [
            "1=NaN", "1=inf", "1=1e39", "1=1e300", "1=-1e39", "256=1", "1", "=1", "1=", "gain=NaN",
        ] {
            let e = parse(&["--tcp", "127.0.0.1:1", &format!("--setting={bad}")]).unwrap_err();
            assert!(e.contains("--setting"), "{bad}: {e}");
        }
        for bad in [
            "0", "-5", "0.01", "NaN", "nan", "inf", "-inf", "1e9", "x", "", "5s",
        ] {
            let e = parse(&["--stdin", &format!("--stale-after={bad}")]).unwrap_err();
            assert!(e.contains("--stale-after"), "{bad}: {e}");
        }
        let e = parse(&["--stale-after", "-1"]).unwrap_err();
        assert!(e.contains("at least 0.1 s"), "{e}");
        let e = parse(&["--stale-after", "inf"]).unwrap_err();
        assert!(e.contains("not a finite number"), "{e}");
        let e = parse(&["--stale-after", "soon"]).unwrap_err();
        assert!(e.contains("not a number of seconds"), "{e}");
        let e = parse(&["--duration", "-1"]).unwrap_err();
        assert!(e.contains("more than 0 s"), "{e}");
        let e = parse(&["--duration", "NaN"]).unwrap_err();
        assert!(e.contains("not a finite number"), "{e}");
        let e = parse(&["--tcp", "127.0.0.1:1", "--ping", "0"]).unwrap_err();
        assert!(e.contains("at least 0.05 s"), "{e}");
    }

    #[test]
    fn valid_values_are_kept() {
        let a = parse(&[
            "--tcp",
            "127.0.0.1:1",
            "--ping",
            "0.2",
            "--duration",
            "10",
            "--setting",
            "3 = 1.5",
            "--baud",
            "115200",
        ])
        .unwrap();
        assert_eq!(
            (a.ping, a.duration, a.link.baud),
            (Some(0.2), Some(10.0), 115_200)
        );
        let resolved: Vec<_> = a.setting.iter().map(|s| s.resolve(None)).collect();
        assert_eq!(
            resolved,
            [Ok(SettingValue {
                index: 3,
                value: 1.5
            })]
        );
        assert_eq!(a.check(), Ok(()));
        assert_eq!(parse(&["--ping", "3600"]).unwrap().ping, Some(3600.0));
        assert_eq!(a.foxglove_clients, crate::viewer::DEFAULT_MAX_CLIENTS);
        assert_eq!(a.stale_after, 5.0);
        assert_eq!(parse(&["--stale-after", "12.5"]).unwrap().stale_after, 12.5);
        assert_eq!(parse(&["--stale-after", "0.1"]).unwrap().stale_after, 0.1);
        let n = parse(&["--foxglove-clients", "256"]).unwrap();
        assert_eq!(n.foxglove_clients, 256);
    }

    #[test]
    fn secure_needs_pprz2_and_an_uplink() {
        let base = ["--udp", "127.0.0.1:4242", "--uplink", "127.0.0.1:4243"];
        let with = |extra: &[&str]| {
            let mut v = base.to_vec();
            v.extend_from_slice(extra);
            parse(&v).unwrap().check()
        };
        assert_eq!(with(&["--secure", "k.keys"]), Ok(()));
        assert_eq!(
            parse(&["--tcp", "127.0.0.1:1", "--secure", "k.keys", "--ac-id", "9"])
                .unwrap()
                .check(),
            Ok(())
        );
        for t in ["pprz1", "xbee", "xbee868", "pprzlog"] {
            let e = with(&["--secure", "k.keys", "--transport", t]).unwrap_err();
            assert!(e.contains("--secure needs --transport pprz2"), "{e}");
        }
        for args in [
            &["--udp", "127.0.0.1:4242", "--secure", "k"][..],
            &["--file", "x", "--secure", "k"],
            &["--stdin", "--secure", "k"],
        ] {
            let e = parse(args).unwrap().check().unwrap_err();
            assert!(e.contains("--secure needs a link"), "{e}");
        }
    }

    #[test]
    fn pings_and_settings_need_an_uplink() {
        for args in [
            &["--file", "x", "--ping", "1"][..],
            &["--stdin", "--setting", "1=2"],
            &["--udp", "127.0.0.1:4242", "--ping", "1"],
        ] {
            let e = parse(args).unwrap().check().unwrap_err();
            assert!(e.contains("need a link"), "{e}");
        }
        let ok = parse(&[
            "--udp",
            "127.0.0.1:4242",
            "--uplink",
            "127.0.0.1:4243",
            "--ping",
            "1",
        ])
        .unwrap();
        assert_eq!(ok.check(), Ok(()));
        assert!(
            parse(&["--tcp", "127.0.0.1:1", "--uplink", "127.0.0.1:2"])
                .unwrap()
                .check()
                .is_err()
        );
    }

    #[test]
    fn zenoh_is_an_input_with_an_uplink_in_pprz2_without_secure() {
        let zenoh = ["--zenoh", "tcp/127.0.0.1:7447"];
        let with = |extra: &[&str]| {
            let mut v = zenoh.to_vec();
            v.extend_from_slice(extra);
            parse(&v)
        };
        let a = with(&["--ping", "1", "--setting", "2=1", "--transport", "pprz2"]).unwrap();
        assert_eq!(a.zenoh.as_deref(), Some("tcp/127.0.0.1:7447"));
        assert_eq!(a.check(), Ok(()));
        let e = with(&["--secure", "k"]).unwrap().check().unwrap_err();
        assert!(e.contains("--secure does not apply to --zenoh"), "{e}");
        for t in ["pprz1", "xbee", "xbee868", "pprzlog"] {
            let e = with(&["--transport", t]).unwrap().check().unwrap_err();
            assert!(e.contains("--zenoh carries PPRZ v2"), "{t}: {e}");
        }
        for other in [
            &["--udp", "127.0.0.1:1"][..],
            &["--tcp", "127.0.0.1:1"],
            &["--file", "x"],
            &["--stdin"],
        ] {
            let e = with(other).unwrap_err();
            assert!(e.contains("cannot be used with"), "{other:?}: {e}");
        }
        for bad in [
            "127.0.0.1:7447",
            "udp/127.0.0.1:7447",
            "tcp/",
            "tcp/host",
            "tcp/127.0.0.1:1 x",
            "tcp/\u{1b}[2J:1",
        ] {
            let e = parse(&["--zenoh", bad]).unwrap_err();
            assert!(e.contains("not a Zenoh TCP endpoint"), "{bad}: {e}");
            assert!(!e.contains('\u{1b}'), "{e}");
        }
    }

    #[test]
    fn one_or_several_aircraft() {
        let link = ["--tcp", "127.0.0.1:1"];
        let with = |extra: &[&str]| {
            let mut v = link.to_vec();
            v.extend_from_slice(extra);
            parse(&v).unwrap()
        };
        assert_eq!(with(&[]).aircraft(), [7]);
        assert_eq!(with(&["--ac-id", "8"]).aircraft(), [8]);
        assert_eq!(
            with(&["--ac-id", "8", "--ac-id", "3,8", "--ac-id=200"]).aircraft(),
            [8, 3, 200]
        );
        for bad in ["256", "-1", "x", ""] {
            let arg = format!("--ac-id={bad}");
            let mut v = link.to_vec();
            v.push(&arg);
            let e = parse(&v).unwrap_err();
            assert!(e.contains("--ac-id"), "{bad}: {e}");
        }
        assert_eq!(with(&["--secure", "k", "--ac-id", "9,9"]).check(), Ok(()));
        let e = with(&["--secure", "k", "--ac-id", "7,8"])
            .check()
            .unwrap_err();
        assert!(e.contains("one aircraft"), "{e}");
        // Broadcast and the ground's own id are no aircraft to make a key exchange with.
        for (id, what) in [("255", "broadcast"), ("0", "the ground")] {
            let e = with(&["--secure", "k", "--ac-id", id]).check().unwrap_err();
            assert!(e.contains(&format!("--ac-id {id} is {what}")), "{e}");
        }
        assert_eq!(with(&["--secure", "k", "--ac-id", "254"]).check(), Ok(()));
        assert_eq!(with(&["--secure", "k", "--ac-id", "1"]).check(), Ok(()));
    }

    const FILE: &str = r#"<settings><dl_settings>
      <dl_setting var="telemetry_mode" min="0" max="2" values="default|debug|minimal"/>
      <dl_setting var="payload_flood" min="0" max="1" values="OFF|ON"/>
      <dl_setting var="gain" min="0" max="10"/>
      <dl_setting var="ap_mode" min="0" max="13" values="KILL|FAILSAFE|HOME|RATE_DIRECT|ATTITUDE_DIRECT|RATE_RC_CLIMB|ATTITUDE_RC_CLIMB|ATTITUDE_CLIMB|RATE_Z_HOLD|ATTITUDE_Z_HOLD|HOVER_DIRECT|HOVER_CLIMB|HOVER_Z_HOLD|NAV"/>
      <dl_setting var="guidance_h_kp" shortname="kp" min="0" max="400"/>
      <dl_setting var="guidance_v_kp" shortname="kp" min="0" max="600"/>
      <dl_setting var="ins.roll_neutral" shortname="roll" min="-15" max="15" unit="rad" alt_unit="deg"/>
    </dl_settings></settings>"#;

    fn resolve(setting: &str, table: Option<&SettingsTable>) -> Result<SettingValue, String> {
        parse(&["--tcp", "127.0.0.1:1", "--setting", setting])
            .unwrap()
            .setting[0]
            .resolve(table)
    }

    #[test]
    fn settings_by_name_label_and_display_unit() {
        let a = parse(&[
            "--tcp",
            "127.0.0.1:1",
            "--settings",
            "a.xml",
            "b.xml",
            "--settings=c.xml",
            "--read-settings",
        ])
        .unwrap();
        let files: Vec<_> = a
            .settings_files
            .iter()
            .map(|p| p.to_str().unwrap())
            .collect();
        assert_eq!(files, ["a.xml", "b.xml", "c.xml"], "in order");
        assert!(a.read_settings);
        assert_eq!(a.check(), Ok(()));
        let t = SettingsTable::parse(&[("s.xml", FILE)]).unwrap();
        let ok = |s: &str| resolve(s, Some(&t)).unwrap();
        assert_eq!(
            ok("gain=2.5"),
            SettingValue {
                index: 2,
                value: 2.5
            }
        );
        assert_eq!(
            ok("ap_mode=HOME"),
            SettingValue {
                index: 3,
                value: 2.0
            }
        );
        assert_eq!(
            ok("ap_mode=NAV"),
            SettingValue {
                index: 3,
                value: 13.0
            }
        );
        assert_eq!(
            ok("1=ON"),
            SettingValue {
                index: 1,
                value: 1.0
            }
        );
        assert_eq!(
            ok("telemetry_mode=1"),
            SettingValue {
                index: 0,
                value: 1.0
            }
        );
        let roll = ok("roll=10");
        assert_eq!(roll.index, 6);
        assert_eq!(
            roll.value,
            (10.0f64 / (180.0 / std::f64::consts::PI)) as f32
        );
        assert_eq!(ok("ins.roll_neutral=-15").index, 6);
    }

    #[test]
    fn settings_refused_before_anything_is_sent() {
        let t = SettingsTable::parse(&[("s.xml", FILE)]).unwrap();
        let refused = |s: &str| resolve(s, Some(&t)).unwrap_err();
        assert_eq!(
            refused("gain=12"),
            "--setting gain=12: setting gain (index 2): 12 is outside its bounds [0, 10]"
        );
        assert_eq!(
            refused("2=-1"),
            "--setting 2=-1: setting gain (index 2): -1 is outside its bounds [0, 10]",
            "the index form is bound-checked too"
        );
        assert_eq!(
            refused("roll=16"),
            "--setting roll=16: setting roll (index 6): 16 deg is outside its bounds [-15, 15] deg"
        );
        let e = refused("kp=1");
        assert!(
            e.contains("`kp` is ambiguous: guidance_h_kp (index 4), guidance_v_kp (index 5)"),
            "{e}"
        );
        let e = refused("ap_mode=WARP");
        assert!(
            e.contains("`WARP` is neither a number nor a label (KILL|"),
            "{e}"
        );
        assert!(e.ends_with("(bounds [0, 13])"), "{e}");
        assert!(refused("nope=1").contains("no setting is named `nope`"));
        assert!(
            refused("7=1").contains("no setting has index 7: the settings files have 7 (0 to 6)")
        );
        let e = parse(&["--tcp", "127.0.0.1:1", "--setting", "gain=inf"]).unwrap_err();
        assert!(e.contains("not a finite number"), "caught when parsed: {e}");
        // Without the files: indices and numbers only.
        assert!(
            resolve("gain=1", None)
                .unwrap_err()
                .contains("a name needs the settings files")
        );
        assert!(
            resolve("3=HOME", None)
                .unwrap_err()
                .contains("a label needs the settings files")
        );
        assert_eq!(
            resolve("3=13", None),
            Ok(SettingValue {
                index: 3,
                value: 13.0
            })
        );
        // Reading the settings needs the files and a link.
        let e = parse(&["--tcp", "127.0.0.1:1", "--read-settings"])
            .unwrap()
            .check()
            .unwrap_err();
        assert!(
            e.contains("--read-settings reads the settings of the --settings files"),
            "{e}"
        );
        let e = parse(&["--stdin", "--settings", "a.xml", "--read-settings"])
            .unwrap()
            .check()
            .unwrap_err();
        assert!(e.contains("need a link"), "{e}");
    }
}
