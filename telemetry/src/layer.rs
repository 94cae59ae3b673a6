//! Link layers: a step between the queue and the wire on the way down, and between the
//! decoder and the subscribers on the way up, for a device whose frames are transformed
//! on the link (the secure link of `pprz-secure` encrypts and authenticates them).
//!
//! ```text
//!  queue ──► writer: layer.seal(frame) ──► device        (counter and encryption at wire time)
//!  device ──► reader: decoder ──► layer.open(frame) ──► destination filter, services, subscribers
//! ```
//!
//! A layer is shared by the device's writer and reader (`&self`, so it keeps its state
//! behind a lock of its own). The writer calls [`LinkLayer::seal`] when it takes a frame
//! for the wire, not when the frame is queued: frames leave the queue in priority order,
//! so whatever the layer numbers (a frame counter) follows the order on the wire. A
//! layer that lengthens frames needs room after each one: give the device
//! [`DeviceConfig::reserve`](crate::DeviceConfig::reserve) spare bytes, allocated with
//! every frame (a message that cannot fit with them is refused at `send`).
//!
//! Every frame stays accounted for: a frame the layer refuses is counted as a
//! [`DropReason::Refused`](crate::DropReason::Refused) drop of the device; a received
//! frame the layer rejects or consumes is counted by the layer.
//!
//! Without a layer, the writer uses [`Plain`], which changes nothing and costs nothing,
//! and the reader delivers straight to its inbox. A reader delivers through a layer with
//! [`Layered`](crate::reader::Layered).

use pprz_transports::{Frame, MAX_FRAME_LEN};

/// Why a [`LinkLayer`] did not let a frame go to the wire (the layer counts its reasons).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Refused;

impl core::fmt::Display for Refused {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("frame refused by the link layer")
    }
}

impl core::error::Error for Refused {}

/// A transformation of one device's frames on the link; see the
/// [module documentation](self).
pub trait LinkLayer: Sync {
    /// Rewrites the frame `buf[..len]` in place for the wire, using at most `buf.len()`
    /// bytes (the frame's whole arena block), and returns the length to write.
    ///
    /// # Errors
    /// [`Refused`]: the frame must not be sent (the writer counts it as
    /// [`DropReason::Refused`](crate::DropReason::Refused)).
    fn seal(&self, buf: &mut [u8], len: usize) -> Result<usize, Refused>;

    /// Opens a received frame: what to deliver to the subscribers, if anything (a frame
    /// rejected, or consumed by the layer itself such as a key exchange, is counted by
    /// the layer).
    fn open(&self, frame: &Frame<'_>, out: &mut [u8; MAX_FRAME_LEN]) -> Opened;

    /// Whether this layer authenticates what it opens. If it does, the frames it
    /// delivers without [`Opened::Authenticated`] are marked
    /// [`Trust::Unauthenticated`](crate::registry::Trust::Unauthenticated) (they do not
    /// count as hearing the ground, for one). `false` unless the layer says otherwise.
    fn authenticates(&self) -> bool {
        false
    }
}

/// What [`LinkLayer::open`] made of a received frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Opened {
    /// Deliver the frame as it was received.
    Unchanged,
    /// Deliver the PPRZ v2 frame (`STX LEN src dst comp|class id fields CK_A CK_B`) the
    /// layer wrote at the start of `out`, of this length.
    Rewritten(usize),
    /// Deliver the PPRZ v2 frame the layer wrote at the start of `out`, of this length,
    /// which the layer authenticated (it was sealed by the peer, and is not a replay).
    Authenticated(usize),
    /// Deliver nothing.
    Withheld,
}

/// No layer: frames go to the wire as queued and are delivered as decoded.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Plain;

impl LinkLayer for Plain {
    #[inline]
    fn seal(&self, _buf: &mut [u8], len: usize) -> Result<usize, Refused> {
        Ok(len)
    }

    #[inline]
    fn open(&self, _frame: &Frame<'_>, _out: &mut [u8; MAX_FRAME_LEN]) -> Opened {
        Opened::Unchanged
    }
}

impl<L: LinkLayer + ?Sized> LinkLayer for &L {
    #[inline]
    fn seal(&self, buf: &mut [u8], len: usize) -> Result<usize, Refused> {
        (**self).seal(buf, len)
    }

    #[inline]
    fn open(&self, frame: &Frame<'_>, out: &mut [u8; MAX_FRAME_LEN]) -> Opened {
        (**self).open(frame, out)
    }

    #[inline]
    fn authenticates(&self) -> bool {
        (**self).authenticates()
    }
}
