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
//! it (so the executor's wake runs with interrupts enabled). Entries are
//! kept sorted in a ring buffer (`heapless::Deque`), so sending takes the front one, FIFO
//! order needs no sequence number, and the eviction candidate is found by binary search.
//!
//! # Time Complexity
//! `receive` is O(1). `push` is O(1) when the new frame is not more important than the
//! least important waiting one (all frames of one priority, say), else it moves the new
//! entry forward past the less important ones; evicting moves the entries behind the
//! evicted one back: both O(Q), where `Q` is the queue capacity, typically 8..64.

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
    relayed: bool,
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

struct State<'a, const Q: usize> {
    /// Invariant: sorted by priority descending, and within a priority by age ascending
    /// (oldest first), so the front entry is the most important and oldest, and the
    /// eviction candidate is the first entry of the back's priority.
    entries: heapless::Deque<Entry<'a>, Q>,
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
    /// Index of the eviction candidate: the oldest entry of the lowest priority.
    fn candidate(&self) -> Option<usize> {
        let lowest = self.entries.back()?.priority;
        // The first index whose priority is `lowest` (binary search: entries before it are
        // more important).
        let (mut lo, mut hi) = (0, self.entries.len() - 1);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            match self.entries.get(mid) {
                Some(e) if e.priority > lowest => lo = mid + 1,
                _ => hi = mid,
            }
        }
        Some(lo)
    }

    /// Removes and returns entry `at` (`at < len`), keeping the order of the others.
    fn remove(&mut self, at: usize) -> Option<Entry<'a>> {
        let len = self.entries.len();
        if at >= len {
            return None;
        }
        // Move it to the nearer end, then take it from there.
        if at < len - at {
            for i in (0..at).rev() {
                self.entries.swap(i, i + 1);
            }
            self.entries.pop_front()
        } else {
            for i in at..len - 1 {
                self.entries.swap(i, i + 1);
            }
            self.entries.pop_back()
        }
    }

    /// Inserts `entry` after every entry at least as important (behind the entries of its
    /// own priority: the newest of them). `Err` if the queue is full.
    fn insert(&mut self, entry: Entry<'a>) -> Result<(), Entry<'a>> {
        let priority = entry.priority;
        // Usually no entry is less important: the new one stays at the back.
        let in_place = self.entries.back().is_none_or(|e| e.priority >= priority);
        self.entries.push_back(entry)?;
        if !in_place {
            // Move it forward past the less important entries.
            let mut at = self.entries.len() - 1;
            while at > 0
                && self
                    .entries
                    .get(at - 1)
                    .is_some_and(|e| e.priority < priority)
            {
                self.entries.swap(at - 1, at);
                at -= 1;
            }
        }
        Ok(())
    }

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
        if entry.relayed {
            count(&mut self.stats.relayed.evicted);
        }
        self.lost(entry.priority, entry.relayed);
    }

    /// Takes the most important frame (see [`FrameQueue::try_receive`]); when there is
    /// none, registers the waker of `cx` and returns the one it replaces (another task's),
    /// for the caller to wake once the lock is let go.
    #[inline]
    fn receive(&mut self, cx: Option<&mut Context<'_>>) -> (Option<FrameBuf<'a>>, Option<Waker>) {
        match self.entries.pop_front() {
            Some(entry) => {
                self.in_flight = true;
                self.in_flight_priority = entry.priority;
                self.in_flight_relayed = entry.relayed;
                self.update_queued();
                (Some(entry.frame), None)
            }
            None => (None, cx.and_then(|cx| self.register(cx.waker()))),
        }
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
                entries: heapless::Deque::new(),
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
                && let Some(old) = s
                    .entries
                    .iter_mut()
                    .find(|e| e.latest == latest && e.priority == priority)
            {
                released = Some(core::mem::replace(&mut old.frame, frame));
                s.stats.superseded = s.stats.superseded.wrapping_add(1);
                let l = s.level(priority);
                l.superseded = l.superseded.wrapping_add(1);
                return (Pushed::Superseded, None, s.waker.take());
            }
            let mut result = Pushed::Queued;
            if s.entries.len() >= depth {
                let victim = s
                    .candidate()
                    .filter(|&i| s.entries.get(i).is_some_and(|e| e.priority < priority))
                    .and_then(|i| s.remove(i));
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
                relayed,
                frame,
            };
            if let Err(entry) = s.insert(entry) {
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
            let i = s.candidate()?;
            let e = s.entries.get(i)?;
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
            let i = s.candidate()?;
            let e = s.entries.get(i)?;
            if e.priority != expected.priority || e.seq != expected.seq {
                return None;
            }
            let entry = s.remove(i)?;
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
        let (frame, replaced) = self.with(|s| s.receive(cx));
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
            let next = if take_next { s.receive(None).0 } else { None };
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
                    let old = queue.with(|s| {
                        let at = s.entries.iter().position(|e| e.latest == key)?;
                        s.remove(at)
                    });
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
