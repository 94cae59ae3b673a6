//! The monitor end to end through its command line: decoding a noisy stream with the
//! project's messages.xml, recording to PPRZLOG and replaying the recording to the same
//! output, and clear errors for bad input.

use std::process::Command;

use pprz_messages::{Message, VarArray};
use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};

mod common;

use common::MESSAGES;

fn monitor(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_pprz-monitor"))
        .args(args)
        .output()
        .expect("the monitor runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Replays a PPRZLOG recording in line mode.
fn replay(log: &std::path::Path) -> (bool, String, String) {
    let log = log.to_str().unwrap();
    monitor(&[
        "--messages",
        MESSAGES,
        "--file",
        log,
        "--transport",
        "pprzlog",
        "--lines",
    ])
}

/// PPRZ v2 frames of a few telemetry messages with garbage between them.
fn stream() -> Vec<u8> {
    let mut out = vec![0x13, 0x99, 0x05, 0x00]; // noise and a false start
    let mut push = |id: u8, fields: &[u8]| {
        let mut buf = [0u8; 300];
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, id));
        let n = PprzV2::new().encode(&meta, fields, &mut buf).unwrap();
        out.extend_from_slice(&buf[..n]);
        out.extend_from_slice(&[0x42]);
    };
    let mut fields = [0u8; 64];
    let gps = common::gps();
    let n = gps.encode(&mut fields).unwrap();
    push(8, &fields[..n]);
    push(31, &[4, 0, 0, 0x20, 0x40]); // DL_VALUE index 4, value 2.5
    push(200, &[1, 2, 3]); // an id the set does not know
    push(31, &[4, 0, 0]); // DL_VALUE with a truncated payload
    let alive = pprz_ground_test_messages::alive();
    let n = alive.encode(&mut fields).unwrap();
    push(2, &fields[..n]);
    out
}

/// Messages built with the generated types of the default set.
mod pprz_ground_test_messages {
    use super::*;
    use pprz_default::messages::telemetry::{Alive, Gps};

    pub fn alive() -> Alive<'static> {
        Alive {
            md5sum: VarArray::new(&[0xDE, 0xAD]),
        }
    }

    #[test]
    fn ids_match() {
        assert_eq!((Gps::ID, Alive::ID), (8, 2));
    }
}

#[test]
fn decodes_records_and_replays_the_same_output() {
    let dir = std::env::temp_dir().join(format!("pprz-monitor-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("stream.bin");
    let log = dir.join("stream.log");
    std::fs::write(&input, stream()).unwrap();

    let (ok, live, _) = monitor(&[
        "--messages",
        MESSAGES,
        "--file",
        input.to_str().unwrap(),
        "--lines",
        "--record",
        log.to_str().unwrap(),
    ]);
    assert!(ok);
    let lines: Vec<&str> = live.lines().collect();
    assert_eq!(lines.len(), 5, "{live}");
    assert!(
        lines[0]
            .starts_with("7 telemetry GPS mode=3 [byte_mask] utm_east=37712345 [cm] 377123.450 m"),
        "{}",
        lines[0]
    );
    assert_eq!(lines[1], "7 telemetry DL_VALUE index=4 value=2.5");
    assert_eq!(lines[2], "7 class1 id=200 unknown message (3 bytes)");
    assert_eq!(
        lines[3],
        "7 telemetry DL_VALUE index=4 <error: payload truncated: needs at least 5 bytes, got 3>"
    );
    assert_eq!(lines[4], "7 telemetry ALIVE md5sum=222,173");

    let (ok, replayed, _) = replay(&log);
    assert!(ok);
    assert_eq!(
        replayed, live,
        "a replay of the recording decodes to the same output"
    );

    // A truncated recording: every whole record still decodes.
    let bytes = std::fs::read(&log).unwrap();
    std::fs::write(&log, &bytes[..bytes.len() - 3]).unwrap();
    let (ok, partial, _) = replay(&log);
    assert!(ok);
    assert_eq!(partial.lines().count(), 4);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_table_view_shows_rates_units_and_counters() {
    let dir = std::env::temp_dir().join(format!("pprz-monitor-table-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("stream.bin");
    std::fs::write(&input, stream()).unwrap();
    let (ok, out, err) = monitor(&["--messages", MESSAGES, "--file", input.to_str().unwrap()]);
    assert!(ok);
    assert!(out.contains("frames ok 5"), "{out}");
    assert!(out.contains("unknown 1  malformed 1"), "{out}");
    assert!(out.contains("telemetry  GPS"), "{out}");
    assert!(err.contains("received per priority level:"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_messages_xml_is_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("pprz-monitor-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let xml = dir.join("bad.xml");
    std::fs::write(&xml, "<protocol><msg_class name=\"telemetry\" id=\"1\"><message name=\"X\" id=\"1\"><field name=\"a\" type=\"uint9\"/></message></msg_class></protocol>").unwrap();
    let (ok, _, err) = monitor(&["--messages", xml.to_str().unwrap(), "--stdin"]);
    assert!(!ok);
    assert!(
        err.contains("bad.xml:1:") && err.contains("unknown type `uint9`"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue: without `--messages` and no messages.xml here, the error read
/// "error: error: messages.xml: cannot read file" on two lines.
#[test]
fn a_missing_messages_file_is_one_clear_line() {
    let (ok, _, err) = monitor(&["--messages", "/nonexistent/messages.xml", "--stdin"]);
    assert!(!ok);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with("error: /nonexistent/messages.xml: cannot read file")
            && err.contains("with --messages"),
        "{err}"
    );
    assert!(!err.contains("error: error:"), "{err}");
}

/// Issue: replaying a recording warned of every PONG in it ("PONG that answers no PING
/// outstanding": the PINGs were sent by the station that recorded), and its first view
/// showed `t=0.0s 2411480 B/s`.
#[test]
fn a_replay_has_no_false_pong_warning_nor_rate_over_no_time() {
    let dir = std::env::temp_dir().join(format!("pprz-monitor-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (input, log) = (dir.join("pongs.bin"), dir.join("pongs.log"));
    let mut bytes = stream();
    for _ in 0..3 {
        let mut buf = [0u8; 16];
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 3)); // PONG to the ground
        let n = PprzV2::new().encode(&meta, &[], &mut buf).unwrap();
        bytes.extend_from_slice(&buf[..n]);
    }
    std::fs::write(&input, bytes).unwrap();
    let (ok, _, err) = monitor(&[
        "--messages",
        MESSAGES,
        "--file",
        input.to_str().unwrap(),
        "--lines",
        "--record",
        log.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let (ok, lines, err) = replay(&log);
    assert!(ok, "{err}");
    assert_eq!(lines.matches("telemetry PONG").count(), 3, "{lines}");
    assert!(!err.contains("PONG that answers no PING"), "{err}");
    assert!(!err.contains("unexpected pongs"), "{err}");
    let log = log.to_str().unwrap();
    let args = [
        "--messages",
        MESSAGES,
        "--file",
        log,
        "--transport",
        "pprzlog",
    ];
    let (ok, table, err) = monitor(&args);
    assert!(ok, "{err}");
    let first = table.split("\x1b[2J\x1b[H").nth(1).unwrap();
    let status = first.lines().next().unwrap();
    assert!(status.contains("s        - B/s  frames ok"), "{status}");
    let _ = std::fs::remove_dir_all(&dir);
}
