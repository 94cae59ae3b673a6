//! The seeded generator: the bit errors and XBee failures of the simulated link, and
//! the fixed-seed tests and benchmark workloads of the workspace.
//!
//! SplitMix64 (Steele, Lea, Flood 2014): tiny, fast, every seed is good, and the same
//! sequence on every platform. Not for keys or nonces: it is predictable by design.
//!
//! ```
//! use pprz_devices::rng::SplitMix64;
//!
//! let mut a = SplitMix64::new(42);
//! let mut b = SplitMix64::new(42);
//! assert_eq!(a.next_u64(), b.next_u64());
//! assert!((8..=255).contains(&a.range(8, 255)));
//! ```

/// A SplitMix64 generator; see the [module docs](self).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator starting from `seed`.
    pub const fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (0 when `n` is 0; the modulo bias is irrelevant here).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }

    /// True with a chance of `percent` in 100.
    pub fn chance(&mut self, percent: u64) -> bool {
        self.next_u64() % 100 < percent
    }

    /// Uniform in `lo..=hi` (the modulo bias is irrelevant here); `lo` if `hi < lo`.
    pub fn range(&mut self, lo: usize, hi: usize) -> usize {
        let span = hi.saturating_sub(lo) as u64;
        let r = match span.checked_add(1) {
            Some(n) => self.next_u64() % n,
            None => self.next_u64(),
        };
        // `r <= span`, so the sum is at most `hi`.
        lo + r as usize
    }

    /// Fills `dst` with the little-endian bytes of successive outputs (the last one cut
    /// short to fit).
    pub fn fill_bytes(&mut self, dst: &mut [u8]) {
        for chunk in dst.chunks_mut(8) {
            let v = self.next_u64().to_le_bytes();
            chunk.copy_from_slice(&v[..chunk.len()]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix_reference_values() {
        // First outputs for seed 1234567 from the reference C implementation.
        let mut rng = SplitMix64::new(1_234_567);
        assert_eq!(rng.next_u64(), 6_457_827_717_110_365_317);
        assert_eq!(rng.next_u64(), 3_203_168_211_198_807_973);
    }

    #[test]
    fn ranges_at_the_edges_never_panic() {
        let mut rng = SplitMix64::new(7);
        for _ in 0..100 {
            assert_eq!(rng.range(5, 3), 5, "empty: the low end");
            assert_eq!(rng.range(9, 9), 9);
            let _ = rng.range(0, usize::MAX);
            assert!(rng.range(usize::MAX - 1, usize::MAX) >= usize::MAX - 1);
        }
    }

    #[test]
    fn same_seed_same_sequence_and_ranges_hold() {
        let mut a = SplitMix64::new(42);
        let mut b = SplitMix64::new(42);
        for _ in 0..1000 {
            let (x, y) = (a.range(8, 255), b.range(8, 255));
            assert_eq!(x, y);
            assert!((8..=255).contains(&x));
            assert!(a.below(3) < 3 && b.below(3) < 3);
        }
        assert_eq!(a.below(0), 0);
    }

    #[test]
    fn fill_bytes_is_the_outputs_little_endian() {
        let mut a = SplitMix64::new(7);
        let mut b = a.clone();
        let mut buf = [0u8; 11];
        a.fill_bytes(&mut buf);
        assert_eq!(buf[..8], b.next_u64().to_le_bytes());
        assert_eq!(buf[8..], b.next_u64().to_le_bytes()[..3]);
    }
}
