//! The XBee modem at work on one direction: a byte into its API parser, a frame
//! transmitted (with retries) and delivered, the transmit status for the writer.

use pprz_transports::xbee as api;

use super::dir::Dir;
use super::modem::{
    InModem, MAX_FRAME_DATA, MAX_RX_FRAME, MODEM_FRAMES, Parse, TxRequest, rx_frame,
};
use super::timing::Timing;
use super::xbee;
use super::{XBeeModem, XBeeVariant};

/// What the XBee modem of one direction works with.
pub(super) struct Modem<'a> {
    pub(super) x: &'a XBeeModem,
    pub(super) timing: &'a Timing,
    /// The modem buffer, in bytes.
    pub(super) buffer: u128,
    /// The address of this direction's module: the source of the frames it delivers.
    pub(super) source: u64,
}

/// A transmit status for the writer of a direction, readable on its reader's ring at
/// `due`.
pub(super) struct Status {
    frame: [u8; api::TX_STATUS_868_FRAME_LEN],
    len: usize,
    pub(super) due: u64,
}

impl Status {
    /// The status frame of `x`'s variant, or `None` if it cannot be encoded.
    fn new(x: &XBeeModem, frame_id: u8, retries: u8, status: u8, due: u64) -> Option<Self> {
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
        let len = encoded.ok()?;
        Some(Self { frame, len, due })
    }

    /// The frame's bytes.
    pub(super) fn bytes(&self) -> &[u8] {
        &self.frame[..self.len]
    }
}

impl<const N: usize> Dir<N> {
    /// A byte enters the XBee modem's API parser at `at`. Returns the transmit status
    /// to queue for the writer, if any.
    pub(super) fn api_byte(&mut self, m: &Modem<'_>, byte: u8, at: u128) -> Option<Status> {
        let p = &mut self.parser;
        if p.state != Parse::Idle {
            p.bytes += 1;
        }
        match p.state {
            Parse::Idle => {
                if byte == xbee::START {
                    p.state = Parse::LengthHigh;
                    p.bytes = 1;
                } else {
                    self.stats.discarded_bytes = self.stats.discarded_bytes.wrapping_add(1);
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
                    self.malformed(bytes);
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
                let request = p.request(m.x.variant, byte);
                let bytes = p.bytes;
                p.state = Parse::Idle;
                match request {
                    Some(req) => return self.send_frame(m, req, bytes, at),
                    None => self.malformed(bytes),
                }
            }
        }
        None
    }

    /// The modem has no room for a frame of `bytes` API bytes complete at `at`: it is
    /// dropped whole, and answered with a status if the modem says so.
    fn drop_frame(&mut self, m: &Modem<'_>, frame_id: u8, bytes: u32, at: u128) -> Option<Status> {
        self.stats.frames_dropped = self.stats.frames_dropped.wrapping_add(1);
        self.stats.dropped_bytes = self.stats.dropped_bytes.wrapping_add(bytes);
        if !m.x.purge_status || frame_id == 0 {
            return None;
        }
        let status = match m.x.variant {
            XBeeVariant::XBee24 => xbee::STATUS_PURGED,
            XBeeVariant::XBee868 => xbee::DELIVERY_NO_BUFFERS,
        };
        Status::new(m.x, frame_id, 0, status, m.timing.ticks_ceil(at))
    }

    /// A valid transmit request of `bytes` API bytes is complete at `at`: the modem
    /// takes it (or drops it), transmits it until acknowledged and delivers it. Returns
    /// its transmit status, if it has a frame id.
    fn send_frame(
        &mut self,
        m: &Modem<'_>,
        req: TxRequest,
        bytes: u32,
        at: u128,
    ) -> Option<Status> {
        let (t, x) = (m.timing, m.x);
        self.prune(at, t.ack_wait);
        let occupied: u128 = self.frames_iter().map(|f| u128::from(f.weight)).sum();
        if occupied + u128::from(bytes) > m.buffer || self.frames_len == MODEM_FRAMES {
            return self.drop_frame(m, req.frame_id, bytes, at);
        }
        let rf_len = self.parser.length - req.rf_start;
        // Transmit, retrying until acknowledged.
        let air_bytes = rf_len + usize::from(x.air_overhead);
        let max_attempts = if req.acked {
            u16::from(x.retries) + 1
        } else {
            1
        };
        let mut frame = InModem {
            start: self.tx_end.max(at),
            air: air_bytes as u128 * t.air_byte,
            attempts: 0,
            acked: req.acked,
            weight: bytes as u16,
        };
        let period = frame.period(t.ack_wait);
        let mut received = false;
        while frame.attempts < max_attempts && !received {
            let ends = frame
                .start
                .saturating_add(u128::from(frame.attempts).saturating_mul(period))
                .saturating_add(frame.air);
            frame.attempts += 1;
            received = self.attempt(air_bytes, t);
            if self.outages.cover(ends, t.scale) {
                received = false;
                self.stats.outage_attempts = self.stats.outage_attempts.wrapping_add(1);
            }
        }
        let attempts = frame.attempts;
        let end = frame.end(t.ack_wait);
        self.tx_end = end;
        self.air_total = self
            .air_total
            .saturating_add(u128::from(attempts).saturating_mul(frame.air));
        self.frames[(self.frames_head + self.frames_len) % MODEM_FRAMES] = frame;
        self.frames_len += 1;
        let s = &mut self.stats;
        s.frames_sent = s.frames_sent.wrapping_add(1);
        s.failed_attempts = s
            .failed_attempts
            .wrapping_add(u32::from(attempts - u16::from(received)));
        if received {
            self.deliver(m, &req, &frame, bytes);
        } else {
            s.frames_lost = s.frames_lost.wrapping_add(1);
            s.bytes_sent = s.bytes_sent.wrapping_add(bytes);
        }
        if req.frame_id == 0 {
            return None;
        }
        let status = match (received || !req.acked, x.variant) {
            (true, _) => xbee::STATUS_SUCCESS,
            (false, XBeeVariant::XBee24) => xbee::STATUS_NO_ACK,
            (false, XBeeVariant::XBee868) => xbee::DELIVERY_NO_ACK,
        };
        let retries = u8::try_from(attempts - 1).unwrap_or(u8::MAX);
        Status::new(x, req.frame_id, retries, status, t.ticks_ceil(end))
    }

    /// `frame`, the transmission of `req` (`bytes` API bytes), was received on its last
    /// attempt: its RX frame goes to the receiver's ring, or is lost if the ring is full.
    fn deliver(&mut self, m: &Modem<'_>, req: &TxRequest, frame: &InModem, bytes: u32) {
        let t = m.timing;
        let last = frame.start + u128::from(frame.attempts - 1) * frame.period(t.ack_wait);
        let due = t.ticks_ceil(last + frame.air).saturating_add(t.latency);
        let mut rx = [0u8; MAX_RX_FRAME];
        let data = &self.parser.data[..self.parser.length];
        let n = rx_frame(m.x, m.source, req, data, &mut rx);
        let stored = self.insert(&rx[..n], due);
        let s = &mut self.stats;
        if stored {
            s.bytes_sent = s.bytes_sent.wrapping_add(bytes);
        } else {
            // Received over the air (and acknowledged), lost at the receiver's UART.
            s.frames_overrun = s.frames_overrun.wrapping_add(1);
            s.overrun_bytes = s.overrun_bytes.wrapping_add(bytes);
        }
    }
}
