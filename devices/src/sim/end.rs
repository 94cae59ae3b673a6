//! The endpoints of a link and their halves, as `embedded-io-async` devices.

use core::convert::Infallible;

use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Instant, Timer};
use embedded_io_async::{ErrorType, Read, Write};

use super::SimStats;
use super::link::{Direction, SimLink};

impl<M: RawMutex, const N: usize> SimLink<M, N> {
    /// The two endpoints, A and B. Take them once: each direction wakes one reader and
    /// one writer.
    pub fn endpoints(&self) -> (SimEnd<'_, M, N>, SimEnd<'_, M, N>) {
        (
            SimEnd::new(self, Direction::AToB, Direction::BToA),
            SimEnd::new(self, Direction::BToA, Direction::AToB),
        )
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
    /// Sends `buf` over the UART into the modem, one byte every `1 / serial_rate` s,
    /// and completes when the last byte has crossed: it always reports the whole of
    /// `buf`. With [`Overflow::Drop`](super::Overflow::Drop) the UART never stops (bytes the modem has no room
    /// for are dropped and counted); with [`Overflow::Wait`](super::Overflow::Wait) it stops while the modem
    /// (or the receiver's ring) is full.
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        Ok(self.link.write(self.direction, buf).await)
    }

    /// Waits until the modem is done with every byte it accepted (in the air; XBee:
    /// every attempt and ACK wait over).
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
