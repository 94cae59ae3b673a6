//! The link's clock: times in fractions of a tick, so that rates which do not divide
//! the tick rate stay exact.

use embassy_time::TICK_HZ;

use super::SimConfig;

/// Derived constants. Times are in units of `1 / (TICK_HZ * scale)` s.
#[derive(Clone, Copy, Debug)]
pub(super) struct Timing {
    /// Units per tick: `max(byte_rate, 1) * max(serial_rate, 1)`.
    pub(super) scale: u128,
    /// Units per byte on the air (0: instant).
    pub(super) air_byte: u128,
    /// Units per byte on the UART (0: instant).
    pub(super) uart_byte: u128,
    /// Latency in ticks.
    pub(super) latency: u64,
    /// XBee ACK wait in units.
    pub(super) ack_wait: u128,
    /// Bit-flip probability as a fraction of 2^64.
    pub(super) ber: u64,
    /// XBee failure probability as a fraction of 2^64.
    pub(super) failure: u64,
}

impl Timing {
    pub(super) const fn new(config: &SimConfig) -> Self {
        let air = config.byte_rate as u128;
        let serial = config.serial_rate as u128;
        let air1 = if air == 0 { 1 } else { air };
        let serial1 = if serial == 0 { 1 } else { serial };
        let hz = TICK_HZ as u128;
        let scale = air1 * serial1;
        let (ack_wait, failure) = match &config.xbee {
            Some(x) => (
                x.ack_delay.as_ticks() as u128 * scale,
                probability_threshold(x.failure_rate),
            ),
            None => (0, 0),
        };
        Self {
            scale,
            air_byte: if air == 0 { 0 } else { hz * serial1 },
            uart_byte: if serial == 0 { 0 } else { hz * air1 },
            latency: config.latency.as_ticks(),
            ack_wait,
            ber: probability_threshold(config.bit_error_rate),
            failure,
        }
    }

    /// The first tick at or after `units`.
    pub(super) fn ticks_ceil(&self, units: u128) -> u64 {
        u64::try_from(units.div_ceil(self.scale)).unwrap_or(u64::MAX)
    }

    pub(super) fn micros(&self, units: u128) -> u64 {
        let per_us = self.scale * u128::from(TICK_HZ);
        u64::try_from(units.saturating_mul(1_000_000) / per_us).unwrap_or(u64::MAX)
    }
}

/// A probability as a fraction of 2^64.
pub(super) const fn probability_threshold(p: f64) -> u64 {
    // `as` saturates (and maps NaN to 0), so any input is safe.
    (p * 18_446_744_073_709_551_616.0) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    pub(super) fn probability_threshold_saturates() {
        assert_eq!(probability_threshold(0.0), 0);
        assert_eq!(probability_threshold(-1.0), 0);
        assert_eq!(probability_threshold(f64::NAN), 0);
        assert_eq!(probability_threshold(1.0), u64::MAX);
        assert_eq!(probability_threshold(0.5), 1 << 63);
    }
}
