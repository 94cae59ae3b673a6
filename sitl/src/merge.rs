//! How the in-process ground takes its radios in: one byte stream into one monitor (one
//! plain radio, as Paparazzi's link agent), or each radio's link into the gateway
//! (`pprz_ground::gateway`), which merges them and feeds its fleet monitor (`--radios
//! 2`, `--frame-loss`), on a Zenoh bus with `--zenoh` (the gateway service). Uplink
//! frames follow the gateway's routes: the link that last brought the aircraft's
//! messages first.

use std::collections::BTreeMap;
use std::net::{SocketAddr, UdpSocket};

use pprz_ground::bus::{Bus, BusConfig};
use pprz_ground::device::Uplink;
use pprz_ground::gateway::serve::Service;
use pprz_ground::gateway::{Arrival, Gateway, GatewayLink};
use pprz_ground::monitor::{Decoded, Monitor};
use pprz_ground::settings::SettingsTable;
use pprz_ground::uplink;
use pprz_telemetry::pprz_transports::{AnyTransport, PprzV2};
use serde::Serialize;
use serde_json::Value;

use crate::options::Args;

/// The names of the gateway's links: radio A's, radio B's.
pub const LINK_NAMES: [&str; 2] = ["radio-a", "radio-b"];

/// Requests from the bus handled per turn of the ground's loop at most.
const REQUESTS_PER_TURN: usize = 64;

/// The name of the gateway on the bus (`pprz/gateway/sitl/...`).
const BUS_NAME: &str = "sitl";

/// What takes the radios in.
enum Kind {
    /// One byte stream, one monitor.
    Single(Box<Monitor>),
    /// The gateway over the radios' links.
    Gateway(Box<Gateway>),
    /// The gateway service on the bus.
    Served(Box<Service>),
}

/// The ground's intake (module doc), with what it delivered per aircraft.
pub struct Merge {
    kind: Kind,
    /// Messages delivered per aircraft (source id).
    delivered: BTreeMap<u8, u64>,
    /// Per aircraft, the messages that had reached the radios' ground ends (before
    /// the frame loss) when the ground stopped ([`Merge::stop`]).
    aired: Option<Box<[u64; 256]>>,
}

impl Merge {
    /// One byte stream into `monitor`.
    pub fn single(monitor: Monitor) -> Self {
        Self {
            kind: Kind::Single(Box::new(monitor)),
            delivered: BTreeMap::new(),
            aired: None,
        }
    }

    /// The gateway over `args.radios` links, `fleet` its fleet monitor; with
    /// `--zenoh`, served on the bus, its commands sent from `sockets[link]` to the
    /// link's uplink address. Fails with the message to print.
    pub fn gateway(
        args: &Args,
        fleet: Monitor,
        table: Option<&std::sync::Arc<SettingsTable>>,
        sockets: &[UdpSocket],
    ) -> Result<Self, String> {
        let set = *fleet.set();
        let links = LINK_NAMES[..usize::from(args.radios)]
            .iter()
            .map(|name| GatewayLink::new(name, set, PprzV2::new().into(), true))
            .collect();
        let gateway = Gateway::new(set, links).with_fleet_monitor(fleet);
        let kind = match &args.zenoh {
            None => Kind::Gateway(Box::new(gateway)),
            Some(endpoint) => {
                let config = BusConfig {
                    peer: true,
                    listen: vec![endpoint.clone()],
                    connect: Vec::new(),
                    multicast: false,
                };
                let bus = Bus::open(&config)?.serving()?.serving_schemas(set)?;
                let mut uplinks = Vec::with_capacity(sockets.len());
                for (socket, to) in sockets.iter().zip(uplink_addresses(args)) {
                    let socket = socket.try_clone().map_err(|e| e.to_string())?;
                    uplinks.push(Uplink::Udp(socket, to));
                }
                let mut service = Service::new(BUS_NAME, gateway, uplinks, bus);
                if let Some(t) = table {
                    service = service.with_settings(t.clone());
                }
                eprintln!("zenoh: listening on {endpoint}");
                Kind::Served(Box::new(service))
            }
        };
        Ok(Self {
            kind,
            delivered: BTreeMap::new(),
            aired: None,
        })
    }

    /// The monitor of what the ground received: the single one, or the gateway's fleet
    /// monitor.
    pub fn monitor(&self) -> &Monitor {
        match &self.kind {
            Kind::Single(m) => m,
            Kind::Gateway(g) => g.fleet(),
            Kind::Served(s) => s.gateway().fleet(),
        }
    }

    /// The same, to note the requests sent.
    pub fn monitor_mut(&mut self) -> &mut Monitor {
        match &mut self.kind {
            Kind::Single(m) => m,
            Kind::Gateway(g) => g.fleet_mut(),
            Kind::Served(s) => s.gateway_mut().fleet_mut(),
        }
    }

    /// The gateway, if the radios are merged.
    pub fn gateway_of(&self) -> Option<&Gateway> {
        match &self.kind {
            Kind::Single(_) => None,
            Kind::Gateway(g) => Some(g),
            Kind::Served(s) => Some(s.gateway()),
        }
    }

    /// The gateway service's counters as JSON, with `--zenoh`.
    pub fn bus_stats(&self) -> Option<Value> {
        match &self.kind {
            Kind::Served(s) => Some(s.stats_json()),
            _ => None,
        }
    }

    /// The ground stopped taking the links in: what had reached the radios' ground ends
    /// by then is noted (the aircraft run on while the summary is made).
    pub fn stop(&mut self) {
        self.aired = Some(Box::new(crate::bridge::arrivals().aired_by));
    }

    /// Messages from aircraft `ac` that had reached a radio's ground end (before the
    /// frame loss, each once) when the ground stopped, or by now.
    pub fn aired(&self, ac: u8) -> u64 {
        match &self.aired {
            Some(a) => a[usize::from(ac)],
            None => crate::bridge::arrivals().aired_by[usize::from(ac)],
        }
    }

    /// Messages delivered so far from aircraft `ac`.
    pub fn delivered(&self, ac: u8) -> u64 {
        self.delivered.get(&ac).copied().unwrap_or(0)
    }

    /// Bytes that came on link `link` at `now`; `on_message` gets each message
    /// delivered (once, however many radios brought it).
    pub fn feed(
        &mut self,
        link: usize,
        now: f64,
        bytes: &[u8],
        mut on_message: impl FnMut(&Decoded<'_>),
    ) {
        let delivered = &mut self.delivered;
        let mut count = |m: &Decoded<'_>| {
            *delivered.entry(m.source).or_insert(0) += 1;
            on_message(m);
        };
        match &mut self.kind {
            Kind::Single(m) => m.feed(now, bytes, count),
            Kind::Gateway(g) => g.feed(link, now, bytes, |d| count(d.message)),
            Kind::Served(s) => s.arrive(link, now, Arrival::Bytes(bytes), |d| count(d.message)),
        }
    }

    /// The clock moved to `now`: stale aircraft, expired requests and merging windows;
    /// with the bus, its requests, and its figures when `publish` (once a second).
    pub fn tick(&mut self, now: f64, publish: bool) {
        match &mut self.kind {
            Kind::Single(m) => m.tick(now),
            Kind::Gateway(g) => g.tick(now),
            Kind::Served(s) => {
                s.serve_requests(now, REQUESTS_PER_TURN);
                if publish {
                    s.tick(now);
                } else {
                    s.gateway_mut().tick(now);
                }
            }
        }
    }

    /// The frames of the uplink message `name` with `values` for aircraft `ac` at `now`:
    /// `(link, frame)`, one per link the route takes (sealed on a secure link).
    pub fn frames(
        &mut self,
        now: f64,
        transport: AnyTransport,
        ac: u8,
        name: &str,
        values: &[(&str, f64)],
    ) -> Vec<(usize, Vec<u8>)> {
        let gateway = match &mut self.kind {
            Kind::Single(m) => {
                let Ok(frame) = uplink::frame(m.set(), transport, ac, name, values) else {
                    return Vec::new();
                };
                return m
                    .seal_uplink(&frame)
                    .map(|f| vec![(0, f)])
                    .unwrap_or_default();
            }
            Kind::Gateway(g) => &mut **g,
            Kind::Served(s) => s.gateway_mut(),
        };
        let set = *gateway.fleet().set();
        let Some(desc) = set.find_by_name("datalink", name) else {
            return Vec::new();
        };
        let mut values = values.to_vec();
        if !values.iter().any(|(n, _)| *n == "ac_id") {
            values.push(("ac_id", f64::from(ac)));
        }
        let Ok(payload) = uplink::encode_scalars(desc, &values) else {
            return Vec::new();
        };
        gateway.uplink(now, ac, desc, &payload).unwrap_or_default()
    }
}

/// Where each link's uplink frames go: radio A's bridge, radio B's.
pub fn uplink_addresses(args: &Args) -> Vec<SocketAddr> {
    [args.uplink, args.uplink_b][..usize::from(args.radios)].to_vec()
}

/// Where the ground listens on each link: radio A's telemetry, radio B's.
pub fn ground_addresses(args: &Args) -> Vec<SocketAddr> {
    [args.ground, args.ground_b][..usize::from(args.radios)].to_vec()
}

/// The gateway's figures in the summary (`--radios 2`, `--frame-loss`, `--zenoh`).
#[derive(Debug, Clone, Serialize)]
pub struct GatewayFigures {
    /// `--radios`.
    pub radios: u8,
    /// `--frame-loss`.
    pub frame_loss: f64,
    /// Frames the loss dropped, aircraft to ground, every radio together.
    pub lost_frames_down: u64,
    /// Frames the loss dropped, ground to aircraft.
    pub lost_frames_up: u64,
    /// The merging window, seconds.
    pub dedup_window_s: f64,
    /// Per link, in link order.
    pub links: Vec<LinkFigures>,
    /// Per aircraft, 7 first.
    pub aircraft: Vec<AircraftDelivery>,
    /// `--zenoh`: the gateway service's counters (as on `pprz/gateway/sitl/stats`).
    pub bus: Option<Value>,
}

/// One link of the gateway.
#[derive(Debug, Clone, Serialize)]
pub struct LinkFigures {
    /// Its name.
    pub link: String,
    /// Frames decoded on it.
    pub frames: u64,
    /// Frames that failed their checksum.
    pub checksum_errors: u64,
    /// Messages it delivered first.
    pub first: u64,
    /// Copies of messages another link delivered first (dropped).
    pub duplicates: u64,
    /// Messages only it delivered.
    pub alone: u64,
    /// Messages another link delivered and it did not.
    pub missed: u64,
}

/// What one aircraft sent and what the gateway delivered of it.
#[derive(Debug, Clone, Serialize)]
pub struct AircraftDelivery {
    /// Its id.
    pub ac_id: u8,
    /// Frames each of its radio devices to the ground sent, radio A first.
    pub sent: Vec<u32>,
    /// Messages that reached a radio's ground end before the frame loss, each once
    /// however many radios carried it.
    pub aired: u64,
    /// Messages the gateway delivered from it (each once).
    pub delivered: u64,
    /// Messages of it the fleet monitor decoded.
    pub fleet_frames: u64,
}

impl GatewayFigures {
    /// Appends the gateway's lines to `s`.
    pub fn text(&self, s: &mut String) {
        use std::fmt::Write as _;
        let _ = writeln!(
            s,
            "Gateway: {} radio(s) per aircraft merged, frame loss {} (lost down {}, up {}), merging window {} s:",
            self.radios,
            self.frame_loss,
            self.lost_frames_down,
            self.lost_frames_up,
            self.dedup_window_s
        );
        for l in &self.links {
            let _ = writeln!(
                s,
                "  link {}: frames {}, checksum errors {}; first {}, duplicates {}, alone {}, missed {}",
                l.link, l.frames, l.checksum_errors, l.first, l.duplicates, l.alone, l.missed
            );
        }
        for a in &self.aircraft {
            let sent: Vec<String> = a.sent.iter().map(u32::to_string).collect();
            let ratio = if a.aired > 0 {
                format!(" ({:.1} %)", a.delivered as f64 * 100.0 / a.aired as f64)
            } else {
                String::new()
            };
            let _ = writeln!(
                s,
                "  aircraft {}: sent {} (per radio), aired {}, delivered {}{ratio}",
                a.ac_id,
                sent.join(" + "),
                a.aired,
                a.delivered
            );
        }
        if let Some(bus) = &self.bus {
            let _ = writeln!(s, "  bus: {bus}");
        }
    }
}
