//! The monitor's state: decodes a byte stream with a chosen transport and a run-time
//! message set, keeps per-message statistics and the latest values, link statistics,
//! round-trip times of PINGs and the acknowledgements of SETTINGs, and renders them.
//!
//! Time is passed in (seconds since the start of the run), so the state is testable and
//! a replay reproduces the same output.

use std::collections::{BTreeMap, VecDeque};
use std::fmt::Write as _;

use pprz_messages::dynamic;
use pprz_transports::{AnyTransport, Decoder, DecoderStats};

use crate::format;
use crate::set::RuntimeSet;

/// How long a window the rates are computed over, in seconds.
pub const RATE_WINDOW: f64 = 5.0;

/// What the monitor knows about one message.
#[derive(Debug, Clone, Default)]
pub struct MessageStats {
    /// Message name (or `id=N` when unknown).
    pub name: String,
    /// Class name.
    pub class: String,
    /// Priority from the message set.
    pub priority: u8,
    /// Messages received.
    pub count: u64,
    /// Arrival times in the last [`RATE_WINDOW`] seconds.
    recent: VecDeque<f64>,
    /// The latest fields, formatted.
    pub last: String,
}

impl MessageStats {
    /// Messages per second over the last [`RATE_WINDOW`] seconds.
    pub fn rate(&self, now: f64) -> f64 {
        let n = self
            .recent
            .iter()
            .filter(|t| now - **t <= RATE_WINDOW)
            .count();
        n as f64 / RATE_WINDOW.min(now.max(1e-9))
    }
}

/// Events worth a line of their own in the live view.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A PONG arrived `rtt` seconds after the last PING.
    Pong {
        /// Round-trip time in seconds.
        rtt: f64,
    },
    /// A DL_VALUE arrived; `ack_after` is set when it acknowledges a pending SETTING or
    /// GET_SETTING of that index.
    DlValue {
        /// Setting index.
        index: u8,
        /// Value reported by the aircraft.
        value: f64,
        /// Seconds since the request, if it answers one.
        ack_after: Option<f64>,
    },
}

/// The decoding monitor.
pub struct Monitor {
    set: RuntimeSet,
    decoder: Decoder<AnyTransport>,
    messages: BTreeMap<(u8, u8), MessageStats>,
    bytes: u64,
    byte_times: VecDeque<(f64, usize)>,
    unknown: u64,
    malformed: u64,
    last_report: Option<String>,
    ping_sent: Option<f64>,
    pending_settings: BTreeMap<u8, f64>,
    events: VecDeque<(f64, Event)>,
    last_rtt: Option<f64>,
}

impl Monitor {
    /// A monitor decoding `transport` frames with the messages of `set`.
    pub fn new(set: RuntimeSet, transport: AnyTransport) -> Self {
        Self {
            set,
            decoder: Decoder::new(transport),
            messages: BTreeMap::new(),
            bytes: 0,
            byte_times: VecDeque::new(),
            unknown: 0,
            malformed: 0,
            last_report: None,
            ping_sent: None,
            pending_settings: BTreeMap::new(),
            events: VecDeque::new(),
            last_rtt: None,
        }
    }

    /// Feeds received bytes at time `now`; `on_message` gets one text line per decoded
    /// message (the plain output mode), and the raw frame bytes (for recording).
    pub fn feed(&mut self, now: f64, bytes: &[u8], mut on_message: impl FnMut(&str, &[u8])) {
        self.bytes += bytes.len() as u64;
        self.byte_times.push_back((now, bytes.len()));
        while self
            .byte_times
            .front()
            .is_some_and(|(t, _)| now - t > RATE_WINDOW)
        {
            self.byte_times.pop_front();
        }
        let mut input = bytes;
        while let Some(frame) = self.decoder.feed(&mut input) {
            let (source, class, id) = (frame.source(), frame.class(), frame.msg_id());
            let payload = frame.payload().to_vec();
            let raw = frame.raw().to_vec();
            let line = self.handle(now, source, class, id, &payload);
            on_message(&line, &raw);
        }
    }

    /// End of input: decodes frames held behind an incomplete false start.
    pub fn flush(&mut self, now: f64, mut on_message: impl FnMut(&str, &[u8])) {
        while let Some(frame) = self.decoder.flush() {
            let (source, class, id) = (frame.source(), frame.class(), frame.msg_id());
            let payload = frame.payload().to_vec();
            let raw = frame.raw().to_vec();
            let line = self.handle(now, source, class, id, &payload);
            on_message(&line, &raw);
        }
    }

    fn handle(&mut self, now: f64, source: u8, class: u8, id: u8, payload: &[u8]) -> String {
        let desc = self.set.find(class, id);
        let line = format::line(source, class, id, desc, payload);
        let Some(desc) = desc else {
            self.unknown += 1;
            return line;
        };
        let ok = dynamic::check(desc, payload).is_ok();
        if !ok {
            self.malformed += 1;
        }
        let entry = self
            .messages
            .entry((class, id))
            .or_insert_with(|| MessageStats {
                name: desc.name.to_owned(),
                class: desc.class_name.to_owned(),
                priority: desc.priority,
                ..MessageStats::default()
            });
        entry.count += 1;
        entry.recent.push_back(now);
        while entry.recent.front().is_some_and(|t| now - t > RATE_WINDOW) {
            entry.recent.pop_front();
        }
        entry.last = format::fields(desc, payload);
        if ok {
            match desc.name {
                "PONG" => {
                    if let Some(sent) = self.ping_sent.take() {
                        self.last_rtt = Some(now - sent);
                        self.event(now, Event::Pong { rtt: now - sent });
                    }
                }
                "DL_VALUE" => {
                    let value = |name| {
                        dynamic::fields(desc, payload)
                            .filter_map(Result::ok)
                            .find(|(f, _)| f.name == name)
                            .and_then(|(_, v)| v.as_f64())
                    };
                    if let (Some(index), Some(value)) = (value("index"), value("value")) {
                        let index = index as u8;
                        let ack_after = self.pending_settings.remove(&index).map(|t| now - t);
                        self.event(
                            now,
                            Event::DlValue {
                                index,
                                value,
                                ack_after,
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
        self.events.push_back((now, event));
        while self.events.len() > 8 {
            self.events.pop_front();
        }
    }

    /// Records that a PING was sent at `now` (the next PONG gives the round-trip time).
    pub fn ping_sent(&mut self, now: f64) {
        self.ping_sent = Some(now);
    }

    /// Records that a SETTING or GET_SETTING of `index` was sent at `now`.
    pub fn setting_sent(&mut self, now: f64, index: u8) {
        self.pending_settings.insert(index, now);
    }

    /// The latest events (PONG round trips, DL_VALUE acknowledgements), oldest first.
    pub fn events(&self) -> impl Iterator<Item = &(f64, Event)> {
        self.events.iter()
    }

    /// The last round-trip time measured.
    pub fn last_rtt(&self) -> Option<f64> {
        self.last_rtt
    }

    /// Statistics per message, by (class, id).
    pub fn messages(&self) -> &BTreeMap<(u8, u8), MessageStats> {
        &self.messages
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
        let n: usize = self
            .byte_times
            .iter()
            .filter(|(t, _)| now - t <= RATE_WINDOW)
            .map(|(_, n)| n)
            .sum();
        n as f64 / RATE_WINDOW.min(now.max(1e-9))
    }

    /// The live view: a table of messages and the link statistics.
    pub fn render(&self, now: f64) -> String {
        let mut s = String::new();
        let st = self.decoder.stats();
        let _ = writeln!(
            s,
            "t={now:7.1}s  {:7.0} B/s  frames ok {}  checksum errors {}  length errors {}  dropped bytes {}  unknown {}  malformed {}",
            self.byte_rate(now),
            st.frames,
            st.checksum_errors,
            st.length_errors,
            st.dropped_bytes,
            self.unknown,
            self.malformed
        );
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
            if last.chars().count() > 110 {
                last = last.chars().take(107).chain("...".chars()).collect();
            }
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
            let _ = match e {
                Event::Pong { rtt } => {
                    writeln!(s, "[{t:7.1}s] PONG: round trip {:.1} ms", rtt * 1e3)
                }
                Event::DlValue {
                    index,
                    value,
                    ack_after: Some(after),
                } => writeln!(
                    s,
                    "[{t:7.1}s] DL_VALUE index={index} value={value}: acknowledged after {:.1} ms",
                    after * 1e3
                ),
                Event::DlValue { index, value, .. } => {
                    writeln!(s, "[{t:7.1}s] DL_VALUE index={index} value={value}")
                }
            };
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
}
