//! The uplink's way to each aircraft: the link(s) it was last heard on.
//!
//! Every delivered message from aircraft N notes which link brought it first. A
//! command for N goes out, with [`Policy::Best`], on the link that most recently
//! brought a message of N first (the fastest one, and the one still working); with
//! [`Policy::All`], on every link that heard N within the stale time. An aircraft
//! reachable only through a relaying aircraft is heard on the relay's link (the relay
//! forwards its frames with their own source id), so its commands take that link and
//! the relay forwards them. An aircraft never heard (or not heard within the stale
//! time on any link) gets the command on every link that can send.
//!
//! ```
//! use pprz_ground::gateway::route::{Policy, RouteTable};
//! let mut r = RouteTable::new(2, 5.0);
//! r.heard(0.0, 1, 7, true);
//! r.heard(0.1, 0, 7, false);
//! assert_eq!(r.uplink(1.0, 7, Policy::Best, &[true, true]), vec![1]);
//! assert_eq!(r.uplink(1.0, 7, Policy::All, &[true, true]), vec![0, 1]);
//! assert_eq!(r.uplink(1.0, 9, Policy::Best, &[true, true]), vec![0, 1]);
//! ```

use std::collections::BTreeMap;

use super::dedup::MAX_LINKS;

/// Which links a command for an aircraft takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Policy {
    /// The link that most recently delivered a message of the aircraft first.
    #[default]
    Best,
    /// Every link that heard the aircraft within the stale time (the aircraft may get
    /// the command twice: fine for SETTING and BLOCK, which set a state; a PING gets
    /// two PONGs).
    All,
}

#[derive(Debug, Clone, Copy)]
struct Heard {
    /// Latest message of the aircraft on the link, delivered or a copy.
    last: f64,
    /// Latest message the link delivered first.
    first: f64,
}

/// When each link last heard each aircraft (module doc).
pub struct RouteTable {
    links: usize,
    stale_after: f64,
    aircraft: BTreeMap<u8, [Option<Heard>; MAX_LINKS]>,
}

impl RouteTable {
    /// A table for `links` links; a link that did not hear an aircraft for
    /// `stale_after` seconds no longer carries it.
    pub fn new(links: usize, stale_after: f64) -> Self {
        Self {
            links: links.min(MAX_LINKS),
            stale_after,
            aircraft: BTreeMap::new(),
        }
    }

    /// Link `link` brought a message of aircraft `ac` at `now`, `first` if it was
    /// delivered (not a copy).
    pub fn heard(&mut self, now: f64, link: usize, ac: u8, first: bool) {
        if link >= self.links {
            return;
        }
        let slot = &mut self.aircraft.entry(ac).or_insert([None; MAX_LINKS])[link];
        let h = slot.get_or_insert(Heard {
            last: now,
            first: f64::NEG_INFINITY,
        });
        h.last = now;
        if first {
            h.first = now;
        }
    }

    /// The links a command for `ac` takes at `now` under `policy`, among those that
    /// can send (`can_send[l]`), in link order; empty when no link can send.
    pub fn uplink(&self, now: f64, ac: u8, policy: Policy, can_send: &[bool]) -> Vec<usize> {
        let able = |l: usize| can_send.get(l).copied().unwrap_or(false);
        let live: Vec<(usize, Heard)> = self
            .aircraft
            .get(&ac)
            .into_iter()
            .flat_map(|links| links.iter().enumerate())
            .filter_map(|(l, h)| Some((l, (*h)?)))
            .filter(|&(l, h)| able(l) && now - h.last <= self.stale_after)
            .collect();
        if live.is_empty() {
            return (0..self.links).filter(|&l| able(l)).collect();
        }
        match policy {
            Policy::All => live.iter().map(|&(l, _)| l).collect(),
            Policy::Best => {
                let best = live
                    .iter()
                    .max_by(|a, b| {
                        (a.1.first, a.1.last)
                            .partial_cmp(&(b.1.first, b.1.last))
                            .unwrap_or(std::cmp::Ordering::Equal)
                            .then(b.0.cmp(&a.0))
                    })
                    .map(|&(l, _)| l);
                best.into_iter().collect()
            }
        }
    }

    /// The links that heard `ac` within the stale time at `now`, with the seconds since.
    pub fn links_of(&self, now: f64, ac: u8) -> Vec<(usize, f64)> {
        self.aircraft
            .get(&ac)
            .into_iter()
            .flat_map(|links| links.iter().enumerate())
            .filter_map(|(l, h)| Some((l, now - (*h)?.last)))
            .filter(|&(_, since)| since <= self.stale_after)
            .collect()
    }
}
