#![doc = include_str!("../README.md")]
#![no_std]
#![deny(unsafe_code)]

pub mod any;
pub mod checksum;
pub mod decoder;
pub mod io;
pub mod pprz;
pub mod pprzlog;
pub mod transport;
pub mod xbee;

pub use any::AnyTransport;
pub use decoder::{Decoder, DecoderStats, TX_STATUS_CAPACITY};
pub use io::{WriteFrameError, write_frame};
pub use pprz::{PprzV1, PprzV2};
pub use pprzlog::PprzLog;
pub use transport::{
    BROADCAST_ID, COMPONENT_BROADCAST, Control, EncodeError, Encoder, Extra, Frame, Framing,
    GROUND_ID, LogInfo, MsgHeader, RxError, TxMeta, TxStatus, XBeeInfo,
};
pub use xbee::{XBee24, XBee868};

/// Longest frame of any transport in this crate, sent or received (an XBee 868
/// loopback frame with a full 256-byte RF payload). A buffer of this size holds any
/// frame; it is the default decoder buffer size.
pub const MAX_FRAME_LEN: usize = xbee::XBee868::MAX_RX_LENGTH + xbee::OVERHEAD;

/// PPRZ v2 decoder with a buffer for the longest frame.
pub type PprzV2Decoder = Decoder<PprzV2, { pprz::MAX_FRAME_LEN }>;
/// PPRZ v1 decoder with a buffer for the longest frame.
pub type PprzV1Decoder = Decoder<PprzV1, { pprz::MAX_FRAME_LEN }>;
/// XBee 802.15.4 decoder with a buffer for the longest frame.
pub type XBee24Decoder = Decoder<XBee24, { XBee24::MAX_RX_LENGTH + xbee::OVERHEAD }>;
/// XBee 868 decoder with a buffer for the longest frame.
pub type XBee868Decoder = Decoder<XBee868, { XBee868::MAX_RX_LENGTH + xbee::OVERHEAD }>;
/// PPRZLOG decoder with a buffer for the longest record.
pub type PprzLogDecoder = Decoder<PprzLog, { pprzlog::MAX_FRAME_LEN }>;

const _: () = {
    assert!(pprz::MAX_FRAME_LEN <= MAX_FRAME_LEN);
    assert!(pprzlog::MAX_FRAME_LEN <= MAX_FRAME_LEN);
    assert!(XBee24::MAX_RX_LENGTH + xbee::OVERHEAD <= MAX_FRAME_LEN);
    // Largest TX frame: 868 header (3 + 14 + 4) + 247 fields + checksum.
    let xbee868_tx_max = xbee::HEADER_LEN
        + xbee::field::tx868::DATA
        + MsgHeader::V2_LEN
        + XBee868::MAX_PAYLOAD_LEN
        + xbee::CHECKSUM_LEN;
    assert!(xbee868_tx_max <= MAX_FRAME_LEN);
};
