//! Settings on the ground: acknowledgements of SETTING and answers to GET_SETTING
//! ([`SettingTracker`]), the settings files that name, bound and label the indices
//! ([`SettingsTable`]), and the reading of every setting ([`Sweep`]).
//!
//! An aircraft answers a SETTING with a DL_VALUE carrying the value *in force* for that
//! index, and also sends DL_VALUEs periodically. A DL_VALUE therefore acknowledges a
//! SETTING only when it carries the value that was set, compared as the wire type of
//! the field (a `float` setting of 0.1 comes back as `0.1f32`, not as `0.1f64`). A
//! DL_VALUE with another value is reported as *not applied*: the aircraft ignored or
//! refused the SETTING, or the DL_VALUE was sent before the SETTING arrived. The
//! request stays pending until a matching value arrives or the timeout expires (a
//! periodic DL_VALUE sent while the SETTING was in flight must not hide the real
//! acknowledgement that follows it).
//!
//! A GET_SETTING asks for the value in force: any DL_VALUE of its index answers it.
//!
//! ```
//! use pprz_ground::settings::{Answer, SettingTracker};
//! use pprz_messages::BaseType;
//! let mut s = SettingTracker::new(5.0);
//! s.setting_sent(0.0, 3, 0.1, BaseType::F32);
//! // The periodic DL_VALUE with the old value: not an acknowledgement.
//! let requested = f64::from(0.1f32);
//! assert_eq!(s.dl_value(0.1, 3, 0.7, BaseType::F32), Answer::NotApplied { requested, after: 0.1 });
//! // The value set, as a float32 on the wire.
//! let after = match s.dl_value(0.2, 3, f64::from(0.1f32), BaseType::F32) {
//!     Answer::Acknowledged { after } => after,
//!     other => panic!("{other:?}"),
//! };
//! assert_eq!(after, 0.2);
//! ```

use std::collections::BTreeMap;

use pprz_messages::BaseType;

mod sweep;
mod table;

pub use sweep::{MAX_NAMED_FAILURES, Sweep, SweepConfig, progress_line};
pub(crate) use table::text;
pub use table::{NameError, SettingsTable, ValueError, display_unit, from_display, to_display};

/// Default time after which an unanswered request is given up, in seconds.
pub const TIMEOUT: f64 = 5.0;

/// `v` as it reads back after being written as a `base` field: rounded to `f32` for a
/// `float`, truncated and saturated to the range of an integer type (as the uplink
/// encoder would have refused anything else).
pub fn quantize(base: BaseType, v: f64) -> f64 {
    match base {
        BaseType::F64 => v,
        BaseType::F32 => f64::from(v as f32),
        BaseType::U8 | BaseType::Char => f64::from(v as u8),
        BaseType::I8 => f64::from(v as i8),
        BaseType::U16 => f64::from(v as u16),
        BaseType::I16 => f64::from(v as i16),
        BaseType::U32 => f64::from(v as u32),
        BaseType::I32 => f64::from(v as i32),
        BaseType::U64 => (v as u64) as f64,
        BaseType::I64 => (v as i64) as f64,
    }
}

/// A SETTING value that cannot be sent: not a finite number that fits a `float` (NaN,
/// an infinity, or a finite double such as 1e300 that would go out as an infinity).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotAFloat(pub f64);

impl std::fmt::Display for NotAFloat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = self.0;
        // 1e300, not three hundred digits.
        if v.is_finite() && v != 0.0 && !(1e-5..1e16).contains(&v.abs()) {
            write!(f, "{v:e} is not a finite number that fits a float")
        } else {
            write!(f, "{v} is not a finite number that fits a float")
        }
    }
}

impl std::error::Error for NotAFloat {}

/// The one rule for the value of a SETTING, wherever it comes from (`--setting`, a
/// viewer): a finite number that fits a `float`. Returns it as a `float`.
///
/// ```
/// use pprz_ground::settings::{NotAFloat, setting_value};
/// assert_eq!(setting_value(1.5), Ok(1.5f32));
/// assert_eq!(setting_value(1e300), Err(NotAFloat(1e300)));
/// assert_eq!(setting_value(-1e39), Err(NotAFloat(-1e39)));
/// assert!(setting_value(f64::NAN).is_err());
/// assert_eq!(NotAFloat(1e300).to_string(), "1e300 is not a finite number that fits a float");
/// ```
///
/// # Errors
/// [`NotAFloat`]: NaN, an infinity, or beyond the range of a `float`.
pub fn setting_value(v: f64) -> Result<f32, NotAFloat> {
    let f = v as f32;
    if f.is_finite() {
        Ok(f)
    } else {
        Err(NotAFloat(v))
    }
}

/// What a DL_VALUE means for the requests pending on its index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Answer {
    /// No request pending on this index: a periodic report.
    Unsolicited,
    /// It carries the value of the pending SETTING, `after` seconds after it was sent.
    Acknowledged {
        /// Seconds since the SETTING was sent.
        after: f64,
    },
    /// A SETTING is pending but the value in force is not the one set.
    NotApplied {
        /// The value the SETTING asked for (as sent on the wire).
        requested: f64,
        /// Seconds since the SETTING was sent.
        after: f64,
    },
    /// It answers a GET_SETTING, `after` seconds after it was sent.
    Answered {
        /// Seconds since the GET_SETTING was sent.
        after: f64,
    },
}

/// A request given up after the timeout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Expired {
    /// Setting index.
    pub index: u8,
    /// The value a SETTING asked for; `None` for a GET_SETTING.
    pub requested: Option<f64>,
    /// The last value the aircraft reported for this index meanwhile (a SETTING not
    /// applied), if any.
    pub reported: Option<f64>,
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    sent: f64,
    /// The value set (as sent), or `None` for a GET_SETTING.
    requested: Option<f64>,
    reported: Option<f64>,
}

/// Requests waiting for their DL_VALUE, at most one per index (256 at most).
#[derive(Debug, Clone)]
pub struct SettingTracker {
    pending: BTreeMap<u8, Pending>,
    timeout: f64,
    acknowledged: u64,
    not_applied: u64,
    unanswered: u64,
}

impl Default for SettingTracker {
    fn default() -> Self {
        Self::new(TIMEOUT)
    }
}

/// Equality of two values read from the wire (NaN equals NaN: a NaN setting echoed back
/// is applied).
fn same(a: f64, b: f64) -> bool {
    a == b || (a.is_nan() && b.is_nan())
}

impl SettingTracker {
    /// A tracker giving requests up after `timeout` seconds.
    pub fn new(timeout: f64) -> Self {
        Self {
            pending: BTreeMap::new(),
            timeout,
            acknowledged: 0,
            not_applied: 0,
            unanswered: 0,
        }
    }

    /// A SETTING of `index` to `value` was sent at `now` in a field of type `base`
    /// (a new request on the same index replaces the previous one).
    pub fn setting_sent(&mut self, now: f64, index: u8, value: f64, base: BaseType) {
        let pending = Pending {
            sent: now,
            requested: Some(quantize(base, value)),
            reported: None,
        };
        self.pending.insert(index, pending);
    }

    /// A GET_SETTING of `index` was sent at `now`. A SETTING pending on the same index
    /// stays pending (its acknowledgement also answers the GET_SETTING).
    pub fn get_setting_sent(&mut self, now: f64, index: u8) {
        self.pending.entry(index).or_insert(Pending {
            sent: now,
            requested: None,
            reported: None,
        });
    }

    /// A DL_VALUE of `index` with `value` (a field of type `base`) arrived at `now`.
    pub fn dl_value(&mut self, now: f64, index: u8, value: f64, base: BaseType) -> Answer {
        let Some(p) = self.pending.get_mut(&index) else {
            return Answer::Unsolicited;
        };
        let after = now - p.sent;
        match p.requested {
            None => {
                self.pending.remove(&index);
                Answer::Answered { after }
            }
            Some(requested) if same(quantize(base, requested), value) => {
                self.pending.remove(&index);
                self.acknowledged += 1;
                Answer::Acknowledged { after }
            }
            Some(requested) => {
                p.reported = Some(value);
                Answer::NotApplied { requested, after }
            }
        }
    }

    /// Gives up the requests older than the timeout at `now`, oldest index first.
    pub fn expire(&mut self, now: f64) -> Vec<Expired> {
        let timeout = self.timeout;
        let mut out = Vec::new();
        self.pending.retain(|&index, p| {
            if now - p.sent <= timeout {
                return true;
            }
            out.push(Expired {
                index,
                requested: p.requested,
                reported: p.reported,
            });
            false
        });
        for e in &out {
            match (e.requested, e.reported) {
                (Some(_), Some(_)) => self.not_applied += 1,
                _ => self.unanswered += 1,
            }
        }
        out
    }

    /// The timeout, in seconds.
    pub fn timeout(&self) -> f64 {
        self.timeout
    }

    /// Requests pending.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// The requests pending, by index, as they would expire now: the value a SETTING
    /// asked for, and the other value the aircraft reported meanwhile, if any.
    pub fn pending_requests(&self) -> impl Iterator<Item = Expired> + '_ {
        self.pending.iter().map(|(&index, p)| Expired {
            index,
            requested: p.requested,
            reported: p.reported,
        })
    }

    /// SETTINGs acknowledged with the value set.
    pub fn acknowledged(&self) -> u64 {
        self.acknowledged
    }

    /// SETTINGs given up while the aircraft reported another value.
    pub fn not_applied(&self) -> u64 {
        self.not_applied
    }

    /// Requests given up without any DL_VALUE of their index.
    pub fn unanswered(&self) -> u64 {
        self.unanswered
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantize_as_the_wire_type() {
        assert_eq!(quantize(BaseType::F32, 0.1), f64::from(0.1f32));
        assert_ne!(quantize(BaseType::F32, 0.1), 0.1);
        assert_eq!(quantize(BaseType::F64, 0.1), 0.1);
        assert_eq!(quantize(BaseType::U8, 300.0), 255.0);
        assert_eq!(quantize(BaseType::I16, -2.7), -2.0);
        assert_eq!(quantize(BaseType::I8, f64::NAN), 0.0);
        assert!(quantize(BaseType::F32, f64::NAN).is_nan());
    }

    /// Issue: a periodic DL_VALUE carrying the old value was shown as the
    /// acknowledgement of a SETTING the aircraft ignored.
    #[test]
    fn an_old_value_is_not_an_acknowledgement() {
        let mut s = SettingTracker::new(5.0);
        s.setting_sent(10.0, 4, 2.5, BaseType::F32);
        assert_eq!(s.dl_value(10.1, 3, 2.5, BaseType::F32), Answer::Unsolicited);
        assert!(matches!(
            s.dl_value(10.2, 4, 1.0, BaseType::F32),
            Answer::NotApplied { requested, .. } if requested == 2.5
        ));
        assert_eq!(s.pending(), 1);
        let pending: Vec<_> = s.pending_requests().collect();
        assert_eq!(pending[0].reported, Some(1.0));
        // The aircraft never applies it: given up, counted as not applied.
        assert_eq!(s.expire(14.0), []);
        assert_eq!(
            s.expire(15.5),
            [Expired {
                index: 4,
                requested: Some(2.5),
                reported: Some(1.0)
            }]
        );
        assert_eq!((s.not_applied(), s.acknowledged(), s.pending()), (1, 0, 0));
        assert_eq!(s.dl_value(16.0, 4, 1.0, BaseType::F32), Answer::Unsolicited);
    }

    #[test]
    fn the_value_set_is_an_acknowledgement_even_after_an_old_one() {
        let mut s = SettingTracker::new(5.0);
        s.setting_sent(0.0, 4, 0.1, BaseType::F32);
        assert!(matches!(
            s.dl_value(0.05, 4, 0.0, BaseType::F32),
            Answer::NotApplied { .. }
        ));
        // 0.1 as f64 is not what a float field carries back.
        assert!(matches!(
            s.dl_value(0.06, 4, 0.1, BaseType::F64),
            Answer::NotApplied { .. }
        ));
        assert_eq!(
            s.dl_value(0.25, 4, f64::from(0.1f32), BaseType::F32),
            Answer::Acknowledged { after: 0.25 }
        );
        assert_eq!(s.acknowledged(), 1);
        assert_eq!(s.pending(), 0);
    }

    #[test]
    fn get_setting_is_answered_by_any_value_and_times_out() {
        let mut s = SettingTracker::new(1.0);
        s.get_setting_sent(0.0, 1);
        assert_eq!(
            s.dl_value(0.5, 1, 42.0, BaseType::F32),
            Answer::Answered { after: 0.5 }
        );
        s.get_setting_sent(1.0, 2);
        s.setting_sent(1.0, 3, 1.0, BaseType::U8);
        s.get_setting_sent(1.1, 3); // the SETTING stays pending
        assert_eq!(s.pending(), 2);
        let expired = s.expire(3.0);
        assert_eq!(expired.len(), 2);
        assert_eq!(expired[1].requested, Some(1.0));
        assert_eq!(s.unanswered(), 2);
    }
}
