//! Named settings in the monitor: names, labels and display units in its events, lines
//! and views, and the reading of every setting on explicit time, with lost requests.

use std::sync::Arc;

use super::*;
use crate::settings::{SettingsTable, SweepConfig};
use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};

const XML: &str = r#"<protocol>
  <msg_class name="telemetry" id="1">
    <message name="DL_VALUE" id="31"><field name="index" type="uint8"/><field name="value" type="float"/></message>
  </msg_class>
  <msg_class name="datalink" id="2">
    <message name="SETTING" id="4"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
  </msg_class></protocol>"#;

/// The example application's four settings.
const APP: &str = r#"<settings><dl_settings><dl_settings name="app">
  <dl_setting var="telemetry_mode" min="0" max="2" values="default|debug|minimal"/>
  <dl_setting var="payload_flood" min="0" max="1" values="OFF|ON"/>
  <dl_setting var="gain" min="0" max="10" step="0.1" persistent="true"/>
  <dl_setting var="ap_mode" min="0" max="19" values="KILL|FAILSAFE|HOME|RATE_DIRECT|ATTITUDE_DIRECT|RATE_RC_CLIMB|ATTITUDE_RC_CLIMB|ATTITUDE_CLIMB|RATE_Z_HOLD|ATTITUDE_Z_HOLD|HOVER_DIRECT|HOVER_CLIMB|HOVER_Z_HOLD|NAV|RC_DIRECT|CARE_FREE|FORWARD|MODULE|FLIP|GUIDED"/>
  <dl_setting var="ins.roll_neutral" shortname="roll" min="-15" max="15" unit="rad" alt_unit="deg"/>
</dl_settings></dl_settings></settings>"#;

/// A file of `n` settings `s0`, `s1`, ..., each 0 to 100.
fn many(n: usize) -> String {
    let mut xml = String::from("<settings><dl_settings>");
    for i in 0..n {
        xml.push_str(&format!(r#"<dl_setting var="s{i}" min="0" max="100"/>"#));
    }
    xml.push_str("</dl_settings></settings>");
    xml
}

fn monitor(settings: &str) -> Monitor {
    let set = RuntimeSet::parse("t.xml", XML).unwrap();
    let table = SettingsTable::parse(&[("s.xml", settings)]).unwrap();
    Monitor::new(set, PprzV2::new().into()).with_settings(Arc::new(table))
}

fn dl_value(index: u8, value: f32) -> Vec<u8> {
    let mut p = vec![index];
    p.extend(value.to_le_bytes());
    let mut buf = [0u8; 64];
    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 31));
    let n = PprzV2::new().encode(&meta, &p, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn feed(m: &mut Monitor, now: f64, bytes: &[u8]) -> Vec<String> {
    let mut lines = Vec::new();
    m.feed(now, bytes, |d| lines.push(d.line.to_owned()));
    lines
}

#[test]
fn settings_are_named_labelled_and_shown_in_their_display_unit() {
    let mut m = monitor(APP);
    let lines = feed(&mut m, 0.1, &dl_value(3, 13.0));
    assert_eq!(
        lines,
        ["7 telemetry DL_VALUE index=3 value=13 setting=ap_mode"]
    );
    let roll = (10.0f64 / (180.0 / std::f64::consts::PI)) as f32;
    m.setting_sent(Some(7), 0.2, 4, f64::from(roll));
    feed(&mut m, 0.25, &dl_value(4, roll));
    // An index beyond the files: as before, by index.
    let lines = feed(&mut m, 0.3, &dl_value(9, 1.0));
    assert_eq!(lines, ["7 telemetry DL_VALUE index=9 value=1"]);
    let events: Vec<String> = m
        .events_with_aircraft()
        .map(|(_, ac, e)| m.event_line(ac, e))
        .collect();
    assert_eq!(
        events,
        [
            "DL_VALUE ap_mode (index 3) = NAV (13)",
            "DL_VALUE roll (index 4) = 10 deg: SETTING acknowledged after 50.0 ms",
            "DL_VALUE index=9 value=1",
        ]
    );
    let view = m.render(1.0);
    for expected in [
        "settings: 2 of 5 known (index, name, value, bounds)",
        "    0 telemetry_mode           ?                    [0, 2]",
        "    3 ap_mode                  NAV (13)             [0, 19]",
        "    4 roll                     10 deg               [-15, 15] deg",
    ] {
        assert!(view.contains(expected), "{expected}\n{view}");
    }
    let summary = m.summary(1.0);
    assert!(
        summary.contains("    2 gain                     ?"),
        "{summary}"
    );
    // A SETTING the aircraft does not apply is named, its values shown.
    m.setting_sent(Some(7), 2.0, 2, 12.0);
    feed(&mut m, 2.1, &dl_value(2, 2.5));
    m.tick(8.0);
    let notice = m
        .notices_with_aircraft()
        .map(|(_, ac, n)| m.notice_line(ac, n))
        .last()
        .unwrap();
    assert_eq!(
        notice,
        "SETTING gain (index 2) to 12 not applied: the aircraft still reports 2.5"
    );
}

/// The aircraft of the test: answers each GET_SETTING `latency` seconds later, except
/// the first requests of `lost_once` and every request of `never`.
struct Aircraft {
    latency: f64,
    lost_once: Vec<u8>,
    never: Vec<u8>,
    answers: Vec<(f64, u8)>,
}

impl Aircraft {
    fn request(&mut self, now: f64, index: u8) {
        if self.never.contains(&index) {
            return;
        }
        if let Some(at) = self.lost_once.iter().position(|&i| i == index) {
            self.lost_once.remove(at);
            return;
        }
        self.answers.push((now + self.latency, index));
    }

    /// The answers due by `now`.
    fn due(&mut self, now: f64) -> Vec<u8> {
        let (due, later): (Vec<_>, Vec<_>) = self.answers.iter().partition(|(t, _)| *t <= now);
        self.answers = later;
        due.into_iter().map(|(_, i)| i).collect()
    }
}

/// Runs a sweep of `n` settings against `aircraft` in steps of 10 ms until it ends (at
/// most `limit` seconds); returns the monitor and the progress lines seen. The rate is
/// out of the way here (an aircraft of the test answers everything).
fn sweep(n: usize, aircraft: &mut Aircraft, limit: f64) -> (Monitor, Vec<String>) {
    let mut m = monitor(&many(n));
    m.read_settings(7, n, SweepConfig::default().rate(1e3).burst(8));
    let mut progress = Vec::new();
    let mut step = 0u32;
    while m.sweeping() {
        let now = f64::from(step) * 0.01;
        assert!(now <= limit, "not done in {limit} s");
        for (ac, index) in m.sweep_requests(now) {
            assert_eq!(ac, 7);
            m.get_setting_sent(Some(7), now, index);
            aircraft.request(now, index);
        }
        assert!(m.aircraft_state(7).unwrap().sweep().unwrap().outstanding() <= 8);
        for index in aircraft.due(now) {
            feed(&mut m, now, &dl_value(index, f32::from(index)));
        }
        m.tick(now);
        let line = m.aircraft_state(7).unwrap().sweep().unwrap().line(None);
        if progress.last() != Some(&line) {
            progress.push(line);
        }
        step += 1;
    }
    (m, progress)
}

#[test]
fn a_sweep_reads_every_setting_paced_and_retries_lost_requests() {
    let mut aircraft = Aircraft {
        latency: 0.05,
        lost_once: vec![3, 11, 11],
        never: Vec::new(),
        answers: Vec::new(),
    };
    let (m, progress) = sweep(40, &mut aircraft, 10.0);
    let a = m.aircraft_state(7).unwrap();
    let s = a.sweep().unwrap();
    assert_eq!((s.read(), s.total(), s.failed().len()), (40, 40, 0));
    // 8 at a time, 60 ms a round (50 ms, and the next 10 ms step): index 11, sent at
    // 0.06 s, is lost, sent again at 1.06 s, lost, and again at 3.06 s (2 s later).
    assert_eq!(s.sends(), 43);
    let seconds = s.duration().unwrap();
    assert!((seconds - 3.11).abs() < 1e-9, "{seconds}");
    assert_eq!(progress[0], "settings: 0/40 read");
    assert!(
        progress.contains(&"settings: 7/40 read".to_owned()),
        "{progress:?}"
    );
    assert!(progress.contains(&"settings: 39/40 read".to_owned()));
    assert_eq!(progress.last().unwrap(), "settings: 40/40 read in 3.1 s");
    assert_eq!(a.setting_values().len(), 40);
    assert_eq!(a.setting_values()[&39], 39.0);
    // The request tracking matched every answer: nothing pending, nothing unanswered.
    assert_eq!((a.settings().pending(), a.settings().unanswered()), (0, 0));
    let (_, ac, e) = m.events_with_aircraft().last().unwrap();
    assert_eq!(m.event_line(ac, e), "settings: 40/40 read in 3.1 s");
}

#[test]
fn a_sweep_names_the_settings_that_never_answer() {
    let mut aircraft = Aircraft {
        latency: 0.02,
        lost_once: Vec::new(),
        never: vec![5, 17],
        answers: Vec::new(),
    };
    let (m, _) = sweep(20, &mut aircraft, 30.0);
    let s = m.aircraft_state(7).unwrap().sweep().unwrap();
    assert_eq!(s.failed(), [5, 17]);
    // Index 17 is first sent at 0.06 s, then 1, 2 and 4 s after each send, and given
    // up 8 s after the last: at 15.06 s.
    assert_eq!(s.sends(), 20 + 2 * 3);
    let seconds = s.duration().unwrap();
    assert!((seconds - 15.06).abs() < 1e-9, "{seconds}");
    let (_, ac, e) = m.events_with_aircraft().last().unwrap();
    assert_eq!(
        m.event_line(ac, e),
        "settings: 18/20 read in 15.1 s; 2 failed (no answer): s5 (index 5), s17 (index 17)"
    );
    let summary = m.summary(16.0);
    assert!(
        summary.contains("settings: 18/20 read in 15.1 s; 2 failed"),
        "{summary}"
    );
    assert!(
        summary.contains("    5 s5                       ?"),
        "{summary}"
    );
}
