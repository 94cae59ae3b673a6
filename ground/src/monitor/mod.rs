//! The monitor's state: decodes a byte stream with a chosen transport and a run-time
//! message set, keeps per-message statistics and the latest values, link statistics,
//! round-trip times of PINGs and the acknowledgements of SETTINGs, and renders them.
//!
//! Time is passed in (seconds since the start of the run), so the state is testable and
//! a replay reproduces the same output.
//!
//! # Several aircraft
//!
//! Every frame names its source (PPRZ v2 `source`, PPRZ v1 `sender_id`): the monitor keeps
//! statistics per message for all aircraft together ([`Monitor::messages`]) and per
//! aircraft ([`Monitor::aircraft`], [`Monitor::aircraft_state`], [`Aircraft`]). With one
//! aircraft the live view is one table; with several it has a section per aircraft, and
//! the events name the aircraft.
//!
//! Each request method ([`Monitor::ping_sent`], [`Monitor::setting_sent`],
//! [`Monitor::get_setting_sent`]) takes an optional destination. A request to aircraft N
//! is answered only by N: a PONG from N answers only a PING sent to N, a DL_VALUE from N
//! only a request sent to N. A request to no particular aircraft (`None`) is for a single
//! aircraft: a PONG or DL_VALUE from any aircraft answers it, when no request addressed
//! to that aircraft is waiting. Only PONGs and DL_VALUEs addressed to the ground
//! (destination 0, broadcast, or none with PPRZ v1) answer anything: one aircraft's
//! answer to another, seen on a shared link, does not.
//!
//! # Named settings
//!
//! With the aircraft's settings files ([`Monitor::with_settings`], a
//! [`SettingsTable`]), the monitor names the settings in its events and notices, shows
//! every setting of each aircraft with its latest value (from DL_VALUE, labelled and in
//! its display unit), bounds and unit, and adds the setting's name to the `--lines` form
//! of DL_VALUE (`setting=<name>`). [`Monitor::read_settings`] reads them all
//! ([`Sweep`](crate::settings::Sweep)).
//!
//! # Link quality
//!
//! Each aircraft's link is tracked ([`Monitor::link_quality`], [`LinkQuality`]): live or
//! stale (no frame for [`Monitor::stale_after`] seconds, 5 by default, as Paparazzi's
//! `link` agent), the aircraft's own view of the uplink (DATALINK_REPORT), the signal
//! strength its RSSI message reports and the one the ground's XBee modem measures, an
//! estimate of the downlink loss over each report period, and the autopilot mode.
//! [`Monitor::tick`] notes an aircraft going stale ([`Notice::LinkStale`]); its next
//! frame notes it live again ([`Notice::LinkLive`]).
//!
//! # Modules
//!
//! The monitor is one type whose methods are kept by concept: decoding (`decode`), the
//! state it updates (`state`), request tracking (`requests`), link quality (`link`),
//! events and notices (`events`), and rendering (`render`).
//!
//! # Bounds
//!
//! Every piece of state is bounded, whatever arrives: one entry per message of the set
//! (with its latest fields cut at [`MAX_FIELDS_LEN`](crate::format::MAX_FIELDS_LEN)) for all aircraft and one per
//! message and tracked aircraft, rates counted in fixed time buckets, at most
//! [`MAX_EVENTS`] events and notices, at most [`crate::ping::MAX_OUTSTANDING`] PINGs and
//! 256 requests outstanding per aircraft. Received frames make the monitor track at most
//! [`MAX_AIRCRAFT`] aircraft: frames from further source ids are decoded, shown and
//! counted with all aircraft and in [`Monitor::untracked_frames`], but get no table of
//! their own (a flood of frames from every source id costs nothing more). Aircraft the
//! ground addresses are tracked whatever the input, and take none of the places of the
//! aircraft heard until they are heard themselves (a few hundred bytes each until then,
//! 256 ids at most). The worst case is
//! `(MAX_AIRCRAFT + 1) * messages in the set` entries of at most about 4 KiB each (tens of
//! MiB for the 367 messages of the full PPRZLINK set, every one sent by 32 aircraft with
//! fields that print to the longest text; a few hundred bytes per entry in practice);
//! [`retained_bytes`](Monitor::retained_bytes) estimates the total.
//!
//! Everything printed is escaped ([`escape`](crate::escape)): no line contains a
//! control character.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use pprz_transports::{AnyTransport, Decoder};

use crate::input::Drops;
use crate::ping::PingTracker;
use crate::secure::GroundSecure;
use crate::set::RuntimeSet;
use crate::settings::{SettingTracker, SettingsTable};

mod decode;
mod events;
mod link;
#[cfg(test)]
mod link_tests;
mod render;
mod requests;
mod state;
#[cfg(test)]
mod sweep_tests;
mod sweeps;
#[cfg(test)]
mod tests;

pub use decode::Decoded;
pub use events::{Event, Notice};
pub use link::{
    DEFAULT_STALE_AFTER, GROUND_RSSI_WEIGHT, LinkQuality, LinkState, MAX_STALE_AFTER,
    MIN_STALE_AFTER, StaleAfterError,
};
pub use render::{describe_event, describe_notice};
pub use state::{Aircraft, MessageStats};

use events::Logged;
use state::Rate;

/// How long a window the rates are computed over, in seconds.
pub const RATE_WINDOW: f64 = 5.0;

/// The shortest time a rate is computed over, in seconds: before it has passed since
/// the start of the run, no rate is shown (a few bytes in the first millisecond are no
/// measure of a link).
pub const MIN_RATE_INTERVAL: f64 = 1.0;

/// Seconds of silence of a live link after which the decoder is flushed: a frame held
/// behind a false start (which announced a longer frame) is decoded then, not when the
/// next bytes arrive.
pub const IDLE_FLUSH: f64 = 0.5;

/// Events and notices kept for the live view (the latest ones).
pub const MAX_EVENTS: usize = 8;

/// Handshake frames waiting for [`Monitor::poll_secure`] (the latest ones).
pub const MAX_SECURE_OUT: usize = 4;

/// Aircraft (source ids) that received frames make the monitor track; frames from
/// further source ids are counted ([`Monitor::untracked_frames`]), not tracked. Aircraft
/// the ground addresses (PING, SETTING) are tracked beyond this bound, and take none of
/// its places until they are heard.
pub const MAX_AIRCRAFT: usize = 32;

/// Seconds during which rejections of the same reason share one notice.
const REJECT_COALESCE: f64 = 1.0;

/// Time buckets of a rate.
const BUCKETS: usize = 10;

/// The decoding monitor.
pub struct Monitor {
    set: RuntimeSet,
    decoder: Decoder<AnyTransport>,
    /// All aircraft together.
    messages: BTreeMap<(u8, u8), MessageStats>,
    aircraft: BTreeMap<u8, Aircraft>,
    /// Aircraft tracked that sent frames (those only addressed do not count).
    heard: usize,
    untracked_frames: u64,
    /// Bit `n` set: frames from source `n` were not tracked.
    untracked_ids: [u64; 4],
    bytes: u64,
    byte_rate: Rate,
    unknown: u64,
    malformed: u64,
    last_report: Option<String>,
    last_rtt: Option<f64>,
    /// PINGs and requests to no particular aircraft.
    pings: PingTracker,
    settings: SettingTracker,
    events: VecDeque<Logged<Event>>,
    notices: VecDeque<Logged<Notice>>,
    input_dropped: Drops,
    input_gaps: u64,
    event_count: u64,
    notice_count: u64,
    secure: Option<GroundSecure>,
    secure_out: VecDeque<Vec<u8>>,
    /// Replaying a recording: this monitor sent no request, so PONGs answer none.
    replay: bool,
    /// Seconds without a frame after which an aircraft is stale.
    stale_after: f64,
    /// The latest time given.
    clock: f64,
    /// The settings files' table: names, bounds, units and labels of the indices.
    table: Option<Arc<SettingsTable>>,
    /// Whether messages get their text forms (the line, the latest values).
    text: bool,
    /// PPRZLOG time stamps, unwrapped.
    log_clock: LogClock,
}

/// PPRZLOG time stamps unwrapped: the format counts 100 µs ticks in 32 bits, which wrap
/// every 429 497 s (about 5 days) of recording. A stamp more than half the range below
/// the previous one is a wrap (a smaller step back is records out of order).
#[derive(Debug, Default)]
struct LogClock {
    last: Option<u32>,
    wraps: u64,
}

impl LogClock {
    /// The time of a record stamped `ticks`, from the start of the recording.
    fn time(&mut self, ticks: u32) -> std::time::Duration {
        if self.last.is_some_and(|l| ticks < l && l - ticks >= 1 << 31) {
            self.wraps = self.wraps.saturating_add(1);
        }
        self.last = Some(ticks);
        let ticks = self
            .wraps
            .saturating_mul(1 << 32)
            .saturating_add(u64::from(ticks));
        std::time::Duration::from_micros(ticks.saturating_mul(100))
    }
}

impl Monitor {
    /// A monitor decoding `transport` frames with the messages of `set`.
    pub fn new(set: RuntimeSet, transport: AnyTransport) -> Self {
        Self {
            set,
            decoder: Decoder::new(transport),
            messages: BTreeMap::new(),
            aircraft: BTreeMap::new(),
            heard: 0,
            untracked_frames: 0,
            untracked_ids: [0; 4],
            bytes: 0,
            byte_rate: Rate::default(),
            unknown: 0,
            malformed: 0,
            last_report: None,
            last_rtt: None,
            pings: PingTracker::default(),
            settings: SettingTracker::default(),
            events: VecDeque::new(),
            notices: VecDeque::new(),
            input_dropped: Drops::default(),
            input_gaps: 0,
            event_count: 0,
            notice_count: 0,
            secure: None,
            secure_out: VecDeque::new(),
            replay: false,
            stale_after: DEFAULT_STALE_AFTER,
            clock: 0.0,
            table: None,
            text: true,
            log_clock: LogClock::default(),
        }
    }

    /// The same monitor with other PING and request trackers (other bounds and
    /// timeouts): these track the PINGs and requests to no particular aircraft, and the
    /// trackers of each aircraft get the same bounds and timeouts (call it before
    /// feeding the monitor or sending anything).
    pub fn with_trackers(mut self, pings: PingTracker, settings: SettingTracker) -> Self {
        self.pings = pings;
        self.settings = settings;
        self
    }

    /// The same monitor replaying a recording: the requests in the recording were sent
    /// by another ground station, so a PONG measures no round trip and is not noted as
    /// answering no PING ([`Notice::UnexpectedPong`]); the PONGs are decoded and counted
    /// as any message. DL_VALUEs are shown as values reported by the aircraft.
    pub fn replaying(mut self) -> Self {
        self.replay = true;
        self
    }

    /// The same monitor without the text forms of the messages: each [`Decoded`]'s
    /// `line` and each message's latest values ([`MessageStats::last`]) stay empty.
    /// Everything else is decoded and counted. For a monitor whose text nobody reads
    /// (a gateway's links), it saves formatting every field of every message.
    pub fn without_text(mut self) -> Self {
        self.text = false;
        self
    }

    /// Whether messages get their text forms ([`without_text`](Self::without_text)).
    pub fn has_text(&self) -> bool {
        self.text
    }
}
