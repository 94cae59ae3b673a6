//! The datalink readers: one [`Reader`] per device/transport pair reads bytes from an
//! `embedded_io_async::Read`, decodes frames incrementally, filters them by destination
//! and hands them to the [`Datalink`]'s subscriber [`Registry`].
//!
//! # One transport per device, one device per transport
//! A [`Reader`] *owns* its device and its transport's decoder, so the pairing is 1:1 by
//! construction (the thesis' registration step, enforced by the compiler): a device
//! cannot be read by two transports, and a decoder cannot read two devices.
//!
//! ```
//! use pprz_telemetry::reader::Reader;
//! use pprz_telemetry::pprz_transports::PprzV2;
//! let mut uart: &[u8] = &[0x99, 0x08, 0x00, 0x07, 0x02, 0x08, 0x19, 0x49]; // PING, any Read
//! let radio = Reader::<_, _>::new(&mut uart, PprzV2::new(), 0);
//! assert_eq!(radio.link(), 0);
//! ```
//!
//! Reading the same device with a second transport does not compile:
//!
//! ```compile_fail,E0499
//! use pprz_telemetry::reader::Reader;
//! use pprz_telemetry::pprz_transports::{PprzV1, PprzV2};
//! let mut uart: &[u8] = &[];
//! let radio = Reader::<_, _>::new(&mut uart, PprzV2::new(), 0);
//! let other = Reader::<_, _>::new(&mut uart, PprzV1::new(2), 1); // `uart` is the radio's
//! drop((radio, other));
//! ```
//!
//! # Destination filtering
//! PPRZ v2 frames carry a destination: frames for our aircraft id or for broadcast
//! (`0xFF`) are accepted, the rest are counted in [`UplinkStats::not_for_us`]. PPRZ v1
//! frames carry none and are accepted.
//!
//! # Idle flush
//! A false start byte announcing a long frame holds the frames behind it until the
//! announced length has arrived. When bytes are pending and the line stays idle for the
//! reader's idle time, the reader flushes its decoder so they come out. (This races the
//! device's `read` against a timer only while bytes are pending; devices whose `read` is
//! not cancel-safe should set the idle time to `None`.)

use core::cell::RefCell;
use core::convert::Infallible;

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Duration, Instant, Timer};
use embedded_io_async::Read;
use pprz_transports::{BROADCAST_ID, Decoder, DecoderStats, Frame, Framing, MAX_FRAME_LEN};

use crate::registry::{Received, Registry};

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

/// The uplink side of an aircraft: its id and the subscribers of received messages.
/// Shared by all readers.
pub struct Datalink<'a, M: RawMutex, const N: usize> {
    ac_id: u8,
    registry: Registry<'a, N>,
    stats: Mutex<M, RefCell<UplinkStats>>,
}

impl<'a, M: RawMutex, const N: usize> Datalink<'a, M, N> {
    /// The datalink of aircraft `ac_id`, with a registry filled at start-up.
    pub const fn new(ac_id: u8, registry: Registry<'a, N>) -> Self {
        Self {
            ac_id,
            registry,
            stats: Mutex::new(RefCell::new(UplinkStats {
                received: 0,
                not_for_us: 0,
                unhandled: 0,
                read_errors: 0,
                last_received: None,
            })),
        }
    }

    /// Our aircraft id.
    pub fn ac_id(&self) -> u8 {
        self.ac_id
    }

    /// A snapshot of the uplink counters.
    pub fn stats(&self) -> UplinkStats {
        self.stats.lock(|s| *s.borrow())
    }

    fn count(&self, f: impl FnOnce(&mut UplinkStats)) {
        self.stats.lock(|s| f(&mut s.borrow_mut()));
    }

    /// Handles one decoded frame received on `link`: destination filter, counters,
    /// subscribers.
    pub fn handle(&self, link: usize, frame: Frame<'_>) {
        if let Some(dest) = frame.destination()
            && dest != self.ac_id
            && dest != BROADCAST_ID
        {
            self.count(|s| s.not_for_us = s.not_for_us.wrapping_add(1));
            return;
        }
        let now = Instant::now();
        self.count(|s| {
            s.received = s.received.wrapping_add(1);
            s.last_received = Some(now);
        });
        if self.registry.dispatch(&Received { link, frame }) == 0 {
            self.count(|s| s.unhandled = s.unhandled.wrapping_add(1));
        }
    }
}

/// Reads one device with one transport; see the [module documentation](self).
///
/// `N` is the decoder's buffer: the longest frame it can hold.
pub struct Reader<R, F: Framing, const N: usize = MAX_FRAME_LEN> {
    io: R,
    decoder: Decoder<F, N>,
    link: usize,
    idle: Option<Duration>,
}

impl<R: Read, F: Framing, const N: usize> Reader<R, F, N> {
    /// A reader of `io` with `framing`; `link` names it in [`Received::link`] (by
    /// convention the index of the same device in the downlink, for replies). Idle flush
    /// after 20 ms.
    pub fn new(io: R, framing: F, link: usize) -> Self {
        Self {
            io,
            decoder: Decoder::new(framing),
            link,
            idle: Some(Duration::from_millis(20)),
        }
    }

    /// Sets the idle time after which pending bytes are flushed (`None`: never).
    pub fn idle_flush(mut self, idle: Option<Duration>) -> Self {
        self.idle = idle;
        self
    }

    /// The link index.
    pub fn link(&self) -> usize {
        self.link
    }

    /// Counters of this reader's decoder (frames, checksum errors, ...).
    pub fn decoder_stats(&self) -> DecoderStats {
        *self.decoder.stats()
    }

    /// Feeds bytes that arrived by other means (a DMA buffer, a datagram), handling every
    /// complete frame; returns how many frames were decoded.
    pub fn feed<M: RawMutex, const S: usize>(
        &mut self,
        bytes: &[u8],
        datalink: &Datalink<'_, M, S>,
    ) -> usize {
        let mut input = bytes;
        let mut frames = 0;
        // Frames that arrived whole in `bytes` are read in place, without a copy.
        while let Some(frame) = self.decoder.feed_borrowed(&mut input) {
            datalink.handle(self.link, frame);
            frames += 1;
        }
        frames
    }

    /// End of input or idle line: handles the frames held behind an incomplete false
    /// start; returns how many.
    pub fn flush<M: RawMutex, const S: usize>(&mut self, datalink: &Datalink<'_, M, S>) -> usize {
        let mut frames = 0;
        while let Some(frame) = self.decoder.flush() {
            datalink.handle(self.link, frame);
            frames += 1;
        }
        frames
    }

    /// Reads and dispatches forever. Read errors are counted and reading goes on (after
    /// a short pause, so a failing device cannot spin the executor).
    pub async fn run<M: RawMutex, const S: usize>(
        &mut self,
        datalink: &Datalink<'_, M, S>,
    ) -> Infallible {
        let mut buf = [0u8; 64];
        loop {
            let pending = self.decoder.buffered() > 0;
            let read = match self.idle {
                Some(idle) if pending => {
                    match select(self.io.read(&mut buf), Timer::after(idle)).await {
                        Either::First(result) => Some(result),
                        Either::Second(()) => None,
                    }
                }
                _ => Some(self.io.read(&mut buf).await),
            };
            match read {
                Some(Ok(0)) | None => {
                    // End of input or idle line.
                    self.flush(datalink);
                    if matches!(read, Some(Ok(0))) {
                        Timer::after(Duration::from_millis(10)).await;
                    }
                }
                Some(Ok(n)) => {
                    self.feed(buf.get(..n).unwrap_or_default(), datalink);
                }
                Some(Err(_)) => {
                    datalink.count(|s| s.read_errors = s.read_errors.wrapping_add(1));
                    Timer::after(Duration::from_millis(10)).await;
                }
            }
        }
    }
}
