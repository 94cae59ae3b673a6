//! The frame arena: one shared byte arena for the pending frames of all devices (the
//! *Dynamic Memory Space* of Jornet's design), allocated and released without a lock.
//!
//! A [`FrameArena`] is a `static` block of `N` bytes. [`FrameArena::alloc`] hands out a
//! [`FrameBuf`]: an exclusively owned, contiguous region of the arena (a *grant*, as in
//! bbqueue). The frame is encoded into it, truncated to its final length, queued, and
//! eventually written to a device, possibly by another task on another executor. Dropping
//! the `FrameBuf`, when the write completes or the queue evicts the frame, releases its
//! memory; there is no other way to release it, so memory cannot leak or be released twice.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
//! use pprz_telemetry::arena::FrameArena;
//! # use critical_section as _;
//!
//! static ARENA: FrameArena<CriticalSectionRawMutex, 4096> = FrameArena::new();
//!
//! let mut frame = ARENA.alloc(64)?;        // room for the largest encoding
//! frame[..3].copy_from_slice(&[0x99, 3, 7]); // encode...
//! frame.truncate(3);                       // ...and keep what was written
//! assert_eq!(&frame[..], &[0x99, 3, 7]);
//! assert_eq!(ARENA.stats().live, 1);
//! drop(frame);                             // the write completed: memory returns
//! assert_eq!(ARENA.stats().live, 0);
//! # Ok::<(), pprz_telemetry::arena::AllocError>(())
//! ```
//!
//! # Allocator
//!
//! The storage is cut into units of [`GRANULARITY`] (8) bytes, and one bit per unit says
//! whether a frame holds it. The bits are packed 32 to a word, in `AtomicU32`s at the end of
//! the storage ([`FrameArena::RESERVED`], 1/65 of `N`, is the only fixed overhead).
//!
//! * **Allocation** tries the units right after the previous allocation first (a telemetry
//!   stream allocates and releases frames in roughly the order it sends them, so they are
//!   usually free). Otherwise it looks for the first run of free units long enough for
//!   the frame, from the word where the previous allocation ended round to it again (*next
//!   fit*), reading each word's free runs with bit scans. It claims the run with one
//!   compare-and-swap per word it spans (one for most frames: a word covers 256 bytes).
//! * **Release** clears the frame's bits, one atomic AND per word. Free runs need no
//!   merging: neighbouring free units are simply neighbouring zero bits.
//! * **No per-frame header.** A live frame's run is described by its [`FrameBuf`] (start
//!   and size), so a frame costs only its length rounded up to 8 bytes.
//! * **Same layout on every target**: 8-byte units and 32-bit words on the host, in Miri
//!   and on the MCU.
//! * **Fully zero-initialised**, so a `static` arena lives in `.bss` and costs no flash.
//!   Besides the `N` bytes, the counters take 28 bytes.
//!
//! Fill level at the first allocation failure, with random frame sizes 8..=255 bytes in
//! steady state (release a random frame, allocate until an allocation fails, record the
//! fill level; 20 000 rounds, fixed seed; `cargo test -p pprz-telemetry --test arena fill
//! -- --nocapture` prints it). *Used* counts rounding and `RESERVED`, *payload* only the
//! requested bytes; both are fractions of `N`:
//!
//! | `N`    | used, mean (worst round) | payload, mean |
//! |--------|--------------------------|---------------|
//! | 4 KiB  | 83.4 % (64.5 %)          | 78.4 %        |
//! | 16 KiB | 87.1 % (79.3 %)          | 81.9 %        |
//! | 64 KiB | 90.9 % (87.0 %)          | 85.8 %        |
//!
//! Smaller arenas fill less at the first failure mostly because a 255-byte request is a
//! larger share of them.
//!
//! # Layout
//!
//! ```text
//!  unit 0                                              UNITS-1
//!  |                                                         |
//!  +---------+------------+---------+-----------------------+------------------+
//!  | frame A | free       | frame B | free                  | bitmap: 1 bit    |
//!  | (owned  |            | (owned  |                       | per unit, in     |
//!  | by its  |            | by its  |                       | AtomicU32 words; |
//!  | FrameBuf)            | FrameBuf)                       | padding          |
//!  +---------+------------+---------+-----------------------+------------------+
//!   1 1 1 1   0 0 0 0 0 0  1 1 1 1   0 0 0 0 0 0 0 0 0 0 0    (RESERVED bytes)
//! ```
//!
//! Unit `u` is bit `u % 32` of word `u / 32`. The bits of the last word beyond `UNITS`
//! stay zero in memory and are read as taken.
//!
//! # Time Complexity
//!
//! Releasing a frame is one atomic AND per word its run spans (at most 5, for the largest
//! frame) and two counter updates. In steady state an allocation finds the units after the
//! previous frame free: a load and a compare-and-swap per word (one, or two when the run
//! crosses into the next word), and three counter updates.
//! Otherwise it examines each bitmap word at most once per attempt (`N / 260` words: 16
//! for 4 KiB; up to four more for a run that began before its first word), with a few bit
//! scans per word, and claims its run. An attempt is repeated
//! only when another context changed the bitmap meanwhile: it claimed some of the same
//! units first, or released frames in words already read (then the failure might not be
//! genuine, so the scan runs again).
//!
//! # Concurrency and `unsafe`
//!
//! Nothing masks interrupts on cores with compare-and-swap (Cortex-M3 and above, x86,
//! RISC-V with the A extension): the bitmap and the counters are
//! atomic words, changed with read-modify-write instructions. On cores without them
//! (ARMv6-M, RV32IMC) each read-modify-write takes the arena's mutex `M` for a few
//! instructions instead (see [`FrameArena`]).
//!
//! This module is allowed `unsafe` code for two things: disjoint `&mut [u8]` views of live
//! frames into one [`UnsafeCell`] buffer, and atomic views of the bitmap words at its end.
//! The invariants that make it sound are written on [`FrameArena`]; property tests check
//! them after every step, threads race on one arena, and the tests run under Miri.

// The crate denies `unsafe_code`; this module needs it to hand out disjoint mutable views
// of one shared buffer (see "Concurrency and `unsafe`" above). Every block is justified.
#![allow(unsafe_code)]

use core::cell::UnsafeCell;
use core::fmt;
use core::ops::{Deref, DerefMut};
use core::sync::atomic::AtomicU32;
use core::sync::atomic::Ordering::{Acquire, Relaxed, Release};

use embassy_sync::blocking_mutex::raw::RawMutex;

use crate::atomic::{self, Fallback};

/// Allocation granularity in bytes: every frame occupies a multiple of this.
pub const GRANULARITY: usize = 8;

/// Largest allocation of any arena, in bytes; an arena smaller than this has a smaller
/// [`FrameArena::MAX_ALLOC`].
pub const MAX_ALLOC_LIMIT: usize = 1024;

/// Smallest usable size of an arena in bytes, checked at compile time.
pub const MIN_USABLE: usize = 512;

/// Units per bitmap word.
const WORD_UNITS: usize = 32;
/// Bytes per bitmap word.
const WORD_BYTES: usize = 4;

/// Why [`FrameArena::alloc`] failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AllocError {
    /// The request is larger than [`FrameArena::MAX_ALLOC`].
    TooLarge {
        /// Requested length in bytes.
        len: usize,
        /// The arena's largest allocation in bytes.
        max: usize,
    },
    /// No run of free units is long enough right now; one will be after frames are
    /// released.
    Full {
        /// Requested length in bytes.
        len: usize,
    },
}

impl fmt::Display for AllocError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooLarge { len, max } => write!(
                f,
                "a frame of {len} bytes exceeds the arena's largest allocation ({max} bytes)"
            ),
            Self::Full { len } => write!(f, "frame arena full: no free block of {len} bytes"),
        }
    }
}

impl core::error::Error for AllocError {}

/// A snapshot of an arena's fill level and counters ([`FrameArena::stats`]).
///
/// The counters are read one after the other without a lock: a snapshot taken while
/// other contexts allocate or release may be off by the frames in transit (for example
/// `live` one more than the frames whose `used` was counted).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ArenaStats {
    /// Bytes of storage, `N`.
    pub capacity: usize,
    /// Bytes not available to new frames: the blocks of live frames (lengths rounded up
    /// to [`GRANULARITY`]) plus the fixed [`FrameArena::RESERVED`] bytes. `used /
    /// capacity` is the fill level.
    pub used: usize,
    /// Live frames: allocated and not yet released.
    pub live: usize,
    /// Largest `used` since creation or the last [`FrameArena::reset_high_water`].
    pub high_water: usize,
    /// Number of runs of free units; with `used`, a measure of fragmentation (at most
    /// `live + 1`: only frames separate free units).
    pub free_blocks: usize,
    /// Successful allocations (wrapping).
    pub allocs: u32,
    /// Releases (wrapping); `allocs.wrapping_sub(frees) == live`.
    pub frees: u32,
    /// Allocations that failed with [`AllocError::Full`] or [`AllocError::TooLarge`]
    /// (wrapping).
    pub failures: u32,
}

/// The storage: frame units, then the bitmap words (hence the alignment), then padding.
#[repr(C, align(4))]
struct Storage<const N: usize>([u8; N]);

/// One shared arena of `N` bytes for the pending frames of all devices.
///
/// `M` is the blocking mutex that stands in for compare-and-swap on cores without it
/// (ARMv6-M, RV32IMC): a `CriticalSectionRawMutex` when frames are allocated or released
/// from several executors or interrupts, a `ThreadModeRawMutex` for one thread-mode
/// executor. On every other core it is never taken, and a frame's allocation and release
/// mask no interrupt. It must be `Sync` ([`new`](Self::new) requires it), because the
/// frames [`alloc`] returns are `Send` and release their memory wherever they are dropped:
///
/// ```compile_fail
/// use embassy_sync::blocking_mutex::raw::NoopRawMutex;
/// use pprz_telemetry::arena::FrameArena;
/// let arena = FrameArena::<NoopRawMutex, 1024>::new(); // error: `NoopRawMutex` is not `Sync`
/// ```
///
/// `N` is checked at compile time: the usable part must be at least [`MIN_USABLE`] bytes.
///
/// ```compile_fail
/// use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
/// use pprz_telemetry::arena::FrameArena;
/// // Too small: fails to compile.
/// static ARENA: FrameArena<CriticalSectionRawMutex, 256> = FrameArena::new();
/// ```
///
/// A frame cannot outlive its arena:
///
/// ```compile_fail
/// use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
/// use pprz_telemetry::arena::FrameArena;
/// let frame = {
///     let arena = FrameArena::<CriticalSectionRawMutex, 1024>::new();
///     arena.alloc(16).unwrap()
/// }; // error: `arena` does not live long enough
/// drop(frame);
/// ```
///
/// # Invariants
///
/// With `UNITS` the number of 8-byte units before the [`RESERVED`](Self::RESERVED) tail:
///
/// 1. A unit's bit is set while the unit is *taken*: owned by a live [`FrameBuf`] that
///    records its start and size, or claimed by an allocation or released by a `FrameBuf`
///    drop that is still running. A bit is set only by a compare-and-swap that saw it
///    clear, so no unit is ever taken twice: the runs of live frames are disjoint.
/// 2. A bit is cleared only by the allocation that set it (giving back a claim that
///    conflicted) or by the drop of the `FrameBuf` that owns it.
/// 3. The bitmap words are accessed only atomically, the bits of the last word beyond
///    `UNITS` stay clear, and the bytes of an owned run only through its `FrameBuf`.
/// 4. Setting a bit acquires and clearing it releases, so a frame's last use happens
///    before the next owner of its units writes them.
/// 5. Every byte of the storage is initialised (zero at creation, then only ever written
///    with initialised values), so a new frame's bytes may hold an older frame's data but
///    are never uninitialised.
///
/// [`alloc`]: Self::alloc
pub struct FrameArena<M: RawMutex, const N: usize> {
    /// Frame units, then the bitmap; see the invariants above.
    storage: UnsafeCell<Storage<N>>,
    /// Units taken by live frames.
    used: AtomicU32,
    /// Largest `used` since creation or the last reset, in units.
    high_water: AtomicU32,
    /// Successful allocations.
    allocs: AtomicU32,
    /// Releases.
    frees: AtomicU32,
    /// Failed allocations.
    failures: AtomicU32,
    /// Claims given back after a conflict (with `frees`, the sign that bits were cleared
    /// while an allocation was scanning).
    rollbacks: AtomicU32,
    /// The word where the last allocation ended: where the next one starts looking.
    next: AtomicU32,
    /// Taken in place of read-modify-write instructions on cores without them.
    lock: Fallback<M>,
}

// Safety: `FrameArena` is `!Sync` only because of `storage`. Concurrent access to it is
// coordinated: the bitmap words are only accessed atomically, and the bytes of a live frame
// are reachable only through the one `FrameBuf` that owns its run (invariants 1-3), whose
// claim acquired the previous owner's release (invariant 4). `M: Sync` makes the fallback
// lock a real lock between threads on cores without compare-and-swap.
unsafe impl<M: RawMutex + Sync, const N: usize> Sync for FrameArena<M, N> {}

impl<M: RawMutex + Sync, const N: usize> FrameArena<M, N> {
    /// An empty arena. A `const fn`, so the arena can be a `static`; it is all zeros, so
    /// it lives in `.bss`.
    ///
    /// Only arenas whose mutex is `Sync` can be created: frames are `Send`, so they may
    /// release their memory from another thread (see [`FrameBuf`]). With one executor,
    /// use `ThreadModeRawMutex` rather than `NoopRawMutex`.
    ///
    /// # Panics
    ///
    /// Never at run time; an invalid `N` is a compile-time error.
    pub const fn new() -> Self {
        let () = Self::VALID;
        Self {
            storage: UnsafeCell::new(Storage([0; N])),
            used: AtomicU32::new(0),
            high_water: AtomicU32::new(0),
            allocs: AtomicU32::new(0),
            frees: AtomicU32::new(0),
            failures: AtomicU32::new(0),
            rollbacks: AtomicU32::new(0),
            next: AtomicU32::new(0),
            lock: Fallback::new(()),
        }
    }
}

/// The words a run of `units` units from unit `start` spans, with the mask of its units in
/// each: `(word, mask)`, in order.
#[inline(always)]
fn spans(start: usize, units: usize) -> impl Iterator<Item = (usize, u32)> {
    let end = start + units;
    let mut u = start;
    core::iter::from_fn(move || {
        (u < end).then(|| {
            let (i, bit) = (u / WORD_UNITS, u % WORD_UNITS);
            let n = (end - u).min(WORD_UNITS - bit);
            u += n;
            (i, ones(n) << bit)
        })
    })
}

/// `n` (1..=32) one bits from bit 0.
const fn ones(n: usize) -> u32 {
    u32::MAX >> (WORD_UNITS - n)
}

impl<M: RawMutex, const N: usize> FrameArena<M, N> {
    /// Number of units available to frames: the largest `u` with
    /// `u * GRANULARITY + 4 * ceil(u / 32) <= N` (one bit per unit, in 4-byte words).
    const UNITS: usize = {
        let mut u = N * 8 / (8 * GRANULARITY + 1);
        while u * GRANULARITY + u.div_ceil(WORD_UNITS) * WORD_BYTES > N {
            u -= 1;
        }
        u
    };

    /// Number of bitmap words.
    const WORDS: usize = Self::UNITS.div_ceil(WORD_UNITS);

    /// The bits of the last word beyond `UNITS`, read as taken.
    const PAD: u32 = match Self::UNITS % WORD_UNITS {
        0 => 0,
        used => !ones(used),
    };

    /// Bytes of the storage not available to frames: the bitmap (one bit per
    /// [`GRANULARITY`] bytes, in 4-byte words) and padding. `stats().used` starts at this
    /// value.
    pub const RESERVED: usize = N - Self::UNITS * GRANULARITY;

    /// Largest allocation in bytes: [`MAX_ALLOC_LIMIT`], or the usable size of a smaller
    /// arena. Always at least [`MIN_USABLE`].
    pub const MAX_ALLOC: usize = if Self::UNITS * GRANULARITY < MAX_ALLOC_LIMIT {
        Self::UNITS * GRANULARITY
    } else {
        MAX_ALLOC_LIMIT
    };

    /// Compile-time check of `N`, forced by [`new`](Self::new).
    const VALID: () = {
        assert!(
            Self::UNITS * GRANULARITY >= MIN_USABLE,
            "FrameArena: N is too small (the usable part must be at least MIN_USABLE bytes)"
        );
        assert!(
            N <= u32::MAX as usize,
            "FrameArena: N is too large (at most u32::MAX bytes)"
        );
    };

    /// A snapshot of the fill level and counters.
    ///
    /// # Time Complexity
    ///
    /// Reads every bitmap word once (to count the free runs); takes no lock.
    pub fn stats(&self) -> ArenaStats {
        // `frees` first: a frame's release is counted after its allocation, so `allocs`
        // read later is not behind (and a difference that is still negative, across
        // cores, reads as none).
        let frees = self.frees.load(Relaxed);
        let allocs = self.allocs.load(Relaxed);
        let units = |v: &AtomicU32| Self::RESERVED + v.load(Relaxed) as usize * GRANULARITY;
        ArenaStats {
            capacity: N,
            used: units(&self.used),
            live: (allocs.wrapping_sub(frees) as i32).max(0) as usize,
            high_water: units(&self.high_water),
            free_blocks: self.free_runs(),
            allocs,
            frees,
            failures: self.failures.load(Relaxed),
        }
    }

    /// Restart the high-water mark from the current fill level.
    pub fn reset_high_water(&self) {
        self.high_water.store(self.used.load(Relaxed), Relaxed);
    }

    /// Bitmap word `i` (`i < WORDS`).
    #[inline(always)]
    fn word(&self, i: usize) -> &AtomicU32 {
        debug_assert!(i < Self::WORDS, "arena: bitmap word out of range");
        let at = Self::UNITS * GRANULARITY + i * WORD_BYTES;
        // Safety: word `i` lies at `at..at + 4` with `at + 4 <= N` (`UNITS`), inside the
        // storage, which lives as long as `self`, and is 4-aligned (`Storage` is, and `at`
        // is a multiple of 4). It is outside every frame's run, and these bytes are only
        // ever accessed through this function, atomically (invariant 3).
        unsafe { AtomicU32::from_ptr(self.base().wrapping_add(at).cast::<u32>()) }
    }

    /// Word `i` as allocation sees it: the bits beyond `UNITS` read as taken.
    #[inline(always)]
    fn taken(&self, i: usize) -> u32 {
        let pad = if i + 1 == Self::WORDS { Self::PAD } else { 0 };
        self.word(i).load(Relaxed) | pad
    }

    /// Number of runs of free units.
    fn free_runs(&self) -> usize {
        let mut runs = 0;
        let mut carry = 0; // 1 if the unit before this word is free
        for i in 0..Self::WORDS {
            let free = !self.taken(i);
            runs += (free & !((free << 1) | carry)).count_ones() as usize;
            carry = free >> 31;
        }
        runs
    }

    /// Clears the bits of units `start .. start + units`, one atomic AND per word.
    fn clear(&self, start: usize, units: usize) {
        for (i, mask) in spans(start, units) {
            atomic::and(&self.lock, self.word(i), !mask, Release);
        }
    }

    /// Where the first run of `units` free units lies, looking from the word where the
    /// last allocation ended round to it again (next fit): its first unit, or `None`.
    fn search(&self, units: usize) -> Option<usize> {
        let from = (self.next.load(Relaxed) as usize / WORD_UNITS).min(Self::WORDS - 1);
        // Free units up to the end of the previous word read, contiguous with this one.
        let mut run = 0;
        let mut i = from;
        // Once round, then on while a run that began before `from` goes on (at most 4
        // more words: a run of 128 units is long enough for any frame).
        for k in 0.. {
            if k > 0 {
                i = if i + 1 == Self::WORDS { 0 } else { i + 1 };
            }
            if i == 0 {
                run = 0; // the storage's end does not continue at its start
            }
            if k >= Self::WORDS && run == 0 {
                break;
            }
            let w = self.taken(i);
            // The run so far, continued by this word's free low units.
            if run + w.trailing_zeros() as usize >= units {
                return Some(i * WORD_UNITS - run);
            }
            if units <= WORD_UNITS {
                // Each run of free units inside the word, lowest first (a few per word).
                let mut free = !w;
                while free != 0 {
                    let first = free.trailing_zeros();
                    let len = (!(free >> first)).trailing_zeros() as usize;
                    if len >= units {
                        return Some(i * WORD_UNITS + first as usize);
                    }
                    // Adding the run's lowest bit carries through the run, clearing it.
                    free &= free.wrapping_add(1 << first);
                }
            }
            run = if w == 0 {
                run + WORD_UNITS
            } else {
                w.leading_zeros() as usize
            };
        }
        None
    }

    /// Takes units `start .. start + units` (found free by [`search`](Self::search)), one
    /// compare-and-swap per word; if another context took one of them first, gives back
    /// the words already taken and returns `false`.
    fn claim(&self, start: usize, units: usize) -> bool {
        for (i, mask) in spans(start, units) {
            if !self.claim_word(i, mask) {
                // The units before this word's part of the run were taken.
                let first = i * WORD_UNITS + mask.trailing_zeros() as usize;
                self.clear(start, first - start);
                atomic::add(&self.lock, &self.rollbacks, 1);
                return false;
            }
        }
        true
    }

    /// Sets the bits `mask` of word `i` if they are all clear (acquiring the frames that
    /// released them); `false` if any is set.
    #[inline(always)]
    fn claim_word(&self, i: usize, mask: u32) -> bool {
        let free = |w: u32| (w & mask == 0).then_some(w | mask);
        atomic::update(&self.lock, self.word(i), Acquire, free).is_ok()
    }

    /// Sets the bits `lo` of word `i` and `hi` of word `i + 1` if they are all clear (one
    /// compare-and-swap each); if the second part was taken first, gives the first back
    /// (counted in `rollbacks`) and returns `false`.
    #[inline(always)]
    fn claim_pair(&self, i: usize, lo: u32, hi: u32) -> bool {
        if !self.claim_word(i, lo) {
            return false;
        }
        if self.claim_word(i + 1, hi) {
            return true;
        }
        atomic::and(&self.lock, self.word(i), !lo, Release);
        atomic::add(&self.lock, &self.rollbacks, 1);
        false
    }

    /// Bits cleared so far (releases and given-back claims): an allocation that finds no
    /// room rescans if this changed while it scanned.
    fn cleared(&self) -> u32 {
        self.frees
            .load(Relaxed)
            .wrapping_add(self.rollbacks.load(Relaxed))
    }

    /// Finds and claims a run of `units` free units: where the last allocation ended if
    /// it is free there (a telemetry stream releases frames in about the order it
    /// allocated them), else the first that fits from that word on, round to it again.
    /// `None` if none fits in a scan during which no bits were cleared.
    fn take(&self, units: usize) -> Option<usize> {
        let hint = self.next.load(Relaxed) as usize;
        let (i, bit) = (hint / WORD_UNITS, hint % WORD_UNITS);
        if bit + units <= WORD_UNITS && i < Self::WORDS {
            let mask = ones(units) << bit;
            if self.taken(i) & mask == 0 && self.claim_word(i, mask) {
                return Some(hint);
            }
        } else if units <= WORD_UNITS && i + 1 < Self::WORDS {
            // The run crosses into the next word (half of the frames of random sizes do).
            let (lo, hi) = (u32::MAX << bit, ones(bit + units - WORD_UNITS));
            if self.taken(i) & lo == 0 && self.taken(i + 1) & hi == 0 && self.claim_pair(i, lo, hi)
            {
                return Some(hint);
            }
        }
        let mut seen = self.cleared();
        loop {
            match self.search(units) {
                Some(start) if self.claim(start, units) => return Some(start),
                Some(_) => {} // another context took some of the units first
                None => {
                    let now = self.cleared();
                    if now == seen {
                        return None;
                    }
                    seen = now; // released meanwhile: the scan may have missed room
                }
            }
        }
    }

    /// Allocate a frame of `len` bytes (`0..=MAX_ALLOC`). Its bytes are initialised but
    /// unspecified (an older frame's data); [`FrameBuf::truncate`] it to the length
    /// actually encoded. Dropping it releases the memory.
    ///
    /// The frame takes `len` rounded up to [`GRANULARITY`] (at least one unit). It fails
    /// with [`AllocError::Full`] only if no run of free units is long enough: when other
    /// contexts allocate and release meanwhile, in the bitmap as it was at the end of a
    /// scan during which no frame was released.
    ///
    /// # Errors
    ///
    /// [`AllocError::TooLarge`] if `len > MAX_ALLOC`, [`AllocError::Full`] if no run of
    /// free units fits. Both count as failures in [`stats`](Self::stats).
    ///
    /// # Time Complexity
    ///
    /// One scan of at most every bitmap word (see the [module](self#time-complexity)),
    /// repeated only when another context took the same units first or released frames
    /// during a scan that found no room. Takes no lock on cores with compare-and-swap.
    pub fn alloc(&self, len: usize) -> Result<FrameBuf<'_>, AllocError> {
        if len > Self::MAX_ALLOC {
            atomic::add(&self.lock, &self.failures, 1);
            return Err(AllocError::TooLarge {
                len,
                max: Self::MAX_ALLOC,
            });
        }
        let units = len.div_ceil(GRANULARITY).max(1);
        let Some(start) = self.take(units) else {
            atomic::add(&self.lock, &self.failures, 1);
            return Err(AllocError::Full { len });
        };
        // The next allocation tries first where this one ended. The casts are lossless:
        // units are below `N <= u32::MAX`, `units <= 128`, `len <= 1024`.
        self.next.store((start + units) as u32, Relaxed);
        let used = atomic::add(&self.lock, &self.used, units as u32) + units as u32;
        if used > self.high_water.load(Relaxed) {
            let higher = |h: u32| (used > h).then_some(used);
            let _ = atomic::update(&self.lock, &self.high_water, Relaxed, higher);
        }
        atomic::add(&self.lock, &self.allocs, 1);
        Ok(FrameBuf {
            arena: self,
            // In bounds: `start < UNITS`, so the run's first byte is in the storage.
            ptr: self.base().wrapping_add(start * GRANULARITY),
            units: units as u16,
            len: len as u16,
        })
    }
}

impl<M: RawMutex + Sync, const N: usize> Default for FrameArena<M, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M: RawMutex, const N: usize> fmt::Debug for FrameArena<M, N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FrameArena")
            .field("stats", &self.stats())
            .finish_non_exhaustive()
    }
}

/// What a [`FrameBuf`] needs of its arena, with `M` and `N` erased.
trait Grants {
    /// Start of the storage.
    fn base(&self) -> *mut u8;

    /// Return the run of `units` units whose first byte is `ptr` to the arena.
    ///
    /// # Safety
    ///
    /// * `ptr` and `units` describe a run allocated by this arena and not yet released.
    /// * No reference into its bytes is used afterwards.
    unsafe fn release(&self, ptr: *mut u8, units: usize);
}

impl<M: RawMutex, const N: usize> Grants for FrameArena<M, N> {
    fn base(&self) -> *mut u8 {
        self.storage.get().cast::<u8>()
    }

    unsafe fn release(&self, ptr: *mut u8, units: usize) {
        // The run's first unit (the caller guarantees `ptr` is one of ours).
        let start = (ptr.addr() - self.base().addr()) / GRANULARITY;
        // `used` first, so that it never counts a unit twice (the high-water mark stays
        // exact); `frees` last, so that an allocation that sees it changed rescans.
        atomic::add(&self.lock, &self.used, (units as u32).wrapping_neg());
        self.clear(start, units);
        atomic::add(&self.lock, &self.frees, 1);
    }
}

/// An exclusively owned, contiguous region of a [`FrameArena`]: a pending frame.
///
/// Created by [`FrameArena::alloc`].
///
/// Dereferences to its first [`len`](Self::len) bytes. Dropping it releases the memory
/// (one atomic AND per 256 bytes of it, no lock). It is `Send` and `Sync`, so it can
/// be queued, handed to a writer task on another executor and held across an `.await`
/// while other tasks allocate and release frames.
pub struct FrameBuf<'a> {
    /// The arena, which outlives the frame.
    arena: &'a dyn Grants,
    /// First byte of the block, a pointer into the arena's storage; the block is owned
    /// by this `FrameBuf` alone (invariant 1).
    ptr: *mut u8,
    /// Size of the block in units; the block ends at or before unit `UNITS`.
    units: u16,
    /// Logical length in bytes; `len <= units * GRANULARITY`.
    len: u16,
}

// Safety: a `FrameBuf` holds a shared reference to its arena and the exclusive right to
// its block. Its arena is `Sync`: the only constructors of `FrameArena`, `new` and
// `default`, require `M: Sync`, which makes `FrameArena<M, N>: Sync`. So the reference
// may be used from another thread (to release the block, atomically), and the block's
// bytes are reached only through this `FrameBuf` (invariant 1), with `&`/`&mut` rules
// enforced by `Deref`/`DerefMut`.
unsafe impl Send for FrameBuf<'_> {}

// Safety: as for `Send`; through `&FrameBuf` another thread can only read the block's
// bytes and the `FrameBuf`'s own fields, never write or release them.
unsafe impl Sync for FrameBuf<'_> {}

impl FrameBuf<'_> {
    /// Logical length in bytes (the requested length, or less after [`truncate`]).
    ///
    /// [`truncate`]: Self::truncate
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether the logical length is zero.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Bytes of arena the frame occupies until it is dropped: its requested length rounded
    /// up to [`GRANULARITY`] (at least one unit).
    pub fn capacity(&self) -> usize {
        usize::from(self.units) * GRANULARITY
    }

    /// Shorten the logical length to `len`, typically to what an encoder wrote. Does
    /// nothing if `len >= self.len()`. The memory stays allocated until the drop.
    pub fn truncate(&mut self, len: usize) {
        if len < self.len() {
            // Lossless: `len < self.len <= u16::MAX`.
            self.len = len as u16;
        }
    }

    /// Sets the logical length to the whole block (its [`capacity`](Self::capacity), at
    /// most `u16::MAX`) and returns it: the spare bytes after a frame, for a link layer
    /// that lengthens the frame in place. They hold whatever the block held before
    /// (possibly an older frame's bytes; never uninitialised, invariant 5).
    pub(crate) fn set_len_to_capacity(&mut self) -> usize {
        self.len = u16::try_from(self.capacity()).unwrap_or(u16::MAX);
        self.len()
    }

    /// Offset of the block in the arena's storage, in bytes.
    fn offset(&self) -> usize {
        self.ptr.addr() - self.arena.base().addr()
    }
}

impl Deref for FrameBuf<'_> {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        // Safety: the block (`units` units from `ptr`) lies inside the storage, which lives
        // for `'a`, and `len <= units * GRANULARITY`. It is owned by this `FrameBuf` alone
        // (invariant 1): the allocator does not touch it (invariant 3) and no other
        // `FrameBuf` covers it, so the only references to these bytes come from this
        // `FrameBuf`, and `&self` keeps `deref_mut` out. The bytes are initialised
        // (invariant 5).
        unsafe { core::slice::from_raw_parts(self.ptr, self.len()) }
    }
}

impl DerefMut for FrameBuf<'_> {
    fn deref_mut(&mut self) -> &mut [u8] {
        // Safety: as in `deref`; `&mut self` makes this the only live reference to the
        // block's bytes.
        unsafe { core::slice::from_raw_parts_mut(self.ptr, self.len()) }
    }
}

impl Drop for FrameBuf<'_> {
    fn drop(&mut self) {
        // Safety: the block was allocated by `self.arena` and is released exactly once,
        // here; references into it borrowed `self`, so none outlives this call.
        unsafe {
            self.arena.release(self.ptr, usize::from(self.units));
        }
    }
}

impl fmt::Debug for FrameBuf<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FrameBuf")
            .field("offset", &self.offset())
            .field("len", &self.len())
            .field("capacity", &self.capacity())
            .finish()
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for FrameBuf<'_> {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "FrameBuf {{ offset: {}, len: {}, capacity: {} }}",
            self.offset(),
            self.len(),
            self.capacity()
        );
    }
}

#[cfg(test)]
mod tests {
    //! White-box tests: the run search across words, claims that conflict, and the
    //! invariants checked after every step of random workloads.

    use super::*;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use proptest::prelude::*;
    use std::vec::Vec;

    type Arena<const N: usize> = FrameArena<CriticalSectionRawMutex, N>;

    #[test]
    fn a_frame_grows_back_to_its_block_and_no_further() {
        let arena: Arena<1024> = FrameArena::new();
        let empty = arena.stats();
        let mut a = arena.alloc(13).unwrap();
        let mut b = arena.alloc(8).unwrap();
        b.fill(0xBB);
        a.fill(0xAA);
        a.truncate(5);
        // The whole block (13 rounded up to 16), writable to its last byte.
        assert_eq!(a.set_len_to_capacity(), 16);
        assert_eq!(a.len(), 16);
        assert_eq!(&a[..13], &[0xAA; 13]);
        a[15] = 0x55;
        a.truncate(14);
        assert_eq!(a.len(), 14);
        // The neighbour's bytes are untouched.
        assert_eq!(&b[..], &[0xBB; 8]);
        drop(a);
        b.fill(0);
        drop(b);
        assert_eq!(arena.stats().used, empty.used);
        assert_eq!(arena.stats().live, 0);
    }

    /// `UNITS` is the largest unit count whose units and bitmap words fit in `N`.
    fn check_units<const N: usize>() {
        let u = Arena::<N>::UNITS;
        let size = |u: usize| u * GRANULARITY + u.div_ceil(WORD_UNITS) * WORD_BYTES;
        assert!(size(u) <= N, "N = {N}");
        assert!(size(u + 1) > N, "N = {N}");
        assert_eq!(Arena::<N>::RESERVED, N - u * GRANULARITY);
        assert_eq!(Arena::<N>::WORDS, u.div_ceil(32));
        assert_eq!(
            Arena::<N>::PAD.count_zeros() as usize,
            u - (Arena::<N>::WORDS - 1) * 32
        );
    }

    #[test]
    fn units_and_reserve() {
        check_units::<528>();
        check_units::<1024>();
        check_units::<4095>();
        check_units::<4096>();
        check_units::<16384>();
        check_units::<100_003>();
        assert_eq!(Arena::<16384>::UNITS, 2016);
        assert_eq!(Arena::<4096>::RESERVED, 64);
        assert_eq!(Arena::<16384>::MAX_ALLOC, MAX_ALLOC_LIMIT);
        assert_eq!(Arena::<600>::MAX_ALLOC, Arena::<600>::UNITS * GRANULARITY);
    }

    impl<M: RawMutex, const N: usize> FrameArena<M, N> {
        /// The bits in memory, as a vector of booleans (padding included).
        fn bits(&self) -> Vec<bool> {
            (0..Self::WORDS * WORD_UNITS)
                .map(|u| self.word(u / 32).load(Relaxed) & (1 << (u % 32)) != 0)
                .collect()
        }

        /// Check invariants 1-3 given the live runs `(start, units)`; return the longest
        /// run of free units.
        fn check(&self, live: &[(usize, usize)]) -> usize {
            let mut owner = std::vec![false; Self::WORDS * WORD_UNITS];
            for &(start, units) in live {
                assert!(start + units <= Self::UNITS, "run beyond the units");
                for taken in &mut owner[start..start + units] {
                    assert!(!*taken, "runs overlap at unit {start}");
                    *taken = true;
                }
            }
            assert_eq!(
                self.bits(),
                owner,
                "the bitmap is the union of the live runs"
            );
            let units: usize = live.iter().map(|&(_, u)| u).sum();
            let stats = self.stats();
            assert_eq!(stats.used, Self::RESERVED + units * GRANULARITY);
            assert_eq!(stats.live, live.len());
            assert!(stats.high_water >= stats.used);
            let (mut runs, mut longest, mut run) = (0, 0, 0);
            for taken in &owner[..Self::UNITS] {
                if *taken {
                    run = 0;
                } else {
                    runs += usize::from(run == 0);
                    run += 1;
                    longest = longest.max(run);
                }
            }
            assert_eq!(stats.free_blocks, runs);
            longest
        }
    }

    /// Runs found across word boundaries, of every length a frame can have, from every
    /// offset in a word; the padding beyond the last unit is never found free.
    #[test]
    fn search_spans_words() {
        let arena: Arena<2048> = FrameArena::new(); // 252 units, 8 words
        assert_eq!(Arena::<2048>::UNITS, 252);
        let step = if cfg!(miri) { 13 } else { 1 };
        for units in (1..=128).step_by(step) {
            for start in (0..=Arena::<2048>::UNITS - units).step_by(step) {
                // Everything taken except `start .. start + units`.
                for i in 0..Arena::<2048>::WORDS {
                    arena.word(i).store(u32::MAX, Relaxed);
                }
                arena.clear(start, units);
                assert_eq!(arena.search(units), Some(start), "{units} at {start}");
                assert_eq!(arena.search(units + 1), None, "{units} at {start}");
                assert!(arena.claim(start, units));
                assert!(arena.bits()[..252].iter().all(|b| *b));
            }
        }
        // Units 224..252 free, and the padding clear in memory.
        for i in 0..Arena::<2048>::WORDS - 1 {
            arena.word(i).store(u32::MAX, Relaxed);
        }
        arena.word(7).store(0, Relaxed);
        assert_eq!(arena.search(28), Some(224));
        assert_eq!(arena.search(29), None);
        // The first fit from the word where the last allocation ended, round to it.
        arena.word(0).store(0xFFFF_00FF, Relaxed);
        assert_eq!(arena.search(8), Some(8));
        assert_eq!(arena.search(9), Some(224));
        arena.next.store(230, Relaxed);
        assert_eq!(arena.search(8), Some(224));
        assert_eq!(arena.search(29), None);
        arena.word(7).store(u32::MAX, Relaxed);
        assert_eq!(arena.search(8), Some(8), "round to the start");
        // A run that begins before the starting word and ends after it.
        arena.word(5).store(0x0000_FFFF, Relaxed); // units 176..192 free
        arena.word(6).store(0xFFFF_0000, Relaxed); // units 192..208 free
        arena.next.store(6 * 32, Relaxed);
        assert_eq!(arena.search(20), Some(176));
        arena.next.store(5 * 32, Relaxed);
        assert_eq!(arena.search(32), Some(176));
    }

    /// An allocation goes where the last one ended if it fits there, else to the first
    /// run that fits from there on, round to the start.
    #[test]
    fn next_fit() {
        let arena: Arena<2048> = FrameArena::new();
        let offset = |f: &FrameBuf<'_>| f.offset() / GRANULARITY;
        let a = arena.alloc(24).unwrap();
        let b = arena.alloc(8).unwrap();
        assert_eq!((offset(&a), offset(&b)), (0, 3));
        drop(a);
        let c = arena.alloc(24).unwrap();
        assert_eq!(
            offset(&c),
            4,
            "after the last one, though units 0..3 are free"
        );
        // Units 7..252 taken: the hint (unit 252) is the end of the storage.
        let big = arena.alloc(MAX_ALLOC_LIMIT).unwrap();
        let last = arena.alloc(117 * GRANULARITY).unwrap();
        assert_eq!((offset(&big), offset(&last)), (7, 135));
        drop(c);
        let d = arena.alloc(24).unwrap();
        assert_eq!(
            offset(&d),
            0,
            "the first run of 3 free units, round to the start"
        );
        assert_eq!(arena.alloc(32).unwrap_err(), AllocError::Full { len: 32 });
        drop((b, d, big, last));
    }

    /// A claim that meets a unit another context took first gives back what it took.
    #[test]
    fn a_conflicting_claim_is_given_back() {
        let arena: Arena<2048> = FrameArena::new();
        arena.word(2).store(1 << 5, Relaxed); // unit 69 is taken
        let before = arena.cleared();
        assert!(!arena.claim(20, 50)); // units 20..70 span words 0, 1 and 2
        assert_eq!(arena.bits().iter().filter(|b| **b).count(), 1);
        assert_ne!(
            arena.cleared(),
            before,
            "a rollback makes failed scans repeat"
        );
        assert!(arena.claim(20, 49));
        assert_eq!(arena.bits().iter().filter(|b| **b).count(), 50);
    }

    #[test]
    fn a_run_across_two_words_is_claimed_whole_or_not_at_all() {
        let arena: Arena<2048> = FrameArena::new();
        // Where the last allocation ended: units 28..36 span words 0 and 1.
        arena.next.store(28, Relaxed);
        assert_eq!(arena.take(8), Some(28));
        let set = |arena: &Arena<2048>| -> Vec<usize> {
            let bits = arena.bits();
            (0..bits.len()).filter(|&u| bits[u]).collect()
        };
        assert_eq!(set(&arena), (28..36).collect::<Vec<_>>());
        // The second word's part taken by another context in the meantime.
        arena.word(2).store(1, Relaxed); // unit 64
        let before = arena.cleared();
        assert!(!arena.claim_pair(1, u32::MAX << 30, 1)); // units 62..65
        let mut expected: Vec<usize> = (28..36).collect();
        expected.push(64);
        assert_eq!(set(&arena), expected, "units 62 and 63 given back");
        assert_ne!(
            arena.cleared(),
            before,
            "a rollback makes failed scans repeat"
        );
        // Seen taken before any claim: the search places the frame elsewhere.
        arena.next.store(62, Relaxed);
        let start = arena.take(3).expect("room");
        assert!(start + 3 <= 64 || start > 64, "not over unit 64: {start}");
    }

    #[derive(Clone, Debug)]
    enum Op {
        Alloc(usize),
        Free(usize),
        Truncate(usize, usize),
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            4 => (0usize..=280).prop_map(Op::Alloc),
            1 => (0usize..=1100).prop_map(Op::Alloc),
            4 => any::<usize>().prop_map(Op::Free),
            1 => (any::<usize>(), 0usize..300).prop_map(|(i, n)| Op::Truncate(i, n)),
        ]
    }

    fn config() -> ProptestConfig {
        ProptestConfig {
            cases: if cfg!(miri) { 3 } else { 256 },
            failure_persistence: None,
            ..ProptestConfig::default()
        }
    }

    proptest! {
        #![proptest_config(config())]

        /// After every step: invariants 1-3 hold, and an allocation failed only if no
        /// run of free units was long enough.
        #[test]
        fn invariants_hold_and_failures_are_genuine(
            ops in proptest::collection::vec(op(), 1..if cfg!(miri) { 40 } else { 300 })
        ) {
            let arena = Arena::<2048>::new();
            let mut frames: Vec<FrameBuf<'_>> = Vec::new();
            let runs = |frames: &[FrameBuf<'_>]| -> Vec<(usize, usize)> {
                frames
                    .iter()
                    .map(|f| (f.offset() / GRANULARITY, usize::from(f.units)))
                    .collect()
            };
            arena.check(&[]);
            for op in ops {
                match op {
                    Op::Alloc(len) => {
                        let units = len.div_ceil(GRANULARITY).max(1);
                        let longest = arena.check(&runs(&frames));
                        match arena.alloc(len) {
                            Ok(frame) => {
                                prop_assert!(len <= Arena::<2048>::MAX_ALLOC);
                                prop_assert_eq!(frame.len(), len);
                                prop_assert_eq!(frame.capacity(), units * GRANULARITY);
                                frames.push(frame);
                            }
                            Err(AllocError::TooLarge { max, .. }) => {
                                prop_assert!(len > max);
                            }
                            Err(AllocError::Full { .. }) => {
                                prop_assert!(longest < units);
                            }
                        }
                    }
                    Op::Free(i) => {
                        if !frames.is_empty() {
                            let n = frames.len();
                            drop(frames.swap_remove(i % n));
                        }
                    }
                    Op::Truncate(i, len) => {
                        if !frames.is_empty() {
                            let n = frames.len();
                            let frame = &mut frames[i % n];
                            let before = frame.len();
                            frame.truncate(len);
                            prop_assert_eq!(frame.len(), len.min(before));
                        }
                    }
                }
                arena.check(&runs(&frames));
            }
            drop(frames);
            prop_assert_eq!(arena.check(&[]), Arena::<2048>::UNITS);
            prop_assert_eq!(arena.stats().used, Arena::<2048>::RESERVED);
        }
    }
}
