//! The transmit queue of one device: frames ordered by priority, oldest first among equal
//! priorities, with eviction of less important frames when full.
//!
//! ```text
//!   most important                                       least important
//!   [ p=2 oldest .. p=2 newest | p=1 oldest .. p=1 newest | p=0 oldest .. p=0 newest ]
//!     ^ sent next                  evicted first: oldest of the lowest priority ^
//! ```
//!
//! This module is internal: the downlink is its only producer, and a device's
//! [`Port`](crate::Port) its only consumer, so no public path can unbalance the
//! accounting (every frame pushed is sent, dropped or evicted, and counted once).
//!
//! # No lock on the way
//! Any task and any interrupt handler may send, so a lock around the queue would mask
//! interrupts (or, with a thread-mode mutex, forbid senders in handlers) for as long as a
//! push, an eviction or a take lasts. Instead the queue is a board of `Q` slots, each
//! owned by one context at a time, and ownership moves with atomic bit operations:
//!
//! * `used`: a bit per slot holding a frame (being queued, waiting, or being moved);
//! * `ready`: a bit per slot whose frame waits and may be claimed, in one set per
//!   priority band (the top two bits of the priority), so that a search for the most or
//!   the least important frame reads one band's frames only;
//! * `len`: the frames waiting or being queued, reserved against the depth limit.
//!
//! A sender reserves one unit of `len` (or, when the queue is full, claims the weakest
//! waiting frame and takes its slot over), claims a free `used` bit, writes its frame,
//! priority and sequence number into the slot, and publishes it by setting its `ready`
//! bit. Whoever clears a `ready` bit owns that frame: the writer taking the most important
//! frame, a sender evicting the least important one or replacing a state message in its
//! place, the arena making room. A claimer reads the slot's sequence number before its
//! claim and checks it after (sequence numbers are unique among a queue's frames): if the
//! slot changed hands in between, it gives it back and looks again. The counters are
//! atomic words too ([`Counters`]).
//!
//! On cores with compare-and-swap no operation of the queue masks interrupts or waits;
//! the only lock is the writer's waker's, taken when the writer sleeps and by the send
//! that wakes it. Cores without compare-and-swap (ARMv6-M, RV32IMC) do each bit operation
//! as a load and a store under the mutex `M`: a few instructions each.
//!
//! Under concurrent senders the order is the order of publication: a frame is visible
//! once its bit is set. A frame being replaced in place, or claimed and given back, is
//! not visible for those few instructions, so a writer taking a frame at that moment
//! takes the next one.
//!
//! # Why not `embassy_sync::PriorityChannel`
//! It is a binary heap behind a lock: equal priorities come out in no particular order
//! unless the key carries a sequence number, it cannot evict, and its 0.8.0
//! `poll_ready_to_send` is buggy.
//!
//! # Time Complexity
//! Taking a frame, finding the eviction candidate or a waiting state message reads the
//! priority and sequence number of each waiting frame of one band: O(n) for `n` frames
//! waiting in that band, at most `Q <= 64`. Queueing without eviction is O(1). On a link
//! that keeps up, `n` is zero or one.

// The frames' cells (`FrameCell`): each use is explained where it is.
#![allow(unsafe_code)]

use core::cell::{Cell, UnsafeCell};
use core::sync::atomic::Ordering::{Acquire, Relaxed, Release, SeqCst};
use core::sync::atomic::{AtomicU32, fence};
use core::task::{Context, Waker};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;

use crate::arena::FrameBuf;
use crate::atomic::{self, Fallback};
use crate::stats::{Counters, DeviceStats, DropReason};
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

/// The word describing a waiting frame: bits 0-7 its priority, 8-15 and 16-23 the class
/// and message id of a state message, bit 24 set for a state message, bit 25 for a
/// forwarded frame.
fn pack(priority: u8, latest: Option<MessageKey>, relayed: bool) -> u32 {
    let key = latest.map_or(0, |k| {
        STATE | u32::from(k.msg_id) << 16 | u32::from(k.class) << 8
    });
    u32::from(priority) | key | if relayed { RELAYED } else { 0 }
}

/// [`pack`]: a state message.
const STATE: u32 = 1 << 24;
/// [`pack`]: a forwarded frame.
const RELAYED: u32 = 1 << 25;
/// [`pack`]: what identifies a state message at its priority.
const KEY: u32 = STATE | 0xff_ffff;
/// `in_flight`: the writer holds a frame (its [`pack`]ed word in the low bits).
const IN_FLIGHT: u32 = 1 << 31;

/// A waiting frame as read before claiming it: its slot, [`pack`]ed word and sequence
/// number.
#[derive(Clone, Copy)]
struct Seen {
    slot: usize,
    meta: u32,
    seq: u32,
}

impl Seen {
    fn priority(&self) -> u8 {
        self.meta as u8
    }

    /// Sent before `other`: more important, or as important and older.
    fn stronger(&self, other: &Seen) -> bool {
        self.priority() > other.priority()
            || (self.priority() == other.priority() && older(self.seq, other.seq))
    }

    /// Evicted before `other`: less important, or as important and older.
    fn weaker(&self, other: &Seen) -> bool {
        self.priority() < other.priority()
            || (self.priority() == other.priority() && older(self.seq, other.seq))
    }
}

/// The frame of a slot. Ownership of a slot moves between contexts through the queue's
/// atomic bit sets (a sender sets a free `used` bit, or claims the frame it evicts; a
/// claimer clears the `ready` bit), and only the owner touches the cell. The bit
/// operations that hand a slot over release and acquire, so the owner's writes to the
/// cell happen before the next owner's reads. A lock per cell would do the same in safe
/// code, but masks interrupts twice per frame with a critical section (measured: 13.5
/// instructions per message on the Cortex-M4, more than a tenth of what the send path
/// still masks).
struct FrameCell<'a>(UnsafeCell<Option<FrameBuf<'a>>>);

// SAFETY: the cell is only touched by the slot's owner, and ownership passes with
// acquire/release bit operations (see `FrameCell`), so no two contexts touch it at once;
// `FrameBuf` itself is `Send`.
unsafe impl Sync for FrameCell<'_> {}

impl<'a> FrameCell<'a> {
    const fn new() -> Self {
        Self(UnsafeCell::new(None))
    }

    /// Replaces the frame, returning the old one.
    ///
    /// # Safety
    /// The caller owns the slot (see [`FrameCell`]).
    unsafe fn replace(&self, frame: Option<FrameBuf<'a>>) -> Option<FrameBuf<'a>> {
        // SAFETY: the caller owns the slot: no other reference to the cell exists.
        unsafe { core::mem::replace(&mut *self.0.get(), frame) }
    }
}

/// What a slot holds besides its frame: its [`pack`]ed word, sequence number and frame
/// length.
struct Info {
    meta: AtomicU32,
    seq: AtomicU32,
    len: AtomicU32,
}

impl Info {
    const fn new() -> Self {
        Self {
            meta: AtomicU32::new(0),
            seq: AtomicU32::new(0),
            len: AtomicU32::new(0),
        }
    }
}

/// Priority bands of the `ready` bits: four, so that the usual priorities (low 64,
/// normal 128, high 192, and below 64) each have their own.
const BANDS: usize = 4;

/// The band of `priority`: its top two bits.
fn band(priority: u8) -> usize {
    usize::from(priority >> 6)
}

/// The word and bit of slot `slot` in the `used` and `ready` bit sets.
fn bit(slot: usize) -> (usize, u32) {
    (slot / 32, 1 << (slot % 32))
}

/// The priority queue of one device; see the [module documentation](self).
///
/// `'a` is the lifetime of the frame arena; `Q` the capacity, at most 64 (each push may
/// set a lower depth limit).
pub struct FrameQueue<'a, M: RawMutex, const Q: usize> {
    /// The frame of each slot, touched only by the slot's owner.
    frames: [FrameCell<'a>; Q],
    /// What each slot holds, written by its owner before publishing it.
    info: [Info; Q],
    /// Slots holding a frame.
    used: [AtomicU32; 2],
    /// Slots whose frame waits to be claimed, by priority band ([`band`]): the most
    /// important frame is in the highest band that has one, the least important in the
    /// lowest, so a search reads one band's frames only.
    ready: [[AtomicU32; 2]; BANDS],
    /// Frames waiting or being queued.
    len: AtomicU32,
    /// The frame the writer holds: `IN_FLIGHT | pack(..)`, or 0.
    in_flight: AtomicU32,
    /// Non-zero while the writer waits for a frame with its waker stored.
    sleeping: AtomicU32,
    waker: Mutex<M, Cell<Option<Waker>>>,
    lock: Fallback<M>,
    counters: Counters,
}

impl<'a, M: RawMutex, const Q: usize> FrameQueue<'a, M, Q> {
    const VALID: () = assert!(Q > 0 && Q <= 64, "queue capacity must be 1..=64");
    /// Words of the bit sets in use.
    const WORDS: usize = Q.div_ceil(32);

    /// An empty queue of depth `Q`.
    pub const fn new() -> Self {
        let () = Self::VALID;
        Self {
            frames: [const { FrameCell::new() }; Q],
            info: [const { Info::new() }; Q],
            used: [const { AtomicU32::new(0) }; 2],
            ready: [const { [const { AtomicU32::new(0) }; 2] }; BANDS],
            len: AtomicU32::new(0),
            in_flight: AtomicU32::new(0),
            sleeping: AtomicU32::new(0),
            waker: Mutex::new(Cell::new(None)),
            lock: Mutex::new(()),
            counters: Counters::new(),
        }
    }

    /// Slots `32 * word ..` that exist.
    const fn mask(word: usize) -> u32 {
        let first = 32 * word;
        if Q >= first + 32 {
            u32::MAX
        } else if Q > first {
            (1 << (Q - first)) - 1
        } else {
            0
        }
    }

    /// The waiting frame of band `band` that `prefer` chooses: it is asked about each
    /// waiting frame against the best so far (`None` for the first).
    #[inline]
    fn pick(&self, band: usize, prefer: impl Fn(&Seen, Option<&Seen>) -> bool) -> Option<Seen> {
        let mut best: Option<Seen> = None;
        let ready = self.ready.get(band)?;
        for (word, ready) in ready.iter().enumerate().take(Self::WORDS) {
            let mut bits = ready.load(Acquire);
            while bits != 0 {
                let slot = 32 * word + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let Some(info) = self.info.get(slot) else {
                    continue;
                };
                let seen = Seen {
                    slot,
                    meta: info.meta.load(Relaxed),
                    seq: info.seq.load(Relaxed),
                };
                if prefer(&seen, best.as_ref()) {
                    best = Some(seen);
                }
            }
        }
        best
    }

    /// Claims the waiting frame `seen` describes: `true` if this context now owns it, as
    /// it was seen. A slot that changed hands since is given back.
    #[inline]
    fn claim(&self, seen: &Seen) -> bool {
        let (word, bit) = bit(seen.slot);
        let band = band(seen.priority());
        let Some(ready) = self.ready.get(band).and_then(|r| r.get(word)) else {
            return false;
        };
        if atomic::and(&self.lock, ready, !bit, Acquire) & bit == 0 {
            return false;
        }
        // Sequence numbers are unique among the frames of a queue: a slot that holds the
        // same one holds the same frame.
        let same = self
            .info
            .get(seen.slot)
            .is_some_and(|i| i.seq.load(Relaxed) == seen.seq);
        if !same {
            self.publish(seen.slot, band);
        }
        same
    }

    /// Makes the frame of `slot` (owned by this context, in `band`) visible, and wakes
    /// the writer if it waits.
    #[inline]
    fn publish(&self, slot: usize, band: usize) {
        let (word, bit) = bit(slot);
        if let Some(ready) = self.ready.get(band).and_then(|r| r.get(word)) {
            atomic::or(&self.lock, ready, bit, Release);
        }
        // Pairs with the fence in `sleep`: either the writer sees the frame, or this
        // sees it sleeping.
        fence(SeqCst);
        if self.sleeping.load(Relaxed) != 0 {
            let waker = self.waker.lock(|w| {
                self.sleeping.store(0, Relaxed);
                w.take()
            });
            // The writer runs (or the executor queues it) outside the lock.
            if let Some(waker) = waker {
                waker.wake();
            }
        }
    }

    /// Stores `waker` as the writer's before it looks once more: a frame published from
    /// now on wakes it. The waker it replaces is woken if it wakes another task (so that
    /// task can register again).
    fn sleep(&self, waker: &Waker) {
        let replaced = self.waker.lock(|w| {
            self.sleeping.store(1, Relaxed);
            match w.take() {
                Some(old) if old.will_wake(waker) => {
                    w.set(Some(old));
                    None
                }
                old => {
                    w.set(Some(waker.clone()));
                    old
                }
            }
        });
        fence(SeqCst);
        if let Some(waker) = replaced {
            waker.wake();
        }
    }

    /// Takes the frame out of `slot` (claimed by this context) and frees the slot.
    #[inline]
    fn vacate(&self, slot: usize) -> Option<FrameBuf<'a>> {
        // SAFETY: the caller claimed the slot; its `used` bit is cleared after this.
        let frame = unsafe { self.frames.get(slot)?.replace(None) };
        let (word, bit) = bit(slot);
        if let Some(used) = self.used.get(word) {
            atomic::and(&self.lock, used, !bit, Release);
        }
        // After the slot is free: a sender holding a unit of `len` finds a free slot.
        let _ = atomic::update(&self.lock, &self.len, Release, |n| n.checked_sub(1));
        frame
    }

    /// Claims a free slot for a sender holding a unit of `len` (so one is free, or about
    /// to be: a slot is freed before its unit is given back).
    fn claim_free(&self) -> Option<usize> {
        // Each failed round saw another context take the slot it chose; the bound keeps
        // a broken invariant from hanging the sender (the frame is then dropped, counted).
        for _ in 0..4 * Q + 4 {
            for (word, used) in self.used.iter().enumerate().take(Self::WORDS) {
                let free = !used.load(Relaxed) & Self::mask(word);
                if free == 0 {
                    continue;
                }
                let bit = free & free.wrapping_neg();
                if atomic::or(&self.lock, used, bit, Acquire) & bit == 0 {
                    return Some(32 * word + bit.trailing_zeros() as usize);
                }
            }
        }
        None
    }

    /// A snapshot of the statistics (see [`Counters`] for what it holds while other
    /// contexts send).
    pub fn stats(&self) -> DeviceStats {
        let waiting = self.len.load(Relaxed).min(u32::from(u16::MAX)) as u16;
        let in_flight = self.in_flight.load(Relaxed) != 0;
        self.counters.snapshot(waiting, in_flight)
    }

    /// Counts a message of `priority` (a forwarded one if `relayed`) submitted for this
    /// device that was dropped before reaching the queue.
    pub fn count_dropped(&self, reason: DropReason, priority: u8, relayed: bool) {
        self.counters.submitted(&self.lock, priority, relayed);
        self.counters.dropped(&self.lock, reason, priority, relayed);
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
        self.counters.submitted(&self.lock, priority, relayed);
        let meta = pack(priority, latest, relayed);
        let frame = match latest {
            Some(_) => match self.replace(meta, frame) {
                Ok(old) => {
                    self.counters.superseded(&self.lock, priority);
                    drop(old);
                    return Pushed::Superseded;
                }
                Err(frame) => frame,
            },
            None => frame,
        };
        let depth = depth.clamp(1, Q) as u32;
        let mut victim = None;
        let slot = loop {
            if atomic::update(&self.lock, &self.len, Acquire, |n| {
                (n < depth).then_some(n + 1)
            })
            .is_ok()
            {
                match self.claim_free() {
                    Some(slot) => break slot,
                    None => {
                        let _ =
                            atomic::update(&self.lock, &self.len, Relaxed, |n| n.checked_sub(1));
                        self.counters
                            .dropped(&self.lock, DropReason::QueueFull, priority, relayed);
                        return Pushed::Dropped;
                    }
                }
            }
            // Full: the least important, oldest frame takes the way out if it is strictly
            // less important, and leaves its slot to this one.
            if let Some(w) = self.weakest().filter(|w| w.priority() < priority) {
                if !self.claim(&w) {
                    // Taken meanwhile: look again.
                    continue;
                }
                // SAFETY: claimed just now; this sender keeps the slot.
                victim = self
                    .frames
                    .get(w.slot)
                    .and_then(|f| unsafe { f.replace(None) });
                self.counters
                    .evicted(&self.lock, true, w.priority(), w.meta & RELAYED != 0);
                break w.slot;
            }
            // Nothing weaker: dropped, unless frames left meanwhile.
            if self.len.load(Relaxed) >= depth {
                self.counters
                    .dropped(&self.lock, DropReason::QueueFull, priority, relayed);
                return Pushed::Dropped;
            }
        };
        if let Some(info) = self.info.get(slot) {
            info.meta.store(meta, Relaxed);
            info.seq.store(seq, Relaxed);
            info.len.store(frame.len() as u32, Relaxed);
        }
        if let Some(f) = self.frames.get(slot) {
            // SAFETY: the slot is this sender's (a free `used` bit it set, or the slot of
            // the frame it evicted) until `publish` below.
            drop(unsafe { f.replace(Some(frame)) });
        }
        self.counters.waiting(&self.lock, self.len.load(Relaxed));
        self.publish(slot, band(priority));
        match victim {
            Some(victim) => {
                drop(victim);
                Pushed::QueuedEvicting
            }
            None => Pushed::Queued,
        }
    }

    /// The oldest waiting instance of the state message `meta` ([`pack`]ed: its priority
    /// and key).
    fn instance_of(&self, meta: u32) -> Option<Seen> {
        self.pick(band(meta as u8), |s, best| {
            s.meta & KEY == meta & KEY && best.is_none_or(|b| older(s.seq, b.seq))
        })
    }

    /// Puts `frame` in the place of the oldest waiting frame with the same [`pack`]ed key
    /// and returns that one's; `Err(frame)` if none waits.
    fn replace(
        &self,
        meta: u32,
        frame: FrameBuf<'a>,
    ) -> Result<Option<FrameBuf<'a>>, FrameBuf<'a>> {
        let len = frame.len() as u32;
        loop {
            let Some(seen) = self.instance_of(meta) else {
                return Err(frame);
            };
            if self.claim(&seen) {
                // SAFETY: claimed just now, published again below.
                let old = self
                    .frames
                    .get(seen.slot)
                    .and_then(|f| unsafe { f.replace(Some(frame)) });
                if let Some(info) = self.info.get(seen.slot) {
                    info.len.store(len, Relaxed);
                }
                self.publish(seen.slot, band(meta as u8));
                return Ok(old);
            }
        }
    }

    /// The eviction candidate, if any.
    pub fn candidate(&self) -> Option<Candidate> {
        let weakest = self.weakest()?;
        Some(Candidate {
            priority: weakest.priority(),
            seq: weakest.seq,
        })
    }

    /// Evicts the current candidate because the arena is full, if it is still `expected`
    /// (another task may have changed the queue since [`candidate`](Self::candidate)).
    /// Returns whether a frame was evicted; its memory is released before returning.
    pub fn evict_for_arena(&self, expected: Candidate) -> bool {
        let Some(seen) = self.pick(band(expected.priority), |s, _| {
            s.priority() == expected.priority && s.seq == expected.seq
        }) else {
            return false;
        };
        if !self.claim(&seen) {
            return false;
        }
        let frame = self.vacate(seen.slot);
        self.counters
            .evicted(&self.lock, false, seen.priority(), seen.meta & RELAYED != 0);
        drop(frame);
        true
    }

    /// The length of the most important frame, without taking it; with a context,
    /// registers the waker when there is none.
    pub fn peek_len(&self, mut cx: Option<&mut Context<'_>>) -> Option<usize> {
        // At most twice round: once more after registering the waker (one copy of the
        // search in flash).
        loop {
            if let Some(s) = self.strongest() {
                return Some(self.info.get(s.slot)?.len.load(Relaxed) as usize);
            }
            self.sleep(cx.take()?.waker());
        }
    }

    /// Whether no frame of band `band` waits (a quick look before a search).
    #[inline]
    fn idle(&self, band: usize) -> bool {
        self.ready
            .get(band)
            .is_none_or(|r| r.iter().take(Self::WORDS).all(|w| w.load(Relaxed) == 0))
    }

    /// The most important waiting frame: the strongest of the highest band that has one.
    #[inline]
    fn strongest(&self) -> Option<Seen> {
        (0..BANDS)
            .rev()
            .filter(|&band| !self.idle(band))
            .find_map(|band| self.pick(band, |s, best| best.is_none_or(|b| s.stronger(b))))
    }

    /// The least important waiting frame: the weakest of the lowest band that has one.
    #[inline]
    fn weakest(&self) -> Option<Seen> {
        (0..BANDS)
            .filter(|&band| !self.idle(band))
            .find_map(|band| self.pick(band, |s, best| best.is_none_or(|b| s.weaker(b))))
    }

    /// Takes the most important frame and marks it in flight.
    fn take(&self) -> Option<FrameBuf<'a>> {
        loop {
            let seen = self.strongest()?;
            if self.claim(&seen) {
                // In flight before the slot is freed, so that a snapshot never misses it.
                self.in_flight.store(IN_FLIGHT | seen.meta, Relaxed);
                return self.vacate(seen.slot);
            }
        }
    }

    /// Takes the most important frame and marks it in flight; with a context, registers
    /// the waker when there is none. For the device's one consumer, which reports the
    /// outcome with [`complete`](Self::complete).
    pub fn try_receive(&self, cx: Option<&mut Context<'_>>) -> Option<FrameBuf<'a>> {
        match (self.take(), cx) {
            (Some(frame), _) => Some(frame),
            (None, None) => None,
            (None, Some(cx)) => {
                self.sleep(cx.waker());
                self.take()
            }
        }
    }

    /// Reports the outcome of writing the in-flight frame: sent, or lost for `reason` (a
    /// write error, or refused by the device's link layer), then releases the frame's
    /// memory. With `take_next`, also takes the most important frame as
    /// [`try_receive`](Self::try_receive) (without a context) does: for a writer that
    /// writes the next frame as soon as a write completes.
    pub fn complete(
        &self,
        frame: FrameBuf<'_>,
        outcome: Result<(), DropReason>,
        take_next: bool,
    ) -> Option<FrameBuf<'a>> {
        let held = self.in_flight.load(Relaxed);
        let (priority, relayed) = (held as u8, held & RELAYED != 0);
        match outcome {
            Ok(()) => self
                .counters
                .sent(&self.lock, priority, relayed, frame.len()),
            Err(reason) => self.counters.dropped(&self.lock, reason, priority, relayed),
        }
        self.in_flight.store(0, Relaxed);
        drop(frame);
        if take_next { self.take() } else { None }
    }

    /// Takes the oldest waiting instance of state message `key` at `priority` without
    /// counting it (tests: the queue itself only supersedes in place).
    #[cfg(test)]
    fn remove_latest(&self, priority: u8, key: MessageKey) -> Option<FrameBuf<'a>> {
        let seen = self.instance_of(pack(priority, Some(key), false))?;
        if self.claim(&seen) {
            self.vacate(seen.slot)
        } else {
            None
        }
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
                    let old = key.and_then(|k| queue.remove_latest(128, k));
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

    /// Pushes (priorities of every band, a few state messages, depths up to `max_depth`),
    /// takes and arena evictions.
    fn op(max_depth: usize) -> impl Strategy<Value = Op> {
        ops(max_depth, 4)
    }

    /// As [`op`], with `pushes` pushes for 2 takes and 1 arena eviction, and depth
    /// `max_depth` for half of them (so that a large queue fills up).
    fn ops(max_depth: usize, pushes: u32) -> impl Strategy<Value = Op> {
        let priority = prop_oneof![(0u8..5).prop_map(|p| p * 60), any::<u8>()];
        let depth = prop_oneof![1usize..max_depth, Just(max_depth)];
        prop_oneof![
            pushes => (priority, prop::option::weighted(0.3, 0u8..3), depth)
                .prop_map(|(priority, key, depth)| Op::Push { priority, key, depth }),
            2 => Just(Op::Take),
            1 => Just(Op::EvictForArena),
        ]
    }

    /// Model entry: priority, seq, key, the id written in the frame.
    type M = (u8, u32, Option<MessageKey>, u32);

    /// Runs `ops` on a queue of `Q` slots and on the model, comparing every result.
    fn check<const Q: usize>(ops: Vec<Op>) -> Result<(), TestCaseError> {
        let arena: FrameArena<RawM, 4096> = FrameArena::new();
        let queue: FrameQueue<'_, RawM, Q> = FrameQueue::new();
        let mut model: Vec<M> = Vec::new();
        let mut seq = 0u32;
        for op in ops {
            match op {
                Op::Push {
                    priority,
                    key,
                    depth,
                } => {
                    seq += 1;
                    let key = key.map(|k| MessageKey {
                        class: 1,
                        msg_id: k,
                    });
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
                            let at = model
                                .iter()
                                .position(|m| m.0 < priority)
                                .unwrap_or(model.len());
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
                        (
                            at,
                            Candidate {
                                priority: model[at].0,
                                seq: model[at].1,
                            },
                        )
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
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn the_queue_behaves_as_the_sorted_model(ops in prop::collection::vec(op(10), 1..300)) {
            check::<8>(ops)?;
        }

        #[test]
        fn a_queue_of_one_slot_too(ops in prop::collection::vec(op(3), 1..100)) {
            check::<1>(ops)?;
        }

        /// Two words of bits: push-heavy, so that the slots past the 32nd are used.
        #[test]
        fn a_queue_of_64_slots_too(ops in prop::collection::vec(ops(64, 12), 1..400)) {
            check::<64>(ops)?;
        }
    }
}

#[cfg(test)]
mod concurrent {
    //! The queue under real concurrency: several threads sending (with evictions, state
    //! messages and arena evictions) while one takes and completes frames. Every frame
    //! is taken at most once, nothing leaks from the arena, and the counters balance.

    use super::*;
    use crate::arena::FrameArena;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as RawM;
    use std::collections::HashSet;
    use std::sync::atomic::{AtomicBool, AtomicU32 as Count};

    #[test]
    fn threads_sending_evicting_and_taking_lose_nothing() {
        const PER_SENDER: u32 = if cfg!(miri) { 60 } else { 4000 };
        let arena: FrameArena<RawM, 1024> = FrameArena::new();
        let queue: FrameQueue<'_, RawM, 12> = FrameQueue::new();
        let seq = Count::new(0);
        let done = AtomicBool::new(false);
        let taken = std::thread::scope(|s| {
            for sender in 0..3u32 {
                let (arena, queue, seq) = (&arena, &queue, &seq);
                s.spawn(move || {
                    for n in 0..PER_SENDER {
                        let latest = (n % 4 == 0).then_some(MessageKey {
                            class: 1,
                            msg_id: (n % 3) as u8,
                        });
                        // State messages at one priority, so that they meet often.
                        let priority = match latest {
                            Some(_) => 100,
                            None => ((n * 7 + sender * 3) % 5) as u8 * 50,
                        };
                        let Ok(mut frame) = arena.alloc(8 + (n % 24) as usize) else {
                            // The arena's way out, as the downlink takes it.
                            if let Some(c) = queue.candidate() {
                                queue.evict_for_arena(c);
                            }
                            queue.count_dropped(DropReason::ArenaFull, priority, false);
                            continue;
                        };
                        frame[..4].copy_from_slice(&sender.to_le_bytes());
                        frame[4..8].copy_from_slice(&n.to_le_bytes());
                        let seq = seq.fetch_add(1, Relaxed);
                        let depth = 4 + (n % 9) as usize;
                        // Forwarded frames are never state messages.
                        let relayed = n % 11 == 0 && latest.is_none();
                        queue.push(priority, seq, latest, relayed, frame, depth);
                        if n % 8 == 0 {
                            // Lets the writer in: a queue that stays full tests less.
                            std::thread::yield_now();
                        }
                    }
                });
            }
            let consumer = s.spawn(|| {
                let mut taken = Vec::new();
                loop {
                    let finished = done.load(SeqCst);
                    match queue.try_receive(None) {
                        Some(frame) => {
                            let mut id = [0u8; 8];
                            id.copy_from_slice(&frame[..8]);
                            taken.push(u64::from_le_bytes(id));
                            let outcome = if taken.len() % 13 == 0 {
                                Err(DropReason::WriteError)
                            } else {
                                Ok(())
                            };
                            queue.complete(frame, outcome, false);
                        }
                        None if finished => return taken,
                        None => std::thread::yield_now(),
                    }
                }
            });
            // The senders end before the scope's own end: wait for them by polling the
            // counters, then let the consumer drain what is left.
            while queue.stats().submitted < 3 * PER_SENDER {
                std::thread::yield_now();
            }
            done.store(true, SeqCst);
            consumer.join().expect("consumer")
        });
        let unique: HashSet<u64> = taken.iter().copied().collect();
        assert_eq!(unique.len(), taken.len(), "a frame was taken twice");
        let stats = queue.stats();
        assert!(stats.is_balanced(), "{stats:?}");
        assert_eq!(stats.queued, 0, "{stats:?}");
        assert_eq!(
            stats.sent + stats.dropped.write_error,
            taken.len() as u32,
            "{stats:?}"
        );
        assert_eq!(stats.submitted, 3 * PER_SENDER);
        assert!(
            stats.evicted.total() > 0 && stats.superseded > 0,
            "{stats:?}"
        );
        assert!(stats.sent > 0, "the writer never ran: {stats:?}");
        assert_eq!(arena.stats().live, 0, "a frame leaked");
    }
}
