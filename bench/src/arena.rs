//! Workload 5: the frame arena's allocation and release cost at a given fill level, and
//! its fill level at the first allocation failure.
//!
//! Frame sizes are uniform in [`MIN_FRAME`]`..=`[`MAX_FRAME`] bytes (a PPRZ frame's
//! length field is one byte), drawn from a fixed seed.
//!
//! * Cost at a fill level ([`prepare`] then [`churn`]): the arena is filled to the target
//!   fraction of its capacity and churned until the free space is fragmented as in steady
//!   state; the measured run then does [`OPS`] steps, each an allocation of a random size
//!   while the arena is below the target and the release of a random live frame
//!   otherwise (an allocation that fails releases instead), so the fill stays within one
//!   frame of the target. Sizes and victims are drawn before the measured run.
//! * [`fill_at_first_failure`]: allocate until the first failure, then repeatedly release
//!   one random frame and allocate until the next failure, recording the fill level at
//!   every failure (the method of `telemetry/tests/arena.rs`).
//!
//! Fill levels are `ArenaStats::used / capacity`: they count the rounding of frames to
//! 8-byte units and the arena's fixed reserved bytes (1/65 of the capacity).

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use pprz_telemetry::arena::{AllocError, FrameArena, FrameBuf};

use crate::rng::Rng;

/// Smallest frame of the workload, in bytes.
pub const MIN_FRAME: usize = 8;
/// Largest frame of the workload, in bytes.
pub const MAX_FRAME: usize = 255;
/// Capacity of the arena of the cost measurement.
pub const ARENA_BYTES: usize = 16 * 1024;
/// Measured steps (allocations plus releases) per fill level.
pub const OPS: usize = 20_000;
/// Seed of the cost measurement.
pub const SEED: u64 = 0x5EED_A4E4;

/// The arena of the cost measurement.
pub type CostArena = FrameArena<CriticalSectionRawMutex, ARENA_BYTES>;

/// An arena held at a fill level, with the inputs of the measured run drawn in advance.
pub struct FillState<'a> {
    arena: &'a CostArena,
    live: Vec<FrameBuf<'a>>,
    /// `used` of the arena's statistics, tracked without taking its lock.
    used: usize,
    target: usize,
    percent: usize,
    sizes: Vec<u16>,
    picks: Vec<u32>,
}

/// What a measured run did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ChurnSummary {
    /// Successful allocations.
    pub allocs: u32,
    /// Releases.
    pub releases: u32,
    /// Allocations that failed (the step then released a frame instead).
    pub failures: u32,
    /// Mean fill level (`used / capacity`) over the steps.
    pub mean_fill: f64,
    /// The target fill level in percent.
    pub percent: usize,
}

impl ChurnSummary {
    /// Allocator operations (allocations, failed allocations and releases).
    pub fn operations(&self) -> u32 {
        self.allocs + self.releases + self.failures
    }
}

impl<'a> FillState<'a> {
    /// Live frames.
    pub fn live(&self) -> usize {
        self.live.len()
    }

    /// Current fill level.
    pub fn fill(&self) -> f64 {
        self.used as f64 / ARENA_BYTES as f64
    }

    /// One step: allocate below the target, release at or above it.
    #[inline]
    fn step(&mut self, k: usize, summary: &mut ChurnSummary) {
        if self.used < self.target {
            let len = usize::from(self.sizes[k % self.sizes.len()]);
            match self.arena.alloc(len) {
                Ok(frame) => {
                    self.used += frame.capacity();
                    self.live.push(frame);
                    summary.allocs += 1;
                    return;
                }
                Err(_) => summary.failures += 1,
            }
        }
        if !self.live.is_empty() {
            let pick = self.picks[k % self.picks.len()] as usize % self.live.len();
            let frame = self.live.swap_remove(pick);
            self.used -= frame.capacity();
            drop(frame);
            summary.releases += 1;
        }
    }
}

/// Fills `arena` to `percent` % and churns it (`4 * OPS` steps, not measured) so its free
/// space is fragmented as in steady state; draws the inputs of the measured run.
///
/// # Panics
/// If `arena` is not empty or `percent` is not in `1..=99`.
pub fn prepare(arena: &CostArena, percent: usize, seed: u64) -> FillState<'_> {
    assert!((1..=99).contains(&percent), "fill level {percent} %");
    let stats = arena.stats();
    assert_eq!(stats.live, 0, "the arena must be empty");
    let mut rng = Rng::new(seed ^ percent as u64);
    let draw = |n: usize, rng: &mut Rng| -> (Vec<u16>, Vec<u32>) {
        let sizes = (0..n)
            .map(|_| rng.range(MIN_FRAME, MAX_FRAME) as u16)
            .collect();
        let picks = (0..n).map(|_| rng.next_u64() as u32).collect();
        (sizes, picks)
    };
    let (sizes, picks) = draw(4 * OPS, &mut rng);
    let mut state = FillState {
        arena,
        live: Vec::new(),
        used: stats.used,
        target: ARENA_BYTES * percent / 100,
        percent,
        sizes,
        picks,
    };
    let mut warm = ChurnSummary::default();
    // Fill up to the target, then churn around it.
    let mut k = 0;
    while state.used < state.target && warm.failures == 0 {
        state.step(k, &mut warm);
        k += 1;
    }
    for k in 0..4 * OPS {
        state.step(k, &mut warm);
    }
    let (sizes, picks) = draw(OPS, &mut rng);
    state.sizes = sizes;
    state.picks = picks;
    state
}

/// The measured run: [`OPS`] steps at the prepared fill level.
pub fn churn(state: &mut FillState<'_>) -> ChurnSummary {
    let mut summary = ChurnSummary::default();
    let mut fill_sum = 0usize;
    for k in 0..OPS {
        state.step(k, &mut summary);
        fill_sum += state.used;
    }
    summary.mean_fill = fill_sum as f64 / (OPS * ARENA_BYTES) as f64;
    summary.percent = state.percent;
    summary
}

/// Fill levels at the first allocation failure ([`fill_at_first_failure`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FailureFill {
    /// Arena capacity in bytes.
    pub capacity: usize,
    /// Failures recorded.
    pub rounds: usize,
    /// Mean of `used / capacity` at the failures.
    pub used_mean: f64,
    /// Lowest `used / capacity` at a failure.
    pub used_min: f64,
    /// Mean of requested bytes / capacity at the failures (without rounding and the
    /// reserved bytes).
    pub payload_mean: f64,
    /// Lowest requested bytes / capacity at a failure.
    pub payload_min: f64,
}

/// The fill level at the first allocation failure of an `N`-byte arena over `rounds`
/// rounds of the randomized steady-state workload (see the module documentation).
///
/// # Panics
/// If an allocation fails for another reason than a full arena (a frame of at most 255
/// bytes is never too large), or `rounds` is 0.
pub fn fill_at_first_failure<const N: usize>(seed: u64, rounds: usize) -> FailureFill {
    assert!(rounds > 0, "no round");
    let arena = FrameArena::<CriticalSectionRawMutex, N>::new();
    let mut rng = Rng::new(seed);
    let mut live: Vec<(FrameBuf<'_>, usize)> = Vec::new();
    let mut requested = 0;
    let (mut used_sum, mut payload_sum) = (0.0, 0.0);
    let (mut used_min, mut payload_min) = (1.0f64, 1.0f64);
    for round in 0..=rounds {
        if round > 0 && !live.is_empty() {
            let (_, len) = live.swap_remove(rng.range(0, live.len() - 1));
            requested -= len;
        }
        loop {
            let len = rng.range(MIN_FRAME, MAX_FRAME);
            match arena.alloc(len) {
                Ok(frame) => {
                    live.push((frame, len));
                    requested += len;
                }
                Err(AllocError::Full { .. }) => break,
                Err(e) => panic!("{e}"),
            }
        }
        if round > 0 {
            let used = arena.stats().used as f64 / N as f64;
            let payload = requested as f64 / N as f64;
            used_sum += used;
            payload_sum += payload;
            used_min = used_min.min(used);
            payload_min = payload_min.min(payload);
        }
    }
    FailureFill {
        capacity: N,
        rounds,
        used_mean: used_sum / rounds as f64,
        used_min,
        payload_mean: payload_sum / rounds as f64,
        payload_min,
    }
}
