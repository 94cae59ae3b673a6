//! The downlink: send a message to one or more devices, each with its own transport and
//! priority queue, all frames in one shared [`FrameArena`]. Sending
//! never blocks: a message is encoded straight into arena memory and queued, or dropped
//! and counted with a reason.
//!
//! ```text
//!  send(&msg) ──encode per transport──► FrameArena (shared bytes)
//!        │                                   ▲ released when written or evicted
//!        ├──► FrameQueue[0] ──► writer task 0 ──► radio  (PPRZ v2)
//!        └──► FrameQueue[1] ──► writer task 1 ──► SD log (PPRZLOG)
//! ```
//!
//! # Overflow policy
//! When a device's queue or the arena has no room, the new message evicts queued
//! messages of strictly lower priority (least important first, and among those the
//! oldest) until it fits; if it still does not fit it is dropped. Equal or higher
//! priorities are never evicted. Every eviction and drop is counted per device and
//! reason ([`DeviceStats`]).
//!
//! # Set-up
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, Targets};
//! use pprz_telemetry::messages::telemetry::{Attitude, DlValue};
//! use pprz_telemetry::pprz_transports::{PprzLog, PprzV2};
//! use static_cell::StaticCell;
//!
//! // One arena for the pending frames of every device (size it for the backlog you accept:
//! // e.g. 4 KiB holds ~50 typical 60-byte frames plus allocator overhead).
//! static ARENA: FrameArena<M, 4096> = FrameArena::new();
//! // Two devices, queues of up to 32 frames each.
//! static DOWNLINK: StaticCell<Downlink<'static, M, 2, 32>> = StaticCell::new();
//!
//! let downlink = DOWNLINK.init(Downlink::new(
//!     &ARENA,
//!     7, // our aircraft id
//!     [
//!         DeviceConfig::new(PprzV2::new().into()),              // radio
//!         DeviceConfig::new(PprzLog::TELEMETRY.into()).depth(16), // SD card log
//!     ],
//! ));
//! // From any task: returns at once.
//! downlink.send(&Attitude { phi: 0.1, psi: 0.0, theta: 0.0 }).unwrap();
//! downlink.send_to(&DlValue { index: 1, value: 2.0 }, Targets::only(0), 200).unwrap();
//! assert_eq!(downlink.stats(0).unwrap().queued, 2);
//! // Then spawn one writer per device: `run_writer(downlink, 0, &mut uart).await`.
//! ```

use core::cell::Cell;
use core::fmt;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use pprz_messages::Message;
use pprz_transports::{AnyTransport, Encoder, GROUND_ID, MsgHeader, TxMeta};

use crate::arena::{AllocError, ArenaStats, FrameArena, FrameBuf};
use crate::queue::{FrameQueue, Pushed};
use crate::stats::{DeviceStats, DropReason};

/// Allocation of frame memory: implemented by [`FrameArena`] of any size, so a
/// [`Downlink`] does not carry the arena size in its type.
pub trait FrameAlloc {
    /// Allocates `len` bytes; see [`FrameArena::alloc`].
    ///
    /// # Errors
    /// As [`FrameArena::alloc`].
    fn alloc_frame(&self, len: usize) -> Result<FrameBuf<'_>, AllocError>;
    /// Statistics of the arena.
    fn arena_stats(&self) -> ArenaStats;
}

impl<M: RawMutex, const N: usize> FrameAlloc for FrameArena<M, N> {
    fn alloc_frame(&self, len: usize) -> Result<FrameBuf<'_>, AllocError> {
        self.alloc(len)
    }
    fn arena_stats(&self) -> ArenaStats {
        self.stats()
    }
}

/// What the shared send path needs from a message, through a vtable ([`Message`] itself,
/// with its associated constants, is not object-safe).
trait EncodeFields {
    /// [`Message::encoded_len`].
    fn fields_len(&self) -> usize;
    /// [`Message::encode`]; the send path only needs to know whether it failed.
    fn encode_fields(&self, buf: &mut [u8]) -> Option<usize>;
}

impl<Msg: Message> EncodeFields for Msg {
    #[inline]
    fn fields_len(&self) -> usize {
        self.encoded_len()
    }

    #[inline]
    fn encode_fields(&self, buf: &mut [u8]) -> Option<usize> {
        self.encode(buf).ok()
    }
}

/// Class, id and priority of a send, passed as one word to the shared send path.
#[derive(Clone, Copy)]
struct Route {
    class: u8,
    msg_id: u8,
    priority: u8,
}

/// How a device is used by the downlink.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceConfig {
    /// Framing of this device's frames.
    pub transport: AnyTransport,
    /// Queue depth limit (at most the downlink's queue capacity `Q`); 0 means `Q`.
    pub depth: usize,
    /// Whether the writer flushes the device after every frame (for devices that
    /// buffer, such as a log file; a UART needs none).
    pub flush: bool,
}

impl DeviceConfig {
    /// A device with this transport, the full queue capacity, no flush.
    pub const fn new(transport: AnyTransport) -> Self {
        Self {
            transport,
            depth: 0,
            flush: false,
        }
    }

    /// With a queue depth limit.
    pub const fn depth(mut self, depth: usize) -> Self {
        self.depth = depth;
        self
    }

    /// Flushing after every frame.
    pub const fn flush(mut self, flush: bool) -> Self {
        self.flush = flush;
        self
    }
}

/// A set of device indices (bit `i` = device `i`, up to 32 devices).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Targets(u32);

impl Targets {
    /// Every device.
    pub const ALL: Targets = Targets(u32::MAX);
    /// No device.
    pub const NONE: Targets = Targets(0);

    /// Only device `index` (no device if `index >= 32`).
    pub const fn only(index: usize) -> Self {
        Self::NONE.with(index)
    }

    /// This set plus device `index`.
    pub const fn with(self, index: usize) -> Self {
        if index < 32 {
            Targets(self.0 | (1 << index))
        } else {
            self
        }
    }

    /// Whether device `index` is in the set.
    pub const fn contains(&self, index: usize) -> bool {
        index < 32 && self.0 & (1 << index) != 0
    }

    /// A set from raw bits (bit `i` = device `i`).
    pub const fn from_bits(bits: u32) -> Self {
        Targets(bits)
    }

    /// The raw bit set.
    pub const fn bits(&self) -> u32 {
        self.0
    }
}

/// A message did not reach (at least) one of its target devices. The drop is counted in
/// that device's statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SendError {
    /// The device (the last one that failed, if several did).
    pub device: usize,
    /// Why.
    pub reason: DropReason,
}

impl fmt::Display for SendError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "message dropped for device {}: {}",
            self.device, self.reason
        )
    }
}

impl core::error::Error for SendError {}

/// The downlink of an aircraft: `D` devices with queues of capacity `Q`, frames in a
/// shared arena that lives for `'a`. See the [module documentation](self).
pub struct Downlink<'a, M: RawMutex, const D: usize, const Q: usize> {
    arena: &'a (dyn FrameAlloc + Sync),
    devices: [DeviceConfig; D],
    queues: [FrameQueue<'a, M, Q>; D],
    ac_id: u8,
    /// Global sequence number: the age of a frame across all queues, for eviction.
    seq: Mutex<M, Cell<u32>>,
    /// PPRZLOG time stamps, in 100 µs ticks.
    clock: fn() -> u32,
}

fn no_clock() -> u32 {
    0
}

impl<'a, M: RawMutex, const D: usize, const Q: usize> Downlink<'a, M, D, Q> {
    const VALID: () = assert!(D > 0 && D <= 32, "a downlink has 1..=32 devices");

    /// A downlink for aircraft `ac_id` over `devices`, frames allocated in `arena`.
    pub fn new(arena: &'a (dyn FrameAlloc + Sync), ac_id: u8, devices: [DeviceConfig; D]) -> Self {
        let () = Self::VALID;
        let queues = core::array::from_fn(|i| {
            let q = FrameQueue::new();
            let depth = devices[i].depth;
            if depth > 0 {
                q.set_depth(depth);
            }
            q
        });
        Self {
            arena,
            devices,
            queues,
            ac_id,
            seq: Mutex::new(Cell::new(0)),
            clock: no_clock,
        }
    }

    /// Sets the clock that stamps PPRZLOG records (100 µs ticks, e.g. from
    /// `embassy_time::Instant::now().as_micros() / 100`).
    pub fn with_clock(mut self, clock: fn() -> u32) -> Self {
        self.clock = clock;
        self
    }

    /// Our aircraft id (the `source` of every frame).
    pub fn ac_id(&self) -> u8 {
        self.ac_id
    }

    /// Number of devices.
    pub const fn devices(&self) -> usize {
        D
    }

    /// The configuration of device `index`.
    pub fn device(&self, index: usize) -> Option<&DeviceConfig> {
        self.devices.get(index)
    }

    /// The queue of device `index` (for its writer task and for inspection).
    pub fn queue(&self, index: usize) -> Option<&FrameQueue<'a, M, Q>> {
        self.queues.get(index)
    }

    /// The queue and flush setting of device `index`, for [`crate::run_writer`].
    pub(crate) fn writer_parts(&self, device: usize) -> Option<(&FrameQueue<'a, M, Q>, bool)> {
        Some((self.queues.get(device)?, self.devices.get(device)?.flush))
    }

    /// Statistics of device `index`.
    pub fn stats(&self, index: usize) -> Option<DeviceStats> {
        self.queues.get(index).map(FrameQueue::stats)
    }

    /// Statistics of the shared arena.
    pub fn arena_stats(&self) -> ArenaStats {
        self.arena.arena_stats()
    }

    /// Sends `msg` to every device at the message's own priority. Never blocks.
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there).
    pub fn send<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.send_to(msg, Targets::ALL, Msg::PRIORITY)
    }

    /// Sends `msg` to the devices in `targets` (indices beyond the last device are
    /// ignored) with `priority`, addressed to the ground. Never blocks.
    ///
    /// The message is encoded once per distinct transport among the targets, directly
    /// into arena memory; devices sharing a transport get a copy of those bytes.
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there).
    #[inline]
    pub fn send_to<Msg: Message>(
        &self,
        msg: &Msg,
        targets: Targets,
        priority: u8,
    ) -> Result<(), SendError> {
        let route = Route {
            class: Msg::CLASS_ID,
            msg_id: Msg::ID,
            priority,
        };
        self.send_fields(msg, route, targets)
    }

    /// The send path of every message type: [`send_to`](Self::send_to) is a thin generic
    /// wrapper around it, so this is compiled once per downlink type instead of once per
    /// message type (about 450 bytes of flash each on a Cortex-M), for two indirect calls
    /// through the message's vtable (`fields_len`, and `encode_fields` per transport).
    fn send_fields(
        &self,
        msg: &dyn EncodeFields,
        route: Route,
        targets: Targets,
    ) -> Result<(), SendError> {
        let Route {
            class,
            msg_id,
            priority,
        } = route;
        let header = MsgHeader::new(self.ac_id, GROUND_ID, class, msg_id);
        let meta = TxMeta::new(header).at((self.clock)());
        let payload_len = msg.fields_len();
        let seq = self.next_seq();
        let mut error = None;
        // Frames are all built before any is queued, so a frame can be copied from an
        // earlier target with the same transport.
        let mut frames: heapless::Vec<(usize, FrameBuf<'a>), D> = heapless::Vec::new();
        for device in (0..D).filter(|&d| targets.contains(d)) {
            let transport = self.devices[device].transport;
            let built = self.build(msg, &meta, payload_len, transport, priority, &frames);
            match built {
                Ok(frame) => {
                    // `frames` has room for one frame per device.
                    let _ = frames.push((device, frame));
                }
                Err(reason) => {
                    self.queues[device].count_dropped(reason, priority);
                    error = Some(SendError { device, reason });
                }
            }
        }
        for (device, frame) in frames {
            if self.queues[device].push(priority, seq, frame) == Pushed::Dropped {
                error = Some(SendError {
                    device,
                    reason: DropReason::QueueFull,
                });
            }
        }
        error.map_or(Ok(()), Err)
    }

    fn next_seq(&self) -> u32 {
        self.seq.lock(|s| {
            let v = s.get();
            s.set(v.wrapping_add(1));
            v
        })
    }

    /// Builds the frame of `msg` for one transport in arena memory.
    fn build(
        &self,
        msg: &dyn EncodeFields,
        meta: &TxMeta,
        payload_len: usize,
        transport: AnyTransport,
        priority: u8,
        built: &[(usize, FrameBuf<'a>)],
    ) -> Result<FrameBuf<'a>, DropReason> {
        let frame_len = transport
            .frame_len(payload_len)
            .map_err(|_| DropReason::TooLarge)?;
        let mut frame = self.alloc(frame_len, priority)?;
        if let Some((_, same)) = built
            .iter()
            .find(|(d, _)| self.devices[*d].transport == transport)
        {
            frame.copy_from_slice(same);
            return Ok(frame);
        }
        let n = msg
            .encode_fields(transport.payload_area(&mut frame))
            .ok_or(DropReason::Encode)?;
        let len = transport
            .finish_frame(meta, &mut frame, n)
            .map_err(|_| DropReason::Encode)?;
        frame.truncate(len);
        Ok(frame)
    }

    /// Allocates arena memory, evicting queued frames of strictly lower priority (the
    /// least important and oldest across all devices first) while the arena is full.
    fn alloc(&self, len: usize, priority: u8) -> Result<FrameBuf<'a>, DropReason> {
        // Each round evicts one frame or gives up; bounded by the number of queued frames
        // (plus rounds lost to concurrent changes, which other senders' progress bounds).
        for _ in 0..=D * Q + D {
            match self.arena.alloc_frame(len) {
                Ok(frame) => return Ok(frame),
                Err(AllocError::TooLarge { .. }) => return Err(DropReason::TooLarge),
                Err(_) => {}
            }
            let victim = self
                .queues
                .iter()
                .enumerate()
                .filter_map(|(d, q)| q.candidate().map(|c| (d, c)))
                .reduce(|a, b| if b.1.weaker_than(&a.1) { b } else { a });
            match victim {
                Some((device, c)) if c.priority < priority => {
                    self.queues[device].evict_for_arena(c);
                }
                _ => return Err(DropReason::ArenaFull),
            }
        }
        Err(DropReason::ArenaFull)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::queue::Candidate;

    #[test]
    fn candidate_order() {
        let a = Candidate {
            priority: 1,
            seq: 10,
        };
        let b = Candidate {
            priority: 1,
            seq: 11,
        };
        let c = Candidate {
            priority: 0,
            seq: 99,
        };
        assert!(a.weaker_than(&b) && !b.weaker_than(&a));
        assert!(c.weaker_than(&a));
        let wrapped = Candidate {
            priority: 1,
            seq: u32::MAX,
        };
        assert!(wrapped.weaker_than(&Candidate {
            priority: 1,
            seq: 2
        }));
    }

    #[test]
    fn targets() {
        let t = Targets::only(1).with(3);
        assert!(t.contains(1) && t.contains(3) && !t.contains(0));
        assert_eq!(Targets::only(40), Targets::NONE);
        assert!(Targets::ALL.contains(31));
    }
}
