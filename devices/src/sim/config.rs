//! The parameters of a simulated link.

use embassy_time::Duration;

use super::XBeeModem;

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
