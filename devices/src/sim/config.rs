//! The parameters of a simulated link, its modem's among them.

use embassy_time::Duration;
use pprz_transports::xbee as api;

use super::xbee;

/// What a direction does with written bytes when its modem buffer is full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Overflow {
    /// Drop them and count them (a radio modem without flow control). Writes never wait
    /// for room.
    #[default]
    Drop,
    /// Stop the UART until there is room (hardware flow control, CTS).
    Wait,
}

/// Parameters of both directions of a [`SimLink`](super::SimLink); see the [module docs](super).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SimConfig {
    /// Bytes per second on the air; 0 for no serialisation delay.
    pub byte_rate: u32,
    /// Delay from the end of a byte's transmission to its arrival.
    pub latency: Duration,
    /// Bytes the modem buffer holds (values below 1 count as 1; in XBee API mode, at
    /// least one frame of the largest size).
    pub buffer: usize,
    /// Probability that a bit is flipped (0 to 1).
    pub bit_error_rate: f64,
    /// Seed of the bit-error (and XBee failure) generator.
    pub seed: u64,
    /// Behaviour when the modem buffer (or the receiver's ring) is full.
    pub overflow: Overflow,
    /// Bytes per second on the UART between the writer and its modem; 0 (the default)
    /// for instant transfers.
    pub serial_rate: u32,
    /// The XBee API modem, or `None` (the default) for a transparent modem.
    pub xbee: Option<XBeeModem>,
}

impl SimConfig {
    /// `byte_rate` bytes/s on the air, an instant UART, no latency, a 256-byte buffer,
    /// no bit errors, seed 1, [`Overflow::Drop`], a transparent modem.
    pub const fn new(byte_rate: u32) -> Self {
        Self {
            byte_rate,
            latency: Duration::from_ticks(0),
            buffer: 256,
            bit_error_rate: 0.0,
            seed: 1,
            overflow: Overflow::Drop,
            serial_rate: 0,
            xbee: None,
        }
    }

    /// Sets [`latency`](Self::latency).
    pub const fn latency(mut self, latency: Duration) -> Self {
        self.latency = latency;
        self
    }

    /// Sets [`buffer`](Self::buffer).
    pub const fn buffer(mut self, bytes: usize) -> Self {
        self.buffer = bytes;
        self
    }

    /// Sets [`bit_error_rate`](Self::bit_error_rate).
    pub const fn bit_error_rate(mut self, ber: f64) -> Self {
        self.bit_error_rate = ber;
        self
    }

    /// Sets [`seed`](Self::seed).
    pub const fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Sets [`overflow`](Self::overflow).
    pub const fn overflow(mut self, overflow: Overflow) -> Self {
        self.overflow = overflow;
        self
    }

    /// Sets [`serial_rate`](Self::serial_rate), in bytes per second (baud / 10 for 8N1).
    pub const fn serial_rate(mut self, bytes_per_s: u32) -> Self {
        self.serial_rate = bytes_per_s;
        self
    }

    /// Makes the modem an XBee in API mode; see [`xbee`](Self::xbee).
    pub const fn xbee(mut self, modem: XBeeModem) -> Self {
        self.xbee = Some(modem);
        self
    }
}

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
