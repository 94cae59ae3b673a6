//! The monitor's state: statistics per message, for all aircraft and per aircraft, and
//! the counters of the link.

use std::collections::BTreeMap;

use pprz_messages::MessageDescriptor;
use pprz_transports::{AnyTransport, Decoder, DecoderStats};

use super::events::Logged;
use super::link::LinkTrack;
use super::{BUCKETS, Event, MIN_RATE_INTERVAL, Monitor, Notice, RATE_WINDOW};
use crate::input::Drops;
use crate::ping::PingTracker;
use crate::secure::GroundSecure;
use crate::set::RuntimeSet;
use crate::settings::{SettingTracker, Sweep};

/// A count of events per second over the last [`RATE_WINDOW`] seconds, kept in
/// [`BUCKETS`] fixed time buckets (constant memory, whatever the rate).
///
/// The rate is the count of the buckets that cover the window divided by the time they
/// cover up to now (the current bucket is partly elapsed), so a steady rate reads true
/// whenever it is read; no rate is given over less than [`MIN_RATE_INTERVAL`].
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Rate {
    /// `(bucket number, count)`; bucket `n` covers `[n, n + 1) * width`.
    buckets: [(i64, u64); BUCKETS],
}

impl Rate {
    const WIDTH: f64 = RATE_WINDOW / BUCKETS as f64;

    fn bucket(now: f64) -> i64 {
        // Saturating conversion; NaN is bucket 0.
        (now / Self::WIDTH).floor() as i64
    }

    pub(super) fn add(&mut self, now: f64, n: u64) {
        let b = Self::bucket(now);
        let slot = &mut self.buckets[b.rem_euclid(BUCKETS as i64) as usize];
        if slot.0 != b {
            *slot = (b, 0);
        }
        slot.1 = slot.1.saturating_add(n);
    }

    /// Events per second at `now` (time since the start of the run); `None` before
    /// [`MIN_RATE_INTERVAL`] has passed.
    pub(super) fn per_second(&self, now: f64) -> Option<f64> {
        let b = Self::bucket(now);
        let first = b.saturating_sub(BUCKETS as i64 - 1);
        // The time the buckets `first..=b` cover, from the start of the run at most.
        let covered = now - (first as f64 * Self::WIDTH).max(0.0);
        if covered.is_nan() || covered < MIN_RATE_INTERVAL {
            return None;
        }
        let n: u64 = self
            .buckets
            .iter()
            .filter(|(i, _)| *i <= b && *i >= first)
            .map(|(_, c)| *c)
            .sum();
        Some(n as f64 / covered)
    }
}

/// What the monitor knows about one message.
#[derive(Debug, Clone, Default)]
pub struct MessageStats {
    /// Message name (escaped).
    pub name: String,
    /// Class name (escaped).
    pub class: String,
    /// Priority from the message set.
    pub priority: u8,
    /// Messages received.
    pub count: u64,
    /// Arrivals in the last [`RATE_WINDOW`] seconds.
    recent: Rate,
    /// The latest fields, formatted and escaped (at most [`MAX_FIELDS_LEN`](crate::format::MAX_FIELDS_LEN)
    /// bytes).
    pub last: String,
}

impl MessageStats {
    /// Messages per second over the last [`RATE_WINDOW`] seconds; `None` before
    /// [`MIN_RATE_INTERVAL`] has passed (a rate over a shorter time means nothing).
    pub fn rate(&self, now: f64) -> Option<f64> {
        self.recent.per_second(now)
    }
}

/// What the monitor knows about one aircraft: the frames received from it (by source
/// id), its messages, and the PINGs and SETTINGs addressed to it.
///
/// Got from [`Monitor::aircraft_state`]; the ids tracked are [`Monitor::aircraft`].
#[derive(Debug, Clone)]
pub struct Aircraft {
    pub(super) id: u8,
    pub(super) frames: u64,
    pub(super) unknown: u64,
    pub(super) malformed: u64,
    pub(super) messages: BTreeMap<(u8, u8), MessageStats>,
    pub(super) pings: PingTracker,
    pub(super) settings: SettingTracker,
    pub(super) last_rtt: Option<f64>,
    pub(super) last_report: Option<String>,
    pub(super) link: LinkTrack,
    /// The latest value reported for each setting index (DL_VALUE).
    pub(super) values: BTreeMap<u8, f64>,
    /// The reading of every setting ([`Monitor::read_settings`]).
    pub(super) sweep: Option<Sweep>,
}

impl Aircraft {
    pub(super) fn new(id: u8, pings: &PingTracker, settings: &SettingTracker) -> Self {
        Self {
            id,
            frames: 0,
            unknown: 0,
            malformed: 0,
            messages: BTreeMap::new(),
            pings: PingTracker::new(pings.capacity(), pings.timeout()),
            settings: SettingTracker::new(settings.timeout()),
            last_rtt: None,
            last_report: None,
            link: LinkTrack::default(),
            values: BTreeMap::new(),
            sweep: None,
        }
    }

    /// The aircraft id (the source id of its frames).
    pub fn id(&self) -> u8 {
        self.id
    }

    /// Frames received from this aircraft (known, unknown and malformed messages).
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Messages from this aircraft whose class and id the set does not know.
    pub fn unknown(&self) -> u64 {
        self.unknown
    }

    /// Known messages from this aircraft whose payload did not match their definition.
    pub fn malformed(&self) -> u64 {
        self.malformed
    }

    /// Statistics per message of this aircraft, by (class, id).
    pub fn messages(&self) -> &BTreeMap<(u8, u8), MessageStats> {
        &self.messages
    }

    /// The PINGs sent to this aircraft ([`Monitor::ping_sent`] with an aircraft) and their PONGs.
    pub fn pings(&self) -> &PingTracker {
        &self.pings
    }

    /// The SETTING and GET_SETTING requests sent to this aircraft
    /// ([`Monitor::setting_sent`], [`Monitor::get_setting_sent`] with an aircraft).
    pub fn settings(&self) -> &SettingTracker {
        &self.settings
    }

    /// The latest value each setting index reported (DL_VALUE), in the aircraft's units;
    /// at most one per index.
    pub fn setting_values(&self) -> &BTreeMap<u8, f64> {
        &self.values
    }

    /// The reading of every setting ([`Monitor::read_settings`]), if one was started.
    pub fn sweep(&self) -> Option<&Sweep> {
        self.sweep.as_ref()
    }

    /// The latest round-trip time measured with a PONG from this aircraft, in seconds
    /// (of a PING sent to it, or of one sent to no particular aircraft).
    pub fn last_rtt(&self) -> Option<f64> {
        self.last_rtt
    }

    /// The time of the latest frame from this aircraft (the monitor's time); `None`
    /// when it was never heard. [`Monitor::link_quality`] tells more.
    pub fn last_heard(&self) -> Option<f64> {
        self.link.last_heard()
    }

    /// The fields of the latest DATALINK_REPORT of this aircraft (escaped).
    pub fn last_report(&self) -> Option<&str> {
        self.last_report.as_deref()
    }

    /// Messages received from this aircraft per priority level, most important first.
    pub fn per_priority(&self) -> BTreeMap<std::cmp::Reverse<u8>, u64> {
        per_priority(&self.messages)
    }

    /// The heap memory this aircraft's state holds, estimated.
    pub(super) fn retained_bytes(&self) -> usize {
        std::mem::size_of::<(u8, Self)>()
            + messages_bytes(&self.messages)
            + self.pings.capacity() * 8
            + self.settings.pending() * 64
            + self.last_report.as_ref().map_or(0, String::capacity)
            + self.link.retained_bytes()
            + self.values.len() * 48
            + self.sweep.as_ref().map_or(0, |s| s.total() * 24)
    }
}

/// Messages per priority level of `messages`, most important first.
fn per_priority(
    messages: &BTreeMap<(u8, u8), MessageStats>,
) -> BTreeMap<std::cmp::Reverse<u8>, u64> {
    let mut out = BTreeMap::new();
    for m in messages.values() {
        *out.entry(std::cmp::Reverse(m.priority)).or_insert(0) += m.count;
    }
    out
}

/// The heap memory of a table of message statistics, estimated.
fn messages_bytes(messages: &BTreeMap<(u8, u8), MessageStats>) -> usize {
    let per_message = std::mem::size_of::<((u8, u8), MessageStats)>() + 4 * 8;
    messages
        .values()
        .map(|m| per_message + m.name.capacity() + m.class.capacity() + m.last.capacity())
        .sum()
}

/// Counts a message `desc` received at `now` with fields `body` in `messages`.
pub(super) fn count_message(
    messages: &mut BTreeMap<(u8, u8), MessageStats>,
    desc: &MessageDescriptor<'_>,
    now: f64,
    body: String,
) {
    let entry = messages
        .entry((desc.class_id, desc.id))
        .or_insert_with(|| MessageStats {
            name: crate::escape::token(desc.name),
            class: crate::escape::token(desc.class_name),
            priority: desc.priority,
            ..MessageStats::default()
        });
    entry.count += 1;
    entry.recent.add(now, 1);
    entry.last = body;
}

impl Monitor {
    /// Whether the monitor tracks more than one aircraft (or frames from aircraft beyond
    /// [`MAX_AIRCRAFT`](super::MAX_AIRCRAFT) arrived): the live view then has a section per aircraft, and
    /// event lines name their aircraft.
    pub fn several_aircraft(&self) -> bool {
        self.aircraft.len() > 1 || self.untracked_frames > 0
    }

    /// The ids of the aircraft tracked, in ascending order: every source id of the
    /// frames received (the first [`MAX_AIRCRAFT`](super::MAX_AIRCRAFT) ones) and every aircraft addressed
    /// with [`ping_sent`](Self::ping_sent) and the other request methods.
    pub fn aircraft(&self) -> Vec<u8> {
        self.aircraft.keys().copied().collect()
    }

    /// What the monitor knows about aircraft `ac_id`; `None` when it is not tracked.
    pub fn aircraft_state(&self, ac_id: u8) -> Option<&Aircraft> {
        self.aircraft.get(&ac_id)
    }

    /// Frames from aircraft beyond [`MAX_AIRCRAFT`](super::MAX_AIRCRAFT), which are decoded and counted with
    /// all aircraft but not tracked one by one.
    pub fn untracked_frames(&self) -> u64 {
        self.untracked_frames
    }

    /// How many different source ids sent the [`untracked_frames`](Self::untracked_frames).
    pub fn untracked_aircraft(&self) -> u32 {
        self.untracked_ids.iter().map(|w| w.count_ones()).sum()
    }

    /// Input dropped under overload so far (see [`input_gap`](Self::input_gap)).
    pub fn input_dropped(&self) -> Drops {
        self.input_dropped
    }

    /// Statistics per message, by (class, id).
    pub fn messages(&self) -> &BTreeMap<(u8, u8), MessageStats> {
        &self.messages
    }

    /// The message set.
    pub fn set(&self) -> &RuntimeSet {
        &self.set
    }

    /// The decoder's counters (frames, checksum errors...).
    pub fn decoder_stats(&self) -> &DecoderStats {
        self.decoder.stats()
    }

    /// Messages whose class and id the set does not know.
    pub fn unknown(&self) -> u64 {
        self.unknown
    }

    /// Known messages whose payload did not match their definition.
    pub fn malformed(&self) -> u64 {
        self.malformed
    }

    /// Bytes received.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Messages received per priority level (all aircraft), most important first.
    pub fn per_priority(&self) -> BTreeMap<std::cmp::Reverse<u8>, u64> {
        per_priority(&self.messages)
    }

    /// Bytes per second over the last [`RATE_WINDOW`] seconds; `None` before
    /// [`MIN_RATE_INTERVAL`] has passed.
    pub fn byte_rate(&self, now: f64) -> Option<f64> {
        self.byte_rate.per_second(now)
    }

    /// An estimate of the heap memory the monitor holds, in bytes (the decoder's
    /// fixed buffer included): bounded by the size of the message set and the number of
    /// aircraft tracked (at most [`MAX_AIRCRAFT`](super::MAX_AIRCRAFT) from received frames, plus those the
    /// ground addressed), whatever the input.
    pub fn retained_bytes(&self) -> usize {
        messages_bytes(&self.messages)
            + self
                .aircraft
                .values()
                .map(Aircraft::retained_bytes)
                .sum::<usize>()
            + std::mem::size_of::<Decoder<AnyTransport>>()
            + self.last_report.as_ref().map_or(0, String::capacity)
            + self.events.capacity() * std::mem::size_of::<Logged<Event>>()
            + self.notices.capacity() * std::mem::size_of::<Logged<Notice>>()
            + self.pings.capacity() * 8
            + self.settings.pending() * 64
            + self
                .secure
                .as_ref()
                .map_or(0, |_| std::mem::size_of::<GroundSecure>() + 2048)
            + self.secure_out.iter().map(Vec::capacity).sum::<usize>()
    }
}
