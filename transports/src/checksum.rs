//! Checksums used by the transports.
//!
//! | transport | checksum | bytes covered |
//! |-----------|----------|---------------|
//! | PPRZ v1/v2 | two running sums `ck_a += b; ck_b += ck_a` (mod 256) | `LEN` .. last `DATA` byte |
//! | XBee API  | `0xFF - (sum & 0xFF)` | every `FRAME_DATA` byte |
//! | PPRZLOG   | plain sum (mod 256) | `LEN` .. last `DATA` byte |
//!
//! All functions are total and allocation-free.

/// The PPRZ two-byte checksum, computed incrementally.
///
/// ```
/// use pprz_transports::checksum::PprzChecksum;
/// let mut ck = PprzChecksum::new();
/// ck.update(&[0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02]);
/// assert_eq!(ck.finish(), (0x1C, 0xC4));
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PprzChecksum {
    a: u8,
    b: u8,
}

impl PprzChecksum {
    /// A checksum over no bytes: `ck_a = ck_b = 0`.
    pub const fn new() -> Self {
        Self { a: 0, b: 0 }
    }

    /// Adds one byte.
    #[inline]
    pub const fn push(&mut self, byte: u8) {
        self.a = self.a.wrapping_add(byte);
        self.b = self.b.wrapping_add(self.a);
    }

    /// Adds every byte of `bytes`, in order.
    ///
    /// Unrolled by hand, 8 bytes per iteration: the release profile's `opt-level = "s"`
    /// does not unroll loops, and a byte loop costs about twice as many instructions
    /// (see `BENCHMARKS.md`, P1).
    #[inline]
    pub fn update(&mut self, bytes: &[u8]) {
        let (chunks, rest) = bytes.as_chunks::<8>();
        for &[x0, x1, x2, x3, x4, x5, x6, x7] in chunks {
            self.push(x0);
            self.push(x1);
            self.push(x2);
            self.push(x3);
            self.push(x4);
            self.push(x5);
            self.push(x6);
            self.push(x7);
        }
        for &byte in rest {
            self.push(byte);
        }
    }

    /// Returns `(ck_a, ck_b)`.
    #[inline]
    pub const fn finish(&self) -> (u8, u8) {
        (self.a, self.b)
    }
}

/// PPRZ checksum `(ck_a, ck_b)` of `bytes` (which must start at the `LEN` byte).
#[inline]
pub fn pprz(bytes: &[u8]) -> (u8, u8) {
    let mut ck = PprzChecksum::new();
    ck.update(bytes);
    ck.finish()
}

/// Sum of `bytes` modulo 256 (the PPRZLOG checksum).
pub fn sum8(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |acc, &b| acc.wrapping_add(b))
}

/// XBee API checksum of `frame_data`: `0xFF - (sum & 0xFF)`.
///
/// A received frame is valid when `sum8(frame_data) + ck == 0xFF (mod 256)`.
pub fn xbee(frame_data: &[u8]) -> u8 {
    0xFF_u8.wrapping_sub(sum8(frame_data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pprz_worked_example() {
        // The worked v2 example (ALIVE from aircraft 7, `docs/wire-formats.md`), LEN..DATA.
        assert_eq!(
            pprz(&[0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02]),
            (0x1C, 0xC4)
        );
    }

    #[test]
    fn unrolled_update_matches_the_byte_rule() {
        let bytes: [u8; 300] =
            core::array::from_fn(|i| (i as u8).wrapping_mul(37).wrapping_add(11));
        for n in 0..bytes.len() {
            let (mut a, mut b) = (0u8, 0u8);
            for &x in &bytes[..n] {
                a = a.wrapping_add(x);
                b = b.wrapping_add(a);
            }
            assert_eq!(pprz(&bytes[..n]), (a, b), "{n} bytes");
            // Incremental, split anywhere: the same sums.
            let mut ck = PprzChecksum::new();
            ck.update(&bytes[..n / 3]);
            ck.update(&bytes[n / 3..n]);
            assert_eq!(ck.finish(), (a, b), "{n} bytes in two parts");
        }
    }

    #[test]
    fn xbee_sum_rule() {
        let data = [0x81, 0x01, 0x00, 0x28, 0x00, 0xAA, 0x55];
        let ck = xbee(&data);
        assert_eq!(sum8(&data).wrapping_add(ck), 0xFF);
    }

    #[test]
    fn sum8_wraps() {
        assert_eq!(sum8(&[0xFF, 0x02]), 0x01);
        assert_eq!(sum8(&[]), 0);
    }
}
