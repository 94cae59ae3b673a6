//! Deterministic simulation helpers: futures polled by hand while embassy-time's mock
//! clock advances, and simple devices.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::future::Future;
use std::pin::pin;
use std::task::{Context, Poll, Waker};

use embassy_time::{Duration, Instant, MockDriver, Timer};

/// The mock clock is global: tests of one binary that use it take this lock.
pub static MOCK_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Takes the mock-time lock and resets the clock to zero.
pub fn mock_time() -> std::sync::MutexGuard<'static, ()> {
    let guard = MOCK_TIME.lock().unwrap_or_else(|e| e.into_inner());
    MockDriver::get().reset();
    guard
}

/// Polls `fut` to completion, advancing mock time by `step` whenever it is pending.
pub fn run_with_mock_time<F: Future>(fut: F, step: Duration, max_steps: u64) -> F::Output {
    let mut fut = pin!(fut);
    let mut cx = Context::from_waker(Waker::noop());
    for _ in 0..max_steps {
        if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
            return v;
        }
        MockDriver::get().advance(step);
    }
    panic!("simulation did not finish in {max_steps} steps");
}

/// One byte time at `baud` (8N1: 10 bits per byte), in microseconds.
pub const fn byte_time_us(baud: u64) -> u64 {
    10 * 1_000_000 / baud
}

/// A UART transmitter that takes one byte time per byte, recording every write
/// (start, end, bytes).
pub struct SimUart<'a> {
    pub byte_us: u64,
    pub log: &'a RefCell<Vec<(Instant, Instant, Vec<u8>)>>,
}

impl embedded_io_async::ErrorType for SimUart<'_> {
    type Error = Infallible;
}

impl embedded_io_async::Write for SimUart<'_> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        let start = Instant::now();
        Timer::after(Duration::from_micros(self.byte_us * buf.len() as u64)).await;
        self.log
            .borrow_mut()
            .push((start, Instant::now(), buf.to_vec()));
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// A receiver that delivers scripted chunks, each after its delay, then waits forever.
pub struct ScriptedRx {
    pub chunks: VecDeque<(Duration, Vec<u8>)>,
}

impl embedded_io_async::ErrorType for ScriptedRx {
    type Error = Infallible;
}

impl embedded_io_async::Read for ScriptedRx {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let Some((delay, mut chunk)) = self.chunks.pop_front() else {
            return core::future::pending().await;
        };
        Timer::after(delay).await;
        let n = chunk.len().min(buf.len());
        buf[..n].copy_from_slice(&chunk[..n]);
        if n < chunk.len() {
            chunk.drain(..n);
            self.chunks.push_front((Duration::from_ticks(0), chunk));
        }
        Ok(n)
    }
}
