//! Types and traits shared by every transport.
//!
//! * [`MsgHeader`]: the routing/identification header of a message (the PPRZ v2
//!   4-byte header in logical form) and [`TxMeta`], what a send needs besides the
//!   message fields.
//! * [`Encoder`]: the TX side. The runtime asks [`Encoder::header_len`] and
//!   [`Encoder::tail_len`], writes the message fields at
//!   `frame[header_len..header_len + n]` (see [`Encoder::payload_area`]), then calls
//!   [`Encoder::finish_frame`], which writes the header and the tail around them
//!   in place. No copy of the fields is made.
//! * [`Framing`]: the RX syntax of a transport (start byte, frame length from the
//!   first bytes, integrity check, borrowed view). The incremental
//!   [`Decoder`](crate::Decoder) drives it.
//! * [`Frame`]: a received, checksum-verified frame borrowed from a buffer.
//! * [`Control`]: a received, checksum-verified frame that carries no message but a
//!   report of the radio module itself (today: an XBee [`TxStatus`]). The
//!   [`Decoder`](crate::Decoder) keeps transmit statuses aside
//!   ([`Decoder::take_tx_status`](crate::Decoder::take_tx_status)) and never hands them
//!   out as message frames.

use core::fmt;

/// Id of the ground station.
pub const GROUND_ID: u8 = 0;
/// Broadcast destination id.
pub const BROADCAST_ID: u8 = 0xFF;
/// Component 0: broadcast to every component of the destination.
pub const COMPONENT_BROADCAST: u8 = 0;

/// The header of a message: who sends it, to whom, and which message it is.
///
/// PPRZ v2, XBee and PPRZLOG carry all of it as 4 bytes:
///
/// ```text
/// +--------+-------------+---------------------------+--------+
/// | source | destination | component << 4 | class    | msg_id |
/// +--------+-------------+---------------------------+--------+
///     0          1                    2                  3
/// ```
///
/// PPRZ v1 carries only `source` (the sender id) and `msg_id`; the class is implied
/// by the direction of the link and there is no destination or component.
///
/// `class` and `component` are 4-bit values: encoding a header where either is
/// above 15 fails with [`EncodeError::InvalidHeader`] instead of silently
/// truncating them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MsgHeader {
    /// Sender id (aircraft id, or [`GROUND_ID`]).
    pub source: u8,
    /// Receiver id ([`GROUND_ID`], an aircraft id, or [`BROADCAST_ID`]).
    pub destination: u8,
    /// Message class (telemetry 1, datalink 2, ...), 0..=15.
    pub class: u8,
    /// Component of the destination, 0..=15 ([`COMPONENT_BROADCAST`] = all).
    pub component: u8,
    /// Message id within its class.
    pub msg_id: u8,
}

/// Offsets of the PPRZ v2 message header (relative to the start of `DATA`).
pub mod field {
    /// A byte range inside a buffer.
    pub type Field = core::ops::Range<usize>;

    /// Sender id.
    pub const SOURCE: usize = 0;
    /// Receiver id.
    pub const DESTINATION: usize = 1;
    /// `component << 4 | class`.
    pub const COMPONENT_CLASS: usize = 2;
    /// Message id.
    pub const MSG_ID: usize = 3;
    /// First byte of the message fields.
    pub const PAYLOAD: usize = MSG_ID + 1;
}

impl MsgHeader {
    /// Length of the header on the wire in PPRZ v2, XBee and PPRZLOG.
    pub const V2_LEN: usize = field::PAYLOAD;
    /// Length of the header on the wire in PPRZ v1 (sender, msg_id).
    pub const V1_LEN: usize = 2;

    /// A header with component 0 (broadcast to every component).
    pub const fn new(source: u8, destination: u8, class: u8, msg_id: u8) -> Self {
        Self {
            source,
            destination,
            class,
            component: COMPONENT_BROADCAST,
            msg_id,
        }
    }

    /// The same header with another component.
    pub const fn with_component(self, component: u8) -> Self {
        Self { component, ..self }
    }

    /// Checks that `class` and `component` fit their 4 bits.
    pub const fn check(&self) -> Result<(), EncodeError> {
        if self.class > 0x0F || self.component > 0x0F {
            Err(EncodeError::InvalidHeader)
        } else {
            Ok(())
        }
    }

    /// Writes the 4-byte v2 header to the start of `buf`.
    pub fn emit_v2(&self, buf: &mut [u8]) -> Result<(), EncodeError> {
        self.check()?;
        let available = buf.len();
        let out = buf
            .get_mut(..Self::V2_LEN)
            .ok_or(EncodeError::BufferTooSmall {
                needed: Self::V2_LEN,
                available,
            })?;
        out[field::SOURCE] = self.source;
        out[field::DESTINATION] = self.destination;
        out[field::COMPONENT_CLASS] = (self.component << 4) | self.class;
        out[field::MSG_ID] = self.msg_id;
        Ok(())
    }

    /// Reads a v2 header from the start of `data`; returns it with the fields after it.
    ///
    /// Returns `None` when `data` is shorter than [`MsgHeader::V2_LEN`].
    #[inline]
    pub fn parse_v2(data: &[u8]) -> Option<(Self, &[u8])> {
        match data {
            [source, destination, cc, msg_id, payload @ ..] => Some((
                Self {
                    source: *source,
                    destination: *destination,
                    class: cc & 0x0F,
                    component: cc >> 4,
                    msg_id: *msg_id,
                },
                payload,
            )),
            _ => None,
        }
    }
}

/// Everything a send needs besides the message fields.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TxMeta {
    /// The message header.
    pub header: MsgHeader,
    /// Time stamp in 100 µs ticks. Only PPRZLOG writes it; the others ignore it.
    pub timestamp: u32,
}

impl TxMeta {
    /// Metadata with a zero time stamp.
    pub const fn new(header: MsgHeader) -> Self {
        Self {
            header,
            timestamp: 0,
        }
    }

    /// The same metadata with a time stamp (100 µs ticks).
    pub const fn at(self, timestamp: u32) -> Self {
        Self { timestamp, ..self }
    }
}

impl From<MsgHeader> for TxMeta {
    fn from(header: MsgHeader) -> Self {
        Self::new(header)
    }
}

/// Why a frame could not be encoded. Nothing is ever truncated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum EncodeError {
    /// The message fields do not fit this transport.
    PayloadTooLong {
        /// Length of the message fields.
        len: usize,
        /// Most field bytes this transport carries.
        max: usize,
    },
    /// The output buffer cannot hold the frame.
    BufferTooSmall {
        /// Frame length.
        needed: usize,
        /// Length of the buffer given.
        available: usize,
    },
    /// `class` or `component` does not fit its 4 bits.
    InvalidHeader,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::PayloadTooLong { len, max } => write!(
                f,
                "message fields too long for the transport: {len} bytes, at most {max}"
            ),
            Self::BufferTooSmall { needed, available } => write!(
                f,
                "frame buffer too small: {needed} bytes needed, {available} available"
            ),
            Self::InvalidHeader => f.write_str("class or component above 15"),
        }
    }
}

impl core::error::Error for EncodeError {}

/// Why bytes were not accepted as a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum RxError {
    /// The first byte is not the transport's start byte.
    BadStart,
    /// Fewer bytes than the frame needs.
    Truncated,
    /// The length field is impossible for this transport, or the frame is too short
    /// for its headers.
    BadLength,
    /// The frame is longer than the decoder's buffer.
    TooLong,
    /// The checksum does not match.
    Checksum,
    /// XBee: a well-formed API frame of a type this transport does not carry.
    UnknownApiId(u8),
}

impl fmt::Display for RxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadStart => f.write_str("not a start byte"),
            Self::Truncated => f.write_str("truncated frame"),
            Self::BadLength => f.write_str("impossible frame length"),
            Self::TooLong => f.write_str("frame longer than the receive buffer"),
            Self::Checksum => f.write_str("checksum mismatch"),
            Self::UnknownApiId(id) => write!(f, "unknown XBee API id 0x{id:02X}"),
        }
    }
}

impl core::error::Error for RxError {}

/// XBee details of a received frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct XBeeInfo {
    /// API id of the frame (`0x81`/`0x01` for 802.15.4, `0x90`/`0x10` for 868).
    pub api_id: u8,
    /// The sender's address for receive frames (`0x81`: 16-bit, `0x90`: 64-bit); the
    /// destination address for transmit frames seen on a cable loopback (`0x01`, `0x10`).
    pub address: u64,
    /// `0x81` only: received signal strength, `n` meaning `-n` dBm.
    pub rssi: Option<u8>,
    /// The options byte of the API frame.
    pub options: u8,
}

/// The outcome of one transmission, as the radio module reports it: an XBee transmit
/// status (API id [`0x89`](crate::xbee::API_TX_STATUS) on 802.15.4,
/// [`0x8B`](crate::xbee::API_TX_STATUS_868) on 868 and the other ZigBee-style modules).
///
/// A module answers every transmit request whose frame id is not
/// [`NO_FRAME_ID`](crate::xbee::NO_FRAME_ID) with exactly one status, once the
/// transmission is over (delivered, or given up). A broadcast is never acknowledged:
/// its status always reads delivered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TxStatus {
    /// Frame id of the transmit request this status answers (1..=255 for a request of
    /// ours; 0 answers none).
    pub frame_id: u8,
    /// Whether the frame was delivered: `status` is
    /// [`status::SUCCESS`](crate::xbee::status::SUCCESS).
    pub delivered: bool,
    /// The raw (delivery) status byte, see [`xbee::status`](crate::xbee::status).
    pub status: u8,
    /// Transmission retries the module made (0x8B); always 0 for 802.15.4 (0x89),
    /// which does not report them.
    pub retries: u8,
}

/// A received, checksum-verified frame that carries no message: a report of the radio
/// module itself. Only XBee transports have any ([`Framing::control`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Control {
    /// XBee transmit status (API id 0x89 or 0x8B).
    TxStatus(TxStatus),
}

/// PPRZLOG details of a logged frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LogInfo {
    /// 0 = telemetry (downlink), 1 = datalink (uplink).
    pub source: u8,
    /// Time stamp in 100 µs ticks.
    pub timestamp: u32,
}

/// Transport-specific details of a received frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Extra {
    /// PPRZ v1/v2: nothing more.
    None,
    /// XBee API frame details.
    XBee(XBeeInfo),
    /// PPRZLOG record details.
    Log(LogInfo),
}

/// A complete, checksum-verified frame, borrowed from the buffer it was found in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame<'a> {
    source: u8,
    destination: Option<u8>,
    class: u8,
    component: u8,
    msg_id: u8,
    payload: &'a [u8],
    data: &'a [u8],
    raw: &'a [u8],
    extra: Extra,
}

impl<'a> Frame<'a> {
    /// Builds a view from a v2 message (`data` = 4-byte header + fields).
    #[inline]
    pub(crate) fn from_v2(raw: &'a [u8], data: &'a [u8], extra: Extra) -> Result<Self, RxError> {
        let (h, payload) = MsgHeader::parse_v2(data).ok_or(RxError::BadLength)?;
        Ok(Self {
            source: h.source,
            destination: Some(h.destination),
            class: h.class,
            component: h.component,
            msg_id: h.msg_id,
            payload,
            data,
            raw,
            extra,
        })
    }

    /// Builds a view from a v1 message (`data` = sender, msg_id, fields).
    pub(crate) fn from_v1(raw: &'a [u8], data: &'a [u8], class: u8) -> Result<Self, RxError> {
        match data {
            [sender, msg_id, payload @ ..] => Ok(Self {
                source: *sender,
                destination: None,
                class,
                component: COMPONENT_BROADCAST,
                msg_id: *msg_id,
                payload,
                data,
                raw,
                extra: Extra::None,
            }),
            _ => Err(RxError::BadLength),
        }
    }

    /// Sender id (v1: `sender_id`).
    pub const fn source(&self) -> u8 {
        self.source
    }

    /// Receiver id; `None` for PPRZ v1, which does not carry one.
    pub const fn destination(&self) -> Option<u8> {
        self.destination
    }

    /// Message class (for PPRZ v1, the class the decoder was configured with).
    pub const fn class(&self) -> u8 {
        self.class
    }

    /// Component (0 for PPRZ v1).
    pub const fn component(&self) -> u8 {
        self.component
    }

    /// Message id.
    pub const fn msg_id(&self) -> u8 {
        self.msg_id
    }

    /// The message fields (what a generated message decodes from).
    pub const fn payload(&self) -> &'a [u8] {
        self.payload
    }

    /// The message header and fields as they are on the wire.
    pub const fn data(&self) -> &'a [u8] {
        self.data
    }

    /// The whole frame as received, start byte to checksum.
    pub const fn raw(&self) -> &'a [u8] {
        self.raw
    }

    /// Transport-specific details.
    pub const fn extra(&self) -> Extra {
        self.extra
    }

    /// XBee 802.15.4 receive frames: received signal strength (`n` = `-n` dBm).
    pub const fn rssi(&self) -> Option<u8> {
        match self.extra {
            Extra::XBee(x) => x.rssi,
            _ => None,
        }
    }

    /// PPRZLOG: time stamp in 100 µs ticks.
    pub const fn timestamp(&self) -> Option<u32> {
        match self.extra {
            Extra::Log(l) => Some(l.timestamp),
            _ => None,
        }
    }

    /// The header in logical form; a missing destination (PPRZ v1) reads as
    /// [`BROADCAST_ID`].
    pub const fn header(&self) -> MsgHeader {
        MsgHeader {
            source: self.source,
            destination: match self.destination {
                Some(d) => d,
                None => BROADCAST_ID,
            },
            class: self.class,
            component: self.component,
            msg_id: self.msg_id,
        }
    }

    /// The metadata to re-send this message (keeps a PPRZLOG time stamp).
    pub const fn tx_meta(&self) -> TxMeta {
        TxMeta {
            header: self.header(),
            timestamp: match self.extra {
                Extra::Log(l) => l.timestamp,
                _ => 0,
            },
        }
    }
}

/// TX side of a transport: writes the frame around message fields already in place.
///
/// Frame layout, for every transport:
///
/// ```text
/// | header_len() bytes | payload_len bytes (message fields) | tail_len() bytes |
/// ```
///
/// In-place use (no copy of the fields):
///
/// ```
/// use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};
/// let t = PprzV2::new();
/// let mut frame = [0u8; pprz_transports::MAX_FRAME_LEN];
/// // The message encoder writes its fields into the payload area...
/// let area = t.payload_area(&mut frame);
/// area[..4].copy_from_slice(&[3, 0, 1, 2]);
/// // ...then the transport writes header and tail around them.
/// let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2));
/// let len = t.finish_frame(&meta, &mut frame, 4).unwrap();
/// assert_eq!(&frame[..len], &[0x99, 0x0C, 7, 0, 1, 2, 3, 0, 1, 2, 0x1C, 0xC4]);
/// ```
pub trait Encoder {
    /// Bytes before the message fields (transport header and message header).
    fn header_len(&self) -> usize;

    /// Bytes after the message fields (checksum).
    fn tail_len(&self) -> usize;

    /// Most message-field bytes one frame carries.
    fn max_payload_len(&self) -> usize;

    /// Longest frame this encoder produces.
    fn max_frame_len(&self) -> usize {
        self.header_len() + self.max_payload_len() + self.tail_len()
    }

    /// Frame length for `payload_len` field bytes, or
    /// [`EncodeError::PayloadTooLong`].
    fn frame_len(&self, payload_len: usize) -> Result<usize, EncodeError> {
        let max = self.max_payload_len();
        if payload_len > max {
            Err(EncodeError::PayloadTooLong {
                len: payload_len,
                max,
            })
        } else {
            Ok(self.header_len() + payload_len + self.tail_len())
        }
    }

    /// Where the message fields go in `frame`: from `header_len()` up to the most
    /// the transport and the buffer allow (empty if the buffer is too small).
    fn payload_area<'b>(&self, frame: &'b mut [u8]) -> &'b mut [u8] {
        let start = self.header_len();
        let end = frame
            .len()
            .saturating_sub(self.tail_len())
            .min(start + self.max_payload_len());
        frame.get_mut(start..end).unwrap_or_default()
    }

    /// Writes the header and tail around `payload_len` field bytes already at
    /// `frame[header_len()..]`; returns the frame length (the frame is
    /// `frame[..len]`).
    fn finish_frame(
        &self,
        meta: &TxMeta,
        frame: &mut [u8],
        payload_len: usize,
    ) -> Result<usize, EncodeError>;

    /// Copies `payload` into `out` and frames it; returns the frame length.
    fn encode(&self, meta: &TxMeta, payload: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
        let len = self.frame_len(payload.len())?;
        let available = out.len();
        let frame = out.get_mut(..len).ok_or(EncodeError::BufferTooSmall {
            needed: len,
            available,
        })?;
        let start = self.header_len();
        frame
            .get_mut(start..start + payload.len())
            .ok_or(EncodeError::BufferTooSmall {
                needed: len,
                available,
            })?
            .copy_from_slice(payload);
        self.finish_frame(meta, frame, payload.len())
    }
}

/// RX syntax of a transport, driven by the incremental [`Decoder`](crate::Decoder).
///
/// A complete candidate (start byte, then as many bytes as
/// [`rx_frame_len`](Framing::rx_frame_len) announced) is first offered to
/// [`control`](Framing::control): a control frame ([`Control`], an XBee transmit
/// status) is accepted or rejected there. Any other candidate is a message frame,
/// accepted when [`check`](Framing::check) succeeds and handed out as a [`Frame`]
/// built by [`view`](Framing::view).
///
/// Every method is total: any input gives an answer, never a panic.
pub trait Framing {
    /// The byte every frame starts with.
    fn start_byte(&self) -> u8;

    /// Longest frame this transport can receive (a buffer this long never
    /// reports [`RxError::TooLong`]).
    fn max_rx_frame_len(&self) -> usize;

    /// Total frame length announced by the first bytes of `head` (which starts with
    /// the start byte): `Ok(None)` if more bytes are needed to know it,
    /// `Err(RxError::BadLength)` if the length field is impossible.
    fn rx_frame_len(&self, head: &[u8]) -> Result<Option<usize>, RxError>;

    /// Checks the integrity of exactly one message frame (`frame.len()` is the length
    /// [`rx_frame_len`](Framing::rx_frame_len) gave): start byte, checksum and, for
    /// XBee, the API id (a control frame's API id is not a message's:
    /// [`RxError::UnknownApiId`]). A message frame is accepted when both `verify` and
    /// [`view`](Framing::view) succeed (see [`check`](Framing::check)).
    fn verify(&self, frame: &[u8]) -> Result<(), RxError>;

    /// Builds the view of one frame without checking its checksum.
    fn view<'a>(&self, frame: &'a [u8]) -> Result<Frame<'a>, RxError>;

    /// Whether a frame is accepted: `Ok` exactly when both [`verify`](Framing::verify)
    /// and [`view`](Framing::view) succeed on `frame`, otherwise the error of the first
    /// that fails. The [`Decoder`](crate::Decoder) calls it on every complete candidate
    /// that is not a control frame ([`control`](Framing::control) gave `None`), then
    /// builds the view once, for the frame it hands out.
    ///
    /// The default runs both (and drops the view); a transport whose `view` can only fail
    /// on a few things `verify` does not check (a frame too short for its headers)
    /// overrides it to check those without building the view, as the PPRZ transports do.
    fn check(&self, frame: &[u8]) -> Result<(), RxError> {
        self.verify(frame)?;
        self.view(frame).map(|_| ())
    }

    /// Whether exactly one frame (as for [`verify`](Framing::verify)) is a control
    /// frame of this transport: `None` when it is not (it is then a message frame,
    /// for [`check`](Framing::check) and [`view`](Framing::view)); `Some(Ok(_))` for a
    /// valid control frame; `Some(Err(_))` for a frame whose API id is a control
    /// frame's but which is not a valid one (bad start byte, length or checksum).
    ///
    /// Checked in the same order as [`verify`](Framing::verify): start byte, length,
    /// checksum, then the layout the API id requires ([`RxError::BadLength`] when the
    /// length does not fit it).
    ///
    /// The default (PPRZ v1/v2, PPRZLOG: no control frames) is `None` for every frame.
    /// XBee: the transmit statuses, API ids 0x89 and 0x8B, both accepted by both XBee
    /// transports (an 802.15.4 XBee 3 answers a 0x10 request with 0x8B).
    fn control(&self, frame: &[u8]) -> Option<Result<Control, RxError>> {
        let _ = frame;
        None
    }

    /// Whether [`control`](Framing::control) can find a control frame at all: `false`
    /// by default (PPRZ v1/v2, PPRZLOG), `true` for the XBee transports. A
    /// [`Decoder`](crate::Decoder) of a transport without control frames has no transmit
    /// status to hand out, and the code that takes them compiles away.
    fn has_control(&self) -> bool {
        false
    }

    /// The valid control frame at the start of `buf` (bytes after it are ignored) and
    /// its length, or `None` if there is none there (no complete frame, or a message
    /// frame, or an invalid control frame). The counterpart of
    /// [`parse`](Framing::parse) for control frames.
    fn parse_control(&self, buf: &[u8]) -> Option<(Control, usize)> {
        if buf.first() != Some(&self.start_byte()) {
            return None;
        }
        let len = self.rx_frame_len(buf).ok()??;
        let frame = buf.get(..len)?;
        match self.control(frame)? {
            Ok(control) => Some((control, len)),
            Err(_) => None,
        }
    }

    /// Parses the message frame at the start of `buf` (bytes after it are ignored):
    /// verifies it and returns its view and length. Handy for datagrams and host tools.
    /// A control frame is not a message: [`RxError::UnknownApiId`] (see
    /// [`parse_control`](Framing::parse_control)).
    fn parse<'a>(&self, buf: &'a [u8]) -> Result<(Frame<'a>, usize), RxError> {
        if buf.first() != Some(&self.start_byte()) {
            return Err(if buf.is_empty() {
                RxError::Truncated
            } else {
                RxError::BadStart
            });
        }
        let len = self.rx_frame_len(buf)?.ok_or(RxError::Truncated)?;
        let frame = buf.get(..len).ok_or(RxError::Truncated)?;
        self.verify(frame)?;
        Ok((self.view(frame)?, len))
    }
}
