//! The writer task of a device: takes the most important frame from the device's queue,
//! writes it with `embedded_io_async::Write::write_all` (and `flush` when configured),
//! counts the outcome and releases the frame's arena memory.
//!
//! A stalled device blocks only its own writer (and so only its own queue, which sheds
//! by priority as it fills); a write error is counted as a
//! [`DropReason::WriteError`](crate::DropReason::WriteError) drop and the writer goes on
//! with the next frame. If the writer future is dropped in the middle of a write, that
//! frame is counted the same way.
//!
//! Embassy tasks cannot be generic, so a firmware wraps this in one task per device:
//!
//! ```ignore
//! #[embassy_executor::task]
//! async fn radio_writer(downlink: &'static MyDownlink, mut uart: BufferedUartTx<'static>) {
//!     let _ = pprz_telemetry::run_writer(downlink, 0, &mut uart).await;
//! }
//! ```

use core::convert::Infallible;
use core::fmt;

use embassy_sync::blocking_mutex::raw::RawMutex;
use embedded_io_async::Write;

use crate::downlink::Downlink;
use crate::queue::FrameQueue;

/// [`run_writer`] was given a device index the downlink does not have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NoSuchDevice(pub usize);

impl fmt::Display for NoSuchDevice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "the downlink has no device {}", self.0)
    }
}

impl core::error::Error for NoSuchDevice {}

/// Runs the writer of device `device` forever, writing its frames to `io`.
///
/// # Errors
/// Returns at once with [`NoSuchDevice`] if `device` is not a device of `downlink`;
/// otherwise never returns.
pub async fn run_writer<M: RawMutex, W: Write, const D: usize, const Q: usize>(
    downlink: &Downlink<'_, M, D, Q>,
    device: usize,
    io: &mut W,
) -> Result<Infallible, NoSuchDevice> {
    let (queue, flush) = downlink.writer_parts(device).ok_or(NoSuchDevice(device))?;
    loop {
        let frame = queue.receive().await;
        let len = frame.len();
        // If this future is dropped mid-write, the guard still reports the frame (as a
        // failed write) so the device's accounting stays balanced.
        let guard = InFlight {
            queue,
            len,
            done: false,
        };
        let mut written = io.write_all(&frame).await.is_ok();
        if written && flush {
            written = io.flush().await.is_ok();
        }
        guard.finish(written);
        // The frame's memory returns to the arena here, when its write is complete.
        drop(frame);
    }
}

/// Reports the outcome of the in-flight frame exactly once, also when the writer is
/// cancelled.
struct InFlight<'q, 'a, M: RawMutex, const Q: usize> {
    queue: &'q FrameQueue<'a, M, Q>,
    len: usize,
    done: bool,
}

impl<M: RawMutex, const Q: usize> InFlight<'_, '_, M, Q> {
    fn finish(mut self, written: bool) {
        self.done = true;
        self.queue.complete(self.len, written);
    }
}

impl<M: RawMutex, const Q: usize> Drop for InFlight<'_, '_, M, Q> {
    fn drop(&mut self) {
        if !self.done {
            self.queue.complete(self.len, false);
        }
    }
}
