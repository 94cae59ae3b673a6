//! The XBee modem model: its configuration, the API parser, the frames it holds and
//! their transmission, retries and statuses.

use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::Duration;
use pprz_transports::xbee as api;

use super::dir::Dir;
use super::link::{Direction, SimLink};
use super::xbee;

/// The XBee module family, which sets the API frame layouts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum XBeeVariant {
    /// 802.15.4 ("Series 1", 2.4 GHz): TX16 (0x01), RX16 (0x81), status 0x89; RF
    /// payload up to 100 bytes.
    #[default]
    XBee24,
    /// 868 MHz: transmit request 0x10, receive packet 0x90, status 0x8B; RF payload up
    /// to 256 bytes.
    XBee868,
}

impl XBeeVariant {
    /// The largest RF payload of a frame.
    pub const fn max_rf_payload(self) -> usize {
        match self {
            Self::XBee24 => api::MAX_RF_PAYLOAD_24,
            Self::XBee868 => api::MAX_RF_PAYLOAD_868,
        }
    }

    /// Length of the transmit request's `FRAME_DATA` before the RF data.
    pub(super) const fn tx_header(self) -> usize {
        match self {
            Self::XBee24 => api::field::tx16::DATA,
            Self::XBee868 => api::field::tx868::DATA,
        }
    }

    /// Length of the receive packet's `FRAME_DATA` before the RF data.
    pub(super) const fn rx_header(self) -> usize {
        match self {
            Self::XBee24 => api::field::rx16::DATA,
            Self::XBee868 => api::field::rx868::DATA,
        }
    }

    /// The largest transmit request, framing included (109 bytes for 802.15.4, 274
    /// for 868).
    pub const fn max_api_frame(self) -> usize {
        self.tx_header() + self.max_rf_payload() + xbee::FRAMING
    }
}

/// An XBee module in API mode; see the [module docs](super#xbee-api-modem).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct XBeeModem {
    /// The module family.
    pub variant: XBeeVariant,
    /// Time from the end of a transmission to its acknowledgement (or to giving up on
    /// it); the modem sends nothing meanwhile. Statuses are written at its end.
    pub ack_delay: Duration,
    /// Probability that a transmission is not acknowledged (lost), 0 to 1.
    pub failure_rate: f64,
    /// Retries after a transmission that was not acknowledged.
    pub retries: u8,
    /// Bytes that each transmission adds on the air to the RF data.
    pub air_overhead: u16,
    /// Address of endpoint A's module, the source of the frames B receives (802.15.4:
    /// the low 16 bits, `MY`; 868: the 64-bit serial number).
    pub address_a: u64,
    /// Address of endpoint B's module, the source of the frames A receives.
    pub address_b: u64,
    /// The RSSI byte of 802.15.4 RX frames (minus dBm: 40 is -40 dBm).
    pub rssi: u8,
    /// B writes API frames too (otherwise plain bytes, delivered unchanged).
    pub api_uplink: bool,
    /// Answer a frame dropped because the modem is full with a status (802.15.4 3
    /// "purged", 868 0x32 "no free buffers"), if its frame id is not 0.
    pub purge_status: bool,
}

impl XBeeModem {
    /// A module of `variant`: 1 ms ACK delay, no failures, 3 retries, no air overhead,
    /// address A 0x0001, address B 0x0100 (the ground's, in Paparazzi), RSSI 40, a
    /// plain uplink, no purge status.
    pub const fn new(variant: XBeeVariant) -> Self {
        Self {
            variant,
            ack_delay: Duration::from_millis(1),
            failure_rate: 0.0,
            retries: 3,
            air_overhead: 0,
            address_a: 0x0001,
            address_b: 0x0100,
            rssi: 40,
            api_uplink: false,
            purge_status: false,
        }
    }

    /// Sets [`ack_delay`](Self::ack_delay).
    pub const fn ack_delay(mut self, delay: Duration) -> Self {
        self.ack_delay = delay;
        self
    }

    /// Sets [`failure_rate`](Self::failure_rate).
    pub const fn failure_rate(mut self, probability: f64) -> Self {
        self.failure_rate = probability;
        self
    }

    /// Sets [`retries`](Self::retries).
    pub const fn retries(mut self, retries: u8) -> Self {
        self.retries = retries;
        self
    }

    /// Sets [`air_overhead`](Self::air_overhead).
    pub const fn air_overhead(mut self, bytes: u16) -> Self {
        self.air_overhead = bytes;
        self
    }

    /// Sets [`address_a`](Self::address_a) and [`address_b`](Self::address_b).
    pub const fn addresses(mut self, a: u64, b: u64) -> Self {
        self.address_a = a;
        self.address_b = b;
        self
    }

    /// Sets [`rssi`](Self::rssi).
    pub const fn rssi(mut self, rssi: u8) -> Self {
        self.rssi = rssi;
        self
    }

    /// Sets [`api_uplink`](Self::api_uplink).
    pub const fn api_uplink(mut self, on: bool) -> Self {
        self.api_uplink = on;
        self
    }

    /// Sets [`purge_status`](Self::purge_status).
    pub const fn purge_status(mut self, on: bool) -> Self {
        self.purge_status = on;
        self
    }
}

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

    pub(super) fn period(&self, ack_wait: u128) -> u128 {
        self.air + if self.acked { ack_wait } else { 0 }
    }

    pub(super) fn end(&self, ack_wait: u128) -> u128 {
        self.start + u128::from(self.attempts) * self.period(ack_wait)
    }

    /// Air time after `now`.
    pub(super) fn air_after(&self, now: u128, ack_wait: u128) -> u128 {
        let period = self.period(ack_wait);
        (0..u128::from(self.attempts))
            .map(|i| {
                let from = self.start + i * period;
                (from + self.air).saturating_sub(from.max(now))
            })
            .sum()
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

impl<M: RawMutex, const N: usize> SimLink<M, N> {
    /// A byte enters the XBee modem's API parser at `at`.
    pub(super) fn api_byte(
        &self,
        direction: Direction,
        d: &mut Dir<N>,
        x: &XBeeModem,
        byte: u8,
        at: u128,
    ) {
        let p = &mut d.parser;
        if p.state != Parse::Idle {
            p.bytes += 1;
        }
        match p.state {
            Parse::Idle => {
                if byte == xbee::START {
                    p.state = Parse::LengthHigh;
                    p.bytes = 1;
                } else {
                    d.stats.discarded_bytes = d.stats.discarded_bytes.wrapping_add(1);
                }
            }
            Parse::LengthHigh => {
                p.length = usize::from(byte) << 8;
                p.state = Parse::LengthLow;
            }
            Parse::LengthLow => {
                p.length |= usize::from(byte);
                p.got = 0;
                if p.length == 0 || p.length > MAX_FRAME_DATA {
                    let bytes = p.bytes;
                    p.state = Parse::Idle;
                    d.malformed(bytes);
                } else {
                    p.state = Parse::Data;
                }
            }
            Parse::Data => {
                p.data[p.got] = byte;
                p.got += 1;
                if p.got == p.length {
                    p.state = Parse::Checksum;
                }
            }
            Parse::Checksum => {
                let request = p.request(x.variant, byte);
                let bytes = p.bytes;
                p.state = Parse::Idle;
                match request {
                    Some(req) => self.send_frame(direction, d, x, req, bytes, at),
                    None => d.malformed(bytes),
                }
            }
        }
    }

    /// The modem has no room for a frame of `bytes` API bytes complete at `at`: it is
    /// dropped whole, and answered with a status if the modem says so.
    fn drop_frame(
        &self,
        direction: Direction,
        d: &mut Dir<N>,
        x: &XBeeModem,
        frame_id: u8,
        bytes: u32,
        at: u128,
    ) {
        d.stats.frames_dropped = d.stats.frames_dropped.wrapping_add(1);
        d.stats.dropped_bytes = d.stats.dropped_bytes.wrapping_add(bytes);
        if x.purge_status && frame_id != 0 {
            let status = match x.variant {
                XBeeVariant::XBee24 => xbee::STATUS_PURGED,
                XBeeVariant::XBee868 => xbee::DELIVERY_NO_BUFFERS,
            };
            let due = self.timing.ticks_ceil(at);
            self.status(direction, d, x, frame_id, 0, status, due);
        }
    }

    /// A valid transmit request of `bytes` API bytes is complete at `at`.
    pub(super) fn send_frame(
        &self,
        direction: Direction,
        d: &mut Dir<N>,
        x: &XBeeModem,
        req: TxRequest,
        bytes: u32,
        at: u128,
    ) {
        let t = &self.timing;
        d.prune(at, t.ack_wait);
        let occupied: u128 = d.frames_iter().map(|f| u128::from(f.weight)).sum();
        if occupied + u128::from(bytes) > self.buffer(Some(x)) || d.frames_len == MODEM_FRAMES {
            self.drop_frame(direction, d, x, req.frame_id, bytes, at);
            return;
        }
        let rf_len = d.parser.length - req.rf_start;
        // Transmit, retrying until acknowledged.
        let air_bytes = rf_len + usize::from(x.air_overhead);
        let max_attempts = if req.acked {
            u16::from(x.retries) + 1
        } else {
            1
        };
        let mut attempts = 0;
        let mut received = false;
        while attempts < max_attempts && !received {
            attempts += 1;
            received = d.attempt(air_bytes, t);
        }
        let frame = InModem {
            start: d.tx_end.max(at),
            air: air_bytes as u128 * t.air_byte,
            attempts,
            acked: req.acked,
            weight: bytes as u16,
        };
        let end = frame.end(t.ack_wait);
        d.tx_end = end;
        d.air_total += u128::from(attempts) * frame.air;
        d.frames[(d.frames_head + d.frames_len) % MODEM_FRAMES] = frame;
        d.frames_len += 1;
        let s = &mut d.stats;
        s.frames_sent = s.frames_sent.wrapping_add(1);
        s.failed_attempts = s
            .failed_attempts
            .wrapping_add(u32::from(attempts - u16::from(received)));
        let mut stored = true;
        if received {
            let last = frame.start + u128::from(attempts - 1) * frame.period(t.ack_wait);
            let due = t.ticks_ceil(last + frame.air).saturating_add(t.latency);
            let source = match direction {
                Direction::AToB => x.address_a,
                Direction::BToA => x.address_b,
            };
            let mut rx = [0u8; MAX_RX_FRAME];
            let n = rx_frame(x, source, &req, &d.parser.data[..d.parser.length], &mut rx);
            stored = d.insert(&rx[..n], due);
        } else {
            s.frames_lost = s.frames_lost.wrapping_add(1);
        }
        let s = &mut d.stats;
        if stored {
            s.bytes_sent = s.bytes_sent.wrapping_add(bytes);
        } else {
            // Received over the air (and acknowledged), lost at the receiver's UART.
            s.frames_overrun = s.frames_overrun.wrapping_add(1);
            s.overrun_bytes = s.overrun_bytes.wrapping_add(bytes);
        }
        if req.frame_id != 0 {
            let status = match (received || !req.acked, x.variant) {
                (true, _) => xbee::STATUS_SUCCESS,
                (false, XBeeVariant::XBee24) => xbee::STATUS_NO_ACK,
                (false, XBeeVariant::XBee868) => xbee::DELIVERY_NO_ACK,
            };
            let retries = u8::try_from(attempts - 1).unwrap_or(u8::MAX);
            self.status(
                direction,
                d,
                x,
                req.frame_id,
                retries,
                status,
                t.ticks_ceil(end),
            );
        }
    }

    /// Queues a transmit status for the writer of `direction` (its own reader, on the
    /// other direction's ring), readable at `due`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn status(
        &self,
        direction: Direction,
        d: &mut Dir<N>,
        x: &XBeeModem,
        frame_id: u8,
        retries: u8,
        status: u8,
        due: u64,
    ) {
        let mut frame = [0u8; api::TX_STATUS_868_FRAME_LEN];
        let encoded = match x.variant {
            XBeeVariant::XBee24 => api::encode_tx_status_24(frame_id, status, &mut frame),
            XBeeVariant::XBee868 => api::encode_tx_status_868(
                frame_id,
                retries,
                status,
                xbee::DISCOVERY_NONE,
                &mut frame,
            ),
        };
        // The buffer holds the larger of the two frames.
        let Ok(n) = encoded else { return };
        let stored = self.with(direction.other(), |o| {
            let stored = o.insert(&frame[..n], due);
            if stored {
                o.rx_waker.wake();
            }
            stored
        });
        let s = &mut d.stats;
        if stored {
            s.statuses = s.statuses.wrapping_add(1);
        } else {
            s.statuses_lost = s.statuses_lost.wrapping_add(1);
        }
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
