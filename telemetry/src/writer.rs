//! The writer task of a device: takes the most important frame from the device's queue,
//! writes it with `embedded_io_async::Write::write_all` (and `flush` when configured),
//! counts the outcome and releases the frame's arena memory.
//!
//! A stalled device blocks only its own writer (and so only its own queue, which sheds
//! by priority as it fills); a write error is counted as a
//! [`DropReason::WriteError`](crate::DropReason::WriteError) drop and the writer goes on
//! with the next frame.
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
        let mut written = io.write_all(&frame).await.is_ok();
        if written && flush {
            written = io.flush().await.is_ok();
        }
        queue.complete(frame.len(), written);
        // The frame's memory returns to the arena here, when its write is complete.
        drop(frame);
    }
}
