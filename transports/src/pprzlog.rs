//! PPRZLOG: the storage framing of Paparazzi logs (SD card, log files).
//!
//! ```text
//!  0      1     2        3           7                 7+LEN
//! +------+-----+--------+-----------+-----------------+----+
//! | 0x99 | LEN | SOURCE | TIMESTAMP | DATA (LEN bytes) | CK |
//! +------+-----+--------+-----------+-----------------+----+
//!                         u32 LE      | source | destination | comp<<4|class | msg_id | fields |
//! ```
//!
//! * `LEN` counts `DATA` only; a record is `LEN + 8` bytes.
//! * `CK` is one byte: the sum (mod 256) of every byte from `LEN` to the end of
//!   `DATA` (so `SOURCE` and `TIMESTAMP` are covered).
//! * `SOURCE`: [`SOURCE_TELEMETRY`] (0, downlink) or [`SOURCE_DATALINK`] (1, uplink).
//! * `TIMESTAMP`: 100 µs ticks (what the ground log converter assumes), little-endian.
//!   A u32 of 100 µs ticks wraps after about 119 hours.
//! * `DATA` is the PPRZ v2 message header (4 bytes) followed by the fields: we chose
//!   the v2 header so a log keeps destination, component and class. `LEN` is one
//!   byte, so a record carries at most 251 field bytes.
//!
//! PPRZLOG and PPRZ share the start byte 0x99; nothing in a stream tells them apart:
//! the reader must know which one it reads.
//!
//! # No-panic contract
//!
//! [`Packet::new_unchecked`] accessors may panic on a short buffer; once
//! [`Packet::check_len`] (or [`Packet::new_checked`]) has succeeded, none of them can.

use crate::checksum;
use crate::transport::{
    EncodeError, Encoder, Extra, Frame, Framing, LogInfo, MsgHeader, RxError, TxMeta,
};

/// Start byte of every record.
pub const STX: u8 = 0x99;
/// Source of downlink (telemetry) records.
pub const SOURCE_TELEMETRY: u8 = 0;
/// Source of uplink (datalink) records.
pub const SOURCE_DATALINK: u8 = 1;
/// Bytes around `DATA`: STX, LEN, SOURCE, TIMESTAMP (4), CK.
pub const OVERHEAD: usize = 8;
/// Longest `DATA` (`LEN` is one byte).
pub const MAX_DATA_LEN: usize = 255;
/// Longest record.
pub const MAX_FRAME_LEN: usize = MAX_DATA_LEN + OVERHEAD;
/// Most field bytes per record.
pub const MAX_PAYLOAD_LEN: usize = MAX_DATA_LEN - MsgHeader::V2_LEN;

/// Byte offsets in a PPRZLOG record.
pub mod field {
    use crate::transport::field::Field;

    /// Start byte.
    pub const STX: usize = 0;
    /// Length of `DATA`.
    pub const LEN: usize = 1;
    /// Source (0 telemetry, 1 datalink).
    pub const SOURCE: usize = 2;
    /// Little-endian u32 time stamp, 100 µs ticks.
    pub const TIMESTAMP: Field = 3..7;
    /// First `DATA` byte.
    pub const DATA_START: usize = TIMESTAMP.end;

    /// `DATA` of a record whose `LEN` is `len`.
    pub const fn data(len: usize) -> Field {
        DATA_START..DATA_START + len
    }
    /// Bytes covered by the checksum in a record whose `LEN` is `len`.
    pub const fn checked(len: usize) -> Field {
        LEN..DATA_START + len
    }
    /// Offset of the checksum in a record whose `LEN` is `len`.
    pub const fn checksum(len: usize) -> usize {
        DATA_START + len
    }
}

/// Length of the record header before `DATA`.
pub const HEADER_LEN: usize = field::DATA_START;

/// A zero-copy view of a PPRZLOG record in a byte buffer.
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

    /// Checks that the buffer holds the whole record `LEN` announces. Bytes after
    /// the record are allowed.
    pub fn check_len(&self) -> Result<(), RxError> {
        let buf = self.buffer.as_ref();
        match buf.get(field::LEN) {
            Some(&len) if buf.len() >= usize::from(len) + OVERHEAD => Ok(()),
            _ => Err(RxError::Truncated),
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

    /// The `LEN` field: length of `DATA`.
    pub fn length(&self) -> u8 {
        self.buffer.as_ref()[field::LEN]
    }

    /// Whole-record length.
    pub fn frame_len(&self) -> usize {
        usize::from(self.length()) + OVERHEAD
    }

    /// The source byte.
    pub fn source(&self) -> u8 {
        self.buffer.as_ref()[field::SOURCE]
    }

    /// The time stamp, 100 µs ticks.
    pub fn timestamp(&self) -> u32 {
        let b = &self.buffer.as_ref()[field::TIMESTAMP];
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }

    /// The checksum byte as received.
    pub fn checksum(&self) -> u8 {
        self.buffer.as_ref()[field::checksum(usize::from(self.length()))]
    }

    /// Whether the checksum byte matches the record.
    pub fn verify_checksum(&self) -> bool {
        let len = usize::from(self.length());
        checksum::sum8(&self.buffer.as_ref()[field::checked(len)]) == self.checksum()
    }
}

impl<'a, T: AsRef<[u8]> + ?Sized> Packet<&'a T> {
    /// `DATA`: the v2 message header and fields.
    pub fn data(&self) -> &'a [u8] {
        &self.buffer.as_ref()[field::data(usize::from(self.length()))]
    }

    /// The record, without bytes after it.
    pub fn frame(&self) -> &'a [u8] {
        &self.buffer.as_ref()[..self.frame_len()]
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Packet<T> {
    /// Sets the start byte.
    pub fn set_stx(&mut self, value: u8) {
        self.buffer.as_mut()[field::STX] = value;
    }

    /// Sets `LEN` (length of `DATA`).
    pub fn set_length(&mut self, value: u8) {
        self.buffer.as_mut()[field::LEN] = value;
    }

    /// Sets the source byte.
    pub fn set_source(&mut self, value: u8) {
        self.buffer.as_mut()[field::SOURCE] = value;
    }

    /// Sets the time stamp (100 µs ticks).
    pub fn set_timestamp(&mut self, value: u32) {
        self.buffer.as_mut()[field::TIMESTAMP].copy_from_slice(&value.to_le_bytes());
    }

    /// Mutable `DATA` (per the `LEN` field).
    pub fn data_mut(&mut self) -> &mut [u8] {
        let range = field::data(usize::from(self.length()));
        &mut self.buffer.as_mut()[range]
    }

    /// Computes and writes the checksum (per the `LEN` field).
    pub fn fill_checksum(&mut self) {
        let len = usize::from(self.length());
        let buf = self.buffer.as_mut();
        buf[field::checksum(len)] = checksum::sum8(&buf[field::checked(len)]);
    }
}

/// The PPRZLOG record framing, writing records with a fixed `SOURCE`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PprzLog {
    /// `SOURCE` byte of written records. Reading ignores it and reports the
    /// source of each record.
    pub source: u8,
}

impl PprzLog {
    /// Records with source [`SOURCE_TELEMETRY`].
    pub const TELEMETRY: Self = Self::new(SOURCE_TELEMETRY);
    /// Records with source [`SOURCE_DATALINK`].
    pub const DATALINK: Self = Self::new(SOURCE_DATALINK);

    /// Records with the given source byte.
    pub const fn new(source: u8) -> Self {
        Self { source }
    }
}

impl Encoder for PprzLog {
    fn header_len(&self) -> usize {
        HEADER_LEN + MsgHeader::V2_LEN
    }

    fn tail_len(&self) -> usize {
        1
    }

    fn max_payload_len(&self) -> usize {
        MAX_PAYLOAD_LEN
    }

    fn finish_frame(
        &self,
        meta: &TxMeta,
        frame: &mut [u8],
        payload_len: usize,
    ) -> Result<usize, EncodeError> {
        let len = self.frame_len(payload_len)?;
        meta.header.check()?;
        let available = frame.len();
        let too_small = EncodeError::BufferTooSmall {
            needed: len,
            available,
        };
        let frame = frame.get_mut(..len).ok_or(too_small)?;
        let data_len = u8::try_from(len - OVERHEAD).map_err(|_| too_small)?;
        let mut packet = Packet::new_unchecked(frame);
        packet.set_stx(STX);
        packet.set_length(data_len);
        packet.set_source(self.source);
        packet.set_timestamp(meta.timestamp);
        meta.header.emit_v2(packet.data_mut())?;
        packet.fill_checksum();
        Ok(len)
    }
}

impl Framing for PprzLog {
    fn start_byte(&self) -> u8 {
        STX
    }

    fn max_rx_frame_len(&self) -> usize {
        MAX_FRAME_LEN
    }

    fn rx_frame_len(&self, head: &[u8]) -> Result<Option<usize>, RxError> {
        match head.get(field::LEN) {
            None => Ok(None),
            Some(&len) if usize::from(len) < MsgHeader::V2_LEN => Err(RxError::BadLength),
            Some(&len) => Ok(Some(usize::from(len) + OVERHEAD)),
        }
    }

    fn verify(&self, frame: &[u8]) -> Result<(), RxError> {
        let packet = Packet::new_checked(frame)?;
        if packet.stx() != STX {
            return Err(RxError::BadStart);
        }
        if packet.frame_len() != frame.len() {
            return Err(RxError::BadLength);
        }
        if packet.verify_checksum() {
            Ok(())
        } else {
            Err(RxError::Checksum)
        }
    }

    fn check(&self, frame: &[u8]) -> Result<(), RxError> {
        self.verify(frame)?;
        // What `view` needs besides: room for the v2 message header in `DATA`.
        if frame.len() < OVERHEAD + MsgHeader::V2_LEN {
            Err(RxError::BadLength)
        } else {
            Ok(())
        }
    }

    fn view<'a>(&self, frame: &'a [u8]) -> Result<Frame<'a>, RxError> {
        let packet = Packet::new_checked(frame)?;
        let info = LogInfo {
            source: packet.source(),
            timestamp: packet.timestamp(),
        };
        Frame::from_v2(packet.frame(), packet.data(), Extra::Log(info))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ALIVE (class 1, id 2) from aircraft 7 to ground, fields 03 00 01 02, logged as
    /// telemetry at t = 0x12345678 ticks:
    ///   99 | LEN = 4 + 4 = 08 | 00 | 78 56 34 12 | 07 00 01 02 03 00 01 02 | CK
    ///   CK = 08+00+78+56+34+12+07+00+01+02+03+00+01+02 = 0x12C -> 0x2C
    static RECORD: [u8; 16] = [
        0x99, 0x08, 0x00, 0x78, 0x56, 0x34, 0x12, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02,
        0x2C,
    ];
    static FIELDS: [u8; 4] = [0x03, 0x00, 0x01, 0x02];

    #[test]
    fn test_deconstruct() {
        let p = Packet::new_checked(&RECORD[..]).unwrap();
        assert_eq!(p.stx(), 0x99);
        assert_eq!(p.length(), 8);
        assert_eq!(p.frame_len(), 16);
        assert_eq!(p.source(), 0);
        assert_eq!(p.timestamp(), 0x1234_5678);
        assert_eq!(p.data(), &RECORD[7..15]);
        assert_eq!(p.checksum(), 0x2C);
        assert!(p.verify_checksum());
    }

    #[test]
    fn test_construct() {
        let mut bytes = [0u8; 16];
        let mut p = Packet::new_unchecked(&mut bytes[..]);
        p.set_stx(STX);
        p.set_length(8);
        p.set_source(SOURCE_TELEMETRY);
        p.set_timestamp(0x1234_5678);
        p.data_mut().copy_from_slice(&RECORD[7..15]);
        p.fill_checksum();
        assert_eq!(bytes, RECORD);
    }

    #[test]
    fn test_parse() {
        let (f, n) = PprzLog::TELEMETRY.parse(&RECORD).unwrap();
        assert_eq!(n, 16);
        assert_eq!(
            (f.source(), f.destination(), f.class(), f.msg_id()),
            (7, Some(0), 1, 2)
        );
        assert_eq!(f.payload(), &FIELDS);
        assert_eq!(f.timestamp(), Some(0x1234_5678));
        assert_eq!(
            f.extra(),
            Extra::Log(LogInfo {
                source: 0,
                timestamp: 0x1234_5678
            })
        );
    }

    #[test]
    fn test_emit() {
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2)).at(0x1234_5678);
        let mut out = [0u8; 32];
        let n = PprzLog::TELEMETRY.encode(&meta, &FIELDS, &mut out).unwrap();
        assert_eq!(&out[..n], &RECORD);
    }

    #[test]
    fn limits() {
        assert_eq!(MAX_PAYLOAD_LEN, 251);
        assert_eq!(PprzLog::TELEMETRY.max_frame_len(), MAX_FRAME_LEN);
    }
}
