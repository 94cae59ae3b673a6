//! The transmit queue of one device: frames ordered by priority, FIFO among equal
//! priorities, with eviction of less important frames when full.
//!
//! ```text
//!   most important                                       least important
//!   front ................................................ back
//!   [ p=2 oldest .. p=2 newest | p=1 oldest .. p=1 newest | p=0 oldest .. p=0 newest ]
//!     ^ sent next                  evicted first: oldest of the lowest priority ^
//! ```
//!
//! This module is internal: the downlink is its only producer, and a device's
//! [`Port`](crate::Port) its only consumer, so no public path can unbalance the
//! accounting (every frame pushed is sent, dropped or evicted, and counted once).
//!
//! # Why not `embassy_sync::PriorityChannel`
//! It is a binary heap: equal priorities come out in no particular order unless the key
//! carries a sequence number, it cannot evict, and its 0.8.0 `poll_ready_to_send` is
//! buggy. This queue is built on embassy-sync's blocking [`Mutex`] (a critical section
//! on boards, so interrupt-free contexts on any executor may send) and the waker of its
//! one consumer, the device's writer task, which is taken under the lock and woken after
//! it (so the executor's wake runs with interrupts enabled). The waiting frames are one
//! FIFO list per priority present, linked through a pool of `Q` slots ([`Lists`]), so
//! FIFO order needs no sequence number and no frame moves once stored.
//!
//! # Time Complexity
//! Under the lock, every operation is a few steps, whatever the queue holds: taking the
//! most important frame (the head of the most important list), queueing a frame (at the
//! tail of its priority's list), evicting the oldest of the least important (the head of
//! the least important list). The only step that depends on the queue is finding the
//! list of a priority among the priorities waiting, and moving that small array when a
//! priority appears or disappears: O(P), where `P` is the number of distinct priorities
//! waiting (a few in practice, at most `Q`). A state message's lookup walks the list of
//! its own priority.

use core::cell::RefCell;
use core::task::{Context, Waker};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;

use crate::arena::FrameBuf;
use crate::stats::{DeviceStats, DropReason};

/// A queued frame: its priority, its global sequence number (age), its bytes, for a
/// state message (latest value wins) the message it carries, and whether it is another
/// aircraft's frame being forwarded (counted apart as well, [`RelayedStats`]).
///
/// [`RelayedStats`]: crate::stats::RelayedStats
struct Entry<'a> {
    priority: u8,
    seq: u32,
    latest: Option<MessageKey>,
    /// 1 if forwarded, else 0. A byte, not a `bool`: a `bool` gives `Option<Entry>` its
    /// spare values and makes `None` 2, so an empty queue (and a `Link` holding it) would
    /// not be all zero bytes and could not be built in `.bss`.
    relayed: u8,
    frame: FrameBuf<'a>,
}

/// Class and id of a state message: a newer one supersedes a waiting older one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageKey {
    /// Class id.
    pub class: u8,
    /// Message id.
    pub msg_id: u8,
}

/// What a push did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Pushed {
    /// Queued; nothing was evicted.
    Queued,
    /// Queued after evicting a less important frame.
    QueuedEvicting,
    /// Queued in the place of an older instance of the same state message, which was
    /// released (counted as superseded).
    Superseded,
    /// Not queued: the queue is full of frames at least as important (counted as a
    /// [`DropReason::QueueFull`] drop; the frame's memory is released).
    Dropped,
}

/// The eviction candidate of a queue: its least important, oldest frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Candidate {
    /// Priority of the candidate.
    pub priority: u8,
    /// Global sequence number of the candidate (smaller is older, modulo wrapping).
    pub seq: u32,
}

impl Candidate {
    /// Whether `self` should be evicted before `other`: lower priority first, then older.
    pub fn weaker_than(&self, other: &Candidate) -> bool {
        self.priority < other.priority
            || (self.priority == other.priority && older(self.seq, other.seq))
    }
}

/// `a` was issued before `b` (sequence numbers wrap; live frames are far less than 2^31
/// apart).
fn older(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) < 0
}

/// Slot index plus one, `0` for none: so that an empty [`Lists`] is all zero bytes.
type Link = u16;

/// A priority of the queue: the FIFO list of its waiting frames, oldest first.
#[derive(Clone, Copy)]
struct Level {
    priority: u8,
    /// First (oldest) and last (newest) slot of the list.
    head: Link,
    tail: Link,
}

/// The waiting frames of a queue: one FIFO list per priority present, linked through a
/// pool of `Q` slots, and the priorities in ascending order. Every operation the queue
/// makes under its lock is a few steps whatever the queue holds: taking the most
/// important frame (the head of the last level), appending a frame to its priority's
/// list, evicting the oldest of the least important (the head of the first level). Only
/// a priority that appears or disappears moves the small level array (at most one entry
/// per distinct priority waiting); frames never move once stored.
struct Lists<'a, const Q: usize> {
    slots: [Option<Entry<'a>>; Q],
    /// Next slot in its level's list, or in the free list.
    next: [Link; Q],
    /// Released slots, to be used again.
    free: Link,
    /// Slots `0..fresh` have been used at least once; the others never were.
    fresh: u16,
    /// The levels present, ascending by priority: `levels[..count]`.
    levels: [Level; Q],
    count: u16,
    len: u16,
}

impl<'a, const Q: usize> Lists<'a, Q> {
    const fn new() -> Self {
        Self {
            slots: [const { None }; Q],
            next: [0; Q],
            free: 0,
            fresh: 0,
            levels: [Level {
                priority: 0,
                head: 0,
                tail: 0,
            }; Q],
            count: 0,
            len: 0,
        }
    }

    /// Waiting frames.
    #[inline]
    fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// The levels present, ascending.
    #[inline]
    fn levels(&self) -> &[Level] {
        &self.levels[..usize::from(self.count)]
    }

    #[inline]
    fn slot(&self, link: Link) -> Option<&Entry<'a>> {
        self.slots.get(usize::from(link).checked_sub(1)?)?.as_ref()
    }

    /// The most important, oldest frame.
    #[inline]
    fn front(&self) -> Option<&Entry<'a>> {
        self.slot(self.levels().last()?.head)
    }

    /// The eviction candidate: the oldest frame of the least important priority.
    #[inline]
    fn candidate(&self) -> Option<&Entry<'a>> {
        self.slot(self.levels().first()?.head)
    }

    /// Takes the head of level `at` (`at < count`), dropping the level when it empties.
    #[inline]
    fn pop_level(&mut self, at: usize) -> Option<Entry<'a>> {
        let head = self.levels.get(at)?.head;
        let i = usize::from(head).checked_sub(1)?;
        let entry = self.slots.get_mut(i)?.take()?;
        let next = core::mem::replace(&mut self.next[i], self.free);
        self.free = head;
        self.len -= 1;
        if next == 0 {
            // The level empties: the ones above it move down (none when it is the most
            // important, the usual case). A plain loop: a few small entries.
            let count = usize::from(self.count);
            for j in at..count - 1 {
                self.levels[j] = self.levels[j + 1];
            }
            self.count -= 1;
        } else {
            self.levels[at].head = next;
        }
        Some(entry)
    }

    /// Takes the most important, oldest frame.
    #[inline]
    fn pop_front(&mut self) -> Option<Entry<'a>> {
        self.pop_level(usize::from(self.count).checked_sub(1)?)
    }

    /// Takes the eviction candidate.
    #[inline]
    fn pop_candidate(&mut self) -> Option<Entry<'a>> {
        self.pop_level(0)
    }

    /// Appends `entry` behind the frames of its priority. `Err` if all `Q` slots are in use.
    #[inline]
    fn push(&mut self, entry: Entry<'a>) -> Result<(), Entry<'a>> {
        let link = if self.free != 0 {
            self.free
        } else if usize::from(self.fresh) < Q {
            self.fresh += 1;
            self.fresh
        } else {
            return Err(entry);
        };
        let i = usize::from(link) - 1;
        if self.free == link {
            self.free = self.next[i];
        }
        self.next[i] = 0;
        let priority = entry.priority;
        // The slot is empty (free or fresh): fills it without the drop of an old value.
        self.slots[i].get_or_insert(entry);
        self.len += 1;
        // The level of `priority`: searched from the most important end, where most
        // frames go.
        let count = usize::from(self.count);
        let mut at = count;
        while at > 0 && self.levels[at - 1].priority > priority {
            at -= 1;
        }
        if at > 0 && self.levels[at - 1].priority == priority {
            let tail = core::mem::replace(&mut self.levels[at - 1].tail, link);
            self.next[usize::from(tail) - 1] = link;
        } else {
            // A new level: `count < Q`, as each level holds at least one of the `Q` frames.
            // The ones above it move up (none when it is the most important).
            for j in (at..count).rev() {
                self.levels[j + 1] = self.levels[j];
            }
            self.levels[at] = Level {
                priority,
                head: link,
                tail: link,
            };
            self.count += 1;
        }
        Ok(())
    }

    /// Takes the oldest waiting frame of `priority` for which `f` holds (tests: the
    /// queue itself only takes from the ends).
    #[cfg(test)]
    fn remove_where(&mut self, priority: u8, f: impl Fn(&Entry<'a>) -> bool) -> Option<Entry<'a>> {
        let at = self.levels().iter().position(|l| l.priority == priority)?;
        let (mut prev, mut link) = (0, self.levels[at].head);
        while let Some(i) = usize::from(link).checked_sub(1) {
            if self.slots[i].as_ref().is_some_and(&f) {
                if prev == 0 {
                    return self.pop_level(at);
                }
                let entry = self.slots[i].take()?;
                let next = core::mem::replace(&mut self.next[i], self.free);
                self.free = link;
                self.len -= 1;
                self.next[usize::from(prev) - 1] = next;
                if self.levels[at].tail == link {
                    self.levels[at].tail = prev;
                }
                return Some(entry);
            }
            (prev, link) = (link, self.next[i]);
        }
        None
    }

    /// The waiting frame of `priority` for which `f` holds, oldest first.
    fn find_mut(
        &mut self,
        priority: u8,
        mut f: impl FnMut(&Entry<'a>) -> bool,
    ) -> Option<&mut Entry<'a>> {
        let level = self.levels().iter().find(|l| l.priority == priority)?;
        let mut link = level.head;
        while let Some(i) = usize::from(link).checked_sub(1) {
            if self.slots[i].as_ref().is_some_and(&mut f) {
                return self.slots[i].as_mut();
            }
            link = self.next[i];
        }
        None
    }
}

struct State<'a, const Q: usize> {
    /// The waiting frames, by priority and age (see [`Lists`]).
    entries: Lists<'a, Q>,
    /// Whether the writer holds a frame taken from this queue, its priority, and
    /// whether it is a forwarded one.
    in_flight: bool,
    in_flight_priority: u8,
    in_flight_relayed: bool,
    /// The writer's waker while it waits for a frame: taken under the lock, woken after.
    waker: Option<Waker>,
    stats: DeviceStats,
}

impl<'a, const Q: usize> State<'a, Q> {
    fn level(&mut self, priority: u8) -> &mut crate::stats::LevelStats {
        &mut self.stats.levels[pprz_messages::priority::level(priority)]
    }

    fn relayed_level(&mut self, priority: u8) -> &mut crate::stats::LevelStats {
        &mut self.stats.relayed.levels[pprz_messages::priority::level(priority)]
    }

    #[inline]
    fn submitted(&mut self, priority: u8, relayed: bool) {
        self.stats.submitted = self.stats.submitted.wrapping_add(1);
        let l = self.level(priority);
        l.submitted = l.submitted.wrapping_add(1);
        if relayed {
            self.relayed_submitted(priority);
        }
    }

    /// The forwarded frames' share of [`submitted`](Self::submitted), out of the
    /// common path (the aircraft's own messages).
    #[cold]
    #[inline(never)]
    fn relayed_submitted(&mut self, priority: u8) {
        let r = &mut self.stats.relayed;
        r.submitted = r.submitted.wrapping_add(1);
        let l = self.relayed_level(priority);
        l.submitted = l.submitted.wrapping_add(1);
    }

    /// The forwarded frames' share of a frame sent.
    #[cold]
    #[inline(never)]
    fn relayed_sent(&mut self, priority: u8) {
        self.stats.relayed.sent = self.stats.relayed.sent.wrapping_add(1);
        let l = self.relayed_level(priority);
        l.sent = l.sent.wrapping_add(1);
    }

    #[inline]
    fn lost(&mut self, priority: u8, relayed: bool) {
        let l = self.level(priority);
        l.lost = l.lost.wrapping_add(1);
        if relayed {
            let l = self.relayed_level(priority);
            l.lost = l.lost.wrapping_add(1);
        }
    }

    /// Counts a frame of `priority` dropped for `reason`.
    fn dropped(&mut self, reason: DropReason, priority: u8, relayed: bool) {
        self.stats.dropped.count(reason);
        if relayed {
            self.stats.relayed.dropped.count(reason);
        }
        self.lost(priority, relayed);
    }

    /// Counts a queued frame evicted because the queue (`queue_full`) or the arena was
    /// full.
    fn evicted(&mut self, entry: &Entry<'_>, queue_full: bool) {
        let count = |e: &mut crate::stats::EvictCounts| {
            let c = if queue_full {
                &mut e.queue_full
            } else {
                &mut e.arena_full
            };
            *c = c.wrapping_add(1);
        };
        count(&mut self.stats.evicted);
        if entry.relayed != 0 {
            count(&mut self.stats.relayed.evicted);
        }
        self.lost(entry.priority, entry.relayed != 0);
    }

    /// Takes the most important frame and marks it in flight (see
    /// [`FrameQueue::try_receive`]).
    #[inline]
    fn take(&mut self) -> Option<FrameBuf<'a>> {
        let entry = self.entries.pop_front()?;
        self.in_flight = true;
        self.in_flight_priority = entry.priority;
        self.in_flight_relayed = entry.relayed != 0;
        self.update_queued();
        Some(entry.frame)
    }

    /// Registers `waker` as the writer's; returns the waker it replaces if that one wakes
    /// another task (woken by the caller after the lock, so that task can register again).
    #[inline]
    fn register(&mut self, waker: &Waker) -> Option<Waker> {
        match &self.waker {
            Some(w) if w.will_wake(waker) => None,
            _ => self.waker.replace(waker.clone()),
        }
    }

    /// Counts the outcome of the in-flight frame of `len` bytes (see
    /// [`FrameQueue::complete`]); the caller updates the queue counts.
    #[inline]
    fn complete(&mut self, len: usize, outcome: Result<(), DropReason>) {
        let priority = self.in_flight_priority;
        let relayed = self.in_flight_relayed;
        match outcome {
            Ok(()) => {
                self.stats.sent = self.stats.sent.wrapping_add(1);
                self.stats.bytes_sent = self.stats.bytes_sent.wrapping_add(len as u32);
                let l = self.level(priority);
                l.sent = l.sent.wrapping_add(1);
                if relayed {
                    self.relayed_sent(priority);
                }
            }
            Err(reason) => self.dropped(reason, priority, relayed),
        }
        self.in_flight = false;
    }

    #[inline]
    fn update_queued(&mut self) {
        // Lossless: `len <= Q <= u16::MAX` (checked at compile time).
        let waiting = self.entries.len() as u16;
        self.stats.waiting = waiting;
        self.stats.queued = waiting.saturating_add(u16::from(self.in_flight));
        self.stats.queue_high_water = self.stats.queue_high_water.max(waiting);
    }
}

/// The priority queue of one device.
///
/// `'a` is the lifetime of the frame arena; `Q` the capacity (each push may set a lower
/// depth limit).
pub struct FrameQueue<'a, M: RawMutex, const Q: usize> {
    state: Mutex<M, RefCell<State<'a, Q>>>,
}

impl<'a, M: RawMutex, const Q: usize> FrameQueue<'a, M, Q> {
    const VALID: () = assert!(
        Q > 0 && Q <= u16::MAX as usize,
        "queue capacity must be 1..=65535"
    );

    /// An empty queue of depth `Q`.
    pub const fn new() -> Self {
        let () = Self::VALID;
        Self {
            state: Mutex::new(RefCell::new(State {
                entries: Lists::new(),
                in_flight: false,
                in_flight_priority: 0,
                in_flight_relayed: false,
                waker: None,
                stats: DeviceStats {
                    submitted: 0,
                    sent: 0,
                    bytes_sent: 0,
                    dropped: crate::stats::DropCounts {
                        too_large: 0,
                        encode: 0,
                        queue_full: 0,
                        arena_full: 0,
                        write_error: 0,
                        rate_limited: 0,
                        refused: 0,
                    },
                    evicted: crate::stats::EvictCounts {
                        queue_full: 0,
                        arena_full: 0,
                    },
                    queued: 0,
                    waiting: 0,
                    queue_high_water: 0,
                    superseded: 0,
                    levels: [crate::stats::LevelStats {
                        submitted: 0,
                        sent: 0,
                        lost: 0,
                        superseded: 0,
                    }; 3],
                    relayed: crate::stats::RelayedStats::ZERO,
                },
            })),
        }
    }

    fn with<R>(&self, f: impl FnOnce(&mut State<'a, Q>) -> R) -> R {
        self.state.lock(|s| f(&mut s.borrow_mut()))
    }

    /// A snapshot of the statistics.
    pub fn stats(&self) -> DeviceStats {
        self.with(|s| s.stats)
    }

    /// Counts a message of `priority` (a forwarded one if `relayed`) submitted for this
    /// device that was dropped before reaching the queue.
    pub fn count_dropped(&self, reason: DropReason, priority: u8, relayed: bool) {
        self.with(|s| {
            s.submitted(priority, relayed);
            s.dropped(reason, priority, relayed);
        });
    }

    /// Queues a frame. A state message (`latest`) takes the place of a waiting older
    /// instance of the same message of the same priority, which is released and counted
    /// as superseded (it keeps that instance's place in line, so the newest value goes
    /// out when the old one would have). Otherwise, when the queue holds `depth` frames
    /// (clamped to `1..=Q`), the oldest of its least important frames is evicted if it is
    /// strictly less important than `priority`; otherwise the new frame is dropped.
    /// Either way it is counted (also as forwarded if `relayed`). Never blocks.
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &self,
        priority: u8,
        seq: u32,
        latest: Option<MessageKey>,
        relayed: bool,
        frame: FrameBuf<'a>,
        depth: usize,
    ) -> Pushed {
        let depth = depth.clamp(1, Q);
        // Evicted, superseded or rejected frames are released after the lock is let go.
        let mut released = None;
        let result = self.with(|s| {
            s.submitted(priority, relayed);
            if latest.is_some()
                && let Some(old) = s.entries.find_mut(priority, |e| e.latest == latest)
            {
                released = Some(core::mem::replace(&mut old.frame, frame));
                s.stats.superseded = s.stats.superseded.wrapping_add(1);
                let l = s.level(priority);
                l.superseded = l.superseded.wrapping_add(1);
                return (Pushed::Superseded, None, s.waker.take());
            }
            let mut result = Pushed::Queued;
            if s.entries.len() >= depth {
                let weaker = s.entries.candidate().is_some_and(|e| e.priority < priority);
                let victim = if weaker {
                    s.entries.pop_candidate()
                } else {
                    None
                };
                match victim {
                    Some(victim) => {
                        s.evicted(&victim, true);
                        released = Some(victim.frame);
                        result = Pushed::QueuedEvicting;
                    }
                    _ => {
                        s.dropped(DropReason::QueueFull, priority, relayed);
                        s.update_queued();
                        return (Pushed::Dropped, Some(frame), None);
                    }
                }
            }
            // Oldest first within a priority: after every entry of the same priority.
            let entry = Entry {
                priority,
                seq,
                latest,
                relayed: u8::from(relayed),
                frame,
            };
            if let Err(entry) = s.entries.push(entry) {
                // Unreachable while depth <= Q; counted rather than lost if it ever is.
                s.dropped(DropReason::QueueFull, priority, relayed);
                s.update_queued();
                return (Pushed::Dropped, Some(entry.frame), None);
            }
            s.update_queued();
            (result, None, s.waker.take())
        });
        let (pushed, rejected, waker) = result;
        // The writer runs (or the executor queues it) with interrupts enabled.
        if let Some(waker) = waker {
            waker.wake();
        }
        drop(released);
        drop(rejected);
        pushed
    }

    /// The eviction candidate, if any.
    pub fn candidate(&self) -> Option<Candidate> {
        self.with(|s| {
            let e = s.entries.candidate()?;
            Some(Candidate {
                priority: e.priority,
                seq: e.seq,
            })
        })
    }

    /// Evicts the current candidate because the arena is full, if it is still `expected`
    /// (another task may have changed the queue since [`candidate`](Self::candidate)).
    /// Returns whether a frame was evicted; its memory is released before returning.
    pub fn evict_for_arena(&self, expected: Candidate) -> bool {
        let evicted = self.with(|s| {
            let e = s.entries.candidate()?;
            if e.priority != expected.priority || e.seq != expected.seq {
                return None;
            }
            let entry = s.entries.pop_candidate()?;
            s.evicted(&entry, false);
            s.update_queued();
            Some(entry)
        });
        evicted.is_some()
    }

    /// The length of the most important frame, without taking it; with a context,
    /// registers the waker when there is none.
    pub fn peek_len(&self, cx: Option<&mut Context<'_>>) -> Option<usize> {
        let (len, replaced) = self.with(|s| match s.entries.front() {
            Some(entry) => (Some(entry.frame.len()), None),
            None => (None, cx.and_then(|cx| s.register(cx.waker()))),
        });
        if let Some(waker) = replaced {
            waker.wake();
        }
        len
    }

    /// Takes the most important frame and marks it in flight; with a context, registers
    /// the waker when there is none. For the device's one consumer, which reports the
    /// outcome with [`complete`](Self::complete).
    pub fn try_receive(&self, cx: Option<&mut Context<'_>>) -> Option<FrameBuf<'a>> {
        let (frame, replaced) = self.with(|s| match s.take() {
            Some(frame) => (Some(frame), None),
            // None waiting: the writer's waker, and the one it replaces to wake after.
            None => (None, cx.and_then(|cx| s.register(cx.waker()))),
        });
        if let Some(waker) = replaced {
            waker.wake();
        }
        frame
    }

    /// Reports the outcome of writing the in-flight frame: sent, or lost for `reason` (a
    /// write error, or refused by the device's link layer), then releases the frame's
    /// memory once this queue's lock is let go (the two critical sections follow each
    /// other instead of nesting, so interrupts wait for the longer of the two only). With
    /// `take_next`, also takes the most important frame as
    /// [`try_receive`](Self::try_receive) (without a context) does, under the same lock:
    /// for a writer that writes the next frame as soon as a write completes.
    pub fn complete(
        &self,
        frame: FrameBuf<'_>,
        outcome: Result<(), DropReason>,
        take_next: bool,
    ) -> Option<FrameBuf<'a>> {
        let len = frame.len();
        let next = self.with(|s| {
            s.complete(len, outcome);
            let next = if take_next { s.take() } else { None };
            if next.is_none() {
                s.update_queued();
            }
            next
        });
        drop(frame);
        next
    }
}

impl<M: RawMutex, const Q: usize> Default for FrameQueue<'_, M, Q> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    //! Superseding in place versus re-queueing, measured on the real queue: a 4800-baud
    //! link (480 B/s) carrying a rotorcraft's status telemetry (about 680 B/s, the
    //! `default` mode of Paparazzi's telemetry.xml), every message sent latest-value-wins.
    //! Re-queueing is emulated here (the older instance leaves, the newer goes to the back
    //! of its priority); the queue itself only supersedes in place.

    use super::*;
    use crate::arena::FrameArena;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as NoopRawMutex;

    /// Status types: period (ms), phase (ms), frame bytes.
    const STATUS: [(u64, u64, usize); 9] = [
        (2100, 0, 26),     // ALIVE
        (1200, 100, 29),   // ROTORCRAFT_STATUS
        (250, 200, 40),    // ROTORCRAFT_FP
        (250, 50, 18),     // ATTITUDE
        (250, 150, 56),    // GPS_INT
        (250, 0, 42),      // INS
        (2500, 500, 30),   // ENERGY
        (5100, 700, 31),   // DATALINK_REPORT
        (11_100, 800, 35), // AUTOPILOT_VERSION
    ];
    const LINK_BYTES_PER_S: u64 = 480;
    const SECONDS: u64 = 60;

    #[derive(Clone, Copy, PartialEq, Eq, Debug)]
    enum Policy {
        InPlace,
        Requeue,
    }

    /// Per policy: p99 age at delivery (µs) and, per type, the longest gap between two
    /// deliveries (µs).
    fn simulate(policy: Policy) -> (u64, [u64; 9]) {
        let arena: FrameArena<NoopRawMutex, 4096> = FrameArena::new();
        let queue: FrameQueue<'_, NoopRawMutex, 32> = FrameQueue::new();
        let mut seq = 0u32;
        let mut ages = Vec::new();
        let mut last = [0u64; 9];
        let mut gaps = [0u64; 9];
        let mut link_free_us = 0u64;
        for ms in 0..SECONDS * 1000 {
            let now_us = ms * 1000;
            for (i, &(period, phase, len)) in STATUS.iter().enumerate() {
                if ms % period != phase {
                    continue;
                }
                let Ok(mut frame) = arena.alloc(len) else {
                    panic!("the arena holds one frame per type");
                };
                frame[0] = i as u8;
                frame[1..9].copy_from_slice(&now_us.to_le_bytes());
                let key = Some(MessageKey {
                    class: 1,
                    msg_id: i as u8,
                });
                if policy == Policy::Requeue {
                    let old = queue.with(|s| s.entries.remove_where(128, |e| e.latest == key));
                    drop(old);
                }
                seq += 1;
                queue.push(128, seq, key, false, frame, 32);
            }
            // The link takes the most important frame whenever it is free.
            while link_free_us <= now_us {
                let Some(frame) = queue.try_receive(None) else {
                    break;
                };
                let start = link_free_us.max(now_us);
                let end = start + frame.len() as u64 * 1_000_000 / LINK_BYTES_PER_S;
                let i = usize::from(frame[0]);
                let mut at = [0u8; 8];
                at.copy_from_slice(&frame[1..9]);
                ages.push(end - u64::from_le_bytes(at));
                gaps[i] = gaps[i].max(end - last[i]);
                last[i] = end;
                queue.complete(frame, Ok(()), false);
                link_free_us = end;
            }
        }
        for (gap, last) in gaps.iter_mut().zip(last) {
            *gap = (*gap).max(SECONDS * 1_000_000 - last.min(SECONDS * 1_000_000));
        }
        ages.sort_unstable();
        let p99 = ages[(ages.len() * 99).div_ceil(100) - 1];
        (p99, gaps)
    }

    /// `cargo test -p pprz-telemetry --lib superseding -- --nocapture` prints the figures
    /// quoted in docs/design-decisions.md.
    #[test]
    fn superseding_in_place_keeps_every_type_flowing_and_re_queueing_does_not() {
        let (in_place_p99, in_place_gaps) = simulate(Policy::InPlace);
        let (requeue_p99, requeue_gaps) = simulate(Policy::Requeue);
        println!("age p99: in place {in_place_p99} µs, re-queue {requeue_p99} µs");
        println!("longest gap per type (µs), in place: {in_place_gaps:?}");
        println!("longest gap per type (µs), re-queue: {requeue_gaps:?}");
        for (i, gap) in in_place_gaps.iter().enumerate() {
            let bound = (STATUS[i].0 + 1000).max(2000) * 1000;
            assert!(*gap <= bound, "in place: type {i} waited {gap} µs");
        }
        // Re-queueing sends slightly fresher samples, but a type refreshed faster than
        // the backlog drains keeps going to the back of the line: the 4 Hz types (250 ms)
        // go more than twice as long without a delivery.
        let fast = |gaps: &[u64; 9]| (2..6).map(|i| gaps[i]).max().unwrap_or(0);
        assert!(fast(&in_place_gaps) < 1_000_000, "{in_place_gaps:?}");
        assert!(
            fast(&requeue_gaps) > 2 * fast(&in_place_gaps),
            "{requeue_gaps:?}"
        );
        assert!(requeue_p99 < in_place_p99);
    }
}

#[cfg(test)]
mod model {
    //! The queue against a plain model: a vector kept sorted by priority (descending),
    //! then age, where pushing inserts behind every frame at least as important, eviction
    //! takes the first frame of the lowest priority, and a state message replaces the
    //! waiting one of the same message and priority in its place.

    use super::*;
    use crate::arena::FrameArena;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as RawM;
    use proptest::prelude::*;

    #[derive(Debug, Clone)]
    enum Op {
        Push {
            priority: u8,
            key: Option<u8>,
            depth: usize,
        },
        Take,
        EvictForArena,
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            4 => (0u8..5, prop::option::weighted(0.3, 0u8..3), 1usize..10)
                .prop_map(|(p, key, depth)| Op::Push { priority: p * 60, key, depth }),
            2 => Just(Op::Take),
            1 => Just(Op::EvictForArena),
        ]
    }

    /// Model entry: priority, seq, key, the id written in the frame.
    type M = (u8, u32, Option<MessageKey>, u32);

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn the_queue_behaves_as_the_sorted_model(ops in prop::collection::vec(op(), 1..300)) {
            const Q: usize = 8;
            let arena: FrameArena<RawM, 2048> = FrameArena::new();
            let queue: FrameQueue<'_, RawM, Q> = FrameQueue::new();
            let mut model: Vec<M> = Vec::new();
            let mut seq = 0u32;
            for op in ops {
                match op {
                    Op::Push { priority, key, depth } => {
                        seq += 1;
                        let key = key.map(|k| MessageKey { class: 1, msg_id: k });
                        let mut frame = arena.alloc(4).expect("room");
                        frame.copy_from_slice(&seq.to_le_bytes());
                        let pushed = queue.push(priority, seq, key, false, frame, depth);
                        let depth = depth.clamp(1, Q);
                        let expected = if let Some(old) = model
                            .iter_mut()
                            .find(|m| key.is_some() && m.2 == key && m.0 == priority)
                        {
                            old.3 = seq;
                            Pushed::Superseded
                        } else {
                            let mut result = Pushed::Queued;
                            let mut admitted = true;
                            if model.len() >= depth {
                                let lowest = model.last().map(|m| m.0);
                                match lowest {
                                    Some(l) if l < priority => {
                                        let at = model.iter().position(|m| m.0 == l).unwrap();
                                        model.remove(at);
                                        result = Pushed::QueuedEvicting;
                                    }
                                    _ => admitted = false,
                                }
                            }
                            if admitted {
                                let at = model.iter().position(|m| m.0 < priority).unwrap_or(model.len());
                                model.insert(at, (priority, seq, key, seq));
                                result
                            } else {
                                Pushed::Dropped
                            }
                        };
                        prop_assert_eq!(pushed, expected);
                    }
                    Op::Take => {
                        let frame = queue.try_receive(None);
                        let expected = (!model.is_empty()).then(|| model.remove(0));
                        prop_assert_eq!(frame.is_some(), expected.is_some());
                        if let (Some(frame), Some(m)) = (frame, expected) {
                            let mut id = [0u8; 4];
                            id.copy_from_slice(&frame[..4]);
                            prop_assert_eq!(u32::from_le_bytes(id), m.3);
                            queue.complete(frame, Ok(()), false);
                        }
                    }
                    Op::EvictForArena => {
                        let candidate = queue.candidate();
                        let expected = model.last().map(|l| {
                            let at = model.iter().position(|m| m.0 == l.0).unwrap();
                            (at, Candidate { priority: model[at].0, seq: model[at].1 })
                        });
                        prop_assert_eq!(candidate, expected.map(|e| e.1));
                        if let Some((at, c)) = expected {
                            prop_assert!(queue.evict_for_arena(c));
                            model.remove(at);
                        }
                    }
                }
                let stats = queue.stats();
                prop_assert_eq!(usize::from(stats.waiting), model.len());
                prop_assert!(stats.is_balanced());
                prop_assert_eq!(arena.stats().live, model.len());
            }
        }
    }
}
