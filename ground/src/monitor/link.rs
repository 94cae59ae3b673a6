//! Link quality per aircraft: whether it is heard (live) or not for a while (stale), its
//! own view of the uplink (DATALINK_REPORT), the signal strength (its RSSI message and
//! the ground modem's XBee RSSI), an estimate of the downlink loss, and its autopilot
//! mode.
//!
//! Every figure is kept with the aircraft's state ([`Aircraft`](super::Aircraft)) and
//! read with [`Monitor::link_quality`]: the live view, the summary and the viewer's
//! `/ac/<id>/link` topic all show that one state.

use pprz_messages::dynamic::{self, Value};
use pprz_messages::{FieldDescriptor, FieldType, MessageDescriptor};

use super::{Monitor, Notice};

/// Seconds without a frame after which an aircraft is stale, unless set otherwise
/// ([`Monitor::with_stale_after`]): Paparazzi's `link` agent waits as long.
pub const DEFAULT_STALE_AFTER: f64 = 5.0;

/// The shortest stale time accepted, in seconds.
pub const MIN_STALE_AFTER: f64 = 0.1;

/// The longest stale time accepted, in seconds (one hour).
pub const MAX_STALE_AFTER: f64 = 3600.0;

/// The weight of each new XBee RSSI in the ground's smoothed mean (an exponential
/// mean: the latest frame counts for 1/8).
pub const GROUND_RSSI_WEIGHT: f64 = 0.125;

/// Whether an aircraft is heard.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// A frame arrived within the stale time.
    Live,
    /// No frame for the stale time or longer.
    Stale,
}

impl LinkState {
    /// `live` or `stale`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Live => "live",
            Self::Stale => "stale",
        }
    }
}

impl std::fmt::Display for LinkState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The link quality of one aircraft at a given time ([`Monitor::link_quality`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LinkQuality {
    /// Live or stale at that time.
    pub state: LinkState,
    /// Seconds since the latest frame from the aircraft.
    pub since_heard: f64,
    /// The aircraft's own view of the uplink: seconds since it last received from the
    /// ground (`uplink_lost_time` of its latest DATALINK_REPORT).
    pub uplink_lost_time: Option<f64>,
    /// The signal strength the aircraft's radio reports (RSSI message), in dBm: the
    /// message's `rssi` n is -n dBm, as XBee modules give it.
    pub rssi_dbm: Option<i16>,
    /// The aircraft radio's transmit power (RSSI message `tx_power`), in dB.
    pub tx_power_db: Option<u8>,
    /// The signal strength the ground's XBee modem reported for the latest frame from
    /// the aircraft, in dBm (`None` with other transports).
    pub ground_rssi_dbm: Option<i16>,
    /// The smoothed mean of the ground's XBee RSSI, in dBm ([`GROUND_RSSI_WEIGHT`]).
    pub ground_rssi_mean_dbm: Option<f64>,
    /// The downlink loss over the latest report period: 1 - received / sent, from 0
    /// to 1 (see [`Monitor::link_quality`]).
    pub loss_rate: Option<f64>,
    /// The downlink loss over every report period estimated so far, from 0 to 1.
    pub loss_overall: Option<f64>,
    /// The autopilot mode (`ap_mode` of ROTORCRAFT_STATUS or PPRZ_MODE), its label from
    /// the `messages.xml` (escaped), or the number when the file gives no label.
    pub ap_mode: Option<String>,
}

/// A stale time out of range: not a finite number from [`MIN_STALE_AFTER`] to
/// [`MAX_STALE_AFTER`] seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaleAfterError(pub f64);

impl std::fmt::Display for StaleAfterError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "stale time {} s is out of range: {MIN_STALE_AFTER} s to {MAX_STALE_AFTER} s",
            self.0
        )
    }
}

impl std::error::Error for StaleAfterError {}

/// The readings of the aircraft's downlink counter at its latest DATALINK_REPORT.
#[derive(Debug, Clone, Copy)]
struct Reading {
    /// `downlink_nb_msgs`, as an unsigned counter of `bits` bits.
    sent: u64,
    bits: u32,
    /// Frames received from the aircraft up to that report (the report included).
    frames: u64,
}

/// What the monitor tracks of one aircraft's link.
#[derive(Debug, Clone, Default)]
pub(super) struct LinkTrack {
    /// Time of the latest frame.
    last_heard: Option<f64>,
    /// Noted stale ([`Notice::LinkStale`]), not heard since.
    stale: bool,
    uplink_lost_time: Option<f64>,
    rssi: Option<u8>,
    tx_power: Option<u8>,
    ground_rssi: Option<u8>,
    ground_rssi_mean: Option<f64>,
    reading: Option<Reading>,
    loss_rate: Option<f64>,
    /// Messages sent and frames received over the periods estimated.
    sent_total: u64,
    received_total: u64,
    ap_mode: Option<String>,
}

impl LinkTrack {
    /// The time of the latest frame from the aircraft.
    pub(super) fn last_heard(&self) -> Option<f64> {
        self.last_heard
    }

    /// The heap memory held.
    pub(super) fn retained_bytes(&self) -> usize {
        self.ap_mode.as_ref().map_or(0, String::capacity)
    }

    /// The quality at `now`; `None` before the aircraft is heard.
    fn quality(&self, now: f64, stale_after: f64) -> Option<LinkQuality> {
        let at = self.last_heard?;
        // Never negative (a time before the latest frame), never NaN.
        let since_heard = (now - at).max(0.0);
        let state = if since_heard >= stale_after {
            LinkState::Stale
        } else {
            LinkState::Live
        };
        let dbm = |n: u8| -i16::from(n);
        Some(LinkQuality {
            state,
            since_heard,
            uplink_lost_time: self.uplink_lost_time,
            rssi_dbm: self.rssi.map(dbm),
            tx_power_db: self.tx_power,
            ground_rssi_dbm: self.ground_rssi.map(dbm),
            ground_rssi_mean_dbm: self.ground_rssi_mean,
            loss_rate: self.loss_rate,
            loss_overall: loss_rate(self.sent_total, self.received_total),
            ap_mode: self.ap_mode.clone(),
        })
    }

    /// A frame from the aircraft at `now` (with the ground modem's RSSI, if any): the
    /// notices of the transitions it makes, in order. A silence that no
    /// [`Monitor::tick`] noted is noted stale first.
    fn heard(&mut self, ac_id: u8, now: f64, stale_after: f64, rssi: Option<u8>) -> Vec<Notice> {
        let mut notes = Vec::new();
        if let Some(at) = self.last_heard {
            let silent = now - at;
            if !self.stale && silent >= stale_after {
                notes.push(Notice::LinkStale {
                    aircraft: ac_id,
                    silent,
                });
                self.stale = true;
            }
            if self.stale {
                notes.push(Notice::LinkLive {
                    aircraft: ac_id,
                    silent: silent.max(0.0),
                });
                self.stale = false;
            }
        }
        // A time before the latest one (or NaN) does not move the latest back.
        if now.is_finite() && self.last_heard.is_none_or(|at| now >= at) {
            self.last_heard = Some(now);
        }
        if let Some(n) = rssi {
            let dbm = -f64::from(n);
            self.ground_rssi = Some(n);
            self.ground_rssi_mean = Some(match self.ground_rssi_mean {
                Some(mean) => mean + GROUND_RSSI_WEIGHT * (dbm - mean),
                None => dbm,
            });
        }
        notes
    }

    /// The stale notice at `now`, when the aircraft goes stale then.
    fn check(&mut self, ac_id: u8, now: f64, stale_after: f64) -> Option<Notice> {
        let silent = now - self.last_heard?;
        // NaN (a time that is no number) is never stale.
        if self.stale || silent.partial_cmp(&stale_after).is_none_or(|o| o.is_lt()) {
            return None;
        }
        self.stale = true;
        Some(Notice::LinkStale {
            aircraft: ac_id,
            silent,
        })
    }

    /// A valid DATALINK_REPORT, the aircraft's `frames` counted (this one included).
    fn report(&mut self, desc: &MessageDescriptor<'_>, payload: &[u8], frames: u64) {
        if let Some((_, v)) = field(desc, payload, "uplink_lost_time") {
            self.uplink_lost_time = v.as_f64().filter(|t| t.is_finite());
        }
        let Some((f, v)) = field(desc, payload, "downlink_nb_msgs") else {
            return;
        };
        let (Some(bits), Some(value)) = (counter_bits(f), v.as_i64()) else {
            return;
        };
        // The counter's bits, whatever its sign.
        let sent = (value as u64) & mask(bits);
        let now = Reading { sent, bits, frames };
        if let Some(before) = self.reading.filter(|r| r.bits == bits) {
            let received = frames.saturating_sub(before.frames);
            if let Some(delta) = counter_delta(before.sent, sent, bits)
                && let Some(rate) = loss_rate(delta, received)
            {
                self.loss_rate = Some(rate);
                self.sent_total = self.sent_total.saturating_add(delta);
                // Frames beyond the messages sent (duplicates) count as no loss.
                self.received_total = self.received_total.saturating_add(received.min(delta));
            }
        }
        self.reading = Some(now);
    }

    /// A valid RSSI message.
    fn rssi(&mut self, desc: &MessageDescriptor<'_>, payload: &[u8]) {
        let byte = |name| {
            field(desc, payload, name)
                .and_then(|(_, v)| v.as_i64())
                .and_then(|n| u8::try_from(n).ok())
        };
        if let Some(rssi) = byte("rssi") {
            self.rssi = Some(rssi);
            self.tx_power = byte("tx_power");
        }
    }

    /// A valid message with the autopilot's `ap_mode`.
    fn mode(&mut self, desc: &MessageDescriptor<'_>, payload: &[u8]) {
        let Some((f, v)) = field(desc, payload, "ap_mode") else {
            return;
        };
        let Some(n) = v.as_i64() else {
            return;
        };
        self.ap_mode = Some(match f.label(n) {
            Some(label) => crate::escape::token(label),
            None => n.to_string(),
        });
    }
}

/// Field `name` of a valid payload and its value.
fn field<'d, 'p>(
    desc: &'d MessageDescriptor<'d>,
    payload: &'p [u8],
    name: &str,
) -> Option<(&'d FieldDescriptor<'d>, Value<'p>)> {
    dynamic::fields(desc, payload)
        .filter_map(Result::ok)
        .find(|(f, _)| f.name == name)
}

/// The bits of an integer scalar field (a wrapping counter); `None` for other fields.
fn counter_bits(f: &FieldDescriptor<'_>) -> Option<u32> {
    use pprz_messages::BaseType as B;
    match f.ty {
        FieldType::Scalar(
            b @ (B::U8 | B::I8 | B::U16 | B::I16 | B::U32 | B::I32 | B::U64 | B::I64),
        ) => Some(8 * b.size() as u32),
        _ => None,
    }
}

/// The values of a counter of `bits` bits.
fn mask(bits: u32) -> u64 {
    if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    }
}

/// How much a wrapping counter of `bits` bits grew from `previous` to `current`; `None`
/// when it went back or jumped by more than half its range (the aircraft restarted, or
/// the value is absurd): no estimate then.
fn counter_delta(previous: u64, current: u64, bits: u32) -> Option<u64> {
    let m = mask(bits);
    let delta = current.wrapping_sub(previous) & m;
    (delta <= m / 2).then_some(delta)
}

/// The loss when `sent` messages were sent and `received` frames arrived: 1 -
/// received / sent, clamped to 0..=1; `None` when nothing was sent.
fn loss_rate(sent: u64, received: u64) -> Option<f64> {
    if sent == 0 {
        return None;
    }
    Some((1.0 - received as f64 / sent as f64).clamp(0.0, 1.0))
}

impl Monitor {
    /// The same monitor marking an aircraft stale after `seconds` without a frame
    /// ([`DEFAULT_STALE_AFTER`] unless set).
    ///
    /// # Errors
    /// [`StaleAfterError`]: not a finite number from [`MIN_STALE_AFTER`] to
    /// [`MAX_STALE_AFTER`].
    pub fn with_stale_after(mut self, seconds: f64) -> Result<Self, StaleAfterError> {
        if !(MIN_STALE_AFTER..=MAX_STALE_AFTER).contains(&seconds) {
            return Err(StaleAfterError(seconds));
        }
        self.stale_after = seconds;
        Ok(self)
    }

    /// Seconds without a frame after which an aircraft is stale.
    pub fn stale_after(&self) -> f64 {
        self.stale_after
    }

    /// The latest time given to [`feed`](Self::feed), [`flush`](Self::flush),
    /// [`input_gap`](Self::input_gap) or [`tick`](Self::tick) (0 before any).
    pub fn clock(&self) -> f64 {
        self.clock
    }

    /// The link quality of aircraft `ac_id` at `now`; `None` when it is not tracked or
    /// was never heard.
    ///
    /// * The state is [`LinkState::Stale`] when no frame came from the aircraft for
    ///   [`stale_after`](Self::stale_after) seconds or more. [`tick`](Self::tick) notes
    ///   the transition ([`Notice::LinkStale`]), and the next frame from the aircraft
    ///   notes the return ([`Notice::LinkLive`]): one notice per transition.
    /// * The downlink loss is an estimate over a report period. Between two
    ///   DATALINK_REPORTs the aircraft's `downlink_nb_msgs` grows by S (the messages it
    ///   sent, a wrapping counter), and the ground receives R frames from it: the loss
    ///   is 1 - R/S, clamped to 0..=1. A period with S = 0 gives no estimate, nor one
    ///   where the counter goes back or jumps by more than half its range (a restart):
    ///   the previous estimate stays.
    /// * Frames count for the aircraft their source id names.
    pub fn link_quality(&self, ac_id: u8, now: f64) -> Option<LinkQuality> {
        self.aircraft
            .get(&ac_id)?
            .link
            .quality(now, self.stale_after)
    }

    /// Moves the clock to `now`, if later.
    pub(super) fn advance(&mut self, now: f64) {
        if now > self.clock {
            self.clock = now;
        }
    }

    /// A frame from tracked aircraft `source` at `now`, with the ground modem's RSSI.
    pub(super) fn link_heard(&mut self, source: u8, now: f64, rssi: Option<u8>) {
        let stale_after = self.stale_after;
        let Some(a) = self.aircraft.get_mut(&source) else {
            return;
        };
        for notice in a.link.heard(source, now, stale_after, rssi) {
            self.notice(now, Some(source), notice);
        }
    }

    /// Notes the aircraft that go stale at `now`.
    pub(super) fn check_links(&mut self, now: f64) {
        let stale_after = self.stale_after;
        let mut notes = Vec::new();
        for (&id, a) in &mut self.aircraft {
            if let Some(n) = a.link.check(id, now, stale_after) {
                notes.push((id, n));
            }
        }
        for (id, n) in notes {
            self.notice(now, Some(id), n);
        }
    }

    /// A valid message from tracked aircraft `source`: the link figures it carries.
    pub(super) fn link_message(
        &mut self,
        source: u8,
        desc: &MessageDescriptor<'_>,
        payload: &[u8],
    ) {
        if desc.class_name != "telemetry" {
            return;
        }
        let Some(a) = self.aircraft.get_mut(&source) else {
            return;
        };
        match desc.name {
            "DATALINK_REPORT" => a.link.report(desc, payload, a.frames),
            "RSSI" => a.link.rssi(desc, payload),
            "ROTORCRAFT_STATUS" | "PPRZ_MODE" => a.link.mode(desc, payload),
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_counter_wraps_and_a_restart_gives_no_delta() {
        assert_eq!(counter_delta(100, 150, 16), Some(50));
        assert_eq!(counter_delta(65_530, 4, 16), Some(10));
        assert_eq!(counter_delta(7, 7, 16), Some(0));
        // Back, or a jump over half the range: a restart, no estimate.
        assert_eq!(counter_delta(150, 100, 16), None);
        assert_eq!(counter_delta(0, 40_000, 16), None);
        assert_eq!(counter_delta(0, 32_767, 16), Some(32_767));
        assert_eq!(counter_delta(250, 2, 8), Some(8));
        assert_eq!(counter_delta(u64::MAX, 1, 64), Some(2));
    }

    #[test]
    fn loss_is_clamped_and_needs_messages_sent() {
        assert_eq!(loss_rate(0, 0), None);
        assert_eq!(loss_rate(0, 12), None);
        assert_eq!(loss_rate(100, 100), Some(0.0));
        assert_eq!(loss_rate(100, 75), Some(0.25));
        assert_eq!(loss_rate(100, 0), Some(1.0));
        // More frames than messages sent (duplicates, a forged source): no loss.
        assert_eq!(loss_rate(10, 50), Some(0.0));
        assert_eq!(loss_rate(u64::MAX, u64::MAX), Some(0.0));
    }

    #[test]
    fn the_stale_time_is_checked() {
        let set = crate::set::RuntimeSet::parse("m.xml", "<protocol></protocol>").unwrap();
        let m = || Monitor::new(set, pprz_transports::PprzV2::new().into());
        for bad in [
            0.0,
            -1.0,
            0.05,
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
            3601.0,
        ] {
            let e = m().with_stale_after(bad).err();
            assert!(e.is_some(), "{bad}");
        }
        assert_eq!(m().stale_after(), DEFAULT_STALE_AFTER);
        assert_eq!(m().with_stale_after(0.1).unwrap().stale_after(), 0.1);
        assert_eq!(m().with_stale_after(3600.0).unwrap().stale_after(), 3600.0);
        let e = StaleAfterError(-2.0).to_string();
        assert!(e.contains("-2 s is out of range"), "{e}");
    }
}
