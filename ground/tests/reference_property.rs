//! Property test: thousands of random and mutated frames of the full PPRZLINK reference
//! message set, in every transport, through the monitor. Whatever arrives: no panic,
//! bounded state, and no control character in any line printed.
//!
//! The reference `messages.xml` is not in this repository; it is found with
//! `pprz_test_support::reference` (`PPRZLINK_DIR`, or `../shared/pprzlink`), and the
//! test is skipped with a printed reason when it is absent (a failure when
//! `PPRZ_REQUIRE_REFERENCE` is set).
//!
//! Deterministic: a fixed-seed PRNG draws the messages, field bytes (text fields get
//! control characters, escape sequences, bidi overrides), mutations, chunk sizes and
//! times.

use pprz_ground::escape;
use pprz_ground::input::Drops;
use pprz_ground::monitor::{Decoded, MAX_EVENTS, Monitor};
use pprz_ground::ping::PingTracker;
use pprz_ground::set::RuntimeSet;
use pprz_ground::settings::SettingTracker;
use pprz_messages::dynamic;
use pprz_test_support::rng::Rng;
use pprz_transports::{
    AnyTransport, Encoder, MsgHeader, PprzLog, PprzV1, PprzV2, TxMeta, XBee24, XBee868,
};

/// A field byte: often one that is hostile when printed.
fn hostile_byte(rng: &mut Rng) -> u8 {
    const HOSTILE: &[u8] = b"\x1b[2J\x1b]0;t\x07\n\r\t\0\x7f\\\"= ,()[]\xc2\x9b\xe2\x80\xae";
    if rng.chance(30) {
        HOSTILE[rng.below(HOSTILE.len())]
    } else {
        rng.next_u64() as u8
    }
}

/// Checks one printed line.
fn assert_clean(line: &str) {
    assert!(
        !line.chars().any(|c| c.is_control() || escape::is_unsafe(c)),
        "control character printed: {line:?}"
    );
}

/// Checks the bounds of the monitor's state.
fn assert_bounded(m: &Monitor, set_len: usize) {
    assert!(m.messages().len() <= set_len);
    assert!(m.events().count() <= MAX_EVENTS);
    assert!(m.notices().count() <= MAX_EVENTS);
    assert!(m.pings().outstanding() <= m.pings().capacity());
    assert!(m.settings().pending() <= 256);
    for s in m.messages().values() {
        assert!(s.last.len() <= pprz_ground::format::MAX_FIELDS_LEN);
    }
    // Per message of the set: its statistics and at most MAX_FIELDS_LEN of text.
    let bound = set_len * (pprz_ground::format::MAX_FIELDS_LEN + 512) + (1 << 16);
    assert!(
        m.retained_bytes() <= bound,
        "{} > {bound}",
        m.retained_bytes()
    );
}

/// One frame of a random message of the set, maybe mutated; and whether it is intact.
fn random_frame(rng: &mut Rng, set: &RuntimeSet, transport: AnyTransport) -> (Vec<u8>, bool) {
    let messages = set.set().messages();
    let desc = &messages[rng.below(messages.len())];
    let mut payload = vec![0u8; transport.max_payload_len()];
    let max_elements = [0, 1, 5, 40, 255][rng.below(5)];
    let n = match dynamic::synthesize(desc, &mut payload, max_elements, || hostile_byte(rng)) {
        Ok(n) => n,
        Err(_) => dynamic::synthesize(desc, &mut payload, 0, || 0).unwrap_or(0),
    };
    payload.truncate(n);
    let meta = TxMeta::new(MsgHeader::new(7, 0, desc.class_id, desc.id)).at(rng.next_u64() as u32);
    let mut buf = vec![0u8; transport.max_frame_len()];
    let Ok(len) = transport.encode(&meta, &payload, &mut buf) else {
        return (Vec::new(), false);
    };
    buf.truncate(len);
    let intact = match rng.below(10) {
        0 => {
            let i = rng.below(buf.len());
            buf[i] ^= 1 << rng.below(8);
            false
        }
        1 => {
            buf.truncate(rng.below(buf.len()));
            false
        }
        2 => {
            // A false start announcing a long frame in front.
            let start = buf[0];
            buf.splice(0..0, [start, 0xFF]);
            true
        }
        3 => {
            let junk: Vec<u8> = (0..rng.below(40)).map(|_| hostile_byte(rng)).collect();
            buf.splice(0..0, junk);
            true
        }
        _ => true,
    };
    (buf, intact)
}

fn transports() -> [(&'static str, AnyTransport); 5] {
    [
        ("pprz2", PprzV2::new().into()),
        ("pprz1", PprzV1::new(1).into()),
        ("xbee", XBee24::default().into()),
        ("xbee868", XBee868::default().into()),
        ("pprzlog", PprzLog::TELEMETRY.into()),
    ]
}

#[test]
fn random_reference_frames_through_the_monitor() {
    let Some(dir) = pprz_test_support::reference::locate_for_test(
        "pprz-ground random_reference_frames_through_the_monitor",
    ) else {
        return;
    };
    let set = RuntimeSet::load(dir.join("messages.xml")).expect("the reference loads");
    let set_len = set.set().len();
    assert!(set_len > 100, "the full reference set: {set_len} messages");
    let mut rng = Rng::new(0x5EED_0F9A_9A00);
    for (name, transport) in transports() {
        let mut m = Monitor::new(set, transport)
            .with_trackers(PingTracker::new(8, 0.5), SettingTracker::new(0.5));
        let mut now = 0.0;
        let mut lines = 0usize;
        let mut intact_frames = 0usize;
        let mut on_line = |d: &Decoded<'_>| {
            assert_clean(d.line);
            assert!(!d.raw.is_empty());
            lines += 1;
        };
        for round in 0..1000 {
            let (frame, intact) = random_frame(&mut rng, &set, transport);
            intact_frames += usize::from(intact);
            let mut rest = &frame[..];
            while !rest.is_empty() {
                let (chunk, tail) = rest.split_at(1 + rng.below(rest.len()));
                rest = tail;
                now += rng.below(20) as f64 * 0.001;
                m.feed(now, chunk, &mut on_line);
            }
            match rng.below(40) {
                0 => m.ping_sent(None, now),
                1 => m.setting_sent(
                    None,
                    now,
                    rng.next_u64() as u8,
                    rng.below(1000) as f64 * 0.1,
                ),
                2 => m.get_setting_sent(None, now, rng.next_u64() as u8),
                3 => m.input_gap(
                    now,
                    Drops {
                        bytes: rng.below(5000) as u64,
                        reads: rng.below(5) as u64,
                    },
                    &mut on_line,
                ),
                4 => m.tick(now),
                _ => {}
            }
            if round % 100 == 0 {
                for line in m.render(now).lines() {
                    assert_clean(line);
                }
                assert_bounded(&m, set_len);
            }
        }
        m.flush(now, &mut on_line);
        for line in m.render(now).lines().chain(m.summary(now).lines()) {
            assert_clean(line);
        }
        assert_bounded(&m, set_len);
        // The test exercises decoding, not only rejection: most intact frames decode.
        assert!(
            lines * 10 >= intact_frames * 7,
            "{name}: {lines} lines for {intact_frames} intact frames"
        );
        assert!(m.decoder_stats().frames > 0, "{name}");
    }
}

/// Text fields of the reference set (INFO_MSG and others) carrying escape codes and
/// line breaks print as one escaped line.
#[test]
fn hostile_text_in_reference_messages_is_escaped() {
    let Some(dir) = pprz_test_support::reference::locate_for_test(
        "pprz-ground hostile_text_in_reference_messages_is_escaped",
    ) else {
        return;
    };
    let set = RuntimeSet::load(dir.join("messages.xml")).expect("the reference loads");
    let info = set
        .find_by_name("telemetry", "INFO_MSG")
        .expect("INFO_MSG in the reference");
    let text = b"ok\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;owned\x07";
    let mut payload = vec![text.len() as u8];
    payload.extend_from_slice(text);
    let t = AnyTransport::from(PprzV2::new());
    let mut buf = [0u8; 300];
    let n = t
        .encode(
            &TxMeta::new(MsgHeader::new(7, 0, info.class_id, info.id)),
            &payload,
            &mut buf,
        )
        .unwrap();
    let mut m = Monitor::new(set, t);
    let mut lines = Vec::new();
    m.feed(0.0, &buf[..n], |d| lines.push(d.line.to_owned()));
    assert_eq!(
        lines,
        [
            r#"7 telemetry INFO_MSG msg="ok\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;owned\x07""#
        ]
    );
    // The reference's units: value and unit apart, no `none`.
    let gps = set.find_by_name("telemetry", "GPS_LLA");
    if let Some(gps) = gps {
        let mut payload = vec![0u8; 64];
        let len = dynamic::synthesize(gps, &mut payload, 0, || 0).unwrap();
        payload.truncate(len);
        payload[..4].copy_from_slice(&434_629_172i32.to_le_bytes());
        let n = t
            .encode(
                &TxMeta::new(MsgHeader::new(7, 0, gps.class_id, gps.id)),
                &payload,
                &mut buf,
            )
            .unwrap();
        let mut lines = Vec::new();
        m.feed(1.0, &buf[..n], |d| lines.push(d.line.to_owned()));
        assert!(
            lines[0].contains("lat=434629172 [1e7deg] 43.4629172 deg"),
            "{}",
            lines[0]
        );
        assert!(!lines[0].contains("none"), "{}", lines[0]);
    }
}
