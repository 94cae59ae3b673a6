//! How a device is used by the downlink: its transport and queue depth
//! ([`DeviceConfig`]), the rate of its replies ([`ReplyLimit`]) and, for a radio that does
//! not push back, its link budget ([`Pacing`]).

use core::cell::Cell;

use pprz_transports::AnyTransport;

use crate::delivery::DeliveryWindow;

/// The most replies (answers to requests received on the device: PONG, DL_VALUE, and
/// whatever [`Device::reply`](crate::Device::reply) sends) a device sends: `per_second` on average, up to
/// `burst` at once. Replies are acknowledgements, high in priority, so without a bound a
/// request flood from the ground (or an attacker) would evict the device's telemetry;
/// replies over the limit are refused and counted as [`DropReason::RateLimited`](crate::DropReason::RateLimited).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReplyLimit {
    /// Average replies per second (0: the device sends no replies).
    pub per_second: u16,
    /// Replies that may go out back to back (at least 1 is used).
    pub burst: u16,
}

impl ReplyLimit {
    /// The default of every device: 20 replies per second, 10 at once (a ground station
    /// pings once a second and reads a page of settings at a time).
    pub const DEFAULT: Self = Self::new(20, 10);

    /// `per_second` replies per second on average, `burst` at once.
    pub const fn new(per_second: u16, burst: u16) -> Self {
        Self { per_second, burst }
    }

    /// Generic cell rate algorithm: `tat` is the theoretical arrival time of the next
    /// reply (in embassy-time ticks); returns whether a reply at `now` conforms, and
    /// advances `tat` if so.
    pub(crate) fn admit(&self, tat: &Cell<u64>, now: u64) -> bool {
        if self.per_second == 0 {
            return false;
        }
        let interval = embassy_time::TICK_HZ / u64::from(self.per_second);
        let tolerance = interval.saturating_mul(u64::from(self.burst.max(1) - 1));
        let next = tat.get().max(now);
        if next - now > tolerance {
            return false;
        }
        tat.set(next.saturating_add(interval));
        true
    }
}

/// The link budget of a radio that does not push back (no hardware flow control): its
/// air throughput, and how many bytes we let wait inside the modem (and the UART
/// driver's buffer before it). The device's writer models the modem's occupancy as a
/// leaky bucket drained at `air_rate` and hands the modem a frame only when the frame
/// fits in `modem_budget`, so frames wait in our priority queue, where they are
/// reordered and shed by priority, instead of in the modem's FIFO, where they are sent
/// in order or lost when it overflows.
///
/// Choosing the figures (see the sizing guide): `air_rate` is the throughput the radio
/// really achieves, not its serial baud rate (a SiK radio at 64 kbit/s air rate with
/// ECC on carries about half of 8000 B/s, minus its framing and duty cycle; measure it
/// with a saturating test). `modem_budget` trades latency for link use: one
/// maximum-size frame plus a margin for clock and throughput error keeps the air busy
/// and bounds the wait of an acknowledgement to about two frame times; it must stay
/// well below the modem's real buffer (2048 bytes for a SiK radio).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pacing {
    /// Bytes per second the radio carries over the air (at least 1).
    pub air_rate: u32,
    /// Bytes we let wait in the modem at most (a frame longer than this goes alone,
    /// once the modelled modem is empty).
    pub modem_budget: u16,
}

impl Pacing {
    /// `air_rate` bytes per second, at most `modem_budget` bytes in the modem.
    pub const fn new(air_rate: u32, modem_budget: u16) -> Self {
        Self {
            air_rate,
            modem_budget,
        }
    }

    /// Time the air takes to carry `bytes` bytes, in embassy-time ticks (rounded up).
    /// Out of line: one copy of the 64-bit division for the writer's modem model.
    #[inline(never)]
    pub(crate) fn air_ticks(&self, bytes: usize) -> u64 {
        let rate = u64::from(self.air_rate.max(1));
        (bytes as u64)
            .saturating_mul(embassy_time::TICK_HZ)
            .div_ceil(rate)
    }
}

/// How a device is used by the downlink.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceConfig {
    /// Framing of this device's frames.
    pub transport: AnyTransport,
    /// Queue depth limit (at most the downlink's queue capacity `Q`); 0 means `Q`.
    pub depth: usize,
    /// Whether the writer flushes the device after every frame (for devices that
    /// buffer, such as a log file; a UART needs none).
    pub flush: bool,
    /// The most replies the device sends (`None`: no limit).
    pub replies: Option<ReplyLimit>,
    /// The link budget of a radio without flow control (`None`: write frames as fast as
    /// the device accepts them, for devices that push back or never lose bytes).
    pub pacing: Option<Pacing>,
    /// For a transport with transmit statuses (XBee API): how many frames may await
    /// their status in the modem (`None`: frames are written without frame ids, the
    /// modem sends no status). See [`delivery`](crate::delivery).
    pub delivery: Option<DeliveryWindow>,
    /// Spare bytes allocated after every frame of this device, for a
    /// [`LinkLayer`](crate::LinkLayer) that lengthens frames when the writer takes
    /// them for the wire (the secure link's 21 bytes of counter, tag and crypto byte). A
    /// message whose frame would not fit the transport with them is refused at `send`
    /// ([`DropReason::TooLarge`](crate::DropReason::TooLarge)).
    pub reserve: u8,
}

impl DeviceConfig {
    /// A device with this transport, the full queue capacity, no flush, replies limited
    /// to [`ReplyLimit::DEFAULT`].
    pub const fn new(transport: AnyTransport) -> Self {
        Self {
            transport,
            depth: 0,
            flush: false,
            replies: Some(ReplyLimit::DEFAULT),
            pacing: None,
            delivery: None,
            reserve: 0,
        }
    }

    /// With `bytes` spare bytes after every frame; see [`reserve`](Self::reserve).
    pub const fn reserve(mut self, bytes: u8) -> Self {
        self.reserve = bytes;
        self
    }

    /// With this transmit-status window (`None`: none); it applies to transports with
    /// transmit statuses (XBee API) and is ignored by the others.
    pub const fn delivery(mut self, window: Option<DeliveryWindow>) -> Self {
        self.delivery = window;
        self
    }

    /// With this link budget (`None`: no pacing); see [`Pacing`].
    pub const fn pacing(mut self, pacing: Option<Pacing>) -> Self {
        self.pacing = pacing;
        self
    }

    /// With this reply rate limit (`None`: replies unlimited).
    pub const fn replies(mut self, limit: Option<ReplyLimit>) -> Self {
        self.replies = limit;
        self
    }

    /// With a queue depth limit.
    pub const fn depth(mut self, depth: usize) -> Self {
        self.depth = depth;
        self
    }

    /// Flushing after every frame.
    pub const fn flush(mut self, flush: bool) -> Self {
        self.flush = flush;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reply_limit_is_a_token_bucket() {
        let tick = embassy_time::TICK_HZ;
        let limit = ReplyLimit::new(10, 3);
        let tat = Cell::new(0);
        // A burst of 3 at t = 0, then one every 100 ms.
        let at = |t: u64| limit.admit(&tat, t);
        assert_eq!([at(0), at(0), at(0), at(0)], [true, true, true, false]);
        assert!(!at(tick / 20));
        assert!(at(tick / 10));
        assert!(!at(tick / 10));
        // After a long silence the full burst again, no more.
        let later = 100 * tick;
        assert_eq!(
            [at(later), at(later), at(later), at(later)],
            [true, true, true, false]
        );
        // 0 per second: no replies; a burst of 0 counts as 1.
        assert!(!ReplyLimit::new(0, 5).admit(&Cell::new(0), 0));
        let one = Cell::new(0);
        assert!(ReplyLimit::new(1, 0).admit(&one, 0));
        assert!(!ReplyLimit::new(1, 0).admit(&one, 0));
        // Near the end of time, no overflow.
        assert!(ReplyLimit::new(u16::MAX, u16::MAX).admit(&Cell::new(0), u64::MAX));
    }
}
