//! The monitor's command line with several aircraft: every line names its source, the
//! table has a section per aircraft, `--ac-id` addresses PINGs and SETTINGs (frame
//! destination and `ac_id` field) to one or several aircraft and their answers are
//! matched by source, and a flood from every source id is bounded.

use std::net::UdpSocket;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use pprz_transports::{Encoder, MsgHeader, PprzV1, PprzV2, TxMeta};

mod common;

use common::{MESSAGES, monitor, run};

/// A fresh temporary directory for one test.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pprz-fleet-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A PPRZ v2 telemetry frame from `source` to the ground.
fn frame_from(source: u8, id: u8, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(source, 0, 1, id));
    let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// ALIVE (telemetry 2) with a 2-byte md5sum.
fn alive_from(source: u8, n: u8) -> Vec<u8> {
    frame_from(source, 2, &[2, n, 0xAD])
}

#[test]
fn lines_name_their_source_and_the_table_has_a_section_per_aircraft() {
    let dir = temp_dir("sections");
    let input = dir.join("two.bin");
    let mut bytes = alive_from(7, 1);
    bytes.extend(alive_from(8, 2));
    bytes.extend(alive_from(8, 3));
    std::fs::write(&input, &bytes).unwrap();
    let file = input.to_str().unwrap();

    let (code, out, err) = run(monitor().args(["--messages", MESSAGES, "--file", file, "--lines"]));
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(
        out.lines().collect::<Vec<_>>(),
        [
            "7 telemetry ALIVE md5sum=1,173",
            "8 telemetry ALIVE md5sum=2,173",
            "8 telemetry ALIVE md5sum=3,173"
        ]
    );
    // The summary per aircraft.
    assert!(err.contains("aircraft: 7, 8\n"), "{err}");
    assert!(
        err.contains(
            "aircraft 8: frames 2  unknown 0  malformed 0\n  received per priority level:"
        ),
        "{err}"
    );

    let (code, view, err) = run(monitor().args(["--messages", MESSAGES, "--file", file]));
    assert_eq!(code, Some(0), "{err}");
    let s7 = view.rfind("aircraft 7: frames 1").expect(&view);
    let s8 = view.rfind("aircraft 8: frames 2").expect(&view);
    assert!(s7 < s8, "{view}");
    assert!(view[s8..].contains("telemetry  ALIVE"), "{view}");

    // PPRZ v1: the source is the sender id.
    let mut v1 = Vec::new();
    for sender in [3u8, 4] {
        let mut buf = [0u8; 64];
        let meta = TxMeta::new(MsgHeader::new(sender, 0, 1, 2));
        let n = PprzV1::new(1)
            .encode(&meta, &[2, sender, 0xAD], &mut buf)
            .unwrap();
        v1.extend_from_slice(&buf[..n]);
    }
    std::fs::write(&input, &v1).unwrap();
    let (code, out, err) = run(monitor().args([
        "--messages",
        MESSAGES,
        "--file",
        file,
        "--transport",
        "pprz1",
        "--lines",
    ]));
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(
        out.lines().collect::<Vec<_>>(),
        [
            "3 telemetry ALIVE md5sum=3,173",
            "4 telemetry ALIVE md5sum=4,173"
        ]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Hostile input: frames from all 256 source ids. Every one is decoded and shown; at
/// most 32 aircraft get a section, the others are counted.
#[test]
fn a_flood_from_every_source_id_is_bounded() {
    let dir = temp_dir("flood");
    let input = dir.join("flood.bin");
    let bytes: Vec<u8> = (0..=255u8).flat_map(|s| alive_from(s, s)).collect();
    std::fs::write(&input, &bytes).unwrap();
    let file = input.to_str().unwrap();
    let (code, out, err) = run(monitor().args(["--messages", MESSAGES, "--file", file, "--lines"]));
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(out.lines().count(), 256);
    assert!(
        out.lines()
            .last()
            .unwrap()
            .starts_with("255 telemetry ALIVE")
    );
    assert!(
        err.contains("not tracked (more than 32 aircraft): 224 frames from 224 aircraft"),
        "{err}"
    );
    assert_eq!(err.matches("\naircraft ").count(), 32, "{err}");
    let (code, view, err) = run(monitor().args(["--messages", MESSAGES, "--file", file]));
    assert_eq!(code, Some(0), "{err}");
    assert!(view.contains("aircraft 31: frames 1"), "{view}");
    assert!(!view.contains("aircraft 32: frames"), "{view}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A frame the fake aircraft received: destination, class, message id, fields.
type Uplink = (u8, u8, u8, Vec<u8>);

/// Runs the monitor over loopback UDP with `args` against fake aircraft that answer as
/// whichever aircraft a frame is addressed to: a PONG for a PING, a DL_VALUE with the
/// value set for a SETTING. Returns the frames they received, and the monitor's exit
/// code, standard output and standard error.
fn with_fake_aircraft(args: &[&str]) -> (Vec<Uplink>, Option<i32>, String, String) {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let port = socket.local_addr().unwrap().port();
    let done = Arc::new(AtomicBool::new(false));
    let stop = done.clone();
    let fake = std::thread::spawn(move || {
        let mut received = Vec::new();
        let mut buf = [0u8; 512];
        while !stop.load(Ordering::SeqCst) {
            let Ok((n, from)) = socket.recv_from(&mut buf) else {
                continue;
            };
            // PPRZ v2: 99 len source destination class id fields... ck_a ck_b
            let f = &buf[..n];
            let (dest, class, id) = (f[3], f[4], f[5]);
            received.push((dest, class, id, f[6..n - 2].to_vec()));
            let reply = match (class, id) {
                (2, 8) => frame_from(dest, 3, &[]),
                // SETTING index ac_id value: applied.
                (2, 4) => frame_from(dest, 31, &[f[6], f[8], f[9], f[10], f[11]]),
                _ => continue,
            };
            socket.send_to(&reply, from).unwrap();
        }
        received
    });
    let uplink = format!("127.0.0.1:{port}");
    let mut all = vec![
        "--messages",
        MESSAGES,
        "--udp",
        "127.0.0.1:0",
        "--uplink",
        &uplink,
        "--lines",
        "--duration",
        "1.5",
    ];
    all.extend_from_slice(args);
    let (code, out, err) = run(monitor().args(all));
    done.store(true, Ordering::SeqCst);
    (fake.join().unwrap(), code, out, err)
}

#[test]
fn ac_id_addresses_pings_and_settings_to_that_aircraft() {
    let (received, code, out, err) =
        with_fake_aircraft(&["--ac-id", "8", "--ping", "0.2", "--setting", "5=0.5"]);
    assert_eq!(code, Some(0), "{err}");
    let pings: Vec<_> = received.iter().filter(|r| (r.1, r.2) == (2, 8)).collect();
    assert!(!pings.is_empty(), "{received:?}");
    assert!(pings.iter().all(|p| p.0 == 8), "{received:?}");
    let settings: Vec<_> = received.iter().filter(|r| (r.1, r.2) == (2, 4)).collect();
    assert_eq!(settings.len(), 1, "{received:?}");
    // SETTING index=5 ac_id=8 value=0.5, to aircraft 8.
    assert_eq!(settings[0].0, 8);
    assert_eq!(settings[0].3, [5, 8, 0, 0, 0, 0x3F]);
    assert!(out.lines().all(|l| l.starts_with("8 telemetry ")), "{out}");
    // One aircraft: the lines as before, without its name.
    assert!(err.contains("] PONG: round trip"), "{err}");
    assert!(
        err.contains("] DL_VALUE index=5 value=0.5: SETTING acknowledged"),
        "{err}"
    );
    assert!(err.contains("settings: acknowledged 1"), "{err}");
    assert!(err.contains("unexpected pongs 0"), "{err}");
    assert!(!err.contains("aircraft 8:"), "{err}");
}

#[test]
fn several_ac_ids_ping_and_set_each_aircraft() {
    let (received, code, out, err) = with_fake_aircraft(&[
        "--ac-id",
        "7",
        "--ac-id",
        "8",
        "--ping",
        "0.2",
        "--setting",
        "5=0.5",
    ]);
    assert_eq!(code, Some(0), "{err}");
    for ac in [7u8, 8] {
        assert!(
            received.iter().any(|r| (r.0, r.1, r.2) == (ac, 2, 8)),
            "no PING to {ac}: {received:?}"
        );
        let settings: Vec<_> = received
            .iter()
            .filter(|r| (r.0, r.1, r.2) == (ac, 2, 4))
            .collect();
        assert_eq!(settings.len(), 1, "{received:?}");
        assert_eq!(
            settings[0].3[1], ac,
            "the ac_id field follows the destination"
        );
        assert!(out.contains(&format!("{ac} telemetry PONG")), "{out}");
        assert!(
            err.contains(&format!("aircraft {ac}: PONG: round trip")),
            "{err}"
        );
        assert!(
            err.contains(&format!(
                "aircraft {ac}: DL_VALUE index=5 value=0.5: SETTING acknowledged"
            )),
            "{err}"
        );
    }
    assert!(
        received.iter().all(|r| r.0 == 7 || r.0 == 8),
        "{received:?}"
    );
    // The summary per aircraft: every PONG matched to its own aircraft.
    assert!(err.contains("aircraft: 7, 8\n"), "{err}");
    for ac in [7, 8] {
        let at = err.find(&format!("aircraft {ac}: frames")).expect(&err);
        let section = &err[at..];
        assert!(section.contains("\n  pings: sent "), "{section}");
        assert!(section.contains("unexpected pongs 0"), "{section}");
        assert!(
            section.contains("\n  settings: acknowledged 1"),
            "{section}"
        );
    }
}
