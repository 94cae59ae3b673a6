//! Round-trip times of PINGs.
//!
//! PING and PONG carry no sequence number, and an aircraft answers PINGs in order, so
//! each PONG answers the oldest PING still outstanding. Several PINGs may be in
//! flight at once (a PING period shorter than the round trip): each keeps its own send
//! time, so the round trip measured is the true one, not the time since the latest
//! PING. A PING not answered within the timeout is counted as lost and no longer
//! waits for a PONG; the number of PINGs outstanding is bounded (the oldest is counted
//! lost when a new one would exceed it).
//!
//! ```
//! use pprz_ground::ping::PingTracker;
//! let mut pings = PingTracker::new(16, 2.0);
//! pings.sent(0.0);
//! pings.sent(0.2);
//! assert_eq!(pings.pong(0.5), Some(0.5)); // answers the PING sent at 0.0
//! assert!((pings.pong(0.7).unwrap() - 0.5).abs() < 1e-12);
//! assert_eq!(pings.pong(0.8), None); // nothing outstanding
//! assert_eq!((pings.answered(), pings.unexpected()), (2, 1));
//! ```

use std::cmp::Ordering;
use std::collections::VecDeque;

/// Default bound on the PINGs outstanding.
pub const MAX_OUTSTANDING: usize = 64;

/// Default time after which an unanswered PING counts as lost, in seconds.
pub const TIMEOUT: f64 = 5.0;

/// PINGs outstanding, oldest first, and the statistics of their PONGs.
#[derive(Debug, Clone)]
pub struct PingTracker {
    outstanding: VecDeque<f64>,
    capacity: usize,
    timeout: f64,
    sent: u64,
    answered: u64,
    lost: u64,
    unexpected: u64,
    last_rtt: Option<f64>,
}

impl Default for PingTracker {
    fn default() -> Self {
        Self::new(MAX_OUTSTANDING, TIMEOUT)
    }
}

impl PingTracker {
    /// A tracker keeping at most `capacity` PINGs outstanding (at least 1), each for at
    /// most `timeout` seconds.
    pub fn new(capacity: usize, timeout: f64) -> Self {
        let capacity = capacity.max(1);
        Self {
            outstanding: VecDeque::with_capacity(capacity),
            capacity,
            timeout,
            sent: 0,
            answered: 0,
            lost: 0,
            unexpected: 0,
            last_rtt: None,
        }
    }

    /// A PING was sent at `now`. Returns how many PINGs this made count as lost (timed
    /// out, or the oldest one dropped to respect the bound).
    pub fn sent(&mut self, now: f64) -> u64 {
        let mut lost = self.expire(now);
        if self.outstanding.len() >= self.capacity {
            self.outstanding.pop_front();
            self.lost += 1;
            lost += 1;
        }
        self.outstanding.push_back(now);
        self.sent += 1;
        lost
    }

    /// Counts as lost the PINGs outstanding for longer than the timeout at `now`;
    /// returns how many.
    pub fn expire(&mut self, now: f64) -> u64 {
        let mut lost = 0;
        // Expires a PING older than the timeout, or whose age is NaN.
        while self.outstanding.front().is_some_and(|sent| {
            matches!(
                (now - sent).partial_cmp(&self.timeout),
                Some(Ordering::Greater) | None
            )
        }) {
            self.outstanding.pop_front();
            lost += 1;
        }
        self.lost += lost;
        lost
    }

    /// A PONG arrived at `now`: the round-trip time of the oldest PING outstanding, or
    /// `None` when none is (a late answer to a PING counted lost, or a PONG nobody asked
    /// for).
    pub fn pong(&mut self, now: f64) -> Option<f64> {
        self.expire(now);
        match self.outstanding.pop_front() {
            Some(sent) => {
                let rtt = now - sent;
                self.answered += 1;
                self.last_rtt = Some(rtt);
                Some(rtt)
            }
            None => {
                self.unexpected += 1;
                None
            }
        }
    }

    /// PINGs sent.
    pub fn sent_count(&self) -> u64 {
        self.sent
    }

    /// PINGs answered by a PONG.
    pub fn answered(&self) -> u64 {
        self.answered
    }

    /// PINGs counted as lost (timed out or pushed out by the bound).
    pub fn lost(&self) -> u64 {
        self.lost
    }

    /// PONGs that answered no PING outstanding.
    pub fn unexpected(&self) -> u64 {
        self.unexpected
    }

    /// PINGs waiting for their PONG.
    pub fn outstanding(&self) -> usize {
        self.outstanding.len()
    }

    /// The bound on the PINGs outstanding.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The timeout, in seconds.
    pub fn timeout(&self) -> f64 {
        self.timeout
    }

    /// The latest round-trip time measured, in seconds.
    pub fn last_rtt(&self) -> Option<f64> {
        self.last_rtt
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue: with `--ping 0.2` and a true round trip of 500 ms, each PING overwrote the
    /// send time of the previous one, and 100.8 ms was shown.
    #[test]
    fn each_pong_answers_its_own_ping() {
        let mut t = PingTracker::new(16, 5.0);
        let mut rtts = Vec::new();
        for i in 0..50 {
            let now = f64::from(i) * 0.1;
            if i % 2 == 0 {
                t.sent(now); // every 0.2 s
            }
            if i >= 5 && (i - 5) % 2 == 0 {
                rtts.push(t.pong(now).unwrap()); // 0.5 s later
            }
        }
        assert_eq!(rtts.len(), 23);
        for rtt in rtts {
            assert!((rtt - 0.5).abs() < 1e-9, "{rtt}");
        }
        assert_eq!((t.sent_count(), t.answered(), t.lost()), (25, 23, 0));
        assert_eq!(t.outstanding(), 2);
    }

    #[test]
    fn unanswered_pings_time_out_as_lost() {
        let mut t = PingTracker::new(16, 1.0);
        t.sent(0.0);
        t.sent(0.5);
        t.sent(2.0);
        // The PINGs of 0.0 and 0.5 are lost: the PONG at 2.1 answers the one of 2.0.
        let rtt = t.pong(2.1).unwrap();
        assert!((rtt - 0.1).abs() < 1e-9);
        assert_eq!((t.lost(), t.answered(), t.outstanding()), (2, 1, 0));
        // A PONG after the timeout of its PING answers nothing.
        t.sent(3.0);
        assert_eq!(t.pong(4.5), None);
        assert_eq!((t.lost(), t.unexpected()), (3, 1));
        assert_eq!(t.expire(f64::NAN), 0);
    }

    #[test]
    fn outstanding_pings_are_bounded() {
        let mut t = PingTracker::new(4, f64::INFINITY);
        let mut lost = 0;
        for i in 0..1000 {
            lost += t.sent(f64::from(i));
            assert!(t.outstanding() <= 4);
        }
        assert_eq!((lost, t.lost(), t.outstanding()), (996, 996, 4));
        // The survivors are the newest: the next PONG answers the PING of 996.
        assert_eq!(t.pong(1000.0), Some(4.0));
        assert_eq!(PingTracker::new(0, 1.0).capacity(), 1);
    }
}
