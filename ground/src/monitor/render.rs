//! Rendering: the live view, the summary at the end of a run, and the text of events
//! and notices.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::state::{Aircraft, MessageStats};
use super::{Event, LinkQuality, LinkState, MAX_AIRCRAFT, Monitor, Notice};
use crate::format;
use crate::ping::PingTracker;
use crate::settings::{Answer, Expired, SettingTracker, SettingsTable, progress_line};

impl Monitor {
    /// An event as a line of the live view: [`describe_event`], after `aircraft N: `
    /// when [`several_aircraft`](Self::several_aircraft) and the event is about one.
    /// With a settings table ([`with_settings`](Self::with_settings)), settings are named
    /// and their values shown with labels and display units.
    pub fn event_line(&self, aircraft: Option<u8>, event: &Event) -> String {
        self.about(aircraft) + &event_text(event, self.names())
    }

    /// A notice as a line of the live view, named after its aircraft as
    /// [`event_line`](Self::event_line) does (a link notice always names its
    /// aircraft).
    pub fn notice_line(&self, aircraft: Option<u8>, notice: &Notice) -> String {
        match notice {
            Notice::LinkStale { .. } | Notice::LinkLive { .. } => describe_notice(notice),
            _ => self.about(aircraft) + &notice_text(notice, self.names()),
        }
    }

    /// The link line of aircraft `ac_id` at `now`: `aircraft N link: ` and its
    /// [`link_quality`](Self::link_quality) (`live, heard 0.2 s ago`, or `stale, not
    /// heard for 6.0 s`, then the figures known); `None` when it is not tracked.
    pub fn link_line(&self, ac_id: u8, now: f64) -> Option<String> {
        Some(format!(
            "aircraft {ac_id} link: {}",
            self.link_body(ac_id, now)?
        ))
    }

    /// The text of [`link_line`](Self::link_line) after `link: `.
    fn link_body(&self, ac_id: u8, now: f64) -> Option<String> {
        self.aircraft.get(&ac_id)?;
        Some(
            self.link_quality(ac_id, now)
                .map_or_else(|| "not heard".to_owned(), |q| link_text(&q)),
        )
    }

    /// How settings are named: after the table, if any.
    fn names(&self) -> Names<'_> {
        Names(self.table.as_deref())
    }

    /// The PING and SETTING statistics of aircraft `a`, and its sweep's line.
    fn aircraft_uplink(&self, a: &Aircraft) -> Vec<String> {
        let mut out = uplink_lines(&a.pings, &a.settings, self.names());
        out.extend(a.sweep.as_ref().map(|s| s.line(self.table.as_deref())));
        out
    }

    /// The settings of aircraft `a`, one a line, when the monitor has a table.
    fn settings_section(&self, a: &Aircraft) -> Vec<String> {
        self.table
            .as_deref()
            .map_or_else(Vec::new, |t| settings_lines(t, a))
    }

    /// `aircraft N: ` with several aircraft, or nothing.
    fn about(&self, aircraft: Option<u8>) -> String {
        match aircraft {
            Some(id) if self.several_aircraft() => format!("aircraft {id}: "),
            _ => String::new(),
        }
    }

    /// The status line: time, byte rate and every counter of lost or rejected input.
    fn status(&self, now: f64) -> String {
        let st = self.decoder.stats();
        format!(
            "t={now:7.1}s  {:>7} B/s  frames ok {}  checksum errors {}  length errors {}  dropped bytes {}  unknown {}  malformed {}  input dropped {} B in {} reads",
            rate_text(self.byte_rate(now), 0),
            st.frames,
            st.checksum_errors,
            st.length_errors,
            st.dropped_bytes,
            self.unknown,
            self.malformed,
            self.input_dropped.bytes,
            self.input_dropped.reads,
        )
    }

    /// PING and SETTING statistics of the requests to no particular aircraft and, with
    /// a single aircraft, of those addressed to it, when there were any.
    fn uplink_status(&self) -> Vec<String> {
        let mut out = uplink_lines(&self.pings, &self.settings, self.names());
        if !self.several_aircraft()
            && let Some(a) = self.aircraft.values().next()
        {
            out.extend(self.aircraft_uplink(a));
        }
        out
    }

    /// The aircraft tracked, and the frames of those not tracked, with several
    /// aircraft.
    fn fleet_line(&self) -> Option<String> {
        if !self.several_aircraft() {
            return None;
        }
        let ids: Vec<String> = self.aircraft.keys().map(u8::to_string).collect();
        let mut s = format!("aircraft: {}", ids.join(", "));
        if self.untracked_frames > 0 {
            let _ = write!(
                s,
                "  not tracked (more than {MAX_AIRCRAFT} aircraft): {} frames from {} aircraft",
                self.untracked_frames,
                self.untracked_aircraft()
            );
        }
        Some(s)
    }

    /// With a single aircraft, its link (`link: ...`, as in
    /// [`link_line`](Self::link_line)), once it is heard.
    fn single_link_line(&self, now: f64) -> Option<String> {
        let a = self.aircraft.values().find(|a| a.frames > 0)?;
        Some(format!("link: {}", self.link_body(a.id, now)?))
    }

    /// The secure link's status lines, if the monitor has one.
    pub fn secure_lines(&self) -> Vec<String> {
        self.secure_status()
            .map(|s| s.lines().to_vec())
            .unwrap_or_default()
    }

    /// The live view: the status, a table of messages, the latest events and notices.
    /// With [`several_aircraft`](Self::several_aircraft), a line listing them, then a
    /// section per aircraft (`aircraft N: frames ...`, its PINGs and SETTINGs, its link
    /// report, its table), and the events and notices name their aircraft.
    pub fn render(&self, now: f64) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "{}", self.status(now));
        for line in self.secure_lines() {
            let _ = writeln!(s, "{line}");
        }
        for line in self.uplink_status() {
            let _ = writeln!(s, "{line}");
        }
        match self.fleet_line() {
            None => {
                if let Some(report) = &self.last_report {
                    let _ = writeln!(s, "aircraft link report: {report}");
                }
                if let Some(line) = self.single_link_line(now) {
                    let _ = writeln!(s, "{line}");
                }
                table(&mut s, &self.messages, now);
                for a in self.aircraft.values().take(1) {
                    for line in self.settings_section(a) {
                        let _ = writeln!(s, "{line}");
                    }
                }
            }
            Some(fleet) => {
                let _ = writeln!(s, "{fleet}");
                for a in self.aircraft.values() {
                    let _ = writeln!(s, "{}", aircraft_head(a));
                    for line in self.aircraft_uplink(a) {
                        let _ = writeln!(s, "{line}");
                    }
                    if let Some(report) = &a.last_report {
                        let _ = writeln!(s, "aircraft link report: {report}");
                    }
                    if let Some(line) = self.link_line(a.id, now) {
                        let _ = writeln!(s, "{line}");
                    }
                    table(&mut s, &a.messages, now);
                    for line in self.settings_section(a) {
                        let _ = writeln!(s, "{line}");
                    }
                }
            }
        }
        for (t, ac, e) in self.events_with_aircraft() {
            let _ = writeln!(s, "[{t:7.1}s] {}", self.event_line(ac, e));
        }
        for (t, ac, n) in self.notices_with_aircraft() {
            let _ = writeln!(s, "[{t:7.1}s] {}", self.notice_line(ac, n));
        }
        s
    }

    /// Messages received per priority level (all aircraft), as a short table.
    pub fn priority_summary(&self) -> String {
        priority_line(&self.per_priority())
    }

    /// The summary of aircraft `ac_id`: `aircraft N: frames F  unknown U  malformed M`,
    /// then, indented, its messages per priority level, its PING and SETTING
    /// statistics, its sweep and (with a settings table) its settings; `None` when the
    /// aircraft is not tracked.
    pub fn aircraft_summary(&self, ac_id: u8) -> Option<String> {
        let a = self.aircraft.get(&ac_id)?;
        let mut s = aircraft_head(a);
        let levels = priority_line(&a.per_priority());
        let lines = std::iter::once(levels)
            .chain(self.aircraft_uplink(a))
            .chain(self.settings_section(a));
        for line in lines {
            let _ = write!(s, "\n  {line}");
        }
        Some(s)
    }

    /// The summary at the end of a run: the status line (with the input dropped under
    /// overload), PING and SETTING statistics, messages per priority level and, with a
    /// single aircraft heard, its link (`link: ...`); with
    /// [`several_aircraft`](Self::several_aircraft), then the aircraft and the
    /// [`aircraft_summary`](Self::aircraft_summary) of each, with its link (`  link:
    /// ...`).
    pub fn summary(&self, now: f64) -> String {
        let mut s = self.status(now);
        for line in self.secure_lines().into_iter().chain(self.uplink_status()) {
            s.push('\n');
            s.push_str(&line);
        }
        s.push('\n');
        s.push_str(&self.priority_summary());
        let Some(fleet) = self.fleet_line() else {
            if let Some(line) = self.single_link_line(now) {
                s.push('\n');
                s.push_str(&line);
            }
            for a in self.aircraft.values().take(1) {
                for line in self.settings_section(a) {
                    s.push('\n');
                    s.push_str(&line);
                }
            }
            return s;
        };
        s.push('\n');
        s.push_str(&fleet);
        for id in self.aircraft.keys() {
            if let Some(a) = self.aircraft_summary(*id) {
                s.push('\n');
                s.push_str(&a);
            }
            if let Some(body) = self.link_body(*id, now) {
                s.push_str("\n  link: ");
                s.push_str(&body);
            }
        }
        s
    }
}

/// `received per priority level:  2: 10  1: 230`.
fn priority_line(levels: &BTreeMap<std::cmp::Reverse<u8>, u64>) -> String {
    let mut s = String::from("received per priority level:");
    for (p, n) in levels {
        let _ = write!(s, "  {}: {n}", p.0);
    }
    s
}

/// The first line of an aircraft's section or summary.
fn aircraft_head(a: &Aircraft) -> String {
    format!(
        "aircraft {}: frames {}  unknown {}  malformed {}",
        a.id, a.frames, a.unknown, a.malformed
    )
}

/// The table of `messages` of the live view, with its header.
fn table(s: &mut String, messages: &BTreeMap<(u8, u8), MessageStats>, now: f64) {
    let _ = writeln!(
        s,
        "{:<10} {:<20} {:>4} {:>7} {:>7}  last values",
        "class", "message", "prio", "count", "rate/s"
    );
    for m in messages.values() {
        let mut last = m.last.clone();
        format::truncate(&mut last, 110);
        let _ = writeln!(
            s,
            "{:<10} {:<20} {:>4} {:>7} {:>7}  {last}",
            m.class,
            m.name,
            m.priority,
            m.count,
            rate_text(m.rate(now), 1)
        );
    }
}

/// PING and SETTING statistics of a pair of trackers, when there were any.
fn uplink_lines(pings: &PingTracker, settings: &SettingTracker, names: Names<'_>) -> Vec<String> {
    let mut out = Vec::new();
    let p = pings;
    if p.sent_count() > 0 || p.unexpected() > 0 {
        let mut s = format!(
            "pings: sent {}  answered {}  lost {}  outstanding {}  unexpected pongs {}",
            p.sent_count(),
            p.answered(),
            p.lost(),
            p.outstanding(),
            p.unexpected()
        );
        if let Some(rtt) = p.last_rtt() {
            let _ = write!(s, "  last round trip {:.1} ms", rtt * 1e3);
        }
        out.push(s);
    }
    let st = settings;
    if st.acknowledged() + st.not_applied() + st.unanswered() > 0 || st.pending() > 0 {
        out.push(format!(
            "settings: acknowledged {}  not applied {}  unanswered {}  pending {}",
            st.acknowledged(),
            st.not_applied(),
            st.unanswered(),
            st.pending()
        ));
        for p in st.pending_requests() {
            let setting = names.setting(p.index);
            out.push(match p {
                Expired {
                    index,
                    requested: Some(requested),
                    reported: Some(reported),
                } => format!(
                    "  pending: SETTING {setting} to {}: not applied so far, the aircraft reports {}",
                    names.value(index, requested),
                    names.value(index, reported)
                ),
                Expired {
                    index,
                    requested: Some(requested),
                    reported: None,
                } => format!(
                    "  pending: SETTING {setting} to {}: no answer yet",
                    names.value(index, requested)
                ),
                Expired { .. } => {
                    format!("  pending: request for setting {setting}: no answer yet")
                }
            });
        }
    }
    out
}

/// The settings of aircraft `a` after `table`: a head line, then per setting its
/// index, name, latest value (`?` before any) and bounds.
fn settings_lines(table: &SettingsTable, a: &Aircraft) -> Vec<String> {
    let known = (0..table.len())
        .filter(|&i| a.values.contains_key(&(i as u8)))
        .count();
    let mut out = vec![format!(
        "settings: {known} of {} known (index, name, value, bounds)",
        table.len()
    )];
    for def in &table.set().settings {
        let value = a
            .values
            .get(&def.index)
            .map_or_else(|| "?".to_owned(), |&v| table.show(def.index, v));
        out.push(format!(
            "  {:>3} {:<24} {:<20} {}",
            def.index,
            crate::settings::text(def.name()),
            value,
            table.bounds(def.index).unwrap_or_default()
        ));
    }
    out
}

/// How settings are named in the text of events, notices and pending requests.
#[derive(Clone, Copy)]
struct Names<'a>(Option<&'a SettingsTable>);

impl Names<'_> {
    /// `index=N`, or `NAME (index N)` with a table that has it.
    fn setting(self, index: u8) -> String {
        match self.0.filter(|t| t.get(index).is_some()) {
            Some(t) => t.describe(index),
            None => format!("index={index}"),
        }
    }

    /// A value of setting `index`: the number, or as the table shows it.
    fn value(self, index: u8, v: f64) -> String {
        match self.0.filter(|t| t.get(index).is_some()) {
            Some(t) => t.show(index, v),
            None => number(v),
        }
    }
}

/// A link quality as text: the state, then the figures known.
fn link_text(q: &LinkQuality) -> String {
    let mut s = match q.state {
        LinkState::Live => format!("live, heard {:.1} s ago", q.since_heard),
        LinkState::Stale => format!("stale, not heard for {:.1} s", q.since_heard),
    };
    if let Some(t) = q.uplink_lost_time {
        let _ = write!(s, "  uplink lost {t} s");
    }
    if let Some(dbm) = q.rssi_dbm {
        let _ = write!(s, "  RSSI {dbm} dBm");
        if let Some(p) = q.tx_power_db {
            let _ = write!(s, " (tx power {p} dB)");
        }
    }
    if let Some(dbm) = q.ground_rssi_dbm {
        let _ = write!(s, "  ground RSSI {dbm} dBm");
        if let Some(mean) = q.ground_rssi_mean_dbm {
            let _ = write!(s, " (mean {mean:.1} dBm)");
        }
    }
    if let Some(loss) = q.loss_rate {
        let _ = write!(
            s,
            "  downlink loss {:.1}% over the last report period",
            loss * 100.0
        );
        if let Some(all) = q.loss_overall {
            let _ = write!(s, " ({:.1}% overall)", all * 100.0);
        }
    }
    if let Some(mode) = &q.ap_mode {
        let _ = write!(s, "  mode {mode}");
    }
    s
}

/// A rate with `decimals` decimals, or `-` when there is none yet.
fn rate_text(rate: Option<f64>, decimals: usize) -> String {
    rate.map_or_else(|| "-".to_owned(), |r| format!("{r:.decimals$}"))
}

/// A value read from the wire: a value that is exactly a `float` is written as the
/// `float` (`0.1`, not `0.10000000149011612`).
fn number(v: f64) -> String {
    let single = v as f32;
    if f64::from(single) == v {
        single.to_string()
    } else {
        v.to_string()
    }
}

/// An event as a line of the live view (settings by index).
pub fn describe_event(e: &Event) -> String {
    event_text(e, Names(None))
}

/// An event as a line, settings named by `names`.
fn event_text(e: &Event, names: Names<'_>) -> String {
    match e {
        Event::Pong { rtt } => format!("PONG: round trip {:.1} ms", rtt * 1e3),
        Event::DlValue {
            index,
            value,
            answer,
        } => {
            let head = match names.0.filter(|t| t.get(*index).is_some()) {
                Some(_) => format!(
                    "DL_VALUE {} = {}",
                    names.setting(*index),
                    names.value(*index, *value)
                ),
                None => format!("DL_VALUE index={index} value={}", number(*value)),
            };
            match answer {
                Answer::Unsolicited => head,
                Answer::Acknowledged { after } => {
                    format!("{head}: SETTING acknowledged after {:.1} ms", after * 1e3)
                }
                Answer::NotApplied { requested, after } => format!(
                    "{head}: SETTING to {} not applied ({:.1} ms after it was sent)",
                    names.value(*index, *requested),
                    after * 1e3
                ),
                Answer::Answered { after } => {
                    format!("{head}: answer after {:.1} ms", after * 1e3)
                }
            }
        }
        Event::SettingsRead {
            read,
            total,
            seconds,
            failed,
        } => progress_line(*read, *total, Some(*seconds), failed, names.0),
        Event::SecureSession { completed } => {
            format!("secure session established (handshake {completed})")
        }
    }
}

/// A notice as a line of the live view (settings by index).
pub fn describe_notice(n: &Notice) -> String {
    notice_text(n, Names(None))
}

/// A notice as a line, settings named by `names`.
fn notice_text(n: &Notice, names: Names<'_>) -> String {
    match n {
        Notice::PingsLost { count } => format!("{count} PING(s) lost: no PONG in time"),
        Notice::UnexpectedPong => "PONG that answers no PING outstanding".into(),
        Notice::RequestExpired(Expired {
            index,
            requested: Some(requested),
            reported: Some(reported),
        }) => format!(
            "SETTING {} to {} not applied: the aircraft still reports {}",
            names.setting(*index),
            names.value(*index, *requested),
            names.value(*index, *reported)
        ),
        Notice::RequestExpired(Expired {
            index,
            requested: Some(requested),
            reported: None,
        }) => format!(
            "SETTING {} to {}: no answer",
            names.setting(*index),
            names.value(*index, *requested)
        ),
        Notice::RequestExpired(Expired { index, .. }) => {
            format!("request for setting {}: no answer", names.setting(*index))
        }
        Notice::InputDropped(d) => format!(
            "input overload: dropped {} bytes in {} reads",
            d.bytes, d.reads
        ),
        Notice::SecureRejected { reason, count } => {
            format!("{count} frame(s) rejected by the secure link: {reason}")
        }
        Notice::HandshakeRefused(e) => format!("key exchange from the aircraft refused: {e}"),
        Notice::LinkStale { aircraft, silent } => {
            format!("aircraft {aircraft}: link stale, not heard for {silent:.1} s")
        }
        Notice::LinkLive { aircraft, silent } => {
            format!("aircraft {aircraft}: link live again after {silent:.1} s")
        }
    }
}
