//! Merging redundant links: a message heard on several links is delivered once.
//!
//! PPRZ frames carry no sequence number, so a copy is recognised by its content: the
//! sender, the message (class and id) and the payload, hashed with a key drawn at
//! start-up (a sender cannot craft collisions it cannot predict). The framing is not
//! part of it, so an XBee radio and a PPRZ v2 radio carrying the same message match.
//!
//! Each content seen in the last [`window`](Dedup::window) seconds keeps how many
//! times each link delivered it. A message from link L is the `c`-th instance of its
//! content on L; it is a copy when another link already delivered that many, and is
//! delivered otherwise. So an aircraft that sends the same content twice on one link
//! (an unchanged status) gets both through, and two links carrying both still deliver
//! two.
//!
//! A copy that arrives later than the window after the first is not recognised: it is
//! delivered again. Choose the window longer than the largest delay between the links
//! and shorter than the period at which the aircraft repeats identical content on one
//! link ([`DEFAULT_WINDOW`]).
//!
//! ```
//! use pprz_ground::gateway::dedup::{Dedup, Verdict};
//! let mut d = Dedup::new(2, 1.0, 1000);
//! let k = d.key(7, 1, 8, &[1, 2, 3]);
//! assert_eq!(d.check(0.00, 0, 7, k), Verdict::First);
//! assert_eq!(d.check(0.01, 1, 7, k), Verdict::Duplicate);
//! assert_eq!(d.check(0.50, 0, 7, k), Verdict::Repeat);
//! ```

use std::collections::hash_map::RandomState;
use std::collections::{HashMap, VecDeque};
use std::hash::{BuildHasher, Hasher};

/// Links the gateway merges at most.
pub const MAX_LINKS: usize = 16;

/// The default window, in seconds: longer than a radio's queueing delay, shorter than
/// the period of Paparazzi's slowest periodic messages.
pub const DEFAULT_WINDOW: f64 = 1.0;

/// The default bound on remembered contents: 50 000 messages per second for the
/// default window, with margin (about 80 bytes each).
pub const DEFAULT_CAPACITY: usize = 1 << 17;

/// What becomes of a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Its content was not seen in the window: delivered.
    First,
    /// Its content was seen, but this link has now delivered it more often than any
    /// other: a repeat by the aircraft, delivered.
    Repeat,
    /// Another link delivered this instance already: dropped.
    Duplicate,
}

impl Verdict {
    /// Whether the message is delivered.
    pub fn delivered(self) -> bool {
        !matches!(self, Self::Duplicate)
    }
}

/// What one link did, as the window closes on the contents it carried.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkMerge {
    /// Messages it delivered first (not copies).
    pub first: u64,
    /// Copies of messages another link delivered first.
    pub duplicates: u64,
    /// Messages only this link delivered, once their window closed.
    pub alone: u64,
    /// Messages another link delivered and this one did not, once their window closed,
    /// for the aircraft this link heard in that window.
    pub missed: u64,
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    ac: u8,
    counts: [u8; MAX_LINKS],
}

/// The merging state of the gateway's links (module doc).
pub struct Dedup {
    hasher: RandomState,
    window: f64,
    capacity: usize,
    links: usize,
    seen: HashMap<u64, Entry>,
    /// Contents in the order they were first seen, with that time.
    order: VecDeque<(f64, u64)>,
    stats: [LinkMerge; MAX_LINKS],
    /// When each link last delivered a message (any verdict) of each aircraft.
    heard: Vec<[f64; 256]>,
    /// Contents forgotten before their window closed because the bound was reached.
    evicted: u64,
}

impl Dedup {
    /// Merging for `links` links (at most [`MAX_LINKS`]; more are taken as that many)
    /// over `window` seconds, remembering at most `capacity` contents.
    pub fn new(links: usize, window: f64, capacity: usize) -> Self {
        Self {
            hasher: RandomState::new(),
            window,
            capacity: capacity.max(1),
            links: links.min(MAX_LINKS),
            seen: HashMap::new(),
            order: VecDeque::new(),
            stats: [LinkMerge::default(); MAX_LINKS],
            heard: vec![[f64::NEG_INFINITY; 256]; links.min(MAX_LINKS)],
            evicted: 0,
        }
    }

    /// The window, in seconds.
    pub fn window(&self) -> f64 {
        self.window
    }

    /// The content key of a message: sender, class, id and payload.
    pub fn key(&self, source: u8, class: u8, id: u8, payload: &[u8]) -> u64 {
        let mut h = self.hasher.build_hasher();
        h.write(&[source, class, id]);
        h.write(payload);
        h.finish()
    }

    /// A message of content `key` from aircraft `ac` on link `link` at `now` (seconds,
    /// not decreasing): whether it is delivered. With a single link, every message is.
    pub fn check(&mut self, now: f64, link: usize, ac: u8, key: u64) -> Verdict {
        self.expire(now);
        let Some(link) = (link < self.links).then_some(link) else {
            return Verdict::First;
        };
        self.heard[link][usize::from(ac)] = now;
        if self.links == 1 {
            self.stats[0].first += 1;
            return Verdict::First;
        }
        if !self.seen.contains_key(&key) && self.seen.len() >= self.capacity {
            self.evict_oldest();
        }
        let mut fresh = false;
        let entry = self.seen.entry(key).or_insert_with(|| {
            fresh = true;
            Entry {
                ac,
                counts: [0; MAX_LINKS],
            }
        });
        if fresh {
            self.order.push_back((now, key));
        }
        let count = entry.counts[link].saturating_add(1);
        entry.counts[link] = count;
        let most_elsewhere = entry
            .counts
            .iter()
            .enumerate()
            .filter(|&(l, _)| l != link)
            .map(|(_, &c)| c)
            .max()
            .unwrap_or(0);
        let verdict = if most_elsewhere >= count {
            Verdict::Duplicate
        } else if fresh {
            Verdict::First
        } else {
            Verdict::Repeat
        };
        let s = &mut self.stats[link];
        match verdict {
            Verdict::Duplicate => s.duplicates += 1,
            _ => s.first += 1,
        }
        verdict
    }

    /// Closes the windows that ended by `now`.
    pub fn expire(&mut self, now: f64) {
        while let Some(&(at, key)) = self.order.front() {
            if now - at <= self.window {
                break;
            }
            self.order.pop_front();
            self.close(at, key);
        }
    }

    fn evict_oldest(&mut self) {
        if let Some((at, key)) = self.order.pop_front() {
            self.close(at, key);
            self.evicted += 1;
        }
    }

    /// Counts what each link alone delivered and what it missed of a content first seen
    /// at `at`.
    fn close(&mut self, at: f64, key: u64) {
        let Some(e) = self.seen.remove(&key) else {
            return;
        };
        let counts = &e.counts[..self.links];
        let most = counts.iter().copied().max().unwrap_or(0);
        let carriers = counts.iter().filter(|&&c| c > 0).count();
        for (l, &c) in counts.iter().enumerate() {
            if carriers == 1 && c > 0 {
                self.stats[l].alone += u64::from(c);
            }
            if c < most && self.heard[l][usize::from(e.ac)] >= at - self.window {
                self.stats[l].missed += u64::from(most - c);
            }
        }
    }

    /// What link `link` did.
    pub fn link(&self, link: usize) -> LinkMerge {
        self.stats.get(link).copied().unwrap_or_default()
    }

    /// Contents forgotten early because the bound was reached (their copies, if any
    /// came later, were delivered again).
    pub fn evicted(&self) -> u64 {
        self.evicted
    }

    /// Contents remembered now.
    pub fn len(&self) -> usize {
        self.seen.len()
    }

    /// Whether nothing is remembered.
    pub fn is_empty(&self) -> bool {
        self.seen.is_empty()
    }
}
