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
//! use pprz_telemetry::registry::{Filter, Registry};
//! use pprz_telemetry::messages::datalink::Block;
//! use pprz_messages::Decode;
//!
//! static BLOCKS: AtomicU32 = AtomicU32::new(0);
//! let on_block = |rx: &pprz_telemetry::registry::Received<'_>| {
//!     if let Ok(block) = rx.decode::<Block>() {
//!         BLOCKS.fetch_add(u32::from(block.block_id), Ordering::Relaxed);
//!     }
//! };
//! let mut registry: Registry<'_, 8> = Registry::new();
//! registry.subscribe(Filter::message::<Block>(), &on_block).unwrap();
//! assert_eq!(registry.len(), 1);
//! ```

use core::cell::Cell;
use core::fmt;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::channel::Channel;
use pprz_messages::{Decode, DecodeError, Message};
use pprz_transports::Frame;

/// A message received on a link: the checksum-verified frame view and where it came
/// from.
#[derive(Debug, Clone, Copy)]
pub struct Received<'f> {
    /// The link (reader) it came from: by convention the index of the same device in the
    /// downlink, so replies go out where the request came in.
    pub link: usize,
    /// The frame: source, destination, class, component, message id, payload.
    pub frame: Frame<'f>,
}

impl<'f> Received<'f> {
    /// Class id of the message.
    pub fn class_id(&self) -> u8 {
        self.frame.class()
    }

    /// Message id.
    pub fn msg_id(&self) -> u8 {
        self.frame.msg_id()
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
}

/// Something that handles received messages. Implemented for every
/// `Fn(&Received) + Sync` closure or function.
pub trait Subscriber: Sync {
    /// Handles one message. Called by the reader task: keep it short, or hand the
    /// message to a task (see [`ChannelSubscriber`]).
    fn on_message(&self, rx: &Received<'_>);
}

impl<F: Fn(&Received<'_>) + Sync> Subscriber for F {
    fn on_message(&self, rx: &Received<'_>) {
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
pub struct Registry<'a, const N: usize> {
    entries: heapless::Vec<(Filter, &'a dyn Subscriber), N>,
}

impl<'a, const N: usize> Registry<'a, N> {
    /// An empty registry.
    pub const fn new() -> Self {
        Self {
            entries: heapless::Vec::new(),
        }
    }

    /// Adds a subscription (at start-up, before the readers run).
    ///
    /// # Errors
    /// [`RegistryFull`] when `N` subscriptions exist already.
    pub fn subscribe(
        &mut self,
        filter: Filter,
        subscriber: &'a dyn Subscriber,
    ) -> Result<(), RegistryFull> {
        self.entries
            .push((filter, subscriber))
            .map_err(|_| RegistryFull { capacity: N })
    }

    /// Number of subscriptions.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether there is no subscription.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Calls every subscriber whose filter matches, in registration order; returns how
    /// many were called.
    pub fn dispatch(&self, rx: &Received<'_>) -> usize {
        let (class_id, msg_id) = (rx.class_id(), rx.msg_id());
        let mut called = 0;
        for (filter, subscriber) in &self.entries {
            if filter.matches(class_id, msg_id) {
                subscriber.on_message(rx);
                called += 1;
            }
        }
        called
    }
}

impl<const N: usize> Default for Registry<'_, N> {
    fn default() -> Self {
        Self::new()
    }
}

/// A received message copied out of the reader's buffer, for async subscribers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OwnedMessage {
    /// The link it came from.
    pub link: usize,
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

impl OwnedMessage {
    /// Copies a received message; `None` if its payload exceeds 256 bytes (no Paparazzi
    /// transport carries that much).
    pub fn copy(rx: &Received<'_>) -> Option<Self> {
        Some(Self {
            link: rx.link,
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
}

/// Feeds an async subscriber task through a [`Channel`] of capacity `K`: the reader
/// never waits; when the channel is full the message is dropped and counted.
///
/// ```
/// use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
/// use embassy_sync::channel::Channel;
/// use pprz_telemetry::registry::{ChannelSubscriber, Filter, OwnedMessage, Registry};
/// # use critical_section as _;
///
/// static INBOX: Channel<M, OwnedMessage, 4> = Channel::new();
/// static NAV: ChannelSubscriber<'static, M, 4> = ChannelSubscriber::new(&INBOX);
///
/// let mut registry: Registry<'static, 8> = Registry::new();
/// registry.subscribe(Filter::Class(2), &NAV).unwrap();
/// // In the navigation task: `let msg = INBOX.receive().await;`
/// assert_eq!(NAV.dropped(), 0);
/// ```
pub struct ChannelSubscriber<'c, M: RawMutex, const K: usize> {
    channel: &'c Channel<M, OwnedMessage, K>,
    dropped: Mutex<M, Cell<u32>>,
}

impl<'c, M: RawMutex, const K: usize> ChannelSubscriber<'c, M, K> {
    /// A subscriber that forwards into `channel`.
    pub const fn new(channel: &'c Channel<M, OwnedMessage, K>) -> Self {
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

impl<M: RawMutex + Sync, const K: usize> Subscriber for ChannelSubscriber<'_, M, K> {
    fn on_message(&self, rx: &Received<'_>) {
        let sent = OwnedMessage::copy(rx).is_some_and(|m| self.channel.try_send(m).is_ok());
        if !sent {
            self.dropped.lock(|d| d.set(d.get().wrapping_add(1)));
        }
    }
}
