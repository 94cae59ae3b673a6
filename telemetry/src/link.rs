//! The one-link facade: the common case of one device (a radio, a USB port, a UDP
//! socket) carrying telemetry down and datalink commands up, with the PING / SETTING /
//! GET_SETTING services, in one `static` and one task.
//!
//! ```text
//!   any task ── LINK.send(&msg) ──► priority queue (frames in ARENA) ──► writer ──► tx
//!                                                                          │
//!   rx ──► reader (decoder, destination filter) ──► services (PING, SETTING, GET_SETTING)
//!                                              └──► your subscribers    replies ┘
//! ```
//!
//! [`Link::run`] is that one task: the writer, the reader and the services, until the
//! end of time. A firmware needs two statics and a task:
//!
//! ```
//! use pprz_telemetry::{FrameArena, Link, LinkMutex};
//! use pprz_default::messages::{Set, telemetry::Attitude}; // your generated set
//!
//! static ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
//! static LINK: Link<'static, Set> = Link::new(&ARENA, 7); // aircraft 7, PPRZ v2
//!
//! // #[embassy_executor::task]
//! async fn radio(tx: impl embedded_io_async::Write, rx: impl embedded_io_async::Read) {
//!     let Err(e) = LINK.run(tx, rx).await; // never returns, unless started twice
//!     panic!("{e}");
//! }
//!
//! // Anywhere, from any task: never blocks.
//! LINK.send(&Attitude { phi: 0.1, psi: 0.0, theta: 0.0 }).unwrap();
//! assert_eq!(LINK.stats().downlink.queued, 1);
//! ```
//!
//! The message set must have the services' messages (PING, PONG, SETTING, GET_SETTING,
//! DL_VALUE): with a set that lacks them, `run` does not compile, and the compiler's note
//! names the messages to add.
//!
//! ```compile_fail,E0277
//! use pprz_telemetry::{FrameArena, Link, LinkMutex};
//! struct NoServices; // a set without the services' messages
//! static ARENA: FrameArena<LinkMutex, 1024> = FrameArena::new();
//! static LINK: Link<'static, NoServices> = Link::new(&ARENA, 7);
//! async fn radio(tx: &mut [u8], rx: &[u8]) {
//!     let _ = LINK.run(tx, rx).await;
//! }
//! ```
//!
//! # Which mutex
//!
//! Every lock of the link (settings, health, registry, the writer's waker, and the
//! arena's, which should be the same mutex) is the link's mutex `M`. The queue and the
//! arena take no lock on cores with compare-and-swap: frames and memory change hands with
//! atomic bit operations. (Cores without it, such as the Cortex-M0, do each of those as
//! a load and a store under `M`.)
//!
//! * [`LinkMutex`] (`CriticalSectionRawMutex`, the default): any task of any executor,
//!   and interrupt handlers, may send. Each lock masks interrupts while it is held: on
//!   the send path of a Cortex-M4, only when a send wakes the sleeping writer (at most
//!   about 20 instructions; `BENCHMARKS.md`).
//! * `ThreadModeRawMutex` (embassy-sync, Cortex-M): for a single-core firmware whose
//!   senders all run in thread mode (tasks of a thread-mode executor). The link never
//!   masks an interrupt, so it never delays an interrupt handler; a send from an
//!   interrupt handler, or from a task of an interrupt-mode executor, panics. (On a
//!   two-core chip such as the RP2040 it does not exclude the other core.)
//! * `mutex::BasepriRawMutex<C>` (feature `basepri`, Cortex-M3/M4/M7/M33): a lock raises
//!   `BASEPRI` to a priority ceiling instead of masking everything. Thread mode and
//!   interrupt handlers at the ceiling or below may send; handlers above it (motors,
//!   sensors) are never delayed by the link and must not use it (a lock from there
//!   panics).
//!
//! ```no_run
//! use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
//! use pprz_default::messages::{Set, telemetry::Attitude};
//! use pprz_telemetry::{FrameArena, Link};
//!
//! static ARENA: FrameArena<ThreadModeRawMutex, 4096> = FrameArena::new();
//! static LINK: Link<'static, Set, 32, 16, 8, ThreadModeRawMutex> = Link::new(&ARENA, 7);
//!
//! // In a task of the thread-mode executor:
//! LINK.send(&Attitude { phi: 0.1, psi: 0.0, theta: 0.0 }).unwrap();
//! ```
//!
//! Settings and subscribers are added at start-up, before or after `run` starts:
//! `LINK.settings().add("gain", &get, &set)`, `LINK.subscribe(Filter::message::<Block>(),
//! &on_block)`. Several devices, several transports per message or a log beside the
//! radio: use [`Downlink`] and its [`Port`]s directly; this facade is built
//! on them.

use core::cell::Cell;
use core::convert::Infallible;

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, RawMutex};
use embedded_io_async::{Read, Write};
use pprz_messages::Message;
use pprz_messages::roles::ServiceSet;
use pprz_transports::{AnyTransport, PprzV2};

use crate::arena::ArenaStats;
use crate::delivery::DeliveryStats;
use crate::downlink::{DeviceConfig, Downlink, FrameAlloc, SendError, SendOptions, Sender};
use crate::health::{HealthConfig, LinkHealth};
use crate::layer::{LinkLayer, Plain};
use crate::reader::{Datalink, Inbox, Layered, Reader, UplinkStats};
use crate::registry::{Filter, Received, RegistryFull, Subscriber};
use crate::services::{ServiceStats, Services};
use crate::settings::Settings;
use crate::stats::DeviceStats;
use crate::writer::{Port, PortsTaken, run_writer_with};

/// The mutex of a [`Link`] (a critical section: the link may be used from any task and
/// from interrupts); also the one to give its [`FrameArena`](crate::FrameArena).
pub type LinkMutex = CriticalSectionRawMutex;

/// One device with telemetry, datalink and services, for message set `S`; see the
/// [module documentation](self).
///
/// * `Q`: the most frames waiting for the device, 1 to 64 (when full, less important
///   frames are evicted, or the new one dropped, and counted).
/// * `SETTINGS`: capacity of the settings table.
/// * `SUBSCRIBERS`: capacity of the subscriber registry (the services need none of it).
/// * `M`: the mutex of every lock of the link ([`LinkMutex`] by default: sends from any
///   task and from interrupts, each lock a short interrupt mask). A firmware that sends
///   only from thread mode may choose `ThreadModeRawMutex`: no interrupt is ever masked
///   by the link, and a send from an interrupt handler panics (see the
///   [module documentation](self)).
pub struct Link<
    'a,
    S,
    const Q: usize = 32,
    const SETTINGS: usize = 16,
    const SUBSCRIBERS: usize = 8,
    M: RawMutex + Sync + 'static = LinkMutex,
> {
    downlink: Downlink<'a, M, 1, Q>,
    datalink: Datalink<'a, M, SUBSCRIBERS>,
    services: Services<'a, S, M, SETTINGS>,
    health: LinkHealth<M>,
    /// The device's port between two runs (a cancelled `run` puts it back here).
    port: Mutex<M, Cell<Option<Port<'a>>>>,
}

/// Counters of a [`Link`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkStats {
    /// The downlink: messages submitted, sent, dropped and evicted by reason and level.
    pub downlink: DeviceStats,
    /// The uplink: messages received, for another aircraft, unhandled, read errors.
    pub uplink: UplinkStats,
    /// The services: requests answered and refused.
    pub services: ServiceStats,
    /// The frame arena.
    pub arena: ArenaStats,
    /// The radio's transmit statuses (XBee API with a [`DeliveryWindow`](crate::DeliveryWindow);
    /// all zero otherwise).
    pub delivery: DeliveryStats,
}

impl<'a, S, const Q: usize, const SETTINGS: usize, const SUBSCRIBERS: usize, M>
    Link<'a, S, Q, SETTINGS, SUBSCRIBERS, M>
where
    M: RawMutex + Sync + 'static,
{
    /// A link for aircraft `ac_id` speaking PPRZ v2, frames allocated in `arena`.
    pub const fn new(arena: &'a (dyn FrameAlloc + Sync), ac_id: u8) -> Self {
        Self::with_device(
            arena,
            ac_id,
            DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),
        )
    }

    /// A link for aircraft `ac_id` over a device configured by `config` (its transport
    /// is used both ways; e.g. `AnyTransport::XBee24(XBee24::new())`).
    pub const fn with_device(
        arena: &'a (dyn FrameAlloc + Sync),
        ac_id: u8,
        config: DeviceConfig,
    ) -> Self {
        Self {
            downlink: Downlink::new(arena, ac_id, [config]),
            datalink: Datalink::new(ac_id),
            services: Services::new(ac_id),
            health: LinkHealth::new(HealthConfig::new()),
            port: Mutex::new(Cell::new(None)),
        }
    }

    /// The same link, its [health](Self::health) judged by `config` (timeouts, what
    /// counts as heard, the way back to Up).
    pub const fn health_config(mut self, config: HealthConfig) -> Self {
        self.health.set_config(config);
        self
    }

    /// Our aircraft id.
    pub fn ac_id(&self) -> u8 {
        self.downlink.ac_id()
    }

    /// Sends `msg` at its own priority; never blocks.
    ///
    /// # Errors
    /// The message was dropped (too large, or no room for it: counted in
    /// [`LinkStats::downlink`]).
    pub fn send<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.downlink.send(msg)
    }

    /// Sends `msg` as `options` say (a priority override, a state message whose newer
    /// value replaces a waiting one, ...; see [`SendOptions`]). Never blocks.
    ///
    /// # Errors
    /// As [`send`](Self::send).
    pub fn send_with<Msg: Message>(
        &self,
        msg: &Msg,
        options: SendOptions,
    ) -> Result<(), SendError> {
        self.downlink.send_with(msg, options)
    }

    /// A copyable handle that sends through this link, for code that should not name
    /// the link's type.
    pub fn sender(&self) -> Sender<'_> {
        self.downlink.sender()
    }

    /// The settings table the SETTING and GET_SETTING services read and write.
    pub fn settings(&self) -> &Settings<'a, M, SETTINGS> {
        self.services.settings()
    }

    /// Subscribes to received messages (the services' messages are answered whether or
    /// not someone subscribes to them too).
    ///
    /// # Errors
    /// [`RegistryFull`] when `SUBSCRIBERS` subscriptions exist already.
    pub fn subscribe(
        &self,
        filter: Filter,
        subscriber: &'a dyn Subscriber<'a>,
    ) -> Result<(), RegistryFull> {
        self.datalink.subscribe(filter, subscriber)
    }

    /// Whether the ground is still there: its state, the time since it was last heard,
    /// and an `async` wait for a change that a failsafe task awaits (see
    /// [`health`](crate::health)). Driven by the frames the link's reader accepts.
    pub fn health(&self) -> &LinkHealth<M> {
        &self.health
    }

    /// A snapshot of every counter.
    pub fn stats(&self) -> LinkStats {
        LinkStats {
            downlink: self.downlink.stats(0).unwrap_or_default(),
            uplink: self.datalink.stats(),
            services: self.services.stats(),
            arena: self.downlink.arena_stats(),
            delivery: self.downlink.delivery_stats(0).unwrap_or_default(),
        }
    }
}

/// The bound `S: ServiceSet` is on each method, not on this block, so that a message set
/// without the services' messages gets the trait's explanation (E0277), not a bare
/// "method not found" (E0599).
impl<'a, S, const Q: usize, const SETTINGS: usize, const SUBSCRIBERS: usize, M>
    Link<'a, S, Q, SETTINGS, SUBSCRIBERS, M>
where
    M: RawMutex + Sync + 'static,
{
    /// Runs the link forever: writes the queued frames to `tx` (most important first),
    /// reads `rx`, answers PING, SETTING and GET_SETTING on it and hands every other
    /// message for us to the subscribers.
    ///
    /// If the `run` future is dropped (e.g. its task ended on a USB disconnect), the frame
    /// being written counts as a write error and the link can run again.
    ///
    /// # Errors
    /// Returns at once with [`PortsTaken`] if the link is running already: a device has
    /// one writer.
    pub async fn run<W: Write, R: Read>(&'a self, tx: W, rx: R) -> Result<Infallible, PortsTaken>
    where
        S: ServiceSet,
    {
        self.run_with_layer(tx, rx, &Plain).await
    }

    /// [`run`](Self::run) with a [`LinkLayer`] on the device (the secure link of
    /// `pprz-secure`): the writer seals each frame with `layer` as it takes it for the
    /// wire, and the reader opens each received frame with it before the services and
    /// subscribers see it. Create the link [`with_device`](Self::with_device) and a
    /// configuration that [reserves](DeviceConfig::reserve) the layer's overhead.
    ///
    /// # Errors
    /// As [`run`](Self::run).
    pub async fn run_with_layer<W: Write, R: Read, L: LinkLayer + ?Sized>(
        &'a self,
        tx: W,
        rx: R,
        layer: &L,
    ) -> Result<Infallible, PortsTaken>
    where
        S: ServiceSet,
    {
        let port = match self.port.lock(Cell::take) {
            Some(port) => port,
            None => {
                let [port] = self.downlink.ports()?;
                port
            }
        };
        let mut guard = PortGuard {
            slot: &self.port,
            port: Some(port),
        };
        let Some(port) = guard.port.as_mut() else {
            return Err(PortsTaken);
        };
        let transport = port.device().config().transport;
        let mut reader: Reader<'a, R, AnyTransport> = Reader::new(rx, transport, port.device());
        let inbox = LinkInbox { link: self };
        let inbox = Layered::new(layer, &inbox);
        match select(run_writer_with(port, tx, layer), reader.run(&inbox)).await {
            Either::First(never) | Either::Second(never) => never,
        }
    }
}

/// Gives the port back to its link when `run` ends (it only ends by being dropped).
struct PortGuard<'l, 'a, M: RawMutex> {
    slot: &'l Mutex<M, Cell<Option<Port<'a>>>>,
    port: Option<Port<'a>>,
}

impl<M: RawMutex> Drop for PortGuard<'_, '_, M> {
    fn drop(&mut self) {
        let port = self.port.take();
        self.slot.lock(|slot| slot.set(port));
    }
}

/// The link's reader delivers here: destination filter and counters, the services,
/// then the subscribers.
struct LinkInbox<
    'l,
    'a,
    S,
    const Q: usize,
    const SETTINGS: usize,
    const SUBSCRIBERS: usize,
    M: RawMutex + Sync + 'static,
> {
    link: &'l Link<'a, S, Q, SETTINGS, SUBSCRIBERS, M>,
}

impl<'a, S: ServiceSet, const Q: usize, const SETTINGS: usize, const SUBSCRIBERS: usize, M>
    Inbox<'a> for LinkInbox<'_, 'a, S, Q, SETTINGS, SUBSCRIBERS, M>
where
    M: RawMutex + Sync + 'static,
{
    fn deliver(&self, rx: &Received<'_, 'a>) {
        self.link
            .datalink
            .deliver_with(rx, Some(&self.link.services), Some(&self.link.health));
    }

    fn read_error(&self) {
        self.link.datalink.read_error();
    }
}
