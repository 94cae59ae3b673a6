//! The send path: [`Downlink`], its devices' queues in one shared arena, and the one
//! non-generic function that encodes a message into arena memory and queues it on each
//! of its devices, evicting less important frames when there is no room.

use core::cell::Cell;
#[cfg(feature = "xbee")]
use core::cell::RefCell;
use core::task::Context;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use pprz_messages::Message;
use pprz_transports::{Encoder, MsgHeader, TxMeta, TxStatus};

use super::config::DeviceConfig;
use super::options::{Route, SendError, SendOptions};
use crate::arena::{AllocError, ArenaStats, FrameArena, FrameBuf};
use crate::delivery::{DeliveryStats, DeliveryWindow, Outstanding};
use crate::queue::{FrameQueue, MessageKey, Pushed};
use crate::route::{Routes, Targets};
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
pub(crate) trait EncodeFields {
    /// [`Message::encoded_len`].
    fn fields_len(&self) -> usize;
    /// [`Message::encode`]; the send path only needs to know whether it failed.
    fn encode_fields(&self, buf: &mut [u8]) -> Option<usize>;
}

/// The fields of a frame being forwarded, copied as they are (never decoded).
pub(crate) struct RawFields<'p>(pub(crate) &'p [u8]);

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

/// The downlink of an aircraft: `D` devices with queues of capacity `Q` (1 to 64: a
/// larger `Q` does not compile), frames in a shared arena that lives for `'a`. See the
/// [module documentation](crate::downlink).
///
/// ```compile_fail
/// use pprz_telemetry::{Downlink, FrameArena, LinkMutex};
/// static ARENA: FrameArena<LinkMutex, 1024> = FrameArena::new();
/// static DOWNLINK: Downlink<'static, LinkMutex, 1, 65> = Downlink::new(&ARENA, 7, [
///     pprz_telemetry::DeviceConfig::new(pprz_telemetry::pprz_transports::AnyTransport::PprzV2(
///         pprz_telemetry::pprz_transports::PprzV2::new(),
///     )),
/// ]);
/// ```
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
    /// Per device, the frames awaiting their transmit status (only XBee radios send
    /// transmit statuses).
    #[cfg(feature = "xbee")]
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
            #[cfg(feature = "xbee")]
            outstanding: [const { Mutex::new(RefCell::new(Outstanding::new())) }; D],
            clock: no_clock,
            routes: Routes::DIRECT,
        }
    }

    /// Sets the route table: which devices lead to the ground, to each other aircraft
    /// and to broadcast ([`Routes`]; by default every device leads everywhere). Used by
    /// [`send`](Self::send) and [`send_with`](Self::send_with), and by the
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

    /// Marks the ports as handed out: `true` the first time only (one writer per
    /// device; see [`ports`](Self::ports)).
    pub(crate) fn claim_ports(&self) -> bool {
        !self.ports_taken.lock(|t| t.replace(true))
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
    /// a [`DeliveryWindow`](crate::DeliveryWindow)); `None` if there is no such device.
    pub fn delivery_stats(&self, index: usize) -> Option<DeliveryStats> {
        self.with_outstanding(index, |o| o.stats)
            .or_else(|| (index < D).then(DeliveryStats::default))
    }

    /// Runs `f` on device `device`'s outstanding frames, under the lock; `None` for a bad
    /// index, and always without the `xbee` feature (no other transport has transmit
    /// statuses, so no frame is ever outstanding).
    fn with_outstanding<R>(
        &self,
        device: usize,
        f: impl FnOnce(&mut Outstanding) -> R,
    ) -> Option<R> {
        #[cfg(feature = "xbee")]
        {
            let o = self.outstanding.get(device)?;
            Some(o.lock(|o| f(&mut o.borrow_mut())))
        }
        #[cfg(not(feature = "xbee"))]
        {
            let _ = (device, f);
            None
        }
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
        self.send_with(msg, SendOptions::new())
    }

    /// Sends `msg` as `options` say: destination, priority, devices, latest value or
    /// reply ([`SendOptions`]). Never blocks.
    ///
    /// The message is encoded once per distinct transport among its devices, directly
    /// into arena memory; devices sharing a transport get a copy of those bytes.
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there), or the options'
    /// device set named no device at all ([`DropReason::NoDevice`], counted in
    /// [`undeliverable`](Self::undeliverable)).
    #[inline]
    pub fn send_with<Msg: Message>(
        &self,
        msg: &Msg,
        options: SendOptions,
    ) -> Result<(), SendError> {
        self.send_fields(msg, Route::of::<Msg>(options), options.devices())
    }

    /// The send path of every message type: [`send_with`](Self::send_with) is a thin generic
    /// wrapper around it, so this is compiled once per downlink type instead of once per
    /// message type (about 450 bytes of flash each on a Cortex-M), for two indirect calls
    /// through the message's vtable (`fields_len`, and `encode_fields` per transport).
    /// Without `targets`, the message goes on the route of its destination (looked up
    /// here, so that the generic wrappers stay a few instructions each).
    pub(super) fn send_fields(
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

/// What the type-erased handles ([`Sender`](crate::Sender), [`Device`](crate::Device),
/// [`Port`](crate::Port)) need from a
/// [`Downlink`] of any mutex, device count and queue capacity.
pub(crate) trait Core: Sync {
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
    /// [`Outstanding::room`] of device `device` (`Ok` for a bad index).
    fn delivery_room(
        &self,
        device: usize,
        window: &DeliveryWindow,
        now: u64,
        cx: Option<&mut Context<'_>>,
    ) -> Result<(), u64>;
    /// [`Outstanding::start`] of device `device`.
    fn delivery_start(&self, device: usize, window: &DeliveryWindow, now: u64) -> Option<u8>;
    /// [`Outstanding::status`] of device `device`.
    fn tx_status(&self, device: usize, status: &TxStatus);
    /// [`Downlink::delivery_stats`].
    fn delivery_stats(&self, device: usize) -> Option<DeliveryStats>;
    /// Counts the outcome of `frame`, device `device`'s in-flight frame, and releases it;
    /// with `take_next`, then takes the device's next frame.
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

    fn delivery_room(
        &self,
        device: usize,
        window: &DeliveryWindow,
        now: u64,
        cx: Option<&mut Context<'_>>,
    ) -> Result<(), u64> {
        self.with_outstanding(device, |o| o.room(window, now, cx))
            .unwrap_or(Ok(()))
    }

    fn delivery_start(&self, device: usize, window: &DeliveryWindow, now: u64) -> Option<u8> {
        self.with_outstanding(device, |o| o.start(window, now))?
    }

    fn tx_status(&self, device: usize, status: &TxStatus) {
        self.with_outstanding(device, |o| o.status(status));
    }

    fn delivery_stats(&self, device: usize) -> Option<DeliveryStats> {
        Downlink::delivery_stats(self, device)
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

#[cfg(test)]
mod tests {
    use crate::queue::Candidate;

    #[test]
    fn delivery_stats_exist_for_each_device_only() {
        use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
        let arena: crate::FrameArena<M, 1024> = crate::FrameArena::new();
        let config = || crate::DeviceConfig::new(pprz_transports::PprzV2::new().into());
        let downlink: super::Downlink<'_, M, 2, 4> =
            super::Downlink::new(&arena, 7, [config(), config()]);
        let status = pprz_transports::TxStatus {
            frame_id: 1,
            delivered: true,
            status: 0,
            retries: 0,
        };
        // No frame is outstanding: counted as unexpected with the `xbee` feature (its
        // window exists), ignored without it (no transport has statuses).
        downlink.device(1).tx_status(&status);
        let unexpected = u32::from(cfg!(feature = "xbee"));
        let stats = downlink.delivery_stats(1).expect("device 1");
        assert_eq!(stats.unexpected, unexpected);
        assert_eq!(downlink.delivery_stats(0), Some(Default::default()));
        assert_eq!(downlink.delivery_stats(2), None);
    }

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
}
