//! PPRZ transport, protocol v1 and v2 (PPRZLINK).
//!
//! ```text
//!  0      1      2                      LEN-2  LEN-1
//! +------+------+----------------------+------+------+
//! | 0x99 | LEN  | DATA (LEN - 4 bytes) | CK_A | CK_B |
//! +------+------+----------------------+------+------+
//!
//! v2 DATA: | source | destination | component<<4 | class | msg_id | fields... |
//! v1 DATA: | sender | msg_id | fields... |
//! ```
//!
//! * `LEN` counts the whole frame (STX and checksum included): at most 255 bytes,
//!   so at most 247 field bytes in v2 and 249 in v1.
//! * Checksum: `ck_a = ck_b = 0`, then for each byte from `LEN` to the last `DATA`
//!   byte: `ck_a += b; ck_b += ck_a` (mod 256).
//! * Nothing on the wire tells v1 from v2: both ends agree in advance. A v1 receiver
//!   is configured with the class implied by the link direction
//!   ([`PprzV1::new`]).
//!
//! # No-panic contract
//!
//! [`Packet::new_unchecked`] accessors may panic on a short buffer; once
//! [`Packet::check_len`] (or [`Packet::new_checked`]) has succeeded, none of them can.

use crate::checksum;
use crate::transport::{EncodeError, Encoder, Extra, Frame, Framing, MsgHeader, RxError, TxMeta};

/// Start byte of every PPRZ frame.
pub const STX: u8 = 0x99;
/// Bytes of framing around `DATA`: STX, LEN, CK_A, CK_B.
pub const OVERHEAD: usize = 4;
/// Longest PPRZ frame (`LEN` is one byte).
pub const MAX_FRAME_LEN: usize = 255;
/// Most field bytes in a v2 frame.
pub const V2_MAX_PAYLOAD_LEN: usize = MAX_FRAME_LEN - OVERHEAD - MsgHeader::V2_LEN;
/// Most field bytes in a v1 frame.
pub const V1_MAX_PAYLOAD_LEN: usize = MAX_FRAME_LEN - OVERHEAD - MsgHeader::V1_LEN;

/// Byte offsets in a PPRZ frame.
pub mod field {
    use crate::transport::field::Field;

    /// Start byte, [`STX`](super::STX).
    pub const STX: usize = 0;
    /// Whole-frame length.
    pub const LEN: usize = 1;
    /// First `DATA` byte.
    pub const DATA_START: usize = 2;
    /// Transport header (STX, LEN).
    pub const HEADER: Field = STX..DATA_START;

    /// `DATA` of a frame of `frame_len` bytes.
    pub const fn data(frame_len: usize) -> Field {
        DATA_START..frame_len - 2
    }
    /// Bytes covered by the checksum in a frame of `frame_len` bytes.
    pub const fn checked(frame_len: usize) -> Field {
        LEN..frame_len - 2
    }
    /// Offset of `CK_A` in a frame of `frame_len` bytes.
    pub const fn ck_a(frame_len: usize) -> usize {
        frame_len - 2
    }
    /// Offset of `CK_B` in a frame of `frame_len` bytes.
    pub const fn ck_b(frame_len: usize) -> usize {
        frame_len - 1
    }
}

/// Length of the transport header (before `DATA`).
pub const HEADER_LEN: usize = field::DATA_START;
/// Length of the transport tail (after `DATA`).
pub const TAIL_LEN: usize = 2;

/// A zero-copy view of a PPRZ frame in a byte buffer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Packet<T> {
    /// Wraps a buffer without checking it.
    pub const fn new_unchecked(buffer: T) -> Packet<T> {
        Packet { buffer }
    }

    /// Wraps a buffer after [`check_len`](Packet::check_len).
    pub fn new_checked(buffer: T) -> Result<Packet<T>, RxError> {
        let packet = Self::new_unchecked(buffer);
        packet.check_len()?;
        Ok(packet)
    }

    /// Checks that the buffer holds the whole frame its `LEN` announces and that
    /// `LEN` is at least [`OVERHEAD`]. Bytes after the frame are allowed.
    pub fn check_len(&self) -> Result<(), RxError> {
        let buf = self.buffer.as_ref();
        let len = match buf.get(field::LEN) {
            Some(&len) => usize::from(len),
            None => return Err(RxError::Truncated),
        };
        if len < OVERHEAD {
            Err(RxError::BadLength)
        } else if buf.len() < len {
            Err(RxError::Truncated)
        } else {
            Ok(())
        }
    }

    /// Returns the buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    /// The start byte.
    pub fn stx(&self) -> u8 {
        self.buffer.as_ref()[field::STX]
    }

    /// The `LEN` field: whole-frame length.
    pub fn length(&self) -> u8 {
        self.buffer.as_ref()[field::LEN]
    }

    /// Whole-frame length as a `usize`.
    pub fn frame_len(&self) -> usize {
        usize::from(self.length())
    }

    /// The checksum bytes `(CK_A, CK_B)` as received.
    pub fn checksum(&self) -> (u8, u8) {
        let buf = self.buffer.as_ref();
        let len = self.frame_len();
        (buf[field::ck_a(len)], buf[field::ck_b(len)])
    }

    /// Whether the checksum bytes match the frame.
    pub fn verify_checksum(&self) -> bool {
        let buf = self.buffer.as_ref();
        checksum::pprz(&buf[field::checked(self.frame_len())]) == self.checksum()
    }
}

impl<'a, T: AsRef<[u8]> + ?Sized> Packet<&'a T> {
    /// `DATA`: the message header and fields.
    pub fn data(&self) -> &'a [u8] {
        &self.buffer.as_ref()[field::data(self.frame_len())]
    }

    /// The frame, without bytes after it.
    pub fn frame(&self) -> &'a [u8] {
        &self.buffer.as_ref()[..self.frame_len()]
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Packet<T> {
    /// Sets the start byte.
    pub fn set_stx(&mut self, value: u8) {
        self.buffer.as_mut()[field::STX] = value;
    }

    /// Sets the `LEN` field.
    pub fn set_length(&mut self, value: u8) {
        self.buffer.as_mut()[field::LEN] = value;
    }

    /// Mutable `DATA` (per the `LEN` field).
    pub fn data_mut(&mut self) -> &mut [u8] {
        let range = field::data(self.frame_len());
        &mut self.buffer.as_mut()[range]
    }

    /// Computes and writes `CK_A`, `CK_B` (per the `LEN` field).
    pub fn fill_checksum(&mut self) {
        let len = self.frame_len();
        let buf = self.buffer.as_mut();
        let (a, b) = checksum::pprz(&buf[field::checked(len)]);
        buf[field::ck_a(len)] = a;
        buf[field::ck_b(len)] = b;
    }
}

/// Writes the frame around the message fields already in place, in one pass: `head`
/// (STX, LEN and the message header) at the start of `frame[..len]`, the checksum in
/// its last two bytes. One bounds check for the whole frame; the checksum range comes
/// from `len`, not from re-reading `LEN` in the buffer.
#[inline]
fn finish<const K: usize>(
    frame: &mut [u8],
    len: usize,
    head: [u8; K],
) -> Result<usize, EncodeError> {
    let available = frame.len();
    let too_small = EncodeError::BufferTooSmall {
        needed: len,
        available,
    };
    let frame = frame.get_mut(..len).ok_or(too_small)?;
    let (body, ck) = frame.split_last_chunk_mut::<TAIL_LEN>().ok_or(too_small)?;
    *body.first_chunk_mut::<K>().ok_or(too_small)? = head;
    let (a, b) = checksum::pprz(body.get(field::LEN..).unwrap_or_default());
    *ck = [a, b];
    Ok(len)
}

/// The `LEN` byte of a frame of `len` bytes.
#[inline]
fn length_byte(len: usize) -> Result<u8, EncodeError> {
    u8::try_from(len).map_err(|_| EncodeError::PayloadTooLong {
        len,
        max: MAX_FRAME_LEN,
    })
}

/// Frame length announced by `head`, requiring room for `msg_header_len` bytes.
fn rx_len(head: &[u8], msg_header_len: usize) -> Result<Option<usize>, RxError> {
    match head.get(field::LEN) {
        None => Ok(None),
        Some(&len) if usize::from(len) < OVERHEAD + msg_header_len => Err(RxError::BadLength),
        Some(&len) => Ok(Some(usize::from(len))),
    }
}

/// The frame `LEN` announces at the start of `buf` and its `DATA`, with the errors of
/// [`Packet::new_checked`].
#[inline]
fn raw_and_data(buf: &[u8]) -> Result<(&[u8], &[u8]), RxError> {
    let len = usize::from(*buf.get(field::LEN).ok_or(RxError::Truncated)?);
    if len < OVERHEAD {
        return Err(RxError::BadLength);
    }
    let raw = buf.get(..len).ok_or(RxError::Truncated)?;
    let data = raw.get(field::data(len)).unwrap_or_default();
    Ok((raw, data))
}

/// Checks start byte, exact length and checksum of one frame.
#[inline]
fn verify(frame: &[u8]) -> Result<(), RxError> {
    let (raw, _) = raw_and_data(frame)?;
    if frame.first() != Some(&STX) {
        return Err(RxError::BadStart);
    }
    if raw.len() != frame.len() {
        return Err(RxError::BadLength);
    }
    match frame.split_last_chunk::<TAIL_LEN>() {
        Some((body, &[ck_a, ck_b]))
            if checksum::pprz(body.get(field::LEN..).unwrap_or_default()) == (ck_a, ck_b) =>
        {
            Ok(())
        }
        _ => Err(RxError::Checksum),
    }
}

/// [`verify`], and room for a message header of `msg_header_len` bytes: exactly when
/// both `verify` and the transport's `view` succeed.
#[inline]
fn check(frame: &[u8], msg_header_len: usize) -> Result<(), RxError> {
    verify(frame)?;
    if frame.len() < OVERHEAD + msg_header_len {
        Err(RxError::BadLength)
    } else {
        Ok(())
    }
}

/// PPRZ protocol v2: source, destination, component and class in every frame.
///
/// ```text
/// | 0x99 | LEN | source | destination | comp<<4|class | msg_id | fields | CK_A | CK_B |
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PprzV2;

impl PprzV2 {
    /// The PPRZ v2 transport.
    pub const fn new() -> Self {
        Self
    }
}

impl Encoder for PprzV2 {
    fn header_len(&self) -> usize {
        HEADER_LEN + MsgHeader::V2_LEN
    }

    fn tail_len(&self) -> usize {
        TAIL_LEN
    }

    fn max_payload_len(&self) -> usize {
        V2_MAX_PAYLOAD_LEN
    }

    #[inline]
    fn finish_frame(
        &self,
        meta: &TxMeta,
        frame: &mut [u8],
        payload_len: usize,
    ) -> Result<usize, EncodeError> {
        let len = self.frame_len(payload_len)?;
        let h = &meta.header;
        h.check()?;
        let head = [
            STX,
            length_byte(len)?,
            h.source,
            h.destination,
            (h.component << 4) | h.class,
            h.msg_id,
        ];
        finish(frame, len, head)
    }
}

impl Framing for PprzV2 {
    fn start_byte(&self) -> u8 {
        STX
    }

    fn max_rx_frame_len(&self) -> usize {
        MAX_FRAME_LEN
    }

    fn rx_frame_len(&self, head: &[u8]) -> Result<Option<usize>, RxError> {
        rx_len(head, MsgHeader::V2_LEN)
    }

    fn verify(&self, frame: &[u8]) -> Result<(), RxError> {
        verify(frame)
    }

    #[inline]
    fn check(&self, frame: &[u8]) -> Result<(), RxError> {
        check(frame, MsgHeader::V2_LEN)
    }

    #[inline]
    fn view<'a>(&self, frame: &'a [u8]) -> Result<Frame<'a>, RxError> {
        let (raw, data) = raw_and_data(frame)?;
        Frame::from_v2(raw, data, Extra::None)
    }
}

/// PPRZ protocol v1: sender and message id only; the class is implied by the link.
///
/// ```text
/// | 0x99 | LEN | sender | msg_id | fields | CK_A | CK_B |
/// ```
///
/// TX ignores the header's destination, class and component. RX reports
/// `destination() == None`, `component() == 0` and the configured class.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PprzV1 {
    /// Class reported for received frames (telemetry 1 on a ground tool, datalink 2
    /// on the aircraft).
    pub rx_class: u8,
}

impl PprzV1 {
    /// The PPRZ v1 transport; received frames are reported with class `rx_class`.
    pub const fn new(rx_class: u8) -> Self {
        Self { rx_class }
    }
}

impl Encoder for PprzV1 {
    fn header_len(&self) -> usize {
        HEADER_LEN + MsgHeader::V1_LEN
    }

    fn tail_len(&self) -> usize {
        TAIL_LEN
    }

    fn max_payload_len(&self) -> usize {
        V1_MAX_PAYLOAD_LEN
    }

    fn finish_frame(
        &self,
        meta: &TxMeta,
        frame: &mut [u8],
        payload_len: usize,
    ) -> Result<usize, EncodeError> {
        let len = self.frame_len(payload_len)?;
        let head = [
            STX,
            length_byte(len)?,
            meta.header.source,
            meta.header.msg_id,
        ];
        finish(frame, len, head)
    }
}

impl Framing for PprzV1 {
    fn start_byte(&self) -> u8 {
        STX
    }

    fn max_rx_frame_len(&self) -> usize {
        MAX_FRAME_LEN
    }

    fn rx_frame_len(&self, head: &[u8]) -> Result<Option<usize>, RxError> {
        rx_len(head, MsgHeader::V1_LEN)
    }

    fn verify(&self, frame: &[u8]) -> Result<(), RxError> {
        verify(frame)
    }

    fn check(&self, frame: &[u8]) -> Result<(), RxError> {
        check(frame, MsgHeader::V1_LEN)
    }

    fn view<'a>(&self, frame: &'a [u8]) -> Result<Frame<'a>, RxError> {
        let (raw, data) = raw_and_data(frame)?;
        Frame::from_v1(raw, data, self.rx_class)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// PROTOCOLS.md worked example: ALIVE (telemetry class 1, id 2) from aircraft 7
    /// to ground, `md5sum` = uint8[] [0, 1, 2] (count byte 3, then 0 1 2).
    static V2_FRAME: [u8; 12] = [
        0x99, 0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x1C, 0xC4,
    ];
    static V2_FIELDS: [u8; 4] = [0x03, 0x00, 0x01, 0x02];

    /// The same message in v1: `99 | LEN=4+2+4=10=0x0A | 07 | 02 | 03 00 01 02 | CK`.
    /// Checksum over 0A 07 02 03 00 01 02:
    ///   ck_a: 0A, 11, 13, 16, 16, 17, 19      ck_b: 0A, 1B, 2E, 44, 5A, 71, 8A
    static V1_FRAME: [u8; 10] = [0x99, 0x0A, 0x07, 0x02, 0x03, 0x00, 0x01, 0x02, 0x19, 0x8A];

    #[test]
    fn test_deconstruct() {
        let packet = Packet::new_checked(&V2_FRAME[..]).unwrap();
        assert_eq!(packet.stx(), 0x99);
        assert_eq!(packet.length(), 12);
        assert_eq!(packet.data(), &V2_FRAME[2..10]);
        assert_eq!(packet.checksum(), (0x1C, 0xC4));
        assert!(packet.verify_checksum());
    }

    #[test]
    fn test_construct() {
        let mut bytes = [0u8; 12];
        let mut packet = Packet::new_unchecked(&mut bytes[..]);
        packet.set_stx(STX);
        packet.set_length(12);
        packet
            .data_mut()
            .copy_from_slice(&[7, 0, 0x01, 2, 3, 0, 1, 2]);
        packet.fill_checksum();
        assert_eq!(bytes, V2_FRAME);
    }

    #[test]
    fn test_parse() {
        let (frame, len) = PprzV2.parse(&V2_FRAME).unwrap();
        assert_eq!(len, 12);
        assert_eq!(frame.source(), 7);
        assert_eq!(frame.destination(), Some(0));
        assert_eq!(frame.class(), 1);
        assert_eq!(frame.component(), 0);
        assert_eq!(frame.msg_id(), 2);
        assert_eq!(frame.payload(), &V2_FIELDS);
        assert_eq!(frame.raw(), &V2_FRAME);
        assert_eq!(frame.extra(), Extra::None);

        let (frame, len) = PprzV1::new(1).parse(&V1_FRAME).unwrap();
        assert_eq!(len, 10);
        assert_eq!(frame.source(), 7);
        assert_eq!(frame.destination(), None);
        assert_eq!(frame.class(), 1);
        assert_eq!(frame.msg_id(), 2);
        assert_eq!(frame.payload(), &V2_FIELDS);
    }

    #[test]
    fn test_emit() {
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2));
        let mut out = [0u8; 32];
        let n = PprzV2.encode(&meta, &V2_FIELDS, &mut out).unwrap();
        assert_eq!(&out[..n], &V2_FRAME);
        let n = PprzV1::new(1).encode(&meta, &V2_FIELDS, &mut out).unwrap();
        assert_eq!(&out[..n], &V1_FRAME);
    }

    #[test]
    fn test_check_len() {
        assert_eq!(
            Packet::new_checked(&[0x99][..]).unwrap_err(),
            RxError::Truncated
        );
        assert_eq!(
            Packet::new_checked(&[0x99, 3, 0][..]).unwrap_err(),
            RxError::BadLength
        );
        assert_eq!(
            Packet::new_checked(&V2_FRAME[..11]).unwrap_err(),
            RxError::Truncated
        );
    }

    #[test]
    fn bad_checksum_rejected() {
        let mut bad = V2_FRAME;
        bad[11] ^= 1;
        assert_eq!(PprzV2.parse(&bad).unwrap_err(), RxError::Checksum);
    }

    #[test]
    fn limits() {
        assert_eq!(V2_MAX_PAYLOAD_LEN, 247);
        assert_eq!(V1_MAX_PAYLOAD_LEN, 249);
        assert_eq!(PprzV2.max_frame_len(), 255);
        assert_eq!(PprzV1::new(1).max_frame_len(), 255);
    }
}
