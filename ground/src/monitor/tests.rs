use super::*;
use crate::escape;
use crate::input::Drops;
use crate::settings::{Answer, Expired};
use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};

const XML: &str = r#"<protocol>
  <msg_class name="telemetry" id="1">
    <message name="PONG" id="3"/>
    <message name="DL_VALUE" id="31"><field name="index" type="uint8"/><field name="value" type="float"/></message>
    <message name="INFO_MSG" id="215"><field name="msg" type="char[]"/></message>
    <message name="GPS_LLA" id="9"><field name="lat" type="int32" unit="1e7deg" alt_unit="deg" alt_unit_coef="0.0000001"/></message>
  </msg_class>
  <msg_class name="datalink" id="2">
    <message name="SETTING" id="4"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
    <message name="PING" id="8"/>
  </msg_class></protocol>"#;

fn monitor() -> Monitor {
    let set = RuntimeSet::parse("t.xml", XML).unwrap();
    Monitor::new(set, PprzV2::new().into())
}

fn frame(id: u8, payload: &[u8]) -> Vec<u8> {
    frame_from(7, 0, id, payload)
}

/// A telemetry frame from aircraft `source` to `destination`.
fn frame_from(source: u8, destination: u8, id: u8, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(source, destination, 1, id));
    let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn dl_value(index: u8, value: f32) -> Vec<u8> {
    dl_value_from(7, index, value)
}

fn dl_value_from(source: u8, index: u8, value: f32) -> Vec<u8> {
    let mut p = vec![index];
    p.extend(value.to_le_bytes());
    frame_from(source, 0, 31, &p)
}

fn pong_from(source: u8) -> Vec<u8> {
    frame_from(source, 0, 3, &[])
}

fn feed(m: &mut Monitor, now: f64, bytes: &[u8]) -> Vec<String> {
    let mut lines = Vec::new();
    m.feed(now, bytes, |d| lines.push(d.line.to_owned()));
    lines
}

fn no_control(text: &str) {
    for line in text.lines() {
        assert!(!line.chars().any(escape::is_unsafe), "{line:?}");
    }
}

/// Issue: with `--ping 0.2` and a true round trip of 500 ms, 100.8 ms was shown.
#[test]
fn each_pong_is_matched_to_its_ping() {
    let mut m = monitor();
    let pong = frame(3, &[]);
    for i in 0..20 {
        m.ping_sent(None, f64::from(i) * 0.2);
    }
    for i in 0..17 {
        feed(&mut m, f64::from(i) * 0.2 + 0.5, &pong);
    }
    let rtts: Vec<f64> = m
        .events()
        .map(|(_, e)| match e {
            Event::Pong { rtt } => *rtt,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(rtts.len(), MAX_EVENTS);
    for rtt in rtts {
        assert!((rtt - 0.5).abs() < 1e-9, "{rtt}");
    }
    assert!((m.last_rtt().unwrap() - 0.5).abs() < 1e-9);
    let view = m.render(4.0);
    assert!(view.contains("PONG: round trip 500.0 ms"), "{view}");
    assert!(
        view.contains("pings: sent 20  answered 17  lost 0  outstanding 3"),
        "{view}"
    );
    // The outstanding ones time out.
    m.tick(100.0);
    assert_eq!(m.pings().lost(), 3);
    assert!(m.render(100.0).contains("3 PING(s) lost"));
    // A PONG nobody asked for is noted, not measured.
    feed(&mut m, 101.0, &pong);
    assert_eq!(m.pings().unexpected(), 1);
}

/// Issue: a periodic DL_VALUE carrying the old value was shown as the
/// acknowledgement of a SETTING the aircraft ignored.
#[test]
fn only_the_value_set_acknowledges_a_setting() {
    let mut m = monitor();
    m.setting_sent(None, 1.0, 4, 0.1);
    feed(&mut m, 1.1, &dl_value(4, 1.0));
    let last = m.events().last().unwrap().1.clone();
    assert!(
        matches!(
            last,
            Event::DlValue {
                index: 4,
                value: 1.0,
                answer: Answer::NotApplied { .. }
            }
        ),
        "{last:?}"
    );
    let view = m.render(1.1);
    assert!(
        view.contains("DL_VALUE index=4 value=1: SETTING to 0.1 not applied"),
        "{view}"
    );
    assert!(
        view.contains(
            "pending: SETTING index=4 to 0.1: not applied so far, the aircraft reports 1"
        ),
        "{view}"
    );
    // The value set, as the float the aircraft stores.
    feed(&mut m, 1.2, &dl_value(4, 0.1));
    let last = m.events().last().unwrap().1.clone();
    assert!(
        matches!(last, Event::DlValue { answer: Answer::Acknowledged { after }, .. } if (after - 0.2).abs() < 1e-9),
        "{last:?}"
    );
    assert_eq!(m.settings().acknowledged(), 1);
    // A SETTING that the aircraft never applies is given up and counted.
    m.setting_sent(None, 2.0, 5, 3.0);
    feed(&mut m, 2.1, &dl_value(5, 2.0));
    m.tick(10.0);
    assert_eq!(m.settings().not_applied(), 1);
    let view = m.render(10.0);
    assert!(
        view.contains("SETTING index=5 to 3 not applied: the aircraft still reports 2"),
        "{view}"
    );
    assert!(
        view.contains("settings: acknowledged 1  not applied 1"),
        "{view}"
    );
}

#[test]
fn input_dropped_is_counted_shown_and_resynchronises() {
    let mut m = monitor();
    let f = frame(215, &[2, b'o', b'k']);
    // Half a frame, then a gap: its end was dropped.
    feed(&mut m, 0.0, &f[..4]);
    let mut lines = Vec::new();
    m.input_gap(
        0.1,
        Drops {
            bytes: 4000,
            reads: 3,
        },
        |d| lines.push(d.line.to_owned()),
    );
    lines.extend(feed(&mut m, 0.1, &f));
    assert_eq!(lines, [r#"7 telemetry INFO_MSG msg="ok""#]);
    m.input_gap(
        0.2,
        Drops {
            bytes: 10,
            reads: 1,
        },
        |_| {},
    );
    m.input_gap(0.3, Drops::default(), |_| {});
    assert_eq!(
        m.input_dropped(),
        Drops {
            bytes: 4010,
            reads: 4
        }
    );
    let view = m.render(0.3);
    assert!(view.contains("input dropped 4010 B in 4 reads"), "{view}");
    assert!(
        view.contains("input overload: dropped 4000 bytes in 3 reads"),
        "{view}"
    );
    assert!(m.summary(0.3).contains("input dropped 4010 B in 4 reads"));
}

/// Issue: one INFO_MSG forged a `7 telemetry ALIVE md5sum=FORGED` line plus
/// clear-screen and window-title escape codes.
#[test]
fn hostile_text_cannot_forge_lines_or_reach_the_terminal() {
    let mut m = monitor();
    let text = b"hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;owned\x07\r\xc2\x9b";
    let mut p = vec![text.len() as u8];
    p.extend_from_slice(text);
    let lines = feed(&mut m, 0.0, &frame(215, &p));
    assert_eq!(lines.len(), 1);
    assert!(
        lines[0]
            .starts_with(r#"7 telemetry INFO_MSG msg="hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J"#),
        "{}",
        lines[0]
    );
    no_control(&lines[0]);
    let view = m.render(1.0);
    no_control(&view);
    assert!(!view.contains("\nALIVE") && !view.contains('\x1b') && !view.contains('\r'));
}

#[test]
fn units_are_apart_from_values() {
    let mut m = monitor();
    let lines = feed(&mut m, 0.0, &frame(9, &434_629_172i32.to_le_bytes()));
    assert_eq!(
        lines,
        ["7 telemetry GPS_LLA lat=434629172 [1e7deg] 43.4629172 deg"]
    );
}

#[test]
fn rates_and_state_are_bounded() {
    let mut m = monitor();
    let f = dl_value(1, 1.0);
    let chunk: Vec<u8> = f.repeat(1000);
    for i in 0..200 {
        feed(&mut m, f64::from(i) * 0.01, &chunk);
    }
    // 200,000 messages in two seconds: the rate is right, the state small.
    let stats = &m.messages()[&(1, 31)];
    assert_eq!(stats.count, 200_000);
    let rate = stats.rate(2.0).unwrap();
    assert!((rate - 1e5).abs() < 1.0, "{rate}");
    assert_eq!(stats.rate(100.0), Some(0.0));
    assert!(m.retained_bytes() < 64 * 1024, "{}", m.retained_bytes());
    assert!(m.events().count() <= MAX_EVENTS);
    let r = m.byte_rate(2.0).unwrap();
    assert!((r - 200.0 * chunk.len() as f64 / 2.0).abs() < 1.0, "{r}");
}

#[test]
fn one_aircraft_keeps_one_table() {
    let mut m = monitor();
    feed(&mut m, 0.0, &frame(215, &[2, b'o', b'k']));
    assert_eq!(m.aircraft(), [7]);
    assert!(!m.several_aircraft());
    let view = m.render(1.0);
    assert!(
        !view.contains("aircraft 7:") && !view.contains("aircraft:"),
        "{view}"
    );
    assert_eq!(view.matches("class      message").count(), 1, "{view}");
    assert!(!m.summary(1.0).contains("aircraft"));
}

#[test]
fn frames_from_two_aircraft_make_two_sections() {
    let mut m = monitor();
    let mut lines = feed(&mut m, 0.0, &frame_from(7, 0, 215, &[2, b'o', b'k']));
    lines.extend(feed(&mut m, 0.1, &frame_from(8, 0, 9, &[1, 0, 0, 0])));
    lines.extend(feed(&mut m, 0.2, &frame_from(8, 0, 9, &[2, 0, 0, 0])));
    lines.extend(feed(&mut m, 0.3, &frame_from(8, 0, 200, &[])));
    // Each line starts with its source.
    assert_eq!(
        lines,
        [
            r#"7 telemetry INFO_MSG msg="ok""#,
            "8 telemetry GPS_LLA lat=1 [1e7deg] 0.0000001 deg",
            "8 telemetry GPS_LLA lat=2 [1e7deg] 0.0000002 deg",
            "8 class1 id=200 unknown message (0 bytes)",
        ]
    );
    assert_eq!(m.aircraft(), [7, 8]);
    assert!(m.several_aircraft());
    // All aircraft together, and each on its own.
    assert_eq!(m.messages().len(), 2);
    let a8 = m.aircraft_state(8).unwrap();
    assert_eq!(
        (a8.id(), a8.frames(), a8.unknown(), a8.malformed()),
        (8, 3, 1, 0)
    );
    assert_eq!(a8.messages()[&(1, 9)].count, 2);
    assert!(!a8.messages().contains_key(&(1, 215)));
    assert_eq!(m.aircraft_state(7).unwrap().messages().len(), 1);
    assert!(m.aircraft_state(9).is_none());
    let prio = pprz_messages::priority::DEFAULT;
    assert_eq!(
        m.aircraft_state(8)
            .map(|a| a.per_priority())
            .unwrap_or_default()[&std::cmp::Reverse(prio)],
        2
    );
    assert_eq!(
        m.aircraft_state(7)
            .map(|a| a.per_priority())
            .unwrap_or_default()[&std::cmp::Reverse(prio)],
        1
    );
    assert_eq!(m.per_priority()[&std::cmp::Reverse(prio)], 3);
    assert!(
        m.aircraft_state(9)
            .map(|a| a.per_priority())
            .unwrap_or_default()
            .is_empty()
    );
    assert_eq!(
        m.aircraft_summary(8).unwrap().lines().nth(1),
        Some(format!("  received per priority level:  {prio}: 2").as_str())
    );

    let view = m.render(1.0);
    no_control(&view);
    let at = |needle: &str| {
        view.find(needle)
            .unwrap_or_else(|| panic!("{needle}: {view}"))
    };
    assert!(view.contains("aircraft: 7, 8\n"), "{view}");
    let (s7, s8) = (
        at("aircraft 7: frames 1  unknown 0  malformed 0\n"),
        at("aircraft 8: frames 3  unknown 1  malformed 0\n"),
    );
    let (info, gps) = (at("INFO_MSG"), at("GPS_LLA"));
    assert!(s7 < info && info < s8 && s8 < gps, "{view}");
    assert_eq!(view.matches("class      message").count(), 2, "{view}");

    let summary = m.summary(1.0);
    assert!(
        summary.contains(&format!(
            "aircraft: 7, 8\naircraft 7: frames 1  unknown 0  malformed 0\n  received per priority level:  {prio}: 1\n  link: live, heard 1.0 s ago\naircraft 8:"
        )),
        "{summary}"
    );
    assert_eq!(m.aircraft_summary(9), None);
}

#[test]
fn a_pong_answers_only_a_ping_to_its_source() {
    let mut m = monitor();
    m.ping_sent(Some(7), 0.0);
    // Aircraft 8 was not pinged: its PONG answers nothing (counted with the PINGs to
    // no particular aircraft, noted with aircraft 8).
    feed(&mut m, 0.1, &pong_from(8));
    assert_eq!(
        m.aircraft_state(7)
            .map(|a| a.pings())
            .unwrap()
            .outstanding(),
        1
    );
    assert_eq!(m.last_rtt(), None);
    let (_, ac, n) = m.notices_with_aircraft().last().unwrap();
    assert_eq!((ac, n), (Some(8), &Notice::UnexpectedPong));
    m.ping_sent(Some(8), 1.0);
    feed(&mut m, 1.25, &pong_from(8));
    assert_eq!(m.aircraft_state(8).and_then(|a| a.last_rtt()), Some(0.25));
    assert_eq!(m.last_rtt(), Some(0.25));
    assert_eq!(m.aircraft_state(7).and_then(|a| a.last_rtt()), None);
    assert_eq!(
        m.aircraft_state(7)
            .map(|a| a.pings())
            .unwrap()
            .outstanding(),
        1
    );
    assert_eq!(
        m.aircraft_state(8).map(|a| a.pings()).unwrap().answered(),
        1
    );
    let (_, ac, e) = m.events_with_aircraft().last().unwrap();
    assert_eq!((ac, e), (Some(8), &Event::Pong { rtt: 0.25 }));
    // 7's answer to aircraft 8 (seen on a shared link) is not an answer to the ground.
    feed(&mut m, 1.5, &frame_from(7, 8, 3, &[]));
    assert_eq!(
        m.aircraft_state(7)
            .map(|a| a.pings())
            .unwrap()
            .outstanding(),
        1
    );
    feed(&mut m, 1.5, &frame_from(7, 0xFF, 3, &[]));
    assert_eq!(m.aircraft_state(7).and_then(|a| a.last_rtt()), Some(1.5));
    // A PING to nobody in particular is answered by any aircraft.
    m.ping_sent(None, 2.0);
    feed(&mut m, 2.5, &pong_from(9));
    assert_eq!(
        (
            m.pings().answered(),
            m.aircraft_state(9).and_then(|a| a.last_rtt())
        ),
        (1, Some(0.5))
    );
    // Timeouts per aircraft, noted with the aircraft.
    m.ping_sent(Some(7), 3.0);
    m.tick(10.0);
    assert_eq!(m.aircraft_state(7).map(|a| a.pings()).unwrap().lost(), 1);
    let view = m.render(10.0);
    assert!(view.contains("aircraft 7: 1 PING(s) lost"), "{view}");
    assert!(
        view.contains("aircraft 8: PONG: round trip 250.0 ms"),
        "{view}"
    );
    assert!(
        view.contains("aircraft 8: frames 2  unknown 0  malformed 0\npings: sent 1  answered 1  lost 0  outstanding 0  unexpected pongs 0  last round trip 250.0 ms\n"),
        "{view}"
    );
    let s = m.aircraft_summary(7).unwrap();
    assert!(s.contains("\n  pings: sent 2  answered 1  lost 1"), "{s}");
}

#[test]
fn a_dl_value_answers_only_a_setting_to_its_source() {
    let mut m = monitor();
    m.setting_sent(Some(8), 0.0, 4, 2.5);
    m.get_setting_sent(Some(7), 0.0, 5);
    feed(&mut m, 0.1, &dl_value_from(7, 4, 2.5));
    assert_eq!(
        m.aircraft_state(8).map(|a| a.settings()).unwrap().pending(),
        1
    );
    feed(&mut m, 0.2, &dl_value_from(8, 4, 2.5));
    assert_eq!(
        m.aircraft_state(8)
            .map(|a| a.settings())
            .unwrap()
            .acknowledged(),
        1
    );
    let (_, ac, e) = m.events_with_aircraft().last().unwrap();
    assert_eq!(ac, Some(8));
    assert!(
        matches!(
            e,
            Event::DlValue {
                index: 4,
                answer: Answer::Acknowledged { .. },
                ..
            }
        ),
        "{e:?}"
    );
    feed(&mut m, 0.3, &dl_value_from(8, 5, 1.0));
    assert_eq!(
        m.aircraft_state(7).map(|a| a.settings()).unwrap().pending(),
        1
    );
    m.tick(10.0);
    assert_eq!(
        m.aircraft_state(7)
            .map(|a| a.settings())
            .unwrap()
            .unanswered(),
        1
    );
    let (_, ac, n) = m.notices_with_aircraft().last().unwrap();
    assert_eq!(ac, Some(7));
    assert!(
        matches!(n, Notice::RequestExpired(Expired { index: 5, .. })),
        "{n:?}"
    );
    assert_eq!(m.settings().pending(), 0);
}

/// Hostile input: frames from every source id track at most [`MAX_AIRCRAFT`]
/// aircraft; the others are counted.
#[test]
fn the_aircraft_tracked_are_bounded() {
    let mut m = monitor();
    let flood: Vec<u8> = (0..=255u8)
        .flat_map(|src| frame_from(src, 0, 215, &[245; 246]))
        .collect();
    for i in 0..4 {
        feed(&mut m, f64::from(i), &flood);
    }
    assert_eq!(m.aircraft().len(), MAX_AIRCRAFT);
    assert_eq!(m.aircraft(), (0..MAX_AIRCRAFT as u8).collect::<Vec<_>>());
    assert_eq!(m.untracked_aircraft(), 256 - MAX_AIRCRAFT as u32);
    assert_eq!(m.untracked_frames(), 4 * (256 - MAX_AIRCRAFT as u64));
    assert_eq!(m.messages()[&(1, 215)].count, 4 * 256);
    assert_eq!(m.decoder_stats().frames, 4 * 256);
    // An aircraft the ground addresses is tracked all the same, and its PONG
    // measured.
    m.ping_sent(Some(200), 5.0);
    feed(&mut m, 5.5, &pong_from(200));
    assert_eq!(m.aircraft_state(200).and_then(|a| a.last_rtt()), Some(0.5));
    assert_eq!(m.aircraft().len(), MAX_AIRCRAFT + 1);
    let view = m.render(6.0);
    no_control(&view);
    assert!(
        view.contains("not tracked (more than 32 aircraft): 896 frames from 224 aircraft"),
        "{view}"
    );
    // 33 tables of one message with the longest text, and no more.
    assert!(
        m.retained_bytes() < 34 * 4096 + 64 * 1024,
        "{}",
        m.retained_bytes()
    );
    assert!(m.summary(6.0).contains("not tracked"));
}

/// Replaying a recording: its PONGs answer PINGs another ground station sent, so they
/// are neither round trips nor PONGs that answer nothing.
#[test]
fn a_replay_notes_no_pong_as_unexpected() {
    let mut m = monitor().replaying();
    let lines = feed(&mut m, 0.5, &pong_from(7));
    assert_eq!(lines, ["7 telemetry PONG"]);
    assert_eq!(m.notices().count(), 0);
    assert_eq!(m.events().count(), 0);
    assert_eq!(m.pings().unexpected(), 0);
    assert_eq!(m.messages()[&(1, 3)].count, 1);
    let view = m.render(1.0);
    assert!(!view.contains("PONG that answers no PING"), "{view}");
    assert!(!view.contains("pings:"), "{view}");
    // A live monitor notes it.
    let mut live = monitor();
    feed(&mut live, 0.5, &pong_from(7));
    assert_eq!(live.notices().count(), 1);
}

/// The first view of a run showed `t=0.0s 2411480 B/s`: 241 bytes over 0.1 ms.
#[test]
fn no_rate_is_shown_over_a_near_zero_interval() {
    let mut m = monitor();
    feed(&mut m, 0.0001, &frame(215, &[240; 241]));
    assert_eq!(m.byte_rate(0.0001), None);
    assert_eq!(m.messages()[&(1, 215)].rate(0.0001), None);
    let view = m.render(0.0001);
    let first = view.lines().next().unwrap();
    assert!(
        first.starts_with("t=    0.0s        - B/s  frames ok 1"),
        "{first}"
    );
    let row = view.lines().find(|l| l.contains("INFO_MSG")).unwrap();
    assert!(row.contains("       1       -  "), "{row}");
    // Once the interval means something, the rate is the bytes over it.
    let len = frame(215, &[240; 241]).len() as f64;
    assert_eq!(m.byte_rate(super::MIN_RATE_INTERVAL), Some(len));
}

/// A steady 4 Hz message read 3.6/s: the window's count was divided by the whole window
/// while its last bucket had only partly elapsed.
#[test]
fn a_steady_rate_reads_true_whenever_it_is_read() {
    let mut m = monitor();
    let f = frame(215, &[2, b'o', b'k']);
    for i in 0..80 {
        let now = f64::from(i) * 0.25 + 0.1;
        feed(&mut m, now, &f);
        for read in [now, now + 0.1, now + 0.2] {
            if read >= 6.0 {
                let rate = m.messages()[&(1, 215)].rate(read).unwrap();
                assert!((rate - 4.0).abs() < 0.2, "{read}: {rate}");
            }
        }
    }
}

/// Issue: GET_SETTINGs to 40 aircraft never heard (ids 100..139) took the
/// [`MAX_AIRCRAFT`] places, so aircraft 7, heard next, was untracked. Aircraft only
/// addressed take no place; those heard still make at most [`MAX_AIRCRAFT`].
#[test]
fn aircraft_only_addressed_take_no_place_of_aircraft_heard() {
    let mut m = monitor();
    for ac in 100..140 {
        m.get_setting_sent(Some(ac), 0.0, 0);
    }
    feed(&mut m, 1.0, &frame_from(7, 0, 215, b"hello"));
    assert!(m.aircraft_state(7).is_some_and(|a| a.frames() == 1));
    assert_eq!(m.untracked_frames(), 0);
    // 31 more aircraft heard: 32 in all, then the bound holds.
    for src in 0..40u8 {
        feed(&mut m, 2.0, &frame_from(src, 0, 215, b"x"));
    }
    let heard = m
        .aircraft()
        .into_iter()
        .filter(|&a| m.aircraft_state(a).unwrap().frames() > 0)
        .count();
    assert_eq!(heard, MAX_AIRCRAFT);
    // 7, then 0..=31: 32 heard; 32..=39 untracked.
    assert_eq!(m.untracked_aircraft(), 8);
    // An aircraft addressed and then heard is tracked, as before.
    feed(&mut m, 3.0, &frame_from(120, 0, 215, b"x"));
    assert_eq!(m.aircraft_state(120).unwrap().frames(), 1);
}

#[test]
fn without_text_a_monitor_counts_the_same_and_formats_nothing() {
    let mut plain = monitor();
    let mut quiet = monitor().without_text();
    let lla = frame(9, &123_456_789i32.to_le_bytes());
    quiet.setting_sent(None, 0.0, 2, 1.5);
    plain.setting_sent(None, 0.0, 2, 1.5);
    for m in [&mut plain, &mut quiet] {
        feed(m, 0.1, &lla);
        feed(m, 0.2, &dl_value(2, 1.5));
    }
    assert_eq!(feed(&mut quiet, 0.3, &lla), [""]);
    assert_eq!(
        feed(&mut plain, 0.3, &lla),
        ["7 telemetry GPS_LLA lat=123456789 [1e7deg] 12.3456789 deg"].map(String::from)
    );
    let (p, q) = (
        plain.aircraft_state(7).unwrap(),
        quiet.aircraft_state(7).unwrap(),
    );
    assert_eq!(
        (p.frames(), p.setting_values()),
        (q.frames(), q.setting_values())
    );
    assert_eq!(
        plain.settings().acknowledged(),
        quiet.settings().acknowledged()
    );
    assert!(quiet.messages().values().all(|m| m.last.is_empty()));
    assert!(!quiet.has_text() && plain.has_text());
}

#[test]
fn pprzlog_time_stamps_are_unwrapped() {
    let mut clock = super::LogClock::default();
    let at = |ticks: u64| std::time::Duration::from_micros(ticks * 100);
    let wrap = 1u64 << 32;
    let times: Vec<_> = [100, u32::MAX - 5, 10, 20, 15, u32::MAX, 3]
        .into_iter()
        .map(|t| clock.time(t))
        .collect();
    assert_eq!(
        times,
        [
            at(100),
            at(u64::from(u32::MAX) - 5),
            at(wrap + 10),
            at(wrap + 20),
            // A small step back is a record out of order, not a wrap.
            at(wrap + 15),
            at(wrap + u64::from(u32::MAX)),
            at(2 * wrap + 3),
        ]
    );
}
