//! Link quality through `pprz-monitor`'s command line: `--stale-after` checked, an
//! aircraft marked stale by the monitor's timer while no frame arrives, and the link
//! figures of an XBee recording in the summary and the MCAP's `/ac/<id>/link` topic.

mod common;

use std::io::Write as _;
use std::process::Stdio;

use common::{MESSAGES, monitor, run};
use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta, XBee24};

/// A telemetry frame from aircraft 7, PPRZ v2.
fn frame(id: u8, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, id));
    let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// A telemetry frame from aircraft 7 as a receiving XBee 802.15.4 modem gives it (RX16),
/// with its RSSI `rssi` (-rssi dBm).
fn xbee_rx(id: u8, payload: &[u8], rssi: u8) -> Vec<u8> {
    let mut buf = [0u8; 128];
    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, id));
    let n = XBee24::new().encode(&meta, payload, &mut buf).unwrap();
    let mut f = buf[..n].to_vec();
    // | 0x7E | len (2) | API id | frame_id | dest (2) | options | ... | checksum |
    f[3] = 0x81;
    f[4..8].copy_from_slice(&[0, 7, rssi, 0]);
    let last = f.len() - 1;
    let sum = f[3..last].iter().fold(0u8, |a, b| a.wrapping_add(*b));
    f[last] = 0xFF - sum;
    f
}

/// DATALINK_REPORT with `uplink_lost_time` and `downlink_nb_msgs`.
fn report_payload(uplink_lost_time: u16, downlink_nb_msgs: u16) -> Vec<u8> {
    let mut p = Vec::new();
    for v in [uplink_lost_time, 3, downlink_nb_msgs, 120, 2] {
        p.extend(v.to_le_bytes());
    }
    p.push(0);
    p
}

#[test]
fn nonsense_stale_times_are_refused() {
    for bad in ["-1", "0", "NaN", "inf", "-inf", "1e9", "soon", ""] {
        let (code, _, err) = run(monitor().args([
            "--messages",
            MESSAGES,
            "--stdin",
            &format!("--stale-after={bad}"),
        ]));
        assert_eq!(code, Some(2), "{bad}: {err}");
        assert!(err.contains("--stale-after"), "{bad}: {err}");
    }
}

/// One frame, then silence: the monitor's timer marks the aircraft stale, once, while
/// nothing arrives; the summary shows it stale.
#[test]
fn a_silent_aircraft_is_marked_stale_while_no_frame_arrives() {
    let mut child = monitor()
        .args(["--messages", MESSAGES, "--stdin", "--lines"])
        .args(["--stale-after", "0.3", "--duration", "1.5"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the monitor runs");
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(&frame(2, &[1, 0xAB])).unwrap();
    stdin.flush().unwrap();
    // The input stays open (and silent) until the run ends.
    let out = child.wait_with_output().unwrap();
    drop(stdin);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "7 telemetry ALIVE md5sum=171\n"
    );
    assert_eq!(
        err.matches("aircraft 7: link stale, not heard for").count(),
        1,
        "{err}"
    );
    assert!(!err.contains("live again"), "{err}");
    assert!(err.contains("\nlink: stale, not heard for "), "{err}");
}

/// An XBee recording: the aircraft's RSSI message, the modem's RSSI of each frame, two
/// DATALINK_REPORTs (a loss estimate) and the autopilot mode, in the summary and in the
/// MCAP's link topic.
#[test]
fn an_xbee_recording_gives_every_link_figure() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("xbee.bin");
    let mut stream = xbee_rx(30, &report_payload(1, 100), 40);
    stream.extend(xbee_rx(28, &[62, 10], 40));
    let mut status = vec![0u8; 24];
    status[8] = 2; // HOME
    stream.extend(xbee_rx(231, &status, 40));
    // 8 sent since the first report, 3 received (the report included).
    stream.extend(xbee_rx(30, &report_payload(4, 108), 40));
    std::fs::write(&input, &stream).unwrap();
    let mcap = tmp.path().join("xbee.mcap");
    let (code, lines, err) = run(monitor()
        .args(["--messages", MESSAGES, "--transport", "xbee", "--lines"])
        .arg("--file")
        .arg(&input)
        .arg("--mcap")
        .arg(&mcap));
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(lines.lines().count(), 4, "{lines}");
    assert!(
        err.contains("uplink lost 4 s  RSSI -62 dBm (tx power 10 dB)  ground RSSI -40 dBm (mean -40.0 dBm)  downlink loss 62.5% over the last report period (62.5% overall)  mode HOME"),
        "{err}"
    );
    assert!(err.contains("\nlink: live, heard "), "{err}");

    let bytes = std::fs::read(&mcap).unwrap();
    let mut last = None;
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let m = m.expect("a readable message");
        if m.channel.topic == "/ac/7/link" {
            last = Some(serde_json::from_slice::<serde_json::Value>(&m.data).unwrap());
        }
    }
    let link = last.expect("a link message");
    assert_eq!(link["state"], "live", "{link}");
    assert_eq!(link["rssi_dbm"], -62, "{link}");
    assert_eq!(link["tx_power_db"], 10, "{link}");
    assert_eq!(link["ground_rssi_dbm"], -40, "{link}");
    assert_eq!(link["ground_rssi_mean_dbm"], -40.0, "{link}");
    assert_eq!(link["uplink_lost_time"], 4.0, "{link}");
    assert_eq!(link["loss_rate"], 0.625, "{link}");
    assert_eq!(link["ap_mode"], "HOME", "{link}");
    assert!(
        link["since_heard_s"].as_f64().is_some_and(|s| s >= 0.0),
        "{link}"
    );
}
