//! Several aircraft: routing by destination, and relaying other aircraft's frames.
//!
//! PPRZ v2 frames carry a source and a destination ([`GROUND_ID`](pprz_transports::GROUND_ID) 0, an aircraft id, or
//! [`BROADCAST_ID`] 0xFF). An aircraft that one aircraft of the fleet cannot reach
//! directly (out of radio range of the ground, in a street canyon) is reached *through*
//! another one: aircraft 7 has a radio to the ground and a second radio to aircraft 8, and
//! relays between them.
//!
//! ```text
//!  ground ◄──radio──► 7 ◄──radio 7-8──► 8
//!                     │
//!   routes of 7: 8 -> radio 7-8, default (the ground) -> radio
//!   routes of 8: default -> radio 7-8
//! ```
//!
//! # Routes
//! [`Routes`](crate::Routes) is a static table given to the [`Downlink`](crate::Downlink)
//! at start-up ([`with_routes`](crate::Downlink::with_routes)): destination id -> devices,
//! a default route (normally to the ground) and the devices a broadcast goes out on. The
//! application's messages follow it too: [`Downlink::send`](crate::Downlink::send) sends
//! to the ground's route, a send [`to`](crate::SendOptions::to) another aircraft to that
//! aircraft's. Without a table, every device leads everywhere (one radio, or a radio and
//! an SD-card log).
//!
//! # Relaying
//! A [`Relay`] is an [`Inbox`] in front of the aircraft's
//! [`Datalink`](crate::reader::Datalink): the readers of every device deliver to it, it
//! hands the datalink what is for us and forwards the PPRZ v2 frames that are not onto
//! the devices of their destination's route, **without decoding their fields**: the frame's header (source,
//! destination, class, component, id) and fields are copied into the shared frame arena
//! and re-framed for each outgoing device's transport (for PPRZ v2 in and out, the bytes
//! sent are the bytes received). Forwarded frames go through the same priority queues as
//! the relay's own messages, so the relay's acknowledgements and status keep their
//! precedence when the relay is saturated: a forwarded frame has the priority its message
//! has in the relay's message table ([`Relay::with_messages`]), or the relay's configured
//! priority for a message it does not know. Broadcast frames are delivered to us and
//! forwarded on the broadcast route. (A firmware that does not relay does not use the
//! type, and carries none of its code.) What each device carried for others is in its
//! [`DeviceStats::relayed`](crate::DeviceStats::relayed) (submitted, sent, dropped by
//! reason, shed per priority level); what the relay refused, in [`RelayStats`].
//!
//! # No loops, no duplicates
//! PPRZ frames have no hop count and no sequence number, so a frame cannot tell how far
//! it went or whether it was seen before (a content filter would also drop legitimate
//! repeats: two PINGs are the same bytes). The relay instead applies three rules that need
//! no memory and no clock:
//!
//! 1. **Never back where it came from**: a frame is not forwarded on the device it
//!    arrived on (a radio shared by the whole fleet hears each frame once, and nobody
//!    repeats it).
//! 2. **Reverse path**: a frame for another aircraft or for broadcast is accepted only
//!    from a device of our route *back to its source*. A copy that went round a loop
//!    (or any second copy of a broadcast, over another path) arrives from elsewhere and
//!    is dropped ([`RelayStats::reverse_path`]). For a frame to circulate, every relay
//!    on the loop would need its route to the source to point backwards along the loop:
//!    the routes to that source would themselves be a loop. With routes that reach
//!    their destinations, every frame is delivered at most once and stops.
//! 3. **Not from us, not from everyone**: a frame claiming our own id as its source is
//!    either ours come back or forged, and is dropped ([`RelayStats::own_source`]). So is
//!    a frame claiming the broadcast id 0xFF as its source: no aircraft sends as 0xFF,
//!    and the route back to 0xFF is the broadcast route, so rule 2 would let such a frame
//!    in from every device and it would circulate on any loop of links
//!    ([`RelayStats::broadcast_source`]; it is not delivered to us either).
//!
//! Routes must therefore be symmetric: the device that leads to an aircraft is the
//! device its frames come from. A frame that breaks a rule is counted, never forwarded.
//!
//! # Hostile frames
//! A frame whose fields do not match its message's definition in the relay's table
//! (wrong length, a variable array longer than the frame) is not forwarded
//! ([`RelayStats::malformed`]); a destination whose route leads nowhere but back is
//! counted in [`RelayStats::no_route`].
//!
//! PPRZ v1 frames carry no destination: they are always for us and never forwarded.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_telemetry::reader::{Datalink, Reader};
//! use pprz_telemetry::{Relay, Routes};
//! use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, Targets};
//! use pprz_telemetry::pprz_transports::{AnyTransport, PprzV2};
//! use pprz_default::messages::MESSAGES; // any generated message set
//!
//! // Aircraft 7: device 0 is the radio to the ground, device 1 the radio to aircraft 8.
//! static ROUTES: [(u8, Targets); 1] = [(8, Targets::only(1))];
//! static ARENA: FrameArena<M, 4096> = FrameArena::new();
//! static DOWNLINK: Downlink<'static, M, 2, 32> = Downlink::new(&ARENA, 7, [
//!     DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),
//!     DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),
//! ])
//! .with_routes(Routes::new(&ROUTES, Targets::only(0)));
//! static DATALINK: Datalink<'static, M, 8> = Datalink::new(7);
//! // Frames for others go with their own priority, unknown messages with 10.
//! static RELAY: Relay<'static, M, Datalink<'static, M, 8>> =
//!     Relay::new(&DATALINK, 10).with_messages(&MESSAGES);
//!
//! let [radio, to_8] = DOWNLINK.ports().unwrap();
//! let mut from_ground = Reader::<_, _>::new(&[][..], PprzV2::new(), radio.device());
//! // A PING from the ground (0) to aircraft 8 comes in on the radio...
//! from_ground.feed(&[0x99, 0x08, 0x00, 0x08, 0x02, 0x08, 0x1A, 0x4C], &RELAY);
//! // ... and waits for the radio to aircraft 8, unchanged.
//! assert_eq!(to_8.device().stats().relayed.submitted, 1);
//! assert_eq!(RELAY.stats().forwarded, 1);
//! // Readers of both devices deliver to `RELAY`: `reader.run(&RELAY).await`.
//! ```

use core::cell::Cell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use pprz_messages::MessageSet;
use pprz_messages::dynamic;
use pprz_transports::{BROADCAST_ID, Frame};

use crate::downlink::Device;
use crate::reader::Inbox;
use crate::registry::Received;
use crate::route::Targets;

/// The relay of an aircraft: an [`Inbox`] in front of its datalink (or any inbox) that
/// forwards frames for other aircraft and broadcast frames over the downlink's
/// [`Routes`](crate::Routes), and hands the datalink what is for us; see the
/// [module documentation](self). Readers of every device deliver to it.
///
/// `M` guards its counters (the mutex of the datalink).
pub struct Relay<'r, M: RawMutex, I: ?Sized> {
    inner: &'r I,
    priority: u8,
    messages: Option<&'r MessageSet<'r>>,
    stats: Mutex<M, Cell<RelayStats>>,
}

impl<'r, M: RawMutex, I: ?Sized> Relay<'r, M, I> {
    /// A relay delivering our frames to `inner` and forwarding the others with
    /// `priority` (the priority of messages the relay does not know; see
    /// [`with_messages`](Self::with_messages)). `const`, so it can be a `static`.
    pub const fn new(inner: &'r I, priority: u8) -> Self {
        Self {
            inner,
            priority,
            messages: None,
            stats: Mutex::new(Cell::new(RelayStats::ZERO)),
        }
    }

    /// With the relay's message table: a forwarded message it defines goes with its own
    /// priority, and only if its fields match the definition.
    pub const fn with_messages(mut self, messages: &'r MessageSet<'r>) -> Self {
        self.messages = Some(messages);
        self
    }

    /// The priority of frames whose message the relay does not know.
    pub fn priority(&self) -> u8 {
        self.priority
    }

    /// A snapshot of the counters.
    pub fn stats(&self) -> RelayStats {
        self.stats.lock(Cell::get)
    }

    fn count(&self, f: impl FnOnce(&mut RelayStats)) {
        self.stats.lock(|s| {
            let mut v = s.get();
            f(&mut v);
            s.set(v);
        });
    }
}

impl<'d, M: RawMutex, I: Inbox<'d> + ?Sized> Inbox<'d> for Relay<'_, M, I> {
    fn deliver(&self, rx: &Received<'_, 'd>) {
        let frame = &rx.frame;
        // PPRZ v1 frames name no destination: always ours.
        let Some(destination) = frame.destination() else {
            return self.inner.deliver(rx);
        };
        let ac_id = rx.device.sender().ac_id();
        if frame.source() == ac_id {
            self.count(|s| s.own_source = s.own_source.wrapping_add(1));
            return;
        }
        if frame.source() == BROADCAST_ID {
            self.count(|s| s.broadcast_source = s.broadcast_source.wrapping_add(1));
            return;
        }
        if destination == ac_id {
            return self.inner.deliver(rx);
        }
        let broadcast = destination == BROADCAST_ID;
        let routed = self.route(frame, destination, rx.device);
        self.count(|s| s.count(routed, broadcast));
        if broadcast && routed != Routed::ReversePath {
            self.inner.deliver(rx);
        }
    }

    fn read_error(&self) {
        self.inner.read_error();
    }
}

/// What the relay did with the frames not (only) for us; the outcome on each device
/// is in that device's [`DeviceStats::relayed`](crate::DeviceStats::relayed).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RelayStats {
    /// Frames handed to the devices of their route (each device's outcome is in its
    /// `relayed` statistics).
    pub forwarded: u32,
    /// Broadcast frames delivered to us (and forwarded, when the broadcast route has
    /// another device).
    pub broadcast: u32,
    /// Frames whose destination's route leads to no device but the one they came from.
    pub no_route: u32,
    /// Frames that arrived on a device that is not on our route back to their source: a
    /// copy that went round a loop, or a second copy of a broadcast.
    pub reverse_path: u32,
    /// Frames claiming our own id as their source.
    pub own_source: u32,
    /// Frames claiming the broadcast id as their source (not delivered to us either).
    pub broadcast_source: u32,
    /// Frames whose fields do not match their message's definition.
    pub malformed: u32,
}

impl RelayStats {
    /// Zero counters, in `const` contexts.
    pub const ZERO: Self = Self {
        forwarded: 0,
        broadcast: 0,
        no_route: 0,
        reverse_path: 0,
        own_source: 0,
        broadcast_source: 0,
        malformed: 0,
    };

    /// Frames the relay refused (every reason but forwarding).
    pub fn refused(&self) -> u32 {
        self.no_route
            .wrapping_add(self.reverse_path)
            .wrapping_add(self.own_source)
            .wrapping_add(self.broadcast_source)
            .wrapping_add(self.malformed)
    }
}

/// What the relay did with one frame (one counter of [`RelayStats`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Routed {
    /// Handed to the devices of its route.
    Forwarded,
    /// A broadcast frame with no other device to go to: delivered only.
    BroadcastOnly,
    /// Its route leads nowhere but back.
    NoRoute,
    /// Not from our route back to its source.
    ReversePath,
    /// Fields that do not match the message's definition.
    Malformed,
}

impl RelayStats {
    /// Counts one outcome; `broadcast` also counts a broadcast frame delivered to us.
    fn count(&mut self, routed: Routed, broadcast: bool) {
        let c = match routed {
            Routed::Forwarded => &mut self.forwarded,
            Routed::BroadcastOnly => &mut self.broadcast,
            Routed::NoRoute => &mut self.no_route,
            Routed::ReversePath => &mut self.reverse_path,
            Routed::Malformed => &mut self.malformed,
        };
        *c = c.wrapping_add(1);
        if broadcast && matches!(routed, Routed::Forwarded | Routed::Malformed) {
            self.broadcast = self.broadcast.wrapping_add(1);
        }
    }
}

impl<M: RawMutex, I: ?Sized> Relay<'_, M, I> {
    /// Routes `frame`, from another aircraft (or the ground), addressed to another
    /// aircraft or to broadcast (`destination`), which arrived on `device`: forwards it
    /// on the devices of its destination's route but `device`, unless a rule of the
    /// [module documentation](self) refuses it. A broadcast frame is to be delivered to us
    /// too unless it failed the reverse-path rule (then it is a second copy).
    fn route(&self, frame: &Frame<'_>, destination: u8, device: Device<'_>) -> Routed {
        let sender = device.sender();
        let routes = sender.routes();
        let incoming = device.index();
        if !routes.to(frame.source()).contains(incoming) {
            return Routed::ReversePath;
        }
        let definition = self
            .messages
            .and_then(|set| set.find(frame.class(), frame.msg_id()));
        let priority = match definition {
            Some(message) => {
                if dynamic::check(message, frame.payload()).is_err() {
                    return Routed::Malformed;
                }
                message.priority
            }
            None => self.priority,
        };
        // Every device of the route but the one the frame came in on (device indices
        // are below 32: `Targets` has one bit per device).
        let others = routes.to(destination).bits() & !(1u32 << (incoming & 31));
        let devices = match sender.devices() {
            n if n >= 32 => u32::MAX,
            n => (1u32 << n) - 1,
        };
        if others & devices == 0 {
            return if destination == BROADCAST_ID {
                Routed::BroadcastOnly
            } else {
                Routed::NoRoute
            };
        }
        // Each device counts what becomes of its copy (`DeviceStats::relayed`).
        let _ = sender.forward(frame, Targets::from_bits(others), priority);
        Routed::Forwarded
    }
}
