//! The fleet gateway's logic (`pprz-gateway`), without any I/O: several links decoded
//! at once, redundant links merged, the uplink routed.
//!
//! * Each link has a [`Monitor`] of its own (its framing, its counters, its view of
//!   each aircraft's link quality).
//! * Every message decoded on a link goes through [`dedup`]: a copy of a message that
//!   another link delivered is counted and dropped.
//! * A delivered message is framed again in PPRZ v2 (its source, destination, class,
//!   id and payload, whatever the framing it came in) and handed, decoded, to one more
//!   monitor, the fleet's ([`Monitor::message`]): its figures are those of the merged
//!   stream, and that frame is what the bus carries for tools that decode frames.
//! * [`route`] notes which link brought each aircraft's messages first;
//!   [`Gateway::uplink`] frames a command for each link it takes.
//!
//! ```
//! use pprz_ground::{gateway::{Gateway, GatewayLink}, set::RuntimeSet};
//! use pprz_transports::PprzV2;
//!
//! let xml = r#"<protocol><msg_class name="telemetry" id="1">
//!     <message name="ALIVE" id="2"><field name="md5sum" type="uint8[]"/></message>
//!     </msg_class></protocol>"#;
//! let set = || RuntimeSet::parse("m.xml", xml).unwrap();
//! let links = vec![
//!     GatewayLink::new("radio-a", set(), PprzV2::new().into(), true),
//!     GatewayLink::new("radio-b", set(), PprzV2::new().into(), true),
//! ];
//! let mut gw = Gateway::new(set(), links);
//! let frame = [0x99, 0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x1C, 0xC4];
//! let mut lines = Vec::new();
//! gw.feed(0, 0.0, &frame, |d| lines.push(d.message.line.to_owned()));
//! gw.feed(1, 0.01, &frame, |d| lines.push(d.message.line.to_owned()));
//! assert_eq!(lines, ["7 telemetry ALIVE md5sum=0,1,2"]);
//! assert_eq!(gw.link_merge(1).duplicates, 1);
//! ```

pub mod dedup;
#[cfg(feature = "bus")]
pub mod options;
pub mod route;
#[cfg(feature = "bus")]
pub mod serve;

use pprz_messages::MessageDescriptor;
use pprz_transports::{AnyTransport, Encoder, GROUND_ID, MsgHeader, PprzV2, TxMeta};

use crate::input::Drops;
use crate::monitor::{Decoded, Monitor};
use crate::set::RuntimeSet;
use crate::uplink::{self, UplinkError};
use dedup::{DEFAULT_CAPACITY, DEFAULT_WINDOW, Dedup, LinkMerge, MAX_LINKS, Verdict};
use route::{Policy, RouteTable};

/// One of the gateway's links: its name, its decoder and whether it can send.
pub struct GatewayLink {
    name: String,
    monitor: Monitor,
    transport: AnyTransport,
    can_send: bool,
}

impl GatewayLink {
    /// A link named `name` decoding `transport` frames with the messages of `set`;
    /// `can_send`: commands can be written to it (not a file, not UDP without an
    /// uplink address).
    pub fn new(name: &str, set: RuntimeSet, transport: AnyTransport, can_send: bool) -> Self {
        Self {
            name: name.to_owned(),
            monitor: Monitor::new(set, transport).without_text(),
            transport,
            can_send,
        }
    }

    /// The link's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The link's monitor: its byte, frame and error counters, and its view of each
    /// aircraft (without the messages' text: [`Monitor::without_text`]).
    pub fn monitor(&self) -> &Monitor {
        &self.monitor
    }

    /// Whether commands can be written to it.
    pub fn can_send(&self) -> bool {
        self.can_send
    }
}

/// What a link brought.
#[derive(Debug, Clone, Copy)]
pub enum Arrival<'a> {
    /// Bytes read.
    Bytes(&'a [u8]),
    /// Input dropped (a queue overflowed) just before the next bytes.
    Gap(Drops),
}

/// A message the gateway delivers.
#[derive(Debug, Clone, Copy)]
pub struct Delivered<'a> {
    /// The link that brought it.
    pub link: usize,
    /// Whether it was the first of its content or a repeat by the aircraft.
    pub verdict: Verdict,
    /// The message, as the fleet's monitor decoded it; its `raw` is the PPRZ v2 frame
    /// the gateway made of it.
    pub message: &'a Decoded<'a>,
    /// The frame as the link received it (opened, on a secure link).
    pub received: &'a [u8],
}

/// The gateway (module doc).
pub struct Gateway {
    links: Vec<GatewayLink>,
    fleet: Monitor,
    dedup: Dedup,
    routes: RouteTable,
    policy: Policy,
}

impl Gateway {
    /// A gateway over `links` (at most [`MAX_LINKS`]: further links are ignored), the
    /// fleet's messages decoded with `set`; default window, bound and policy.
    pub fn new(set: RuntimeSet, mut links: Vec<GatewayLink>) -> Self {
        links.truncate(MAX_LINKS);
        let n = links.len();
        let fleet = Monitor::new(set, PprzV2::new().into());
        let stale = fleet.stale_after();
        Self {
            links,
            fleet,
            dedup: Dedup::new(n, DEFAULT_WINDOW, DEFAULT_CAPACITY),
            routes: RouteTable::new(n, stale),
            policy: Policy::Best,
        }
    }

    /// The same gateway merging over `window` seconds, remembering at most `capacity`
    /// contents ([`dedup`]).
    pub fn with_window(mut self, window: f64, capacity: usize) -> Self {
        self.dedup = Dedup::new(self.links.len(), window, capacity);
        self
    }

    /// The same gateway routing commands with `policy`.
    pub fn with_policy(mut self, policy: Policy) -> Self {
        self.policy = policy;
        self
    }

    /// The same gateway with `fleet` as the monitor of the merged stream (its stale
    /// time, settings table...); it must decode PPRZ v2.
    pub fn with_fleet_monitor(mut self, fleet: Monitor) -> Self {
        self.routes = RouteTable::new(self.links.len(), fleet.stale_after());
        self.fleet = fleet;
        self
    }

    /// The links.
    pub fn links(&self) -> &[GatewayLink] {
        &self.links
    }

    /// The monitor of the merged stream.
    pub fn fleet(&self) -> &Monitor {
        &self.fleet
    }

    /// The monitor of the merged stream, to note the requests a ground station sends
    /// through the gateway ([`Monitor::ping_sent`], [`Monitor::setting_sent`]).
    pub fn fleet_mut(&mut self) -> &mut Monitor {
        &mut self.fleet
    }

    /// What link `link` delivered, duplicated, delivered alone and missed.
    pub fn link_merge(&self, link: usize) -> LinkMerge {
        self.dedup.link(link)
    }

    /// The merging state (window, contents remembered, early evictions).
    pub fn dedup(&self) -> &Dedup {
        &self.dedup
    }

    /// Where commands go.
    pub fn routes(&self) -> &RouteTable {
        &self.routes
    }

    /// Bytes received on link `link` at `now` (seconds, not decreasing); `deliver`
    /// gets each message delivered. Bytes for a link that does not exist are ignored.
    pub fn feed(
        &mut self,
        link: usize,
        now: f64,
        bytes: &[u8],
        deliver: impl FnMut(&Delivered<'_>),
    ) {
        self.arrive(link, now, Arrival::Bytes(bytes), deliver);
    }

    /// Input of link `link` was dropped just before its next bytes: the link's monitor
    /// counts it and delivers the frames held behind the one it abandons
    /// ([`Monitor::input_gap`]).
    pub fn input_gap(
        &mut self,
        link: usize,
        now: f64,
        dropped: Drops,
        deliver: impl FnMut(&Delivered<'_>),
    ) {
        self.arrive(link, now, Arrival::Gap(dropped), deliver);
    }

    /// What arrived on link `link` at `now`, decoded by the link's monitor and merged.
    pub fn arrive(
        &mut self,
        link: usize,
        now: f64,
        arrival: Arrival<'_>,
        mut deliver: impl FnMut(&Delivered<'_>),
    ) {
        let Self {
            links,
            fleet,
            dedup,
            routes,
            ..
        } = self;
        let Some(l) = links.get_mut(link) else {
            return;
        };
        let on_message = |d: &Decoded<'_>| merge(now, link, d, dedup, routes, fleet, &mut deliver);
        match arrival {
            Arrival::Bytes(bytes) => l.monitor.feed(now, bytes, on_message),
            Arrival::Gap(dropped) => l.monitor.input_gap(now, dropped, on_message),
        }
    }

    /// The clock moved to `now` without input: closes merging windows and marks the
    /// aircraft that went stale.
    pub fn tick(&mut self, now: f64) {
        self.dedup.expire(now);
        for l in &mut self.links {
            l.monitor.tick(now);
        }
        self.fleet.tick(now);
    }

    /// Frames of message `desc` (a datalink message) with `payload` for aircraft `ac`
    /// at `now`, one for each link the route takes: `(link, frame)`, framed with the
    /// link's transport and sealed on a secure link.
    ///
    /// # Errors
    /// No link can send, or a link's transport refused the frame.
    pub fn uplink(
        &mut self,
        now: f64,
        ac: u8,
        desc: &MessageDescriptor<'_>,
        payload: &[u8],
    ) -> Result<Vec<(usize, Vec<u8>)>, UplinkError> {
        let can_send: Vec<bool> = self.links.iter().map(|l| l.can_send).collect();
        let route = self.routes.uplink(now, ac, self.policy, &can_send);
        if route.is_empty() {
            return Err(UplinkError::Transport(
                "no link can send to the aircraft".into(),
            ));
        }
        let mut out = Vec::with_capacity(route.len());
        for l in route {
            let link = &mut self.links[l];
            let frame = uplink::encode(link.transport, ac, desc, payload)?;
            let frame = link
                .monitor
                .seal_uplink(&frame)
                .map_err(|e| UplinkError::Transport(e.to_string()))?;
            out.push((l, frame));
        }
        Ok(out)
    }
}

/// One message decoded on `link`: merged, routed, decoded again by the fleet's monitor
/// and delivered.
fn merge(
    now: f64,
    link: usize,
    d: &Decoded<'_>,
    dedup: &mut Dedup,
    routes: &mut RouteTable,
    fleet: &mut Monitor,
    deliver: &mut impl FnMut(&Delivered<'_>),
) {
    let key = dedup.key(d.source, d.class_id, d.msg_id, d.payload);
    let verdict = dedup.check(now, link, d.source, key);
    routes.heard(now, link, d.source, verdict.delivered());
    if !verdict.delivered() {
        return;
    }
    let Some(frame) = pprz_v2(d) else {
        return;
    };
    fleet.message(now, d, &frame, |message| {
        deliver(&Delivered {
            link,
            verdict,
            message,
            received: d.raw,
        });
    });
}

/// The PPRZ v2 frame of a decoded message.
fn pprz_v2(d: &Decoded<'_>) -> Option<Vec<u8>> {
    let header = MsgHeader::new(
        d.source,
        d.destination.unwrap_or(GROUND_ID),
        d.class_id,
        d.msg_id,
    );
    let t = PprzV2::new();
    let mut out = vec![0u8; Encoder::max_frame_len(&t)];
    let n = t.encode(&TxMeta::new(header), d.payload, &mut out).ok()?;
    out.truncate(n);
    Some(out)
}

#[cfg(test)]
mod tests;
