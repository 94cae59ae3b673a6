//! Link quality: stale marking with explicit times, RSSI (the aircraft's message and the
//! ground modem's), the downlink loss estimate, the autopilot mode, and hostile input.

use super::*;
use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta, XBee24};

/// The project's message set (RSSI, DATALINK_REPORT, ROTORCRAFT_STATUS as the aircraft
/// sends them).
fn set() -> RuntimeSet {
    RuntimeSet::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../messages.xml")).unwrap()
}

fn monitor() -> Monitor {
    Monitor::new(set(), PprzV2::new().into())
}

const ALIVE: u8 = 2;
const RSSI: u8 = 28;
const DATALINK_REPORT: u8 = 30;
const ROTORCRAFT_STATUS: u8 = 231;

/// A telemetry frame from aircraft `source` to the ground.
fn frame_from(source: u8, id: u8, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(source, 0, 1, id));
    let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn alive(source: u8) -> Vec<u8> {
    frame_from(source, ALIVE, &[1, 0xAB])
}

/// A DATALINK_REPORT with `uplink_lost_time` and `downlink_nb_msgs`.
fn report(source: u8, uplink_lost_time: u16, downlink_nb_msgs: u16) -> Vec<u8> {
    let mut p = Vec::new();
    for v in [uplink_lost_time, 3, downlink_nb_msgs, 120, 2] {
        p.extend(v.to_le_bytes());
    }
    p.push(0);
    frame_from(source, DATALINK_REPORT, &p)
}

/// A ROTORCRAFT_STATUS with `ap_mode`.
fn status(source: u8, ap_mode: u8) -> Vec<u8> {
    let mut p = vec![0u8; 24];
    p[8] = ap_mode;
    frame_from(source, ROTORCRAFT_STATUS, &p)
}

fn feed(m: &mut Monitor, now: f64, bytes: &[u8]) {
    m.feed(now, bytes, |_| {});
}

/// The link notices so far, as text.
fn link_notices(m: &Monitor) -> Vec<String> {
    m.notices_with_aircraft()
        .filter(|(_, _, n)| matches!(n, Notice::LinkStale { .. } | Notice::LinkLive { .. }))
        .map(|(t, ac, n)| format!("{t} {ac:?} {}", m.notice_line(ac, n)))
        .collect()
}

fn state(m: &Monitor, ac: u8, now: f64) -> LinkState {
    m.link_quality(ac, now).unwrap().state
}

#[test]
fn an_aircraft_goes_stale_after_exactly_the_stale_time_and_live_on_its_next_frame() {
    let mut m = monitor();
    assert_eq!(m.stale_after(), 5.0);
    feed(&mut m, 1.5, &alive(7));
    assert_eq!(m.aircraft_state(7).unwrap().last_heard(), Some(1.5));
    m.tick(6.25);
    assert_eq!(state(&m, 7, 6.25), LinkState::Live);
    assert_eq!(m.notice_count(), 0);
    // 5 s after the frame: stale, noted once.
    m.tick(6.5);
    assert_eq!(state(&m, 7, 6.5), LinkState::Stale);
    assert_eq!(
        link_notices(&m),
        ["6.5 Some(7) aircraft 7: link stale, not heard for 5.0 s"]
    );
    for t in [6.5, 7.0, 50.0, 100.0] {
        m.tick(t);
    }
    assert_eq!(m.notice_count(), 1);
    let view = m.render(100.0);
    assert!(
        view.contains("\nlink: stale, not heard for 98.5 s\n"),
        "{view}"
    );
    assert!(
        view.contains("aircraft 7: link stale, not heard for 5.0 s"),
        "{view}"
    );
    assert!(
        m.summary(100.0)
            .ends_with("link: stale, not heard for 98.5 s")
    );
    // Heard again: live, noted once.
    feed(&mut m, 110.0, &alive(7));
    feed(&mut m, 110.25, &alive(7));
    m.tick(110.5);
    assert_eq!(state(&m, 7, 110.5), LinkState::Live);
    assert_eq!(m.notice_count(), 2);
    assert_eq!(
        link_notices(&m)[1],
        "110 Some(7) aircraft 7: link live again after 108.5 s"
    );
    assert!(m.render(110.5).contains("\nlink: live, heard 0.2 s ago\n"));
    // And stale again 5 s after the latest frame.
    m.tick(115.0);
    assert_eq!(m.notice_count(), 2);
    m.tick(115.25);
    assert_eq!(m.notice_count(), 3);
}

#[test]
fn the_stale_time_is_the_one_configured() {
    let mut m = monitor().with_stale_after(0.5).unwrap();
    feed(&mut m, 0.0, &alive(7));
    m.tick(0.25);
    assert_eq!(m.notice_count(), 0);
    m.tick(0.5);
    assert_eq!(
        link_notices(&m),
        ["0.5 Some(7) aircraft 7: link stale, not heard for 0.5 s"]
    );
    assert!(monitor().with_stale_after(0.0).is_err());
}

/// A silence no tick saw (the monitor's loop was busy) is noted when the next frame
/// arrives: stale then live, one notice each.
#[test]
fn a_silence_no_tick_saw_is_noted_with_the_next_frame() {
    let mut m = monitor();
    feed(&mut m, 0.0, &alive(7));
    feed(&mut m, 20.0, &alive(7));
    assert_eq!(
        link_notices(&m),
        [
            "20 Some(7) aircraft 7: link stale, not heard for 20.0 s",
            "20 Some(7) aircraft 7: link live again after 20.0 s"
        ]
    );
    m.tick(21.0);
    assert_eq!(m.notice_count(), 2);
    // Within the stale time, nothing.
    feed(&mut m, 24.0, &alive(7));
    assert_eq!(m.notice_count(), 2);
}

/// Each aircraft has its own state; the notices name it, with one aircraft or several.
#[test]
fn each_aircraft_goes_stale_on_its_own() {
    let mut m = monitor();
    feed(&mut m, 0.0, &alive(7));
    feed(&mut m, 3.0, &alive(8));
    // Aircraft 9, only addressed, is never heard: no state, no notice.
    m.ping_sent(Some(9), 0.0);
    m.tick(5.0);
    assert_eq!(state(&m, 7, 5.0), LinkState::Stale);
    assert_eq!(state(&m, 8, 5.0), LinkState::Live);
    assert_eq!(m.link_quality(9, 5.0), None);
    m.tick(8.0);
    assert_eq!(
        link_notices(&m),
        [
            "5 Some(7) aircraft 7: link stale, not heard for 5.0 s",
            "8 Some(8) aircraft 8: link stale, not heard for 5.0 s"
        ]
    );
    let view = m.render(8.0);
    assert!(
        view.contains("aircraft 7 link: stale, not heard for 8.0 s"),
        "{view}"
    );
    assert!(view.contains("aircraft 9 link: not heard"), "{view}");
    let summary = m.summary(8.0);
    assert!(
        summary.contains("\n  link: stale, not heard for 5.0 s"),
        "{summary}"
    );
}

#[test]
fn the_aircraft_rssi_message_gives_its_signal_strength() {
    let mut m = monitor();
    // The wrong length first: malformed, no RSSI.
    feed(&mut m, 0.0, &frame_from(7, RSSI, &[40]));
    assert_eq!(m.aircraft_state(7).unwrap().malformed(), 1);
    let q = m.link_quality(7, 0.0).unwrap();
    assert_eq!((q.rssi_dbm, q.tx_power_db), (None, None));
    feed(&mut m, 0.1, &frame_from(7, RSSI, &[40, 10]));
    let q = m.link_quality(7, 0.1).unwrap();
    assert_eq!((q.rssi_dbm, q.tx_power_db), (Some(-40), Some(10)));
    assert_eq!(q.ground_rssi_dbm, None);
    assert!(m.render(0.1).contains("RSSI -40 dBm (tx power 10 dB)"));
    // Too long, or too short: the latest valid one stays.
    feed(&mut m, 0.2, &frame_from(7, RSSI, &[90, 1, 2]));
    feed(&mut m, 0.3, &frame_from(7, RSSI, &[]));
    assert_eq!(m.link_quality(7, 0.3).unwrap().rssi_dbm, Some(-40));
    assert_eq!(m.aircraft_state(7).unwrap().malformed(), 3);
    feed(&mut m, 0.4, &frame_from(7, RSSI, &[255, 0]));
    assert_eq!(m.link_quality(7, 0.4).unwrap().rssi_dbm, Some(-255));
}

/// An XBee RX16 frame from aircraft `source` with the modem's `rssi` (a TX16 frame
/// encoded, then turned into what a receiving modem gives).
fn xbee_rx(source: u8, id: u8, payload: &[u8], rssi: u8) -> Vec<u8> {
    let mut buf = [0u8; 128];
    let meta = TxMeta::new(MsgHeader::new(source, 0, 1, id));
    let n = XBee24::new().encode(&meta, payload, &mut buf).unwrap();
    let mut f = buf[..n].to_vec();
    // | 0x7E | len (2) | 0x01 | frame_id | dest (2) | options | ... | ck |
    f[3] = 0x81;
    f[4..8].copy_from_slice(&[0, source, rssi, 0]);
    let last = f.len() - 1;
    let sum = f[3..last].iter().fold(0u8, |a, b| a.wrapping_add(*b));
    f[last] = 0xFF - sum;
    f
}

#[test]
fn the_ground_modems_rssi_is_kept_per_aircraft() {
    let mut m = Monitor::new(set(), XBee24::default().into());
    let mut stream = xbee_rx(7, ALIVE, &[1, 2], 40);
    stream.extend(xbee_rx(7, ALIVE, &[1, 2], 48));
    stream.extend(xbee_rx(8, ALIVE, &[1, 2], 90));
    feed(&mut m, 1.0, &stream);
    assert_eq!(m.decoder_stats().frames, 3);
    let q7 = m.link_quality(7, 1.0).unwrap();
    assert_eq!(q7.ground_rssi_dbm, Some(-48));
    assert_eq!(q7.ground_rssi_mean_dbm, Some(-41.0));
    let q8 = m.link_quality(8, 1.0).unwrap();
    assert_eq!(
        (q8.ground_rssi_dbm, q8.ground_rssi_mean_dbm),
        (Some(-90), Some(-90.0))
    );
    assert_eq!(q8.rssi_dbm, None);
    let view = m.render(1.0);
    assert!(
        view.contains(
            "aircraft 7 link: live, heard 0.0 s ago  ground RSSI -48 dBm (mean -41.0 dBm)"
        ),
        "{view}"
    );
    // A TX16 frame (a loopback) carries no RSSI: the latest stays.
    let mut tx = [0u8; 64];
    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, ALIVE));
    let n = XBee24::new().encode(&meta, &[1, 2], &mut tx).unwrap();
    feed(&mut m, 2.0, &tx[..n]);
    assert_eq!(m.aircraft_state(7).unwrap().frames(), 3);
    assert_eq!(m.link_quality(7, 2.0).unwrap().ground_rssi_dbm, Some(-48));
}

#[test]
fn the_downlink_loss_is_estimated_over_each_report_period() {
    let mut m = monitor();
    // The first report: no estimate yet.
    feed(&mut m, 0.0, &report(7, 0, 65_530));
    let q = m.link_quality(7, 0.0).unwrap();
    assert_eq!((q.loss_rate, q.uplink_lost_time), (None, Some(0.0)));
    // 16 messages sent across the wrap, 8 frames received (the report included).
    for _ in 0..7 {
        feed(&mut m, 1.0, &alive(7));
    }
    feed(&mut m, 5.0, &report(7, 2, 10));
    let q = m.link_quality(7, 5.0).unwrap();
    assert_eq!((q.loss_rate, q.loss_overall), (Some(0.5), Some(0.5)));
    assert_eq!(q.uplink_lost_time, Some(2.0));
    let view = m.render(5.0);
    assert!(
        view.contains("link: live, heard 0.0 s ago  uplink lost 2 s  downlink loss 50.0% over the last report period (50.0% overall)"),
        "{view}"
    );
    // Nothing sent: no estimate, the previous one stays.
    feed(&mut m, 5.5, &report(7, 0, 10));
    assert_eq!(m.link_quality(7, 5.5).unwrap().loss_rate, Some(0.5));
    // 20 sent, 10 frames and the report received.
    for _ in 0..10 {
        feed(&mut m, 6.0, &alive(7));
    }
    feed(&mut m, 10.0, &report(7, 0, 30));
    let q = m.link_quality(7, 10.0).unwrap();
    assert_eq!(q.loss_rate, Some(1.0 - 11.0 / 20.0));
    assert_eq!(q.loss_overall, Some(1.0 - 19.0 / 36.0));
    // All received, and more (duplicates): no loss, never below 0.
    for _ in 0..30 {
        feed(&mut m, 11.0, &alive(7));
    }
    feed(&mut m, 15.0, &report(7, 0, 40));
    assert_eq!(m.link_quality(7, 15.0).unwrap().loss_rate, Some(0.0));
}

/// Hostile or absurd reports: a counter that goes back or jumps by more than half its
/// range gives no estimate (a restart), and the next period is measured from it.
#[test]
fn absurd_counters_give_no_estimate() {
    let mut m = monitor();
    feed(&mut m, 0.0, &report(7, 0, 100));
    feed(&mut m, 1.0, &alive(7));
    feed(&mut m, 2.0, &report(7, 0, 104));
    assert_eq!(m.link_quality(7, 2.0).unwrap().loss_rate, Some(0.5));
    // Back (a restart), then a jump of 40000: no estimate.
    feed(&mut m, 3.0, &report(7, 65_535, 3));
    feed(&mut m, 4.0, &report(7, 65_535, 40_003));
    let q = m.link_quality(7, 4.0).unwrap();
    assert_eq!(q.loss_rate, Some(0.5));
    assert_eq!(q.uplink_lost_time, Some(65_535.0));
    // From the latest report on, measured again: 4 sent, 4 received.
    for _ in 0..3 {
        feed(&mut m, 4.5, &alive(7));
    }
    feed(&mut m, 5.0, &report(7, 0, 40_007));
    assert_eq!(m.link_quality(7, 5.0).unwrap().loss_rate, Some(0.0));
    // A report of the wrong length is malformed: not used.
    feed(&mut m, 6.0, &frame_from(7, DATALINK_REPORT, &[0xFF; 5]));
    assert_eq!(m.link_quality(7, 6.0).unwrap().uplink_lost_time, Some(0.0));
    no_control(&m.render(6.0));
}

#[test]
fn the_autopilot_mode_has_its_label() {
    let mut m = monitor();
    feed(&mut m, 0.0, &status(7, 13));
    assert_eq!(
        m.link_quality(7, 0.0).unwrap().ap_mode.as_deref(),
        Some("NAV")
    );
    // The link-loss failsafe of a rotorcraft: HOME.
    feed(&mut m, 1.0, &status(7, 2));
    assert_eq!(
        m.link_quality(7, 1.0).unwrap().ap_mode.as_deref(),
        Some("HOME")
    );
    assert!(m.render(1.0).contains("  mode HOME\n"));
    // A value with no label: the number.
    feed(&mut m, 2.0, &status(7, 200));
    assert_eq!(
        m.link_quality(7, 2.0).unwrap().ap_mode.as_deref(),
        Some("200")
    );
    // The wrong length: malformed, the mode stays.
    feed(&mut m, 3.0, &frame_from(7, ROTORCRAFT_STATUS, &[2; 9]));
    assert_eq!(
        m.link_quality(7, 3.0).unwrap().ap_mode.as_deref(),
        Some("200")
    );
}

/// Frames that claim another aircraft's id change only that aircraft's state: a
/// stream from aircraft 9 (RSSI, reports, a mode, malformed frames) leaves aircraft 7's
/// link as it was.
#[test]
fn frames_of_another_aircraft_leave_an_aircrafts_link_alone() {
    let mut m = monitor();
    feed(&mut m, 0.0, &frame_from(7, RSSI, &[40, 10]));
    feed(&mut m, 0.0, &report(7, 1, 100));
    feed(&mut m, 0.0, &status(7, 13));
    let before = m.link_quality(7, 0.0).unwrap();
    let mut hostile = Vec::new();
    for i in 0..200u16 {
        hostile.extend(frame_from(9, RSSI, &[i as u8, 0xFF]));
        hostile.extend(report(9, i, i.wrapping_mul(40_000)));
        hostile.extend(status(9, 2));
        hostile.extend(frame_from(9, RSSI, &[1]));
        hostile.extend(frame_from(9, DATALINK_REPORT, &[0xFF; 40]));
    }
    feed(&mut m, 1.0, &hostile);
    assert_eq!(m.link_quality(7, 0.0).unwrap(), before);
    let q9 = m.link_quality(9, 1.0).unwrap();
    assert_eq!(q9.ap_mode.as_deref(), Some("HOME"));
    assert!(q9.loss_rate.is_none_or(|l| (0.0..=1.0).contains(&l)));
    // Aircraft 7 is still noted stale on its own time.
    m.tick(4.9);
    assert_eq!(m.notice_count(), 0);
    m.tick(5.0);
    assert_eq!(
        link_notices(&m),
        ["5 Some(7) aircraft 7: link stale, not heard for 5.0 s"]
    );
}

/// Times that go back, or are not numbers, never make a state absurd.
#[test]
fn odd_times_do_not_break_the_state() {
    let mut m = monitor();
    feed(&mut m, 10.0, &alive(7));
    feed(&mut m, 4.0, &alive(7));
    assert_eq!(m.aircraft_state(7).unwrap().last_heard(), Some(10.0));
    feed(&mut m, f64::NAN, &alive(7));
    m.tick(f64::NAN);
    assert_eq!(m.aircraft_state(7).unwrap().last_heard(), Some(10.0));
    let q = m.link_quality(7, 2.0).unwrap();
    assert_eq!((q.state, q.since_heard), (LinkState::Live, 0.0));
    let q = m.link_quality(7, f64::NAN).unwrap();
    assert_eq!((q.state, q.since_heard), (LinkState::Live, 0.0));
    assert_eq!(m.clock(), 10.0);
    assert_eq!(m.notice_count(), 0);
}

fn no_control(text: &str) {
    for line in text.lines() {
        assert!(!line.chars().any(crate::escape::is_unsafe), "{line:?}");
    }
}
