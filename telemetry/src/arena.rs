//! The frame arena: one shared byte arena for the pending frames of all devices (the
//! *Dynamic Memory Space* of Jornet's design), with bounded, constant-time allocation and
//! release.
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
//! A purpose-built TLSF (two-level segregated fit, Masmano et al. 2004), chosen over
//! wrapping the `rlsf` crate after measuring both on the same workload (see
//! `tests/arena.rs`, `fill_at_first_failure`):
//!
//! * **No per-frame header.** A live frame's block is described by its [`FrameBuf`]
//!   (start and size), so a frame costs only its length rounded up to
//!   [`GRANULARITY`] (8 bytes). Free blocks carry their own header and footer, and one
//!   *boundary bit* per 8-byte unit marks the first and last unit of every free block;
//!   that bitmap is the only fixed overhead ([`FrameArena::RESERVED`], 1/65 of `N`).
//!   `rlsf` puts a 2-word header in front of every block and rounds blocks to 4 words:
//!   8 + up to 15 bytes per frame on a 32-bit MCU, 16 + up to 31 bytes on a 64-bit host.
//! * **Exact size classes for frames.** With 16 second-level classes per power of two,
//!   every size up to 32 units (256 bytes; a PPRZ frame's length field is one byte) has a
//!   class of its own, so the good-fit search is a best fit: it finds the smallest free
//!   block that is large enough, and fails only when none is.
//! * **Same layout on every target.** Offsets and sizes are `u16` counts of 8-byte units,
//!   so the host tests, Miri and the MCU exercise the very same block layout.
//! * **Fully zero-initialised**, so a `static` arena lives in `.bss` and costs no flash.
//!   Besides the `N` bytes, the free-list heads, bitmaps and counters take about 480 bytes
//!   on a 32-bit target, whatever `N`.
//!
//! Fill level at the first allocation failure, with random frame sizes 8..=255 bytes in
//! steady state (release a random frame, allocate until an allocation fails, record the
//! fill level; 20 000 rounds, fixed seed; `cargo test -p pprz-telemetry --test arena fill
//! -- --nocapture` prints it). *Used* counts rounding and `RESERVED`, *payload* only the
//! requested bytes; both are fractions of `N`:
//!
//! | `N`    | used, mean (worst round) | payload, mean | `rlsf` 0.2 payload, 32-bit / 64-bit |
//! |--------|--------------------------|---------------|-------------------------------------|
//! | 4 KiB  | 87.9 % (67.6 %)          | 82.7 %        | 73.8 % / 65.1 %                     |
//! | 16 KiB | 92.8 % (84.3 %)          | 87.3 %        | 78.8 % / 67.8 %                     |
//! | 64 KiB | 96.1 % (93.0 %)          | 90.7 %        | 85.8 % / 70.6 %                     |
//!
//! (`rlsf`: `Tlsf<u16, u16, 12, 16>` over the same workload and seed, outside this
//! repository; 32-bit figures run under Miri for `i686`, 2 000 rounds.) Smaller arenas fill
//! less at the first failure mostly because a 255-byte request is a larger share of them.
//!
//! # Cache
//!
//! A telemetry stream allocates and releases frames of the same few sizes over and over.
//! While the arena is at most three quarters full, a released block of up to 32 units
//! (256 bytes) is kept whole, at most 16 of them, on a list per exact size; the next
//! allocation of that many units takes it without searching, splitting or merging. When
//! neither the cache nor the free lists have a block for a request, the cached blocks go
//! back to the free lists one at a time (each merges with its free neighbours) and the
//! free lists are tried again after each: an allocation fails only once the cache is
//! empty and no free block fits, as without the cache. [`ArenaStats::cached`] counts the
//! cached blocks; they count as free in [`ArenaStats::used`].
//!
//! # Layout
//!
//! ```text
//!  unit 0                                                       UNITS-1
//!  |                                                                  |
//!  +---------+--------------------+---------+--------------------------+--------------+
//!  | frame A | free block         | frame B | free block               | boundary     |
//!  | (owned  | size next prev ... | (owned  | size next prev ...  foot | bitmap, pad  |
//!  | by its  |               foot | by its  |                          | (RESERVED    |
//!  | FrameBuf)                    | FrameBuf)                          |  bytes)      |
//!  +---------+--------------------+---------+--------------------------+--------------+
//!            ^1                 1^          ^1                       1^    boundary bits
//! ```
//!
//! A free block of `s` units starting at unit `b` stores, little-endian `u16`s: its size
//! `s` at byte 0, the next and previous block of its free list at bytes 2 and 4 (unit
//! index + 1, 0 = none), and `s` again at bytes 6..8 of its last unit (the footer). A
//! one-unit free block holds all four fields. The allocator never reads or writes the
//! bytes of a block owned by a `FrameBuf`.
//!
//! Free lists are indexed by size class `(fl, sl)`: sizes below 16 units have class
//! `(0, s)`; a size `s` with `2^f <= s < 2^(f+1)`, `f >= 4`, has class
//! `(f - 3, (s >> (f - 4)) - 16)`. A first-level bitmap and one second-level bitmap per
//! first level say which lists are non-empty.
//!
//! # Time Complexity
//!
//! [`FrameArena::alloc`] and releasing a [`FrameBuf`] run in bounded time whatever the
//! fill level and fragmentation: a few bit scans (`trailing_zeros`), unlinking at most
//! three free blocks and linking one, or taking or putting one cached block. Nothing
//! loops over blocks, lists or units, except that an allocation that finds no block
//! returns the cached blocks first: at most 16 steps of that kind, plus one for each
//! block another context caches while it runs. The lock is held for one step at a time.
//!
//! # Concurrency and `unsafe`
//!
//! The allocator metadata (lists, bitmaps, counters) is only touched with the
//! [`Mutex<M, _>`](Mutex) held; on a board `M` is a critical section. The bytes of a live
//! frame are read and written without the lock, through its `FrameBuf`: this module is
//! allowed `unsafe` code for exactly that, disjoint `&mut [u8]` views into one
//! [`UnsafeCell`] buffer, and for the allocator's raw reads and writes of free blocks'
//! headers. The invariants that make it sound are written on [`FrameArena`]; property
//! tests check them after every step and the tests run under Miri. Release builds trust
//! the invariants for the allocator's metadata accesses (no bounds check per access, as
//! in `rlsf`); debug builds, and so the tests and Miri, assert every access in bounds.

// The crate denies `unsafe_code`; this module needs it to hand out disjoint mutable views
// of one shared buffer (see "Concurrency and `unsafe`" above). Every block is justified.
#![allow(unsafe_code)]

use core::cell::UnsafeCell;
use core::fmt;
use core::ops::{Deref, DerefMut};
use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;

/// Allocation granularity in bytes: every frame occupies a multiple of this.
pub const GRANULARITY: usize = 8;

/// Largest allocation of any arena, in bytes; an arena smaller than this has a smaller
/// [`FrameArena::MAX_ALLOC`].
pub const MAX_ALLOC_LIMIT: usize = 1024;

/// Smallest usable size of an arena in bytes, checked at compile time.
pub const MIN_USABLE: usize = 512;

/// log2 of the number of second-level classes per power of two.
const SLI: u32 = 4;
/// Number of second-level classes per first level.
const SL: usize = 1 << SLI;
/// Number of first levels: sizes are below 2^16 units, so `fl = f - SLI + 1 <= 12`.
const FL: usize = 16 - SLI as usize + 1;
/// Largest number of units an arena may have (so that `unit + 1` fits a `u16` link).
const MAX_UNITS: usize = u16::MAX as usize - 1;
/// Released blocks of up to this many units (256 bytes: every PPRZ frame) may be cached
/// whole for the next allocation of their exact size.
const CACHE_SIZES: usize = 32;
/// Largest number of cached blocks.
const CACHE_BLOCKS: u16 = 16;

/// Byte offsets of the fields of a free block (relative to its first or last unit).
mod field {
    /// Size in units, at the start of the first unit.
    pub const SIZE: usize = 0;
    /// Next block in the free list (unit + 1, 0 = none), first unit.
    pub const NEXT: usize = 2;
    /// Previous block in the free list (unit + 1, 0 = none), first unit.
    pub const PREV: usize = 4;
    /// Size in units again, at the end of the last unit.
    pub const FOOT: usize = 6;
}

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
    /// No free block is large enough right now; one will be after frames are released.
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
    /// Number of free blocks; with `used`, a measure of fragmentation. Cached blocks are
    /// not counted here but in `cached`.
    pub free_blocks: usize,
    /// Released blocks kept whole for the next allocation of their size (at most 16,
    /// see [the cache](self#cache)). They count as free in `used`.
    pub cached: usize,
    /// Successful allocations (wrapping).
    pub allocs: u32,
    /// Releases (wrapping); `allocs.wrapping_sub(frees) == live`.
    pub frees: u32,
    /// Allocations that failed with [`AllocError::Full`] or [`AllocError::TooLarge`]
    /// (wrapping).
    pub failures: u32,
}

/// One shared arena of `N` bytes for the pending frames of all devices.
///
/// `M` is the blocking mutex that protects the allocator metadata: a
/// `CriticalSectionRawMutex` when frames are allocated or released from several executors
/// or interrupts, a `ThreadModeRawMutex` for one thread-mode executor. It must be `Sync`
/// ([`new`](Self::new) requires it), because the frames [`alloc`] returns are `Send` and
/// release their memory wherever they are dropped:
///
/// ```compile_fail
/// use embassy_sync::blocking_mutex::raw::NoopRawMutex;
/// use pprz_telemetry::arena::FrameArena;
/// let arena = FrameArena::<NoopRawMutex, 1024>::new(); // error: `NoopRawMutex` is not `Sync`
/// ```
///
/// `N` is checked at compile time: the usable part must be at least [`MIN_USABLE`] bytes
/// and at most 65 534 units of [`GRANULARITY`] bytes (about 512 KiB).
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
/// 1. Units `0..UNITS` are partitioned into consecutive blocks. Each is either *free*, in
///    exactly one free list (that of its size class), *cached*, in exactly one cache list
///    (that of its size in units, at most 32), or *owned* by exactly one live
///    [`FrameBuf`] that records its start and size.
/// 2. No two free blocks are adjacent (coalescing), so there are at most
///    `live + cached + 1` free blocks.
/// 3. The boundary bit of a unit is set iff the unit is the first or the last unit of a
///    free block.
/// 4. A free block's header and footer hold its size and list links; a cached block's
///    `NEXT` field links its cache list. The allocator reads and writes only these fields
///    of free and cached blocks and the boundary bitmap, and only with the lock held; the
///    bytes of an owned block are accessed only through its `FrameBuf`.
/// 5. Second-level bit `(fl, sl)` is set iff list `(fl, sl)` is non-empty; first-level bit
///    `fl` is set iff any of its second-level bits is.
/// 6. Every byte of the storage is initialised (zero at creation, then only ever written
///    with initialised values), so a new frame's bytes may hold an older frame's data but
///    are never uninitialised.
///
/// [`alloc`]: Self::alloc
pub struct FrameArena<M: RawMutex, const N: usize> {
    /// Allocator metadata; see the invariants above.
    state: Mutex<M, State>,
    /// Frame units, then the boundary bitmap, then padding.
    storage: UnsafeCell<[u8; N]>,
    /// A copy of the cache's size bits, written with the lock held and read without it:
    /// an allocation takes the lock for the cache only when its size's bit is set.
    cached_sizes: AtomicU32,
}

// Safety: `FrameArena` is `!Sync` only because of `storage`. Concurrent access to it is
// coordinated: the allocator touches free blocks and the bitmap only with the mutex held
// (`M: Sync` makes the mutex a real lock between threads), and the bytes of a live frame
// are reachable only through the one `FrameBuf` that owns the block (invariants 1 and 4).
// Lock release/acquire orders a frame's last use before the reuse of its bytes.
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
            state: Mutex::new(State::EMPTY),
            storage: UnsafeCell::new([0; N]),
            cached_sizes: AtomicU32::new(0),
        }
    }
}

impl<M: RawMutex, const N: usize> FrameArena<M, N> {
    /// Number of units available to frames: the largest `u` with
    /// `u * GRANULARITY + ceil(u / 8) <= N` (one boundary bit per unit).
    const UNITS: usize = {
        let mut u = N * 8 / (8 * GRANULARITY + 1);
        while u * GRANULARITY + u.div_ceil(8) > N {
            u -= 1;
        }
        u
    };

    /// Bytes of the storage not available to frames: the boundary bitmap (one bit per
    /// [`GRANULARITY`] bytes) and padding. `stats().used` starts at this value.
    pub const RESERVED: usize = N - Self::UNITS * GRANULARITY;

    /// Largest allocation in bytes: [`MAX_ALLOC_LIMIT`], or the usable size of a smaller
    /// arena. Always at least [`MIN_USABLE`].
    pub const MAX_ALLOC: usize = if Self::UNITS * GRANULARITY < MAX_ALLOC_LIMIT {
        Self::UNITS * GRANULARITY
    } else {
        MAX_ALLOC_LIMIT
    };

    /// Fill level (`used`, bytes) up to which released frame blocks are cached.
    const CACHE_FILL: usize = N / 4 * 3;

    /// Compile-time check of `N`, forced by [`new`](Self::new).
    const VALID: () = {
        assert!(
            Self::UNITS * GRANULARITY >= MIN_USABLE,
            "FrameArena: N is too small (the usable part must be at least MIN_USABLE bytes)"
        );
        assert!(
            Self::UNITS <= MAX_UNITS,
            "FrameArena: N is too large (at most 65534 units of GRANULARITY bytes)"
        );
    };

    /// A snapshot of the fill level and counters.
    ///
    /// # Time Complexity
    ///
    /// Constant; takes the lock briefly.
    pub fn stats(&self) -> ArenaStats {
        self.with_heap(|st, _| ArenaStats {
            capacity: N,
            used: st.used,
            live: st.live(),
            high_water: st.high_water,
            free_blocks: st.free_blocks,
            cached: usize::from(st.cached),
            allocs: st.allocs,
            frees: st.frees,
            failures: st.failures,
        })
    }

    /// Restart the high-water mark from the current fill level.
    pub fn reset_high_water(&self) {
        self.with_heap(|st, _| st.high_water = st.used);
    }

    /// Run `f` on the metadata with the lock held, setting the arena up on first use.
    fn with_heap<R>(&self, f: impl FnOnce(&mut State, Mem) -> R) -> R {
        let mem = Mem {
            base: self.storage.get().cast::<u8>(),
            units: Self::UNITS,
        };
        // Safety: `lock_mut` is sound unless called re-entrantly; this is the only place
        // that locks `state`, and `f` is one of this module's closures, none of which
        // calls back into the arena (they only touch `State` and `Mem`).
        unsafe {
            self.state.lock_mut(|st| {
                if !st.ready {
                    st.set_up(mem, Self::RESERVED);
                }
                let result = f(st, mem);
                self.cached_sizes.store(st.cache_bits, Relaxed);
                result
            })
        }
    }
    /// Allocate a frame of `len` bytes (`0..=MAX_ALLOC`). Its bytes are initialised but
    /// unspecified (an older frame's data); [`FrameBuf::truncate`] it to the length
    /// actually encoded. Dropping it releases the memory.
    ///
    /// The block is `len` rounded up to [`GRANULARITY`] (at least one unit). For
    /// `len <= 256` this fails with [`AllocError::Full`] only if no free block is large
    /// enough once the cached blocks are back in the free lists; above, only if none is
    /// large enough by a margin of at most `len / 16`, unless the first block of the
    /// request's own size class fits.
    ///
    /// # Errors
    ///
    /// [`AllocError::TooLarge`] if `len > MAX_ALLOC`, [`AllocError::Full`] if no free
    /// block fits. Both count as failures in [`stats`](Self::stats).
    ///
    /// # Time Complexity
    ///
    /// Bounded, whatever the fill level: one short section under the lock for a cached
    /// block, one for the free lists, and when neither has a block, at most 16 more (one
    /// cached block returned to the free lists and the free lists tried again in each),
    /// plus one for each block another context caches meanwhile.
    ///
    /// # Panics
    ///
    /// Never, unless the allocator's invariants were broken (a bug in this module): debug
    /// builds then panic on the first metadata access out of the arena's bounds (see
    /// `Mem`); release builds do not check, to keep an allocation to a few dozen
    /// instructions.
    pub fn alloc(&self, len: usize) -> Result<FrameBuf<'_>, AllocError> {
        if len > Self::MAX_ALLOC {
            self.with_heap(|st, _| st.failures = st.failures.wrapping_add(1));
            return Err(AllocError::TooLarge {
                len,
                max: Self::MAX_ALLOC,
            });
        }
        let units = len.div_ceil(GRANULARITY).max(1);
        // A cached block of the size (a short section of its own, so that a hit does not
        // pay for the free lists' size class), else the free lists. When neither has a
        // block, the cached blocks go back to the free lists one per lock (each may merge
        // with its neighbours) and the free lists are tried again: the lock is never held
        // for more than one release and one allocation.
        let mut start = None;
        // The bit may be stale (another context cached or took a block since): the lock
        // is then taken for nothing, or a cached block is left for the next allocation.
        if units <= CACHE_SIZES && self.cached_sizes.load(Relaxed) & (1 << (units - 1)) != 0 {
            start = self.with_heap(|st, mem| {
                let start = st.take_cached(mem, units);
                if start.is_some() {
                    st.allocated(units);
                }
                start
            });
        }
        if start.is_none() {
            start = loop {
                let step = self.with_heap(|st, mem| {
                    let start = st.alloc(mem, units);
                    if start.is_some() {
                        st.allocated(units);
                    } else if st.uncache_one(mem) {
                        return None;
                    } else {
                        st.failures = st.failures.wrapping_add(1);
                    }
                    Some(start)
                });
                if let Some(start) = step {
                    break start;
                }
            };
        }
        match start {
            // The casts are lossless: `start + units <= UNITS <= MAX_UNITS` and
            // `len <= MAX_ALLOC_LIMIT`.
            Some(start) => Ok(FrameBuf {
                arena: self,
                // In bounds: `start < UNITS`, so the block's first byte is in the storage.
                ptr: self.base().wrapping_add(start * GRANULARITY),
                units: units as u16,
                len: len as u16,
            }),
            None => Err(AllocError::Full { len }),
        }
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

    /// Return the block of `units` units whose first byte is `ptr` to the free lists.
    ///
    /// # Safety
    ///
    /// * `ptr` and `units` describe a block allocated by this arena and not yet released.
    /// * No reference into its bytes is used afterwards.
    unsafe fn release(&self, ptr: *mut u8, units: usize);
}

impl<M: RawMutex, const N: usize> Grants for FrameArena<M, N> {
    fn base(&self) -> *mut u8 {
        self.storage.get().cast::<u8>()
    }

    unsafe fn release(&self, ptr: *mut u8, units: usize) {
        // The block's first unit (the caller guarantees `ptr` is one of ours).
        let start = (ptr.addr() - self.base().addr()) / GRANULARITY;
        self.with_heap(|st, mem| {
            st.frees = st.frees.wrapping_add(1);
            st.used -= units * GRANULARITY;
            // Above three quarters full, blocks go straight back to the free lists: there
            // a cached block would soon have to be returned by a failing allocation.
            if st.used > Self::CACHE_FILL || !st.cache(mem, start, units) {
                st.free(mem, start, units);
            }
        });
    }
}

/// An exclusively owned, contiguous region of a [`FrameArena`]: a pending frame.
///
/// Created by [`FrameArena::alloc`].
///
/// Dereferences to its first [`len`](Self::len) bytes. Dropping it releases the memory
/// (in constant time, taking the arena's lock briefly). It is `Send` and `Sync`, so it can
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
// may be used from another thread (to release the block, under the lock), and the block's
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
    /// (possibly an older frame's bytes; never uninitialised, invariant 6).
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
        // (invariant 1): the allocator does not touch it (invariant 4) and no other
        // `FrameBuf` covers it, so the only references to these bytes come from this
        // `FrameBuf`, and `&self` keeps `deref_mut` out. The bytes are initialised
        // (invariant 6).
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

/// Raw access to the storage for the allocator, valid while the lock is held.
///
/// Every unit index the allocator passes is below `units`: it is a block start or end
/// taken from a [`FrameBuf`], a free-list link, a boundary bit or a free block's size
/// (invariants 1-4). Debug builds (the tests, Miri) assert it on every access; release
/// builds rely on the invariants, as `rlsf` does, so that an operation costs a few dozen
/// instructions rather than twice that in checks.
#[derive(Clone, Copy)]
struct Mem {
    /// Start of the storage (`N` bytes).
    base: *mut u8,
    /// Number of frame units; the boundary bitmap follows them.
    units: usize,
}

impl Mem {
    /// Pointer to byte `field` of unit `unit`.
    #[inline(always)]
    fn at(self, unit: usize, field: usize) -> *mut u8 {
        debug_assert!(unit < self.units, "arena: unit out of range");
        // `unit < units` and `field <= 6`, so this stays inside the storage's
        // `units * GRANULARITY` frame bytes.
        self.base.wrapping_add(unit * GRANULARITY + field)
    }

    /// Read the `u16` field at `field` of unit `unit` of a free block.
    #[inline(always)]
    fn get(self, unit: usize, field: usize) -> usize {
        // Safety: `at + 2 <= units * GRANULARITY <= N`, in bounds of the storage (see
        // `Mem`). The unit is the first or last unit of a free block (callers follow
        // free-list links, boundary bits and footers, invariants 1-4), which no
        // `FrameBuf` covers, and the lock is held, so nothing writes it concurrently.
        // `[u8; 2]` has alignment 1.
        let bytes = unsafe { self.at(unit, field).cast::<[u8; 2]>().read() };
        usize::from(u16::from_le_bytes(bytes))
    }

    /// Write the `u16` field at `field` of unit `unit` of a free block.
    #[inline(always)]
    fn set(self, unit: usize, field: usize, value: usize) {
        // Values are unit counts or links, at most `MAX_UNITS + 1`.
        let bytes = (value as u16).to_le_bytes();
        // Safety: as in `get`; the unit belongs to a free block or to a block being freed
        // or split off, which no `FrameBuf` covers.
        unsafe { self.at(unit, field).cast::<[u8; 2]>().write(bytes) };
    }

    /// Pointer to the bitmap byte holding the boundary bit of `unit`, and its mask.
    #[inline(always)]
    fn bit(self, unit: usize) -> (*mut u8, u8) {
        debug_assert!(unit < self.units, "arena: unit out of range");
        // The bitmap's `ceil(units / 8)` bytes follow the frame units inside the storage.
        let at = self.units * GRANULARITY + unit / 8;
        (self.base.wrapping_add(at), 1 << (unit % 8))
    }

    /// The boundary bit of `unit` (invariant 3).
    #[inline(always)]
    fn boundary(self, unit: usize) -> bool {
        let (byte, mask) = self.bit(unit);
        // Safety: `byte` is in bounds (`units * GRANULARITY + ceil(units / 8) <= N`); the
        // bitmap is only accessed by the allocator, with the lock held.
        unsafe { byte.read() & mask != 0 }
    }

    /// Set the boundary bit of `unit`.
    #[inline(always)]
    fn mark(self, unit: usize) {
        let (byte, mask) = self.bit(unit);
        // Safety: as in `boundary`.
        unsafe { byte.write(byte.read() | mask) };
    }

    /// Clear the boundary bit of `unit`.
    #[inline(always)]
    fn unmark(self, unit: usize) {
        let (byte, mask) = self.bit(unit);
        // Safety: as in `boundary`.
        unsafe { byte.write(byte.read() & !mask) };
    }
}

/// The block a free-list link points to (links are unit + 1, 0 = none).
#[inline(always)]
fn unlink(link: usize) -> Option<usize> {
    link.checked_sub(1)
}

/// Size class `(fl, sl)` of a size in units (`1..=MAX_UNITS`).
#[inline(always)]
fn class(size: usize) -> (usize, usize) {
    if size < SL {
        (0, size)
    } else {
        let f = size.ilog2();
        ((f - SLI + 1) as usize, (size >> (f - SLI)) - SL)
    }
}

/// The class of [`round_up`]`(size)`, with one bit scan: the smallest class whose every
/// block is at least `size` units.
#[inline(always)]
fn class_up(size: usize) -> (usize, usize) {
    if size < SL {
        (0, size)
    } else {
        let shift = size.ilog2() - SLI;
        // `top` is in `SL..=2 * SL`; `2 * SL` is the first class of the next first level.
        let top = (size + (1 << shift) - 1) >> shift;
        let flat = ((shift as usize + 1) << SLI) + top - SL;
        (flat >> SLI, flat & (SL - 1))
    }
}

/// `size` rounded up to the smallest size of its class or the next one, so that every
/// block of that class or above is at least `size`.
#[cfg(test)]
fn round_up(size: usize) -> usize {
    if size < SL {
        size
    } else {
        let step = 1 << (size.ilog2() - SLI);
        (size + step - 1) & !(step - 1)
    }
}

/// Allocator metadata and counters. All zeros is a valid "not yet set up" state.
struct State {
    /// Whether the initial free block has been inserted.
    ready: bool,
    /// Bit `fl` set iff `sl_bitmap[fl] != 0` (invariant 5).
    fl_bitmap: u16,
    /// Bit `sl` of `sl_bitmap[fl]` set iff `heads[fl][sl]` is not none (invariant 5).
    sl_bitmap: [u16; FL],
    /// First block of each free list, as a link.
    heads: [[u16; SL]; FL],
    /// First cached block of each size `1..=CACHE_SIZES` units (index `size - 1`), as a
    /// link; the next one is in the block's `NEXT` field.
    cache: [u16; CACHE_SIZES],
    /// Bit `size - 1` set iff `cache[size - 1]` is not none.
    cache_bits: u32,
    /// Cached blocks, at most `CACHE_BLOCKS`.
    cached: u16,
    /// See [`ArenaStats`]; `live` is `allocs - frees`.
    used: usize,
    high_water: usize,
    free_blocks: usize,
    allocs: u32,
    frees: u32,
    failures: u32,
}

impl State {
    /// The state of a new arena.
    const EMPTY: Self = Self {
        ready: false,
        fl_bitmap: 0,
        sl_bitmap: [0; FL],
        heads: [[0; SL]; FL],
        cache: [0; CACHE_SIZES],
        cache_bits: 0,
        cached: 0,
        used: 0,
        high_water: 0,
        free_blocks: 0,
        allocs: 0,
        frees: 0,
        failures: 0,
    };

    /// Live frames.
    fn live(&self) -> usize {
        // Exact: at most `MAX_UNITS` frames are live, far below 2^32.
        self.allocs.wrapping_sub(self.frees) as usize
    }

    /// Write the header and footer of the free block `block..block + size` and put it at
    /// the head of its free list. Its boundary bits are the caller's business, and so is
    /// `free_blocks`.
    #[inline(always)]
    fn push(&mut self, mem: Mem, block: usize, size: usize) {
        let (fl, sl) = class(size);
        let head = usize::from(self.heads[fl][sl]);
        mem.set(block, field::SIZE, size);
        mem.set(block, field::NEXT, head);
        mem.set(block, field::PREV, 0);
        mem.set(block + size - 1, field::FOOT, size);
        if let Some(head) = unlink(head) {
            mem.set(head, field::PREV, block + 1);
        }
        self.heads[fl][sl] = (block + 1) as u16;
        self.sl_bitmap[fl] |= 1 << sl;
        self.fl_bitmap |= 1 << fl;
    }

    /// Take the free block `block` of `size` units out of its list (anywhere in it).
    #[inline(always)]
    fn remove(&mut self, mem: Mem, block: usize, size: usize) {
        let next = mem.get(block, field::NEXT);
        let prev = mem.get(block, field::PREV);
        if let Some(next) = unlink(next) {
            mem.set(next, field::PREV, prev);
        }
        match unlink(prev) {
            Some(prev) => mem.set(prev, field::NEXT, next),
            None => {
                let (fl, sl) = class(size);
                self.heads[fl][sl] = next as u16;
                if next == 0 {
                    self.emptied(fl, sl);
                }
            }
        }
    }

    /// List `(fl, sl)` became empty: clear its bits (invariant 5).
    #[inline(always)]
    fn emptied(&mut self, fl: usize, sl: usize) {
        self.sl_bitmap[fl] &= !(1 << sl);
        if self.sl_bitmap[fl] == 0 {
            self.fl_bitmap &= !(1 << fl);
        }
    }

    /// The smallest non-empty class `(fl, sl)` or above.
    #[inline(always)]
    fn find(&self, (fl, sl): (usize, usize)) -> Option<(usize, usize)> {
        let here = self.sl_bitmap[fl] & (u16::MAX << sl);
        if here != 0 {
            return Some((fl, here.trailing_zeros() as usize));
        }
        // `fl < FL <= 15`: the shift does not overflow.
        let above = self.fl_bitmap & (u16::MAX << (fl + 1));
        if above == 0 {
            return None;
        }
        let fl = above.trailing_zeros() as usize;
        Some((fl, self.sl_bitmap[fl].trailing_zeros() as usize))
    }

    /// Set up a new arena: all `mem.units` units form one free block.
    #[cold]
    #[inline(never)]
    fn set_up(&mut self, mem: Mem, reserved: usize) {
        self.ready = true;
        self.used = reserved;
        self.high_water = reserved;
        mem.mark(0);
        mem.mark(mem.units - 1);
        self.push(mem, 0, mem.units);
        self.free_blocks = 1;
    }

    /// Allocate `units` (`1..=MAX_UNITS`) and return the first unit.
    #[inline(always)]
    fn alloc(&mut self, mem: Mem, units: usize) -> Option<usize> {
        // Good fit: the first block of any list of the rounded-up class or above fits.
        // Failing that, the first block of the request's own class may (only for sizes of
        // 32 units and more, whose classes span several sizes).
        let (fl, sl) = match self.find(class_up(units)) {
            Some(found) => found,
            None => {
                let (fl, sl) = class(units);
                let head = unlink(usize::from(self.heads[fl][sl]))?;
                if mem.get(head, field::SIZE) < units {
                    return None;
                }
                (fl, sl)
            }
        };
        // Take the head of list `(fl, sl)`, which is not empty (invariant 5).
        let block = usize::from(self.heads[fl][sl]).wrapping_sub(1);
        let size = mem.get(block, field::SIZE);
        let next = mem.get(block, field::NEXT);
        self.pop(mem, fl, sl, next);
        // Unit `block` is no longer the first unit of a free block (invariant 3).
        mem.unmark(block);
        if size > units {
            // The rest stays free: its last unit keeps its bit, its first unit gets one.
            // Its neighbours are this block (now allocated) and a used block, so it is
            // not adjacent to a free block (invariant 2).
            let rest = block + units;
            mem.mark(rest);
            self.push(mem, rest, size - units);
        } else {
            mem.unmark(block + size - 1);
            self.free_blocks -= 1;
        }
        Some(block)
    }

    /// Count an allocation of `units`.
    #[inline(always)]
    fn allocated(&mut self, units: usize) {
        self.allocs = self.allocs.wrapping_add(1);
        self.used += units * GRANULARITY;
        self.high_water = self.high_water.max(self.used);
    }

    /// Take a cached block of exactly `units` units, if there is one.
    #[inline(always)]
    fn take_cached(&mut self, mem: Mem, units: usize) -> Option<usize> {
        let i = units.wrapping_sub(1);
        let block = unlink(usize::from(*self.cache.get(i)?))?;
        let next = mem.get(block, field::NEXT);
        self.cache[i] = next as u16;
        if next == 0 {
            self.cache_bits &= !(1 << i);
        }
        self.cached -= 1;
        Some(block)
    }

    /// Keep the released block `block..block + units` whole for the next allocation of
    /// its size, if it is small enough and the cache has room; otherwise `false`.
    #[inline(always)]
    fn cache(&mut self, mem: Mem, block: usize, units: usize) -> bool {
        let i = units.wrapping_sub(1);
        if i >= CACHE_SIZES || self.cached >= CACHE_BLOCKS {
            return false;
        }
        // Its first unit is not a free block's, so the field is the allocator's to use.
        mem.set(block, field::NEXT, usize::from(self.cache[i]));
        self.cache[i] = (block + 1) as u16;
        self.cache_bits |= 1 << i;
        self.cached += 1;
        true
    }

    /// Return the largest cached block to the free lists (merging it with its free
    /// neighbours); `false` if the cache is empty.
    #[inline(never)]
    fn uncache_one(&mut self, mem: Mem) -> bool {
        if self.cache_bits == 0 {
            return false;
        }
        let units = (u32::BITS - self.cache_bits.leading_zeros()) as usize;
        match self.take_cached(mem, units) {
            Some(block) => {
                self.free(mem, block, units);
                true
            }
            None => false,
        }
    }

    /// Remove the head of list `(fl, sl)`, whose successor is `next` (a link).
    #[inline(always)]
    fn pop(&mut self, mem: Mem, fl: usize, sl: usize, next: usize) {
        self.heads[fl][sl] = next as u16;
        match unlink(next) {
            Some(next) => mem.set(next, field::PREV, 0),
            None => self.emptied(fl, sl),
        }
    }

    /// Release the allocated block `block..block + units`, merging it with free neighbours.
    // One copy, for the release of an uncached block and for the cache's return of one.
    #[inline(never)]
    fn free(&mut self, mem: Mem, block: usize, units: usize) {
        let (mut start, mut size) = (block, units);
        let end = block + units;
        let mut blocks = self.free_blocks + 1;
        if end < mem.units && mem.boundary(end) {
            // `end` starts the next block; its bit is set iff that block is free. Its
            // last unit becomes the merged block's last; its first unit (if another) is
            // now inside the merged block.
            let next_size = mem.get(end, field::SIZE);
            self.remove(mem, end, next_size);
            if next_size > 1 {
                mem.unmark(end);
            }
            size += next_size;
            blocks -= 1;
        } else {
            mem.mark(end - 1);
        }
        if block > 0 && mem.boundary(block - 1) {
            // `block - 1` ends the previous block; its bit is set iff that block is free.
            let prev_size = mem.get(block - 1, field::FOOT);
            start = block - prev_size;
            self.remove(mem, start, prev_size);
            if prev_size > 1 {
                mem.unmark(block - 1);
            }
            size += prev_size;
            blocks -= 1;
        } else {
            mem.mark(block);
        }
        self.push(mem, start, size);
        self.free_blocks = blocks;
    }
}

#[cfg(test)]
mod tests {
    //! White-box tests: size classes, and the invariants checked after every step of
    //! random workloads against a shadow model.

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

    #[test]
    fn classes_are_exact_up_to_32_units_and_monotonic() {
        let mut last = (0, 0);
        // Under Miri, every frame size, then a sample of the larger sizes.
        let step = if cfg!(miri) { 97 } else { 1 };
        let sizes = (1..=300).chain((301..=MAX_UNITS).step_by(step));
        for size in sizes.chain([MAX_UNITS]) {
            let c = class(size);
            assert!(c >= last, "classes must grow with the size");
            assert!(c.0 < FL && c.1 < SL);
            let r = round_up(size);
            assert!(
                r >= size && (r - size) * 16 <= size,
                "round_up({size}) = {r}"
            );
            if size <= 32 {
                assert_eq!(r, size, "frame sizes have exact classes");
            }
            // `r` is the smallest size of its class, and that class is not below the
            // class of `size`: every block of class `class(r)` or above holds `size`.
            assert!(class(r) >= c);
            assert_eq!(class_up(size), class(r), "class_up({size})");
            assert!(r == 1 || class(r - 1) < class(r), "round_up({size}) = {r}");
            last = c;
        }
        assert_eq!(class(MAX_UNITS).0, FL - 1);
    }

    /// `UNITS` is the largest unit count whose units and boundary bits fit in `N`.
    fn check_units<const N: usize>() {
        let u = Arena::<N>::UNITS;
        assert!(u * GRANULARITY + u.div_ceil(8) <= N, "N = {N}");
        assert!((u + 1) * GRANULARITY + (u + 1).div_ceil(8) > N, "N = {N}");
        assert_eq!(Arena::<N>::RESERVED, N - u * GRANULARITY);
    }

    #[test]
    fn units_and_reserve() {
        check_units::<528>();
        check_units::<1024>();
        check_units::<4095>();
        check_units::<16384>();
        check_units::<100_003>();
        check_units::<532_471>();
        assert_eq!(Arena::<16384>::UNITS, 2016);
        assert_eq!(Arena::<16384>::MAX_ALLOC, MAX_ALLOC_LIMIT);
        assert_eq!(Arena::<600>::MAX_ALLOC, Arena::<600>::UNITS * GRANULARITY);
        assert_eq!(Arena::<532_471>::UNITS, MAX_UNITS);
        assert_eq!(Arena::<532_472>::UNITS, MAX_UNITS + 1);
    }

    impl<M: RawMutex, const N: usize> FrameArena<M, N> {
        /// Check invariants 1-5 given the live blocks `(start, units)`; return the size of
        /// the largest free block.
        fn check(&self, live: &[(usize, usize)]) -> usize {
            #[derive(Clone, Copy, PartialEq, Debug)]
            enum Owner {
                Frame(usize),
                Free(usize),
                Cached(usize),
            }
            self.with_heap(|st, mem| {
                let mut owner = std::vec![None::<Owner>; mem.units];
                let mut mark = |start: usize, size: usize, tag: Owner| {
                    for slot in &mut owner[start..start + size] {
                        assert_eq!(*slot, None, "blocks overlap at unit {start}");
                        *slot = Some(tag);
                    }
                };
                for (i, &(start, units)) in live.iter().enumerate() {
                    mark(start, units, Owner::Frame(i));
                }
                let (mut free_blocks, mut free_units, mut largest) = (0, 0, 0);
                let mut ends = Vec::new();
                for fl in 0..FL {
                    assert_eq!(st.fl_bitmap & (1 << fl) != 0, st.sl_bitmap[fl] != 0);
                    for sl in 0..SL {
                        let head = unlink(usize::from(st.heads[fl][sl]));
                        assert_eq!(st.sl_bitmap[fl] & (1 << sl) != 0, head.is_some());
                        let (mut prev, mut cur) = (None, head);
                        while let Some(b) = cur {
                            let size = mem.get(b, field::SIZE);
                            assert_eq!(class(size), (fl, sl), "block in the wrong list");
                            assert_eq!(mem.get(b + size - 1, field::FOOT), size);
                            assert_eq!(unlink(mem.get(b, field::PREV)), prev);
                            mark(b, size, Owner::Free(b));
                            ends.extend([b, b + size - 1]);
                            free_blocks += 1;
                            free_units += size;
                            largest = largest.max(size);
                            (prev, cur) = (Some(b), unlink(mem.get(b, field::NEXT)));
                        }
                    }
                }
                let (mut cached, mut cached_units) = (0, 0);
                for i in 0..CACHE_SIZES {
                    let head = unlink(usize::from(st.cache[i]));
                    assert_eq!(st.cache_bits & (1 << i) != 0, head.is_some());
                    let mut cur = head;
                    while let Some(b) = cur {
                        mark(b, i + 1, Owner::Cached(b));
                        cached += 1;
                        cached_units += i + 1;
                        cur = unlink(mem.get(b, field::NEXT));
                    }
                }
                assert_eq!(usize::from(st.cached), cached);
                assert!(cached <= usize::from(CACHE_BLOCKS));
                let owner: Vec<Owner> = owner
                    .into_iter()
                    .map(|o| o.expect("a unit in no block: a leak"))
                    .collect();
                for pair in owner.windows(2) {
                    if let [Owner::Free(a), Owner::Free(b)] = pair {
                        assert_eq!(a, b, "adjacent free blocks");
                    }
                }
                for u in 0..mem.units {
                    assert_eq!(mem.boundary(u), ends.contains(&u), "boundary bit {u}");
                }
                assert_eq!(st.free_blocks, free_blocks);
                assert_eq!(st.live(), live.len());
                assert_eq!(
                    st.used,
                    Self::RESERVED + (mem.units - free_units - cached_units) * GRANULARITY
                );
                largest
            })
        }

        /// Return every cached block to the free lists.
        fn uncache_all(&self) {
            while self.with_heap(|st, mem| st.uncache_one(mem)) {}
        }
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

        /// After every step: invariants 1-5 hold, and an allocation failed only if no
        /// free block was large enough (exactly as documented on `alloc`).
        #[test]
        fn invariants_hold_and_failures_are_genuine(
            ops in proptest::collection::vec(op(), 1..if cfg!(miri) { 40 } else { 300 })
        ) {
            let arena = Arena::<2048>::new();
            let mut frames: Vec<FrameBuf<'_>> = Vec::new();
            let blocks = |frames: &[FrameBuf<'_>]| -> Vec<(usize, usize)> {
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
                                // A failure first returned every cached block: the free
                                // lists as they are now are those the last attempt saw.
                                prop_assert_eq!(arena.stats().cached, 0);
                                let largest = arena.check(&blocks(&frames));
                                let own_head_fits = arena.with_heap(|st, mem| {
                                    let (fl, sl) = class(units);
                                    unlink(usize::from(st.heads[fl][sl]))
                                        .is_some_and(|b| mem.get(b, field::SIZE) >= units)
                                });
                                prop_assert!(largest < round_up(units) && !own_head_fits);
                                if units <= 32 {
                                    prop_assert!(largest < units);
                                }
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
                arena.check(&blocks(&frames));
            }
            drop(frames);
            arena.check(&[]);
            arena.uncache_all();
            prop_assert_eq!(arena.check(&[]), Arena::<2048>::UNITS);
            prop_assert_eq!(arena.stats().used, Arena::<2048>::RESERVED);
        }
    }
}
