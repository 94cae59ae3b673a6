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
//! Encoding, [`Framing`] and the [`Decoder`](crate::Decoder) are total: any input,
//! however short or corrupt, gives a typed error, never a panic.

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

    /// `DATA` of a frame of `frame_len` bytes (at least [`OVERHEAD`](super::OVERHEAD)).
    pub const fn data(frame_len: usize) -> Field {
        DATA_START..frame_len.saturating_sub(super::TAIL_LEN)
    }
}

/// Length of the transport header (before `DATA`).
pub const HEADER_LEN: usize = field::DATA_START;
/// Length of the transport tail (after `DATA`).
pub const TAIL_LEN: usize = 2;

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
    if len < K + TAIL_LEN {
        return Err(too_small);
    }
    *frame.first_chunk_mut::<K>().ok_or(too_small)? = head;
    put_checksum(frame);
    Ok(len)
}

/// Writes the checksum of `frame` (`LEN` .. last `DATA` byte) into its last two bytes
/// (a slice shorter than the tail is left as it is).
///
/// A call rather than inlined into [`finish`]: across it the caller keeps only the
/// frame's length live (the checksum is stored here), so encoding loops spill fewer
/// registers around it.
#[inline(never)]
fn put_checksum(frame: &mut [u8]) {
    if let Some((body, ck)) = frame.split_last_chunk_mut::<TAIL_LEN>() {
        let (a, b) = checksum::pprz(body.get(field::LEN..).unwrap_or_default());
        *ck = [a, b];
    }
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

/// The frame `LEN` announces at the start of `buf` and its `DATA` (bytes after the frame
/// are ignored). [`RxError::Truncated`] if `buf` holds no `LEN` byte or fewer bytes than
/// `LEN` announces, [`RxError::BadLength`] if `LEN` is below [`OVERHEAD`].
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

    /// Worked example (also in `docs/wire-formats.md`): ALIVE (telemetry class 1, id 2)
    /// from aircraft 7 to ground, `md5sum` = uint8[] [0, 1, 2] (count byte 3, then 0 1 2):
    /// `99 | LEN=0C | 07 00 01 02 | 03 00 01 02 | CK`. Checksum over 0C 07 00 01 02 03 00 01 02:
    ///   ck_a: 0C, 13, 13, 14, 16, 19, 19, 1A, 1C      ck_b: 0C, 1F, 32, 46, 5C, 75, 8E, A8, C4
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
        // The frame's parts, through the verified view.
        let (frame, len) = PprzV2.parse(&V2_FRAME).unwrap();
        let raw = frame.raw();
        assert_eq!(raw[field::STX], 0x99);
        assert_eq!(raw[field::LEN], 12);
        assert_eq!(len, 12);
        assert_eq!(frame.data(), &V2_FRAME[2..10]);
        assert_eq!(&V2_FRAME[field::data(len)], &V2_FRAME[2..10]);
        assert_eq!((raw[10], raw[11]), (0x1C, 0xC4));
        assert_eq!(checksum::pprz(&V2_FRAME[field::LEN..10]), (0x1C, 0xC4));
        assert_eq!(PprzV2.verify(&V2_FRAME), Ok(()));
    }

    #[test]
    fn test_construct() {
        // In place: the fields at `header_len()`, then STX, LEN, the v2 header
        // (07 00 01 02) and the checksum written around them.
        let mut bytes = [0xEEu8; 12];
        let fields_at = PprzV2.header_len();
        assert_eq!(fields_at, HEADER_LEN + MsgHeader::V2_LEN);
        bytes[fields_at..fields_at + 4].copy_from_slice(&V2_FIELDS);
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2));
        assert_eq!(PprzV2.finish_frame(&meta, &mut bytes, 4), Ok(12));
        assert_eq!(&bytes[field::data(12)], &[7, 0, 0x01, 2, 3, 0, 1, 2]);
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
        // No LEN byte, or fewer bytes than LEN announces: truncated; LEN below the
        // framing overhead: bad length. Through `parse` and through the view alone.
        for t in [PprzV2.into(), PprzV1::new(1).into()] {
            let t: crate::AnyTransport = t;
            assert_eq!(t.parse(&[0x99]).unwrap_err(), RxError::Truncated);
            assert_eq!(t.parse(&[0x99, 3, 0]).unwrap_err(), RxError::BadLength);
            assert_eq!(t.parse(&V2_FRAME[..11]).unwrap_err(), RxError::Truncated);
            assert_eq!(t.view(&[0x99]).unwrap_err(), RxError::Truncated);
            assert_eq!(t.view(&[0x99, 3, 0]).unwrap_err(), RxError::BadLength);
            assert_eq!(t.view(&V2_FRAME[..11]).unwrap_err(), RxError::Truncated);
        }
        // Bytes after the frame are allowed.
        let mut longer = [0u8; 16];
        longer[..12].copy_from_slice(&V2_FRAME);
        assert_eq!(
            PprzV2.parse(&longer).map(|(f, n)| (f.raw(), n)),
            Ok((&V2_FRAME[..], 12))
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
