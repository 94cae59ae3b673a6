//! What the live view shows on lines of their own: events (round trips, DL_VALUEs,
//! secure sessions) and notices (what went wrong), the latest ones kept.

use std::collections::VecDeque;

use pprz_secure::{HandshakeError, Reject};

use super::{MAX_EVENTS, Monitor};
use crate::input::Drops;
use crate::settings::{Answer, Expired};

/// Events worth a line of their own in the live view.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A PONG arrived `rtt` seconds after the PING it answers (the oldest outstanding).
    Pong {
        /// Round-trip time in seconds.
        rtt: f64,
    },
    /// A DL_VALUE arrived; `answer` tells whether it acknowledges a pending SETTING
    /// (with the value set), reports it not applied (another value), or answers a
    /// GET_SETTING.
    DlValue {
        /// Setting index.
        index: u8,
        /// Value reported by the aircraft.
        value: f64,
        /// What it means for the requests pending on this index.
        answer: Answer,
    },
    /// The reading of every setting of an aircraft ([`Monitor::read_settings`]) ended.
    SettingsRead {
        /// Settings read.
        read: usize,
        /// Settings in the sweep.
        total: usize,
        /// Seconds from its first request to its end.
        seconds: f64,
        /// The indices without an answer, in order.
        failed: Vec<u8>,
    },
    /// A secure session was set up with the aircraft (handshake completed).
    SecureSession {
        /// Handshakes completed so far.
        completed: u32,
    },
}

/// Things that went wrong (and a link's return), worth a line of their own in the live
/// view.
#[derive(Debug, Clone, PartialEq)]
pub enum Notice {
    /// PINGs counted as lost (no PONG within the timeout, or too many outstanding).
    PingsLost {
        /// How many.
        count: u64,
    },
    /// A PONG that answers no PING outstanding.
    UnexpectedPong,
    /// A SETTING or GET_SETTING given up after the timeout.
    RequestExpired(Expired),
    /// Input dropped under overload before the bytes that followed.
    InputDropped(Drops),
    /// Frames rejected by the secure link (not decoded): `count` in a row for the same
    /// reason within a second share one notice.
    SecureRejected {
        /// Why.
        reason: Reject,
        /// How many.
        count: u64,
    },
    /// A key-exchange message from the aircraft refused (forged, malformed, unexpected).
    HandshakeRefused(HandshakeError),
    /// No frame from the aircraft for the stale time
    /// ([`Monitor::stale_after`](super::Monitor::stale_after)): its link is stale.
    LinkStale {
        /// The aircraft.
        aircraft: u8,
        /// Seconds since its latest frame.
        silent: f64,
    },
    /// A frame from a stale aircraft: its link is live again.
    LinkLive {
        /// The aircraft.
        aircraft: u8,
        /// Seconds it was silent.
        silent: f64,
    },
}

/// An event or notice, the aircraft it concerns (if any), and when it happened.
#[derive(Debug, Clone)]
pub(super) struct Logged<T> {
    pub(super) aircraft: Option<u8>,
    pub(super) entry: (f64, T),
}

/// Pushes `item` about `aircraft` at time `now`, keeping the latest [`MAX_EVENTS`].
fn push_bounded<T>(queue: &mut VecDeque<Logged<T>>, now: f64, aircraft: Option<u8>, item: T) {
    if queue.len() >= MAX_EVENTS {
        queue.pop_front();
    }
    queue.push_back(Logged {
        aircraft,
        entry: (now, item),
    });
}

impl Monitor {
    pub(super) fn event(&mut self, now: f64, aircraft: Option<u8>, event: Event) {
        self.event_count += 1;
        push_bounded(&mut self.events, now, aircraft, event);
    }

    pub(super) fn notice(&mut self, now: f64, aircraft: Option<u8>, notice: Notice) {
        self.notice_count += 1;
        push_bounded(&mut self.notices, now, aircraft, notice);
    }

    /// Events so far (more than [`events`](Self::events) keeps): the latest
    /// `event_count() - n` events are the ones after the first `n`.
    pub fn event_count(&self) -> u64 {
        self.event_count
    }

    /// Notices so far (more than [`notices`](Self::notices) keeps).
    pub fn notice_count(&self) -> u64 {
        self.notice_count
    }

    /// The latest events (PONG round trips, DL_VALUEs), oldest first; at most
    /// [`MAX_EVENTS`]. [`events_with_aircraft`](Self::events_with_aircraft) tells which
    /// aircraft each one is about.
    pub fn events(&self) -> impl Iterator<Item = &(f64, Event)> {
        self.events.iter().map(|l| &l.entry)
    }

    /// The latest events as [`events`](Self::events) gives them, with the aircraft each
    /// is about: `(time, aircraft, event)`. The aircraft is the source of the PONG or
    /// DL_VALUE, or the aircraft of the secure link.
    pub fn events_with_aircraft(&self) -> impl Iterator<Item = (f64, Option<u8>, &Event)> {
        self.events
            .iter()
            .map(|l| (l.entry.0, l.aircraft, &l.entry.1))
    }

    /// The latest notices (PINGs lost, requests given up, input dropped), oldest first;
    /// at most [`MAX_EVENTS`].
    pub fn notices(&self) -> impl Iterator<Item = &(f64, Notice)> {
        self.notices.iter().map(|l| &l.entry)
    }

    /// The latest notices as [`notices`](Self::notices) gives them, with the aircraft
    /// each is about (`None`: the link, or requests to no particular aircraft).
    pub fn notices_with_aircraft(&self) -> impl Iterator<Item = (f64, Option<u8>, &Notice)> {
        self.notices
            .iter()
            .map(|l| (l.entry.0, l.aircraft, &l.entry.1))
    }
}
