//! What one send names: [`SendOptions`] (destination, priority, devices, latest value,
//! reply) and what it returns ([`SendError`]).

use core::fmt;

use pprz_messages::Message;
use pprz_transports::{Frame, GROUND_ID};

use crate::route::Targets;
use crate::stats::DropReason;

/// How to send one message, for `send_with` (on [`Downlink`](crate::Downlink),
/// [`Sender`](crate::Sender), [`Device`](crate::Device) and [`Link`](crate::Link)).
///
/// Every choice has a name, so no two arguments of one type can be swapped. The default
/// ([`new`](Self::new)) is what plain `send` does: to the ground, at the message's own
/// priority, on the devices of the ground's route, queued as an event. A value is
/// `const`, so a task can keep its options in a `const`.
///
/// ```
/// use pprz_telemetry::{SendOptions, Targets};
///
/// // To aircraft 8, ahead of the usual traffic.
/// const URGENT_TO_8: SendOptions = SendOptions::new().to(8).priority(250);
/// // A periodic sample on the log (device 1) only: a newer one replaces a waiting one.
/// const LOG_SAMPLE: SendOptions = SendOptions::new().on(Targets::only(1)).latest();
/// assert_ne!(URGENT_TO_8, LOG_SAMPLE);
/// assert_eq!(SendOptions::new(), SendOptions::default());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SendOptions {
    to: u8,
    priority: Option<u8>,
    devices: Option<Targets>,
    latest: bool,
    reply: bool,
}

impl SendOptions {
    /// To the ground, at the message's own priority, on the ground's route.
    pub const fn new() -> Self {
        Self {
            to: GROUND_ID,
            priority: None,
            devices: None,
            latest: false,
            reply: false,
        }
    }

    /// Addressed to aircraft `aircraft`: an aircraft id,
    /// [`GROUND_ID`] (the default) or
    /// [`BROADCAST_ID`](pprz_transports::BROADCAST_ID) for every aircraft. Without
    /// [`on`](Self::on), the message goes out on the devices of that destination's
    /// [route](crate::Routes).
    pub const fn to(mut self, aircraft: u8) -> Self {
        self.to = aircraft;
        self
    }

    /// At `priority` (0..=255, higher is more important) instead of the message's own.
    pub const fn priority(mut self, priority: u8) -> Self {
        self.priority = Some(priority);
        self
    }

    /// On the devices in `devices` only, whatever the route (indices beyond the last
    /// device are ignored; a set naming no device is refused as
    /// [`DropReason::NoDevice`]). `Targets::from(device)` names one device.
    pub const fn on(mut self, devices: Targets) -> Self {
        self.devices = Some(devices);
        self
    }

    /// A **state** message (a periodic sample: attitude, position, status): where an
    /// older message of the same type and priority still waits in a device's queue, the
    /// new one takes its place (the old one counts as
    /// [`superseded`](crate::DeviceStats::superseded)), so a saturated link carries the
    /// latest value, not a stale backlog. Events (acknowledgements, one-shot messages)
    /// are sent without it.
    ///
    /// Only one stream of a message type should be sent this way: two sources of the
    /// same message (two sensors reporting through one message type) would supersede
    /// each other.
    pub const fn latest(mut self) -> Self {
        self.latest = true;
        self
    }

    /// An answer to a request received on the device: within each device's
    /// [`ReplyLimit`](crate::ReplyLimit); replies over it are refused and counted as
    /// [`DropReason::RateLimited`].
    pub const fn reply(mut self) -> Self {
        self.reply = true;
        self
    }

    /// The device set named with [`on`](Self::on), if any.
    pub(crate) const fn devices(&self) -> Option<Targets> {
        self.devices
    }
}

impl Default for SendOptions {
    fn default() -> Self {
        Self::new()
    }
}

/// Class, id, destination and priority of a send, whether it answers a request (subject
/// to the devices' [`ReplyLimit`]), whether it is a state message (a newer one supersedes
/// a waiting older one) and, for another aircraft's frame being forwarded, its source
/// and component, passed as two words to the shared send path.
#[derive(Clone, Copy)]
pub(crate) struct Route {
    pub(crate) class: u8,
    pub(crate) msg_id: u8,
    pub(crate) priority: u8,
    pub(crate) reply: bool,
    pub(crate) latest: bool,
    pub(crate) to: u8,
    pub(crate) relayed: Option<Relayed>,
}

/// The header fields a forwarded frame keeps: its source and component.
#[derive(Clone, Copy)]
pub(crate) struct Relayed {
    pub(crate) source: u8,
    pub(crate) component: u8,
}

impl Route {
    /// A `Msg` sent with `options`.
    #[inline]
    pub(crate) fn of<Msg: Message>(options: SendOptions) -> Self {
        Self {
            class: Msg::CLASS_ID,
            msg_id: Msg::ID,
            priority: match options.priority {
                Some(priority) => priority,
                None => Msg::PRIORITY,
            },
            reply: options.reply,
            latest: options.latest,
            to: options.to,
            relayed: None,
        }
    }

    /// Another aircraft's `frame`, forwarded with `priority`.
    pub(crate) fn forward(frame: &Frame<'_>, priority: u8) -> Self {
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
}

/// A message did not reach (at least) one of its target devices. The drop is counted in
/// that device's statistics (or, for [`DropReason::NoDevice`], in the downlink's
/// [`undeliverable`](crate::Downlink::undeliverable) counter).
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
