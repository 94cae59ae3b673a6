//! XBee API transport (API mode 1, no escaping), 802.15.4 ("XBee 2.4") and 868 MHz.
//!
//! ```text
//!  0      1         2         3                           3+LEN
//! +------+---------+---------+---------------------------+----+
//! | 0x7E | LEN_MSB | LEN_LSB | FRAME_DATA (LEN bytes)    | CK |
//! +------+---------+---------+---------------------------+----+
//!                              CK = 0xFF - (sum(FRAME_DATA) & 0xFF)
//! ```
//!
//! `FRAME_DATA` starts with the API id. Inside the RF data there is only the PPRZ v2
//! message header (4 bytes) and the fields: no 0x99, no PPRZ length or checksum.
//!
//! 802.15.4 ([`XBee24`]), offsets in `FRAME_DATA`:
//!
//! ```text
//! TX16 (sent):     | 0x01 | frame_id | dest_hi | dest_lo | options | v2 hdr | fields |
//! RX16 (received): | 0x81 | src_hi   | src_lo  | rssi    | options | v2 hdr | fields |
//! ```
//!
//! A receiver also accepts 0x01 (a TX16 frame seen on a cable loopback). The RF
//! payload is at most 100 bytes: 4-byte header + at most 96 field bytes.
//!
//! 868 MHz ([`XBee868`]), offsets in `FRAME_DATA`:
//!
//! ```text
//! 0x10 (sent):     | 0x10 | frame_id | dest64 (8) | FF FE | radius 0 | options | v2 hdr | fields |
//! 0x90 (received): | 0x90 | src64 (8) | src16 (2) | options | v2 hdr | fields |
//! ```
//!
//! A receiver also accepts 0x10 (loopback). `LEN` counts every `FRAME_DATA` byte
//! (the reference C code computes it as for 802.15.4, which is wrong for 868).
//! The module's RF payload is at most 256 bytes; we send at most 247 field bytes
//! (251 RF bytes), the PPRZ v2 limit, so every XBee 868 message can be relayed
//! over PPRZ v2 unchanged. Receive accepts up to the full 256 RF bytes.
//!
//! Transmit statuses (both radios): a transmit request whose frame id is not
//! [`NO_FRAME_ID`] is answered by the local module with one status frame once the
//! transmission is over:
//!
//! ```text
//! 0x89 (802.15.4):  | 0x89 | frame_id | status |
//! 0x8B (868, ...):  | 0x8B | frame_id | FF FE (reserved) | retries | delivery | discovery |
//! ```
//!
//! Status / delivery 0 is success (constants in [`status`]). Both XBee transports
//! accept both layouts (an 802.15.4 XBee 3 answers a 0x10 request with 0x8B). A status
//! is a control frame ([`Control`]): the [`Decoder`](crate::Decoder) keeps it aside as
//! a [`TxStatus`] ([`Decoder::take_tx_status`](crate::Decoder::take_tx_status)) and
//! never hands it out as a message. A status frame of another length, or with a bad
//! checksum, is rejected like any bad candidate (counted as a length or checksum
//! error). Frame ids are written at send time with
//! [`AnyTransport::set_frame_id`](crate::AnyTransport::set_frame_id) (or
//! [`XBee24::set_tx_frame_id`], [`XBee868::set_tx_frame_id`]);
//! [`encode_tx_status_24`] and [`encode_tx_status_868`] build status frames for
//! simulated modems and tests.
//!
//! | API id | direction | frame | [`XBee24`] | [`XBee868`] |
//! |--------|-----------|-------|------------|-------------|
//! | 0x01 | sent | TX16 request | sent, received (loopback) | unknown API |
//! | 0x81 | received | RX16 packet | message frame | unknown API |
//! | 0x10 | sent | transmit request | unknown API | sent, received (loopback) |
//! | 0x90 | received | receive packet | unknown API | message frame |
//! | 0x89 | received | 802.15.4 transmit status | [`TxStatus`] | [`TxStatus`] |
//! | 0x8B | received | transmit status | [`TxStatus`] | [`TxStatus`] |
//! | other | | | unknown API | unknown API |
//!
//! Address mapping (both radios): receiver 0 (ground) -> `0x0100`, 0xFF (broadcast)
//! -> `0xFFFF`, any other id -> the id itself. On 868 the same 16-bit value is the
//! low half of the 64-bit destination (`0x000000000000FFFF` is the 868 broadcast
//! address).
//!
//! # No-panic contract
//!
//! [`Packet::new_unchecked`] accessors may panic on a short buffer; once
//! [`Packet::check_len`] (or [`Packet::new_checked`]) has succeeded, none of them can.

use crate::checksum;
use crate::transport::{
    Control, EncodeError, Encoder, Extra, Frame, Framing, MsgHeader, RxError, TxMeta, TxStatus,
    XBeeInfo,
};

/// Start delimiter of every API frame.
pub const START: u8 = 0x7E;
/// 802.15.4 transmit request, 16-bit address.
pub const API_TX16: u8 = 0x01;
/// 802.15.4 receive packet, 16-bit address.
pub const API_RX16: u8 = 0x81;
/// 868 transmit request.
pub const API_TX_868: u8 = 0x10;
/// 868 receive packet.
pub const API_RX_868: u8 = 0x90;
/// 802.15.4 transmit status: `| 0x89 | frame_id | status |`.
pub const API_TX_STATUS: u8 = 0x89;
/// 868 (and ZigBee, DigiMesh, XBee 3) transmit status:
/// `| 0x8B | frame_id | FF FE | retries | delivery | discovery |`.
pub const API_TX_STATUS_868: u8 = 0x8B;
/// Frame id 0: the module sends no transmit status.
pub const NO_FRAME_ID: u8 = 0;
/// 16-bit address of the ground station's module.
pub const GROUND_ADDRESS: u16 = 0x0100;
/// 16-bit broadcast address.
pub const BROADCAST_ADDRESS: u16 = 0xFFFF;
/// Largest 802.15.4 RF payload.
pub const MAX_RF_PAYLOAD_24: usize = 100;
/// Largest 868 RF payload.
pub const MAX_RF_PAYLOAD_868: usize = 256;
/// Length of the checksum (the only byte after `FRAME_DATA`).
pub const CHECKSUM_LEN: usize = 1;
/// Bytes of framing around `FRAME_DATA`: start, length (2), checksum.
pub const OVERHEAD: usize = 3 + CHECKSUM_LEN;
/// Length of a whole 802.15.4 transmit status frame (0x89): 7 bytes.
pub const TX_STATUS_FRAME_LEN: usize = field::tx_status::LEN + OVERHEAD;
/// Length of a whole 868 transmit status frame (0x8B): 11 bytes.
pub const TX_STATUS_868_FRAME_LEN: usize = field::tx_status_868::LEN + OVERHEAD;

/// Transmit status codes: the status byte of 0x89 and the delivery status byte of
/// 0x8B ([`TxStatus::status`]), and the discovery status byte of 0x8B.
///
/// Values 0..=3 are shared by both frames (802.15.4 calls 1 "no ACK", the others
/// "MAC ACK failure"); the others are 0x8B delivery statuses. Modules may report codes
/// not listed here: anything but [`SUCCESS`](status::SUCCESS) is a failure.
pub mod status {
    /// Delivered (a broadcast always reports it).
    pub const SUCCESS: u8 = 0x00;
    /// No acknowledgement from the destination after the MAC retries (802.15.4 "no
    /// ACK", 0x8B "MAC ACK failure").
    pub const NO_ACK: u8 = 0x01;
    /// The channel was never clear (802.15.4 CCA failure, 868 LBT failure).
    pub const CCA_FAILURE: u8 = 0x02;
    /// 802.15.4: the indirect (coordinator) transmission was purged; 868: no spectrum
    /// available.
    pub const PURGED: u8 = 0x03;
    /// 0x8B: no network acknowledgement from the destination.
    pub const NETWORK_ACK_FAILURE: u8 = 0x21;
    /// 0x8B: no route to the destination.
    pub const ROUTE_NOT_FOUND: u8 = 0x25;
    /// 0x8B: internal resource error.
    pub const INTERNAL_ERROR: u8 = 0x31;
    /// 0x8B: lack of free buffers, timers...
    pub const RESOURCE_ERROR: u8 = 0x32;
    /// 0x8B: RF payload too large for the module.
    pub const PAYLOAD_TOO_LARGE: u8 = 0x74;
    /// 0x8B: indirect message unrequested.
    pub const INDIRECT_UNREQUESTED: u8 = 0x75;

    /// 0x8B discovery status: no discovery overhead.
    pub const DISCOVERY_NONE: u8 = 0x00;
    /// 0x8B discovery status: address discovery.
    pub const DISCOVERY_ADDRESS: u8 = 0x01;
    /// 0x8B discovery status: route discovery.
    pub const DISCOVERY_ROUTE: u8 = 0x02;
    /// 0x8B discovery status: address and route discovery.
    pub const DISCOVERY_ADDRESS_AND_ROUTE: u8 = 0x03;
}

/// Byte offsets in an API frame.
pub mod field {
    use crate::transport::field::Field;

    /// Start delimiter.
    pub const START: usize = 0;
    /// Big-endian length of `FRAME_DATA`.
    pub const LENGTH: Field = 1..3;
    /// First `FRAME_DATA` byte: the API id.
    pub const FRAME_DATA_START: usize = LENGTH.end;
    /// API id.
    pub const API_ID: usize = FRAME_DATA_START;

    /// `FRAME_DATA` of a frame whose length field is `length`.
    pub const fn frame_data(length: usize) -> Field {
        FRAME_DATA_START..FRAME_DATA_START + length
    }
    /// Checksum offset in a frame whose length field is `length`.
    pub const fn checksum(length: usize) -> usize {
        FRAME_DATA_START + length
    }

    /// TX16 (0x01) offsets in `FRAME_DATA`.
    pub mod tx16 {
        use super::Field;
        /// API id, 0x01.
        pub const API_ID: usize = 0;
        /// Frame id (0: no status).
        pub const FRAME_ID: usize = 1;
        /// Big-endian 16-bit destination.
        pub const DEST: Field = 2..4;
        /// Options.
        pub const OPTIONS: usize = 4;
        /// RF data.
        pub const DATA: usize = 5;
    }

    /// RX16 (0x81) offsets in `FRAME_DATA`.
    pub mod rx16 {
        use super::Field;
        /// API id, 0x81.
        pub const API_ID: usize = 0;
        /// Big-endian 16-bit source.
        pub const SOURCE: Field = 1..3;
        /// RSSI, `n` = `-n` dBm.
        pub const RSSI: usize = 3;
        /// Options.
        pub const OPTIONS: usize = 4;
        /// RF data.
        pub const DATA: usize = 5;
    }

    /// 868 transmit request (0x10) offsets in `FRAME_DATA`.
    pub mod tx868 {
        use super::Field;
        /// API id, 0x10.
        pub const API_ID: usize = 0;
        /// Frame id (0: no status).
        pub const FRAME_ID: usize = 1;
        /// Big-endian 64-bit destination.
        pub const DEST64: Field = 2..10;
        /// 16-bit destination, always `FF FE`.
        pub const DEST16: Field = 10..12;
        /// Broadcast radius (0 = maximum).
        pub const RADIUS: usize = 12;
        /// Options.
        pub const OPTIONS: usize = 13;
        /// RF data.
        pub const DATA: usize = 14;
    }

    /// 802.15.4 transmit status (0x89) offsets in `FRAME_DATA`.
    pub mod tx_status {
        /// API id, 0x89.
        pub const API_ID: usize = 0;
        /// Frame id of the request this status answers.
        pub const FRAME_ID: usize = 1;
        /// Status (0: success).
        pub const STATUS: usize = 2;
        /// `FRAME_DATA` length (the `LEN` field) of every 0x89 frame.
        pub const LEN: usize = 3;
    }

    /// Transmit status (0x8B) offsets in `FRAME_DATA`.
    pub mod tx_status_868 {
        use super::Field;
        /// API id, 0x8B.
        pub const API_ID: usize = 0;
        /// Frame id of the request this status answers.
        pub const FRAME_ID: usize = 1;
        /// Reserved (`FF FE` on 868; the 16-bit destination on ZigBee).
        pub const RESERVED: Field = 2..4;
        /// Transmission retries.
        pub const RETRIES: usize = 4;
        /// Delivery status (0: success).
        pub const DELIVERY: usize = 5;
        /// Discovery status.
        pub const DISCOVERY: usize = 6;
        /// `FRAME_DATA` length (the `LEN` field) of every 0x8B frame.
        pub const LEN: usize = 7;
    }

    /// 868 receive packet (0x90) offsets in `FRAME_DATA`.
    pub mod rx868 {
        use super::Field;
        /// API id, 0x90.
        pub const API_ID: usize = 0;
        /// Big-endian 64-bit source.
        pub const SOURCE64: Field = 1..9;
        /// 16-bit source (`FF FE`).
        pub const SOURCE16: Field = 9..11;
        /// Options.
        pub const OPTIONS: usize = 11;
        /// RF data.
        pub const DATA: usize = 12;
    }
}

/// Length of the API frame header before `FRAME_DATA`.
pub const HEADER_LEN: usize = field::FRAME_DATA_START;

/// 16-bit XBee address of a PPRZ receiver id: 0 (ground) -> `0x0100`,
/// 0xFF (broadcast) -> `0xFFFF`, otherwise the id.
pub const fn address16(receiver: u8) -> u16 {
    match receiver {
        crate::transport::GROUND_ID => GROUND_ADDRESS,
        crate::transport::BROADCAST_ID => BROADCAST_ADDRESS,
        id => id as u16,
    }
}

/// 64-bit XBee 868 address of a PPRZ receiver id: [`address16`] in the low bits.
pub const fn address64(receiver: u8) -> u64 {
    address16(receiver) as u64
}

/// A zero-copy view of an XBee API frame in a byte buffer.
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

    /// Checks that the buffer holds the whole frame the length field announces
    /// and that `FRAME_DATA` is not empty. Bytes after the frame are allowed.
    pub fn check_len(&self) -> Result<(), RxError> {
        let buf = self.buffer.as_ref();
        let length = match buf.get(field::LENGTH) {
            Some(&[hi, lo]) => usize::from(u16::from_be_bytes([hi, lo])),
            _ => return Err(RxError::Truncated),
        };
        if length == 0 {
            Err(RxError::BadLength)
        } else if buf.len() < length + OVERHEAD {
            Err(RxError::Truncated)
        } else {
            Ok(())
        }
    }

    /// Returns the buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    /// The start delimiter.
    pub fn start(&self) -> u8 {
        self.buffer.as_ref()[field::START]
    }

    /// The length field: number of `FRAME_DATA` bytes.
    pub fn length(&self) -> u16 {
        let buf = self.buffer.as_ref();
        u16::from_be_bytes([buf[field::LENGTH.start], buf[field::LENGTH.start + 1]])
    }

    /// Whole-frame length.
    pub fn frame_len(&self) -> usize {
        usize::from(self.length()) + OVERHEAD
    }

    /// The API id (first `FRAME_DATA` byte).
    pub fn api_id(&self) -> u8 {
        self.buffer.as_ref()[field::API_ID]
    }

    /// The checksum byte as received.
    pub fn checksum(&self) -> u8 {
        self.buffer.as_ref()[field::checksum(usize::from(self.length()))]
    }

    /// Whether `sum(FRAME_DATA) + CK == 0xFF (mod 256)`.
    pub fn verify_checksum(&self) -> bool {
        let buf = self.buffer.as_ref();
        let data = &buf[field::frame_data(usize::from(self.length()))];
        checksum::sum8(data).wrapping_add(self.checksum()) == 0xFF
    }
}

impl<'a, T: AsRef<[u8]> + ?Sized> Packet<&'a T> {
    /// `FRAME_DATA`: API id and the API frame's fields.
    pub fn frame_data(&self) -> &'a [u8] {
        &self.buffer.as_ref()[field::frame_data(usize::from(self.length()))]
    }

    /// The frame, without bytes after it.
    pub fn frame(&self) -> &'a [u8] {
        &self.buffer.as_ref()[..self.frame_len()]
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Packet<T> {
    /// Sets the start delimiter.
    pub fn set_start(&mut self, value: u8) {
        self.buffer.as_mut()[field::START] = value;
    }

    /// Sets the length field.
    pub fn set_length(&mut self, value: u16) {
        self.buffer.as_mut()[field::LENGTH].copy_from_slice(&value.to_be_bytes());
    }

    /// Mutable `FRAME_DATA` (per the length field).
    pub fn frame_data_mut(&mut self) -> &mut [u8] {
        let range = field::frame_data(usize::from(self.length()));
        &mut self.buffer.as_mut()[range]
    }

    /// Computes and writes the checksum (per the length field).
    pub fn fill_checksum(&mut self) {
        let length = usize::from(self.length());
        let buf = self.buffer.as_mut();
        buf[field::checksum(length)] = checksum::xbee(&buf[field::frame_data(length)]);
    }
}

/// Frames `frame[..len]`: start, length, API header written by `api_header`, v2
/// header, checksum. The fields are already in place after the v2 header.
fn finish(
    frame: &mut [u8],
    len: usize,
    header: &MsgHeader,
    api_header_len: usize,
    api_header: impl FnOnce(&mut [u8]),
) -> Result<usize, EncodeError> {
    header.check()?;
    let available = frame.len();
    let too_small = EncodeError::BufferTooSmall {
        needed: len,
        available,
    };
    let frame = frame.get_mut(..len).ok_or(too_small)?;
    let length = u16::try_from(len - OVERHEAD).map_err(|_| too_small)?;
    let mut packet = Packet::new_unchecked(frame);
    packet.set_start(START);
    packet.set_length(length);
    let data = packet.frame_data_mut();
    let (api, rest) = data.split_at_mut_checked(api_header_len).ok_or(too_small)?;
    api_header(api);
    header.emit_v2(rest)?;
    packet.fill_checksum();
    Ok(len)
}

/// Length field of `head`, if known, checked against `1..=max_length`.
fn rx_len(head: &[u8], max_length: usize) -> Result<Option<usize>, RxError> {
    match head.get(field::LENGTH) {
        Some(&[hi, lo]) => {
            let length = usize::from(u16::from_be_bytes([hi, lo]));
            if length == 0 || length > max_length {
                Err(RxError::BadLength)
            } else {
                Ok(Some(length + OVERHEAD))
            }
        }
        _ => Ok(None),
    }
}

/// Start, exact length, checksum, then the API id must be one of `accepted`.
fn verify(frame: &[u8], accepted: [u8; 2]) -> Result<(), RxError> {
    let packet = Packet::new_checked(frame)?;
    if packet.start() != START {
        return Err(RxError::BadStart);
    }
    if packet.frame_len() != frame.len() {
        return Err(RxError::BadLength);
    }
    if !packet.verify_checksum() {
        return Err(RxError::Checksum);
    }
    let api = packet.api_id();
    if accepted.contains(&api) {
        Ok(())
    } else {
        Err(RxError::UnknownApiId(api))
    }
}

/// [`Framing::control`] of both XBee transports: the transmit statuses.
fn control(frame: &[u8]) -> Option<Result<Control, RxError>> {
    match frame.get(field::API_ID) {
        Some(&(API_TX_STATUS | API_TX_STATUS_868)) => Some(tx_status(frame)),
        _ => None,
    }
}

/// A transmit status frame (0x89 or 0x8B), checked as [`verify`] checks messages:
/// start, exact length, checksum, then the layout of its API id.
fn tx_status(frame: &[u8]) -> Result<Control, RxError> {
    let packet = Packet::new_checked(frame)?;
    if packet.start() != START {
        return Err(RxError::BadStart);
    }
    if packet.frame_len() != frame.len() {
        return Err(RxError::BadLength);
    }
    if !packet.verify_checksum() {
        return Err(RxError::Checksum);
    }
    let report = match *packet.frame_data() {
        [API_TX_STATUS, frame_id, code] => TxStatus {
            frame_id,
            delivered: code == status::SUCCESS,
            status: code,
            retries: 0,
        },
        [
            API_TX_STATUS_868,
            frame_id,
            _,
            _,
            retries,
            delivery,
            _discovery,
        ] => TxStatus {
            frame_id,
            delivered: delivery == status::SUCCESS,
            status: delivery,
            retries,
        },
        [API_TX_STATUS | API_TX_STATUS_868, ..] => return Err(RxError::BadLength),
        [api, ..] => return Err(RxError::UnknownApiId(api)),
        [] => return Err(RxError::BadLength),
    };
    Ok(Control::TxStatus(report))
}

/// Writes the API frame whose `FRAME_DATA` is `data` to the start of `out`.
fn encode_api_frame<const L: usize>(data: [u8; L], out: &mut [u8]) -> Result<usize, EncodeError> {
    let len = L + OVERHEAD;
    let available = out.len();
    let too_small = EncodeError::BufferTooSmall {
        needed: len,
        available,
    };
    let frame = out.get_mut(..len).ok_or(too_small)?;
    let mut packet = Packet::new_unchecked(frame);
    packet.set_start(START);
    packet.set_length(u16::try_from(L).map_err(|_| too_small)?);
    packet.frame_data_mut().copy_from_slice(&data);
    packet.fill_checksum();
    Ok(len)
}

/// Builds the 802.15.4 transmit status frame (0x89) a module sends for the request
/// `frame_id`, with status byte `status` ([`status`] codes), at the start of `out`;
/// returns its length, [`TX_STATUS_FRAME_LEN`]. For simulated modems and tests.
///
/// ```
/// use pprz_transports::{Control, Framing, TxStatus, XBee24, xbee};
/// let mut out = [0u8; 16];
/// let n = xbee::encode_tx_status_24(0x47, xbee::status::NO_ACK, &mut out).unwrap();
/// assert_eq!(&out[..n], &[0x7E, 0x00, 0x03, 0x89, 0x47, 0x01, 0x2E]);
/// let status = TxStatus { frame_id: 0x47, delivered: false, status: 1, retries: 0 };
/// assert_eq!(XBee24::new().parse_control(&out), Some((Control::TxStatus(status), 7)));
/// ```
pub fn encode_tx_status_24(frame_id: u8, status: u8, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode_api_frame([API_TX_STATUS, frame_id, status], out)
}

/// Builds the transmit status frame (0x8B) a module sends for the request `frame_id`
/// after `retries` retries, with delivery status `delivery` and discovery status
/// `discovery` ([`status`] codes), reserved bytes `FF FE`, at the start of `out`;
/// returns its length, [`TX_STATUS_868_FRAME_LEN`]. For simulated modems and tests.
pub fn encode_tx_status_868(
    frame_id: u8,
    retries: u8,
    delivery: u8,
    discovery: u8,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    encode_api_frame(
        [
            API_TX_STATUS_868,
            frame_id,
            0xFF,
            0xFE,
            retries,
            delivery,
            discovery,
        ],
        out,
    )
}

/// The `FRAME_DATA` of a transmit request `frame` with API id `api` whose header
/// (`header_len` `FRAME_DATA` bytes) is whole; bytes after the frame are allowed.
fn tx_request(frame: &[u8], api: u8, header_len: usize) -> Option<&[u8]> {
    let packet = Packet::new_checked(frame).ok()?;
    let data = packet.frame_data();
    (packet.start() == START && packet.api_id() == api && data.len() >= header_len).then_some(data)
}

/// Frame id of the transmit request `frame` (API id `api`, header `header_len` bytes).
fn tx_frame_id(frame: &[u8], api: u8, header_len: usize, at: usize) -> Option<u8> {
    tx_request(frame, api, header_len)?.get(at).copied()
}

/// Rewrites the frame id of the transmit request `frame` and its checksum.
fn set_tx_frame_id(frame: &mut [u8], id: u8, api: u8, header_len: usize, at: usize) -> bool {
    if tx_request(frame, api, header_len).is_none() {
        return false;
    }
    let mut packet = Packet::new_unchecked(frame);
    match packet.frame_data_mut().get_mut(at) {
        Some(byte) => *byte = id,
        None => return false,
    }
    packet.fill_checksum();
    true
}

fn be_u64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0u64, |acc, &b| (acc << 8) | u64::from(b))
}

/// XBee 802.15.4 ("XBee 2.4", series 1) in API mode 1.
///
/// Sends TX16 (0x01); receives RX16 (0x81) and TX16 (0x01, cable loopback) as
/// messages, and transmit statuses (0x89, 0x8B) as control frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct XBee24 {
    /// Frame id of sent frames ([`NO_FRAME_ID`]: the module sends no status).
    pub frame_id: u8,
    /// Options byte of sent frames (0x01 disables the MAC acknowledgement).
    pub options: u8,
}

impl XBee24 {
    /// Most field bytes per frame: 100-byte RF payload minus the 4-byte header.
    pub const MAX_PAYLOAD_LEN: usize = MAX_RF_PAYLOAD_24 - MsgHeader::V2_LEN;
    /// Largest `FRAME_DATA` accepted: RX16/TX16 header + a full RF payload.
    pub const MAX_RX_LENGTH: usize = field::rx16::DATA + MAX_RF_PAYLOAD_24;

    /// Frame id 0 and options 0, as the reference firmware.
    pub const fn new() -> Self {
        Self {
            frame_id: NO_FRAME_ID,
            options: 0,
        }
    }

    /// The frame id of a TX16 frame (API id 0x01, as this encoder writes it), or `None`
    /// if `frame` does not start with a whole one. Bytes after the frame are allowed;
    /// the checksum is not verified.
    pub fn tx_frame_id(&self, frame: &[u8]) -> Option<u8> {
        use field::tx16;
        tx_frame_id(frame, API_TX16, tx16::DATA, tx16::FRAME_ID)
    }

    /// Rewrites the frame id of the TX16 frame at the start of `frame` to `id`, and its
    /// checksum (recomputed over the whole `FRAME_DATA`); `false` (and `frame`
    /// untouched) if `frame` does not start with a whole TX16 frame. `id`
    /// [`NO_FRAME_ID`] asks the module for no status.
    pub fn set_tx_frame_id(&self, frame: &mut [u8], id: u8) -> bool {
        use field::tx16;
        set_tx_frame_id(frame, id, API_TX16, tx16::DATA, tx16::FRAME_ID)
    }
}

impl Encoder for XBee24 {
    fn header_len(&self) -> usize {
        HEADER_LEN + field::tx16::DATA + MsgHeader::V2_LEN
    }

    fn tail_len(&self) -> usize {
        CHECKSUM_LEN
    }

    fn max_payload_len(&self) -> usize {
        Self::MAX_PAYLOAD_LEN
    }

    fn finish_frame(
        &self,
        meta: &TxMeta,
        frame: &mut [u8],
        payload_len: usize,
    ) -> Result<usize, EncodeError> {
        use field::tx16;
        let len = self.frame_len(payload_len)?;
        let dest = address16(meta.header.destination).to_be_bytes();
        finish(frame, len, &meta.header, tx16::DATA, |api| {
            api[tx16::API_ID] = API_TX16;
            api[tx16::FRAME_ID] = self.frame_id;
            api[tx16::DEST].copy_from_slice(&dest);
            api[tx16::OPTIONS] = self.options;
        })
    }
}

impl Framing for XBee24 {
    fn start_byte(&self) -> u8 {
        START
    }

    fn max_rx_frame_len(&self) -> usize {
        Self::MAX_RX_LENGTH + OVERHEAD
    }

    fn rx_frame_len(&self, head: &[u8]) -> Result<Option<usize>, RxError> {
        rx_len(head, Self::MAX_RX_LENGTH)
    }

    fn verify(&self, frame: &[u8]) -> Result<(), RxError> {
        verify(frame, [API_RX16, API_TX16])
    }

    fn control(&self, frame: &[u8]) -> Option<Result<Control, RxError>> {
        control(frame)
    }

    fn has_control(&self) -> bool {
        true
    }

    fn view<'a>(&self, frame: &'a [u8]) -> Result<Frame<'a>, RxError> {
        use field::{rx16, tx16};
        let packet = Packet::new_checked(frame)?;
        let fd = packet.frame_data();
        let head = fd.get(..rx16::DATA).ok_or(RxError::BadLength)?;
        let info = match packet.api_id() {
            API_RX16 => XBeeInfo {
                api_id: API_RX16,
                address: be_u64(&head[rx16::SOURCE]),
                rssi: Some(head[rx16::RSSI]),
                options: head[rx16::OPTIONS],
            },
            API_TX16 => XBeeInfo {
                api_id: API_TX16,
                address: be_u64(&head[tx16::DEST]),
                rssi: None,
                options: head[tx16::OPTIONS],
            },
            other => return Err(RxError::UnknownApiId(other)),
        };
        let data = fd.get(rx16::DATA..).ok_or(RxError::BadLength)?;
        Frame::from_v2(packet.frame(), data, Extra::XBee(info))
    }
}

/// XBee 868 MHz modules in API mode 1.
///
/// Sends 0x10 (transmit request, 64-bit destination); receives 0x90 and 0x10
/// (cable loopback) as messages, and transmit statuses (0x8B, 0x89) as control frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct XBee868 {
    /// Frame id of sent frames ([`NO_FRAME_ID`]: the module sends no status).
    pub frame_id: u8,
    /// Options byte of sent frames.
    pub options: u8,
}

impl XBee868 {
    /// Most field bytes per frame we send: the PPRZ v2 limit (see the module doc).
    pub const MAX_PAYLOAD_LEN: usize = crate::pprz::V2_MAX_PAYLOAD_LEN;
    /// Largest `FRAME_DATA` accepted: 0x10 header (the longer one) + 256 RF bytes.
    pub const MAX_RX_LENGTH: usize = field::tx868::DATA + MAX_RF_PAYLOAD_868;

    /// Frame id 0 and options 0, as the reference firmware.
    pub const fn new() -> Self {
        Self {
            frame_id: NO_FRAME_ID,
            options: 0,
        }
    }

    /// The frame id of a transmit request (API id 0x10, as this encoder writes it), or
    /// `None` if `frame` does not start with a whole one. Bytes after the frame are
    /// allowed; the checksum is not verified.
    pub fn tx_frame_id(&self, frame: &[u8]) -> Option<u8> {
        use field::tx868;
        tx_frame_id(frame, API_TX_868, tx868::DATA, tx868::FRAME_ID)
    }

    /// Rewrites the frame id of the transmit request (0x10) at the start of `frame` to
    /// `id`, and its checksum (recomputed over the whole `FRAME_DATA`); `false` (and
    /// `frame` untouched) if `frame` does not start with a whole 0x10 frame. `id`
    /// [`NO_FRAME_ID`] asks the module for no status.
    pub fn set_tx_frame_id(&self, frame: &mut [u8], id: u8) -> bool {
        use field::tx868;
        set_tx_frame_id(frame, id, API_TX_868, tx868::DATA, tx868::FRAME_ID)
    }
}

impl Encoder for XBee868 {
    fn header_len(&self) -> usize {
        HEADER_LEN + field::tx868::DATA + MsgHeader::V2_LEN
    }

    fn tail_len(&self) -> usize {
        CHECKSUM_LEN
    }

    fn max_payload_len(&self) -> usize {
        Self::MAX_PAYLOAD_LEN
    }

    fn finish_frame(
        &self,
        meta: &TxMeta,
        frame: &mut [u8],
        payload_len: usize,
    ) -> Result<usize, EncodeError> {
        use field::tx868;
        let len = self.frame_len(payload_len)?;
        let dest = address64(meta.header.destination).to_be_bytes();
        finish(frame, len, &meta.header, tx868::DATA, |api| {
            api[tx868::API_ID] = API_TX_868;
            api[tx868::FRAME_ID] = self.frame_id;
            api[tx868::DEST64].copy_from_slice(&dest);
            api[tx868::DEST16].copy_from_slice(&[0xFF, 0xFE]);
            api[tx868::RADIUS] = 0;
            api[tx868::OPTIONS] = self.options;
        })
    }
}

impl Framing for XBee868 {
    fn start_byte(&self) -> u8 {
        START
    }

    fn max_rx_frame_len(&self) -> usize {
        Self::MAX_RX_LENGTH + OVERHEAD
    }

    fn rx_frame_len(&self, head: &[u8]) -> Result<Option<usize>, RxError> {
        rx_len(head, Self::MAX_RX_LENGTH)
    }

    fn verify(&self, frame: &[u8]) -> Result<(), RxError> {
        verify(frame, [API_RX_868, API_TX_868])
    }

    fn control(&self, frame: &[u8]) -> Option<Result<Control, RxError>> {
        control(frame)
    }

    fn has_control(&self) -> bool {
        true
    }

    fn view<'a>(&self, frame: &'a [u8]) -> Result<Frame<'a>, RxError> {
        use field::{rx868, tx868};
        let packet = Packet::new_checked(frame)?;
        let fd = packet.frame_data();
        let (info, data_start) = match packet.api_id() {
            API_RX_868 => {
                let head = fd.get(..rx868::DATA).ok_or(RxError::BadLength)?;
                let info = XBeeInfo {
                    api_id: API_RX_868,
                    address: be_u64(&head[rx868::SOURCE64]),
                    rssi: None,
                    options: head[rx868::OPTIONS],
                };
                (info, rx868::DATA)
            }
            API_TX_868 => {
                let head = fd.get(..tx868::DATA).ok_or(RxError::BadLength)?;
                let info = XBeeInfo {
                    api_id: API_TX_868,
                    address: be_u64(&head[tx868::DEST64]),
                    rssi: None,
                    options: head[tx868::OPTIONS],
                };
                (info, tx868::DATA)
            }
            other => return Err(RxError::UnknownApiId(other)),
        };
        let data = fd.get(data_start..).ok_or(RxError::BadLength)?;
        if data.len() > MAX_RF_PAYLOAD_868 {
            return Err(RxError::BadLength);
        }
        Frame::from_v2(packet.frame(), data, Extra::XBee(info))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ALIVE (class 1, id 2) from aircraft 7 to ground, fields 03 00 01 02, sent
    /// over 802.15.4 with TX16:
    ///   FRAME_DATA = 01 00 01 00 00 | 07 00 01 02 | 03 00 01 02   (13 bytes, LEN 0x000D)
    ///   dest = ground -> 0x0100
    ///   sum = 01+00+01+00+00+07+00+01+02+03+00+01+02 = 0x12, CK = 0xFF - 0x12 = 0xED
    static TX16_FRAME: [u8; 17] = [
        0x7E, 0x00, 0x0D, 0x01, 0x00, 0x01, 0x00, 0x00, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01,
        0x02, 0xED,
    ];

    /// The same message received by the ground module from source 0x0007, RSSI 40
    /// (-40 dBm = 0x28), options 0:
    ///   FRAME_DATA = 81 00 07 28 00 | 07 00 01 02 | 03 00 01 02
    ///   sum = 81+07+28+07+01+02+03+01+02 = 0xC0, CK = 0xFF - 0xC0 = 0x3F
    static RX16_FRAME: [u8; 17] = [
        0x7E, 0x00, 0x0D, 0x81, 0x00, 0x07, 0x28, 0x00, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01,
        0x02, 0x3F,
    ];

    /// The same message sent over 868 to ground (dest64 = 0x0000000000000100):
    ///   FRAME_DATA = 10 00 | 00 00 00 00 00 00 01 00 | FF FE | 00 | 00 | 07 00 01 02 | 03 00 01 02
    ///   LEN = 14 + 4 + 4 = 22 = 0x0016
    ///   sum = 10+01+FF+FE+07+01+02+03+01+02 = 0x21E -> 0x1E, CK = 0xFF - 0x1E = 0xE1
    static TX868_FRAME: [u8; 26] = [
        0x7E, 0x00, 0x16, 0x10, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0xFF, 0xFE,
        0x00, 0x00, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0xE1,
    ];

    /// Received over 868 from 0x0013A20040A1B2C3:
    ///   FRAME_DATA = 90 | 00 13 A2 00 40 A1 B2 C3 | FF FE | 01 | 07 00 01 02 | 03 00 01 02
    ///   LEN = 12 + 8 = 20 = 0x0014
    ///   sum = 90+13+A2+40+A1+B2+C3+FF+FE+01+07+01+02+03+01+02 = 0x5A9 -> 0xA9,
    ///   CK = 0xFF - 0xA9 = 0x56
    static RX868_FRAME: [u8; 24] = [
        0x7E, 0x00, 0x14, 0x90, 0x00, 0x13, 0xA2, 0x00, 0x40, 0xA1, 0xB2, 0xC3, 0xFF, 0xFE, 0x01,
        0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x56,
    ];

    static FIELDS: [u8; 4] = [0x03, 0x00, 0x01, 0x02];

    fn meta() -> TxMeta {
        TxMeta::new(MsgHeader::new(7, 0, 1, 2))
    }

    #[test]
    fn test_deconstruct() {
        let p = Packet::new_checked(&RX16_FRAME[..]).unwrap();
        assert_eq!(p.start(), 0x7E);
        assert_eq!(p.length(), 13);
        assert_eq!(p.frame_len(), 17);
        assert_eq!(p.api_id(), API_RX16);
        assert_eq!(p.frame_data(), &RX16_FRAME[3..16]);
        assert_eq!(p.checksum(), 0x3F);
        assert!(p.verify_checksum());
        let p = Packet::new_checked(&RX868_FRAME[..]).unwrap();
        assert_eq!(p.length(), 20);
        assert_eq!(p.api_id(), API_RX_868);
        assert!(p.verify_checksum());
    }

    #[test]
    fn test_construct() {
        let mut bytes = [0u8; 17];
        let mut p = Packet::new_unchecked(&mut bytes[..]);
        p.set_start(START);
        p.set_length(13);
        p.frame_data_mut().copy_from_slice(&RX16_FRAME[3..16]);
        p.fill_checksum();
        assert_eq!(bytes, RX16_FRAME);
    }

    #[test]
    fn test_emit() {
        let mut out = [0u8; 64];
        let n = XBee24::new().encode(&meta(), &FIELDS, &mut out).unwrap();
        assert_eq!(&out[..n], &TX16_FRAME);
        let n = XBee868::new().encode(&meta(), &FIELDS, &mut out).unwrap();
        assert_eq!(&out[..n], &TX868_FRAME);
    }

    #[test]
    fn test_parse() {
        let (f, n) = XBee24::new().parse(&RX16_FRAME).unwrap();
        assert_eq!(n, 17);
        assert_eq!(
            (f.source(), f.destination(), f.class(), f.msg_id()),
            (7, Some(0), 1, 2)
        );
        assert_eq!(f.payload(), &FIELDS);
        assert_eq!(f.rssi(), Some(0x28));
        assert_eq!(
            f.extra(),
            Extra::XBee(XBeeInfo {
                api_id: 0x81,
                address: 7,
                rssi: Some(0x28),
                options: 0
            })
        );
        // Loopback of our own TX16 frame.
        let (f, _) = XBee24::new().parse(&TX16_FRAME).unwrap();
        assert_eq!(f.payload(), &FIELDS);
        assert_eq!(f.rssi(), None);
        let (f, _) = XBee868::new().parse(&RX868_FRAME).unwrap();
        assert_eq!(
            (f.source(), f.destination(), f.class(), f.msg_id()),
            (7, Some(0), 1, 2)
        );
        assert_eq!(f.payload(), &FIELDS);
        match f.extra() {
            Extra::XBee(x) => {
                assert_eq!(x.address, 0x0013_A200_40A1_B2C3);
                assert_eq!(x.options, 1);
            }
            other => panic!("{other:?}"),
        }
        let (f, _) = XBee868::new().parse(&TX868_FRAME).unwrap();
        assert_eq!(f.payload(), &FIELDS);
    }

    #[test]
    fn wrong_radio_is_unknown_api() {
        // LEN 20 is within the 802.15.4 limit and the checksum is good: only the API
        // id is foreign.
        assert_eq!(
            XBee24::new().parse(&RX868_FRAME).unwrap_err(),
            RxError::UnknownApiId(0x90)
        );
        assert_eq!(
            XBee868::new().parse(&RX16_FRAME).unwrap_err(),
            RxError::UnknownApiId(0x81)
        );
    }

    /// 802.15.4 transmit status for frame id 0x47, no ACK (status 1):
    ///   FRAME_DATA = 89 47 01, sum = 0xD1, CK = 0xFF - 0xD1 = 0x2E
    static TX_STATUS_24: [u8; 7] = [0x7E, 0x00, 0x03, 0x89, 0x47, 0x01, 0x2E];

    /// 868 transmit status for frame id 0x47, success, route discovery:
    ///   FRAME_DATA = 8B 47 FF FE 00 00 02, sum = 8B+47+FF+FE+02 = 0x2D1 -> 0xD1,
    ///   CK = 0xFF - 0xD1 = 0x2E
    static TX_STATUS_868: [u8; 11] = [
        0x7E, 0x00, 0x07, 0x8B, 0x47, 0xFF, 0xFE, 0x00, 0x00, 0x02, 0x2E,
    ];

    /// 868 transmit status for frame id 0x47 after 2 retries, network ACK failure:
    ///   FRAME_DATA = 8B 47 FF FE 02 21 00, sum = 0x2CF + 02 + 21 = 0x2F2 -> 0xF2,
    ///   CK = 0xFF - 0xF2 = 0x0D
    static TX_STATUS_868_FAILED: [u8; 11] = [
        0x7E, 0x00, 0x07, 0x8B, 0x47, 0xFF, 0xFE, 0x02, 0x21, 0x00, 0x0D,
    ];

    fn tx_status(frame_id: u8, delivered: bool, status: u8, retries: u8) -> Control {
        Control::TxStatus(TxStatus {
            frame_id,
            delivered,
            status,
            retries,
        })
    }

    #[test]
    fn tx_status_emit() {
        let mut out = [0u8; 16];
        let n = encode_tx_status_24(0x47, status::NO_ACK, &mut out).unwrap();
        assert_eq!((&out[..n], n), (&TX_STATUS_24[..], TX_STATUS_FRAME_LEN));
        let n = encode_tx_status_868(0x47, 0, status::SUCCESS, status::DISCOVERY_ROUTE, &mut out)
            .unwrap();
        assert_eq!(
            (&out[..n], n),
            (&TX_STATUS_868[..], TX_STATUS_868_FRAME_LEN)
        );
        let n = encode_tx_status_868(
            0x47,
            2,
            status::NETWORK_ACK_FAILURE,
            status::DISCOVERY_NONE,
            &mut out,
        )
        .unwrap();
        assert_eq!(&out[..n], &TX_STATUS_868_FAILED);
        // Too small a buffer is a typed error and writes nothing.
        let mut small = [0u8; 10];
        assert_eq!(
            encode_tx_status_868(1, 0, 0, 0, &mut small),
            Err(EncodeError::BufferTooSmall {
                needed: 11,
                available: 10
            })
        );
        assert_eq!(small, [0; 10]);
        assert_eq!(
            encode_tx_status_24(1, 0, &mut small[..6]),
            Err(EncodeError::BufferTooSmall {
                needed: 7,
                available: 6
            })
        );
    }

    #[test]
    fn tx_status_parse() {
        let t24 = XBee24::new();
        let t868 = XBee868::new();
        // Both transports read both layouts.
        for t in [&t24 as &dyn Framing, &t868] {
            assert_eq!(
                t.control(&TX_STATUS_24),
                Some(Ok(tx_status(0x47, false, status::NO_ACK, 0)))
            );
            assert_eq!(
                t.control(&TX_STATUS_868),
                Some(Ok(tx_status(0x47, true, status::SUCCESS, 0)))
            );
            assert_eq!(
                t.control(&TX_STATUS_868_FAILED),
                Some(Ok(tx_status(0x47, false, status::NETWORK_ACK_FAILURE, 2)))
            );
            // Bytes after the frame: parse_control, like parse, ignores them.
            let mut longer = TX_STATUS_868.to_vec();
            longer.extend_from_slice(&RX16_FRAME);
            assert_eq!(
                t.parse_control(&longer),
                Some((tx_status(0x47, true, 0, 0), 11))
            );
            // Not messages.
            assert_eq!(
                t.parse(&TX_STATUS_24).unwrap_err(),
                RxError::UnknownApiId(API_TX_STATUS)
            );
            assert_eq!(
                t.parse(&TX_STATUS_868).unwrap_err(),
                RxError::UnknownApiId(API_TX_STATUS_868)
            );
            // Messages are not control frames.
            for frame in [&RX16_FRAME[..], &TX16_FRAME, &RX868_FRAME, &TX868_FRAME] {
                assert_eq!(t.control(frame), None);
                assert_eq!(t.parse_control(frame), None);
            }
            // Too short to have an API id: not a control frame either.
            for short in [&[][..], &[0x7E], &[0x7E, 0x00], &[0x7E, 0x00, 0x03]] {
                assert_eq!(t.control(short), None);
                assert_eq!(t.parse_control(short), None);
            }
        }
        // PPRZ has no control frames, even on the same bytes.
        assert_eq!(crate::PprzV2::new().control(&TX_STATUS_24), None);
        assert_eq!(crate::PprzV2::new().parse_control(&TX_STATUS_24), None);
    }

    #[test]
    fn tx_status_malformed() {
        let t = XBee24::new();
        // Bad checksum.
        let mut bad = TX_STATUS_24;
        bad[6] ^= 0x01;
        assert_eq!(t.control(&bad), Some(Err(RxError::Checksum)));
        assert_eq!(t.parse_control(&bad), None);
        let mut bad = TX_STATUS_868;
        bad[8] ^= 0x40;
        assert_eq!(t.control(&bad), Some(Err(RxError::Checksum)));
        // Wrong length for the API id, good checksum: 0x89 with 4 bytes, 0x8B with 3
        // and with 8.
        let mut out = [0u8; 16];
        for data in [
            &[API_TX_STATUS, 0x47, 0x00, 0x00][..],
            &[API_TX_STATUS, 0x47][..],
            &[API_TX_STATUS_868, 0x47, 0x00][..],
            &[API_TX_STATUS_868, 0x47, 0xFF, 0xFE, 0, 0, 0, 0][..],
        ] {
            let n = data.len() + OVERHEAD;
            let mut p = Packet::new_unchecked(&mut out[..n]);
            p.set_start(START);
            p.set_length(data.len() as u16);
            p.frame_data_mut().copy_from_slice(data);
            p.fill_checksum();
            assert_eq!(
                t.control(&out[..n]),
                Some(Err(RxError::BadLength)),
                "{data:02x?}"
            );
            assert_eq!(t.parse_control(&out[..n]), None);
        }
        // Truncated, or bytes past the announced length (`control` takes exactly one
        // frame), or a bad start byte.
        assert_eq!(t.control(&TX_STATUS_24[..6]), Some(Err(RxError::Truncated)));
        let mut longer = TX_STATUS_24.to_vec();
        longer.push(0);
        assert_eq!(t.control(&longer), Some(Err(RxError::BadLength)));
        let mut bad = TX_STATUS_24;
        bad[0] = 0x7D;
        assert_eq!(t.control(&bad), Some(Err(RxError::BadStart)));
        assert_eq!(t.parse_control(&bad), None);
        // LEN 0 with the API id byte present.
        assert_eq!(
            t.control(&[0x7E, 0x00, 0x00, API_TX_STATUS]),
            Some(Err(RxError::BadLength))
        );
    }

    #[test]
    fn frame_id_rewrite() {
        let (t24, t868) = (XBee24::new(), XBee868::new());
        let mut f24 = TX16_FRAME;
        let mut f868 = TX868_FRAME;
        assert_eq!(t24.tx_frame_id(&f24), Some(NO_FRAME_ID));
        assert_eq!(t868.tx_frame_id(&f868), Some(NO_FRAME_ID));
        for id in 0..=255u8 {
            assert!(t24.set_tx_frame_id(&mut f24, id));
            assert!(t868.set_tx_frame_id(&mut f868, id));
            assert_eq!(t24.tx_frame_id(&f24), Some(id));
            assert_eq!(t868.tx_frame_id(&f868), Some(id));
            assert_eq!(f24[3 + field::tx16::FRAME_ID], id);
            assert_eq!(f868[3 + field::tx868::FRAME_ID], id);
            // Checksum rewritten: the frame still parses (loopback) to the same message.
            let (f, _) = t24.parse(&f24).unwrap();
            assert_eq!((f.source(), f.payload()), (7, &FIELDS[..]));
            let (f, _) = t868.parse(&f868).unwrap();
            assert_eq!((f.source(), f.payload()), (7, &FIELDS[..]));
            // Only the frame id and the checksum changed.
            assert_eq!(f24[..4], TX16_FRAME[..4]);
            assert_eq!(f24[5..16], TX16_FRAME[5..16]);
            assert_eq!(f868[5..25], TX868_FRAME[5..25]);
        }
        // The encoder's own frame id is read back.
        let mut out = [0u8; 64];
        let n = XBee24 {
            frame_id: 9,
            options: 1,
        }
        .encode(&meta(), &FIELDS, &mut out)
        .unwrap();
        assert_eq!(t24.tx_frame_id(&out[..n]), Some(9));
        // Bytes after the frame are allowed (and left alone).
        out[n] = 0xAA;
        assert!(t24.set_tx_frame_id(&mut out, 10));
        assert_eq!((t24.tx_frame_id(&out), out[n]), (Some(10), 0xAA));
        assert!(t24.parse(&out).is_ok());
        // Not a transmit request of this radio, or not whole: None, false, untouched.
        for (frame, len) in [
            (&RX16_FRAME[..], 17),
            (&TX868_FRAME[..], 26),
            (&TX16_FRAME[..16], 16),
            (&TX_STATUS_24[..], 7),
            (&[][..], 0),
        ] {
            let mut copy = [0u8; 32];
            copy[..len].copy_from_slice(frame);
            assert_eq!(t24.tx_frame_id(&copy[..len]), None);
            assert!(!t24.set_tx_frame_id(&mut copy[..len], 5));
            assert_eq!(&copy[..len], frame);
        }
        for (frame, len) in [
            (&RX868_FRAME[..], 24),
            (&TX16_FRAME[..], 17),
            (&TX868_FRAME[..25], 25),
        ] {
            let mut copy = [0u8; 32];
            copy[..len].copy_from_slice(frame);
            assert_eq!(t868.tx_frame_id(&copy[..len]), None);
            assert!(!t868.set_tx_frame_id(&mut copy[..len], 5));
            assert_eq!(&copy[..len], frame);
        }
        // A 0x01 frame too short for the TX16 header (LEN 2: API id and frame id only).
        let mut short = [0x7E, 0x00, 0x02, API_TX16, 0x00, 0xFE];
        assert_eq!(t24.tx_frame_id(&short), None);
        assert!(!t24.set_tx_frame_id(&mut short, 1));
    }

    #[test]
    fn addresses() {
        assert_eq!(address16(0), 0x0100);
        assert_eq!(address16(0xFF), 0xFFFF);
        assert_eq!(address16(42), 42);
        assert_eq!(address64(0xFF), 0xFFFF);
    }

    #[test]
    fn limits() {
        assert_eq!(XBee24::MAX_PAYLOAD_LEN, 96);
        assert_eq!(XBee24::new().max_frame_len(), 12 + 96 + 1);
        assert_eq!(XBee868::new().max_frame_len(), 21 + 247 + 1);
        assert_eq!(XBee868::new().max_rx_frame_len(), 274);
    }
}
