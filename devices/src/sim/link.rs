//! The link: its two directions, writes through the UART into the modem and reads
//! from the receiver's ring.

use core::cell::RefCell;
use core::future::poll_fn;
use core::task::Poll;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Instant, Timer};

use super::dir::Dir;
use super::modem::{MODEM_FRAMES, rx_frame_len};
use super::outage::OutageError;
use super::timing::Timing;
use super::transmit::{Modem, Status};
use super::{Overflow, SimConfig, SimStats, XBeeModem};

/// A direction of a [`SimLink`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Direction {
    /// Written on endpoint A (the aircraft), read on endpoint B.
    AToB,
    /// Written on endpoint B (the ground), read on endpoint A.
    BToA,
}

impl Direction {
    pub(super) const fn index(self) -> usize {
        match self {
            Self::AToB => 0,
            Self::BToA => 1,
        }
    }

    pub(super) const fn other(self) -> Self {
        match self {
            Self::AToB => Self::BToA,
            Self::BToA => Self::AToB,
        }
    }
}

/// What a push or pop attempt asks the caller to do.
pub(super) enum Step {
    Done(usize),
    /// Try again at this tick.
    At(u64),
    /// Try again when the reader has freed this many bytes of the ring.
    Room(usize),
    /// Try again when the writer made progress.
    Peer,
}

/// Progress of one `write` call.
pub(super) struct Cursor {
    /// Bytes that crossed the UART.
    pub(super) done: usize,
    /// The UART (re)starts now: at the beginning and after waiting for the reader.
    pub(super) fresh: bool,
}

/// A simulated radio link; see the [module docs](super).
///
/// `M` is the mutex kind (`NoopRawMutex` when both endpoints run on one executor,
/// `CriticalSectionRawMutex` otherwise); `N` is the per-direction ring size.
/// `new` is `const`, so a link can be a `static`.
pub struct SimLink<M: RawMutex, const N: usize> {
    pub(super) config: SimConfig,
    pub(super) timing: Timing,
    pub(super) dirs: [Mutex<M, RefCell<Dir<N>>>; 2],
}

impl<M: RawMutex, const N: usize> SimLink<M, N> {
    const VALID: () = assert!(N > 0, "a SimLink needs a ring of at least one byte");

    /// A link with both directions empty and zero counters. `N = 0` does not compile.
    pub const fn new(config: SimConfig) -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::VALID;
        Self {
            config,
            timing: Timing::new(&config),
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

    /// Counters of one direction, busy times up to now.
    pub fn stats(&self, direction: Direction) -> SimStats {
        let t = &self.timing;
        let now = Self::now_units(t);
        let api = self.modem(direction).is_some();
        self.with(direction, |d| {
            let mut stats = d.stats;
            stats.serial_busy_us = t.micros(d.uart_busy);
            let ahead = if api {
                d.frames_iter().map(|f| f.air_after(now, t.ack_wait)).sum()
            } else {
                d.tx_end.saturating_sub(now)
            };
            stats.air_busy_us = t.micros(d.air_total.saturating_sub(ahead));
            stats
        })
    }

    /// Cuts `direction` from `from` until `until`: what the modem sends on the air in
    /// that window is lost. The modem does not know: it keeps taking bytes from the UART
    /// and sending them at its air rate, so flow control and the modem buffer behave as
    /// without the outage. A transparent modem loses each byte whose transmission ends
    /// in the window ([`SimStats::outage_bytes`]); an XBee modem's transmissions that
    /// end in the window fail ([`SimStats::outage_attempts`]), so an acknowledged frame
    /// is retried, and lost (status "no ACK") if every attempt falls in the window.
    /// Windows may overlap; bytes already on their way when a window opens arrive.
    ///
    /// # Errors
    /// [`OutageError::Empty`] if `until` is not after `from`, [`OutageError::Full`] if
    /// the direction already has [`MAX_OUTAGES`](super::MAX_OUTAGES) windows.
    pub fn add_outage(
        &self,
        direction: Direction,
        from: Instant,
        until: Instant,
    ) -> Result<(), OutageError> {
        self.with(direction, |d| {
            d.outages.add(from.as_ticks(), until.as_ticks())
        })
    }

    /// Bytes in the modem of `direction` now: waiting or on the air (transparent), or
    /// the API bytes of the frames not yet done and of a frame being received (XBee).
    pub fn modem_occupancy(&self, direction: Direction) -> usize {
        let t = &self.timing;
        let now = Self::now_units(t);
        let api = self.modem(direction).is_some();
        self.with(direction, |d| {
            let bytes = if api {
                d.frames_iter()
                    .filter(|f| f.end(t.ack_wait) > now)
                    .map(|f| u128::from(f.weight))
                    .sum::<u128>()
                    + u128::from(d.parser.in_progress())
            } else if t.air_byte == 0 {
                0
            } else {
                d.queued(now, t.air_byte)
            };
            usize::try_from(bytes).unwrap_or(usize::MAX)
        })
    }

    pub(super) fn with<R>(&self, direction: Direction, f: impl FnOnce(&mut Dir<N>) -> R) -> R {
        self.dirs[direction.index()].lock(|d| f(&mut d.borrow_mut()))
    }

    pub(super) fn now_units(t: &Timing) -> u128 {
        u128::from(Instant::now().as_ticks()) * t.scale
    }

    /// The XBee modem of `direction`, if it speaks API.
    pub(super) fn modem(&self, direction: Direction) -> Option<&XBeeModem> {
        match (&self.config.xbee, direction) {
            (Some(x), Direction::AToB) => Some(x),
            (Some(x), Direction::BToA) if x.api_uplink => Some(x),
            _ => None,
        }
    }

    /// The modem buffer, in bytes.
    pub(super) fn buffer(&self, modem: Option<&XBeeModem>) -> u128 {
        let min = modem.map_or(1, |x| x.variant.max_api_frame());
        self.config.buffer.max(min) as u128
    }

    pub(super) fn push(&self, direction: Direction, buf: &[u8], cursor: &mut Cursor) -> Step {
        let t = &self.timing;
        let now = Self::now_units(t);
        let modem = self.modem(direction);
        let wait = self.config.overflow == Overflow::Wait;
        let api = modem.map(|x| Modem {
            x,
            timing: t,
            buffer: self.buffer(Some(x)),
            source: match direction {
                Direction::AToB => x.address_a,
                Direction::BToA => x.address_b,
            },
        });
        self.with(direction, |d| {
            if cursor.fresh {
                d.uart_end = d.uart_end.max(now);
                cursor.fresh = false;
            }
            let before = cursor.done;
            let mut step = Step::Done(buf.len());
            while let Some(&byte) = buf.get(cursor.done) {
                let mut start = d.uart_end;
                if wait {
                    match self.room(d, start, modem) {
                        Ok(at) => start = start.max(at),
                        Err(need) => {
                            step = Step::Room(need);
                            break;
                        }
                    }
                }
                let end = start + t.uart_byte;
                if end > now {
                    step = Step::At(t.ticks_ceil(end));
                    break;
                }
                if wait
                    && let Some(x) = modem
                    && let Some(req) = d.parser.request(x.variant, byte)
                {
                    let need = rx_frame_len(x.variant, d.parser.length - req.rf_start);
                    if need <= N && N - d.len < need {
                        step = Step::Room(need);
                        break;
                    }
                }
                d.uart_end = end;
                d.uart_busy += t.uart_byte;
                d.stats.bytes_written = d.stats.bytes_written.wrapping_add(1);
                cursor.done += 1;
                match &api {
                    Some(m) => {
                        if let Some(status) = d.api_byte(m, byte, end) {
                            self.queue_status(direction, d, &status);
                        }
                    }
                    None => self.transparent_byte(d, byte, end),
                }
            }
            if matches!(step, Step::Room(_)) {
                cursor.fresh = true;
            }
            if cursor.done > before {
                d.rx_waker.wake();
            }
            step
        })
    }

    /// When (at or after `at`) the modem can take the next byte, or `Err(bytes)` if
    /// the receiver must first free that many bytes of the ring.
    pub(super) fn room(
        &self,
        d: &Dir<N>,
        at: u128,
        modem: Option<&XBeeModem>,
    ) -> Result<u128, usize> {
        let t = &self.timing;
        let buffer = self.buffer(modem);
        if modem.is_none() {
            if d.len >= N {
                return Err(1);
            }
            if t.air_byte == 0 || d.queued(at, t.air_byte) < buffer {
                return Ok(at);
            }
            // Room again once the queue has drained to `buffer - 1` bytes.
            return Ok(d.tx_end - (buffer - 1) * t.air_byte);
        }
        let mut bytes = u128::from(d.parser.in_progress());
        let mut count = 0;
        for f in d.frames_iter().filter(|f| f.end(t.ack_wait) > at) {
            bytes += u128::from(f.weight);
            count += 1;
        }
        if bytes < buffer && count < MODEM_FRAMES {
            return Ok(at);
        }
        for f in d.frames_iter().filter(|f| f.end(t.ack_wait) > at) {
            bytes -= u128::from(f.weight);
            count -= 1;
            if bytes < buffer && count < MODEM_FRAMES {
                return Ok(f.end(t.ack_wait));
            }
        }
        // Unreachable: the buffer holds the largest frame.
        Ok(at)
    }

    /// A byte enters the transparent modem at `at`.
    pub(super) fn transparent_byte(&self, d: &mut Dir<N>, byte: u8, at: u128) {
        let t = &self.timing;
        let full = t.air_byte > 0 && d.queued(at, t.air_byte) >= self.buffer(None);
        let s = &mut d.stats;
        if full {
            s.dropped_bytes = s.dropped_bytes.wrapping_add(1);
            return;
        }
        let sent_at = d.tx_end.max(at) + t.air_byte;
        if d.outages.cover(sent_at, t.scale) {
            // Sent into the void: it takes its air time, and nobody receives it.
            d.tx_end = sent_at;
            d.air_total += t.air_byte;
            d.stats.outage_bytes = d.stats.outage_bytes.wrapping_add(1);
            return;
        }
        let s = &mut d.stats;
        if d.len >= N {
            s.overrun_bytes = s.overrun_bytes.wrapping_add(1);
            return;
        }
        d.tx_end = d.tx_end.max(at) + t.air_byte;
        d.air_total += t.air_byte;
        let due = t.ticks_ceil(d.tx_end).saturating_add(t.latency);
        let byte = d.corrupt(byte, t.ber);
        d.insert(&[byte], due);
        d.stats.bytes_sent = d.stats.bytes_sent.wrapping_add(1);
    }

    /// Queues a transmit status for the writer of `direction` (its own reader, on the
    /// other direction's ring).
    fn queue_status(&self, direction: Direction, d: &mut Dir<N>, status: &Status) {
        let stored = self.with(direction.other(), |o| {
            let stored = o.insert(status.bytes(), status.due);
            if stored {
                o.rx_waker.wake();
            }
            stored
        });
        let s = &mut d.stats;
        if stored {
            s.statuses = s.statuses.wrapping_add(1);
        } else {
            s.statuses_lost = s.statuses_lost.wrapping_add(1);
        }
    }

    pub(super) fn pop(&self, direction: Direction, buf: &mut [u8]) -> Step {
        let now = Instant::now().as_ticks();
        self.with(direction, |d| {
            let mut n = 0;
            let mut last = 0;
            while n < buf.len() && d.len > 0 && d.due[d.head] <= now {
                buf[n] = d.data[d.head];
                last = d.due[d.head];
                d.head = (d.head + 1) % N;
                d.len -= 1;
                n += 1;
            }
            if n > 0 {
                d.partial = d.len > 0 && d.due[d.head] == last;
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

    /// When the modem will be done with everything it accepted.
    pub(super) fn drained_at(&self, direction: Direction) -> Option<u64> {
        let now = Self::now_units(&self.timing);
        self.with(direction, |d| {
            (d.tx_end > now).then(|| self.timing.ticks_ceil(d.tx_end))
        })
    }

    /// Waits until the reader of `direction` freed `need` bytes of the ring.
    pub(super) async fn wait_reader(&self, direction: Direction, need: usize) {
        poll_fn(|cx| {
            self.with(direction, |d| {
                if N - d.len >= need {
                    Poll::Ready(())
                } else {
                    d.tx_waker.register(cx.waker());
                    Poll::Pending
                }
            })
        })
        .await;
    }

    /// Waits until something was put in the ring of `direction`.
    pub(super) async fn wait_writer(&self, direction: Direction) {
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

    pub(super) async fn write(&self, direction: Direction, buf: &[u8]) -> usize {
        let mut cursor = Cursor {
            done: 0,
            fresh: true,
        };
        loop {
            match self.push(direction, buf, &mut cursor) {
                Step::Done(n) => return n,
                Step::At(tick) => Timer::at(Instant::from_ticks(tick)).await,
                Step::Room(need) => self.wait_reader(direction, need).await,
                Step::Peer => unreachable!("push never waits for a writer"),
            }
        }
    }

    pub(super) async fn read(&self, direction: Direction, buf: &mut [u8]) -> usize {
        if buf.is_empty() {
            return 0;
        }
        loop {
            match self.pop(direction, buf) {
                Step::Done(n) => return n,
                Step::At(tick) => Timer::at(Instant::from_ticks(tick)).await,
                Step::Peer | Step::Room(_) => self.wait_writer(direction).await,
            }
        }
    }
}
