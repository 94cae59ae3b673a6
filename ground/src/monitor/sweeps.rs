//! Named settings: the settings files' table, the latest value of each setting per
//! aircraft, and the reading of every setting ([`Sweep`]).

use std::sync::Arc;

use super::{Event, Monitor};
use crate::settings::{SettingsTable, Sweep, SweepConfig};

impl Monitor {
    /// The same monitor naming the settings after `table` (the aircraft's settings
    /// files): events, notices, the live view and the summary show names, values with
    /// their labels and display units, and bounds.
    pub fn with_settings(mut self, table: Arc<SettingsTable>) -> Self {
        self.table = Some(table);
        self
    }

    /// The settings files' table, if given.
    pub fn settings_table(&self) -> Option<&SettingsTable> {
        self.table.as_deref()
    }

    /// Starts reading settings `0..count` of aircraft `ac_id` (tracked from now on),
    /// paced by `config`: [`sweep_requests`](Self::sweep_requests) gives the
    /// GET_SETTINGs to send. A sweep already running for the aircraft is replaced.
    ///
    /// ```
    /// # use pprz_ground::{monitor::Monitor, set::RuntimeSet, settings::SweepConfig};
    /// # use pprz_transports::PprzV2;
    /// # let set = RuntimeSet::parse("m.xml", "<protocol></protocol>").unwrap();
    /// let mut monitor = Monitor::new(set, PprzV2::new().into());
    /// monitor.read_settings(7, 100, SweepConfig::default());
    /// // 4 at once, then 15 per second.
    /// let first = monitor.sweep_requests(0.0);
    /// assert_eq!(first, [(7, 0), (7, 1), (7, 2), (7, 3)]);
    /// // Send each, then tell the monitor:
    /// for &(ac, index) in &first {
    ///     monitor.get_setting_sent(Some(ac), 0.0, index);
    /// }
    /// assert_eq!(monitor.aircraft_state(7).unwrap().settings().pending(), 4);
    /// ```
    pub fn read_settings(&mut self, ac_id: u8, count: usize, config: SweepConfig) {
        self.addressed(ac_id).sweep = Some(Sweep::new(count, config));
    }

    /// The GET_SETTINGs the sweeps want sent at `now`, as `(aircraft, index)`: send
    /// each, then record it with [`get_setting_sent`](Self::get_setting_sent) so that
    /// its DL_VALUE is matched. A sweep that ends (its last requests given up) is noted
    /// ([`Event::SettingsRead`]).
    pub fn sweep_requests(&mut self, now: f64) -> Vec<(u8, u8)> {
        self.advance(now);
        let mut out = Vec::new();
        let mut ended = Vec::new();
        for (&id, a) in &mut self.aircraft {
            let Some(sweep) = a.sweep.as_mut().filter(|s| !s.done()) else {
                continue;
            };
            out.extend(sweep.due(now).into_iter().map(|i| (id, i)));
            if sweep.done() {
                ended.push(id);
            }
        }
        for id in ended {
            self.sweep_ended(now, id);
        }
        out
    }

    /// Whether a sweep of any aircraft is still running.
    pub fn sweeping(&self) -> bool {
        self.aircraft
            .values()
            .any(|a| a.sweep.as_ref().is_some_and(|s| !s.done()))
    }

    /// Notes the end of aircraft `ac_id`'s sweep.
    pub(super) fn sweep_ended(&mut self, now: f64, ac_id: u8) {
        let Some(s) = self.aircraft.get(&ac_id).and_then(|a| a.sweep.as_ref()) else {
            return;
        };
        let event = Event::SettingsRead {
            read: s.read(),
            total: s.total(),
            seconds: s.duration().unwrap_or(0.0),
            failed: s.failed(),
        };
        self.event(now, Some(ac_id), event);
    }

    /// The latest value aircraft `ac_id` reported for setting `index` (DL_VALUE), in
    /// its own units.
    pub fn setting_value(&self, ac_id: u8, index: u8) -> Option<f64> {
        self.aircraft.get(&ac_id)?.values.get(&index).copied()
    }
}
