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

//! # Pacing
//! A radio without flow control accepts bytes faster than it sends them and drops what
//! overflows its buffer. For such a device, configured with a [`Pacing`] link budget,
//! the writer models the modem's occupancy (a leaky bucket drained at the air rate) and
//! takes the next frame only when it fits in the budget: until then frames wait in the
//! queue, where a more important one can still overtake them.

//!
//! # Link layers
//! [`run_writer_with`] seals every frame with the device's
//! [`LinkLayer`] (the secure link) just before writing it.
//!
//! # Transmit statuses
//! For an XBee device configured with a [`DeliveryWindow`], the
//! writer gives every frame a fresh frame id and waits, before taking the next frame,
//! until fewer than `in_modem` frames await their transmit status (or the oldest timed
//! out); see [`delivery`](crate::delivery).

use core::future::poll_fn;
use core::task::Poll;

use embassy_futures::select::select;
use embassy_time::{Instant, Timer};
use embedded_io_async::Write;

use crate::delivery::DeliveryWindow;
use crate::downlink::{Device, Outgoing, Pacing, Port};
use crate::layer::{LinkLayer, Plain};

/// Runs the writer of `port`'s device forever, writing its frames to `io`. (The port is
/// borrowed, so it outlives a cancelled writer and can be given to the next one.)
pub async fn run_writer<W: Write>(port: &mut Port<'_>, io: W) -> ! {
    run_writer_with(port, io, &Plain).await
}

/// [`run_writer`] for a device with a [`LinkLayer`]: each frame is sealed by `layer` when
/// the writer takes it for the wire (so a frame counter follows the order on the wire,
/// after priority reordering); a frame the layer refuses is not written and counts as a
/// [`DropReason::Refused`](crate::DropReason::Refused) drop.
pub async fn run_writer_with<W: Write, L: LinkLayer + ?Sized>(
    port: &mut Port<'_>,
    mut io: W,
    layer: &L,
) -> ! {
    let device = port.device();
    let config = device.config();
    // Frames grow by up to this much when sealed: the modem model counts it.
    let reserve = usize::from(config.reserve);
    let mut modem = config.pacing.map(ModemModel::new);
    let window = config.delivery.filter(|_| config.transport.has_tx_status());
    // Without pacing or a status window nothing waits between two frames: the next frame
    // is taken under the lock that counts the last one, into the same `Outgoing`.
    let back_to_back = modem.is_none() && window.is_none();
    let mut frame = Outgoing::none(device);
    loop {
        if !frame.is_taken() {
            if let Some(window) = &window {
                wait_for_room(device, window).await;
            }
            if let Some(model) = &modem {
                // Wait for room for the most important frame; look again after waiting,
                // as a more important (perhaps longer) frame may have arrived meanwhile.
                let len = port.ready().await + reserve;
                let at = model.ready_at(len);
                if at > Instant::now().as_ticks() {
                    Timer::at(Instant::from_ticks(at)).await;
                    continue;
                }
            }
            frame = device.next().await;
        }
        if frame.seal_with(layer).is_err() {
            frame.refuse_in_place();
            continue;
        }
        if !back_to_back {
            // The clock is read only for the devices that use it.
            let now = Instant::now().as_ticks();
            if let Some(model) = &mut modem {
                model.add(frame.len(), now);
            }
            if let Some(window) = &window
                && let Some(id) = device.delivery_start(window, now)
            {
                config.transport.set_frame_id(frame.bytes_mut(), id);
            }
        }
        let mut written = io.write_all(&frame).await.is_ok();
        if written && config.flush {
            written = io.flush().await.is_ok();
        }
        // Counted here; if this future is dropped mid-write, `frame` counts itself as a
        // failed write when it drops. A frame taken here is never held across an
        // `.await` before its write.
        frame.finish_and_take(written, back_to_back);
    }
}

/// Waits until `device`'s modem may take one more frame under `window`: a transmit
/// status arrives, or the oldest outstanding frame times out.
async fn wait_for_room(device: Device<'_>, window: &DeliveryWindow) {
    loop {
        let deadline = match device.delivery_room(window, Instant::now().as_ticks(), None) {
            Ok(()) => return,
            Err(deadline) => deadline,
        };
        // Registered for the next status on the first poll, ready on the one after.
        let mut registered = false;
        let status = poll_fn(|cx| {
            if registered {
                return Poll::Ready(());
            }
            registered = true;
            match device.delivery_room(window, Instant::now().as_ticks(), Some(cx)) {
                Ok(()) => Poll::Ready(()),
                Err(_) => Poll::Pending,
            }
        });
        select(Timer::at(Instant::from_ticks(deadline)), status).await;
    }
}

/// The modelled occupancy of a radio modem: the time (in embassy-time ticks) at which
/// it will have sent everything handed to it, draining at the air rate.
#[derive(Debug, Clone, Copy)]
struct ModemModel {
    pacing: Pacing,
    empty_at: u64,
}

impl ModemModel {
    fn new(pacing: Pacing) -> Self {
        Self {
            pacing,
            empty_at: 0,
        }
    }

    /// The earliest time a frame of `len` bytes fits: when the bytes still in the modem
    /// plus the frame are at most the budget (a frame longer than the budget waits for
    /// an empty modem).
    fn ready_at(&self, len: usize) -> u64 {
        let budget = self.pacing.air_ticks(usize::from(self.pacing.modem_budget));
        let own = self.pacing.air_ticks(len);
        self.empty_at.saturating_sub(budget.saturating_sub(own))
    }

    /// `len` bytes handed to the modem at `now`.
    fn add(&mut self, len: usize, now: u64) {
        self.empty_at = self
            .empty_at
            .max(now)
            .saturating_add(self.pacing.air_ticks(len));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_modem_model_drains_at_the_air_rate() {
        let tick = embassy_time::TICK_HZ;
        // 1000 B/s, 300 bytes of budget.
        let mut m = ModemModel::new(Pacing::new(1000, 300));
        assert_eq!(m.ready_at(100), 0, "empty: a frame goes at once");
        m.add(100, 0);
        m.add(100, 0);
        // 200 bytes in: a third frame of 100 fits now, a fourth when 100 have left.
        assert_eq!(m.ready_at(100), 0);
        m.add(100, 0);
        assert_eq!(m.ready_at(100), tick / 10);
        // Longer than the budget: waits for an empty modem.
        assert_eq!(m.ready_at(400), 3 * tick / 10);
        // Idle time is not credited: after a silence the model starts empty.
        m.add(50, 10 * tick);
        assert_eq!(m.empty_at, 10 * tick + tick / 20);
        // An air rate of 0 is taken as 1 B/s rather than dividing by zero.
        let slow = ModemModel::new(Pacing::new(0, 10));
        assert_eq!(slow.pacing.air_ticks(2), 2 * tick);
    }
}
