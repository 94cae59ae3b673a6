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
//! Everything is `const`, so the arena and the downlink are plain `static`s:
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, Targets};
//! use pprz_telemetry::pprz_transports::{AnyTransport, PprzLog, PprzV2};
//! use pprz_default::messages::telemetry::Attitude; // any generated message set
//!
//! // One arena for the pending frames of every device (size it for the backlog you accept:
//! // e.g. 4 KiB holds ~50 typical 60-byte frames plus allocator overhead).
//! static ARENA: FrameArena<M, 4096> = FrameArena::new();
//! // Two devices, queues of up to 32 frames each.
//! static DOWNLINK: Downlink<'static, M, 2, 32> = Downlink::new(&ARENA, 7, [
//!     DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),              // radio
//!     DeviceConfig::new(AnyTransport::PprzLog(PprzLog::TELEMETRY)).depth(16), // SD card log
//! ]);
//!
//! // At start-up: one port per device, each for the device's writer task.
//! let [radio, log] = DOWNLINK.ports().unwrap();
//! // spawner.spawn(radio_writer(radio, uart_tx)) with `run_writer(&mut port, uart_tx).await`
//!
//! // From any task: returns at once. `sender()` is a copyable handle without the
//! // downlink's generic parameters.
//! let tx = DOWNLINK.sender();
//! let attitude = Attitude { phi: 0.1, psi: 0.0, theta: 0.0 };
//! tx.send(&attitude).unwrap(); // every device
//! radio.device().send_with_priority(&attitude, 200).unwrap(); // only the radio
//! tx.send_on(&attitude, Targets::from(log.device()), 10).unwrap();
//! assert_eq!(radio.device().stats().queued, 2);
//! assert_eq!(log.device().stats().queued, 2);
//! ```

use core::cell::{Cell, RefCell};
use core::fmt;
use core::future::poll_fn;
use core::task::{Context, Poll};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use pprz_messages::Message;
use pprz_transports::{AnyTransport, Encoder, Frame, GROUND_ID, MsgHeader, TxMeta, TxStatus};

use crate::arena::{AllocError, ArenaStats, FrameArena, FrameBuf};
use crate::delivery::{DeliveryStats, DeliveryWindow, Outstanding};
use crate::layer::LinkLayer;
use crate::queue::{FrameQueue, MessageKey, Pushed};
use crate::relay::Routes;
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

/// The fields of a frame being forwarded, copied as they are (never decoded).
struct RawFields<'p>(&'p [u8]);

impl EncodeFields for RawFields<'_> {
    fn fields_len(&self) -> usize {
        self.0.len()
    }

    fn encode_fields(&self, buf: &mut [u8]) -> Option<usize> {
        buf.get_mut(..self.0.len())?.copy_from_slice(self.0);
        Some(self.0.len())
    }
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

/// Class, id, destination and priority of a send, whether it answers a request (subject
/// to the devices' [`ReplyLimit`]), whether it is a state message (a newer one supersedes
/// a waiting older one) and, for another aircraft's frame being forwarded, its source
/// and component, passed as two words to the shared send path.
#[derive(Clone, Copy)]
struct Route {
    class: u8,
    msg_id: u8,
    priority: u8,
    reply: bool,
    latest: bool,
    to: u8,
    relayed: Option<Relayed>,
}

/// The header fields a forwarded frame keeps: its source and component.
#[derive(Clone, Copy)]
struct Relayed {
    source: u8,
    component: u8,
}

impl Route {
    #[inline]
    fn of<Msg: Message>(priority: u8) -> Self {
        Self {
            class: Msg::CLASS_ID,
            msg_id: Msg::ID,
            priority,
            reply: false,
            latest: false,
            to: GROUND_ID,
            relayed: None,
        }
    }

    /// The same, addressed to `to`.
    #[inline]
    fn to(self, to: u8) -> Self {
        Self { to, ..self }
    }

    /// Another aircraft's `frame`, forwarded with `priority`.
    fn forward(frame: &Frame<'_>, priority: u8) -> Self {
        Self {
            class: frame.class(),
            msg_id: frame.msg_id(),
            priority,
            reply: false,
            latest: false,
            to: frame.destination().unwrap_or(GROUND_ID),
            relayed: Some(Relayed {
                source: frame.source(),
                component: frame.component(),
            }),
        }
    }

    #[inline]
    fn latest<Msg: Message>(priority: u8) -> Self {
        Self {
            latest: true,
            ..Self::of::<Msg>(priority)
        }
    }

    #[inline]
    fn reply<Msg: Message>() -> Self {
        Self {
            reply: true,
            ..Self::of::<Msg>(Msg::PRIORITY)
        }
    }
}

/// The most replies (answers to requests received on the device: PONG, DL_VALUE, and
/// whatever [`Device::reply`] sends) a device sends: `per_second` on average, up to
/// `burst` at once. Replies are acknowledgements, high in priority, so without a bound a
/// request flood from the ground (or an attacker) would evict the device's telemetry;
/// replies over the limit are refused and counted as [`DropReason::RateLimited`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReplyLimit {
    /// Average replies per second (0: the device sends no replies).
    pub per_second: u16,
    /// Replies that may go out back to back (at least 1 is used).
    pub burst: u16,
}

impl ReplyLimit {
    /// The default of every device: 20 replies per second, 10 at once (a ground station
    /// pings once a second and reads a page of settings at a time).
    pub const DEFAULT: Self = Self::new(20, 10);

    /// `per_second` replies per second on average, `burst` at once.
    pub const fn new(per_second: u16, burst: u16) -> Self {
        Self { per_second, burst }
    }

    /// Generic cell rate algorithm: `tat` is the theoretical arrival time of the next
    /// reply (in embassy-time ticks); returns whether a reply at `now` conforms, and
    /// advances `tat` if so.
    fn admit(&self, tat: &Cell<u64>, now: u64) -> bool {
        if self.per_second == 0 {
            return false;
        }
        let interval = embassy_time::TICK_HZ / u64::from(self.per_second);
        let tolerance = interval.saturating_mul(u64::from(self.burst.max(1) - 1));
        let next = tat.get().max(now);
        if next - now > tolerance {
            return false;
        }
        tat.set(next.saturating_add(interval));
        true
    }
}

/// The link budget of a radio that does not push back (no hardware flow control): its
/// air throughput, and how many bytes we let wait inside the modem (and the UART
/// driver's buffer before it). The device's writer models the modem's occupancy as a
/// leaky bucket drained at `air_rate` and hands the modem a frame only when the frame
/// fits in `modem_budget`, so frames wait in our priority queue, where they are
/// reordered and shed by priority, instead of in the modem's FIFO, where they are sent
/// in order or lost when it overflows.
///
/// Choosing the figures (see the sizing guide): `air_rate` is the throughput the radio
/// really achieves, not its serial baud rate (a SiK radio at 64 kbit/s air rate with
/// ECC on carries about half of 8000 B/s, minus its framing and duty cycle; measure it
/// with a saturating test). `modem_budget` trades latency for link use: one
/// maximum-size frame plus a margin for clock and throughput error keeps the air busy
/// and bounds the wait of an acknowledgement to about two frame times; it must stay
/// well below the modem's real buffer (2048 bytes for a SiK radio).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pacing {
    /// Bytes per second the radio carries over the air (at least 1).
    pub air_rate: u32,
    /// Bytes we let wait in the modem at most (a frame longer than this goes alone,
    /// once the modelled modem is empty).
    pub modem_budget: u16,
}

impl Pacing {
    /// `air_rate` bytes per second, at most `modem_budget` bytes in the modem.
    pub const fn new(air_rate: u32, modem_budget: u16) -> Self {
        Self {
            air_rate,
            modem_budget,
        }
    }

    /// Time the air takes to carry `bytes` bytes, in embassy-time ticks (rounded up).
    pub(crate) fn air_ticks(&self, bytes: usize) -> u64 {
        let rate = u64::from(self.air_rate.max(1));
        (bytes as u64)
            .saturating_mul(embassy_time::TICK_HZ)
            .div_ceil(rate)
    }
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
    /// The most replies the device sends (`None`: no limit).
    pub replies: Option<ReplyLimit>,
    /// The link budget of a radio without flow control (`None`: write frames as fast as
    /// the device accepts them, for devices that push back or never lose bytes).
    pub pacing: Option<Pacing>,
    /// For a transport with transmit statuses (XBee API): how many frames may await
    /// their status in the modem (`None`: frames are written without frame ids, the
    /// modem sends no status). See [`delivery`](crate::delivery).
    pub delivery: Option<DeliveryWindow>,
    /// Spare bytes allocated after every frame of this device, for a
    /// [`LinkLayer`] that lengthens frames when the writer takes
    /// them for the wire (the secure link's 21 bytes of counter, tag and crypto byte). A
    /// message whose frame would not fit the transport with them is refused at `send`
    /// ([`DropReason::TooLarge`]).
    pub reserve: u8,
}

impl DeviceConfig {
    /// A device with this transport, the full queue capacity, no flush, replies limited
    /// to [`ReplyLimit::DEFAULT`].
    pub const fn new(transport: AnyTransport) -> Self {
        Self {
            transport,
            depth: 0,
            flush: false,
            replies: Some(ReplyLimit::DEFAULT),
            pacing: None,
            delivery: None,
            reserve: 0,
        }
    }

    /// With `bytes` spare bytes after every frame; see [`reserve`](Self::reserve).
    pub const fn reserve(mut self, bytes: u8) -> Self {
        self.reserve = bytes;
        self
    }

    /// With this transmit-status window (`None`: none); it applies to transports with
    /// transmit statuses (XBee API) and is ignored by the others.
    pub const fn delivery(mut self, window: Option<DeliveryWindow>) -> Self {
        self.delivery = window;
        self
    }

    /// With this link budget (`None`: no pacing); see [`Pacing`].
    pub const fn pacing(mut self, pacing: Option<Pacing>) -> Self {
        self.pacing = pacing;
        self
    }

    /// With this reply rate limit (`None`: replies unlimited).
    pub const fn replies(mut self, limit: Option<ReplyLimit>) -> Self {
        self.replies = limit;
        self
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
/// that device's statistics (or, for [`DropReason::NoDevice`], in the downlink's
/// [`undeliverable`](Downlink::undeliverable) counter).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SendError {
    /// The device (the last one that failed, if several did; for
    /// [`DropReason::NoDevice`], the number of devices).
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
    seq: SeqCounter<M>,
    /// Whether [`ports`](Self::ports) handed the ports out already.
    ports_taken: Mutex<M, Cell<bool>>,
    /// Sends whose targets named no device.
    undeliverable: Mutex<M, Cell<u32>>,
    /// Per device, the reply rate limit's state (see [`ReplyLimit::admit`]).
    reply_tat: [Mutex<M, Cell<u64>>; D],
    /// Per device, the frames awaiting their transmit status.
    outstanding: [Mutex<M, RefCell<Outstanding>>; D],
    /// PPRZLOG time stamps, in 100 µs ticks.
    clock: fn() -> u32,
    /// Which devices lead to which aircraft.
    routes: Routes<'a>,
}

fn no_clock() -> u32 {
    0
}

/// The downlink's global sequence number (wrapping): an atomic counter where the target
/// has atomic read-modify-write (no lock taken per message), else a counter under the
/// downlink's mutex (e.g. `thumbv6m`).
struct SeqCounter<M: RawMutex> {
    #[cfg(target_has_atomic = "32")]
    next: core::sync::atomic::AtomicU32,
    #[cfg(target_has_atomic = "32")]
    _mutex: core::marker::PhantomData<M>,
    #[cfg(not(target_has_atomic = "32"))]
    next: Mutex<M, Cell<u32>>,
}

impl<M: RawMutex> SeqCounter<M> {
    const fn new() -> Self {
        Self {
            #[cfg(target_has_atomic = "32")]
            next: core::sync::atomic::AtomicU32::new(0),
            #[cfg(target_has_atomic = "32")]
            _mutex: core::marker::PhantomData,
            #[cfg(not(target_has_atomic = "32"))]
            next: Mutex::new(Cell::new(0)),
        }
    }

    /// The next number.
    #[inline]
    fn next(&self) -> u32 {
        #[cfg(target_has_atomic = "32")]
        {
            // Only uniqueness and order matter, not ordering with other memory.
            self.next
                .fetch_add(1, core::sync::atomic::Ordering::Relaxed)
        }
        #[cfg(not(target_has_atomic = "32"))]
        self.next.lock(|n| {
            let v = n.get();
            n.set(v.wrapping_add(1));
            v
        })
    }
}

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

/// The mutex must be `Sync` (`CriticalSectionRawMutex`, or `ThreadModeRawMutex` within one
/// executor): the downlink's ports and handles are shared between tasks.
impl<'a, M: RawMutex + Sync, const D: usize, const Q: usize> Downlink<'a, M, D, Q> {
    const VALID: () = assert!(D > 0 && D <= 32, "a downlink has 1..=32 devices");
    /// The [`Targets`] bits of this downlink's devices.
    const DEVICE_BITS: u32 = if D >= 32 { u32::MAX } else { (1 << D) - 1 };

    /// A downlink for aircraft `ac_id` over `devices`, frames allocated in `arena`.
    /// A `const fn`, so the downlink can be a `static`.
    pub const fn new(
        arena: &'a (dyn FrameAlloc + Sync),
        ac_id: u8,
        devices: [DeviceConfig; D],
    ) -> Self {
        let () = Self::VALID;
        Self {
            arena,
            devices,
            queues: [const { FrameQueue::new() }; D],
            ac_id,
            seq: SeqCounter::new(),
            ports_taken: Mutex::new(Cell::new(false)),
            undeliverable: Mutex::new(Cell::new(0)),
            reply_tat: [const { Mutex::new(Cell::new(0)) }; D],
            outstanding: [const { Mutex::new(RefCell::new(Outstanding::new())) }; D],
            clock: no_clock,
            routes: Routes::DIRECT,
        }
    }

    /// Sets the route table: which devices lead to the ground, to each other aircraft
    /// and to broadcast ([`Routes`]; by default every device leads everywhere). Used by
    /// [`send`](Self::send) and [`send_to`](Self::send_to), and by the
    /// [relay](crate::relay) to forward other aircraft's frames.
    pub const fn with_routes(mut self, routes: Routes<'a>) -> Self {
        self.routes = routes;
        self
    }

    /// The route table.
    pub fn routes(&self) -> Routes<'a> {
        self.routes
    }

    /// Sets the clock that stamps PPRZLOG records (100 µs ticks, e.g. from
    /// `embassy_time::Instant::now().as_micros() / 100`).
    pub const fn with_clock(mut self, clock: fn() -> u32) -> Self {
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
    pub fn config(&self, index: usize) -> Option<&DeviceConfig> {
        self.devices.get(index)
    }

    /// Statistics of device `index`.
    pub fn stats(&self, index: usize) -> Option<DeviceStats> {
        self.queues.get(index).map(FrameQueue::stats)
    }

    /// What the transmit statuses of device `index` said (all zero for a device without
    /// a [`DeliveryWindow`]); `None` if there is no such device.
    pub fn delivery_stats(&self, index: usize) -> Option<DeliveryStats> {
        self.outstanding
            .get(index)
            .map(|o| o.lock(|o| o.borrow().stats))
    }

    /// Statistics of the shared arena.
    pub fn arena_stats(&self) -> ArenaStats {
        self.arena.arena_stats()
    }

    /// Sends that named no device of this downlink (an empty [`Targets`] set, or only
    /// indices past the last device): refused with [`DropReason::NoDevice`], counted
    /// here since no device's statistics can hold them.
    pub fn undeliverable(&self) -> u32 {
        self.undeliverable.lock(Cell::get)
    }

    /// Sends `msg` to the ground at the message's own priority, on the devices of the
    /// ground's route (every device unless [routes](Self::with_routes) say otherwise).
    /// Never blocks.
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there).
    #[inline]
    pub fn send<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.send_fields(msg, Route::of::<Msg>(Msg::PRIORITY), None)
    }

    /// Sends `msg`, a **state** message (a periodic sample: attitude, position, status),
    /// to every device at the message's own priority: where an older `Msg` of the same
    /// priority still waits in a device's queue, the new one takes its place (the old
    /// one counts as [`superseded`](DeviceStats::superseded)), so a saturated link
    /// carries the latest value, not a stale backlog. Events (acknowledgements,
    /// one-shot messages) go with [`send`](Self::send). Never blocks.
    ///
    /// Only one stream of `Msg` should be sent this way: two sources of the same
    /// message (two sensors reporting through one message type) would supersede each
    /// other.
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there).
    pub fn send_latest<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.send_fields(msg, Route::latest::<Msg>(Msg::PRIORITY), None)
    }

    /// Sends `msg` to aircraft `destination` (or [`GROUND_ID`], or
    /// [`BROADCAST_ID`](pprz_transports::BROADCAST_ID) for every aircraft) with
    /// `priority`, on the devices the [route table](Self::with_routes) gives for it.
    /// Never blocks.
    ///
    /// # Errors
    /// As [`send_on`](Self::send_on).
    #[inline]
    pub fn send_to<Msg: Message>(
        &self,
        msg: &Msg,
        destination: u8,
        priority: u8,
    ) -> Result<(), SendError> {
        self.send_fields(msg, Route::of::<Msg>(priority).to(destination), None)
    }

    /// Sends `msg` on the devices in `targets` (indices beyond the last device are
    /// ignored) with `priority`, addressed to the ground. Never blocks.
    ///
    /// The message is encoded once per distinct transport among the targets, directly
    /// into arena memory; devices sharing a transport get a copy of those bytes.
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there), or `targets`
    /// named no device at all ([`DropReason::NoDevice`], counted in
    /// [`undeliverable`](Self::undeliverable)).
    #[inline]
    pub fn send_on<Msg: Message>(
        &self,
        msg: &Msg,
        targets: Targets,
        priority: u8,
    ) -> Result<(), SendError> {
        self.send_fields(msg, Route::of::<Msg>(priority), Some(targets))
    }

    /// The send path of every message type: [`send_on`](Self::send_on) is a thin generic
    /// wrapper around it, so this is compiled once per downlink type instead of once per
    /// message type (about 450 bytes of flash each on a Cortex-M), for two indirect calls
    /// through the message's vtable (`fields_len`, and `encode_fields` per transport).
    /// Without `targets`, the message goes on the route of its destination (looked up
    /// here, so that the generic wrappers stay a few instructions each).
    fn send_fields(
        &self,
        msg: &dyn EncodeFields,
        route: Route,
        targets: Option<Targets>,
    ) -> Result<(), SendError> {
        let Route {
            class,
            msg_id,
            priority,
            reply,
            latest,
            to,
            relayed,
        } = route;
        let targets = targets.unwrap_or_else(|| self.routes.to(to));
        let (source, component, relay) = match relayed {
            Some(r) => (r.source, r.component, true),
            None => (self.ac_id, pprz_transports::COMPONENT_BROADCAST, false),
        };
        let latest = latest.then_some(MessageKey { class, msg_id });
        if targets.bits() & Self::DEVICE_BITS == 0 {
            self.undeliverable.lock(|n| n.set(n.get().wrapping_add(1)));
            return Err(SendError {
                device: D,
                reason: DropReason::NoDevice,
            });
        }
        let header = MsgHeader::new(source, to, class, msg_id).with_component(component);
        let meta = TxMeta::new(header).at((self.clock)());
        let payload_len = msg.fields_len();
        let seq = self.next_seq();
        let mut error = None;
        // Frames are all built before any is queued, so a frame can be copied from an
        // earlier target with the same transport.
        let mut frames: [Option<FrameBuf<'a>>; D] = [const { None }; D];
        for device in (0..D).filter(|&d| targets.contains(d)) {
            if reply && !self.admit_reply(device) {
                self.queues[device].count_dropped(DropReason::RateLimited, priority, relay);
                error = Some(SendError {
                    device,
                    reason: DropReason::RateLimited,
                });
                continue;
            }
            let config = &self.devices[device];
            let built = self.build(msg, &meta, payload_len, config, priority, &frames);
            match built {
                Ok(frame) => frames[device] = Some(frame),
                Err(reason) => {
                    self.queues[device].count_dropped(reason, priority, relay);
                    error = Some(SendError { device, reason });
                }
            }
        }
        for (device, frame) in frames.iter_mut().enumerate() {
            let Some(frame) = frame.take() else {
                continue;
            };
            let depth = match self.devices[device].depth {
                0 => Q,
                depth => depth,
            };
            if self.queues[device].push(priority, seq, latest, relay, frame, depth)
                == Pushed::Dropped
            {
                error = Some(SendError {
                    device,
                    reason: DropReason::QueueFull,
                });
            }
        }
        error.map_or(Ok(()), Err)
    }

    /// Whether device `device`'s reply rate limit lets one more reply out now.
    fn admit_reply(&self, device: usize) -> bool {
        match self.devices[device].replies {
            None => true,
            Some(limit) => {
                let now = embassy_time::Instant::now().as_ticks();
                self.reply_tat[device].lock(|tat| limit.admit(tat, now))
            }
        }
    }

    fn next_seq(&self) -> u32 {
        self.seq.next()
    }

    /// Builds the frame of `msg` for one transport in arena memory.
    fn build(
        &self,
        msg: &dyn EncodeFields,
        meta: &TxMeta,
        payload_len: usize,
        config: &DeviceConfig,
        priority: u8,
        built: &[Option<FrameBuf<'a>>],
    ) -> Result<FrameBuf<'a>, DropReason> {
        let transport = config.transport;
        let reserve = usize::from(config.reserve);
        let frame_len = transport
            .frame_len(payload_len)
            .map_err(|_| DropReason::TooLarge)?;
        if reserve > 0 {
            // The frame as the layer will lengthen it must still fit the transport.
            transport
                .frame_len(payload_len + reserve)
                .map_err(|_| DropReason::TooLarge)?;
        }
        let mut frame = self.alloc(frame_len + reserve, priority)?;
        if let Some(same) = built
            .iter()
            .zip(&self.devices)
            .find_map(|(f, d)| f.as_ref().filter(|_| d.transport == transport))
        {
            // Same transport, same length: the earlier frame was checked against
            // `payload_len` below. Never a panic, whatever the lengths.
            let dest = frame.get_mut(..same.len()).ok_or(DropReason::Encode)?;
            dest.copy_from_slice(same);
            frame.truncate(same.len());
            return Ok(frame);
        }
        let n = msg
            .encode_fields(transport.payload_area(&mut frame))
            .ok_or(DropReason::Encode)?;
        // A `Message` impl whose `encode` disagrees with its `encoded_len` (a hand-written
        // one, say) is dropped as unencodable rather than sent with a length the receiver
        // did not expect.
        if n != payload_len {
            return Err(DropReason::Encode);
        }
        let len = transport
            .finish_frame(meta, &mut frame, n)
            .map_err(|_| DropReason::Encode)?;
        if len > frame_len {
            return Err(DropReason::Encode);
        }
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

impl<'a, M: RawMutex + Sync, const D: usize, const Q: usize> Downlink<'a, M, D, Q> {
    /// A copyable, type-erased handle that sends through this downlink: what tasks and
    /// callbacks that only send should hold, so the downlink's mutex, device count and
    /// queue capacity do not appear in their signatures.
    pub fn sender(&self) -> Sender<'_> {
        Sender { core: self }
    }

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
        if self.ports_taken.lock(|t| t.replace(true)) {
            return Err(PortsTaken);
        }
        Ok(core::array::from_fn(|index| Port {
            device: Device {
                core: self,
                // D <= 32.
                index: index as u8,
            },
        }))
    }
}

/// What the type-erased handles ([`Sender`], [`Device`], [`Port`]) need from a
/// [`Downlink`] of any mutex, device count and queue capacity.
trait Core: Sync {
    fn ac_id(&self) -> u8;
    fn routes(&self) -> Routes<'_>;
    fn device_count(&self) -> usize;
    fn config(&self, device: usize) -> Option<DeviceConfig>;
    fn send_fields(
        &self,
        msg: &dyn EncodeFields,
        route: Route,
        targets: Option<Targets>,
    ) -> Result<(), SendError>;
    fn stats(&self, device: usize) -> Option<DeviceStats>;
    fn undeliverable(&self) -> u32;
    fn arena_stats(&self) -> ArenaStats;
    fn try_receive(&self, device: usize, cx: Option<&mut Context<'_>>) -> Option<FrameBuf<'_>>;
    fn peek_len(&self, device: usize, cx: Option<&mut Context<'_>>) -> Option<usize>;
    /// Runs `f` on device `device`'s outstanding frames (nothing for a bad index).
    fn outstanding(&self, device: usize, f: &mut dyn FnMut(&mut Outstanding));
    /// Counts the outcome of `frame`, device `device`'s in-flight frame, and releases it;
    /// with `take_next`, then takes the device's next frame under the same lock.
    fn complete(
        &self,
        device: usize,
        frame: FrameBuf<'_>,
        outcome: Result<(), DropReason>,
        take_next: bool,
    ) -> Option<FrameBuf<'_>>;
}

impl<M: RawMutex + Sync, const D: usize, const Q: usize> Core for Downlink<'_, M, D, Q> {
    fn ac_id(&self) -> u8 {
        self.ac_id
    }

    fn routes(&self) -> Routes<'_> {
        self.routes
    }

    fn device_count(&self) -> usize {
        D
    }

    fn config(&self, device: usize) -> Option<DeviceConfig> {
        self.devices.get(device).copied()
    }

    fn send_fields(
        &self,
        msg: &dyn EncodeFields,
        route: Route,
        targets: Option<Targets>,
    ) -> Result<(), SendError> {
        Downlink::send_fields(self, msg, route, targets)
    }

    fn stats(&self, device: usize) -> Option<DeviceStats> {
        Downlink::stats(self, device)
    }

    fn undeliverable(&self) -> u32 {
        Downlink::undeliverable(self)
    }

    fn arena_stats(&self) -> ArenaStats {
        Downlink::arena_stats(self)
    }

    fn try_receive(&self, device: usize, cx: Option<&mut Context<'_>>) -> Option<FrameBuf<'_>> {
        self.queues.get(device)?.try_receive(cx)
    }

    fn peek_len(&self, device: usize, cx: Option<&mut Context<'_>>) -> Option<usize> {
        self.queues.get(device)?.peek_len(cx)
    }

    fn outstanding(&self, device: usize, f: &mut dyn FnMut(&mut Outstanding)) {
        if let Some(o) = self.outstanding.get(device) {
            o.lock(|o| f(&mut o.borrow_mut()));
        }
    }

    fn complete(
        &self,
        device: usize,
        frame: FrameBuf<'_>,
        outcome: Result<(), DropReason>,
        take_next: bool,
    ) -> Option<FrameBuf<'_>> {
        self.queues.get(device)?.complete(frame, outcome, take_next)
    }
}

/// A copyable handle that sends through a [`Downlink`] of any size
/// ([`Downlink::sender`]), like embassy-sync's `DynamicSender`: sending never blocks.
#[derive(Clone, Copy)]
pub struct Sender<'d> {
    core: &'d dyn Core,
}

impl fmt::Debug for Sender<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Sender")
            .field("ac_id", &self.core.ac_id())
            .field("devices", &self.core.device_count())
            .finish()
    }
}

impl<'d> Sender<'d> {
    /// Sends `msg` to the ground at the message's own priority; see [`Downlink::send`].
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there).
    #[inline]
    pub fn send<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.core
            .send_fields(msg, Route::of::<Msg>(Msg::PRIORITY), None)
    }

    /// Sends `msg` to aircraft `destination` with `priority`, on the devices of its
    /// route; see [`Downlink::send_to`].
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there).
    #[inline]
    pub fn send_to<Msg: Message>(
        &self,
        msg: &Msg,
        destination: u8,
        priority: u8,
    ) -> Result<(), SendError> {
        self.core
            .send_fields(msg, Route::of::<Msg>(priority).to(destination), None)
    }

    /// Sends `msg` on `targets` with `priority`, to the ground; see
    /// [`Downlink::send_on`].
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there).
    #[inline]
    pub fn send_on<Msg: Message>(
        &self,
        msg: &Msg,
        targets: Targets,
        priority: u8,
    ) -> Result<(), SendError> {
        self.core
            .send_fields(msg, Route::of::<Msg>(priority), Some(targets))
    }

    /// Sends the state message `msg` to the ground, superseding a waiting older one;
    /// see [`Downlink::send_latest`].
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there).
    #[inline]
    pub fn send_latest<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.core
            .send_fields(msg, Route::latest::<Msg>(Msg::PRIORITY), None)
    }

    /// Forwards another aircraft's `frame` on `targets` with `priority`: the same
    /// header (source, destination, class, component, id) and the fields copied as they
    /// are, re-framed for each device's transport; counted as relayed
    /// ([`RelayedStats`](crate::stats::RelayedStats)).
    pub(crate) fn forward(
        &self,
        frame: &Frame<'_>,
        targets: Targets,
        priority: u8,
    ) -> Result<(), SendError> {
        self.core.send_fields(
            &RawFields(frame.payload()),
            Route::forward(frame, priority),
            Some(targets),
        )
    }

    /// The downlink's route table.
    pub fn routes(&self) -> Routes<'d> {
        self.core.routes()
    }

    /// Our aircraft id.
    pub fn ac_id(&self) -> u8 {
        self.core.ac_id()
    }

    /// Number of devices of the downlink.
    pub fn devices(&self) -> usize {
        self.core.device_count()
    }

    /// Statistics of device `index`.
    pub fn stats(&self, index: usize) -> Option<DeviceStats> {
        self.core.stats(index)
    }

    /// Sends that named no device; see [`Downlink::undeliverable`].
    pub fn undeliverable(&self) -> u32 {
        self.core.undeliverable()
    }

    /// Statistics of the shared arena.
    pub fn arena_stats(&self) -> ArenaStats {
        self.core.arena_stats()
    }
}

/// Names one device of a [`Downlink`]: obtained from the device's [`Port`], so a reader
/// given this handle replies on the device its requests came in on, by construction.
/// Copyable; sending through it never blocks.
#[derive(Clone, Copy)]
pub struct Device<'d> {
    core: &'d dyn Core,
    index: u8,
}

impl fmt::Debug for Device<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Device")
            .field("index", &self.index)
            .finish_non_exhaustive()
    }
}

impl PartialEq for Device<'_> {
    /// The same device of the same downlink.
    fn eq(&self, other: &Self) -> bool {
        core::ptr::addr_eq(self.core, other.core) && self.index == other.index
    }
}

impl Eq for Device<'_> {}

impl<'d> Device<'d> {
    /// The device's index in its downlink (the order of the configurations).
    pub fn index(&self) -> usize {
        usize::from(self.index)
    }

    /// Sends `msg` to this device only, at the message's own priority.
    ///
    /// # Errors
    /// The message was dropped (counted in this device's statistics).
    #[inline]
    pub fn send<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.send_with_priority(msg, Msg::PRIORITY)
    }

    /// Sends `msg` to this device only, with `priority`.
    ///
    /// # Errors
    /// The message was dropped (counted in this device's statistics).
    #[inline]
    pub fn send_with_priority<Msg: Message>(
        &self,
        msg: &Msg,
        priority: u8,
    ) -> Result<(), SendError> {
        self.core
            .send_fields(msg, Route::of::<Msg>(priority), Some(Targets::from(*self)))
    }

    /// Sends the state message `msg` to this device only, superseding a waiting older
    /// one; see [`Downlink::send_latest`].
    ///
    /// # Errors
    /// The message was dropped (counted in this device's statistics).
    #[inline]
    pub fn send_latest<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.core.send_fields(
            msg,
            Route::latest::<Msg>(Msg::PRIORITY),
            Some(Targets::from(*self)),
        )
    }

    /// Sends `msg`, an answer to a request received on this device, to this device at
    /// the message's own priority, within the device's [`ReplyLimit`], addressed to the
    /// ground.
    ///
    /// # Errors
    /// The reply was dropped, [`DropReason::RateLimited`] among the reasons (counted in
    /// this device's statistics).
    #[inline]
    pub fn reply<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.reply_to(msg, GROUND_ID)
    }

    /// [`reply`](Self::reply) addressed to `destination`: the sender of the request
    /// (the ground, or another aircraft; [`Received::reply`] answers its source).
    ///
    /// # Errors
    /// As [`reply`](Self::reply).
    ///
    /// [`Received::reply`]: crate::registry::Received::reply
    #[inline]
    pub fn reply_to<Msg: Message>(&self, msg: &Msg, destination: u8) -> Result<(), SendError> {
        self.core.send_fields(
            msg,
            Route::reply::<Msg>().to(destination),
            Some(Targets::from(*self)),
        )
    }

    /// A transmit status the radio sent for one of this device's frames (the device's
    /// [`Reader`](crate::reader::Reader) passes on those it decodes): frees that frame's
    /// place in the [`DeliveryWindow`] and counts the outcome; a status for no
    /// outstanding frame is counted and ignored.
    pub fn tx_status(&self, status: &TxStatus) {
        self.core
            .outstanding(self.index(), &mut |o| o.status(status));
    }

    /// What the transmit statuses of this device said.
    pub fn delivery_stats(&self) -> DeliveryStats {
        let mut stats = DeliveryStats::default();
        self.core
            .outstanding(self.index(), &mut |o| stats = o.stats);
        stats
    }

    /// Whether a frame may go to the modem now under `window`, else the deadline of the
    /// oldest outstanding frame (registering `cx` for the next status).
    pub(crate) fn delivery_room(
        &self,
        window: &DeliveryWindow,
        now: u64,
        cx: Option<&mut Context<'_>>,
    ) -> Result<(), u64> {
        let mut cx = cx;
        let mut room = Ok(());
        self.core.outstanding(self.index(), &mut |o| {
            room = o.room(window, now, cx.take());
        });
        room
    }

    /// A fresh frame id for a frame going to the modem now, recorded as outstanding.
    pub(crate) fn delivery_start(&self, window: &DeliveryWindow, now: u64) -> Option<u8> {
        let mut id = None;
        self.core
            .outstanding(self.index(), &mut |o| id = o.start(window, now));
        id
    }

    /// Statistics of this device.
    pub fn stats(&self) -> DeviceStats {
        self.core.stats(self.index()).unwrap_or_default()
    }

    /// The configuration of this device.
    pub fn config(&self) -> DeviceConfig {
        // A device handle only exists for an index of its downlink.
        self.core
            .config(self.index())
            .unwrap_or(DeviceConfig::new(AnyTransport::PprzV2(
                pprz_transports::PprzV2::new(),
            )))
    }

    /// A handle sending to every device of the same downlink.
    pub fn sender(&self) -> Sender<'d> {
        Sender { core: self.core }
    }

    /// Waits for this device's most important frame (see [`Port::next`]).
    pub(crate) async fn next(&self) -> Outgoing<'d> {
        poll_fn(|cx| match self.receive(Some(cx)) {
            Some(frame) => Poll::Ready(frame),
            None => Poll::Pending,
        })
        .await
    }

    /// Takes this device's most important frame; with a context, registers it for the
    /// next frame when there is none. For the device's one consumer: its [`Port`], or
    /// the writer task that holds the port.
    pub(crate) fn receive(&self, cx: Option<&mut Context<'_>>) -> Option<Outgoing<'d>> {
        let frame = self.core.try_receive(self.index(), cx)?;
        Some(Outgoing {
            frame: Some(frame),
            device: *self,
        })
    }
}

impl From<Device<'_>> for Targets {
    fn from(device: Device<'_>) -> Self {
        Targets::only(device.index())
    }
}

/// The consumer side of one device's queue, handed out once per device by
/// [`Downlink::ports`]: for the device's writer task ([`run_writer`](crate::run_writer)),
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
            .field("device", &self.device.index)
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
        self.device.receive(None)
    }

    /// The length of the most important frame waiting, if any, without taking it (a
    /// more important frame may arrive before the next [`try_next`](Self::try_next)).
    pub fn peek_len(&self) -> Option<usize> {
        self.device.core.peek_len(self.device.index(), None)
    }

    /// Waits until a frame waits, without taking it; returns the length of the most
    /// important one (as [`peek_len`](Self::peek_len)).
    pub async fn ready(&self) -> usize {
        let device = self.device;
        poll_fn(|cx| match device.core.peek_len(device.index(), Some(cx)) {
            Some(len) => Poll::Ready(len),
            None => Poll::Pending,
        })
        .await
    }

    /// Waits for the most important frame; as [`try_next`](Self::try_next).
    pub async fn next(&mut self) -> Outgoing<'_> {
        self.device.next().await
    }
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
            .field("device", &self.device.index)
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
        self.frame = self
            .device
            .core
            .complete(self.device.index(), frame, outcome, take_next);
    }

    /// [`refuse`](Self::refuse) in place.
    pub(crate) fn refuse_in_place(&mut self) {
        if let Some(frame) = self.frame.take() {
            self.device
                .core
                .complete(self.device.index(), frame, Err(DropReason::Refused), false);
        }
    }

    fn finish_with(mut self, outcome: Result<(), DropReason>) {
        if let Some(frame) = self.frame.take() {
            self.device
                .core
                .complete(self.device.index(), frame, outcome, false);
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
            self.device.core.complete(
                self.device.index(),
                frame,
                Err(DropReason::WriteError),
                false,
            );
        }
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
    fn reply_limit_is_a_token_bucket() {
        let tick = embassy_time::TICK_HZ;
        let limit = ReplyLimit::new(10, 3);
        let tat = Cell::new(0);
        // A burst of 3 at t = 0, then one every 100 ms.
        let at = |t: u64| limit.admit(&tat, t);
        assert_eq!([at(0), at(0), at(0), at(0)], [true, true, true, false]);
        assert!(!at(tick / 20));
        assert!(at(tick / 10));
        assert!(!at(tick / 10));
        // After a long silence the full burst again, no more.
        let later = 100 * tick;
        assert_eq!(
            [at(later), at(later), at(later), at(later)],
            [true, true, true, false]
        );
        // 0 per second: no replies; a burst of 0 counts as 1.
        assert!(!ReplyLimit::new(0, 5).admit(&Cell::new(0), 0));
        let one = Cell::new(0);
        assert!(ReplyLimit::new(1, 0).admit(&one, 0));
        assert!(!ReplyLimit::new(1, 0).admit(&one, 0));
        // Near the end of time, no overflow.
        assert!(ReplyLimit::new(u16::MAX, u16::MAX).admit(&Cell::new(0), u64::MAX));
    }

    #[test]
    fn targets() {
        let t = Targets::only(1).with(3);
        assert!(t.contains(1) && t.contains(3) && !t.contains(0));
        assert_eq!(Targets::only(40), Targets::NONE);
        assert!(Targets::ALL.contains(31));
    }
}
