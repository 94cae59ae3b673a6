//! Reading every setting of an aircraft ([`Sweep`]).

use super::SettingsTable;

/// The most failed settings a line names (the others are counted).
pub const MAX_NAMED_FAILURES: usize = 8;

/// How a [`Sweep`] is paced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepConfig {
    /// GET_SETTINGs waiting for their answer at most (1 to 256).
    pub outstanding: usize,
    /// Seconds after which an unanswered GET_SETTING is sent again (doubling with each
    /// send).
    pub retry_after: f64,
    /// Sends of one index at most, the first included (at least 1).
    pub attempts: u32,
    /// GET_SETTINGs sent per second at most, on average (first sends and retries).
    pub rate: f64,
    /// GET_SETTINGs that may go out at once within the rate (at least 1).
    pub burst: u32,
}

impl Default for SweepConfig {
    /// 8 outstanding, 15 per second, 4 at once, sent again after 1 s, 2 s, 4 s: 4 sends
    /// at most. 15 per second leaves room for a PING or a SETTING within the 20 replies
    /// per second an aircraft of this stack sends by default.
    fn default() -> Self {
        Self {
            outstanding: 8,
            retry_after: 1.0,
            attempts: 4,
            rate: 15.0,
            burst: 4,
        }
    }
}

impl SweepConfig {
    /// With at most `n` requests outstanding (kept within 1 to 256).
    #[must_use]
    pub fn outstanding(mut self, n: usize) -> Self {
        self.outstanding = n.clamp(1, 256);
        self
    }

    /// Sending again after `seconds` (a finite number above 0; otherwise unchanged).
    #[must_use]
    pub fn retry_after(mut self, seconds: f64) -> Self {
        if seconds.is_finite() && seconds > 0.0 {
            self.retry_after = seconds;
        }
        self
    }

    /// At most `n` sends of an index (at least 1).
    #[must_use]
    pub fn attempts(mut self, n: u32) -> Self {
        self.attempts = n.max(1);
        self
    }

    /// At most `per_second` GET_SETTINGs per second (a finite number above 0;
    /// otherwise unchanged).
    #[must_use]
    pub fn rate(mut self, per_second: f64) -> Self {
        if per_second.is_finite() && per_second > 0.0 {
            self.rate = per_second;
        }
        self
    }

    /// At most `n` GET_SETTINGs at once within the rate (at least 1).
    #[must_use]
    pub fn burst(mut self, n: u32) -> Self {
        self.burst = n.max(1);
        self
    }

    /// Whether a request may go out at `now`, given `next`, the theoretical time of the
    /// next one (generic cell rate algorithm); advances `next` if so.
    fn admit(&self, next: &mut f64, now: f64) -> bool {
        let interval = 1.0 / self.rate;
        let tolerance = interval * f64::from(self.burst.max(1) - 1);
        let at = next.max(now);
        if at - now > tolerance + 1e-9 {
            return false;
        }
        *next = at + interval;
        true
    }
}

/// Where one index stands.
#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    /// To send (again), after `sends` sends.
    Waiting { sends: u32 },
    /// Sent `sends` times, the last at `at`.
    Outstanding { at: f64, sends: u32 },
    /// A DL_VALUE arrived.
    Read,
    /// No answer to any of the sends.
    Failed,
}

/// The reading of every setting of an aircraft: one GET_SETTING per index, paced.
///
/// A [`Sweep`] decides which GET_SETTINGs to send, on explicit time: at most
/// [`SweepConfig::outstanding`] wait for their DL_VALUE at once, in index order, and at
/// most [`SweepConfig::rate`] go out per second (a few at once, [`SweepConfig::burst`]).
/// The rate matters: an aircraft bounds its replies (our telemetry stack answers 20
/// requests per second by default, 10 at once, PINGs included, and refuses the others),
/// so requests sent faster are lost and cost a retry. A request without an answer after
/// [`SweepConfig::retry_after`] seconds is sent again, the wait doubling each time, at
/// most [`SweepConfig::attempts`] sends in all; then the index has failed. Any DL_VALUE
/// of an index reads it (a periodic one too: it carries the value in force), even after
/// it failed.
///
/// The monitor runs one sweep per aircraft ([`Monitor::read_settings`]) and passes the
/// requests through its request tracking ([`Monitor::get_setting_sent`]), which matches
/// the answers.
///
/// ```
/// use pprz_ground::settings::{Sweep, SweepConfig};
/// let mut sweep = Sweep::new(3, SweepConfig::default().outstanding(2).rate(100.0));
/// assert_eq!(sweep.due(0.0), [0, 1]);
/// sweep.answered(0.05, 0);
/// assert_eq!(sweep.due(0.05), [2]);
/// sweep.answered(0.1, 2);
/// assert!(sweep.due(0.5).is_empty());
/// // Index 1 was lost: sent again after a second.
/// assert_eq!(sweep.due(1.0), [1]);
/// sweep.answered(1.1, 1);
/// assert!(sweep.done());
/// assert_eq!(sweep.line(None), "settings: 3/3 read in 1.1 s");
/// ```
///
/// [`Monitor::read_settings`]: crate::monitor::Monitor::read_settings
/// [`Monitor::get_setting_sent`]: crate::monitor::Monitor::get_setting_sent
#[derive(Debug, Clone)]
pub struct Sweep {
    config: SweepConfig,
    states: Vec<State>,
    outstanding: usize,
    read: usize,
    failed: usize,
    sends: u64,
    /// The theoretical time of the next request, for the rate.
    next: f64,
    started: Option<f64>,
    ended: Option<f64>,
}

impl Sweep {
    /// A sweep of indices `0..count` (at most 256).
    pub fn new(count: usize, config: SweepConfig) -> Self {
        Self {
            config,
            states: vec![State::Waiting { sends: 0 }; count.min(256)],
            outstanding: 0,
            read: 0,
            failed: 0,
            sends: 0,
            next: f64::NEG_INFINITY,
            started: None,
            ended: None,
        }
    }

    /// The GET_SETTINGs to send at `now`, in index order: lost ones again (or given up
    /// after the last attempt), and new ones while fewer than
    /// [`outstanding`](SweepConfig::outstanding) wait and the
    /// [`rate`](SweepConfig::rate) allows. Each is counted as sent at `now` (a send that
    /// fails is a request lost). Call it often (every 10 to 50 ms): the rate sends at
    /// most [`burst`](SweepConfig::burst) at once.
    pub fn due(&mut self, now: f64) -> Vec<u8> {
        self.started.get_or_insert(now);
        for state in &mut self.states {
            if let State::Outstanding { at, sends } = *state {
                let wait = self.config.retry_after * f64::from(1u32 << (sends - 1).min(16));
                if now - at < wait {
                    continue;
                }
                self.outstanding -= 1;
                if sends >= self.config.attempts {
                    *state = State::Failed;
                    self.failed += 1;
                } else {
                    *state = State::Waiting { sends };
                }
            }
        }
        let mut out = Vec::new();
        for (index, state) in self.states.iter_mut().enumerate() {
            if self.outstanding >= self.config.outstanding {
                break;
            }
            if let State::Waiting { sends } = *state {
                if !self.config.admit(&mut self.next, now) {
                    break;
                }
                *state = State::Outstanding {
                    at: now,
                    sends: sends + 1,
                };
                self.outstanding += 1;
                self.sends += 1;
                out.push(index as u8);
            }
        }
        self.note_end(now);
        out
    }

    /// A DL_VALUE of `index` arrived at `now`: the index is read. Returns whether it
    /// was not read before.
    pub fn answered(&mut self, now: f64, index: u8) -> bool {
        let Some(state) = self.states.get_mut(usize::from(index)) else {
            return false;
        };
        match *state {
            State::Read => return false,
            State::Outstanding { .. } => self.outstanding -= 1,
            State::Failed => self.failed -= 1,
            State::Waiting { .. } => {}
        }
        *state = State::Read;
        self.read += 1;
        self.note_end(now);
        true
    }

    /// Notes the end, at `now`, once every index is read or failed.
    fn note_end(&mut self, now: f64) {
        if self.ended.is_none() && self.read + self.failed == self.states.len() {
            self.ended = Some(now);
        }
    }

    /// Whether every index is read or failed.
    pub fn done(&self) -> bool {
        self.ended.is_some()
    }

    /// Indices in the sweep.
    pub fn total(&self) -> usize {
        self.states.len()
    }

    /// Indices read.
    pub fn read(&self) -> usize {
        self.read
    }

    /// The indices that failed (no answer to any attempt), in order.
    pub fn failed(&self) -> Vec<u8> {
        (0..self.states.len())
            .filter(|&i| self.states[i] == State::Failed)
            .map(|i| i as u8)
            .collect()
    }

    /// GET_SETTINGs waiting for their answer.
    pub fn outstanding(&self) -> usize {
        self.outstanding
    }

    /// GET_SETTINGs sent so far, first sends and retries.
    pub fn sends(&self) -> u64 {
        self.sends
    }

    /// Seconds from the first request to the end; `None` before the end.
    pub fn duration(&self) -> Option<f64> {
        Some(self.ended? - self.started?)
    }

    /// `settings: 37/100 read` while it runs; at the end `settings: 100/100 read in
    /// 4.2 s`, with the settings that failed (named from `table` when given, the first
    /// [`MAX_NAMED_FAILURES`]).
    pub fn line(&self, table: Option<&SettingsTable>) -> String {
        progress_line(
            self.read,
            self.states.len(),
            self.duration(),
            &self.failed(),
            table,
        )
    }
}

/// The line of a sweep: `settings: READ/TOTAL read`, and at its end (`seconds` known)
/// ` in S s`, then the failed settings (the first [`MAX_NAMED_FAILURES`], named from
/// `table` when given).
pub fn progress_line(
    read: usize,
    total: usize,
    seconds: Option<f64>,
    failed: &[u8],
    table: Option<&SettingsTable>,
) -> String {
    let Some(seconds) = seconds else {
        return format!("settings: {read}/{total} read");
    };
    let mut s = format!("settings: {read}/{total} read in {seconds:.1} s");
    if !failed.is_empty() {
        let names: Vec<String> = failed
            .iter()
            .take(MAX_NAMED_FAILURES)
            .map(|&i| match table {
                Some(t) => t.describe(i),
                None => format!("index {i}"),
            })
            .collect();
        s.push_str(&format!(
            "; {} failed (no answer): {}",
            failed.len(),
            names.join(", ")
        ));
        if failed.len() > MAX_NAMED_FAILURES {
            s.push_str(&format!(" and {} more", failed.len() - MAX_NAMED_FAILURES));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paced_by_the_outstanding_bound() {
        let mut s = Sweep::new(20, SweepConfig::default().outstanding(4).rate(1e3).burst(8));
        assert_eq!(s.due(0.0), [0, 1, 2, 3]);
        assert!(s.due(0.01).is_empty(), "four wait");
        for i in 0..3 {
            s.answered(0.02, i);
        }
        assert_eq!(s.due(0.02), [4, 5, 6]);
        assert_eq!(s.outstanding(), 4);
        assert_eq!(s.line(None), "settings: 3/20 read");
        // A DL_VALUE of an index not asked yet (periodic) reads it too.
        assert!(s.answered(0.03, 19));
        assert!(!s.answered(0.03, 19), "once");
        assert!(!s.answered(0.03, 200), "beyond the sweep");
        assert_eq!(s.read(), 4);
    }

    /// Lost requests are sent again with a doubling wait, then given up; a late answer
    /// still reads the index.
    #[test]
    fn lost_requests_are_retried_then_given_up() {
        let config = SweepConfig::default()
            .outstanding(2)
            .retry_after(0.5)
            .attempts(3);
        let mut s = Sweep::new(3, config);
        assert_eq!(s.due(10.0), [0, 1]);
        s.answered(10.1, 0);
        assert_eq!(s.due(10.1), [2]);
        s.answered(10.2, 2);
        // Index 1 never answers: sent again at 10.5 (0.5 s), 11.5 (1 s later), then
        // given up at 13.5 (2 s after the third send).
        assert!(s.due(10.49).is_empty());
        assert_eq!(s.due(10.5), [1]);
        assert!(s.due(11.49).is_empty());
        assert_eq!(s.due(11.5), [1]);
        assert!(s.due(13.49).is_empty());
        assert!(!s.done());
        assert!(s.due(13.5).is_empty());
        assert!(s.done());
        assert_eq!(s.failed(), [1]);
        assert_eq!(s.sends(), 5);
        assert_eq!(
            s.line(None),
            "settings: 2/3 read in 3.5 s; 1 failed (no answer): index 1"
        );
        // The answer comes after all: read.
        assert!(s.answered(14.0, 1));
        assert_eq!((s.read(), s.failed().len()), (3, 0));
        assert_eq!(s.line(None), "settings: 3/3 read in 3.5 s");
    }

    #[test]
    fn an_empty_sweep_ends_at_once_and_failures_are_listed_within_a_bound() {
        let mut s = Sweep::new(0, SweepConfig::default());
        assert!(s.due(1.0).is_empty());
        assert_eq!(s.line(None), "settings: 0/0 read in 0.0 s");
        let config = SweepConfig::default()
            .outstanding(256)
            .attempts(1)
            .rate(1e6)
            .burst(100);
        let mut s = Sweep::new(12, config);
        assert_eq!(s.due(0.0).len(), 12);
        assert!(s.due(1.0).is_empty());
        let line = s.line(None);
        assert!(line.ends_with("index 7 and 4 more"), "{line}");
        assert!(line.contains("12 failed"), "{line}");
    }

    /// At 15 per second, 4 at once: the aircraft's reply limit (20 per second, 10 at
    /// once) is never exceeded, however often the sweep is asked.
    #[test]
    fn paced_by_the_rate() {
        let mut s = Sweep::new(100, SweepConfig::default().outstanding(100));
        let mut sent = Vec::new();
        for step in 0..1000 {
            let now = f64::from(step) * 0.01;
            for i in s.due(now) {
                sent.push(now);
                s.answered(now, i);
            }
        }
        assert_eq!(sent.len(), 100);
        assert_eq!(&sent[..5], &[0.0, 0.0, 0.0, 0.0, 0.07]);
        // In any second, at most 15 + 3 (the burst beyond the rate).
        for (i, &t) in sent.iter().enumerate() {
            let within = sent[i..].iter().take_while(|&&u| u < t + 1.0).count();
            assert!(within <= 18, "{within} in the second from {t}");
        }
        let last = *sent.last().unwrap();
        assert!((6.3..6.5).contains(&last), "{last}");
    }

    #[test]
    fn the_config_stays_sane() {
        let c = SweepConfig::default()
            .outstanding(0)
            .retry_after(f64::NAN)
            .attempts(0)
            .rate(-1.0)
            .burst(0);
        assert_eq!((c.outstanding, c.retry_after, c.attempts), (1, 1.0, 1));
        assert_eq!((c.rate, c.burst), (15.0, 1));
        assert_eq!(SweepConfig::default().outstanding(1000).outstanding, 256);
    }
}
