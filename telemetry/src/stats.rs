//! Downlink statistics per device: what was submitted, sent, dropped (by reason) and
//! evicted, queue high-water mark, and what the ground's DATALINK_REPORT needs.
//!
//! Accounting invariant, in every snapshot taken while no other context sends or writes
//! on the device (the counters are read one by one, without a lock: a snapshot taken
//! meanwhile may be off by the messages in transit):
//!
//! ```text
//! submitted = sent + dropped.total() + evicted.total() + superseded + queued
//! ```
//!
//! where `queued` counts the frames waiting in the device's queue plus the one its writer
//! is writing, and `superseded` the state messages replaced, while waiting, by a newer
//! instance of the same message ([`SendOptions::latest`](crate::SendOptions::latest)).
//! Every message accepted for sending is therefore either sent or counted as dropped,
//! evicted or superseded, by reason.

use core::fmt;
use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

use embassy_sync::blocking_mutex::raw::RawMutex;

use crate::atomic::{self, Fallback};

/// Why a message did not reach a device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum DropReason {
    /// The frame is larger than the device's transport carries, or than the arena
    /// allocates.
    TooLarge,
    /// The message could not be encoded (a variable array of more than 255 elements).
    Encode,
    /// The device's queue was full of messages at least as important.
    QueueFull,
    /// The frame arena was full of messages at least as important.
    ArenaFull,
    /// The device reported an error while writing the frame.
    WriteError,
    /// No device of the downlink was among the targets (an empty [`Targets`] set, or
    /// only indices past the last device). Counted once per send in the downlink's
    /// [`undeliverable`](crate::Downlink::undeliverable) counter, not per device.
    ///
    /// [`Targets`]: crate::Targets
    NoDevice,
    /// The device's reply rate limit ([`ReplyLimit`](crate::ReplyLimit)) refused a reply
    /// (a request flood must not starve the device's telemetry).
    RateLimited,
    /// The device's [`LinkLayer`](crate::layer::LinkLayer) refused the frame when the
    /// writer took it for the wire (the secure link: no session yet, or the session's
    /// frame counter used up).
    Refused,
}

impl fmt::Display for DropReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::TooLarge => "frame too large for the transport or the arena",
            Self::Encode => "message could not be encoded",
            Self::QueueFull => "device queue full of more important messages",
            Self::ArenaFull => "frame arena full of more important messages",
            Self::WriteError => "device write error",
            Self::NoDevice => "no device of the downlink among the targets",
            Self::RateLimited => "reply refused by the device's reply rate limit",
            Self::Refused => "frame refused by the device's link layer",
        })
    }
}

/// Messages dropped before reaching the wire, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DropCounts {
    /// [`DropReason::TooLarge`]
    pub too_large: u32,
    /// [`DropReason::Encode`]
    pub encode: u32,
    /// [`DropReason::QueueFull`]: the new message was less important than everything queued.
    pub queue_full: u32,
    /// [`DropReason::ArenaFull`]: the new message was less important than everything queued.
    pub arena_full: u32,
    /// [`DropReason::WriteError`]
    pub write_error: u32,
    /// [`DropReason::RateLimited`]: replies refused by the device's reply rate limit.
    pub rate_limited: u32,
    /// [`DropReason::Refused`]: frames the device's link layer refused at write time.
    pub refused: u32,
}

impl DropCounts {
    /// Sum of all reasons.
    pub fn total(&self) -> u32 {
        self.too_large
            .wrapping_add(self.encode)
            .wrapping_add(self.queue_full)
            .wrapping_add(self.arena_full)
            .wrapping_add(self.write_error)
            .wrapping_add(self.rate_limited)
            .wrapping_add(self.refused)
    }

    /// The position of `reason` among the fields, `None` for [`DropReason::NoDevice`] (not
    /// a device's drop: the downlink counts it, `undeliverable`).
    pub(crate) fn index(reason: DropReason) -> Option<usize> {
        Some(match reason {
            DropReason::TooLarge => 0,
            DropReason::Encode => 1,
            DropReason::QueueFull => 2,
            DropReason::ArenaFull => 3,
            DropReason::WriteError => 4,
            DropReason::RateLimited => 5,
            DropReason::Refused => 6,
            DropReason::NoDevice => return None,
        })
    }
}

/// Queued messages removed to make room for a more important one, by what was full.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EvictCounts {
    /// Evicted because the device's queue was full.
    pub queue_full: u32,
    /// Evicted because the shared frame arena was full.
    pub arena_full: u32,
}

impl EvictCounts {
    /// Sum of both causes.
    pub fn total(&self) -> u32 {
        self.queue_full.wrapping_add(self.arena_full)
    }
}

/// Messages of one priority level (see [`pprz_messages::priority::level`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LevelStats {
    /// Messages of this level accepted for sending to the device.
    pub submitted: u32,
    /// Written completely.
    pub sent: u32,
    /// Dropped or evicted (shed), or lost to a write error.
    pub lost: u32,
    /// Replaced while waiting by a newer instance of the same state message.
    pub superseded: u32,
}

/// Statistics of one device of the downlink (a snapshot).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceStats {
    /// Messages accepted for sending to this device.
    pub submitted: u32,
    /// Frames written completely.
    pub sent: u32,
    /// Bytes of the frames written completely.
    pub bytes_sent: u32,
    /// Messages dropped, by reason.
    pub dropped: DropCounts,
    /// Queued messages evicted by more important ones.
    pub evicted: EvictCounts,
    /// State messages replaced, while waiting, by a newer instance of the same message
    /// (sent with [`SendOptions::latest`](crate::SendOptions::latest)): not lost information,
    /// so counted apart from the drops.
    pub superseded: u32,
    /// Frames waiting in the queue or being written now.
    pub queued: u16,
    /// Frames waiting in the queue (`queued` without the one being written).
    pub waiting: u16,
    /// Largest number of frames ever waiting in the queue.
    pub queue_high_water: u16,
    /// The same accounting per priority level (high, normal, low; indexed by
    /// [`pprz_messages::priority::level`]): `submitted - sent - lost - superseded` of a
    /// level are still queued.
    pub levels: [LevelStats; 3],
    /// The part of all this that other aircraft's frames forwarded onto this device
    /// (the route's report: [`relay`](crate::relay)); included in the figures above.
    pub relayed: RelayedStats,
}

/// Frames of other aircraft forwarded onto one device (a route of the
/// [`relay`](crate::relay)): what was submitted, sent, dropped by reason and shed, per
/// priority level. Forwarded frames are never state messages, so none is superseded.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RelayedStats {
    /// Forwarded frames accepted for sending on the device.
    pub submitted: u32,
    /// Written completely.
    pub sent: u32,
    /// Dropped before the queue or by the writer, by reason.
    pub dropped: DropCounts,
    /// Evicted from the queue by more important frames (the relay's own messages or other
    /// forwarded ones).
    pub evicted: EvictCounts,
    /// Per priority level; a level's `lost` is what the relay shed of it.
    pub levels: [LevelStats; 3],
}

impl RelayedStats {
    /// Forwarded frames that will never reach the wire (dropped and evicted).
    pub fn lost(&self) -> u32 {
        self.dropped.total().wrapping_add(self.evicted.total())
    }

    /// Forwarded frames waiting in the queue or being written.
    pub fn queued(&self) -> u32 {
        self.submitted
            .wrapping_sub(self.sent)
            .wrapping_sub(self.lost())
    }
}

impl DeviceStats {
    /// Whether `submitted = sent + dropped + evicted + superseded + queued`, for the
    /// device and for each level (it always should).
    pub fn is_balanced(&self) -> bool {
        let queued = u32::from(self.queued);
        let levels_queued = self.levels.iter().fold(0u32, |n, l| {
            n.wrapping_add(
                l.submitted
                    .wrapping_sub(l.sent)
                    .wrapping_sub(l.lost)
                    .wrapping_sub(l.superseded),
            )
        });
        self.submitted
            == self
                .sent
                .wrapping_add(self.dropped.total())
                .wrapping_add(self.evicted.total())
                .wrapping_add(self.superseded)
                .wrapping_add(queued)
            && levels_queued == queued
            && self.relayed_is_balanced()
    }

    /// The forwarded frames' share: its levels add up to its totals, and no more of
    /// them are queued than frames are.
    fn relayed_is_balanced(&self) -> bool {
        let r = &self.relayed;
        let sum =
            |f: fn(&LevelStats) -> u32| r.levels.iter().fold(0u32, |n, l| n.wrapping_add(f(l)));
        sum(|l| l.submitted) == r.submitted
            && sum(|l| l.sent) == r.sent
            && sum(|l| l.lost) == r.lost()
            && sum(|l| l.superseded) == 0
            && r.queued() <= u32::from(self.queued)
    }

    /// Messages that will never reach the wire (dropped and evicted).
    pub fn lost(&self) -> u32 {
        self.dropped.total().wrapping_add(self.evicted.total())
    }

    /// `downlink_nb_msgs` of DATALINK_REPORT: messages sent, modulo 2^16 as the ground
    /// expects.
    pub fn downlink_nb_msgs(&self) -> u16 {
        self.sent as u16
    }

    /// `downlink_ovrn` of DATALINK_REPORT: messages lost for lack of room (dropped or
    /// evicted because the queue or the arena was full), saturating at 255 rather than
    /// wrapping like the reference firmware's counter.
    pub fn downlink_ovrn(&self) -> u8 {
        let overruns = self
            .dropped
            .queue_full
            .wrapping_add(self.dropped.arena_full)
            .wrapping_add(self.evicted.total());
        u8::try_from(overruns).unwrap_or(u8::MAX)
    }

    /// `downlink_rate` of DATALINK_REPORT in bytes/s, from an earlier snapshot taken
    /// `elapsed_ms` milliseconds before this one (saturating at `u16::MAX`).
    pub fn downlink_rate(&self, earlier: &DeviceStats, elapsed_ms: u32) -> u16 {
        if elapsed_ms == 0 {
            return 0;
        }
        let bytes = u64::from(self.bytes_sent.wrapping_sub(earlier.bytes_sent));
        u16::try_from(bytes * 1000 / u64::from(elapsed_ms)).unwrap_or(u16::MAX)
    }
}

/// The counters of one device's queue, each its own atomic word, so that every context
/// counts without taking a lock (see the queue). [`snapshot`](Self::snapshot) reads them
/// one by one: a snapshot taken while another context sends or writes may be off by the
/// messages in transit (counted submitted, not yet queued or dropped); one taken between
/// two operations is exact.
pub(crate) struct Counters {
    words: [AtomicU32; Counters::LEN],
}

/// Layout of one block of [`Counters`] (the device's totals, then the forwarded part):
/// the drop reasons in [`DropCounts`]' order, the two eviction causes, then per level
/// submitted, sent, lost, superseded (the totals submitted and sent are the levels' sums).
mod at {
    pub const DROPPED: usize = 0;
    pub const EVICTED: usize = DROPPED + 7;
    pub const LEVELS: usize = EVICTED + 2;
    pub const BLOCK: usize = LEVELS + 3 * 4;
    /// The second block: the forwarded frames' share.
    pub const RELAYED: usize = BLOCK;
    /// After both blocks: bytes sent, superseded, queue high-water mark.
    pub const BYTES: usize = 2 * BLOCK;
    pub const SUPERSEDED: usize = BYTES + 1;
    pub const HIGH_WATER: usize = BYTES + 2;
}

impl Counters {
    const LEN: usize = at::HIGH_WATER + 1;

    /// All zero.
    pub(crate) const fn new() -> Self {
        Self {
            words: [const { AtomicU32::new(0) }; Counters::LEN],
        }
    }

    #[inline]
    fn add<M: RawMutex>(&self, lock: &Fallback<M>, i: usize, v: u32) {
        if let Some(w) = self.words.get(i) {
            atomic::add(lock, w, v);
        }
    }

    /// Adds one to counter `what` of level `priority`'s and to counter `total` if any
    /// (submitted and sent have none: their totals are the sums of the levels), in the
    /// device's block and, for a forwarded frame, in the relayed block.
    #[inline]
    fn level<M: RawMutex>(
        &self,
        lock: &Fallback<M>,
        total: Option<usize>,
        what: usize,
        priority: u8,
        relayed: bool,
    ) {
        let level = at::LEVELS + 4 * pprz_messages::priority::level(priority) + what;
        if let Some(total) = total {
            self.add(lock, total, 1);
        }
        self.add(lock, level, 1);
        if relayed {
            self.relayed(lock, total, level);
        }
    }

    /// The forwarded frames' share, out of the common path (the aircraft's own messages).
    #[cold]
    #[inline(never)]
    fn relayed<M: RawMutex>(&self, lock: &Fallback<M>, total: Option<usize>, level: usize) {
        if let Some(total) = total {
            self.add(lock, at::RELAYED + total, 1);
        }
        self.add(lock, at::RELAYED + level, 1);
    }

    /// A message of `priority` accepted for sending.
    #[inline]
    pub(crate) fn submitted<M: RawMutex>(&self, lock: &Fallback<M>, priority: u8, relayed: bool) {
        self.level(lock, None, 0, priority, relayed);
    }

    /// A frame of `len` bytes written completely.
    #[inline]
    pub(crate) fn sent<M: RawMutex>(
        &self,
        lock: &Fallback<M>,
        priority: u8,
        relayed: bool,
        len: usize,
    ) {
        self.add(lock, at::BYTES, len as u32);
        self.level(lock, None, 1, priority, relayed);
    }

    /// A message dropped for `reason` (nothing for [`DropReason::NoDevice`], which the
    /// downlink counts).
    pub(crate) fn dropped<M: RawMutex>(
        &self,
        lock: &Fallback<M>,
        reason: DropReason,
        priority: u8,
        relayed: bool,
    ) {
        let Some(i) = DropCounts::index(reason) else {
            return;
        };
        self.level(lock, Some(at::DROPPED + i), 2, priority, relayed);
    }

    /// A queued frame evicted because the queue (`queue_full`) or the arena was full.
    pub(crate) fn evicted<M: RawMutex>(
        &self,
        lock: &Fallback<M>,
        queue_full: bool,
        priority: u8,
        relayed: bool,
    ) {
        let i = at::EVICTED + usize::from(!queue_full);
        self.level(lock, Some(i), 2, priority, relayed);
    }

    /// A waiting state message of `priority` replaced by a newer one.
    pub(crate) fn superseded<M: RawMutex>(&self, lock: &Fallback<M>, priority: u8) {
        self.level(lock, Some(at::SUPERSEDED), 3, priority, false);
    }

    /// Raises the queue's high-water mark to `waiting` frames.
    #[inline]
    pub(crate) fn waiting<M: RawMutex>(&self, lock: &Fallback<M>, waiting: u32) {
        let Some(w) = self.words.get(at::HIGH_WATER) else {
            return;
        };
        if w.load(Relaxed) < waiting {
            let _ = atomic::update(lock, w, Relaxed, |hw| (hw < waiting).then_some(waiting));
        }
    }

    /// The counters as [`DeviceStats`], with `waiting` frames in the queue and, if
    /// `in_flight`, one being written.
    pub(crate) fn snapshot(&self, waiting: u16, in_flight: bool) -> DeviceStats {
        let own = self.block(0);
        DeviceStats {
            submitted: own.submitted,
            sent: own.sent,
            bytes_sent: self.word(at::BYTES),
            dropped: own.dropped,
            evicted: own.evicted,
            superseded: self.word(at::SUPERSEDED),
            queued: waiting.saturating_add(u16::from(in_flight)),
            waiting,
            queue_high_water: self.word(at::HIGH_WATER) as u16,
            levels: own.levels,
            relayed: self.block(at::RELAYED),
        }
    }

    /// Counter `i`.
    fn word(&self, i: usize) -> u32 {
        self.words.get(i).map_or(0, |w| w.load(Relaxed))
    }

    /// The block of counters at `b` (the device's, or the forwarded frames'). Out of line:
    /// a snapshot reads two blocks, and one copy of this code is half the flash.
    #[inline(never)]
    fn block(&self, b: usize) -> RelayedStats {
        let w = |i: usize| self.word(b + i);
        let level = |l: usize| LevelStats {
            submitted: w(at::LEVELS + 4 * l),
            sent: w(at::LEVELS + 4 * l + 1),
            lost: w(at::LEVELS + 4 * l + 2),
            superseded: w(at::LEVELS + 4 * l + 3),
        };
        let levels = [level(0), level(1), level(2)];
        let sum = |f: fn(&LevelStats) -> u32| levels.iter().fold(0u32, |n, l| n.wrapping_add(f(l)));
        let d = |r: usize| w(at::DROPPED + r);
        RelayedStats {
            submitted: sum(|l| l.submitted),
            sent: sum(|l| l.sent),
            dropped: DropCounts {
                too_large: d(0),
                encode: d(1),
                queue_full: d(2),
                arena_full: d(3),
                write_error: d(4),
                rate_limited: d(5),
                refused: d(6),
            },
            evicted: EvictCounts {
                queue_full: w(at::EVICTED),
                arena_full: w(at::EVICTED + 1),
            },
            levels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_report_fields() {
        let mut s = DeviceStats {
            submitted: 70_010,
            sent: 70_000,
            bytes_sent: 5_000,
            ..Default::default()
        };
        s.dropped.queue_full += 1;
        s.evicted.arena_full = 300;
        s.queued = 9;
        s.submitted = s.sent + s.lost() + u32::from(s.queued);
        assert!(!s.is_balanced(), "the levels must balance too");
        s.levels[1] = LevelStats {
            submitted: s.submitted,
            sent: s.sent,
            lost: s.lost(),
            superseded: 0,
        };
        assert!(s.is_balanced());
        assert_eq!(s.downlink_nb_msgs(), (70_000u32 % 65_536) as u16);
        assert_eq!(s.downlink_ovrn(), 255);
        let earlier = DeviceStats {
            bytes_sent: 1_000,
            ..Default::default()
        };
        assert_eq!(s.downlink_rate(&earlier, 2_000), 2_000);
        assert_eq!(s.downlink_rate(&earlier, 0), 0);
    }
}
