//! The writer task of a device: takes the most important frame from the device's
//! [`Port`], writes it with `embedded_io_async::Write::write_all` (and `flush` when the
//! device is configured so), counts the outcome and releases the frame's arena memory.
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
//! async fn radio_writer(mut port: Port<'static>, uart: BufferedUartTx<'static>) -> ! {
//!     pprz_telemetry::run_writer(&mut port, uart).await
//! }
//! ```

use embedded_io_async::Write;

use crate::downlink::Port;

/// Runs the writer of `port`'s device forever, writing its frames to `io`. (The port is
/// borrowed, so it outlives a cancelled writer and can be given to the next one.)
pub async fn run_writer<W: Write>(port: &mut Port<'_>, mut io: W) -> ! {
    let flush = port.device().config().flush;
    loop {
        let frame = port.next().await;
        let mut written = io.write_all(&frame).await.is_ok();
        if written && flush {
            written = io.flush().await.is_ok();
        }
        // Counted here; if this future is dropped mid-write, `frame` counts itself as a
        // failed write when it drops.
        frame.finish(written);
    }
}
