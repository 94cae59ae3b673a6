//! What the simulation measures on its own clock (embassy-time's mock clock, the
//! aircraft's time, not wall time): when the application submitted each message, when
//! each message reached the ground end of the radio, and the PING round trips through
//! the radio.
//!
//! The age of a delivered message is the time from its submission (recorded through the
//! example application's [`Config::observer`](pprz_example_app::Config::observer)) to
//! its arrival at the ground end of the radio, where the ground bridge decodes it. A
//! message received is matched to a submission of the same class, id and identical
//! payload bytes; when several submissions have identical bytes (a constant message such
//! as ALIVE, or the payload flood, whose frames are all alike), the latest one before the
//! arrival is taken, so the age of such a message is a lower bound. Messages the
//! application did not submit itself (PONG, and DL_VALUE answering a SETTING, sent by the
//! services) have no submission of their own: PONG is measured by the PING round trip
//! instead, and a DL_VALUE answer matches the periodic DL_VALUE of the same setting and
//! value submitted since the SETTING went up, if there was one. Submissions older than
//! [`HORIZON_S`] are forgotten, so a message waiting longer than that counts as received
//! but not aged.
//!
//! Per aircraft, it also keeps the changes of its link health (recorded from the
//! aircraft's side by [`crate::link`]), and what the ground saw: the `ap_mode` of its
//! ROTORCRAFT_STATUS messages and the times it heard nothing from it.

use std::cell::Cell;
use std::collections::{BTreeMap, HashMap};
use std::future::{Future, poll_fn};
use std::pin::pin;
use std::sync::{LazyLock, Mutex, MutexGuard};

use embassy_time::Instant;
use pprz_default::messages::MESSAGES;
use pprz_default::messages::datalink::{Ping, Setting};
use pprz_default::messages::telemetry::{DlValue, Pong, RotorcraftStatus};
use pprz_example_app::AC_ID;
use pprz_ground::ping::PingTracker;
use pprz_messages::{Decode, Message};
use pprz_telemetry::health::Health;
use pprz_telemetry::pprz_messages::priority;

use pprz_devices::rng::SplitMix64;

/// Seconds (simulated) a submission is remembered for matching.
pub const HORIZON_S: u64 = 120;

/// Most samples kept per distribution; beyond, a uniform sample of them (reservoir), so
/// a long run keeps bounded memory and unbiased percentiles.
const MAX_SAMPLES: usize = 1 << 20;

/// A distribution of durations, in microseconds.
#[derive(Debug, Clone)]
pub struct Samples {
    values: Vec<u64>,
    /// Values offered (kept or not).
    seen: u64,
    /// The reservoir's random generator (fixed seed: runs are reproducible).
    rng: SplitMix64,
}

impl Default for Samples {
    fn default() -> Self {
        Self {
            values: Vec::new(),
            seen: 0,
            rng: SplitMix64::new(0),
        }
    }
}

impl Samples {
    /// Adds one duration.
    pub fn push(&mut self, micros: u64) {
        self.seen += 1;
        if self.values.len() < MAX_SAMPLES {
            self.values.push(micros);
            return;
        }
        // Reservoir sampling (algorithm R): keep the new value with probability
        // MAX_SAMPLES / seen, in place of a random one.
        let slot = self.rng.next_u64() % self.seen;
        if let Some(v) = usize::try_from(slot)
            .ok()
            .and_then(|i| self.values.get_mut(i))
        {
            *v = micros;
        }
    }

    /// Durations offered.
    pub fn count(&self) -> u64 {
        self.seen
    }

    /// The `p`-th percentile (nearest rank, `p` in 0..=100), in milliseconds, or `None`
    /// without samples.
    pub fn percentile_ms(&self, p: f64) -> Option<f64> {
        let mut sorted = self.values.clone();
        sorted.sort_unstable();
        let n = sorted.len();
        if n == 0 {
            return None;
        }
        let rank = ((p / 100.0) * n as f64).ceil() as usize;
        let v = sorted[rank.clamp(1, n) - 1];
        Some(v as f64 / 1000.0)
    }
}

/// What the ground end of the radio received at one priority level.
#[derive(Debug, Clone, Default)]
pub struct LevelRecord {
    /// Messages decoded at the ground end of the radio.
    pub received: u64,
    /// Ages (submission to arrival) of the messages matched to a submission.
    pub ages: Samples,
    /// Matches among them to a payload submitted more than once (their age is a lower
    /// bound).
    pub ambiguous: u64,
}

/// One message type: submitted by the application, received at the ground end of the
/// radio.
#[derive(Debug, Clone, Copy, Default)]
pub struct TypeRecord {
    /// Messages the application submitted (the services' replies are not seen).
    pub submitted: u64,
    /// Messages decoded.
    pub received: u64,
    /// Last arrival, in microseconds.
    last_us: u64,
    /// Longest time between two arrivals, in microseconds (0 before the second).
    pub max_gap_us: u64,
}

/// A distinct message submitted: aircraft, class, id and payload.
type SubmissionKey = (u8, u8, u8, Vec<u8>);

/// Everything measured; one per process ([`lock`]).
#[derive(Debug, Default)]
pub struct Record {
    /// Latest submission time (µs) of each distinct message (aircraft, class, id,
    /// payload), and how many times it was submitted.
    submissions: HashMap<SubmissionKey, (u64, u32)>,
    /// Submissions recorded since the last pruning.
    since_prune: usize,
    /// Per level (high, normal, low).
    pub levels: [LevelRecord; 3],
    /// Messages received whose class and id the message set does not know.
    pub unknown: u64,
    /// Per message type (class, id).
    pub types: BTreeMap<(u8, u8), TypeRecord>,
    /// PINGs that went up the radio and the PONGs that came down.
    pub pings: PingTracker,
    /// PING round trips through the radio.
    pub rtt: Samples,
    /// Per aircraft (by id): what it submitted and what reached the ground from it, and
    /// its PINGs. The figures above are the radio's: every aircraft together, and the
    /// PINGs of the first aircraft.
    pub aircraft: BTreeMap<u8, AircraftRecord>,
}

/// One aircraft of the fleet.
#[derive(Debug, Default)]
pub struct AircraftRecord {
    /// Messages its application submitted, per level.
    pub submitted: [u64; 3],
    /// Messages from it decoded at the ground end of the radio, per level.
    pub received: [u64; 3],
    /// PINGs to it and its PONGs.
    pub pings: PingTracker,
    /// Their round trips.
    pub rtt: Samples,
    /// Its link health's changes (µs, new state), as the aircraft saw them.
    pub health: Vec<(u64, Health)>,
    /// Its `ap_mode` as the ground saw it: the first ROTORCRAFT_STATUS, then each one
    /// that changed it (µs, raw `ap_mode`).
    pub ap_modes: Vec<(u64, u8)>,
    /// When the ground last received a message from it (µs).
    pub last_heard_us: Option<u64>,
    /// Times the ground heard nothing from it for more than [`SILENCE_US`]: the last
    /// message before and the first after (µs).
    pub silences: Vec<(u64, u64)>,
    /// Health changes, `ap_mode` changes and silences past the first [`MAX_EVENTS`] of
    /// each, counted but not kept.
    pub omitted: u64,
}

/// Events an aircraft's record keeps per list (health changes, `ap_mode` changes,
/// silences): the first ones; later ones are counted in [`AircraftRecord::omitted`], so
/// the record of a long run stays bounded.
pub const MAX_EVENTS: usize = 10_000;

/// Appends `event` to `list` if it holds fewer than [`MAX_EVENTS`], else counts it.
fn keep<T>(list: &mut Vec<T>, omitted: &mut u64, event: T) {
    if list.len() < MAX_EVENTS {
        list.push(event);
    } else {
        *omitted = omitted.saturating_add(1);
    }
}

/// A gap between two messages from an aircraft longer than this (µs) is a silence in
/// the summary (its telemetry comes several times a second).
pub const SILENCE_US: u64 = 1_000_000;

impl AircraftRecord {
    /// A message from the aircraft reached the ground at `now_us`: ends a silence.
    fn heard(&mut self, now_us: u64) {
        if let Some(last) = self.last_heard_us
            && now_us.saturating_sub(last) > SILENCE_US
        {
            keep(&mut self.silences, &mut self.omitted, (last, now_us));
        }
        self.last_heard_us = Some(now_us);
    }

    /// A ROTORCRAFT_STATUS from the aircraft with `payload` reached the ground at
    /// `now_us`: its `ap_mode`, kept if it changed.
    fn status(&mut self, payload: &[u8], now_us: u64) {
        let Ok(status) = RotorcraftStatus::decode(payload) else {
            return;
        };
        if self.ap_modes.last().map(|&(_, m)| m) != Some(status.ap_mode) {
            keep(
                &mut self.ap_modes,
                &mut self.omitted,
                (now_us, status.ap_mode),
            );
        }
    }
}

static RECORD: LazyLock<Mutex<Record>> = LazyLock::new(Mutex::default);

/// The record (a panic elsewhere does not make it unreadable).
pub fn lock() -> MutexGuard<'static, Record> {
    RECORD
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

thread_local! {
    /// The aircraft whose application the executor's thread is running now
    /// ([`as_aircraft`]); [`AC_ID`] outside.
    static CURRENT: Cell<u8> = const { Cell::new(AC_ID) };
}

/// Runs `application` as aircraft `ac`'s: while it runs, what it submits is recorded
/// as `ac`'s ([`submitted`], the observer every aircraft's application is given, is a
/// plain function that cannot tell them apart otherwise).
pub async fn as_aircraft<F: Future>(ac: u8, application: F) -> F::Output {
    let mut application = pin!(application);
    poll_fn(|cx| {
        let outside = CURRENT.replace(ac);
        let poll = application.as_mut().poll(cx);
        CURRENT.set(outside);
        poll
    })
    .await
}

/// The observer given to every aircraft's application: the message
/// `class_id`/`msg_id` with fields `payload` was submitted at `now` by the aircraft
/// running ([`as_aircraft`]).
pub fn submitted(class_id: u8, msg_id: u8, payload: &[u8], now: Instant) {
    let ac = CURRENT.get();
    lock().submitted(ac, class_id, msg_id, payload, now.as_micros());
}

/// A frame from the ground to `destination` with `payload` went up the radio at `now`:
/// tracked if it is a PING. A SETTING makes the DL_VALUE of its setting and value
/// submitted before it unmatchable: the acknowledgement is not that old one.
pub fn uplink(destination: u8, class_id: u8, msg_id: u8, payload: &[u8], now: Instant) {
    if (class_id, msg_id) == (Setting::CLASS_ID, Setting::ID)
        && let Ok(setting) = Setting::decode(payload)
    {
        let answer = DlValue {
            index: setting.index,
            value: setting.value,
        };
        let mut fields = [0u8; 8];
        if let Ok(len) = answer.encode(&mut fields) {
            let key = (
                destination,
                DlValue::CLASS_ID,
                DlValue::ID,
                fields[..len].to_vec(),
            );
            lock().submissions.remove(&key);
        }
    }
    if (class_id, msg_id) == (Ping::CLASS_ID, Ping::ID) {
        let mut record = lock();
        let t = seconds(now.as_micros());
        if destination == AC_ID {
            record.pings.sent(t);
        }
        record
            .aircraft
            .entry(destination)
            .or_default()
            .pings
            .sent(t);
    }
}

/// The link health of aircraft `ac` became `state` at `at`.
pub fn health(ac: u8, at: Instant, state: Health) {
    let mut record = lock();
    let r = record.aircraft.entry(ac).or_default();
    keep(&mut r.health, &mut r.omitted, (at.as_micros(), state));
}

/// A message from `source` arrived at the ground end of the radio at `now`.
pub fn received(source: u8, class_id: u8, msg_id: u8, payload: &[u8], now: Instant) {
    lock().received(source, class_id, msg_id, payload, now.as_micros());
}

fn seconds(micros: u64) -> f64 {
    micros as f64 / 1e6
}

impl Record {
    fn submitted(&mut self, ac_id: u8, class_id: u8, msg_id: u8, payload: &[u8], now_us: u64) {
        if let Some(desc) = MESSAGES.find(class_id, msg_id) {
            self.aircraft.entry(ac_id).or_default().submitted[priority::level(desc.priority)] += 1;
        }
        let entry = self
            .submissions
            .entry((ac_id, class_id, msg_id, payload.to_vec()))
            .or_insert((now_us, 0));
        *entry = (now_us, entry.1.saturating_add(1));
        self.types.entry((class_id, msg_id)).or_default().submitted += 1;
        self.since_prune += 1;
        // Now and then, forget the submissions past the horizon.
        if self.since_prune >= 4096 && self.submissions.len() >= 65_536 {
            let oldest = now_us.saturating_sub(HORIZON_S * 1_000_000);
            self.submissions.retain(|_, (at, _)| *at >= oldest);
            self.since_prune = 0;
        }
    }

    fn received(&mut self, source: u8, class_id: u8, msg_id: u8, payload: &[u8], now_us: u64) {
        let Some(desc) = MESSAGES.find(class_id, msg_id) else {
            self.unknown += 1;
            return;
        };
        // Only the fleet's aircraft get a record (a forged source cannot grow it).
        if let Some(aircraft) = self.aircraft.get_mut(&source) {
            aircraft.received[priority::level(desc.priority)] += 1;
            aircraft.heard(now_us);
            if (class_id, msg_id) == (RotorcraftStatus::CLASS_ID, RotorcraftStatus::ID) {
                aircraft.status(payload, now_us);
            }
            if (class_id, msg_id) == (Pong::CLASS_ID, Pong::ID)
                && let Some(rtt) = aircraft.pings.pong(seconds(now_us))
            {
                aircraft.rtt.push((rtt * 1e6).round() as u64);
            }
        }
        let level = &mut self.levels[priority::level(desc.priority)];
        level.received += 1;
        let t = self.types.entry((class_id, msg_id)).or_default();
        if t.received > 0 {
            t.max_gap_us = t.max_gap_us.max(now_us.saturating_sub(t.last_us));
        }
        t.received += 1;
        t.last_us = now_us;
        // The key is rebuilt for the lookup: a HashMap of owned keys is not searched by
        // borrowed tuples.
        let key = (source, class_id, msg_id, payload.to_vec());
        if let Some(&(at, times)) = self.submissions.get(&key)
            && now_us.saturating_sub(at) <= HORIZON_S * 1_000_000
        {
            level.ages.push(now_us.saturating_sub(at));
            if times > 1 {
                level.ambiguous += 1;
            }
        }
        if (class_id, msg_id) == (Pong::CLASS_ID, Pong::ID)
            && source == AC_ID
            && let Some(rtt) = self.pings.pong(seconds(now_us))
        {
            self.rtt.push((rtt * 1e6).round() as u64);
        }
    }
}

#[cfg(test)]
mod tests {
    use pprz_default::messages::telemetry::Attitude;

    use super::*;

    #[test]
    fn an_aircraft_keeps_its_first_events_and_counts_the_rest() {
        let mut r = AircraftRecord::default();
        // A silence of 2 s between each two messages.
        for k in 0..=(MAX_EVENTS as u64 + 5) {
            r.heard(k * 2 * SILENCE_US);
        }
        assert_eq!(r.silences.len(), MAX_EVENTS);
        assert_eq!(r.silences[0], (0, 2 * SILENCE_US));
        assert_eq!(r.omitted, 5);
    }

    #[test]
    fn percentiles_are_nearest_rank() {
        let mut s = Samples::default();
        assert_eq!(s.percentile_ms(50.0), None);
        for us in (1..=100).rev() {
            s.push(us * 1000);
        }
        assert_eq!(s.count(), 100);
        assert_eq!(s.percentile_ms(50.0), Some(50.0));
        assert_eq!(s.percentile_ms(99.0), Some(99.0));
        assert_eq!(s.percentile_ms(0.0), Some(1.0));
        assert_eq!(s.percentile_ms(100.0), Some(100.0));
    }

    #[test]
    fn an_arrival_matches_the_latest_identical_submission() {
        let mut r = Record::default();
        let (class, id) = (Attitude::CLASS_ID, Attitude::ID);
        let level = priority::level(Attitude::PRIORITY);
        r.submitted(AC_ID, class, id, &[1, 2], 1_000);
        r.submitted(AC_ID, class, id, &[3, 4], 2_000);
        r.submitted(AC_ID, class, id, &[1, 2], 5_000);
        // [3, 4] was submitted once: exact; [1, 2] twice: from the latest, ambiguous.
        r.received(AC_ID, class, id, &[3, 4], 12_000);
        r.received(AC_ID, class, id, &[1, 2], 13_000);
        // Never submitted: received, not aged.
        r.received(AC_ID, class, id, &[9], 14_000);
        let l = &r.levels[level];
        assert_eq!((l.received, l.ages.count(), l.ambiguous), (3, 2, 1));
        assert_eq!(l.ages.percentile_ms(0.0), Some(8.0));
        assert_eq!(l.ages.percentile_ms(100.0), Some(10.0));
        let t = r.types[&(class, id)];
        assert_eq!((t.submitted, t.received, t.max_gap_us), (3, 3, 1_000));
        let a = &r.aircraft[&AC_ID];
        assert_eq!((a.submitted[level], a.received[level]), (3, 3));
        // A source that is not an aircraft of the fleet gets no record.
        r.received(99, class, id, &[9], 15_000);
        assert!(!r.aircraft.contains_key(&99));
    }

    #[test]
    fn pong_arrivals_time_the_pings() {
        let mut r = Record::default();
        r.pings.sent(1.0);
        r.received(AC_ID, Pong::CLASS_ID, Pong::ID, &[], 1_030_000);
        assert_eq!(r.pings.answered(), 1);
        assert_eq!(r.rtt.percentile_ms(50.0), Some(30.0));
        // Unknown message types are counted apart.
        r.received(AC_ID, 0xEE, 0xEE, &[], 2_000_000);
        assert_eq!(r.unknown, 1);
    }
}
