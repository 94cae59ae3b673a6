//! The command line of `pprz-gateway`, every value checked when it is parsed.
//!
//! ```
//! use clap::Parser as _;
//! use pprz_ground::gateway::options::GatewayArgs;
//! let a = GatewayArgs::try_parse_from(["pprz-gateway", "--udp", "127.0.0.1:4242"]).unwrap();
//! assert_eq!(a.links().unwrap().len(), 1);
//! let a = GatewayArgs::try_parse_from([
//!     "pprz-gateway", "--link", "a=udp:127.0.0.1:4242", "--link", "b=udp:127.0.0.1:4244",
//! ]).unwrap();
//! assert_eq!(a.links().unwrap().len(), 2);
//! assert!(GatewayArgs::try_parse_from(["pprz-gateway", "--dedup-window", "0"]).is_err());
//! ```

use std::path::PathBuf;

use clap::{Parser, ValueEnum};

use super::dedup::MAX_LINKS;
use super::route::Policy;
use crate::bus::{BusConfig, DEFAULT_LISTEN};
use crate::cli::{LinkArgs, parse_duration, parse_stale_after};
use crate::device::LinkSpec;

/// Longest merging window, in seconds.
pub const MAX_WINDOW: f64 = 60.0;

/// Highest `--uplink-rate`.
pub const MAX_UPLINK_RATE: f64 = 1000.0;

/// `--uplink-policy`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PolicyArg {
    /// The link that most recently brought the aircraft's messages first.
    Best,
    /// Every link that heard the aircraft.
    All,
}

impl From<PolicyArg> for Policy {
    fn from(p: PolicyArg) -> Self {
        match p {
            PolicyArg::Best => Policy::Best,
            PolicyArg::All => Policy::All,
        }
    }
}

/// Serve a fleet on a Zenoh bus: read several links to the aircraft at once, merge
/// redundant links (each message delivered once), publish every message on
/// `pprz/<ac_id>/<class>/<MESSAGE>` as JSON, and send the commands put on
/// `pprz/<ac_id>/uplink/<MESSAGE>` on the link each aircraft was last heard on.
#[derive(Debug, Parser)]
#[command(name = "pprz-gateway", version, about)]
pub struct GatewayArgs {
    /// One link, with pprz-monitor's options.
    #[command(flatten)]
    pub link: LinkArgs,
    /// A link NAME=KIND:TARGET[,OPTION=VALUE]... (repeatable, at most 16): KIND:TARGET
    /// is udp:ADDR, tcp:ADDR, serial:DEVICE, file:PATH or stdin:; the options
    /// uplink=ADDR (UDP), baud=N (serial) and transport=T (as --transport; default
    /// pprz2). Example: radio-a=udp:127.0.0.1:4242,uplink=127.0.0.1:4243. Not with the
    /// one-link options.
    #[arg(long = "link", value_name = "NAME=KIND:TARGET")]
    pub links: Vec<LinkSpec>,
    /// Seconds within which a message heard again on another link is a copy (0.001 to
    /// 60): longer than the largest delay between the links, shorter than the period
    /// at which an aircraft repeats a message unchanged.
    #[arg(long, value_name = "SECONDS", default_value_t = super::dedup::DEFAULT_WINDOW, value_parser = parse_window, allow_negative_numbers = true)]
    pub dedup_window: f64,
    /// Which links a command takes.
    #[arg(long, value_enum, default_value = "best")]
    pub uplink_policy: PolicyArg,
    /// Commands per second each aircraft takes at most (0.1 to 1000); further ones
    /// are refused and counted.
    #[arg(long, value_name = "N", default_value_t = super::serve::DEFAULT_UPLINK_RATE, value_parser = parse_rate, allow_negative_numbers = true)]
    pub uplink_rate: f64,
    /// An aircraft not heard for this many seconds is stale, and its links no longer
    /// carry its commands (0.1 to 3600).
    #[arg(long, value_name = "SECONDS", default_value_t = crate::monitor::DEFAULT_STALE_AFTER, value_parser = parse_stale_after, allow_negative_numbers = true)]
    pub stale_after: f64,
    /// The aircraft's settings files (Paparazzi settings.xml), in order: settings
    /// queries on `pprz/<ac_id>/settings/<name>` then take names, labels and bounds.
    #[arg(long = "settings", value_name = "FILE", num_args = 1..)]
    pub settings_files: Vec<PathBuf>,
    /// The gateway's name in the bus keys (`pprz/gateway/<name>/...`).
    #[arg(long, default_value = "gw", value_parser = parse_name)]
    pub name: String,
    /// Zenoh endpoint to listen on (repeatable; default tcp/127.0.0.1:7447).
    #[arg(long, value_name = "ENDPOINT", value_parser = crate::cli::parse_zenoh_endpoint)]
    pub zenoh_listen: Vec<String>,
    /// Zenoh endpoint to connect to: a zenohd router or another peer (repeatable).
    #[arg(long, value_name = "ENDPOINT", value_parser = crate::cli::parse_zenoh_endpoint)]
    pub zenoh_connect: Vec<String>,
    /// Find other Zenoh peers by multicast scouting on the local network (off by
    /// default: only the endpoints given are used, nothing leaves the machine
    /// otherwise).
    #[arg(long)]
    pub zenoh_multicast: bool,
    /// Write the counters as JSON to this file at the end.
    #[arg(long, value_name = "PATH")]
    pub summary_json: Option<PathBuf>,
    /// Stop after this many seconds.
    #[arg(long, value_name = "SECONDS", value_parser = parse_duration, allow_negative_numbers = true)]
    pub duration: Option<f64>,
}

impl GatewayArgs {
    /// The links: the `--link`s, or the one link of the one-link options.
    ///
    /// # Errors
    /// Both kinds given, too many links, or two links of one name.
    pub fn links(&self) -> Result<Vec<LinkSpec>, String> {
        if self.links.is_empty() {
            return Ok(vec![LinkSpec {
                name: "link".into(),
                endpoint: self.link.endpoint(),
                transport: self.link.transport,
            }]);
        }
        if self.link.given() || self.link.uplink.is_some() {
            return Err("give either --link options or one link (--udp, --tcp, --serial, --file, --stdin), not both".into());
        }
        if self.links.len() > MAX_LINKS {
            return Err(format!("{} links: at most {MAX_LINKS}", self.links.len()));
        }
        for (i, l) in self.links.iter().enumerate() {
            if self.links[..i].iter().any(|o| o.name == l.name) {
                return Err(format!("two links are named {}", l.name));
            }
        }
        let stdin = self
            .links
            .iter()
            .filter(|l| l.endpoint == crate::device::Endpoint::Stdin)
            .count();
        if stdin > 1 {
            return Err("one link at most reads standard input".into());
        }
        Ok(self.links.clone())
    }

    /// The bus configuration.
    pub fn bus(&self) -> BusConfig {
        let listen = if self.zenoh_listen.is_empty() {
            vec![DEFAULT_LISTEN.to_owned()]
        } else {
            self.zenoh_listen.clone()
        };
        BusConfig {
            peer: true,
            listen,
            connect: self.zenoh_connect.clone(),
            multicast: self.zenoh_multicast,
        }
    }
}

fn number(s: &str, what: &str, lo: f64, hi: f64) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{}` is not a number", crate::escape::token(s)))?;
    if !v.is_finite() || v < lo || v > hi {
        return Err(format!("{what} {v} is out of range: {lo} to {hi}"));
    }
    Ok(v)
}

/// `--dedup-window`: 0.001 to [`MAX_WINDOW`] seconds.
fn parse_window(s: &str) -> Result<f64, String> {
    number(s, "window", 0.001, MAX_WINDOW)
}

/// `--uplink-rate`: 0.1 to [`MAX_UPLINK_RATE`].
fn parse_rate(s: &str) -> Result<f64, String> {
    number(s, "rate", 0.1, MAX_UPLINK_RATE)
}

/// `--name`: 1 to 32 letters, digits, `-` or `_`.
fn parse_name(s: &str) -> Result<String, String> {
    crate::device::check_name("gateway name", s).map(|()| s.to_owned())
}
