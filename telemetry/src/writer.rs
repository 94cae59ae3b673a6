//! The writer task of a device: takes the most important frame from the device's
//! [`Port`], writes it with `embedded_io_async::Write::write` until the whole frame is out
//! (and `flush` when the device is configured so), counts the outcome and releases the
//! frame's arena memory.
//!
//! A stalled device blocks only its own writer (and so only its own queue, which sheds
//! by priority as it fills); a write error is counted as a
//! [`DropReason::WriteError`] drop and the writer goes on
//! with the next frame. So is a write that reports no byte written or more bytes than it
//! was given (a device breaking the `Write` contract; `write_all` would panic). If the
//! writer future is dropped in the middle of a write, that frame is counted the same way.
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

use core::fmt;
use core::future::poll_fn;
use core::task::{Context, Poll};

use embassy_futures::select::select;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Instant, Timer};
use embedded_io_async::Write;

use crate::arena::FrameBuf;
use crate::delivery::DeliveryWindow;
use crate::downlink::{Device, Downlink, Pacing};
use crate::layer::{LinkLayer, Plain};
use crate::stats::DropReason;

/// [`Downlink::ports`] was called before: each device has one port, handed out once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PortsTaken;

impl fmt::Display for PortsTaken {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("the downlink's ports were taken already (one writer per device)")
    }
}

impl core::error::Error for PortsTaken {}

/// The writer's side of a downlink: its ports, handed out here, next to their consumer.
impl<'a, M: RawMutex + Sync, const D: usize, const Q: usize> Downlink<'a, M, D, Q> {
    /// The ports of the devices, in the order of the configurations given to
    /// [`new`](Self::new): one per device, handed out once. Each goes to the device's
    /// writer task ([`run_writer`](crate::run_writer)); its [`Port::device`] handle names
    /// the device for readers (replies) and targeted sends.
    ///
    /// ```
    /// # use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
    /// # use pprz_telemetry::{DeviceConfig, Downlink, FrameArena};
    /// # use pprz_telemetry::pprz_transports::{AnyTransport, PprzLog, PprzV2};
    /// static ARENA: FrameArena<M, 2048> = FrameArena::new();
    /// static DOWNLINK: Downlink<'static, M, 2, 16> = Downlink::new(&ARENA, 7, [
    ///     DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),
    ///     DeviceConfig::new(AnyTransport::PprzLog(PprzLog::TELEMETRY)),
    /// ]);
    /// let [radio, log] = DOWNLINK.ports().unwrap();
    /// assert_eq!((radio.device().index(), log.device().index()), (0, 1));
    /// assert!(DOWNLINK.ports().is_err()); // one writer per device
    /// ```
    ///
    /// # Errors
    /// [`PortsTaken`] if the ports were handed out before.
    pub fn ports(&self) -> Result<[Port<'_>; D], PortsTaken> {
        if !self.claim_ports() {
            return Err(PortsTaken);
        }
        Ok(core::array::from_fn(|index| Port {
            device: self.device(index),
        }))
    }
}

/// The consumer side of one device's queue, handed out once per device by
/// [`Downlink::ports`]: for the device's writer task ([`run_writer`]),
/// or for code that drains the queue itself. Not copyable, so a device has one writer,
/// and a port has one frame out at a time: the per-level counters of a queue cannot be
/// corrupted by a second consumer.
///
/// A second port of the same device cannot be made, by copy or by clone:
///
/// ```compile_fail,E0382
/// # use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
/// # use pprz_telemetry::{DeviceConfig, Downlink, FrameArena};
/// # use pprz_telemetry::pprz_transports::PprzV2;
/// # static ARENA: FrameArena<M, 1024> = FrameArena::new();
/// # static DOWNLINK: Downlink<'static, M, 1, 8> =
/// #     Downlink::new(&ARENA, 7, [DeviceConfig::new(PprzV2::new().into())]);
/// let [port] = DOWNLINK.ports().unwrap();
/// let writer_a = port;
/// let writer_b = port; // moved already
/// ```
///
/// nor can a second frame be taken before the first is finished:
///
/// ```compile_fail,E0499
/// # use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
/// # use pprz_telemetry::{DeviceConfig, Downlink, FrameArena};
/// # use pprz_telemetry::pprz_transports::PprzV2;
/// # static ARENA: FrameArena<M, 1024> = FrameArena::new();
/// # static DOWNLINK: Downlink<'static, M, 1, 8> =
/// #     Downlink::new(&ARENA, 7, [DeviceConfig::new(PprzV2::new().into())]);
/// let [mut port] = DOWNLINK.ports().unwrap();
/// let first = port.try_next();
/// let second = port.try_next();
/// drop((first, second));
/// ```
pub struct Port<'d> {
    device: Device<'d>,
}

impl fmt::Debug for Port<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Port")
            .field("device", &self.device.index())
            .finish()
    }
}

impl<'d> Port<'d> {
    /// The handle of this port's device.
    pub fn device(&self) -> Device<'d> {
        self.device
    }

    /// The most important frame waiting, if any. Report how its write went with
    /// [`Outgoing::finish`]; dropping it unreported counts a failed write.
    pub fn try_next(&mut self) -> Option<Outgoing<'_>> {
        self.receive(None)
    }

    /// The length of the most important frame waiting, if any, without taking it (a
    /// more important frame may arrive before the next [`try_next`](Self::try_next)).
    pub fn peek_len(&self) -> Option<usize> {
        self.device.peek_len(None)
    }

    /// Waits until a frame waits, without taking it; returns the length of the most
    /// important one (as [`peek_len`](Self::peek_len)).
    pub async fn ready(&self) -> usize {
        let device = self.device;
        poll_fn(|cx| match device.peek_len(Some(cx)) {
            Some(len) => Poll::Ready(len),
            None => Poll::Pending,
        })
        .await
    }

    /// Waits for the most important frame; as [`try_next`](Self::try_next).
    pub async fn next(&mut self) -> Outgoing<'_> {
        next_frame(self.device).await
    }

    /// Takes the most important frame; as [`receive`].
    pub(crate) fn receive(&self, cx: Option<&mut Context<'_>>) -> Option<Outgoing<'d>> {
        receive(self.device, cx)
    }
}

/// Takes `device`'s most important frame; with a context, registers it for the next
/// frame when there is none. For the device's one consumer: its [`Port`], or the writer
/// task that holds the port.
fn receive<'d>(device: Device<'d>, cx: Option<&mut Context<'_>>) -> Option<Outgoing<'d>> {
    let frame = device.take_frame(cx)?;
    Some(Outgoing {
        frame: Some(frame),
        device,
    })
}

/// Waits for `device`'s most important frame; as [`receive`].
async fn next_frame(device: Device<'_>) -> Outgoing<'_> {
    poll_fn(|cx| match receive(device, Some(cx)) {
        Some(frame) => Poll::Ready(frame),
        None => Poll::Pending,
    })
    .await
}

/// A frame taken from a device's queue: its bytes, to write to the device, then
/// [`finish`](Self::finish) to count the outcome. Dropped unfinished (e.g. a writer
/// cancelled mid-write), it counts as a failed write, so every frame is counted once.
/// Its arena memory is released when it is dropped.
pub struct Outgoing<'p> {
    /// The frame; `None` once its outcome is counted (and its memory released).
    frame: Option<FrameBuf<'p>>,
    device: Device<'p>,
}

impl fmt::Debug for Outgoing<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Outgoing")
            .field("device", &self.device.index())
            .field("len", &self.len())
            .finish()
    }
}

impl<'p> Outgoing<'p> {
    /// The frame's bytes, to change before writing (the writer sets XBee frame ids).
    pub(crate) fn bytes_mut(&mut self) -> &mut [u8] {
        self.frame.as_deref_mut().unwrap_or_default()
    }

    /// Lets `layer` rewrite the frame for the wire in place, in the whole of its arena
    /// block (the frame plus the spare bytes its device reserves,
    /// [`DeviceConfig::reserve`]). `Err` if the layer refused it: the frame must not be
    /// written (its bytes are unspecified) and is to be [`refused`](Self::refuse).
    pub(crate) fn seal_with<L: LinkLayer + ?Sized>(&mut self, layer: &L) -> Result<(), ()> {
        let frame = self.frame.as_mut().ok_or(())?;
        let len = frame.len();
        let capacity = frame.set_len_to_capacity();
        match layer.seal(frame, len) {
            Ok(sealed) if sealed <= capacity => {
                frame.truncate(sealed);
                Ok(())
            }
            _ => {
                frame.truncate(len);
                Err(())
            }
        }
    }

    /// Counts the frame as sent (`written`) or as a
    /// [`DropReason::WriteError`] drop, and releases its memory.
    pub fn finish(self, written: bool) {
        self.finish_with(if written {
            Ok(())
        } else {
            Err(DropReason::WriteError)
        });
    }

    /// Counts the frame as a [`DropReason::Refused`] drop (the device's link layer would
    /// not send it) and releases its memory.
    pub fn refuse(self) {
        self.finish_with(Err(DropReason::Refused));
    }

    /// A finished `Outgoing` of `device` (holding no frame), for a writer's loop.
    pub(crate) fn none(device: Device<'p>) -> Self {
        Self {
            frame: None,
            device,
        }
    }

    /// Whether it holds a frame (not finished yet).
    pub(crate) fn is_taken(&self) -> bool {
        self.frame.is_some()
    }

    /// [`finish`](Self::finish) in place; with `take_next`, also takes the device's next
    /// frame into `self` if one waits, under the same lock (for a writer that writes the
    /// next frame at once).
    pub(crate) fn finish_and_take(&mut self, written: bool, take_next: bool) {
        let Some(frame) = self.frame.take() else {
            return;
        };
        let outcome = if written {
            Ok(())
        } else {
            Err(DropReason::WriteError)
        };
        self.frame = self.device.complete(frame, outcome, take_next);
    }

    /// [`refuse`](Self::refuse) in place.
    pub(crate) fn refuse_in_place(&mut self) {
        if let Some(frame) = self.frame.take() {
            self.device.complete(frame, Err(DropReason::Refused), false);
        }
    }

    fn finish_with(mut self, outcome: Result<(), DropReason>) {
        if let Some(frame) = self.frame.take() {
            self.device.complete(frame, outcome, false);
        }
    }
}

impl core::ops::Deref for Outgoing<'_> {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        self.frame.as_deref().unwrap_or_default()
    }
}

impl Drop for Outgoing<'_> {
    fn drop(&mut self) {
        if let Some(frame) = self.frame.take() {
            self.device
                .complete(frame, Err(DropReason::WriteError), false);
        }
    }
}

/// Runs the writer of `port`'s device forever, writing its frames to `io`. (The port is
/// borrowed, so it outlives a cancelled writer and can be given to the next one.)
pub async fn run_writer<W: Write>(port: &mut Port<'_>, io: W) -> ! {
    run_writer_with(port, io, &Plain).await
}

/// [`run_writer`] for a device with a [`LinkLayer`]: each frame is sealed by `layer` when
/// the writer takes it for the wire (so a frame counter follows the order on the wire,
/// after priority reordering); a frame the layer refuses is not written and counts as a
/// [`DropReason::Refused`] drop.
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
            frame = next_frame(device).await;
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
        let mut written = write_frame(&mut io, &frame).await;
        if written && config.flush {
            written = io.flush().await.is_ok();
        }
        // Counted here; if this future is dropped mid-write, `frame` counts itself as a
        // failed write when it drops. A frame taken here is never held across an
        // `.await` before its write.
        frame.finish_and_take(written, back_to_back);
    }
}

/// Writes the whole of `frame` to `io`, in as many writes as it takes: `false` if a write
/// fails, reports no byte written, or reports more bytes than it was given (where
/// `embedded_io_async`'s `write_all` would panic).
async fn write_frame<W: Write>(io: &mut W, mut frame: &[u8]) -> bool {
    if frame.is_empty() {
        return true;
    }
    loop {
        match io.write(frame).await {
            // The usual case: the device took the whole frame.
            Ok(n) if n == frame.len() => return true,
            Ok(n) if n > 0 => match frame.get(n..) {
                Some(rest) => frame = rest,
                None => return false,
            },
            _ => return false,
        }
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
    /// The air time of the modem's budget, in ticks.
    budget: u64,
    empty_at: u64,
}

impl ModemModel {
    fn new(pacing: Pacing) -> Self {
        Self {
            pacing,
            budget: pacing.air_ticks(usize::from(pacing.modem_budget)),
            empty_at: 0,
        }
    }

    /// The earliest time a frame of `len` bytes fits: when the bytes still in the modem
    /// plus the frame are at most the budget (a frame longer than the budget waits for
    /// an empty modem).
    fn ready_at(&self, len: usize) -> u64 {
        let own = self.pacing.air_ticks(len);
        self.empty_at
            .saturating_sub(self.budget.saturating_sub(own))
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
