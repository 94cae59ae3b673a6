//! Run-time choice of transport without `dyn`.
//!
//! The runtime picks a transport per device (a radio with PPRZ v2, an SD log with
//! PPRZLOG...) at run time; [`AnyTransport`] is a small `Copy` enum that dispatches
//! to the concrete transports with a `match`, so it can be stored in a `static`
//! table and used both to encode ([`Encoder`]) and to decode
//! (`Decoder<AnyTransport>`).
//!
//! ```
//! use pprz_transports::{AnyTransport, Decoder, Encoder, MsgHeader, PprzLog, TxMeta, XBee24};
//! static LINKS: [AnyTransport; 2] = [
//!     AnyTransport::XBee24(XBee24::new()),
//!     AnyTransport::PprzLog(PprzLog::TELEMETRY),
//! ];
//! let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2)).at(1234);
//! let mut buf = [0u8; pprz_transports::MAX_FRAME_LEN];
//! for link in &LINKS {
//!     let n = link.encode(&meta, &[1, 2, 3], &mut buf).unwrap();
//!     let mut decoder: Decoder<AnyTransport> = Decoder::new(*link);
//!     let mut input = &buf[..n];
//!     let frame = decoder.feed(&mut input).unwrap();
//!     assert_eq!(frame.payload(), &[1, 2, 3]);
//! }
//! ```

#[cfg(feature = "v1")]
use crate::pprz::PprzV1;
use crate::pprz::PprzV2;
#[cfg(feature = "pprzlog")]
use crate::pprzlog::PprzLog;
use crate::transport::{Control, EncodeError, Encoder, Frame, Framing, RxError, TxMeta};
#[cfg(feature = "xbee")]
use crate::xbee::{XBee24, XBee868};

/// One of the transports of this crate, chosen at run time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum AnyTransport {
    /// PPRZ protocol v1 (feature `v1`).
    #[cfg(feature = "v1")]
    PprzV1(PprzV1),
    /// PPRZ protocol v2 (always there).
    PprzV2(PprzV2),
    /// XBee 802.15.4 API (feature `xbee`).
    #[cfg(feature = "xbee")]
    XBee24(XBee24),
    /// XBee 868 API (feature `xbee`).
    #[cfg(feature = "xbee")]
    XBee868(XBee868),
    /// PPRZLOG records (feature `pprzlog`).
    #[cfg(feature = "pprzlog")]
    PprzLog(PprzLog),
}

macro_rules! dispatch {
    ($self:ident, $t:ident => $e:expr) => {
        match $self {
            #[cfg(feature = "v1")]
            AnyTransport::PprzV1($t) => $e,
            AnyTransport::PprzV2($t) => $e,
            #[cfg(feature = "xbee")]
            AnyTransport::XBee24($t) => $e,
            #[cfg(feature = "xbee")]
            AnyTransport::XBee868($t) => $e,
            #[cfg(feature = "pprzlog")]
            AnyTransport::PprzLog($t) => $e,
        }
    };
}

macro_rules! impl_from {
    ($($feature:literal $t:ident),*) => {$(
        #[cfg(feature = $feature)]
        impl From<$t> for AnyTransport {
            fn from(t: $t) -> Self {
                Self::$t(t)
            }
        }
    )*};
}
impl_from!("v1" PprzV1, "xbee" XBee24, "xbee" XBee868, "pprzlog" PprzLog);

impl From<PprzV2> for AnyTransport {
    fn from(t: PprzV2) -> Self {
        Self::PprzV2(t)
    }
}

/// Frame ids and transmit statuses, for a writer that keeps at most a few frames
/// inside the radio module and waits for each one's status.
///
/// ```
/// use pprz_transports::{AnyTransport, Decoder, Encoder, MsgHeader, TxMeta, XBee24, xbee};
/// let t = AnyTransport::XBee24(XBee24::new());
/// assert!(t.has_tx_status());
/// let mut frame = [0u8; pprz_transports::MAX_FRAME_LEN];
/// let n = t.encode(&TxMeta::new(MsgHeader::new(7, 0, 1, 2)), &[1, 2], &mut frame).unwrap();
/// assert_eq!(t.frame_id(&frame[..n]), Some(xbee::NO_FRAME_ID));
/// // Just before writing it: a fresh frame id (checksum rewritten too).
/// assert!(t.set_frame_id(&mut frame[..n], 42));
/// assert_eq!(t.frame_id(&frame[..n]), Some(42));
/// // The module answers with a transmit status, which the decoder keeps aside.
/// let mut status = [0u8; 16];
/// let m = xbee::encode_tx_status_24(42, xbee::status::SUCCESS, &mut status).unwrap();
/// let mut decoder: Decoder<AnyTransport> = Decoder::new(t);
/// let mut input = &status[..m];
/// assert!(decoder.feed(&mut input).is_none());
/// let s = decoder.take_tx_status().unwrap();
/// assert_eq!((s.frame_id, s.delivered), (42, true));
/// ```
impl AnyTransport {
    /// Whether frames of this transport carry a frame id that the radio module answers
    /// with a transmit status ([`TxStatus`](crate::TxStatus)): the XBee transports.
    pub const fn has_tx_status(&self) -> bool {
        match self {
            #[cfg(feature = "xbee")]
            Self::XBee24(_) | Self::XBee868(_) => true,
            _ => false,
        }
    }

    /// The frame id of `frame`, a frame this transport encoded (bytes after it are
    /// allowed; the checksum is not verified): `None` for transports without frame ids
    /// (PPRZ, PPRZLOG) or when `frame` does not start with a whole transmit request of
    /// this transport.
    pub fn frame_id(&self, frame: &[u8]) -> Option<u8> {
        match self {
            #[cfg(feature = "xbee")]
            Self::XBee24(t) => t.tx_frame_id(frame),
            #[cfg(feature = "xbee")]
            Self::XBee868(t) => t.tx_frame_id(frame),
            _ => {
                let _ = frame;
                None
            }
        }
    }

    /// Rewrites the frame id of `frame`, a frame this transport encoded, to `id`, and
    /// its checksum, in place: `false` (and `frame` untouched) for transports without
    /// frame ids or when `frame` does not start with a whole transmit request of this
    /// transport. A writer gives each frame a fresh id in 1..=255 just before writing
    /// it (0, [`NO_FRAME_ID`](crate::xbee::NO_FRAME_ID), asks for no status).
    pub fn set_frame_id(&self, frame: &mut [u8], id: u8) -> bool {
        match self {
            #[cfg(feature = "xbee")]
            Self::XBee24(t) => t.set_tx_frame_id(frame, id),
            #[cfg(feature = "xbee")]
            Self::XBee868(t) => t.set_tx_frame_id(frame, id),
            _ => {
                let _ = (frame, id);
                false
            }
        }
    }
}

impl Encoder for AnyTransport {
    fn header_len(&self) -> usize {
        dispatch!(self, t => t.header_len())
    }

    fn tail_len(&self) -> usize {
        dispatch!(self, t => t.tail_len())
    }

    fn max_payload_len(&self) -> usize {
        dispatch!(self, t => t.max_payload_len())
    }

    // One dispatch each, rather than one per length the default methods read.
    fn frame_len(&self, payload_len: usize) -> Result<usize, EncodeError> {
        dispatch!(self, t => t.frame_len(payload_len))
    }

    fn payload_area<'b>(&self, frame: &'b mut [u8]) -> &'b mut [u8] {
        dispatch!(self, t => t.payload_area(frame))
    }

    // Not inlined: callers (the downlink's send path) would otherwise hoist the
    // constants of every transport's header out of their loops, whichever one is used.
    #[inline(never)]
    fn finish_frame(
        &self,
        meta: &TxMeta,
        frame: &mut [u8],
        payload_len: usize,
    ) -> Result<usize, EncodeError> {
        dispatch!(self, t => t.finish_frame(meta, frame, payload_len))
    }
}

impl Framing for AnyTransport {
    fn start_byte(&self) -> u8 {
        dispatch!(self, t => t.start_byte())
    }

    fn max_rx_frame_len(&self) -> usize {
        dispatch!(self, t => t.max_rx_frame_len())
    }

    fn rx_frame_len(&self, head: &[u8]) -> Result<Option<usize>, RxError> {
        dispatch!(self, t => t.rx_frame_len(head))
    }

    fn verify(&self, frame: &[u8]) -> Result<(), RxError> {
        dispatch!(self, t => t.verify(frame))
    }

    fn check(&self, frame: &[u8]) -> Result<(), RxError> {
        dispatch!(self, t => t.check(frame))
    }

    fn control(&self, frame: &[u8]) -> Option<Result<Control, RxError>> {
        dispatch!(self, t => t.control(frame))
    }

    fn has_control(&self) -> bool {
        self.has_tx_status()
    }

    fn view<'a>(&self, frame: &'a [u8]) -> Result<Frame<'a>, RxError> {
        dispatch!(self, t => t.view(frame))
    }
}
