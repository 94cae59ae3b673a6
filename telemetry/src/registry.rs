//! The subscriber registry of the datalink: who gets which received message.
//!
//! Filled at start-up (no macros, no global switch), then shared read-only by every
//! reader task. Several subscribers may subscribe to one message (by class and id), to a
//! whole class, or to everything. Subscribers are either plain callbacks, called by the
//! reader with the received frame and the link it came from, or async tasks fed through
//! an embassy-sync [`Channel`] by a [`ChannelSubscriber`], which counts the messages it
//! drops when its task is too slow.
//!
//! ```
//! use core::sync::atomic::{AtomicU32, Ordering};
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_telemetry::registry::{Filter, Received, Registry};
//! use pprz_default::messages::datalink::Block; // any generated message set
//!
//! static BLOCKS: AtomicU32 = AtomicU32::new(0);
//! fn on_block(rx: &Received<'_, '_>) {
//!     if let Ok(block) = rx.decode::<Block>() {
//!         BLOCKS.fetch_add(u32::from(block.block_id), Ordering::Relaxed);
//!     }
//! }
//! static REGISTRY: Registry<'static, M, 8> = Registry::new();
//! REGISTRY.subscribe(Filter::message::<Block>(), &on_block).unwrap();
//! assert_eq!(REGISTRY.len(), 1);
//! ```

use core::cell::{Cell, RefCell};
use core::fmt;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::channel::Channel;
use pprz_messages::{Decode, DecodeError, Message};
use pprz_transports::Frame;

use crate::downlink::{Device, SendError, SendOptions};

/// A message received on a device: the checksum-verified frame view (borrowed from the
/// reader's buffer for `'f`) and the device it came in on (the reader's, a handle that
/// lives for `'d`), where [`reply`](Self::reply) sends.
#[derive(Debug, Clone, Copy)]
pub struct Received<'f, 'd> {
    /// The device it came in on.
    pub device: Device<'d>,
    /// The frame: source, destination, class, component, message id, payload.
    pub frame: Frame<'f>,
    /// Whether a link layer vouched for the frame.
    pub trust: Trust,
}

/// Whether a [link layer](crate::layer) vouched for a received frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Trust {
    /// No layer that authenticates is on the device: the frame is as the transport
    /// decoded it.
    Plain,
    /// A layer authenticated it (a sealed frame of the secure link, checked and not a
    /// replay).
    Authenticated,
    /// A layer that authenticates let it through without authenticating it (a plaintext
    /// frame on its whitelist, such as the key exchange).
    Unauthenticated,
}

impl<'f, 'd> Received<'f, 'd> {
    /// `frame`, received on `device`, with no layer's word on it ([`Trust::Plain`]).
    pub const fn new(device: Device<'d>, frame: Frame<'f>) -> Self {
        Self {
            device,
            frame,
            trust: Trust::Plain,
        }
    }

    /// Class id of the message.
    pub fn class_id(&self) -> u8 {
        self.frame.class()
    }

    /// Message id.
    pub fn msg_id(&self) -> u8 {
        self.frame.msg_id()
    }

    /// Who sent it: the ground ([`GROUND_ID`]) or an aircraft id (for PPRZ v1, the
    /// frame's sender id).
    ///
    /// [`GROUND_ID`]: pprz_transports::GROUND_ID
    pub fn source(&self) -> u8 {
        self.frame.source()
    }

    /// The message fields.
    pub fn payload(&self) -> &'f [u8] {
        self.frame.payload()
    }

    /// Decodes the message as `M`.
    ///
    /// # Errors
    /// [`DecodeError::UnknownMessage`] if the frame is not an `M` (other class or id),
    /// or the payload's decoding error.
    pub fn decode<M: Decode<'f>>(&self) -> Result<M, DecodeError> {
        if (self.class_id(), self.msg_id()) != (M::CLASS_ID, M::ID) {
            return Err(DecodeError::UnknownMessage {
                class_id: self.class_id(),
                msg_id: self.msg_id(),
            });
        }
        M::decode(self.payload())
    }

    /// Sends `msg` on the device the message came in on, addressed to its
    /// [`source`](Self::source) (the ground for a PPRZ v1 frame, which names no
    /// destination), at `msg`'s priority, within that device's reply rate limit
    /// ([`SendOptions::reply`]); never blocks.
    ///
    /// # Errors
    /// The reply was dropped (counted in that device's statistics).
    pub fn reply<M: Message>(&self, msg: &M) -> Result<(), SendError> {
        let to = match self.frame.destination() {
            Some(_) => self.frame.source(),
            None => pprz_transports::GROUND_ID,
        };
        self.device
            .send_with(msg, SendOptions::new().to(to).reply())
    }
}

/// Something that handles received messages arriving on devices that live for `'d`.
/// Implemented for every `Fn(&Received<'_, '_>) + Sync` closure or function.
pub trait Subscriber<'d>: Sync {
    /// Handles one message. Called by the reader task: keep it short, or hand the
    /// message to a task (see [`ChannelSubscriber`]).
    fn on_message(&self, rx: &Received<'_, 'd>);
}

impl<'d, F: Fn(&Received<'_, 'd>) + Sync> Subscriber<'d> for F {
    fn on_message(&self, rx: &Received<'_, 'd>) {
        self(rx)
    }
}

/// Which messages a subscriber gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Filter {
    /// One message, by class and id.
    Message {
        /// Class id.
        class_id: u8,
        /// Message id.
        msg_id: u8,
    },
    /// Every message of a class.
    Class(u8),
    /// Every message (catch-all).
    All,
}

impl Filter {
    /// The filter for the generated message type `M`.
    pub const fn message<M: Message>() -> Self {
        Filter::Message {
            class_id: M::CLASS_ID,
            msg_id: M::ID,
        }
    }

    /// Whether a message of this class and id passes.
    pub const fn matches(&self, class_id: u8, msg_id: u8) -> bool {
        match *self {
            Filter::Message {
                class_id: c,
                msg_id: m,
            } => c == class_id && m == msg_id,
            Filter::Class(c) => c == class_id,
            Filter::All => true,
        }
    }
}

/// The registry has no room for another subscription.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RegistryFull {
    /// Capacity of the registry.
    pub capacity: usize,
}

impl fmt::Display for RegistryFull {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "subscriber registry full ({} subscriptions): raise its capacity",
            self.capacity
        )
    }
}

impl core::error::Error for RegistryFull {}

/// Up to `N` subscriptions, in registration order.
///
/// Subscriptions are added through `&self` (at start-up, typically), so a registry can
/// be a `static`; `M` protects the list (each lock is short and never held while a
/// subscriber runs, so a subscriber may use the registry).
pub struct Registry<'a, M: RawMutex, const N: usize> {
    /// `entries[..len]` are the subscriptions. (A plain array: no drop glue, so a
    /// subscriber may borrow the structure that holds the registry.)
    inner: Mutex<M, RefCell<Subscriptions<'a, N>>>,
}

struct Subscriptions<'a, const N: usize> {
    len: usize,
    entries: [Option<(Filter, &'a dyn Subscriber<'a>)>; N],
}

impl<'a, M: RawMutex, const N: usize> Registry<'a, M, N> {
    /// An empty registry.
    pub const fn new() -> Self {
        Self {
            inner: Mutex::new(RefCell::new(Subscriptions {
                len: 0,
                entries: [None; N],
            })),
        }
    }

    /// Adds a subscription.
    ///
    /// # Errors
    /// [`RegistryFull`] when `N` subscriptions exist already.
    pub fn subscribe(
        &self,
        filter: Filter,
        subscriber: &'a dyn Subscriber<'a>,
    ) -> Result<(), RegistryFull> {
        self.inner.lock(|s| {
            let mut s = s.borrow_mut();
            let len = s.len;
            let slot = s.entries.get_mut(len).ok_or(RegistryFull { capacity: N })?;
            *slot = Some((filter, subscriber));
            s.len = len + 1;
            Ok(())
        })
    }

    /// Number of subscriptions.
    pub fn len(&self) -> usize {
        self.inner.lock(|s| s.borrow().len)
    }

    /// Whether there is no subscription.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Calls every subscriber whose filter matches, in registration order; returns how
    /// many were called.
    pub fn dispatch(&self, rx: &Received<'_, 'a>) -> usize {
        let (class_id, msg_id) = (rx.class_id(), rx.msg_id());
        let mut called = 0;
        let mut from = 0;
        while let Some((subscriber, next)) = self.find(from, class_id, msg_id) {
            subscriber.on_message(rx);
            called += 1;
            from = next;
        }
        called
    }

    /// The first subscriber from slot `from` on whose filter matches, and the slot after
    /// it; the lock is released before the subscriber is called.
    fn find(
        &self,
        from: usize,
        class_id: u8,
        msg_id: u8,
    ) -> Option<(&'a dyn Subscriber<'a>, usize)> {
        self.inner.lock(|s| {
            let s = s.borrow();
            let entries = s.entries.get(from..s.len)?;
            entries.iter().enumerate().find_map(|(i, e)| {
                e.filter(|(f, _)| f.matches(class_id, msg_id))
                    .map(|(_, sub)| (sub, from + i + 1))
            })
        })
    }
}

impl<M: RawMutex, const N: usize> Default for Registry<'_, M, N> {
    fn default() -> Self {
        Self::new()
    }
}

/// A received message copied out of the reader's buffer, for async subscribers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OwnedMessage<'d> {
    /// The device it came in on (where [`reply`](Self::reply) sends).
    pub device: Device<'d>,
    /// Sender id.
    pub source: u8,
    /// Destination id (`None` on PPRZ v1, which has none).
    pub destination: Option<u8>,
    /// Class id.
    pub class_id: u8,
    /// Component id.
    pub component: u8,
    /// Message id.
    pub msg_id: u8,
    /// The message fields.
    pub payload: heapless::Vec<u8, 256>,
}

impl<'d> OwnedMessage<'d> {
    /// Copies a received message; `None` if its payload exceeds 256 bytes (no Paparazzi
    /// transport carries that much).
    pub fn copy(rx: &Received<'_, 'd>) -> Option<Self> {
        Some(Self {
            device: rx.device,
            source: rx.frame.source(),
            destination: rx.frame.destination(),
            class_id: rx.class_id(),
            component: rx.frame.component(),
            msg_id: rx.msg_id(),
            payload: heapless::Vec::from_slice(rx.payload()).ok()?,
        })
    }

    /// Decodes the message as `M`, as [`Received::decode`].
    ///
    /// # Errors
    /// Not an `M`, or the payload's decoding error.
    pub fn decode<'p, M: Decode<'p>>(&'p self) -> Result<M, DecodeError> {
        if (self.class_id, self.msg_id) != (M::CLASS_ID, M::ID) {
            return Err(DecodeError::UnknownMessage {
                class_id: self.class_id,
                msg_id: self.msg_id,
            });
        }
        M::decode(&self.payload)
    }

    /// Sends `msg` on the device the message came in on; as [`Received::reply`].
    ///
    /// # Errors
    /// The reply was dropped (counted in that device's statistics).
    pub fn reply<M: Message>(&self, msg: &M) -> Result<(), SendError> {
        self.device.reply(msg)
    }
}

/// Feeds an async subscriber task through a [`Channel`] of capacity `K`: the reader
/// never waits; when the channel is full the message is dropped and counted.
///
/// The messages carry the handle of the device they came in on, for replies, so the
/// channel's lifetime is the devices' (a `static` channel needs a `static` downlink).
///
/// ```
/// use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
/// use embassy_sync::channel::Channel;
/// use pprz_telemetry::registry::{ChannelSubscriber, Filter, OwnedMessage, Registry};
/// # use critical_section as _;
///
/// static INBOX: Channel<M, OwnedMessage<'static>, 4> = Channel::new();
/// static NAV: ChannelSubscriber<'static, M, 4> = ChannelSubscriber::new(&INBOX);
/// static REGISTRY: Registry<'static, M, 8> = Registry::new();
///
/// REGISTRY.subscribe(Filter::Class(2), &NAV).unwrap();
/// // In the navigation task: `let msg = INBOX.receive().await;`
/// assert_eq!(NAV.dropped(), 0);
/// ```
pub struct ChannelSubscriber<'c, M: RawMutex, const K: usize> {
    channel: &'c Channel<M, OwnedMessage<'c>, K>,
    dropped: Mutex<M, Cell<u32>>,
}

impl<'c, M: RawMutex, const K: usize> ChannelSubscriber<'c, M, K> {
    /// A subscriber that forwards into `channel`.
    pub const fn new(channel: &'c Channel<M, OwnedMessage<'c>, K>) -> Self {
        Self {
            channel,
            dropped: Mutex::new(Cell::new(0)),
        }
    }

    /// Messages dropped because the channel was full.
    pub fn dropped(&self) -> u32 {
        self.dropped.lock(Cell::get)
    }
}

impl<'c, M: RawMutex + Sync, const K: usize> Subscriber<'c> for ChannelSubscriber<'c, M, K> {
    fn on_message(&self, rx: &Received<'_, 'c>) {
        let sent = OwnedMessage::copy(rx).is_some_and(|m| self.channel.try_send(m).is_ok());
        if !sent {
            self.dropped.lock(|d| d.set(d.get().wrapping_add(1)));
        }
    }
}
