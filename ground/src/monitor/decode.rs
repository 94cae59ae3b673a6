//! Decoding: frames from the byte stream (opened first on a secure link), messages from
//! the frames, and the state they update.

use pprz_messages::dynamic;
use pprz_messages::{BaseType, FieldType, MessageDescriptor};
use pprz_secure::{HandshakeError, Reject, SealError};
use pprz_transports::{AnyTransport, BROADCAST_ID, Framing, GROUND_ID, PprzV2};

use super::events::Logged;
use super::state::{Aircraft, count_message};
use super::{Event, LogClock, MAX_AIRCRAFT, MAX_SECURE_OUT, Monitor, Notice, REJECT_COALESCE};
use crate::format;
use crate::input::Drops;
use crate::secure::{GroundSecure, HandshakeEvent, Incoming, SecureSetupError, SecureStatus};

/// The scalar type of field `name` of `desc`.
pub(super) fn scalar_type(desc: Option<&MessageDescriptor<'_>>, name: &str) -> Option<BaseType> {
    desc?.fields.iter().find_map(|f| match f.ty {
        FieldType::Scalar(base) if f.name == name => Some(base),
        _ => None,
    })
}

impl Monitor {
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

    /// Feeds received bytes at time `now`; `on_message` gets each decoded message
    /// ([`Decoded`]: its text line, escaped and without control characters, the raw
    /// frame bytes for recording, and the decoded form for viewers).
    pub fn feed(&mut self, now: f64, bytes: &[u8], mut on_message: impl FnMut(&Decoded<'_>)) {
        self.advance(now);
        self.bytes += bytes.len() as u64;
        self.byte_rate.add(now, bytes.len() as u64);
        let mut input = bytes;
        while let Some(frame) = self.decoder.feed(&mut input) {
            let received = Received::of(&frame, &mut self.log_clock);
            self.deliver(now, received, &mut on_message);
        }
    }

    /// A message another decoder delivered (a gateway's link), carried in `frame`: counted
    /// and handled as if this monitor had decoded that frame from its input, without
    /// decoding it again; `on_message` gets it with `frame` as its raw frame. Not for a
    /// secure link (the message is taken as authenticated by whoever decoded it).
    pub fn message(
        &mut self,
        now: f64,
        m: &Decoded<'_>,
        frame: &[u8],
        mut on_message: impl FnMut(&Decoded<'_>),
    ) {
        self.advance(now);
        self.bytes += frame.len() as u64;
        self.byte_rate.add(now, frame.len() as u64);
        let header = Header {
            source: m.source,
            destination: m.destination,
            class: m.class_id,
            id: m.msg_id,
            rssi: None,
        };
        let handled = self.handle(now, &header, m.payload);
        on_message(&handled.decoded(&header, m.payload, frame, m.log_time));
    }

    /// End of input: decodes frames held behind an incomplete false start.
    pub fn flush(&mut self, now: f64, mut on_message: impl FnMut(&Decoded<'_>)) {
        self.advance(now);
        while let Some(frame) = self.decoder.flush() {
            let received = Received::of(&frame, &mut self.log_clock);
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
        self.advance(now);
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
    /// [`MAX_AIRCRAFT`] aircraft were heard; already tracked because the ground
    /// addresses it) or not. Aircraft only addressed, never heard, take none of the
    /// [`MAX_AIRCRAFT`] places.
    fn admit(&mut self, source: u8) {
        if !self.aircraft.contains_key(&source) && self.heard >= MAX_AIRCRAFT {
            self.untracked_frames += 1;
            self.untracked_ids[usize::from(source / 64)] |= 1 << (source % 64);
            return;
        }
        let (pings, settings) = (&self.pings, &self.settings);
        let a = self
            .aircraft
            .entry(source)
            .or_insert_with(|| Aircraft::new(source, pings, settings));
        if a.frames == 0 {
            self.heard += 1;
        }
        a.frames += 1;
    }

    /// The state of aircraft `ac_id`, which the ground addresses: created whatever the
    /// bound.
    pub(super) fn addressed(&mut self, ac_id: u8) -> &mut Aircraft {
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
        self.link_heard(source, now, header.rssi);
        let aircraft = self.aircraft.get_mut(&source);
        let Some(desc) = self.set.find(class, id) else {
            self.unknown += 1;
            if let Some(a) = aircraft {
                a.unknown += 1;
            }
            let line = if self.text {
                format::line(source, class, id, None, payload)
            } else {
                String::new()
            };
            return Handled {
                line,
                message: None,
                valid: false,
            };
        };
        let (body, mut line) = if self.text {
            let body = format::fields(desc, payload);
            let line = format::known_line(source, desc, &body);
            (body, line)
        } else {
            (String::new(), String::new())
        };
        let ok = dynamic::check(desc, payload).is_ok();
        let dl_value = (ok && desc.name == "DL_VALUE")
            .then(|| dl_value_fields(desc, payload))
            .flatten();
        if let Some((index, _, _)) = dl_value
            && self.text
            && let Some(name) = self.table.as_deref().and_then(|t| t.unique_name(index))
        {
            line.push_str(" setting=");
            line.push_str(&crate::escape::token(name));
        }
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
        if ok {
            self.link_message(source, desc, payload);
        }
        if report {
            self.last_report = Some(body.clone());
        }
        count_message(&mut self.messages, desc, now, body);
        if ok && header.to_ground() {
            if desc.name == "PONG" {
                self.pong(now, source);
            }
            if let Some((index, value, base)) = dl_value {
                self.dl_value(now, source, index, value, base);
            }
        }
        Handled {
            line,
            message: Some(desc),
            valid: ok,
        }
    }
}

/// The index, value and value type of a valid DL_VALUE.
fn dl_value_fields(desc: &MessageDescriptor<'_>, payload: &[u8]) -> Option<(u8, f64, BaseType)> {
    let value = |name| {
        dynamic::fields(desc, payload)
            .filter_map(Result::ok)
            .find(|(f, _)| f.name == name)
            .map(|(_, v)| v)
    };
    let index = u8::try_from(value("index")?.as_i64()?).ok()?;
    let number = value("value")?.as_f64()?;
    let base = scalar_type(Some(desc), "value").unwrap_or(BaseType::F64);
    Some((index, number, base))
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
    /// The signal strength the ground's XBee modem measured (`n` = `-n` dBm).
    rssi: Option<u8>,
}

impl Header {
    fn of(frame: &pprz_transports::Frame<'_>) -> Self {
        Self {
            source: frame.source(),
            destination: frame.destination(),
            class: frame.class(),
            id: frame.msg_id(),
            rssi: frame.rssi(),
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
    fn of(frame: &pprz_transports::Frame<'_>, clock: &mut LogClock) -> Self {
        Self {
            header: Header::of(frame),
            payload: frame.payload().to_vec(),
            data: frame.data().to_vec(),
            raw: frame.raw().to_vec(),
            log_time: frame.timestamp().map(|ticks| clock.time(ticks)),
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
            destination: header.destination,
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
    /// The frame's destination id (`None` with PPRZ v1, which has none).
    pub destination: Option<u8>,
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
