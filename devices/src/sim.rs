//! A simulated radio link for tests and host runs (feature `sim`).
//!
//! [`SimLink`] is a pair of connected endpoints. Each direction models a transparent
//! serial radio modem:
//!
//! ```text
//!  write ──> [ radio TX buffer: `buffer` bytes ] ──> air at `byte_rate` ──> + `latency` ──> read
//!                 full? Drop (counted) or Wait          bit errors (seeded)
//! ```
//!
//! * **Byte rate**: bytes leave the TX buffer one after the other, one every
//!   `1 / byte_rate` s (`byte_rate = 0`: no serialisation delay).
//! * **Latency**: a byte can be read `latency` after its last bit was sent.
//! * **Buffer**: at most `buffer` bytes wait to be sent (the byte being sent counts).
//!   When it is full, [`Overflow::Drop`] (what a radio modem does) drops the written
//!   bytes and counts them in [`SimStats::dropped_bytes`], while the write still
//!   "succeeds", as a UART write to a modem does; [`Overflow::Wait`] makes the write
//!   wait for room, modelling hardware flow control (CTS), so that the telemetry
//!   queue behind the writer sheds low-priority messages instead of the radio
//!   dropping random bytes.
//! * **Bit errors**: every bit is flipped with probability `bit_error_rate`, drawn from
//!   a SplitMix64 generator seeded with [`SimConfig::seed`] (the other direction uses
//!   a derived seed), so a run is reproducible. Flipped bits are counted.
//! * **Receiver storage**: bytes in the air and bytes arrived but not yet read share
//!   one ring of `N` bytes per direction (the const parameter). If the receiver does
//!   not read and the ring fills, further bytes are lost as receiver overruns
//!   ([`SimStats::overrun_bytes`]) with `Drop`, or the writer waits with `Wait`.
//!
//! Time is embassy-time's: under the mock driver (`embassy-time/mock-driver`) a
//! simulation is deterministic and runs as fast as the test advances the clock; on
//! the host with the `std` driver it runs in real time. The crate does not pick a
//! driver: the final binary does.
//!
//! Memory: `9 * N` bytes per direction (each byte carries its arrival time).
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::NoopRawMutex;
//! use embassy_time::Duration;
//! use pprz_devices::sim::{SimConfig, SimLink};
//!
//! // A 57600-baud radio (5760 bytes/s), 20 ms latency, 256-byte modem buffer, BER 1e-5.
//! let config = SimConfig::new(5760)
//!     .latency(Duration::from_millis(20))
//!     .buffer(256)
//!     .bit_error_rate(1e-5)
//!     .seed(42);
//! let link = SimLink::<NoopRawMutex, 1024>::new(config);
//! let (aircraft, ground) = link.endpoints();
//! let (uplink_rx, downlink_tx) = aircraft.split(); // for a reader task and a writer task
//! # let _ = (ground, uplink_rx, downlink_tx);
//! ```

use core::cell::RefCell;
use core::convert::Infallible;
use core::future::poll_fn;
use core::task::Poll;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::waitqueue::WakerRegistration;
use embassy_time::{Duration, Instant, TICK_HZ, Timer};
use embedded_io_async::{ErrorType, Read, Write};

/// What a direction does with written bytes when its TX buffer is full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Overflow {
    /// Drop them and count them (a radio modem without flow control). Writes never wait.
    #[default]
    Drop,
    /// Make the write wait for room (hardware flow control).
    Wait,
}

/// Parameters of both directions of a [`SimLink`]; see the [module docs](self).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SimConfig {
    /// Bytes per second on the air; 0 for no serialisation delay.
    pub byte_rate: u32,
    /// Delay from the end of a byte's transmission to its arrival.
    pub latency: Duration,
    /// Bytes the TX buffer holds (values below 1 count as 1).
    pub buffer: usize,
    /// Probability that a bit is flipped (0 to 1).
    pub bit_error_rate: f64,
    /// Seed of the bit-error generator.
    pub seed: u64,
    /// Behaviour when the TX buffer (or the receiver's ring) is full.
    pub overflow: Overflow,
}

impl SimConfig {
    /// `byte_rate` bytes/s, no latency, a 256-byte buffer, no bit errors, seed 1,
    /// [`Overflow::Drop`].
    pub const fn new(byte_rate: u32) -> Self {
        Self {
            byte_rate,
            latency: Duration::from_ticks(0),
            buffer: 256,
            bit_error_rate: 0.0,
            seed: 1,
            overflow: Overflow::Drop,
        }
    }

    /// Sets [`latency`](Self::latency).
    pub const fn latency(mut self, latency: Duration) -> Self {
        self.latency = latency;
        self
    }

    /// Sets [`buffer`](Self::buffer).
    pub const fn buffer(mut self, bytes: usize) -> Self {
        self.buffer = bytes;
        self
    }

    /// Sets [`bit_error_rate`](Self::bit_error_rate).
    pub const fn bit_error_rate(mut self, ber: f64) -> Self {
        self.bit_error_rate = ber;
        self
    }

    /// Sets [`seed`](Self::seed).
    pub const fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Sets [`overflow`](Self::overflow).
    pub const fn overflow(mut self, overflow: Overflow) -> Self {
        self.overflow = overflow;
        self
    }
}

/// A direction of a [`SimLink`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Direction {
    /// Written on endpoint A, read on endpoint B.
    AToB,
    /// Written on endpoint B, read on endpoint A.
    BToA,
}

impl Direction {
    const fn index(self) -> usize {
        match self {
            Self::AToB => 0,
            Self::BToA => 1,
        }
    }
}

/// Counters of one direction of a [`SimLink`]. All wrap around.
///
/// `bytes_written == bytes_sent + dropped_bytes + overrun_bytes`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SimStats {
    /// Bytes handed to `write` and accounted for (sent or dropped).
    pub bytes_written: u32,
    /// Bytes accepted into the TX buffer (they will arrive).
    pub bytes_sent: u32,
    /// Bytes returned by `read`.
    pub bytes_delivered: u32,
    /// Bytes dropped because the TX buffer was full ([`Overflow::Drop`]).
    pub dropped_bytes: u32,
    /// Bytes dropped because the receiver's ring was full ([`Overflow::Drop`]).
    pub overrun_bytes: u32,
    /// Bits flipped.
    pub bit_errors: u32,
    /// Bytes with at least one flipped bit.
    pub corrupted_bytes: u32,
}

/// SplitMix64 (Steele, Lea, Flood 2014): tiny, fast, every seed is good.
#[derive(Debug)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// One direction: the radio's TX buffer plus the bytes in the air and at the receiver.
///
/// Invariants: `len <= N`, `head < N` (when `N > 0`); `data`/`due` hold the bytes in
/// order from `head`, with non-decreasing `due`.
struct Dir<const N: usize> {
    data: [u8; N],
    /// Arrival tick of each byte.
    due: [u64; N],
    head: usize,
    len: usize,
    /// End of transmission of the last accepted byte, in ticks x `byte_rate`.
    tx_end: u128,
    rng: SplitMix64,
    stats: SimStats,
    rx_waker: WakerRegistration,
    tx_waker: WakerRegistration,
}

/// What a push or pop attempt asks the caller to do.
enum Step {
    Done(usize),
    /// Try again at this tick.
    At(u64),
    /// Try again when the other side made progress.
    Peer,
}

/// A simulated radio link; see the [module docs](self).
///
/// `M` is the mutex kind (`NoopRawMutex` when both endpoints run on one executor,
/// `CriticalSectionRawMutex` otherwise); `N` is the per-direction ring size.
/// `new` is `const`, so a link can be a `static`.
pub struct SimLink<M: RawMutex, const N: usize> {
    config: SimConfig,
    /// Bit-flip probability as a fraction of 2^64.
    ber_threshold: u64,
    dirs: [Mutex<M, RefCell<Dir<N>>>; 2],
}

const fn ber_threshold(ber: f64) -> u64 {
    // `as` saturates (and maps NaN to 0), so any input is safe.
    (ber * 18_446_744_073_709_551_616.0) as u64
}

impl<M: RawMutex, const N: usize> SimLink<M, N> {
    const VALID: () = assert!(N > 0, "a SimLink needs a ring of at least one byte");

    /// A link with both directions empty and zero counters. `N = 0` does not compile.
    pub const fn new(config: SimConfig) -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::VALID;
        Self {
            config,
            ber_threshold: ber_threshold(config.bit_error_rate),
            dirs: [
                Mutex::new(RefCell::new(Dir::new(config.seed))),
                Mutex::new(RefCell::new(Dir::new(config.seed ^ 0x5DEE_CE66_D1CE_4E5B))),
            ],
        }
    }

    /// The configuration.
    pub const fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The two endpoints, A and B. Take them once: each direction wakes one reader and
    /// one writer.
    pub fn endpoints(&self) -> (SimEnd<'_, M, N>, SimEnd<'_, M, N>) {
        (
            SimEnd::new(self, Direction::AToB, Direction::BToA),
            SimEnd::new(self, Direction::BToA, Direction::AToB),
        )
    }

    /// Counters of one direction.
    pub fn stats(&self, direction: Direction) -> SimStats {
        self.with(direction, |d| d.stats)
    }

    fn with<R>(&self, direction: Direction, f: impl FnOnce(&mut Dir<N>) -> R) -> R {
        self.dirs[direction.index()].lock(|d| f(&mut d.borrow_mut()))
    }

    fn now_ticks() -> u64 {
        Instant::now().as_ticks()
    }

    /// Ticks at which `scaled` (ticks x byte_rate) is reached.
    fn ticks_of(&self, scaled: u128) -> u64 {
        let rate = u128::from(self.config.byte_rate.max(1));
        u64::try_from(scaled.div_ceil(rate)).unwrap_or(u64::MAX)
    }

    fn push(&self, direction: Direction, buf: &[u8]) -> Step {
        let now = Self::now_ticks();
        let rate = u128::from(self.config.byte_rate);
        let hz = u128::from(TICK_HZ);
        let now_scaled = u128::from(now) * rate;
        let buffer = self.config.buffer.max(1) as u128;
        let latency = self.config.latency.as_ticks();
        let wait = self.config.overflow == Overflow::Wait;
        self.with(direction, |d| {
            let mut accepted = 0;
            let mut step = None;
            for &byte in buf {
                let queued = if rate == 0 {
                    0
                } else {
                    d.tx_end.saturating_sub(now_scaled).div_ceil(hz)
                };
                let full = if queued >= buffer {
                    // Room again once the queue has drained to `buffer - 1` bytes.
                    Some(Step::At(self.ticks_of(d.tx_end - (buffer - 1) * hz)))
                } else if d.len >= N {
                    Some(Step::Peer)
                } else {
                    None
                };
                if let Some(full) = full {
                    if wait {
                        step = Some(full);
                        break;
                    }
                    d.stats.bytes_written = d.stats.bytes_written.wrapping_add(1);
                    let counter = match full {
                        Step::Peer => &mut d.stats.overrun_bytes,
                        _ => &mut d.stats.dropped_bytes,
                    };
                    *counter = counter.wrapping_add(1);
                    accepted += 1;
                    continue;
                }
                let sent_at = if rate == 0 {
                    now
                } else {
                    d.tx_end = d.tx_end.max(now_scaled) + hz;
                    self.ticks_of(d.tx_end)
                };
                let byte = d.corrupt(byte, self.ber_threshold);
                d.enqueue(byte, sent_at.saturating_add(latency));
                d.stats.bytes_written = d.stats.bytes_written.wrapping_add(1);
                d.stats.bytes_sent = d.stats.bytes_sent.wrapping_add(1);
                accepted += 1;
            }
            if accepted > 0 {
                d.rx_waker.wake();
                Step::Done(accepted)
            } else {
                step.unwrap_or(Step::Done(0))
            }
        })
    }

    fn pop(&self, direction: Direction, buf: &mut [u8]) -> Step {
        let now = Self::now_ticks();
        self.with(direction, |d| {
            let mut n = 0;
            while n < buf.len() && d.len > 0 && d.due[d.head] <= now {
                buf[n] = d.data[d.head];
                d.head = (d.head + 1) % N;
                d.len -= 1;
                n += 1;
            }
            if n > 0 {
                d.stats.bytes_delivered = d.stats.bytes_delivered.wrapping_add(crate::len_u32(n));
                d.tx_waker.wake();
                Step::Done(n)
            } else if d.len > 0 {
                Step::At(d.due[d.head])
            } else {
                Step::Peer
            }
        })
    }

    /// When the last accepted byte will have left the TX buffer.
    fn drained_at(&self, direction: Direction) -> Option<u64> {
        let now_scaled = u128::from(Self::now_ticks()) * u128::from(self.config.byte_rate);
        self.with(direction, |d| {
            (self.config.byte_rate > 0 && d.tx_end > now_scaled).then(|| self.ticks_of(d.tx_end))
        })
    }

    /// Waits until the reader of `direction` freed room in the ring.
    async fn wait_reader(&self, direction: Direction) {
        poll_fn(|cx| {
            self.with(direction, |d| {
                if d.len < N {
                    Poll::Ready(())
                } else {
                    d.tx_waker.register(cx.waker());
                    Poll::Pending
                }
            })
        })
        .await;
    }

    /// Waits until the writer of `direction` put a byte in the ring.
    async fn wait_writer(&self, direction: Direction) {
        poll_fn(|cx| {
            self.with(direction, |d| {
                if d.len > 0 {
                    Poll::Ready(())
                } else {
                    d.rx_waker.register(cx.waker());
                    Poll::Pending
                }
            })
        })
        .await;
    }

    async fn write(&self, direction: Direction, buf: &[u8]) -> usize {
        loop {
            match self.push(direction, buf) {
                Step::Done(n) => return n,
                Step::At(tick) => Timer::at(Instant::from_ticks(tick)).await,
                Step::Peer => self.wait_reader(direction).await,
            }
        }
    }

    async fn read(&self, direction: Direction, buf: &mut [u8]) -> usize {
        if buf.is_empty() {
            return 0;
        }
        loop {
            match self.pop(direction, buf) {
                Step::Done(n) => return n,
                Step::At(tick) => Timer::at(Instant::from_ticks(tick)).await,
                Step::Peer => self.wait_writer(direction).await,
            }
        }
    }
}

impl<const N: usize> Dir<N> {
    const fn new(seed: u64) -> Self {
        Self {
            data: [0; N],
            due: [0; N],
            head: 0,
            len: 0,
            tx_end: 0,
            rng: SplitMix64(seed),
            stats: SimStats {
                bytes_written: 0,
                bytes_sent: 0,
                bytes_delivered: 0,
                dropped_bytes: 0,
                overrun_bytes: 0,
                bit_errors: 0,
                corrupted_bytes: 0,
            },
            rx_waker: WakerRegistration::new(),
            tx_waker: WakerRegistration::new(),
        }
    }

    /// Appends a byte; the caller checked `len < N`.
    fn enqueue(&mut self, byte: u8, due: u64) {
        let tail = (self.head + self.len) % N;
        self.data[tail] = byte;
        self.due[tail] = due;
        self.len += 1;
    }

    fn corrupt(&mut self, byte: u8, threshold: u64) -> u8 {
        if threshold == 0 {
            return byte;
        }
        let mut flips = 0u8;
        for bit in 0..8 {
            if self.rng.next() < threshold {
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

/// One endpoint of a [`SimLink`]: reads what the other endpoint writes and the other
/// way round. [`split`](Self::split) it to give the halves to a reader and a writer task.
pub struct SimEnd<'a, M: RawMutex, const N: usize> {
    /// The receiving half.
    pub rx: SimRx<'a, M, N>,
    /// The sending half.
    pub tx: SimTx<'a, M, N>,
}

impl<'a, M: RawMutex, const N: usize> SimEnd<'a, M, N> {
    fn new(link: &'a SimLink<M, N>, tx: Direction, rx: Direction) -> Self {
        Self {
            rx: SimRx {
                link,
                direction: rx,
            },
            tx: SimTx {
                link,
                direction: tx,
            },
        }
    }

    /// The receiving and the sending half.
    pub fn split(self) -> (SimRx<'a, M, N>, SimTx<'a, M, N>) {
        (self.rx, self.tx)
    }
}

/// The sending half of a [`SimEnd`].
pub struct SimTx<'a, M: RawMutex, const N: usize> {
    link: &'a SimLink<M, N>,
    direction: Direction,
}

impl<M: RawMutex, const N: usize> SimTx<'_, M, N> {
    /// Counters of this half's direction.
    pub fn stats(&self) -> SimStats {
        self.link.stats(self.direction)
    }
}

/// The receiving half of a [`SimEnd`].
pub struct SimRx<'a, M: RawMutex, const N: usize> {
    link: &'a SimLink<M, N>,
    direction: Direction,
}

impl<M: RawMutex, const N: usize> SimRx<'_, M, N> {
    /// Counters of this half's direction.
    pub fn stats(&self) -> SimStats {
        self.link.stats(self.direction)
    }
}

impl<M: RawMutex, const N: usize> ErrorType for SimTx<'_, M, N> {
    type Error = Infallible;
}

impl<M: RawMutex, const N: usize> ErrorType for SimRx<'_, M, N> {
    type Error = Infallible;
}

impl<M: RawMutex, const N: usize> ErrorType for SimEnd<'_, M, N> {
    type Error = Infallible;
}

impl<M: RawMutex, const N: usize> Write for SimTx<'_, M, N> {
    /// Accepts bytes into the TX buffer. With [`Overflow::Drop`] it never waits and
    /// reports every byte written (dropped ones are counted); with [`Overflow::Wait`]
    /// it waits until at least one byte fits.
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        Ok(self.link.write(self.direction, buf).await)
    }

    /// Waits until every accepted byte has left the TX buffer (is in the air).
    async fn flush(&mut self) -> Result<(), Infallible> {
        while let Some(tick) = self.link.drained_at(self.direction) {
            Timer::at(Instant::from_ticks(tick)).await;
        }
        Ok(())
    }
}

impl<M: RawMutex, const N: usize> Read for SimRx<'_, M, N> {
    /// Waits until at least one byte has arrived, then returns every arrived byte that
    /// fits in `buf`.
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        Ok(self.link.read(self.direction, buf).await)
    }
}

impl<M: RawMutex, const N: usize> Write for SimEnd<'_, M, N> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.tx.write(buf).await
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        self.tx.flush().await
    }
}

impl<M: RawMutex, const N: usize> Read for SimEnd<'_, M, N> {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        self.rx.read(buf).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ber_threshold_saturates() {
        assert_eq!(ber_threshold(0.0), 0);
        assert_eq!(ber_threshold(-1.0), 0);
        assert_eq!(ber_threshold(f64::NAN), 0);
        assert_eq!(ber_threshold(1.0), u64::MAX);
        assert_eq!(ber_threshold(0.5), 1 << 63);
    }

    #[test]
    fn splitmix_reference_values() {
        // First outputs for seed 1234567 from the reference C implementation.
        let mut rng = SplitMix64(1_234_567);
        assert_eq!(rng.next(), 6_457_827_717_110_365_317);
        assert_eq!(rng.next(), 3_203_168_211_198_807_973);
    }
}
