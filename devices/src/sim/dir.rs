//! One direction of the link: the UART, the modem and the receiver's ring.

use embassy_sync::waitqueue::WakerRegistration;

use super::SimStats;
use super::modem::{InModem, MODEM_FRAMES, Parser};
use super::outage::Outages;
use super::timing::Timing;
use crate::rng::SplitMix64;

/// One direction: the UART, the modem and the receiver's ring.
///
/// Ring invariants: `len <= N`, `head < N`; `data`/`due` hold the bytes in delivery
/// order from `head`, with non-decreasing `due` (except right after a partly read run,
/// see `insert`).
pub(super) struct Dir<const N: usize> {
    pub(super) data: [u8; N],
    /// Arrival tick of each byte.
    pub(super) due: [u64; N],
    pub(super) head: usize,
    pub(super) len: usize,
    /// The run of equal arrival times at `head` has been partly read: nothing is
    /// inserted before its end (an RX frame is never split).
    pub(super) partial: bool,
    /// When the last byte crossed the UART.
    pub(super) uart_end: u128,
    /// UART time used.
    pub(super) uart_busy: u128,
    /// When the modem is done with everything it accepted.
    pub(super) tx_end: u128,
    /// Air time scheduled.
    pub(super) air_total: u128,
    /// Frames in the XBee modem, oldest first, from `frames_head`.
    pub(super) frames: [InModem; MODEM_FRAMES],
    pub(super) frames_head: usize,
    pub(super) frames_len: usize,
    pub(super) parser: Parser,
    pub(super) rng: SplitMix64,
    pub(super) stats: SimStats,
    /// When this direction delivers nothing.
    pub(super) outages: Outages,
    pub(super) rx_waker: WakerRegistration,
    pub(super) tx_waker: WakerRegistration,
}

impl<const N: usize> Dir<N> {
    pub(super) const fn new(seed: u64) -> Self {
        Self {
            data: [0; N],
            due: [0; N],
            head: 0,
            len: 0,
            partial: false,
            uart_end: 0,
            uart_busy: 0,
            tx_end: 0,
            air_total: 0,
            frames: [InModem::EMPTY; MODEM_FRAMES],
            frames_head: 0,
            frames_len: 0,
            parser: Parser::new(),
            rng: SplitMix64::new(seed),
            stats: SimStats {
                bytes_written: 0,
                bytes_sent: 0,
                bytes_delivered: 0,
                dropped_bytes: 0,
                overrun_bytes: 0,
                bit_errors: 0,
                corrupted_bytes: 0,
                serial_busy_us: 0,
                air_busy_us: 0,
                frames_sent: 0,
                frames_dropped: 0,
                frames_overrun: 0,
                malformed_frames: 0,
                discarded_bytes: 0,
                failed_attempts: 0,
                frames_lost: 0,
                statuses: 0,
                statuses_lost: 0,
                outage_bytes: 0,
                outage_attempts: 0,
            },
            outages: Outages::NONE,
            rx_waker: WakerRegistration::new(),
            tx_waker: WakerRegistration::new(),
        }
    }

    /// Bytes in the transparent modem at `at` (the one on the air counts): they leave
    /// back to back until `tx_end`.
    pub(super) fn queued(&self, at: u128, air_byte: u128) -> u128 {
        self.tx_end.saturating_sub(at).div_ceil(air_byte)
    }

    /// Inserts `bytes`, arriving at `due`, after every byte arriving at or before
    /// `due` (and never into a partly read run). Returns `false` if they do not fit.
    pub(super) fn insert(&mut self, bytes: &[u8], due: u64) -> bool {
        let k = bytes.len();
        if k > N - self.len {
            return false;
        }
        let at = |i: usize| (self.head + i) % N;
        let mut pos = self.len;
        while pos > 0 && self.due[at(pos - 1)] > due {
            pos -= 1;
        }
        if self.partial && pos < self.len {
            // Not before the end of the partly read run.
            let run = self.due[self.head];
            let mut end = 0;
            while end < self.len && self.due[at(end)] == run {
                end += 1;
            }
            pos = pos.max(end);
        }
        let mut i = self.len;
        while i > pos {
            i -= 1;
            let (from, to) = (at(i), at(i + k));
            self.data[to] = self.data[from];
            self.due[to] = self.due[from];
        }
        for (j, &b) in bytes.iter().enumerate() {
            let to = at(pos + j);
            self.data[to] = b;
            self.due[to] = due;
        }
        self.len += k;
        true
    }

    pub(super) fn frames_iter(&self) -> impl Iterator<Item = &InModem> {
        (0..self.frames_len).map(|i| &self.frames[(self.frames_head + i) % MODEM_FRAMES])
    }

    /// Forgets the frames the modem is done with at `at`.
    pub(super) fn prune(&mut self, at: u128, ack_wait: u128) {
        while self.frames_len > 0 && self.frames[self.frames_head].end(ack_wait) <= at {
            self.frames_head = (self.frames_head + 1) % MODEM_FRAMES;
            self.frames_len -= 1;
        }
    }

    pub(super) fn malformed(&mut self, bytes: u32) {
        let s = &mut self.stats;
        s.malformed_frames = s.malformed_frames.wrapping_add(1);
        s.discarded_bytes = s.discarded_bytes.wrapping_add(bytes);
    }

    /// One transmission of `air_bytes` bytes: `true` if it is received and
    /// acknowledged (no bit error, no random failure).
    pub(super) fn attempt(&mut self, air_bytes: usize, t: &Timing) -> bool {
        let mut clean = true;
        if t.ber > 0 {
            for _ in 0..air_bytes {
                clean &= self.corrupt(0, t.ber) == 0;
            }
        }
        clean && (t.failure == 0 || self.rng.next_u64() >= t.failure)
    }

    pub(super) fn corrupt(&mut self, byte: u8, threshold: u64) -> u8 {
        if threshold == 0 {
            return byte;
        }
        let mut flips = 0u8;
        for bit in 0..8 {
            if self.rng.next_u64() < threshold {
                flips |= 1 << bit;
            }
        }
        if flips != 0 {
            self.stats.bit_errors = self.stats.bit_errors.wrapping_add(flips.count_ones());
            self.stats.corrupted_bytes = self.stats.corrupted_bytes.wrapping_add(1);
        }
        byte ^ flips
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    pub(super) fn memory_per_direction_is_as_documented() {
        assert!(core::mem::size_of::<Dir<1>>() <= 9 + 1536);
        assert!(core::mem::size_of::<Dir<4096>>() <= 9 * 4096 + 1536);
    }

    #[test]
    pub(super) fn insert_keeps_arrival_order_and_runs_whole() {
        let mut d = Dir::<16>::new(1);
        assert!(d.insert(&[1], 10));
        assert!(d.insert(&[2], 30));
        assert!(d.insert(&[7, 7, 7], 20));
        assert!(d.insert(&[3], 30));
        let order: std::vec::Vec<_> = (0..d.len).map(|i| (d.data[i], d.due[i])).collect();
        assert_eq!(
            order,
            [(1, 10), (7, 20), (7, 20), (7, 20), (2, 30), (3, 30)]
        );
        // A partly read run is not split, even by an earlier arrival.
        d.head = 2;
        d.len = 4;
        d.partial = true;
        assert!(d.insert(&[9], 5));
        let order: std::vec::Vec<_> = (0..d.len).map(|i| d.data[(d.head + i) % 16]).collect();
        assert_eq!(order, [7, 7, 9, 2, 3]);
        assert!(!d.insert(&[0; 12], 40), "does not fit");
    }
}
