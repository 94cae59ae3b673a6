//! The counters of a direction.

use embassy_time::Duration;

/// Counters of one direction of a [`SimLink`](super::SimLink). The `u32` counters wrap around.
///
/// Transparent modem: `bytes_written == bytes_sent + dropped_bytes + overrun_bytes +
/// outage_bytes`.
/// XBee API modem: `bytes_written == bytes_sent + dropped_bytes + overrun_bytes +
/// discarded_bytes + ` the bytes of a frame still being received, the byte counters
/// counting the API bytes of whole frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SimStats {
    /// Bytes that crossed the UART into the modem.
    pub bytes_written: u32,
    /// Bytes the modem accepted for transmission (API mode: the API bytes of the frames
    /// sent, except those lost to a receiver overrun).
    pub bytes_sent: u32,
    /// Bytes returned by `read` on this direction (RX frames and statuses included).
    pub bytes_delivered: u32,
    /// Bytes dropped because the modem buffer was full ([`Overflow::Drop`](super::Overflow::Drop)).
    pub dropped_bytes: u32,
    /// Bytes dropped because the receiver's ring was full ([`Overflow::Drop`](super::Overflow::Drop), or a
    /// frame larger than the ring).
    pub overrun_bytes: u32,
    /// Bits flipped.
    pub bit_errors: u32,
    /// Bytes with at least one flipped bit (API mode: such a transmission fails).
    pub corrupted_bytes: u32,
    /// Time the UART spent transferring bytes into the modem, in µs (rounded down).
    pub serial_busy_us: u64,
    /// Time the air spent carrying this direction's bytes, in µs (rounded down), up to
    /// now (transmissions scheduled for later are not counted yet).
    pub air_busy_us: u64,
    /// API frames accepted by the modem and transmitted.
    pub frames_sent: u32,
    /// API frames dropped whole because the modem buffer was full.
    pub frames_dropped: u32,
    /// API frames sent (and acknowledged) but lost because the receiver's ring could
    /// not hold them (their API bytes are in `overrun_bytes`).
    pub frames_overrun: u32,
    /// Malformed API frames (bad length or checksum, unexpected API id, RF data too
    /// long), dropped.
    pub malformed_frames: u32,
    /// Bytes the API parser dropped: malformed frames and bytes outside frames.
    pub discarded_bytes: u32,
    /// Transmissions of API frames that failed (random failure or bit error).
    pub failed_attempts: u32,
    /// API frames that failed every attempt (never received).
    pub frames_lost: u32,
    /// Transmit statuses written back to this direction's writer.
    pub statuses: u32,
    /// Transmit statuses lost because the writer's receiver ring was full.
    pub statuses_lost: u32,
    /// Transparent modem: bytes sent on the air during an outage
    /// ([`SimLink::add_outage`](super::SimLink::add_outage)), never received.
    pub outage_bytes: u32,
    /// API modem: transmissions that ended during an outage, and failed (they are
    /// counted in `failed_attempts` too; a frame whose every attempt failed is in
    /// `frames_lost`).
    pub outage_attempts: u32,
}

impl SimStats {
    /// [`serial_busy_us`](Self::serial_busy_us) as a [`Duration`].
    pub const fn serial_busy(&self) -> Duration {
        Duration::from_micros(self.serial_busy_us)
    }

    /// [`air_busy_us`](Self::air_busy_us) as a [`Duration`].
    pub const fn air_busy(&self) -> Duration {
        Duration::from_micros(self.air_busy_us)
    }
}
