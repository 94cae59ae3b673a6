//! The end summary: what the radio device submitted, sent, shed and superseded per
//! priority level, what reached the ground and how old, the modem's losses and busy
//! times, the XBee transmit statuses and the PING round trips. Printed as a table and,
//! with `--summary-json`, written as JSON (the schema is in the README's SITL section;
//! the field names below are the JSON's).

use pprz_example_app::AC_ID;
use serde::Serialize;

/// Everything the summary shows.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Version of this JSON layout (incremented when a field changes meaning or goes).
    pub schema: u32,
    /// The simulated radio and load.
    pub config: RunConfig,
    /// Simulated seconds elapsed when the summary was taken.
    pub simulated_s: f64,
    /// Per priority level.
    pub levels: Levels,
    /// The radio device's totals in the downlink.
    pub downlink: DownlinkFigures,
    /// The aircraft's radio modem (aircraft to ground direction).
    pub modem: ModemFigures,
    /// XBee transmit statuses (`None`, JSON `null`, for PPRZ v2).
    pub delivery: Option<DeliveryFigures>,
    /// PINGs through the radio, timed on the simulation's clock at the ground end.
    pub ping: PingFigures,
    /// Per message type submitted or received, by class and id.
    pub messages: Vec<MessageFigures>,
    /// The aircraft's end of the secure link (`--secure`; `None`, JSON `null`, without).
    pub secure: Option<SecureFigures>,
    /// `--fleet 2` or more: per aircraft and per level, and with `--relay` the relay's
    /// routes (`None`, JSON `null`, with one aircraft). The figures above are the
    /// radios' to the ground: every aircraft's frames together.
    pub fleet: Option<FleetFigures>,
    /// The link to the ground: each aircraft's link health and what the ground saw of
    /// its failsafe, with the outages of the run.
    pub link: LinkFigures,
    /// The gateway merging the ground's radios (`--radios 2`, `--frame-loss`,
    /// `--zenoh`; `None`, JSON `null`, otherwise).
    pub gateway: Option<crate::merge::GatewayFigures>,
}

/// The link to the ground, per aircraft: the health the aircraft kept (from its own
/// side) and what the ground saw. Times are simulated seconds.
#[derive(Debug, Clone, Serialize)]
pub struct LinkFigures {
    /// The aircraft's link health is Lost (and its failsafe flies home) after this
    /// many seconds without a frame from the ground (`--lost-timeout`).
    pub lost_timeout_s: f64,
    /// It is Degraded after this many.
    pub degraded_timeout_s: f64,
    /// When the ground set `ap_mode` back to NAV (`--resume-nav`; `None`, JSON `null`,
    /// without).
    pub resume_nav_s: Option<f64>,
    /// Bytes sent on the downlink during an outage, lost (transparent radio), every
    /// radio to the ground together.
    pub lost_bytes_down: u32,
    /// Bytes sent on the uplink during an outage, lost (transparent radio), every radio
    /// to the ground together.
    pub lost_bytes_up: u32,
    /// XBee: downlink transmissions that failed in an outage.
    pub failed_attempts_down: u32,
    /// XBee: uplink transmissions that failed in an outage.
    pub failed_attempts_up: u32,
    /// Each aircraft, the one whose radio reaches the ground first.
    pub aircraft: Vec<AircraftLink>,
}

/// One aircraft's link to the ground.
#[derive(Debug, Clone, Serialize)]
pub struct AircraftLink {
    /// Its id.
    pub ac_id: u8,
    /// The outages of its way to the ground (its radio, or with `--relay` aircraft 7's,
    /// also aircraft 8's way: every radio to the ground is cut alike).
    pub outages: Vec<Window>,
    /// Its link health's changes, from Lost (nothing heard yet) at the start.
    pub transitions: Vec<Transition>,
    /// Times its link became Lost after it was heard (one in progress included).
    pub losses: u32,
    /// Its link health at the end: `"up"`, `"degraded"` or `"lost"`.
    pub state: &'static str,
    /// Its `ap_mode` as the ground saw it in ROTORCRAFT_STATUS: the first, then each
    /// change.
    pub ap_modes: Vec<ModeChange>,
    /// Each failsafe as the ground saw it.
    pub failsafes: Vec<Failsafe>,
    /// Times the ground heard nothing from it for more than a second.
    pub silences: Vec<Silence>,
    /// Health changes, `ap_mode` changes and silences past the first 10 000 of each:
    /// counted, not listed (the record of a long run stays bounded).
    pub events_omitted: u64,
}

/// An outage window.
#[derive(Debug, Clone, Serialize)]
pub struct Window {
    /// `"up"`, `"down"` or `"both"`.
    pub direction: &'static str,
    /// Its start.
    pub from_s: f64,
    /// Its end.
    pub until_s: f64,
}

/// A change of link health.
#[derive(Debug, Clone, Serialize)]
pub struct Transition {
    /// When.
    pub t_s: f64,
    /// The new state: `"up"`, `"degraded"` or `"lost"`.
    pub state: &'static str,
}

/// A ROTORCRAFT_STATUS whose `ap_mode` differed from the one before (or the first).
#[derive(Debug, Clone, Serialize)]
pub struct ModeChange {
    /// When it reached the ground.
    pub t_s: f64,
    /// Its `ap_mode` (`"NAV"`, `"HOME"`; the number if it has no name).
    pub ap_mode: String,
}

/// A failsafe as the ground saw it.
#[derive(Debug, Clone, Serialize)]
pub struct Failsafe {
    /// The first ROTORCRAFT_STATUS with `ap_mode` HOME reached the ground then.
    pub home_s: f64,
    /// The first after it with NAV (`None`, JSON `null`: still in HOME at the end).
    pub nav_s: Option<f64>,
}

/// A time the ground heard nothing from an aircraft.
#[derive(Debug, Clone, Serialize)]
pub struct Silence {
    /// The last message before it reached the ground then.
    pub from_s: f64,
    /// The first after it (`None`, JSON `null`: silent until the end).
    pub until_s: Option<f64>,
}

impl LinkFigures {
    /// Appends the link's lines to `s`.
    fn text(&self, s: &mut String) {
        use std::fmt::Write as _;
        let resume = self
            .resume_nav_s
            .map(|t| format!("; ap_mode set back to NAV at {t} s"))
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "Link to the ground (the aircraft's health: degraded after {} s, lost after {} s without a frame from the ground{resume}):",
            self.degraded_timeout_s, self.lost_timeout_s
        );
        if let Some(first) = self.aircraft.first()
            && !first.outages.is_empty()
        {
            let windows: Vec<String> = first
                .outages
                .iter()
                .map(|w| format!("{} {}..{} s", w.direction, w.from_s, w.until_s))
                .collect();
            let _ = writeln!(
                s,
                "  outages: {}; lost in them: downlink {} bytes, uplink {} bytes (XBee attempts failed: down {}, up {})",
                windows.join(", "),
                self.lost_bytes_down,
                self.lost_bytes_up,
                self.failed_attempts_down,
                self.failed_attempts_up
            );
        }
        for a in &self.aircraft {
            a.text(s);
        }
    }
}

impl AircraftLink {
    /// Appends the aircraft's lines to `s`.
    fn text(&self, s: &mut String) {
        use std::fmt::Write as _;
        let changes: Vec<String> = self
            .transitions
            .iter()
            .map(|t| format!("{} {:.3} s", t.state, t.t_s))
            .collect();
        let changes = if changes.is_empty() {
            "never heard the ground".to_owned()
        } else {
            changes.join(", ")
        };
        let _ = writeln!(
            s,
            "  aircraft {} link health: {changes}; losses {}; {} at the end",
            self.ac_id, self.losses, self.state
        );
        for f in &self.failsafes {
            let nav = f.nav_s.map_or_else(
                || "still HOME at the end".to_owned(),
                |t| format!("NAV again at {t:.3} s"),
            );
            let _ = writeln!(
                s,
                "  aircraft {} failsafe, as the ground saw it: HOME at {:.3} s, {nav}",
                self.ac_id, f.home_s
            );
        }
        for q in &self.silences {
            let until = q
                .until_s
                .map_or_else(|| "the end".to_owned(), |t| format!("{t:.3} s"));
            let _ = writeln!(
                s,
                "  aircraft {}: the ground heard nothing from it from {:.3} s to {until}",
                self.ac_id, q.from_s
            );
        }
    }
}

/// A fleet: each aircraft, and with `--relay` what the relay carried on each of its
/// routes.
#[derive(Debug, Clone, Serialize)]
pub struct FleetFigures {
    /// Each aircraft, by id: 7 first.
    pub aircraft: Vec<AircraftFigures>,
    /// The relay's routes: what it forwarded for the others on each of its devices
    /// (empty without `--relay`).
    pub routes: Vec<RouteFigures>,
    /// What the relay did with the frames not only for itself: forwarded, or refused
    /// and why (`None`, JSON `null`, without `--relay`).
    pub relay: Option<RelayFigures>,
}

/// The relay's decisions on the frames for other aircraft and broadcast frames it read
/// on any of its devices (`pprz_telemetry::RelayStats`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct RelayFigures {
    /// The relay's id.
    pub ac_id: u8,
    /// Frames handed to the devices of their route.
    pub forwarded: u32,
    /// Broadcast frames delivered to the relay itself.
    pub broadcast: u32,
    /// Frames refused, every reason below together.
    pub refused: u32,
    /// Refused: their destination's route leads nowhere but back where they came from.
    pub no_route: u32,
    /// Refused: they came from a device that is not the relay's route back to their
    /// source (a forged source, a copy that went round a loop, a second copy of a
    /// broadcast).
    pub reverse_path: u32,
    /// Refused: they claimed the relay's own id as their source.
    pub own_source: u32,
    /// Refused: they claimed the broadcast id as their source.
    pub broadcast_source: u32,
    /// Refused: their fields do not match their message's definition.
    pub malformed: u32,
}

/// One aircraft of the fleet.
#[derive(Debug, Clone, Serialize)]
pub struct AircraftFigures {
    /// Its id.
    pub ac_id: u8,
    /// The aircraft relaying its frames to the ground (`null`: its radio reaches it).
    pub relayed_by: Option<u8>,
    /// Per level (high, normal, low), most important first.
    pub levels: [AircraftLevel; 3],
    /// PINGs from the ground to it.
    pub ping: PingFigures,
}

/// One priority level of one aircraft.
#[derive(Debug, Clone, Serialize)]
pub struct AircraftLevel {
    /// `"high"`, `"normal"` or `"low"`.
    pub level: &'static str,
    /// Messages submitted to its own radio (the application's, and the services'
    /// replies).
    pub submitted: u32,
    /// Written to its own radio.
    pub sent: u32,
    /// Shed on its own radio (dropped or evicted).
    pub shed: u32,
    /// Forwarded towards the ground by the relay (accepted into the relay's queue).
    pub forwarded: u32,
    /// Shed by the relay (dropped or evicted there).
    pub shed_by_relay: u32,
    /// Decoded at the ground end of the ground's radio, with this aircraft as source.
    pub received: u64,
}

/// One route of the relay: the frames of other aircraft it forwarded on one device.
#[derive(Debug, Clone, Serialize)]
pub struct RouteFigures {
    /// The relay's id.
    pub relay: u8,
    /// What the device leads to (`"ground"`, `"aircraft 8"`).
    pub to: String,
    /// Forwarded frames accepted for the device, per level (high, normal, low).
    pub forwarded: [u32; 3],
    /// Written.
    pub sent: u32,
    /// Shed, per level: dropped or evicted by more important frames.
    pub shed: [u32; 3],
    /// Dropped because the queue was full of more important frames.
    pub queue_full: u32,
    /// Dropped because the arena was full of more important frames.
    pub arena_full: u32,
    /// Evicted by more important frames.
    pub evicted: u32,
}

/// The aircraft's end of the secure link.
#[derive(Debug, Clone, Default, Serialize)]
pub struct SecureFigures {
    /// Whether a session was established at the end.
    pub session: bool,
    /// Handshakes the aircraft answered with fresh keys.
    pub handshakes_started: u32,
    /// Handshakes completed (sessions installed).
    pub handshakes_completed: u32,
    /// Key-exchange messages refused (malformed, wrong address, unexpected, duplicate,
    /// rate limited, bad key, tag or signature).
    pub handshakes_refused: u32,
    /// Frames encrypted and sent.
    pub encrypted: u32,
    /// Frames received and decrypted.
    pub decrypted: u32,
    /// Received frames rejected (bad tag, replayed, plaintext not allowed or unsecured,
    /// malformed, wrong address, no session).
    pub rejected: u32,
    /// Frames the current session can still send.
    pub counter_space_left: u32,
}

/// The options of the run.
#[derive(Debug, Clone, Serialize)]
pub struct RunConfig {
    /// `"pprz2"` or `"xbee"` (XBee 802.15.4 API).
    pub transport: &'static str,
    /// UART baud rate (8N1) between the autopilot and its modem.
    pub baud: u32,
    /// UART throughput, bytes per second (`baud / 10`).
    pub serial_rate_bytes_per_s: u32,
    /// The modem's over-the-air throughput, bytes per second.
    pub air_rate_bytes_per_s: u32,
    /// The modem's buffer, bytes.
    pub modem_buffer_bytes: usize,
    /// `"cts"` (the modem stops the UART when full) or `"none"` (it drops bytes).
    pub flow_control: &'static str,
    /// Whether the radio device paces its writes to the air rate.
    pub pacing: bool,
    /// The pacing budget in bytes (`null` without pacing).
    pub pacing_budget_bytes: Option<u16>,
    /// XBee: frames awaiting their transmit status at most (`null` for PPRZ v2).
    pub in_modem: Option<u8>,
    /// Whether the low-priority payload flood is on.
    pub overload: bool,
    /// The flood's rate, bytes per second (0 without `--overload`).
    pub flood_bytes_per_s: u32,
    /// Simulated seconds per wall-clock second.
    pub speed: f64,
    /// The requested run time, simulated seconds.
    pub duration_s: f64,
}

/// The three priority levels.
#[derive(Debug, Clone, Serialize)]
pub struct Levels {
    /// Acknowledgements (PONG, DL_VALUE).
    pub high: Level,
    /// Flight status telemetry.
    pub normal: Level,
    /// Payload and debug data.
    pub low: Level,
}

impl Levels {
    /// The levels with their names, most important first.
    pub fn named(&self) -> [(&'static str, &Level); 3] {
        [
            ("high", &self.high),
            ("normal", &self.normal),
            ("low", &self.low),
        ]
    }
}

/// One priority level.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Level {
    /// Messages submitted to the radio device.
    pub submitted: u32,
    /// Frames written to the modem.
    pub sent: u32,
    /// Messages shed: dropped (queue or arena full, rate limit, too large, write error)
    /// or evicted by more important ones.
    pub shed: u32,
    /// State samples replaced, while waiting, by a newer sample.
    pub superseded: u32,
    /// Messages decoded at the ground end of the radio.
    pub received: u64,
    /// Received messages matched to their submission (those with an age).
    pub aged: u64,
    /// Median age at arrival (submission to arrival), milliseconds.
    pub age_p50_ms: Option<f64>,
    /// 99th percentile of the age at arrival, milliseconds.
    pub age_p99_ms: Option<f64>,
    /// Aged messages whose payload was submitted more than once (constant messages,
    /// the identical frames of the payload flood): their age is measured from the latest
    /// such submission, a lower bound.
    pub ambiguous: u64,
}

/// One message type the application submitted or the ground end of the radio received.
#[derive(Debug, Clone, Serialize)]
pub struct MessageFigures {
    /// Class name (`telemetry`).
    pub class: &'static str,
    /// Message name (`ATTITUDE`).
    pub name: &'static str,
    /// Priority level: `"high"`, `"normal"` or `"low"`.
    pub level: &'static str,
    /// Messages the application submitted (0 for the services' replies, PONG, and for
    /// DL_VALUE only the periodic ones).
    pub submitted: u64,
    /// Messages decoded at the ground end of the radio.
    pub received: u64,
    /// Longest time between two arrivals, milliseconds (`null` before the second).
    pub max_gap_ms: Option<f64>,
}

/// The radio device's totals.
#[derive(Debug, Clone, Default, Serialize)]
pub struct DownlinkFigures {
    /// Frames written to the modem.
    pub sent: u32,
    /// Messages dropped, all reasons.
    pub dropped: u32,
    /// Dropped: the queue was full of more important messages.
    pub queue_full: u32,
    /// Dropped: the arena was full of more important frames.
    pub arena_full: u32,
    /// Dropped: too large for the transport (XBee 802.15.4: 96 field bytes).
    pub too_large: u32,
    /// Replies refused by the reply rate limit.
    pub rate_limited: u32,
    /// Refused by the secure link when taken for the wire (no session yet, or the
    /// session's counter used up).
    pub refused: u32,
    /// Messages evicted for more important ones.
    pub evicted: u32,
    /// State samples superseded.
    pub superseded: u32,
    /// Messages still queued.
    pub queued: u16,
}

/// The aircraft's radio modem.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ModemFigures {
    /// Bytes the modem dropped because its buffer was full (no flow control).
    pub dropped_bytes: u32,
    /// XBee: API frames dropped whole because the modem was full.
    pub frames_dropped: u32,
    /// Bytes lost because the ground's receive ring was full.
    pub overrun_bytes: u32,
    /// Fraction of the simulated time the UART was transferring bytes (0 to 1).
    pub uart_busy: f64,
    /// Fraction of the simulated time the air carried this direction's bytes (0 to 1).
    pub air_busy: f64,
}

/// XBee transmit statuses, as the radio device counted them.
#[derive(Debug, Clone, Default, Serialize)]
pub struct DeliveryFigures {
    /// Frames the modem reported delivered.
    pub delivered: u32,
    /// Frames the modem reported not delivered (no ACK, purged, ...).
    pub failed: u32,
    /// Frames whose status never came in time.
    pub timeouts: u32,
    /// Statuses for no outstanding frame.
    pub unexpected: u32,
}

/// PINGs through the radio.
#[derive(Debug, Clone, Default, Serialize)]
pub struct PingFigures {
    /// PINGs that went up the radio.
    pub sent: u64,
    /// PINGs answered by a PONG.
    pub answered: u64,
    /// PINGs unanswered after 5 s, or pushed out by 64 newer ones outstanding.
    pub lost: u64,
    /// Median round trip, milliseconds.
    pub rtt_p50_ms: Option<f64>,
    /// 99th percentile of the round trip, milliseconds.
    pub rtt_p99_ms: Option<f64>,
}

/// `v` with one decimal, or `-`.
fn ms(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_owned(), |v| format!("{v:.1}"))
}

/// `fraction` as a percentage with one decimal.
fn percent(fraction: f64) -> String {
    format!("{:.1} %", fraction * 100.0)
}

impl Summary {
    /// The summary as text, for the terminal.
    pub fn text(&self) -> String {
        let mut s = String::new();
        self.radio_text(&mut s);
        self.levels_text(&mut s);
        self.counters_text(&mut s);
        if let Some(fleet) = &self.fleet {
            fleet.text(&mut s);
        }
        self.link.text(&mut s);
        if let Some(gateway) = &self.gateway {
            gateway.text(&mut s);
        }
        s
    }

    /// The radio's line.
    fn radio_text(&self, s: &mut String) {
        use std::fmt::Write as _;
        let c = &self.config;
        let pacing = match c.pacing_budget_bytes {
            Some(budget) => format!("on (budget {budget} B)"),
            None => "off".to_owned(),
        };
        let in_modem = c
            .in_modem
            .map(|k| format!(", {k} frame(s) awaiting status at most"))
            .unwrap_or_default();
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "Radio: {} at {} baud ({} B/s UART), air {} B/s, modem buffer {} B, flow control {}, pacing {}{in_modem}; {:.1} s simulated",
            c.transport,
            c.baud,
            c.serial_rate_bytes_per_s,
            c.air_rate_bytes_per_s,
            c.modem_buffer_bytes,
            c.flow_control,
            pacing,
            self.simulated_s,
        );
    }

    /// The table per priority level, with its legend.
    fn levels_text(&self, s: &mut String) {
        use std::fmt::Write as _;
        let _ = writeln!(s, "Priority shedding on the radio:");
        let _ = writeln!(
            s,
            "  {:<8} {:>10} {:>10} {:>10} {:>10} {:>10} {:>11} {:>11}",
            "level",
            "submitted",
            "sent",
            "shed",
            "superseded",
            "received",
            "age p50 ms",
            "age p99 ms"
        );
        for (name, level) in self.levels.named() {
            let _ = writeln!(
                s,
                "  {:<8} {:>10} {:>10} {:>10} {:>10} {:>10} {:>11} {:>11}",
                name,
                level.submitted,
                level.sent,
                level.shed,
                level.superseded,
                level.received,
                ms(level.age_p50_ms),
                ms(level.age_p99_ms),
            );
        }
        let _ = writeln!(
            s,
            "  (high: acknowledgements PONG/DL_VALUE; normal: flight status; low: payload and debug;\n   superseded: state samples replaced, while waiting, by a newer sample; received: decoded at\n   the ground end of the radio; age: submission to arrival on the simulated clock, for the\n   messages matched to their submission: a lower bound for constant ones and the flood)"
        );
    }

    /// The counters of the downlink, the secure link, the modem, the XBee transmit
    /// statuses and the PINGs through the radio.
    fn counters_text(&self, s: &mut String) {
        use std::fmt::Write as _;
        let d = &self.downlink;
        let _ = writeln!(
            s,
            "  downlink: sent {}, dropped {} (queue full {}, arena full {}, too large {}, replies over the rate limit {}, refused by the secure link {}), evicted {}, still queued {}",
            d.sent,
            d.dropped,
            d.queue_full,
            d.arena_full,
            d.too_large,
            d.rate_limited,
            d.refused,
            d.evicted,
            d.queued
        );
        if let Some(k) = &self.secure {
            let _ = writeln!(
                s,
                "  secure link (aircraft): session {}, handshakes started {}, completed {}, refused {}; frames encrypted {}, decrypted {}, rejected {}; counter space left {}",
                if k.session { "up" } else { "none" },
                k.handshakes_started,
                k.handshakes_completed,
                k.handshakes_refused,
                k.encrypted,
                k.decrypted,
                k.rejected,
                k.counter_space_left
            );
        }
        let m = &self.modem;
        let _ = writeln!(
            s,
            "  modem: dropped bytes {} (whole XBee frames {}), UART busy {}, air busy {}",
            m.dropped_bytes,
            m.frames_dropped,
            percent(m.uart_busy),
            percent(m.air_busy)
        );
        if let Some(x) = &self.delivery {
            let _ = writeln!(
                s,
                "  XBee transmit statuses: delivered {}, failed {}, timed out {}, unexpected {}",
                x.delivered, x.failed, x.timeouts, x.unexpected
            );
        }
        let p = &self.ping;
        let _ = write!(
            s,
            "  PINGs up the radio to aircraft {AC_ID}: sent {}, answered {}, lost {}",
            p.sent, p.answered, p.lost
        );
        if p.rtt_p50_ms.is_some() {
            let _ = write!(
                s,
                ", round trip p50 {} ms, p99 {} ms",
                ms(p.rtt_p50_ms),
                ms(p.rtt_p99_ms)
            );
        }
        let _ = writeln!(s);
    }

    /// The summary as pretty-printed JSON.
    pub fn json(&self) -> String {
        // Serialising plain structs of numbers and strings cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }
}

impl FleetFigures {
    /// Appends the fleet's table to `s`.
    fn text(&self, s: &mut String) {
        use std::fmt::Write as _;
        let _ = writeln!(s, "Fleet, per aircraft and level:");
        let _ = writeln!(
            s,
            "  {:<10} {:<8} {:>10} {:>10} {:>10} {:>10} {:>14} {:>10}",
            "aircraft",
            "level",
            "submitted",
            "sent",
            "shed",
            "forwarded",
            "shed by relay",
            "received"
        );
        for a in &self.aircraft {
            let who = match a.relayed_by {
                Some(relay) => format!("{} via {relay}", a.ac_id),
                None => a.ac_id.to_string(),
            };
            for l in &a.levels {
                let _ = writeln!(
                    s,
                    "  {:<10} {:<8} {:>10} {:>10} {:>10} {:>10} {:>14} {:>10}",
                    who,
                    l.level,
                    l.submitted,
                    l.sent,
                    l.shed,
                    l.forwarded,
                    l.shed_by_relay,
                    l.received
                );
            }
            let p = &a.ping;
            let _ = writeln!(
                s,
                "  {:<10} PINGs sent {}, answered {}, lost {}, round trip p50 {} ms, p99 {} ms",
                who,
                p.sent,
                p.answered,
                p.lost,
                ms(p.rtt_p50_ms),
                ms(p.rtt_p99_ms)
            );
        }
        for r in &self.routes {
            let _ = writeln!(
                s,
                "  relay {} -> {}: forwarded {} (high {}, normal {}, low {}), sent {}, shed {} (high {}, normal {}, low {}: queue full {}, arena full {}, evicted {})",
                r.relay,
                r.to,
                r.forwarded.iter().sum::<u32>(),
                r.forwarded[0],
                r.forwarded[1],
                r.forwarded[2],
                r.sent,
                r.shed.iter().sum::<u32>(),
                r.shed[0],
                r.shed[1],
                r.shed[2],
                r.queue_full,
                r.arena_full,
                r.evicted
            );
        }
        let Some(r) = &self.relay else {
            let _ = writeln!(
                s,
                "  (submitted, sent, shed: on the aircraft's own radio, its replies included; received: at\n   the ground)"
            );
            return;
        };
        let _ = writeln!(
            s,
            "  relay {} refused {} (own source {}, broadcast source {}, reverse path {}, no route {}, malformed {}); forwarded {}, broadcast {}",
            r.ac_id,
            r.refused,
            r.own_source,
            r.broadcast_source,
            r.reverse_path,
            r.no_route,
            r.malformed,
            r.forwarded,
            r.broadcast
        );
        let _ = writeln!(
            s,
            "  (submitted, sent, shed: on the aircraft's own radio, its replies included; forwarded,\n   shed by relay: its frames at the relay, towards the ground; received: at the ground;\n   relay refused: frames it would not forward, by rule: own source: claiming its id; broadcast\n   source: claiming 0xFF; reverse path: not from its route back to their source; no route:\n   nowhere to go but back; malformed: fields that do not match their message)"
        );
    }
}
