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
//! PINGs and SETTINGs can be addressed to an aircraft ([`Monitor::ping_sent_to`],
//! [`Monitor::setting_value_sent_to`], [`Monitor::get_setting_sent_to`]): a PONG from
//! aircraft N answers only a PING sent to N, a DL_VALUE from N only a request sent to N.
//! The forms without an aircraft ([`Monitor::ping_sent`], [`Monitor::setting_value_sent`],
//! ...) are for a single aircraft: a PONG or DL_VALUE from any aircraft answers them, when
//! no request addressed to that aircraft is waiting. Only PONGs and DL_VALUEs addressed to
//! the ground (destination 0, broadcast, or none with PPRZ v1) answer anything: one
//! aircraft's answer to another, seen on a shared link, does not.
//!
//! # Bounds
//!
//! Every piece of state is bounded, whatever arrives: one entry per message of the set
//! (with its latest fields cut at [`format::MAX_FIELDS_LEN`]) for all aircraft and one per
//! message and tracked aircraft, rates counted in fixed time buckets, at most
//! [`MAX_EVENTS`] events and notices, at most [`crate::ping::MAX_OUTSTANDING`] PINGs and
//! 256 requests outstanding per aircraft. Received frames make the monitor track at most
//! [`MAX_AIRCRAFT`] aircraft: frames from further source ids are decoded, shown and
//! counted with all aircraft and in [`Monitor::untracked_frames`], but get no table of
//! their own (a flood of frames from every source id costs nothing more). Aircraft the
//! ground addresses are tracked whatever the input. The worst case is
//! `(MAX_AIRCRAFT + 1) * messages in the set` entries of at most about 4 KiB each (tens of
//! MiB for the 367 messages of the full PPRZLINK set, every one sent by 32 aircraft with
//! fields that print to the longest text; a few hundred bytes per entry in practice);
//! [`retained_bytes`](Monitor::retained_bytes) estimates the total.
//!
//! Everything printed is escaped ([`escape`](crate::escape)): no line contains a
//! control character.

use std::collections::{BTreeMap, VecDeque};
use std::fmt::Write as _;

use pprz_messages::dynamic;
use pprz_messages::{BaseType, FieldType, MessageDescriptor};
use pprz_secure::{HandshakeError, Reject, SealError};
use pprz_transports::{
    AnyTransport, BROADCAST_ID, Decoder, DecoderStats, Framing, GROUND_ID, PprzV2,
};

use crate::format;
use crate::input::Drops;
use crate::ping::PingTracker;
use crate::secure::{GroundSecure, HandshakeEvent, Incoming, SecureSetupError, SecureStatus};
use crate::set::RuntimeSet;
use crate::settings::{Answer, Expired, SettingTracker};

/// How long a window the rates are computed over, in seconds.
pub const RATE_WINDOW: f64 = 5.0;

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
/// the ground addresses (PING, SETTING) are tracked beyond this bound.
pub const MAX_AIRCRAFT: usize = 32;

/// Seconds during which rejections of the same reason share one notice.
const REJECT_COALESCE: f64 = 1.0;

/// Time buckets of a rate.
const BUCKETS: usize = 10;

/// A count of events per second over the last [`RATE_WINDOW`] seconds, kept in
/// [`BUCKETS`] fixed time buckets (constant memory, whatever the rate).
#[derive(Debug, Clone, Copy, Default)]
struct Rate {
    /// `(bucket number, count)`; bucket `n` covers `[n, n + 1) * width`.
    buckets: [(i64, u64); BUCKETS],
}

impl Rate {
    const WIDTH: f64 = RATE_WINDOW / BUCKETS as f64;

    fn bucket(now: f64) -> i64 {
        // Saturating conversion; NaN is bucket 0.
        (now / Self::WIDTH).floor() as i64
    }

    fn add(&mut self, now: f64, n: u64) {
        let b = Self::bucket(now);
        let slot = &mut self.buckets[b.rem_euclid(BUCKETS as i64) as usize];
        if slot.0 != b {
            *slot = (b, 0);
        }
        slot.1 = slot.1.saturating_add(n);
    }

    fn per_second(&self, now: f64) -> f64 {
        let b = Self::bucket(now);
        let oldest = b.saturating_sub(BUCKETS as i64);
        let n: u64 = self
            .buckets
            .iter()
            .filter(|(i, _)| *i <= b && *i > oldest)
            .map(|(_, c)| *c)
            .sum();
        n as f64 / RATE_WINDOW.min(now.max(1e-9))
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
    /// The latest fields, formatted and escaped (at most [`format::MAX_FIELDS_LEN`]
    /// bytes).
    pub last: String,
}

impl MessageStats {
    /// Messages per second over the last [`RATE_WINDOW`] seconds.
    pub fn rate(&self, now: f64) -> f64 {
        self.recent.per_second(now)
    }
}

/// What the monitor knows about one aircraft: the frames received from it (by source
/// id), its messages, and the PINGs and SETTINGs addressed to it.
///
/// Got from [`Monitor::aircraft_state`]; the ids tracked are [`Monitor::aircraft`].
#[derive(Debug, Clone)]
pub struct Aircraft {
    id: u8,
    frames: u64,
    unknown: u64,
    malformed: u64,
    messages: BTreeMap<(u8, u8), MessageStats>,
    pings: PingTracker,
    settings: SettingTracker,
    last_rtt: Option<f64>,
    last_report: Option<String>,
}

impl Aircraft {
    fn new(id: u8, pings: &PingTracker, settings: &SettingTracker) -> Self {
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

    /// The PINGs sent to this aircraft ([`Monitor::ping_sent_to`]) and their PONGs.
    pub fn pings(&self) -> &PingTracker {
        &self.pings
    }

    /// The SETTING and GET_SETTING requests sent to this aircraft
    /// ([`Monitor::setting_value_sent_to`], [`Monitor::get_setting_sent_to`]).
    pub fn settings(&self) -> &SettingTracker {
        &self.settings
    }

    /// The latest round-trip time measured with a PONG from this aircraft, in seconds
    /// (of a PING sent to it, or of one sent to no particular aircraft).
    pub fn last_rtt(&self) -> Option<f64> {
        self.last_rtt
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
    fn retained_bytes(&self) -> usize {
        std::mem::size_of::<(u8, Self)>()
            + messages_bytes(&self.messages)
            + self.pings.capacity() * 8
            + self.settings.pending() * 64
            + self.last_report.as_ref().map_or(0, String::capacity)
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
fn count_message(
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
    /// A secure session was set up with the aircraft (handshake completed).
    SecureSession {
        /// Handshakes completed so far.
        completed: u32,
    },
}

/// Things that went wrong, worth a line of their own in the live view.
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
}

/// An event or notice, the aircraft it concerns (if any), and when it happened.
#[derive(Debug, Clone)]
struct Logged<T> {
    aircraft: Option<u8>,
    entry: (f64, T),
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

/// The decoding monitor.
pub struct Monitor {
    set: RuntimeSet,
    decoder: Decoder<AnyTransport>,
    /// All aircraft together.
    messages: BTreeMap<(u8, u8), MessageStats>,
    aircraft: BTreeMap<u8, Aircraft>,
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
}

/// The scalar type of field `name` of `desc`.
fn scalar_type(desc: Option<&MessageDescriptor<'_>>, name: &str) -> Option<BaseType> {
    desc?.fields.iter().find_map(|f| match f.ty {
        FieldType::Scalar(base) if f.name == name => Some(base),
        _ => None,
    })
}

impl Monitor {
    /// A monitor decoding `transport` frames with the messages of `set`.
    pub fn new(set: RuntimeSet, transport: AnyTransport) -> Self {
        Self {
            set,
            decoder: Decoder::new(transport),
            messages: BTreeMap::new(),
            aircraft: BTreeMap::new(),
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
        }
    }

    /// The same monitor on a secure link: every frame is opened by `secure` first
    /// (frames that fail are counted and noted, never decoded), the key exchange is
    /// handled, and [`poll_secure`](Self::poll_secure) and
    /// [`seal_uplink`](Self::seal_uplink) give the frames to write.
    ///
    /// # Errors
    /// [`SecureSetupError::NotPprzV2`]: the monitor's transport is not PPRZ v2.
    pub fn with_secure(mut self, secure: GroundSecure) -> Result<Self, SecureSetupError> {
        if !matches!(self.decoder.framing(), AnyTransport::PprzV2(_)) {
            return Err(SecureSetupError::NotPprzV2);
        }
        self.secure = Some(secure);
        Ok(self)
    }

    /// The frames to write to the aircraft at `now` for the secure link: handshake
    /// replies produced by the frames received, then what the handshake sends on its own
    /// (message 1 and its repeats). Call it every loop iteration (at least every 100 ms
    /// or so); empty without a secure link.
    pub fn poll_secure(&mut self, now: f64) -> Vec<Vec<u8>> {
        let mut out: Vec<Vec<u8>> = self.secure_out.drain(..).collect();
        if let Some(secure) = &mut self.secure
            && let Some(frame) = secure.poll(millis(now))
        {
            out.push(frame);
        }
        out
    }

    /// An uplink frame (PING, SETTING...) ready to write: sealed on a secure link,
    /// unchanged otherwise.
    ///
    /// # Errors
    /// On a secure link, [`SealError::NoSession`] before the handshake has completed
    /// (and the other [`SealError`]s); the frame must not be sent.
    pub fn seal_uplink(&mut self, frame: &[u8]) -> Result<Vec<u8>, SealError> {
        match &mut self.secure {
            Some(secure) => secure.seal(frame),
            None => Ok(frame.to_vec()),
        }
    }

    /// The secure link's state and counters; `None` without a secure link.
    pub fn secure_status(&self) -> Option<SecureStatus> {
        self.secure.as_ref().map(GroundSecure::status)
    }

    /// Whether uplink frames can be sent: always without a secure link, once the
    /// session keys are installed with one.
    pub fn uplink_ready(&self) -> bool {
        self.secure.as_ref().is_none_or(GroundSecure::has_session)
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

    /// Feeds received bytes at time `now`; `on_message` gets each decoded message
    /// ([`Decoded`]: its text line, escaped and without control characters, the raw
    /// frame bytes for recording, and the decoded form for viewers).
    pub fn feed(&mut self, now: f64, bytes: &[u8], mut on_message: impl FnMut(&Decoded<'_>)) {
        self.bytes += bytes.len() as u64;
        self.byte_rate.add(now, bytes.len() as u64);
        let mut input = bytes;
        while let Some(frame) = self.decoder.feed(&mut input) {
            let received = Received::of(&frame);
            self.deliver(now, received, &mut on_message);
        }
    }

    /// End of input: decodes frames held behind an incomplete false start.
    pub fn flush(&mut self, now: f64, mut on_message: impl FnMut(&Decoded<'_>)) {
        while let Some(frame) = self.decoder.flush() {
            let received = Received::of(&frame);
            self.deliver(now, received, &mut on_message);
        }
    }

    /// Decodes a received frame, after opening it on a secure link.
    fn deliver(&mut self, now: f64, frame: Received, on_message: &mut impl FnMut(&Decoded<'_>)) {
        let Some(secure) = &mut self.secure else {
            let handled = self.handle(now, &frame.header, &frame.payload);
            on_message(&handled.decoded(&frame.header, &frame.payload, &frame.raw, frame.log_time));
            return;
        };
        match secure.open(&frame.data, millis(now)) {
            Incoming::Plain(plain) => match PprzV2::new().view(&plain) {
                Ok(f) => {
                    let header = Header::of(&f);
                    let payload = f.payload().to_vec();
                    let handled = self.handle(now, &header, &payload);
                    on_message(&handled.decoded(&header, &payload, &plain, None));
                }
                // The channel gives well-formed frames only.
                Err(_) => self.secure_rejected(now, Reject::Malformed),
            },
            Incoming::Handshake { event, reply } => {
                if let Some(reply) = reply {
                    if self.secure_out.len() >= MAX_SECURE_OUT {
                        self.secure_out.pop_front();
                    }
                    self.secure_out.push_back(reply);
                }
                match event {
                    HandshakeEvent::Established => {
                        let completed = secure.status().stats.handshake.completed;
                        let ac = self.secure.as_ref().map(GroundSecure::ac_id);
                        self.event(now, ac, Event::SecureSession { completed });
                    }
                    HandshakeEvent::Resend => {}
                    HandshakeEvent::Refused(HandshakeError::Duplicate) => {}
                    HandshakeEvent::Refused(e) => {
                        let ac = self.secure.as_ref().map(GroundSecure::ac_id);
                        self.notice(now, ac, Notice::HandshakeRefused(e));
                    }
                }
            }
            Incoming::Rejected(reason) => self.secure_rejected(now, reason),
        }
    }

    /// Notes a rejected secure frame; a run of rejections for one reason shares a notice.
    fn secure_rejected(&mut self, now: f64, reason: Reject) {
        if let Some(Logged {
            entry: (at, Notice::SecureRejected { reason: r, count }),
            ..
        }) = self.notices.back_mut()
            && *r == reason
            && now - *at < REJECT_COALESCE
        {
            *count = count.saturating_add(1);
            return;
        }
        self.notice(now, None, Notice::SecureRejected { reason, count: 1 });
    }

    /// Input was dropped under overload just before the next bytes: counts it, notes it
    /// for the live view, and abandons the frame being assembled (its end was dropped),
    /// decoding the frames buffered behind it, as [`flush`](Self::flush) does.
    pub fn input_gap(&mut self, now: f64, dropped: Drops, on_message: impl FnMut(&Decoded<'_>)) {
        if dropped.is_empty() {
            return;
        }
        self.input_dropped.bytes += dropped.bytes;
        self.input_dropped.reads += dropped.reads;
        self.input_gaps += 1;
        self.notice(now, None, Notice::InputDropped(dropped));
        self.flush(now, on_message);
    }

    /// Counts a frame from aircraft `source`, tracked (created while fewer than
    /// [`MAX_AIRCRAFT`] are) or not.
    fn admit(&mut self, source: u8) {
        if !self.aircraft.contains_key(&source) && self.aircraft.len() >= MAX_AIRCRAFT {
            self.untracked_frames += 1;
            self.untracked_ids[usize::from(source / 64)] |= 1 << (source % 64);
            return;
        }
        let (pings, settings) = (&self.pings, &self.settings);
        let a = self
            .aircraft
            .entry(source)
            .or_insert_with(|| Aircraft::new(source, pings, settings));
        a.frames += 1;
    }

    /// The state of aircraft `ac_id`, which the ground addresses: created whatever the
    /// bound.
    fn addressed(&mut self, ac_id: u8) -> &mut Aircraft {
        let (pings, settings) = (&self.pings, &self.settings);
        self.aircraft
            .entry(ac_id)
            .or_insert_with(|| Aircraft::new(ac_id, pings, settings))
    }

    fn handle(&mut self, now: f64, header: &Header, payload: &[u8]) -> Handled {
        let &Header {
            source, class, id, ..
        } = header;
        self.admit(source);
        let aircraft = self.aircraft.get_mut(&source);
        let Some(desc) = self.set.find(class, id) else {
            self.unknown += 1;
            if let Some(a) = aircraft {
                a.unknown += 1;
            }
            let line = format::line(source, class, id, None, payload);
            return Handled {
                line,
                message: None,
                valid: false,
            };
        };
        let body = format::fields(desc, payload);
        let line = format::known_line(source, desc, &body);
        let ok = dynamic::check(desc, payload).is_ok();
        let report = ok && desc.name == "DATALINK_REPORT";
        if let Some(a) = aircraft {
            if !ok {
                a.malformed += 1;
            }
            if report {
                a.last_report = Some(body.clone());
            }
            count_message(&mut a.messages, desc, now, body.clone());
        }
        if !ok {
            self.malformed += 1;
        }
        if report {
            self.last_report = Some(body.clone());
        }
        count_message(&mut self.messages, desc, now, body);
        if ok && header.to_ground() {
            match desc.name {
                "PONG" => self.pong(now, source),
                "DL_VALUE" => {
                    let value = |name| {
                        dynamic::fields(desc, payload)
                            .filter_map(Result::ok)
                            .find(|(f, _)| f.name == name)
                            .map(|(_, v)| v)
                    };
                    let index = value("index").and_then(|v| v.as_i64());
                    let number = value("value").and_then(|v| v.as_f64());
                    if let (Some(index), Some(value)) =
                        (index.and_then(|i| u8::try_from(i).ok()), number)
                    {
                        let base = scalar_type(Some(desc), "value").unwrap_or(BaseType::F64);
                        self.dl_value(now, source, index, value, base);
                    }
                }
                _ => {}
            }
        }
        Handled {
            line,
            message: Some(desc),
            valid: ok,
        }
    }

    /// A PONG from `source` at `now`: it answers the oldest PING outstanding to
    /// `source`, else the oldest one sent to no particular aircraft.
    fn pong(&mut self, now: f64, source: u8) {
        self.expire_pings(now, Some(source));
        self.expire_pings(now, None);
        let rtt = match self.aircraft.get_mut(&source) {
            Some(a) if a.pings.outstanding() > 0 => a.pings.pong(now),
            _ if self.pings.outstanding() > 0 => self.pings.pong(now),
            // Unexpected: counted by the aircraft if PINGs were sent to it.
            Some(a) if a.pings.sent_count() > 0 => a.pings.pong(now),
            _ => self.pings.pong(now),
        };
        match rtt {
            Some(rtt) => {
                if let Some(a) = self.aircraft.get_mut(&source) {
                    a.last_rtt = Some(rtt);
                }
                self.last_rtt = Some(rtt);
                self.event(now, Some(source), Event::Pong { rtt });
            }
            None => self.notice(now, Some(source), Notice::UnexpectedPong),
        }
    }

    /// A DL_VALUE from `source` at `now`: it answers the request pending on `index` for
    /// `source`, else the one sent to no particular aircraft.
    fn dl_value(&mut self, now: f64, source: u8, index: u8, value: f64, base: BaseType) {
        let answer = match self.aircraft.get_mut(&source) {
            Some(a) => a.settings.dl_value(now, index, value, base),
            None => Answer::Unsolicited,
        };
        let answer = match answer {
            Answer::Unsolicited => self.settings.dl_value(now, index, value, base),
            answer => answer,
        };
        let event = Event::DlValue {
            index,
            value,
            answer,
        };
        self.event(now, Some(source), event);
    }

    /// Counts as lost the PINGs to `aircraft` (or to none) older than their timeout at
    /// `now`, and notes it.
    fn expire_pings(&mut self, now: f64, aircraft: Option<u8>) {
        let lost = match aircraft {
            Some(id) => self
                .aircraft
                .get_mut(&id)
                .map_or(0, |a| a.pings.expire(now)),
            None => self.pings.expire(now),
        };
        if lost > 0 {
            self.notice(now, aircraft, Notice::PingsLost { count: lost });
        }
    }

    fn event(&mut self, now: f64, aircraft: Option<u8>, event: Event) {
        self.event_count += 1;
        push_bounded(&mut self.events, now, aircraft, event);
    }

    fn notice(&mut self, now: f64, aircraft: Option<u8>, notice: Notice) {
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

    /// Gives up the PINGs and requests older than their timeouts at `now` (counted
    /// lost, noted for the live view), of every aircraft. Call it regularly; the other
    /// methods taking `now` do it too where it matters.
    pub fn tick(&mut self, now: f64) {
        self.expire_pings(now, None);
        for e in self.settings.expire(now) {
            self.notice(now, None, Notice::RequestExpired(e));
        }
        let ids: Vec<u8> = self.aircraft.keys().copied().collect();
        for id in ids {
            self.expire_pings(now, Some(id));
            if let Some(a) = self.aircraft.get_mut(&id) {
                for e in a.settings.expire(now) {
                    self.notice(now, Some(id), Notice::RequestExpired(e));
                }
            }
        }
    }

    /// Records that a PING to no particular aircraft (the single-aircraft form) was sent
    /// at `now`; the PONGs answer the PINGs outstanding in order, oldest first. A PONG
    /// from any aircraft answers it, when that aircraft has no PING of
    /// [`ping_sent_to`](Self::ping_sent_to) outstanding. Statistics: [`pings`](Self::pings).
    pub fn ping_sent(&mut self, now: f64) {
        let lost = self.pings.sent(now);
        if lost > 0 {
            self.notice(now, None, Notice::PingsLost { count: lost });
        }
    }

    /// Records that a PING addressed to aircraft `ac_id` (its v2 destination) was sent at
    /// `now`: only a PONG whose source is `ac_id` answers it (the oldest PING outstanding
    /// to `ac_id` first). The aircraft is tracked from now on, whatever
    /// [`MAX_AIRCRAFT`] says. Statistics: [`pings_of`](Self::pings_of),
    /// [`last_rtt_of`](Self::last_rtt_of); the [`Event::Pong`] it produces is tagged with
    /// `ac_id` in [`events_with_aircraft`](Self::events_with_aircraft).
    ///
    /// ```
    /// # use pprz_ground::{monitor::Monitor, set::RuntimeSet};
    /// # use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};
    /// # let set = RuntimeSet::parse("m.xml", r#"<protocol><msg_class name="telemetry" id="1">
    /// #     <message name="PONG" id="3"/></msg_class></protocol>"#).unwrap();
    /// let mut monitor = Monitor::new(set, PprzV2::new().into());
    /// monitor.ping_sent_to(1.0, 7);
    /// monitor.ping_sent_to(1.0, 8);
    /// // A PONG from aircraft 8 to the ground (source 8, destination 0).
    /// let mut pong = [0u8; 16];
    /// let n = PprzV2::new().encode(&TxMeta::new(MsgHeader::new(8, 0, 1, 3)), &[], &mut pong).unwrap();
    /// monitor.feed(1.25, &pong[..n], |_| {});
    /// assert_eq!(monitor.last_rtt_of(8), Some(0.25));
    /// assert_eq!(monitor.last_rtt_of(7), None);
    /// assert_eq!(monitor.pings_of(7).unwrap().outstanding(), 1);
    /// assert_eq!(monitor.aircraft(), [7, 8]);
    /// ```
    pub fn ping_sent_to(&mut self, now: f64, ac_id: u8) {
        let lost = self.addressed(ac_id).pings.sent(now);
        if lost > 0 {
            self.notice(now, Some(ac_id), Notice::PingsLost { count: lost });
        }
    }

    /// The type of the `value` field of SETTING in the set (`float` without one).
    fn setting_type(&self) -> BaseType {
        scalar_type(self.set.find_by_name("datalink", "SETTING"), "value").unwrap_or(BaseType::F32)
    }

    /// Records that a SETTING of `index` to `value` was sent at `now` to no particular
    /// aircraft (the single-aircraft form): only a DL_VALUE carrying that value
    /// (compared as the type of the `value` fields of SETTING and DL_VALUE) acknowledges
    /// it; another value is reported as not applied. A DL_VALUE from any aircraft
    /// answers it, when that aircraft has no request of its own pending on `index`.
    pub fn setting_value_sent(&mut self, now: f64, index: u8, value: f64) {
        let base = self.setting_type();
        self.settings.setting_sent(now, index, value, base);
    }

    /// Records that a SETTING of `index` to `value` was sent at `now` to aircraft
    /// `ac_id`, as [`setting_value_sent`](Self::setting_value_sent) does, but only a
    /// DL_VALUE whose source is `ac_id` answers it. The aircraft is tracked from now on.
    /// Statistics: [`settings_of`](Self::settings_of).
    pub fn setting_value_sent_to(&mut self, now: f64, ac_id: u8, index: u8, value: f64) {
        let base = self.setting_type();
        self.addressed(ac_id)
            .settings
            .setting_sent(now, index, value, base);
    }

    /// Records that a request for setting `index` whose value is not known here was
    /// sent at `now` (a SETTING sent elsewhere): the next DL_VALUE of that index answers
    /// it, but is not taken as proof that a value was applied. Prefer
    /// [`setting_value_sent`](Self::setting_value_sent).
    pub fn setting_sent(&mut self, now: f64, index: u8) {
        self.settings.get_setting_sent(now, index);
    }

    /// Records that a GET_SETTING of `index` was sent at `now` to no particular
    /// aircraft (the single-aircraft form).
    pub fn get_setting_sent(&mut self, now: f64, index: u8) {
        self.settings.get_setting_sent(now, index);
    }

    /// Records that a GET_SETTING of `index` was sent at `now` to aircraft `ac_id`: the
    /// next DL_VALUE of that index from `ac_id` answers it. The aircraft is tracked from
    /// now on.
    pub fn get_setting_sent_to(&mut self, now: f64, ac_id: u8, index: u8) {
        self.addressed(ac_id).settings.get_setting_sent(now, index);
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

    /// Whether the monitor tracks more than one aircraft (or frames from aircraft beyond
    /// [`MAX_AIRCRAFT`] arrived): the live view then has a section per aircraft, and
    /// event lines name their aircraft.
    pub fn several_aircraft(&self) -> bool {
        self.aircraft.len() > 1 || self.untracked_frames > 0
    }

    /// An event as a line of the live view: [`describe_event`], after `aircraft N: `
    /// when [`several_aircraft`](Self::several_aircraft) and the event is about one.
    pub fn event_line(&self, aircraft: Option<u8>, event: &Event) -> String {
        self.about(aircraft) + &describe_event(event)
    }

    /// A notice as a line of the live view, named after its aircraft as
    /// [`event_line`](Self::event_line) does.
    pub fn notice_line(&self, aircraft: Option<u8>, notice: &Notice) -> String {
        self.about(aircraft) + &describe_notice(notice)
    }

    /// `aircraft N: ` with several aircraft, or nothing.
    fn about(&self, aircraft: Option<u8>) -> String {
        match aircraft {
            Some(id) if self.several_aircraft() => format!("aircraft {id}: "),
            _ => String::new(),
        }
    }

    /// The last round-trip time measured, of any PING and any aircraft.
    pub fn last_rtt(&self) -> Option<f64> {
        self.last_rtt
    }

    /// The last round-trip time measured with a PONG from aircraft `ac_id` (of a PING
    /// sent to it with [`ping_sent_to`](Self::ping_sent_to), or to no particular
    /// aircraft with [`ping_sent`](Self::ping_sent)); `None` before any, or when the
    /// aircraft is not tracked.
    pub fn last_rtt_of(&self, ac_id: u8) -> Option<f64> {
        self.aircraft.get(&ac_id)?.last_rtt
    }

    /// The PINGs sent to aircraft `ac_id` ([`ping_sent_to`](Self::ping_sent_to)) and
    /// their statistics; `None` when the aircraft is not tracked.
    pub fn pings_of(&self, ac_id: u8) -> Option<&PingTracker> {
        Some(&self.aircraft.get(&ac_id)?.pings)
    }

    /// The SETTING and GET_SETTING requests sent to aircraft `ac_id` and their
    /// statistics; `None` when the aircraft is not tracked.
    pub fn settings_of(&self, ac_id: u8) -> Option<&SettingTracker> {
        Some(&self.aircraft.get(&ac_id)?.settings)
    }

    /// The ids of the aircraft tracked, in ascending order: every source id of the
    /// frames received (the first [`MAX_AIRCRAFT`] ones) and every aircraft addressed
    /// with [`ping_sent_to`](Self::ping_sent_to) and the other `_to` methods.
    pub fn aircraft(&self) -> Vec<u8> {
        self.aircraft.keys().copied().collect()
    }

    /// What the monitor knows about aircraft `ac_id`; `None` when it is not tracked.
    pub fn aircraft_state(&self, ac_id: u8) -> Option<&Aircraft> {
        self.aircraft.get(&ac_id)
    }

    /// Frames from aircraft beyond [`MAX_AIRCRAFT`], which are decoded and counted with
    /// all aircraft but not tracked one by one.
    pub fn untracked_frames(&self) -> u64 {
        self.untracked_frames
    }

    /// How many different source ids sent the [`untracked_frames`](Self::untracked_frames).
    pub fn untracked_aircraft(&self) -> u32 {
        self.untracked_ids.iter().map(|w| w.count_ones()).sum()
    }

    /// The PINGs to no particular aircraft ([`ping_sent`](Self::ping_sent)) and their
    /// statistics; [`pings_of`](Self::pings_of) for those sent to an aircraft.
    pub fn pings(&self) -> &PingTracker {
        &self.pings
    }

    /// The SETTING and GET_SETTING requests to no particular aircraft and their
    /// statistics; [`settings_of`](Self::settings_of) for those sent to an aircraft.
    pub fn settings(&self) -> &SettingTracker {
        &self.settings
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

    /// Messages received from aircraft `ac_id` per priority level, most important
    /// first; empty when the aircraft is not tracked.
    pub fn per_priority_of(&self, ac_id: u8) -> BTreeMap<std::cmp::Reverse<u8>, u64> {
        self.aircraft
            .get(&ac_id)
            .map(Aircraft::per_priority)
            .unwrap_or_default()
    }

    /// Bytes per second over the last [`RATE_WINDOW`] seconds.
    pub fn byte_rate(&self, now: f64) -> f64 {
        self.byte_rate.per_second(now)
    }

    /// An estimate of the heap memory the monitor holds, in bytes (the decoder's
    /// fixed buffer included): bounded by the size of the message set and the number of
    /// aircraft tracked (at most [`MAX_AIRCRAFT`] from received frames, plus those the
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

    /// The status line: time, byte rate and every counter of lost or rejected input.
    fn status(&self, now: f64) -> String {
        let st = self.decoder.stats();
        format!(
            "t={now:7.1}s  {:7.0} B/s  frames ok {}  checksum errors {}  length errors {}  dropped bytes {}  unknown {}  malformed {}  input dropped {} B in {} reads",
            self.byte_rate(now),
            st.frames,
            st.checksum_errors,
            st.length_errors,
            st.dropped_bytes,
            self.unknown,
            self.malformed,
            self.input_dropped.bytes,
            self.input_dropped.reads,
        )
    }

    /// PING and SETTING statistics of the requests to no particular aircraft and, with
    /// a single aircraft, of those addressed to it, when there were any.
    fn uplink_status(&self) -> Vec<String> {
        let mut out = uplink_lines(&self.pings, &self.settings);
        if !self.several_aircraft()
            && let Some(a) = self.aircraft.values().next()
        {
            out.extend(uplink_lines(&a.pings, &a.settings));
        }
        out
    }

    /// The aircraft tracked, and the frames of those not tracked, with several
    /// aircraft.
    fn fleet_line(&self) -> Option<String> {
        if !self.several_aircraft() {
            return None;
        }
        let ids: Vec<String> = self.aircraft.keys().map(u8::to_string).collect();
        let mut s = format!("aircraft: {}", ids.join(", "));
        if self.untracked_frames > 0 {
            let _ = write!(
                s,
                "  not tracked (more than {MAX_AIRCRAFT} aircraft): {} frames from {} aircraft",
                self.untracked_frames,
                self.untracked_aircraft()
            );
        }
        Some(s)
    }

    /// The secure link's status lines, if the monitor has one.
    pub fn secure_lines(&self) -> Vec<String> {
        self.secure_status()
            .map(|s| s.lines().to_vec())
            .unwrap_or_default()
    }

    /// The live view: the status, a table of messages, the latest events and notices.
    /// With [`several_aircraft`](Self::several_aircraft), a line listing them, then a
    /// section per aircraft (`aircraft N: frames ...`, its PINGs and SETTINGs, its link
    /// report, its table), and the events and notices name their aircraft.
    pub fn render(&self, now: f64) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "{}", self.status(now));
        for line in self.secure_lines() {
            let _ = writeln!(s, "{line}");
        }
        for line in self.uplink_status() {
            let _ = writeln!(s, "{line}");
        }
        match self.fleet_line() {
            None => {
                if let Some(report) = &self.last_report {
                    let _ = writeln!(s, "aircraft link report: {report}");
                }
                table(&mut s, &self.messages, now);
            }
            Some(fleet) => {
                let _ = writeln!(s, "{fleet}");
                for a in self.aircraft.values() {
                    let _ = writeln!(s, "{}", aircraft_head(a));
                    for line in uplink_lines(&a.pings, &a.settings) {
                        let _ = writeln!(s, "{line}");
                    }
                    if let Some(report) = &a.last_report {
                        let _ = writeln!(s, "aircraft link report: {report}");
                    }
                    table(&mut s, &a.messages, now);
                }
            }
        }
        for (t, ac, e) in self.events_with_aircraft() {
            let _ = writeln!(s, "[{t:7.1}s] {}", self.event_line(ac, e));
        }
        for (t, ac, n) in self.notices_with_aircraft() {
            let _ = writeln!(s, "[{t:7.1}s] {}", self.notice_line(ac, n));
        }
        s
    }

    /// Messages received per priority level (all aircraft), as a short table.
    pub fn priority_summary(&self) -> String {
        priority_line(&self.per_priority())
    }

    /// Messages received from aircraft `ac_id` per priority level, as a short table
    /// (`received per priority level:  2: 10  1: 230`; no level when the aircraft is not
    /// tracked).
    pub fn priority_summary_of(&self, ac_id: u8) -> String {
        priority_line(&self.per_priority_of(ac_id))
    }

    /// The summary of aircraft `ac_id`: `aircraft N: frames F  unknown U  malformed M`,
    /// then, indented, its messages per priority level and its PING and SETTING
    /// statistics; `None` when the aircraft is not tracked.
    pub fn aircraft_summary(&self, ac_id: u8) -> Option<String> {
        let a = self.aircraft.get(&ac_id)?;
        let mut s = aircraft_head(a);
        let levels = priority_line(&a.per_priority());
        for line in std::iter::once(levels).chain(uplink_lines(&a.pings, &a.settings)) {
            let _ = write!(s, "\n  {line}");
        }
        Some(s)
    }

    /// The summary at the end of a run: the status line (with the input dropped under
    /// overload), PING and SETTING statistics, and messages per priority level; with
    /// [`several_aircraft`](Self::several_aircraft), then the aircraft and the
    /// [`aircraft_summary`](Self::aircraft_summary) of each.
    pub fn summary(&self, now: f64) -> String {
        let mut s = self.status(now);
        for line in self.secure_lines().into_iter().chain(self.uplink_status()) {
            s.push('\n');
            s.push_str(&line);
        }
        s.push('\n');
        s.push_str(&self.priority_summary());
        if let Some(fleet) = self.fleet_line() {
            s.push('\n');
            s.push_str(&fleet);
            for id in self.aircraft.keys() {
                if let Some(a) = self.aircraft_summary(*id) {
                    s.push('\n');
                    s.push_str(&a);
                }
            }
        }
        s
    }
}

/// `received per priority level:  2: 10  1: 230`.
fn priority_line(levels: &BTreeMap<std::cmp::Reverse<u8>, u64>) -> String {
    let mut s = String::from("received per priority level:");
    for (p, n) in levels {
        let _ = write!(s, "  {}: {n}", p.0);
    }
    s
}

/// The first line of an aircraft's section or summary.
fn aircraft_head(a: &Aircraft) -> String {
    format!(
        "aircraft {}: frames {}  unknown {}  malformed {}",
        a.id, a.frames, a.unknown, a.malformed
    )
}

/// The table of `messages` of the live view, with its header.
fn table(s: &mut String, messages: &BTreeMap<(u8, u8), MessageStats>, now: f64) {
    let _ = writeln!(
        s,
        "{:<10} {:<20} {:>4} {:>7} {:>7}  last values",
        "class", "message", "prio", "count", "rate/s"
    );
    for m in messages.values() {
        let mut last = m.last.clone();
        format::truncate(&mut last, 110);
        let _ = writeln!(
            s,
            "{:<10} {:<20} {:>4} {:>7} {:>7.1}  {last}",
            m.class,
            m.name,
            m.priority,
            m.count,
            m.rate(now)
        );
    }
}

/// PING and SETTING statistics of a pair of trackers, when there were any.
fn uplink_lines(pings: &PingTracker, settings: &SettingTracker) -> Vec<String> {
    let mut out = Vec::new();
    let p = pings;
    if p.sent_count() > 0 || p.unexpected() > 0 {
        let mut s = format!(
            "pings: sent {}  answered {}  lost {}  outstanding {}  unexpected pongs {}",
            p.sent_count(),
            p.answered(),
            p.lost(),
            p.outstanding(),
            p.unexpected()
        );
        if let Some(rtt) = p.last_rtt() {
            let _ = write!(s, "  last round trip {:.1} ms", rtt * 1e3);
        }
        out.push(s);
    }
    let st = settings;
    if st.acknowledged() + st.not_applied() + st.unanswered() > 0 || st.pending() > 0 {
        out.push(format!(
            "settings: acknowledged {}  not applied {}  unanswered {}  pending {}",
            st.acknowledged(),
            st.not_applied(),
            st.unanswered(),
            st.pending()
        ));
        for p in st.pending_requests() {
            out.push(match p {
                Expired {
                    index,
                    requested: Some(requested),
                    reported: Some(reported),
                } => format!(
                    "  pending: SETTING index={index} to {}: not applied so far, the aircraft reports {}",
                    number(requested),
                    number(reported)
                ),
                Expired {
                    index,
                    requested: Some(requested),
                    reported: None,
                } => format!(
                    "  pending: SETTING index={index} to {}: no answer yet",
                    number(requested)
                ),
                Expired { index, .. } => {
                    format!("  pending: request for setting index={index}: no answer yet")
                }
            });
        }
    }
    out
}

/// A time in seconds as milliseconds (saturating; NaN and negative times are 0).
fn millis(now: f64) -> u64 {
    (now * 1000.0) as u64
}

/// The addressing of a decoded message.
struct Header {
    source: u8,
    /// `None` with PPRZ v1, which has no destination.
    destination: Option<u8>,
    class: u8,
    id: u8,
}

impl Header {
    fn of(frame: &pprz_transports::Frame<'_>) -> Self {
        Self {
            source: frame.source(),
            destination: frame.destination(),
            class: frame.class(),
            id: frame.msg_id(),
        }
    }

    /// Whether the message is for the ground: destination ground, broadcast, or none
    /// (PPRZ v1).
    fn to_ground(&self) -> bool {
        matches!(self.destination, None | Some(GROUND_ID | BROADCAST_ID))
    }
}

/// What the monitor keeps of a decoded frame (the decoder's frame borrows the decoder).
struct Received {
    header: Header,
    payload: Vec<u8>,
    data: Vec<u8>,
    raw: Vec<u8>,
    /// The PPRZLOG time stamp.
    log_time: Option<std::time::Duration>,
}

impl Received {
    fn of(frame: &pprz_transports::Frame<'_>) -> Self {
        Self {
            header: Header::of(frame),
            payload: frame.payload().to_vec(),
            data: frame.data().to_vec(),
            raw: frame.raw().to_vec(),
            log_time: frame
                .timestamp()
                .map(|ticks| std::time::Duration::from_micros(u64::from(ticks) * 100)),
        }
    }
}

/// What [`Monitor::handle`] made of a message.
struct Handled {
    line: String,
    message: Option<&'static MessageDescriptor<'static>>,
    valid: bool,
}

impl Handled {
    fn decoded<'a>(
        &'a self,
        header: &Header,
        payload: &'a [u8],
        raw: &'a [u8],
        log_time: Option<std::time::Duration>,
    ) -> Decoded<'a> {
        Decoded {
            line: &self.line,
            raw,
            source: header.source,
            class_id: header.class,
            msg_id: header.id,
            message: self.message,
            payload,
            valid: self.valid,
            log_time,
        }
    }
}

/// A message the monitor decoded, as its callbacks ([`Monitor::feed`],
/// [`Monitor::flush`], [`Monitor::input_gap`]) receive it.
#[derive(Debug, Clone, Copy)]
pub struct Decoded<'a> {
    /// The text line (`--lines` output): escaped, without control characters.
    pub line: &'a str,
    /// The frame as received (opened, on a secure link), for recording.
    pub raw: &'a [u8],
    /// The aircraft that sent it (the frame's source id).
    pub source: u8,
    /// The message class id.
    pub class_id: u8,
    /// The message id within its class.
    pub msg_id: u8,
    /// The message's description, when the set knows the message.
    pub message: Option<&'static MessageDescriptor<'static>>,
    /// The payload (the fields' bytes).
    pub payload: &'a [u8],
    /// Whether the payload matches the description (false for unknown messages).
    pub valid: bool,
    /// The PPRZLOG time stamp of the frame (from the start of the log), when the
    /// transport carries one.
    pub log_time: Option<std::time::Duration>,
}

/// A value read from the wire: a value that is exactly a `float` is written as the
/// `float` (`0.1`, not `0.10000000149011612`).
fn number(v: f64) -> String {
    let single = v as f32;
    if f64::from(single) == v {
        single.to_string()
    } else {
        v.to_string()
    }
}

/// An event as a line of the live view.
pub fn describe_event(e: &Event) -> String {
    match e {
        Event::Pong { rtt } => format!("PONG: round trip {:.1} ms", rtt * 1e3),
        Event::DlValue {
            index,
            value,
            answer,
        } => {
            let head = format!("DL_VALUE index={index} value={}", number(*value));
            match answer {
                Answer::Unsolicited => head,
                Answer::Acknowledged { after } => {
                    format!("{head}: SETTING acknowledged after {:.1} ms", after * 1e3)
                }
                Answer::NotApplied { requested, after } => format!(
                    "{head}: SETTING to {} not applied ({:.1} ms after it was sent)",
                    number(*requested),
                    after * 1e3
                ),
                Answer::Answered { after } => {
                    format!("{head}: answer after {:.1} ms", after * 1e3)
                }
            }
        }
        Event::SecureSession { completed } => {
            format!("secure session established (handshake {completed})")
        }
    }
}

/// A notice as a line of the live view.
pub fn describe_notice(n: &Notice) -> String {
    match n {
        Notice::PingsLost { count } => format!("{count} PING(s) lost: no PONG in time"),
        Notice::UnexpectedPong => "PONG that answers no PING outstanding".into(),
        Notice::RequestExpired(Expired {
            index,
            requested: Some(requested),
            reported: Some(reported),
        }) => format!(
            "SETTING index={index} to {} not applied: the aircraft still reports {}",
            number(*requested),
            number(*reported)
        ),
        Notice::RequestExpired(Expired {
            index,
            requested: Some(requested),
            reported: None,
        }) => format!("SETTING index={index} to {}: no answer", number(*requested)),
        Notice::RequestExpired(Expired { index, .. }) => {
            format!("request for setting index={index}: no answer")
        }
        Notice::InputDropped(d) => format!(
            "input overload: dropped {} bytes in {} reads",
            d.bytes, d.reads
        ),
        Notice::SecureRejected { reason, count } => {
            format!("{count} frame(s) rejected by the secure link: {reason}")
        }
        Notice::HandshakeRefused(e) => format!("key exchange from the aircraft refused: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::escape;
    use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};

    const XML: &str = r#"<protocol>
      <msg_class name="telemetry" id="1">
        <message name="PONG" id="3"/>
        <message name="DL_VALUE" id="31"><field name="index" type="uint8"/><field name="value" type="float"/></message>
        <message name="INFO_MSG" id="215"><field name="msg" type="char[]"/></message>
        <message name="GPS_LLA" id="9"><field name="lat" type="int32" unit="1e7deg" alt_unit="deg" alt_unit_coef="0.0000001"/></message>
      </msg_class>
      <msg_class name="datalink" id="2">
        <message name="SETTING" id="4"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
        <message name="PING" id="8"/>
      </msg_class></protocol>"#;

    fn monitor() -> Monitor {
        let set = RuntimeSet::parse("t.xml", XML).unwrap();
        Monitor::new(set, PprzV2::new().into())
    }

    fn frame(id: u8, payload: &[u8]) -> Vec<u8> {
        frame_from(7, 0, id, payload)
    }

    /// A telemetry frame from aircraft `source` to `destination`.
    fn frame_from(source: u8, destination: u8, id: u8, payload: &[u8]) -> Vec<u8> {
        let mut buf = [0u8; 300];
        let meta = TxMeta::new(MsgHeader::new(source, destination, 1, id));
        let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn dl_value(index: u8, value: f32) -> Vec<u8> {
        dl_value_from(7, index, value)
    }

    fn dl_value_from(source: u8, index: u8, value: f32) -> Vec<u8> {
        let mut p = vec![index];
        p.extend(value.to_le_bytes());
        frame_from(source, 0, 31, &p)
    }

    fn pong_from(source: u8) -> Vec<u8> {
        frame_from(source, 0, 3, &[])
    }

    fn feed(m: &mut Monitor, now: f64, bytes: &[u8]) -> Vec<String> {
        let mut lines = Vec::new();
        m.feed(now, bytes, |d| lines.push(d.line.to_owned()));
        lines
    }

    fn no_control(text: &str) {
        for line in text.lines() {
            assert!(!line.chars().any(escape::is_unsafe), "{line:?}");
        }
    }

    /// Issue: with `--ping 0.2` and a true round trip of 500 ms, 100.8 ms was shown.
    #[test]
    fn each_pong_is_matched_to_its_ping() {
        let mut m = monitor();
        let pong = frame(3, &[]);
        for i in 0..20 {
            m.ping_sent(f64::from(i) * 0.2);
        }
        for i in 0..17 {
            feed(&mut m, f64::from(i) * 0.2 + 0.5, &pong);
        }
        let rtts: Vec<f64> = m
            .events()
            .map(|(_, e)| match e {
                Event::Pong { rtt } => *rtt,
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(rtts.len(), MAX_EVENTS);
        for rtt in rtts {
            assert!((rtt - 0.5).abs() < 1e-9, "{rtt}");
        }
        assert!((m.last_rtt().unwrap() - 0.5).abs() < 1e-9);
        let view = m.render(4.0);
        assert!(view.contains("PONG: round trip 500.0 ms"), "{view}");
        assert!(
            view.contains("pings: sent 20  answered 17  lost 0  outstanding 3"),
            "{view}"
        );
        // The outstanding ones time out.
        m.tick(100.0);
        assert_eq!(m.pings().lost(), 3);
        assert!(m.render(100.0).contains("3 PING(s) lost"));
        // A PONG nobody asked for is noted, not measured.
        feed(&mut m, 101.0, &pong);
        assert_eq!(m.pings().unexpected(), 1);
    }

    /// Issue: a periodic DL_VALUE carrying the old value was shown as the
    /// acknowledgement of a SETTING the aircraft ignored.
    #[test]
    fn only_the_value_set_acknowledges_a_setting() {
        let mut m = monitor();
        m.setting_value_sent(1.0, 4, 0.1);
        feed(&mut m, 1.1, &dl_value(4, 1.0));
        let last = m.events().last().unwrap().1.clone();
        assert!(
            matches!(
                last,
                Event::DlValue {
                    index: 4,
                    value: 1.0,
                    answer: Answer::NotApplied { .. }
                }
            ),
            "{last:?}"
        );
        let view = m.render(1.1);
        assert!(
            view.contains("DL_VALUE index=4 value=1: SETTING to 0.1 not applied"),
            "{view}"
        );
        assert!(
            view.contains(
                "pending: SETTING index=4 to 0.1: not applied so far, the aircraft reports 1"
            ),
            "{view}"
        );
        // The value set, as the float the aircraft stores.
        feed(&mut m, 1.2, &dl_value(4, 0.1));
        let last = m.events().last().unwrap().1.clone();
        assert!(
            matches!(last, Event::DlValue { answer: Answer::Acknowledged { after }, .. } if (after - 0.2).abs() < 1e-9),
            "{last:?}"
        );
        assert_eq!(m.settings().acknowledged(), 1);
        // A SETTING that the aircraft never applies is given up and counted.
        m.setting_value_sent(2.0, 5, 3.0);
        feed(&mut m, 2.1, &dl_value(5, 2.0));
        m.tick(10.0);
        assert_eq!(m.settings().not_applied(), 1);
        let view = m.render(10.0);
        assert!(
            view.contains("SETTING index=5 to 3 not applied: the aircraft still reports 2"),
            "{view}"
        );
        assert!(
            view.contains("settings: acknowledged 1  not applied 1"),
            "{view}"
        );
    }

    #[test]
    fn input_dropped_is_counted_shown_and_resynchronises() {
        let mut m = monitor();
        let f = frame(215, &[2, b'o', b'k']);
        // Half a frame, then a gap: its end was dropped.
        feed(&mut m, 0.0, &f[..4]);
        let mut lines = Vec::new();
        m.input_gap(
            0.1,
            Drops {
                bytes: 4000,
                reads: 3,
            },
            |d| lines.push(d.line.to_owned()),
        );
        lines.extend(feed(&mut m, 0.1, &f));
        assert_eq!(lines, [r#"7 telemetry INFO_MSG msg="ok""#]);
        m.input_gap(
            0.2,
            Drops {
                bytes: 10,
                reads: 1,
            },
            |_| {},
        );
        m.input_gap(0.3, Drops::default(), |_| {});
        assert_eq!(
            m.input_dropped(),
            Drops {
                bytes: 4010,
                reads: 4
            }
        );
        let view = m.render(0.3);
        assert!(view.contains("input dropped 4010 B in 4 reads"), "{view}");
        assert!(
            view.contains("input overload: dropped 4000 bytes in 3 reads"),
            "{view}"
        );
        assert!(m.summary(0.3).contains("input dropped 4010 B in 4 reads"));
    }

    /// Issue: one INFO_MSG forged a `7 telemetry ALIVE md5sum=FORGED` line plus
    /// clear-screen and window-title escape codes.
    #[test]
    fn hostile_text_cannot_forge_lines_or_reach_the_terminal() {
        let mut m = monitor();
        let text = b"hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;owned\x07\r\xc2\x9b";
        let mut p = vec![text.len() as u8];
        p.extend_from_slice(text);
        let lines = feed(&mut m, 0.0, &frame(215, &p));
        assert_eq!(lines.len(), 1);
        assert!(
            lines[0].starts_with(
                r#"7 telemetry INFO_MSG msg="hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J"#
            ),
            "{}",
            lines[0]
        );
        no_control(&lines[0]);
        let view = m.render(1.0);
        no_control(&view);
        assert!(!view.contains("\nALIVE") && !view.contains('\x1b') && !view.contains('\r'));
    }

    #[test]
    fn units_are_apart_from_values() {
        let mut m = monitor();
        let lines = feed(&mut m, 0.0, &frame(9, &434_629_172i32.to_le_bytes()));
        assert_eq!(
            lines,
            ["7 telemetry GPS_LLA lat=434629172 [1e7deg] 43.4629172 deg"]
        );
    }

    #[test]
    fn rates_and_state_are_bounded() {
        let mut m = monitor();
        let f = dl_value(1, 1.0);
        let chunk: Vec<u8> = f.repeat(1000);
        for i in 0..200 {
            feed(&mut m, f64::from(i) * 0.01, &chunk);
        }
        // 200,000 messages in two seconds: the rate is right, the state small.
        let stats = &m.messages()[&(1, 31)];
        assert_eq!(stats.count, 200_000);
        assert!((stats.rate(2.0) - 1e5).abs() < 1.0, "{}", stats.rate(2.0));
        assert_eq!(stats.rate(100.0), 0.0);
        assert!(m.retained_bytes() < 64 * 1024, "{}", m.retained_bytes());
        assert!(m.events().count() <= MAX_EVENTS);
        let r = m.byte_rate(2.0);
        assert!((r - 200.0 * chunk.len() as f64 / 2.0).abs() < 1.0, "{r}");
    }

    #[test]
    fn one_aircraft_keeps_one_table() {
        let mut m = monitor();
        feed(&mut m, 0.0, &frame(215, &[2, b'o', b'k']));
        assert_eq!(m.aircraft(), [7]);
        assert!(!m.several_aircraft());
        let view = m.render(1.0);
        assert!(
            !view.contains("aircraft 7:") && !view.contains("aircraft:"),
            "{view}"
        );
        assert_eq!(view.matches("class      message").count(), 1, "{view}");
        assert!(!m.summary(1.0).contains("aircraft"));
    }

    #[test]
    fn frames_from_two_aircraft_make_two_sections() {
        let mut m = monitor();
        let mut lines = feed(&mut m, 0.0, &frame_from(7, 0, 215, &[2, b'o', b'k']));
        lines.extend(feed(&mut m, 0.1, &frame_from(8, 0, 9, &[1, 0, 0, 0])));
        lines.extend(feed(&mut m, 0.2, &frame_from(8, 0, 9, &[2, 0, 0, 0])));
        lines.extend(feed(&mut m, 0.3, &frame_from(8, 0, 200, &[])));
        // Each line starts with its source.
        assert_eq!(
            lines,
            [
                r#"7 telemetry INFO_MSG msg="ok""#,
                "8 telemetry GPS_LLA lat=1 [1e7deg] 0.0000001 deg",
                "8 telemetry GPS_LLA lat=2 [1e7deg] 0.0000002 deg",
                "8 class1 id=200 unknown message (0 bytes)",
            ]
        );
        assert_eq!(m.aircraft(), [7, 8]);
        assert!(m.several_aircraft());
        // All aircraft together, and each on its own.
        assert_eq!(m.messages().len(), 2);
        let a8 = m.aircraft_state(8).unwrap();
        assert_eq!(
            (a8.id(), a8.frames(), a8.unknown(), a8.malformed()),
            (8, 3, 1, 0)
        );
        assert_eq!(a8.messages()[&(1, 9)].count, 2);
        assert!(!a8.messages().contains_key(&(1, 215)));
        assert_eq!(m.aircraft_state(7).unwrap().messages().len(), 1);
        assert!(m.aircraft_state(9).is_none());
        let prio = pprz_messages::priority::DEFAULT;
        assert_eq!(m.per_priority_of(8)[&std::cmp::Reverse(prio)], 2);
        assert_eq!(m.per_priority_of(7)[&std::cmp::Reverse(prio)], 1);
        assert_eq!(m.per_priority()[&std::cmp::Reverse(prio)], 3);
        assert!(m.per_priority_of(9).is_empty());
        assert_eq!(
            m.priority_summary_of(8),
            format!("received per priority level:  {prio}: 2")
        );

        let view = m.render(1.0);
        no_control(&view);
        let at = |needle: &str| {
            view.find(needle)
                .unwrap_or_else(|| panic!("{needle}: {view}"))
        };
        assert!(view.contains("aircraft: 7, 8\n"), "{view}");
        let (s7, s8) = (
            at("aircraft 7: frames 1  unknown 0  malformed 0\n"),
            at("aircraft 8: frames 3  unknown 1  malformed 0\n"),
        );
        let (info, gps) = (at("INFO_MSG"), at("GPS_LLA"));
        assert!(s7 < info && info < s8 && s8 < gps, "{view}");
        assert_eq!(view.matches("class      message").count(), 2, "{view}");

        let summary = m.summary(1.0);
        assert!(
            summary.contains(&format!(
                "aircraft: 7, 8\naircraft 7: frames 1  unknown 0  malformed 0\n  received per priority level:  {prio}: 1\naircraft 8:"
            )),
            "{summary}"
        );
        assert_eq!(m.aircraft_summary(9), None);
    }

    #[test]
    fn a_pong_answers_only_a_ping_to_its_source() {
        let mut m = monitor();
        m.ping_sent_to(0.0, 7);
        // Aircraft 8 was not pinged: its PONG answers nothing (counted with the PINGs to
        // no particular aircraft, noted with aircraft 8).
        feed(&mut m, 0.1, &pong_from(8));
        assert_eq!(m.pings_of(7).unwrap().outstanding(), 1);
        assert_eq!(m.last_rtt(), None);
        let (_, ac, n) = m.notices_with_aircraft().last().unwrap();
        assert_eq!((ac, n), (Some(8), &Notice::UnexpectedPong));
        m.ping_sent_to(1.0, 8);
        feed(&mut m, 1.25, &pong_from(8));
        assert_eq!(m.last_rtt_of(8), Some(0.25));
        assert_eq!(m.last_rtt(), Some(0.25));
        assert_eq!(m.last_rtt_of(7), None);
        assert_eq!(m.pings_of(7).unwrap().outstanding(), 1);
        assert_eq!(m.pings_of(8).unwrap().answered(), 1);
        let (_, ac, e) = m.events_with_aircraft().last().unwrap();
        assert_eq!((ac, e), (Some(8), &Event::Pong { rtt: 0.25 }));
        // 7's answer to aircraft 8 (seen on a shared link) is not an answer to the ground.
        feed(&mut m, 1.5, &frame_from(7, 8, 3, &[]));
        assert_eq!(m.pings_of(7).unwrap().outstanding(), 1);
        feed(&mut m, 1.5, &frame_from(7, 0xFF, 3, &[]));
        assert_eq!(m.last_rtt_of(7), Some(1.5));
        // A PING to nobody in particular is answered by any aircraft.
        m.ping_sent(2.0);
        feed(&mut m, 2.5, &pong_from(9));
        assert_eq!((m.pings().answered(), m.last_rtt_of(9)), (1, Some(0.5)));
        // Timeouts per aircraft, noted with the aircraft.
        m.ping_sent_to(3.0, 7);
        m.tick(10.0);
        assert_eq!(m.pings_of(7).unwrap().lost(), 1);
        let view = m.render(10.0);
        assert!(view.contains("aircraft 7: 1 PING(s) lost"), "{view}");
        assert!(
            view.contains("aircraft 8: PONG: round trip 250.0 ms"),
            "{view}"
        );
        assert!(
            view.contains("aircraft 8: frames 2  unknown 0  malformed 0\npings: sent 1  answered 1  lost 0  outstanding 0  unexpected pongs 0  last round trip 250.0 ms\n"),
            "{view}"
        );
        let s = m.aircraft_summary(7).unwrap();
        assert!(s.contains("\n  pings: sent 2  answered 1  lost 1"), "{s}");
    }

    #[test]
    fn a_dl_value_answers_only_a_setting_to_its_source() {
        let mut m = monitor();
        m.setting_value_sent_to(0.0, 8, 4, 2.5);
        m.get_setting_sent_to(0.0, 7, 5);
        feed(&mut m, 0.1, &dl_value_from(7, 4, 2.5));
        assert_eq!(m.settings_of(8).unwrap().pending(), 1);
        feed(&mut m, 0.2, &dl_value_from(8, 4, 2.5));
        assert_eq!(m.settings_of(8).unwrap().acknowledged(), 1);
        let (_, ac, e) = m.events_with_aircraft().last().unwrap();
        assert_eq!(ac, Some(8));
        assert!(
            matches!(
                e,
                Event::DlValue {
                    index: 4,
                    answer: Answer::Acknowledged { .. },
                    ..
                }
            ),
            "{e:?}"
        );
        feed(&mut m, 0.3, &dl_value_from(8, 5, 1.0));
        assert_eq!(m.settings_of(7).unwrap().pending(), 1);
        m.tick(10.0);
        assert_eq!(m.settings_of(7).unwrap().unanswered(), 1);
        let (_, ac, n) = m.notices_with_aircraft().last().unwrap();
        assert_eq!(ac, Some(7));
        assert!(
            matches!(n, Notice::RequestExpired(Expired { index: 5, .. })),
            "{n:?}"
        );
        assert_eq!(m.settings().pending(), 0);
    }

    /// Hostile input: frames from every source id track at most [`MAX_AIRCRAFT`]
    /// aircraft; the others are counted.
    #[test]
    fn the_aircraft_tracked_are_bounded() {
        let mut m = monitor();
        let flood: Vec<u8> = (0..=255u8)
            .flat_map(|src| frame_from(src, 0, 215, &[245; 246]))
            .collect();
        for i in 0..4 {
            feed(&mut m, f64::from(i), &flood);
        }
        assert_eq!(m.aircraft().len(), MAX_AIRCRAFT);
        assert_eq!(m.aircraft(), (0..MAX_AIRCRAFT as u8).collect::<Vec<_>>());
        assert_eq!(m.untracked_aircraft(), 256 - MAX_AIRCRAFT as u32);
        assert_eq!(m.untracked_frames(), 4 * (256 - MAX_AIRCRAFT as u64));
        assert_eq!(m.messages()[&(1, 215)].count, 4 * 256);
        assert_eq!(m.decoder_stats().frames, 4 * 256);
        // An aircraft the ground addresses is tracked all the same, and its PONG
        // measured.
        m.ping_sent_to(5.0, 200);
        feed(&mut m, 5.5, &pong_from(200));
        assert_eq!(m.last_rtt_of(200), Some(0.5));
        assert_eq!(m.aircraft().len(), MAX_AIRCRAFT + 1);
        let view = m.render(6.0);
        no_control(&view);
        assert!(
            view.contains("not tracked (more than 32 aircraft): 896 frames from 224 aircraft"),
            "{view}"
        );
        // 33 tables of one message with the longest text, and no more.
        assert!(
            m.retained_bytes() < 34 * 4096 + 64 * 1024,
            "{}",
            m.retained_bytes()
        );
        assert!(m.summary(6.0).contains("not tracked"));
    }
}
