//! Transmit-status feedback from radios that give it (XBee API): the frames a device's
//! writer has handed to the modem and not yet seen acknowledged.
//!
//! ```text
//!  writer: frame id 1..=255 set in the frame ──► modem ──► air
//!     ▲  at most `in_modem` frames outstanding          │
//!     └── Device::tx_status(status) ◄── reader ◄── transmit status (0x89 / 0x8B)
//! ```
//!
//! With a [`DeliveryWindow`] configured ([`DeviceConfig::delivery`](crate::DeviceConfig)),
//! the writer gives each frame a fresh frame id and takes the next frame from the queue
//! only while fewer than `in_modem` frames await their status: the other frames wait in
//! the priority queue, where they can be overtaken and shed. A status that never comes
//! frees its place after `timeout_ms` (counted, the writer goes on); a status for no
//! outstanding frame (unknown, late, or repeated) is counted and ignored. Delivery
//! failures the radio reports are counted per device ([`DeliveryStats`]).

use core::task::Context;

use embassy_sync::waitqueue::WakerRegistration;

use pprz_transports::TxStatus;

/// Most frames awaiting their transmit status a device allows.
pub const MAX_IN_MODEM: usize = 8;

/// How many frames may await their transmit status in a radio modem (XBee API), and
/// how long a status may take.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeliveryWindow {
    /// Frames in the modem at most (1..=[`MAX_IN_MODEM`]; 1 keeps the modem's queue
    /// empty, 2 keeps the air busy while the next frame crosses the UART).
    pub in_modem: u8,
    /// Milliseconds after which a missing status frees its place (counted as a timeout).
    pub timeout_ms: u32,
}

impl DeliveryWindow {
    /// `in_modem` frames at most (clamped to 1..=[`MAX_IN_MODEM`]), statuses expected
    /// within `timeout_ms`.
    pub const fn new(in_modem: u8, timeout_ms: u32) -> Self {
        let in_modem = if in_modem == 0 {
            1
        } else if in_modem as usize > MAX_IN_MODEM {
            MAX_IN_MODEM as u8
        } else {
            in_modem
        };
        Self {
            in_modem,
            timeout_ms,
        }
    }
}

/// What the transmit statuses of a device said.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeliveryStats {
    /// Frames the radio reported delivered.
    pub delivered: u32,
    /// Frames the radio reported not delivered (no ACK, CCA failure, purged, ...).
    pub failed: u32,
    /// Frames whose status never came (their place freed after the timeout).
    pub timeouts: u32,
    /// Statuses for no outstanding frame (unknown frame id, after a timeout, repeated).
    pub unexpected: u32,
}

/// The outstanding frames of one device (shared by its writer and its reader).
pub(crate) struct Outstanding {
    /// Frame id and deadline (embassy-time ticks) of each outstanding frame, oldest first.
    frames: heapless::Vec<(u8, u64), MAX_IN_MODEM>,
    /// The last frame id given (1..=255, then 1 again).
    last_id: u8,
    waker: WakerRegistration,
    pub(crate) stats: DeliveryStats,
}

impl Outstanding {
    #[cfg_attr(not(feature = "xbee"), allow(dead_code))]
    pub(crate) const fn new() -> Self {
        Self {
            frames: heapless::Vec::new(),
            last_id: 0,
            waker: WakerRegistration::new(),
            stats: DeliveryStats {
                delivered: 0,
                failed: 0,
                timeouts: 0,
                unexpected: 0,
            },
        }
    }

    /// Frees the places of the frames whose deadline has passed at `now`.
    fn expire(&mut self, now: u64) {
        let before = self.frames.len();
        self.frames.retain(|&(_, deadline)| deadline > now);
        let expired = (before - self.frames.len()) as u32;
        self.stats.timeouts = self.stats.timeouts.wrapping_add(expired);
    }

    /// Whether a frame may go to the modem at `now` (after expiring the late ones);
    /// otherwise the deadline of the oldest outstanding frame, and the waker of `cx` is
    /// registered for the next status.
    pub(crate) fn room(
        &mut self,
        window: &DeliveryWindow,
        now: u64,
        cx: Option<&mut Context<'_>>,
    ) -> Result<(), u64> {
        self.expire(now);
        // Clamped as `new` clamps (`in_modem` is a public field): a window of none would
        // never let a frame out, one past the record's capacity would send untracked ones.
        if self.frames.len() < usize::from(window.in_modem).clamp(1, MAX_IN_MODEM) {
            return Ok(());
        }
        if let Some(cx) = cx {
            self.waker.register(cx.waker());
        }
        Err(self.frames.first().map_or(now, |&(_, deadline)| deadline))
    }

    /// A fresh frame id for a frame going to the modem at `now`, recorded as
    /// outstanding until `now + timeout`. `None` when the window is full (the caller
    /// checked [`room`](Self::room) first, so only a racing writer could see it).
    pub(crate) fn start(&mut self, window: &DeliveryWindow, now: u64) -> Option<u8> {
        let timeout = u64::from(window.timeout_ms) * embassy_time::TICK_HZ / 1000;
        let id = match self.last_id {
            255 => 1,
            id => id + 1,
        };
        self.frames
            .push((id, now.saturating_add(timeout.max(1))))
            .ok()?;
        self.last_id = id;
        Some(id)
    }

    /// A transmit status arrived: frees its frame's place and counts the outcome.
    pub(crate) fn status(&mut self, status: &TxStatus) {
        match self
            .frames
            .iter()
            .position(|&(id, _)| id == status.frame_id)
        {
            Some(i) => {
                self.frames.remove(i);
                let n = if status.delivered {
                    &mut self.stats.delivered
                } else {
                    &mut self.stats.failed
                };
                *n = n.wrapping_add(1);
                self.waker.wake();
            }
            None => self.stats.unexpected = self.stats.unexpected.wrapping_add(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn status(frame_id: u8, delivered: bool) -> TxStatus {
        TxStatus {
            frame_id,
            delivered,
            status: u8::from(!delivered),
            retries: 0,
        }
    }

    #[test]
    fn a_window_of_outstanding_frames() {
        let ms = embassy_time::TICK_HZ / 1000;
        let window = DeliveryWindow::new(2, 100);
        let mut o = Outstanding::new();
        assert_eq!(o.room(&window, 0, None), Ok(()));
        assert_eq!(o.start(&window, 0), Some(1));
        assert_eq!(o.start(&window, 10 * ms), Some(2));
        assert_eq!(
            o.room(&window, 20 * ms, None),
            Err(100 * ms),
            "full until frame 1's deadline"
        );
        o.status(&status(1, false));
        o.status(&status(1, true)); // repeated: unexpected
        o.status(&status(77, true)); // never sent
        assert_eq!(o.room(&window, 20 * ms, None), Ok(()));
        assert_eq!(o.start(&window, 20 * ms), Some(3));
        // Frame 2 times out at 110 ms; its late status is unexpected.
        assert_eq!(o.room(&window, 110 * ms, None), Ok(()));
        o.status(&status(2, true));
        o.status(&status(3, true));
        assert_eq!(
            o.stats,
            DeliveryStats {
                delivered: 1,
                failed: 1,
                timeouts: 1,
                unexpected: 3,
            }
        );
    }

    #[test]
    fn frame_ids_skip_zero_and_the_window_is_clamped() {
        let window = DeliveryWindow::new(1, 0);
        let mut o = Outstanding::new();
        for expected in (1..=255).chain(1..=3) {
            assert_eq!(o.start(&window, 0), Some(expected));
            o.status(&status(expected, true));
        }
        assert_eq!(o.stats.delivered, 258);
        assert_eq!(DeliveryWindow::new(0, 1).in_modem, 1);
        assert_eq!(DeliveryWindow::new(200, 1).in_modem, MAX_IN_MODEM as u8);
        // The same clamp when the field is set directly.
        let mut fresh = Outstanding::new();
        let none = DeliveryWindow {
            in_modem: 0,
            ..DeliveryWindow::new(1, 100)
        };
        assert_eq!(fresh.room(&none, 0, None), Ok(()), "one frame may go");
        assert!(fresh.start(&none, 0).is_some());
        assert!(fresh.room(&none, 0, None).is_err());
        let many = DeliveryWindow {
            in_modem: u8::MAX,
            ..none
        };
        for _ in 1..MAX_IN_MODEM {
            assert_eq!(fresh.room(&many, 0, None), Ok(()));
            assert!(fresh.start(&many, 0).is_some());
        }
        assert!(
            fresh.room(&many, 0, None).is_err(),
            "no more than it can track"
        );
        // A timeout of 0 still gives a status one tick.
        assert!(o.start(&window, 5).is_some());
        assert_eq!(o.room(&window, 5, None), Err(6));
        assert_eq!(o.room(&window, 6, None), Ok(()));
        assert_eq!(o.stats.timeouts, 1);
    }
}
