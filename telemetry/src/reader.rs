//! The datalink readers: one [`Reader`] per device/transport pair reads bytes from an
//! `embedded_io_async::Read`, decodes frames incrementally, filters them by destination
//! and hands them to the [`Datalink`]'s subscriber [`Registry`].
//!
//! # One transport per device, one device per transport
//! A [`Reader`] *owns* its device and its transport's decoder, so the pairing is 1:1 by
//! construction: a device cannot be read by two transports, and a decoder cannot read
//! two devices. It also holds the [`Device`] handle of the same device in the downlink,
//! taken from that device's port, so every message it delivers carries the device its
//! replies go to.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_telemetry::reader::{Datalink, Reader};
//! use pprz_telemetry::{DeviceConfig, Downlink, FrameArena};
//! use pprz_telemetry::pprz_transports::{AnyTransport, PprzV2};
//!
//! static ARENA: FrameArena<M, 1024> = FrameArena::new();
//! static DOWNLINK: Downlink<'static, M, 1, 8> =
//!     Downlink::new(&ARENA, 7, [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()))]);
//! static DATALINK: Datalink<'static, M, 4> = Datalink::new(7);
//!
//! let [radio] = DOWNLINK.ports().unwrap();
//! let uart: &[u8] = &[0x99, 0x08, 0x00, 0x07, 0x02, 0x08, 0x19, 0x49]; // PING, any Read
//! let mut reader = Reader::<_, _>::new(uart, PprzV2::new(), radio.device());
//! reader.feed(&[0x99, 0x08, 0x00, 0x07, 0x02, 0x08, 0x19, 0x49], &DATALINK);
//! assert_eq!(DATALINK.stats().received, 1);
//! // In a task: `reader.run(&DATALINK).await`, next to `run_writer(&mut radio, uart_tx)`.
//! ```
//!
//! Reading the same device with a second transport does not compile:
//!
//! ```compile_fail,E0499
//! # use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! # use pprz_telemetry::reader::Reader;
//! # use pprz_telemetry::{DeviceConfig, Downlink, FrameArena};
//! # use pprz_telemetry::pprz_transports::{AnyTransport, PprzV1, PprzV2};
//! # static ARENA: FrameArena<M, 1024> = FrameArena::new();
//! # static DOWNLINK: Downlink<'static, M, 1, 8> =
//! #     Downlink::new(&ARENA, 7, [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()))]);
//! # let [radio] = DOWNLINK.ports().unwrap();
//! let mut uart: &[u8] = &[];
//! let a = Reader::<_, _>::new(&mut uart, PprzV2::new(), radio.device());
//! let b = Reader::<_, _>::new(&mut uart, PprzV1::new(2), radio.device()); // `uart` is a's
//! drop((a, b));
//! ```
//!
//! Transmit statuses (XBee API) are not messages: the reader hands them to its device's
//! writer ([`Device::tx_status`]), which counts them and frees the frames' places in the
//! modem ([`delivery`](crate::delivery)).
//!
//! # Destination filtering
//! PPRZ v2 frames carry a destination: frames for our aircraft id or for broadcast
//! (`0xFF`) are accepted, the rest are counted in [`UplinkStats::not_for_us`]. PPRZ v1
//! frames carry none and are accepted. To forward frames for other aircraft instead,
//! readers deliver to a [`Relay`](crate::relay::Relay) around the datalink.
//!
//! # Idle flush
//! A false start byte announcing a long frame holds the frames behind it until the
//! announced length has arrived. When bytes are pending and the line stays idle for the
//! reader's idle time, the reader flushes its decoder so they come out. (This races the
//! device's `read` against a timer only while bytes are pending; devices whose `read` is
//! not cancel-safe should set the idle time to `None`.)

use core::cell::RefCell;

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Duration, Instant, Timer};
use embedded_io_async::Read;
use pprz_transports::{BROADCAST_ID, Decoder, DecoderStats, Frame, Framing, MAX_FRAME_LEN, PprzV2};

use crate::downlink::Device;
use crate::health::HealthInput;
use crate::layer::{LinkLayer, Opened};
use crate::registry::{Filter, Received, Registry, RegistryFull, Subscriber, Trust};

/// Counters of the uplink (all readers of one [`Datalink`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UplinkStats {
    /// Messages accepted (for us or broadcast).
    pub received: u32,
    /// PPRZ v2 frames addressed to another aircraft.
    pub not_for_us: u32,
    /// Accepted messages no subscriber wanted.
    pub unhandled: u32,
    /// Errors reported by devices' `read`.
    pub read_errors: u32,
    /// When the last message was accepted.
    pub last_received: Option<Instant>,
}

/// Where a [`Reader`] delivers the frames it decodes on devices that live for `'d`:
/// a [`Datalink`], or a structure built around one.
pub trait Inbox<'d> {
    /// Handles one decoded frame.
    fn deliver(&self, rx: &Received<'_, 'd>);
    /// Counts an error reported by the device's `read`.
    fn read_error(&self);
}

/// A built-in handler run before the subscribers (the one-link facade's services).
pub(crate) trait Handler<'d> {
    /// Handles `rx` if it is one of its messages; returns whether it was.
    fn handle(&self, rx: &Received<'_, 'd>) -> bool;
}

/// The uplink side of an aircraft: its id, the subscribers of received messages and
/// the uplink counters. Shared by all readers; `const`, so it can be a `static`.
pub struct Datalink<'a, M: RawMutex, const N: usize> {
    ac_id: u8,
    registry: Registry<'a, M, N>,
    stats: Mutex<M, RefCell<UplinkStats>>,
    health: Option<&'a dyn HealthInput>,
}

impl<'a, M: RawMutex, const N: usize> Datalink<'a, M, N> {
    /// The datalink of aircraft `ac_id`, with an empty registry of `N` subscriptions.
    pub const fn new(ac_id: u8) -> Self {
        Self {
            ac_id,
            registry: Registry::new(),
            stats: Mutex::new(RefCell::new(UplinkStats {
                received: 0,
                not_for_us: 0,
                unhandled: 0,
                read_errors: 0,
                last_received: None,
            })),
            health: None,
        }
    }

    /// [`new`](Self::new), and every accepted frame drives `health` (see
    /// [`health`](crate::health) for what counts).
    pub const fn with_health(ac_id: u8, health: &'a dyn HealthInput) -> Self {
        let mut datalink = Self::new(ac_id);
        datalink.health = Some(health);
        datalink
    }

    /// Our aircraft id.
    pub fn ac_id(&self) -> u8 {
        self.ac_id
    }

    /// Subscribes to received messages; see [`Registry::subscribe`].
    ///
    /// # Errors
    /// [`RegistryFull`] when `N` subscriptions exist already.
    pub fn subscribe(
        &self,
        filter: Filter,
        subscriber: &'a dyn Subscriber<'a>,
    ) -> Result<(), RegistryFull> {
        self.registry.subscribe(filter, subscriber)
    }

    /// The subscriber registry.
    pub fn registry(&self) -> &Registry<'a, M, N> {
        &self.registry
    }

    /// A snapshot of the uplink counters.
    pub fn stats(&self) -> UplinkStats {
        self.stats.lock(|s| *s.borrow())
    }

    fn count(&self, f: impl FnOnce(&mut UplinkStats)) {
        self.stats.lock(|s| f(&mut s.borrow_mut()));
    }

    /// Applies the destination filter and counts: when `frame` was accepted, if it is for
    /// us.
    fn accept(&self, frame: &Frame<'_>) -> Option<Instant> {
        if let Some(dest) = frame.destination()
            && dest != self.ac_id
            && dest != BROADCAST_ID
        {
            self.count(|s| s.not_for_us = s.not_for_us.wrapping_add(1));
            return None;
        }
        let now = Instant::now();
        self.count(|s| {
            s.received = s.received.wrapping_add(1);
            s.last_received = Some(now);
        });
        Some(now)
    }

    /// Handles one received frame: destination filter, counters, link health (the
    /// datalink's, and `health` if any), then `first` (built-in services, if any) and the
    /// registry's subscribers.
    pub(crate) fn deliver_with(
        &self,
        rx: &Received<'_, 'a>,
        first: Option<&dyn Handler<'a>>,
        health: Option<&dyn HealthInput>,
    ) {
        let Some(now) = self.accept(&rx.frame) else {
            return;
        };
        for h in [self.health, health].into_iter().flatten() {
            h.frame(rx, now);
        }
        let by_first = first.is_some_and(|f| f.handle(rx));
        let by_subscribers = self.registry.dispatch(rx) > 0;
        if !(by_first || by_subscribers) {
            self.count(|s| s.unhandled = s.unhandled.wrapping_add(1));
        }
    }
}

impl<'a, M: RawMutex, const N: usize> Inbox<'a> for Datalink<'a, M, N> {
    fn deliver(&self, rx: &Received<'_, 'a>) {
        self.deliver_with(rx, None, None);
    }

    fn read_error(&self) {
        self.count(|s| s.read_errors = s.read_errors.wrapping_add(1));
    }
}

/// Reads one device with one transport; see the [module documentation](self).
///
/// `'d` is the lifetime of the downlink whose [`Device`] handle the reader holds; `N` is
/// the decoder's buffer: the longest frame it can hold.
pub struct Reader<'d, R, F: Framing, const N: usize = MAX_FRAME_LEN> {
    io: R,
    decoder: Decoder<F, N>,
    device: Device<'d>,
    idle: Option<Duration>,
}

impl<'d, R: Read, F: Framing, const N: usize> Reader<'d, R, F, N> {
    /// A reader of `io` with `framing`, for the device `device` of the downlink (from
    /// the device's [`Port::device`](crate::Port::device)): messages it delivers carry
    /// that device, where replies go. Idle flush after 20 ms.
    pub fn new(io: R, framing: F, device: Device<'d>) -> Self {
        Self {
            io,
            decoder: Decoder::new(framing),
            device,
            idle: Some(Duration::from_millis(20)),
        }
    }

    /// Sets the idle time after which pending bytes are flushed (`None`: never).
    pub fn idle_flush(mut self, idle: Option<Duration>) -> Self {
        self.idle = idle;
        self
    }

    /// The device this reader reads (and replies on).
    pub fn device(&self) -> Device<'d> {
        self.device
    }

    /// Hands the transmit statuses the decoder found (XBee API) to the device's writer.
    fn pass_tx_statuses(&mut self) {
        while let Some(status) = self.decoder.take_tx_status() {
            self.device.tx_status(&status);
        }
    }

    /// Counters of this reader's decoder (frames, checksum errors, ...).
    pub fn decoder_stats(&self) -> DecoderStats {
        *self.decoder.stats()
    }

    /// Feeds bytes that arrived by other means (a DMA buffer, a datagram), delivering
    /// every complete frame to `inbox`; returns how many frames were decoded.
    pub fn feed<'x, I: Inbox<'x> + ?Sized>(&mut self, bytes: &[u8], inbox: &I) -> usize
    where
        'd: 'x,
    {
        let mut input = bytes;
        let mut frames = 0;
        // Frames that arrived whole in `bytes` are read in place, without a copy.
        while let Some(frame) = self.decoder.feed_borrowed(&mut input) {
            inbox.deliver(&Received::new(self.device, frame));
            frames += 1;
        }
        self.pass_tx_statuses();
        frames
    }

    /// End of input or idle line: delivers the frames held behind an incomplete false
    /// start; returns how many.
    pub fn flush<'x, I: Inbox<'x> + ?Sized>(&mut self, inbox: &I) -> usize
    where
        'd: 'x,
    {
        let mut frames = 0;
        while let Some(frame) = self.decoder.flush() {
            inbox.deliver(&Received::new(self.device, frame));
            frames += 1;
        }
        self.pass_tx_statuses();
        frames
    }

    /// Reads and delivers forever. Read errors are counted and reading goes on (after a
    /// short pause, so a failing device cannot spin the executor); so is a read that
    /// reports more bytes than it was given (a device breaking the `Read` contract).
    pub async fn run<'x, I: Inbox<'x> + ?Sized>(&mut self, inbox: &I) -> !
    where
        'd: 'x,
    {
        let mut buf = [0u8; 64];
        loop {
            let pending = self.decoder.buffered() > 0;
            let read = match self.idle {
                Some(idle) if pending => {
                    // Saturating: an idle time too long to add to the clock never ends.
                    let at = Instant::now().saturating_add(idle);
                    match select(self.io.read(&mut buf), Timer::at(at)).await {
                        Either::First(result) => Some(result),
                        Either::Second(()) => None,
                    }
                }
                _ => Some(self.io.read(&mut buf).await),
            };
            match read {
                Some(Ok(0)) | None => {
                    // End of input or idle line.
                    self.flush(inbox);
                    if matches!(read, Some(Ok(0))) {
                        Timer::after(Duration::from_millis(10)).await;
                    }
                }
                Some(Ok(n)) if n <= buf.len() => {
                    self.feed(buf.get(..n).unwrap_or_default(), inbox);
                }
                Some(Ok(_) | Err(_)) => {
                    inbox.read_error();
                    Timer::after(Duration::from_millis(10)).await;
                }
            }
        }
    }
}

/// An [`Inbox`] that opens every frame with a [`LinkLayer`] before handing it to
/// `inbox`: what a device's [`Reader`] delivers to when the
/// device has a layer (`reader.run(&Layered::new(&layer, &datalink))`).
#[derive(Debug)]
pub struct Layered<'l, L: ?Sized, I: ?Sized> {
    layer: &'l L,
    inbox: &'l I,
}

impl<'l, L: ?Sized, I: ?Sized> Layered<'l, L, I> {
    /// Frames from the reader go through `layer`, then to `inbox`.
    pub const fn new(layer: &'l L, inbox: &'l I) -> Self {
        Self { layer, inbox }
    }
}

impl<'d, L: LinkLayer + ?Sized, I: Inbox<'d> + ?Sized> Inbox<'d> for Layered<'_, L, I> {
    fn deliver(&self, rx: &Received<'_, 'd>) {
        let mut out = [0u8; MAX_FRAME_LEN];
        // Behind a layer that authenticates, only what it authenticated is trusted.
        let unvouched = if self.layer.authenticates() {
            Trust::Unauthenticated
        } else {
            rx.trust
        };
        let (len, trust) = match self.layer.open(&rx.frame, &mut out) {
            Opened::Withheld => return,
            Opened::Unchanged => {
                return self.inbox.deliver(&Received {
                    trust: unvouched,
                    ..*rx
                });
            }
            Opened::Rewritten(len) => (len, unvouched),
            Opened::Authenticated(len) => (len, Trust::Authenticated),
        };
        // A layer that returns a bad frame delivers nothing (nothing to count it under:
        // a bug of the layer, not an input).
        let Some(bytes) = out.get(..len) else {
            return;
        };
        if let Ok(frame) = PprzV2::new().view(bytes) {
            self.inbox.deliver(&Received {
                device: rx.device,
                frame,
                trust,
            });
        }
    }

    fn read_error(&self) {
        self.inbox.read_error();
    }
}
