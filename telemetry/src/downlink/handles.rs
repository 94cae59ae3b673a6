//! The handles that send through a [`Downlink`] without naming its type: [`Sender`] (every
//! device, by route) and [`Device`] (one device, for targeted sends and replies).

use core::fmt;
use core::task::Context;

use embassy_sync::blocking_mutex::raw::RawMutex;
use pprz_messages::Message;
use pprz_transports::{AnyTransport, Frame, TxStatus};

use super::config::DeviceConfig;
use super::options::{Route, SendError, SendOptions};
use super::send::{Core, Downlink, RawFields};
use crate::arena::{ArenaStats, FrameBuf};
use crate::delivery::{DeliveryStats, DeliveryWindow};
use crate::route::{Routes, Targets};
use crate::stats::{DeviceStats, DropReason};

impl<'a, M: RawMutex + Sync, const D: usize, const Q: usize> Downlink<'a, M, D, Q> {
    /// A copyable, type-erased handle that sends through this downlink: what tasks and
    /// callbacks that only send should hold, so the downlink's mutex, device count and
    /// queue capacity do not appear in their signatures.
    pub fn sender(&self) -> Sender<'_> {
        Sender { core: self }
    }

    /// The handle of device `index` (an index below `D`, at most 32).
    pub(crate) fn device(&self, index: usize) -> Device<'_> {
        Device {
            core: self,
            // D <= 32 (checked at compile time by `Downlink::new`).
            index: index as u8,
        }
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
        self.send_with(msg, SendOptions::new())
    }

    /// Sends `msg` as `options` say; see [`Downlink::send_with`].
    ///
    /// # Errors
    /// The message was dropped for at least one device (counted there), or the options'
    /// device set named none.
    #[inline]
    pub fn send_with<Msg: Message>(
        &self,
        msg: &Msg,
        options: SendOptions,
    ) -> Result<(), SendError> {
        self.core
            .send_fields(msg, Route::of::<Msg>(options), options.devices())
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

/// Names one device of a [`Downlink`]: obtained from the device's [`Port`](crate::Port), so a reader
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

    /// Sends `msg` to the ground on this device only, at the message's own priority.
    ///
    /// # Errors
    /// The message was dropped (counted in this device's statistics).
    #[inline]
    pub fn send<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.send_with(msg, SendOptions::new())
    }

    /// Sends `msg` on this device only, as `options` say (destination, priority, latest
    /// value, reply; a device set named in `options` is replaced by this device).
    ///
    /// # Errors
    /// The message was dropped (counted in this device's statistics), among the reasons
    /// [`DropReason::RateLimited`](crate::DropReason::RateLimited) for a reply over the
    /// device's [`ReplyLimit`](crate::ReplyLimit).
    #[inline]
    pub fn send_with<Msg: Message>(
        &self,
        msg: &Msg,
        options: SendOptions,
    ) -> Result<(), SendError> {
        self.core
            .send_fields(msg, Route::of::<Msg>(options), Some(Targets::from(*self)))
    }

    /// Sends `msg`, an answer to a request received on this device, to the ground on
    /// this device, at the message's own priority, within the device's
    /// [`ReplyLimit`](crate::ReplyLimit). [`Received::reply`] answers the request's
    /// source instead.
    ///
    /// # Errors
    /// As [`send_with`](Self::send_with).
    ///
    /// [`Received::reply`]: crate::registry::Received::reply
    #[inline]
    pub fn reply<Msg: Message>(&self, msg: &Msg) -> Result<(), SendError> {
        self.send_with(msg, SendOptions::new().reply())
    }

    /// A transmit status the radio sent for one of this device's frames (the device's
    /// [`Reader`](crate::reader::Reader) passes on those it decodes): frees that frame's
    /// place in the [`DeliveryWindow`] and counts the outcome; a status for no
    /// outstanding frame is counted and ignored. Without the `xbee` feature no transport
    /// has transmit statuses, no frame is outstanding, and this does nothing.
    pub fn tx_status(&self, status: &TxStatus) {
        self.core.tx_status(self.index(), status);
    }

    /// What the transmit statuses of this device said.
    pub fn delivery_stats(&self) -> DeliveryStats {
        self.core.delivery_stats(self.index()).unwrap_or_default()
    }

    /// Whether a frame may go to the modem now under `window`, else the deadline of the
    /// oldest outstanding frame (registering `cx` for the next status).
    pub(crate) fn delivery_room(
        &self,
        window: &DeliveryWindow,
        now: u64,
        cx: Option<&mut Context<'_>>,
    ) -> Result<(), u64> {
        self.core.delivery_room(self.index(), window, now, cx)
    }

    /// A fresh frame id for a frame going to the modem now, recorded as outstanding.
    pub(crate) fn delivery_start(&self, window: &DeliveryWindow, now: u64) -> Option<u8> {
        self.core.delivery_start(self.index(), window, now)
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

    /// Takes this device's most important frame; with a context, registers it for the
    /// next frame when there is none. For the device's one consumer, its
    /// [`Port`](crate::Port).
    pub(crate) fn take_frame(&self, cx: Option<&mut Context<'_>>) -> Option<FrameBuf<'d>> {
        self.core.try_receive(self.index(), cx)
    }

    /// The length of this device's most important frame, if any, without taking it;
    /// with a context, registers it for the next frame when there is none.
    pub(crate) fn peek_len(&self, cx: Option<&mut Context<'_>>) -> Option<usize> {
        self.core.peek_len(self.index(), cx)
    }

    /// Counts the outcome of `frame`, this device's in-flight frame, and releases it;
    /// with `take_next`, then takes the device's next frame under the same lock.
    pub(crate) fn complete(
        &self,
        frame: FrameBuf<'_>,
        outcome: Result<(), DropReason>,
        take_next: bool,
    ) -> Option<FrameBuf<'d>> {
        self.core.complete(self.index(), frame, outcome, take_next)
    }
}

impl From<Device<'_>> for Targets {
    fn from(device: Device<'_>) -> Self {
        Targets::only(device.index())
    }
}
