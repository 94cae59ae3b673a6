//! The XBee modem's state: its API parser, the frames it holds, the RX frames it
//! delivers.

use pprz_transports::xbee as api;

use super::xbee;
use super::{XBeeModem, XBeeVariant};

/// Largest `FRAME_DATA` of a transmit request (868: 14-byte header + 256 bytes).
pub(super) const MAX_FRAME_DATA: usize = XBeeVariant::XBee868.tx_header() + api::MAX_RF_PAYLOAD_868;
/// Largest RX frame, framing included (868: 12-byte header + 256 bytes).
pub(super) const MAX_RX_FRAME: usize = rx_frame_len(XBeeVariant::XBee868, api::MAX_RF_PAYLOAD_868);
/// Frames the XBee modem holds.
pub(super) const MODEM_FRAMES: usize = 16;

/// A frame in the XBee modem, from its acceptance to the end of its last attempt (and
/// ACK wait).
#[derive(Clone, Copy, Debug)]
pub(super) struct InModem {
    /// Start of the first attempt.
    pub(super) start: u128,
    /// Air time of one attempt.
    pub(super) air: u128,
    pub(super) attempts: u16,
    /// The modem waits for an acknowledgement after each attempt.
    pub(super) acked: bool,
    /// API bytes it occupies in the buffer.
    pub(super) weight: u16,
}

impl InModem {
    pub(super) const EMPTY: Self = Self {
        start: 0,
        air: 0,
        attempts: 0,
        acked: false,
        weight: 0,
    };

    // Saturating: an ACK delay of `Duration::MAX` ("never") at high rates is near the
    // top of `u128`; such a frame then ends at the end of time.
    pub(super) fn period(&self, ack_wait: u128) -> u128 {
        self.air
            .saturating_add(if self.acked { ack_wait } else { 0 })
    }

    pub(super) fn end(&self, ack_wait: u128) -> u128 {
        self.start
            .saturating_add(u128::from(self.attempts).saturating_mul(self.period(ack_wait)))
    }

    /// Air time after `now`.
    pub(super) fn air_after(&self, now: u128, ack_wait: u128) -> u128 {
        let period = self.period(ack_wait);
        (0..u128::from(self.attempts))
            .map(|i| {
                let from = self.start.saturating_add(i.saturating_mul(period));
                from.saturating_add(self.air).saturating_sub(from.max(now))
            })
            .fold(0, u128::saturating_add)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Parse {
    /// Looking for the start delimiter.
    Idle,
    LengthHigh,
    LengthLow,
    Data,
    Checksum,
}

/// The XBee modem's API parser.
pub(super) struct Parser {
    pub(super) state: Parse,
    /// `FRAME_DATA` length announced.
    pub(super) length: usize,
    /// `FRAME_DATA` bytes received.
    pub(super) got: usize,
    /// API bytes of the current frame received so far.
    pub(super) bytes: u32,
    pub(super) data: [u8; MAX_FRAME_DATA],
}

/// A valid transmit request in the parser.
#[derive(Clone, Copy, Debug)]
pub(super) struct TxRequest {
    pub(super) frame_id: u8,
    pub(super) broadcast: bool,
    pub(super) acked: bool,
    /// RF data: `data[rf_start..]`.
    pub(super) rf_start: usize,
}

impl Parser {
    pub(super) const fn new() -> Self {
        Self {
            state: Parse::Idle,
            length: 0,
            got: 0,
            bytes: 0,
            data: [0; MAX_FRAME_DATA],
        }
    }

    /// API bytes of a frame being received.
    pub(super) fn in_progress(&self) -> u32 {
        if self.state == Parse::Idle {
            0
        } else {
            self.bytes
        }
    }

    /// The transmit request completed by `checksum`, if it is one and valid.
    pub(super) fn request(&self, variant: XBeeVariant, checksum: u8) -> Option<TxRequest> {
        let data = &self.data[..self.length];
        if self.state != Parse::Checksum || xbee::checksum(data) != checksum {
            return None;
        }
        let header = variant.tx_header();
        if data.len() < header || data.len() - header > variant.max_rf_payload() {
            return None;
        }
        let (broadcast, options) = match variant {
            XBeeVariant::XBee24 if data[0] == xbee::API_TX16 => {
                let mut dest = [0u8; 2];
                dest.copy_from_slice(&data[api::field::tx16::DEST]);
                let broadcast = u16::from_be_bytes(dest) == xbee::BROADCAST_16;
                (broadcast, data[api::field::tx16::OPTIONS])
            }
            XBeeVariant::XBee868 if data[0] == xbee::API_TX_868 => {
                let mut dest = [0u8; 8];
                dest.copy_from_slice(&data[api::field::tx868::DEST64]);
                let broadcast = u64::from_be_bytes(dest) == xbee::BROADCAST_64;
                (broadcast, data[api::field::tx868::OPTIONS])
            }
            _ => return None,
        };
        // The frame id is at the same offset in both requests.
        Some(TxRequest {
            frame_id: data[api::field::tx16::FRAME_ID],
            broadcast,
            acked: !broadcast && options & xbee::OPTION_DISABLE_ACK == 0,
            rf_start: header,
        })
    }
}

/// Length of the RX frame carrying `rf_len` bytes of RF data.
pub(super) const fn rx_frame_len(variant: XBeeVariant, rf_len: usize) -> usize {
    variant.rx_header() + rf_len + xbee::FRAMING
}

/// Writes the RX frame of `req` (whose `FRAME_DATA` is `data`) to `out`; returns its
/// length.
pub(super) fn rx_frame(
    x: &XBeeModem,
    source: u64,
    req: &TxRequest,
    data: &[u8],
    out: &mut [u8; MAX_RX_FRAME],
) -> usize {
    let rf = &data[req.rf_start..];
    let header = x.variant.rx_header();
    let fd = &mut out[api::HEADER_LEN..];
    match x.variant {
        XBeeVariant::XBee24 => {
            use api::field::rx16;
            fd[rx16::API_ID] = xbee::API_RX16;
            fd[rx16::SOURCE].copy_from_slice(&(source as u16).to_be_bytes());
            fd[rx16::RSSI] = x.rssi;
            fd[rx16::OPTIONS] = if req.broadcast {
                xbee::RX_OPTION_BROADCAST
            } else {
                0
            };
        }
        XBeeVariant::XBee868 => {
            use api::field::rx868;
            fd[rx868::API_ID] = xbee::API_RX_868;
            fd[rx868::SOURCE64].copy_from_slice(&source.to_be_bytes());
            fd[rx868::SOURCE16].copy_from_slice(&[0xFF, 0xFE]);
            fd[rx868::OPTIONS] = if req.broadcast {
                xbee::RX_OPTION_BROADCAST
            } else if req.acked {
                xbee::RX_OPTION_ACKED
            } else {
                0
            };
        }
    }
    fd[header..header + rf.len()].copy_from_slice(rf);
    xbee::frame_in_place(out, header + rf.len())
}
