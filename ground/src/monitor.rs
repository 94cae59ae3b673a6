//! The monitor's state: decodes a byte stream with a chosen transport and a run-time
//! message set, keeps per-message statistics and the latest values, link statistics,
//! round-trip times of PINGs and the acknowledgements of SETTINGs, and renders them.
//!
//! Time is passed in (seconds since the start of the run), so the state is testable and
//! a replay reproduces the same output.
//!
//! Every piece of state is bounded, whatever arrives: one entry per message of the set
//! (with its latest fields cut at [`format::MAX_FIELDS_LEN`]), rates counted in fixed
//! time buckets, at most [`MAX_EVENTS`] events and notices, at most
//! [`crate::ping::MAX_OUTSTANDING`] PINGs and 256 requests outstanding.
//! [`retained_bytes`](Monitor::retained_bytes) estimates the total.
//!
//! Everything printed is escaped ([`escape`](crate::escape)): no line contains a
//! control character.

use std::collections::{BTreeMap, VecDeque};
use std::fmt::Write as _;

use pprz_messages::dynamic;
use pprz_messages::{BaseType, FieldType, MessageDescriptor};
use pprz_secure::{HandshakeError, Reject, SealError};
use pprz_transports::{AnyTransport, Decoder, DecoderStats, Framing, PprzV2};

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

/// Pushes `item` at time `now`, keeping the latest [`MAX_EVENTS`].
fn push_bounded<T>(queue: &mut VecDeque<(f64, T)>, now: f64, item: T) {
    if queue.len() >= MAX_EVENTS {
        queue.pop_front();
    }
    queue.push_back((now, item));
}

/// The decoding monitor.
pub struct Monitor {
    set: RuntimeSet,
    decoder: Decoder<AnyTransport>,
    messages: BTreeMap<(u8, u8), MessageStats>,
    bytes: u64,
    byte_rate: Rate,
    unknown: u64,
    malformed: u64,
    last_report: Option<String>,
    pings: PingTracker,
    settings: SettingTracker,
    events: VecDeque<(f64, Event)>,
    notices: VecDeque<(f64, Notice)>,
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
            bytes: 0,
            byte_rate: Rate::default(),
            unknown: 0,
            malformed: 0,
            last_report: None,
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
    /// timeouts).
    pub fn with_trackers(mut self, pings: PingTracker, settings: SettingTracker) -> Self {
        self.pings = pings;
        self.settings = settings;
        self
    }

    /// Feeds received bytes at time `now`; `on_message` gets one text line per decoded
    /// message (the plain output mode; escaped, without control characters), and the
    /// raw frame bytes (for recording).
    pub fn feed(&mut self, now: f64, bytes: &[u8], mut on_message: impl FnMut(&str, &[u8])) {
        self.bytes += bytes.len() as u64;
        self.byte_rate.add(now, bytes.len() as u64);
        let mut input = bytes;
        while let Some(frame) = self.decoder.feed(&mut input) {
            let received = Received::of(&frame);
            self.deliver(now, received, &mut on_message);
        }
    }

    /// End of input: decodes frames held behind an incomplete false start.
    pub fn flush(&mut self, now: f64, mut on_message: impl FnMut(&str, &[u8])) {
        while let Some(frame) = self.decoder.flush() {
            let received = Received::of(&frame);
            self.deliver(now, received, &mut on_message);
        }
    }

    /// Decodes a received frame, after opening it on a secure link.
    fn deliver(&mut self, now: f64, frame: Received, on_message: &mut impl FnMut(&str, &[u8])) {
        let Some(secure) = &mut self.secure else {
            let line = self.handle(now, frame.source, frame.class, frame.id, &frame.payload);
            on_message(&line, &frame.raw);
            return;
        };
        match secure.open(&frame.data, millis(now)) {
            Incoming::Plain(plain) => match PprzV2::new().view(&plain) {
                Ok(f) => {
                    let (source, class, id) = (f.source(), f.class(), f.msg_id());
                    let payload = f.payload().to_vec();
                    let line = self.handle(now, source, class, id, &payload);
                    on_message(&line, &plain);
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
                        self.event(now, Event::SecureSession { completed });
                    }
                    HandshakeEvent::Resend => {}
                    HandshakeEvent::Refused(HandshakeError::Duplicate) => {}
                    HandshakeEvent::Refused(e) => {
                        self.notice(now, Notice::HandshakeRefused(e));
                    }
                }
            }
            Incoming::Rejected(reason) => self.secure_rejected(now, reason),
        }
    }

    /// Notes a rejected secure frame; a run of rejections for one reason shares a notice.
    fn secure_rejected(&mut self, now: f64, reason: Reject) {
        if let Some((at, Notice::SecureRejected { reason: r, count })) = self.notices.back_mut()
            && *r == reason
            && now - *at < REJECT_COALESCE
        {
            *count = count.saturating_add(1);
            return;
        }
        self.notice(now, Notice::SecureRejected { reason, count: 1 });
    }

    /// Input was dropped under overload just before the next bytes: counts it, notes it
    /// for the live view, and abandons the frame being assembled (its end was dropped),
    /// decoding the frames buffered behind it, as [`flush`](Self::flush) does.
    pub fn input_gap(&mut self, now: f64, dropped: Drops, on_message: impl FnMut(&str, &[u8])) {
        if dropped.is_empty() {
            return;
        }
        self.input_dropped.bytes += dropped.bytes;
        self.input_dropped.reads += dropped.reads;
        self.input_gaps += 1;
        self.notice(now, Notice::InputDropped(dropped));
        self.flush(now, on_message);
    }

    fn handle(&mut self, now: f64, source: u8, class: u8, id: u8, payload: &[u8]) -> String {
        let Some(desc) = self.set.find(class, id) else {
            self.unknown += 1;
            return format::line(source, class, id, None, payload);
        };
        let body = format::fields(desc, payload);
        let line = format::known_line(source, desc, &body);
        let ok = dynamic::check(desc, payload).is_ok();
        if !ok {
            self.malformed += 1;
        }
        let entry = self
            .messages
            .entry((class, id))
            .or_insert_with(|| MessageStats {
                name: crate::escape::token(desc.name),
                class: crate::escape::token(desc.class_name),
                priority: desc.priority,
                ..MessageStats::default()
            });
        entry.count += 1;
        entry.recent.add(now, 1);
        entry.last = body;
        if ok {
            match desc.name {
                "PONG" => match self.pings.pong(now) {
                    Some(rtt) => self.event(now, Event::Pong { rtt }),
                    None => self.notice(now, Notice::UnexpectedPong),
                },
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
                        let answer = self.settings.dl_value(now, index, value, base);
                        self.event(
                            now,
                            Event::DlValue {
                                index,
                                value,
                                answer,
                            },
                        );
                    }
                }
                "DATALINK_REPORT" => self.last_report = Some(entry.last.clone()),
                _ => {}
            }
        }
        line
    }

    fn event(&mut self, now: f64, event: Event) {
        self.event_count += 1;
        push_bounded(&mut self.events, now, event);
    }

    fn notice(&mut self, now: f64, notice: Notice) {
        self.notice_count += 1;
        push_bounded(&mut self.notices, now, notice);
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
    /// lost, noted for the live view). Call it regularly; the other methods taking
    /// `now` do it too where it matters.
    pub fn tick(&mut self, now: f64) {
        let lost = self.pings.expire(now);
        if lost > 0 {
            self.notice(now, Notice::PingsLost { count: lost });
        }
        for e in self.settings.expire(now) {
            self.notice(now, Notice::RequestExpired(e));
        }
    }

    /// Records that a PING was sent at `now`; the PONGs answer the PINGs outstanding in
    /// order, oldest first.
    pub fn ping_sent(&mut self, now: f64) {
        let lost = self.pings.sent(now);
        if lost > 0 {
            self.notice(now, Notice::PingsLost { count: lost });
        }
    }

    /// Records that a SETTING of `index` to `value` was sent at `now`: only a DL_VALUE
    /// carrying that value (compared as the type of the `value` fields of SETTING and
    /// DL_VALUE) acknowledges it; another value is reported as not applied.
    pub fn setting_value_sent(&mut self, now: f64, index: u8, value: f64) {
        let base = scalar_type(self.set.find_by_name("datalink", "SETTING"), "value")
            .unwrap_or(BaseType::F32);
        self.settings.setting_sent(now, index, value, base);
    }

    /// Records that a request for setting `index` whose value is not known here was
    /// sent at `now` (a SETTING sent elsewhere): the next DL_VALUE of that index answers
    /// it, but is not taken as proof that a value was applied. Prefer
    /// [`setting_value_sent`](Self::setting_value_sent).
    pub fn setting_sent(&mut self, now: f64, index: u8) {
        self.settings.get_setting_sent(now, index);
    }

    /// Records that a GET_SETTING of `index` was sent at `now`.
    pub fn get_setting_sent(&mut self, now: f64, index: u8) {
        self.settings.get_setting_sent(now, index);
    }

    /// The latest events (PONG round trips, DL_VALUEs), oldest first; at most
    /// [`MAX_EVENTS`].
    pub fn events(&self) -> impl Iterator<Item = &(f64, Event)> {
        self.events.iter()
    }

    /// The latest notices (PINGs lost, requests given up, input dropped), oldest first;
    /// at most [`MAX_EVENTS`].
    pub fn notices(&self) -> impl Iterator<Item = &(f64, Notice)> {
        self.notices.iter()
    }

    /// The last round-trip time measured.
    pub fn last_rtt(&self) -> Option<f64> {
        self.pings.last_rtt()
    }

    /// The PINGs outstanding and their statistics.
    pub fn pings(&self) -> &PingTracker {
        &self.pings
    }

    /// The SETTING and GET_SETTING requests pending and their statistics.
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

    /// Messages received per priority level, most important first.
    pub fn per_priority(&self) -> BTreeMap<std::cmp::Reverse<u8>, u64> {
        let mut out = BTreeMap::new();
        for m in self.messages.values() {
            *out.entry(std::cmp::Reverse(m.priority)).or_insert(0) += m.count;
        }
        out
    }

    /// Bytes per second over the last [`RATE_WINDOW`] seconds.
    pub fn byte_rate(&self, now: f64) -> f64 {
        self.byte_rate.per_second(now)
    }

    /// An estimate of the heap memory the monitor holds, in bytes (the decoder's
    /// fixed buffer included): bounded by the size of the message set, whatever the
    /// input.
    pub fn retained_bytes(&self) -> usize {
        let per_message = std::mem::size_of::<((u8, u8), MessageStats)>() + 4 * 8;
        let messages: usize = self
            .messages
            .values()
            .map(|m| per_message + m.name.capacity() + m.class.capacity() + m.last.capacity())
            .sum();
        messages
            + std::mem::size_of::<Decoder<AnyTransport>>()
            + self.last_report.as_ref().map_or(0, String::capacity)
            + self.events.capacity() * std::mem::size_of::<(f64, Event)>()
            + self.notices.capacity() * std::mem::size_of::<(f64, Notice)>()
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

    /// PING and SETTING statistics, when there were any.
    fn uplink_status(&self) -> Vec<String> {
        let mut out = Vec::new();
        let p = &self.pings;
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
        let st = &self.settings;
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

    /// The secure link's status lines, if the monitor has one.
    pub fn secure_lines(&self) -> Vec<String> {
        self.secure_status()
            .map(|s| s.lines().to_vec())
            .unwrap_or_default()
    }

    /// The live view: the status, a table of messages, the latest events and notices.
    pub fn render(&self, now: f64) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "{}", self.status(now));
        for line in self.secure_lines() {
            let _ = writeln!(s, "{line}");
        }
        for line in self.uplink_status() {
            let _ = writeln!(s, "{line}");
        }
        if let Some(report) = &self.last_report {
            let _ = writeln!(s, "aircraft link report: {report}");
        }
        let _ = writeln!(
            s,
            "{:<10} {:<20} {:>4} {:>7} {:>7}  last values",
            "class", "message", "prio", "count", "rate/s"
        );
        for m in self.messages.values() {
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
        for (t, e) in &self.events {
            let _ = writeln!(s, "[{t:7.1}s] {}", describe_event(e));
        }
        for (t, n) in &self.notices {
            let _ = writeln!(s, "[{t:7.1}s] {}", describe_notice(n));
        }
        s
    }

    /// Messages received per priority level, as a short table.
    pub fn priority_summary(&self) -> String {
        let mut s = String::from("received per priority level:");
        for (p, n) in self.per_priority() {
            let _ = write!(s, "  {}: {n}", p.0);
        }
        s
    }

    /// The summary at the end of a run: the status line (with the input dropped under
    /// overload), PING and SETTING statistics, and messages per priority level.
    pub fn summary(&self, now: f64) -> String {
        let mut s = self.status(now);
        for line in self.secure_lines().into_iter().chain(self.uplink_status()) {
            s.push('\n');
            s.push_str(&line);
        }
        s.push('\n');
        s.push_str(&self.priority_summary());
        s
    }
}

/// A time in seconds as milliseconds (saturating; NaN and negative times are 0).
fn millis(now: f64) -> u64 {
    (now * 1000.0) as u64
}

/// What the monitor keeps of a decoded frame (the decoder's frame borrows the decoder).
struct Received {
    source: u8,
    class: u8,
    id: u8,
    payload: Vec<u8>,
    data: Vec<u8>,
    raw: Vec<u8>,
}

impl Received {
    fn of(frame: &pprz_transports::Frame<'_>) -> Self {
        Self {
            source: frame.source(),
            class: frame.class(),
            id: frame.msg_id(),
            payload: frame.payload().to_vec(),
            data: frame.data().to_vec(),
            raw: frame.raw().to_vec(),
        }
    }
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
        let mut buf = [0u8; 300];
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, id));
        let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn dl_value(index: u8, value: f32) -> Vec<u8> {
        let mut p = vec![index];
        p.extend(value.to_le_bytes());
        frame(31, &p)
    }

    fn feed(m: &mut Monitor, now: f64, bytes: &[u8]) -> Vec<String> {
        let mut lines = Vec::new();
        m.feed(now, bytes, |l, _| lines.push(l.to_owned()));
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
            |l, _| lines.push(l.to_owned()),
        );
        lines.extend(feed(&mut m, 0.1, &f));
        assert_eq!(lines, [r#"7 telemetry INFO_MSG msg="ok""#]);
        m.input_gap(
            0.2,
            Drops {
                bytes: 10,
                reads: 1,
            },
            |_, _| {},
        );
        m.input_gap(0.3, Drops::default(), |_, _| {});
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
}
