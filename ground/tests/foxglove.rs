//! `pprz-monitor --mcap` and `--foxglove`, checked by independent readers.
//!
//! * A PPRZLOG file of every message of the full PPRZLINK reference set (random field
//!   values, two aircraft) is converted with `--file log --transport pprzlog --mcap`;
//!   PyPI's `mcap` reads the recording back (`ground/tests/foxglove/check_mcap.py`):
//!   every topic has its schema, every message validates, counts and values equal the
//!   monitor's `--lines` output. The log's time stamps are the recording's times.
//! * Write errors end the run with a failure; Ctrl-C finalises the recording.
//! * A client that subscribes to everything and then stops reading does not hold up
//!   decoding.
//!
//! The tools are found with `pprz_test_support::viewer_tools` (skipped, with a printed
//! reason, when they are not installed; a failure when `PPRZ_REQUIRE_REFERENCE` is set).

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Stdio};

use common::{MESSAGES, monitor, run};
use pprz_ground::set::RuntimeSet;
use pprz_messages::dynamic;
use pprz_test_support::reference::skip_test;
use pprz_test_support::rng::Rng;
use pprz_test_support::viewer_tools;
use pprz_transports::{AnyTransport, Encoder, MsgHeader, PprzLog, PprzV2, TxMeta};

/// Frames of every message of `set`, `per_message` times from each of `sources`, with
/// random field values; the PPRZLOG time stamps (100 µs ticks) are increasing.
fn stream(
    set: &RuntimeSet,
    transport: AnyTransport,
    sources: &[u8],
    per_message: usize,
    seed: u64,
) -> (Vec<u8>, Vec<u32>) {
    let mut rng = Rng::new(seed);
    let mut out = Vec::new();
    let mut stamps = Vec::new();
    let mut stamp = 1_000u32;
    for _ in 0..per_message {
        for &source in sources {
            for desc in set.set().messages() {
                let mut payload = vec![0u8; transport.max_payload_len()];
                let elements = [0, 1, 7, 255][rng.below(4)];
                let Ok(n) =
                    dynamic::synthesize(desc, &mut payload, elements, || rng.next_u64() as u8)
                else {
                    continue;
                };
                payload.truncate(n);
                stamp += 1 + rng.below(50) as u32;
                let meta = TxMeta::new(MsgHeader::new(source, 0, desc.class_id, desc.id)).at(stamp);
                let mut buf = vec![0u8; transport.max_frame_len()];
                if let Ok(len) = transport.encode(&meta, &payload, &mut buf) {
                    out.extend_from_slice(&buf[..len]);
                    stamps.push(stamp);
                }
            }
        }
    }
    (out, stamps)
}

/// Runs `check_mcap.py` on a recording and the lines of the same run.
fn check_mcap(python: &Path, mcap: &Path, lines: &str, extra: &[&str]) -> (bool, String) {
    let lines_path = mcap.with_extension("lines");
    std::fs::write(&lines_path, lines).unwrap();
    let script = viewer_tools::scripts().join("check_mcap.py");
    let out = Command::new(python)
        .arg(script)
        .arg(mcap)
        .arg(&lines_path)
        .args(extra)
        .output()
        .expect("python runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

/// The log times of the recording's message topics (not location or link), in order.
fn message_log_times(path: &Path) -> Vec<u64> {
    let bytes = std::fs::read(path).unwrap();
    let mut times = Vec::new();
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let m = m.expect("a readable message");
        let topic = &m.channel.topic;
        if !(topic.ends_with("/location") || topic.ends_with("/link")) {
            times.push(m.log_time);
        }
    }
    times
}

#[test]
fn a_pprzlog_of_the_full_reference_set_converts_to_an_mcap_an_independent_reader_agrees_with() {
    let who = "pprz-ground mcap_of_the_full_reference_set";
    let Some(dir) = pprz_test_support::reference::locate_for_test(who) else {
        return;
    };
    let Some(python) = viewer_tools::python(who) else {
        return;
    };
    let messages = dir.join("messages.xml");
    let set = RuntimeSet::load(&messages).unwrap();
    assert!(set.set().len() > 300);
    let (log, stamps) = stream(&set, PprzLog::TELEMETRY.into(), &[7, 8], 2, 0xF0C5_61E0);
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("flight.log");
    std::fs::write(&input, &log).unwrap();
    let out = tmp.path().join("flight.mcap");
    let (code, lines, err) = run(monitor()
        .args(["--transport", "pprzlog", "--lines", "--messages"])
        .arg(&messages)
        .arg("--file")
        .arg(&input)
        .arg("--mcap")
        .arg(&out));
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(lines.lines().count(), stamps.len(), "{err}");
    assert!(err.contains("foxglove: published"), "{err}");

    let (ok, report) = check_mcap(
        &python,
        &out,
        &lines,
        &[
            "--messages",
            messages.to_str().unwrap(),
            "--log-times",
            "replay",
        ],
    );
    assert!(ok, "{report}");
    assert!(report.contains("checked"), "{report}");

    // The times are the log's (100 µs ticks), in order, for every decoded message.
    let valid: Vec<u64> = lines
        .lines()
        .zip(&stamps)
        .filter(|(l, _)| !l.contains("<error:") && !l.contains("unknown message"))
        .map(|(_, &s)| u64::from(s) * 100_000)
        .collect();
    assert_eq!(message_log_times(&out), valid);
}

#[test]
fn a_recording_that_cannot_be_written_ends_the_run_with_a_failure() {
    if !Path::new("/dev/full").exists() {
        skip_test(
            "pprz-ground a_recording_that_cannot_be_written_ends_the_run_with_a_failure",
            "no /dev/full here",
        );
        return;
    }
    let set = RuntimeSet::load(MESSAGES).unwrap();
    let (log, _) = stream(&set, PprzV2::new().into(), &[7], 40, 1);
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in.bin");
    std::fs::write(&input, &log).unwrap();
    let (code, _, err) = run(monitor()
        .args([
            "--lines",
            "--messages",
            MESSAGES,
            "--mcap",
            "/dev/full",
            "--file",
        ])
        .arg(&input));
    assert_eq!(code, Some(1), "{err}");
    // The first cause, not what the SDK says after it.
    let failures: Vec<&str> = err.lines().filter(|l| l.contains("failed")).collect();
    assert_eq!(
        failures,
        ["error: recording to /dev/full failed: No space left on device (os error 28)"],
        "{err}"
    );
}

#[test]
fn a_recording_cannot_overwrite_an_input() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in.bin");
    std::fs::write(&input, b"keep").unwrap();
    let (code, _, err) = run(monitor()
        .args(["--messages", MESSAGES, "--file"])
        .arg(&input)
        .arg("--mcap")
        .arg(&input));
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(std::fs::read(&input).unwrap(), b"keep");
    // Nor the PPRZLOG recording of the same run.
    let rec = tmp.path().join("rec.log");
    let (code, _, err) = run(monitor()
        .args(["--messages", MESSAGES, "--file"])
        .arg(&input)
        .arg("--record")
        .arg(&rec)
        .arg("--mcap")
        .arg(&rec));
    assert_eq!(code, Some(1), "{err}");
}

/// Reads lines of `child`'s standard output until `n` arrived; returns them.
fn read_lines(out: &mut impl BufRead, n: usize) -> Vec<String> {
    let mut lines = Vec::new();
    while lines.len() < n {
        let mut line = String::new();
        if out.read_line(&mut line).unwrap() == 0 {
            break;
        }
        lines.push(line);
    }
    lines
}

/// Sends SIGINT (Ctrl-C) to `child`.
fn interrupt(child: &Child) {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

#[test]
fn ctrl_c_finalises_the_recording() {
    let Some(python) = viewer_tools::python("pprz-ground ctrl_c_finalises_the_recording") else {
        return;
    };
    let set = RuntimeSet::load(MESSAGES).unwrap();
    let (bytes, stamps) = stream(&set, PprzV2::new().into(), &[7], 3, 2);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("live.mcap");
    let mut child = Command::new(env!("CARGO_BIN_EXE_pprz-monitor"))
        .args(["--stdin", "--lines", "--messages", MESSAGES, "--mcap"])
        .arg(&out)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The input stays open (a live link): only Ctrl-C ends the run.
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(&bytes).unwrap();
    stdin.flush().unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut lines = read_lines(&mut stdout, stamps.len());
    assert_eq!(lines.len(), stamps.len());
    interrupt(&child);
    lines.extend(read_lines(&mut stdout, usize::MAX));
    let status = child.wait().unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    drop(stdin);
    assert_eq!(status.code(), Some(0), "{err}");
    let (ok, report) = check_mcap(&python, &out, &lines.concat(), &["--log-times", "wall"]);
    assert!(ok, "{report}");
}

#[test]
fn a_client_that_stops_reading_does_not_hold_up_decoding() {
    let who = "pprz-ground a_client_that_stops_reading_does_not_hold_up_decoding";
    let Some(client) = viewer_tools::node_client(who) else {
        return;
    };
    let set = RuntimeSet::load(MESSAGES).unwrap();
    let transport: AnyTransport = PprzV2::new().into();
    let (first, first_stamps) = stream(&set, transport, &[7], 1, 3);
    // Enough JSON to fill any socket buffer many times over.
    let (bulk, bulk_stamps) = stream(&set, transport, &[7], 1500, 4);
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_pprz-monitor"))
        .args([
            "--lines",
            "--messages",
            MESSAGES,
            "--foxglove",
            "127.0.0.1:0",
            "--tcp",
        ])
        .arg(addr.to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut link, _) = listener.accept().unwrap();
    // Standard error: the server's address, then everything else (read to the end, so
    // that the monitor never waits on it).
    let (url, stderr) = viewer_tools::served_url(child.stderr.take().unwrap());
    // One of each message: every topic exists; the client subscribes to all of them.
    link.write_all(&first).unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    assert_eq!(
        read_lines(&mut stdout, first_stamps.len()).len(),
        first_stamps.len()
    );
    let mut stalled = Command::new("node")
        .arg(&client)
        .arg(&url)
        .arg("--stall")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut said = String::new();
    BufReader::new(stalled.stdout.take().unwrap())
        .read_line(&mut said)
        .unwrap();
    assert_eq!(said.trim(), "stalled");
    // Every message of the bulk is decoded while the client reads nothing (written from
    // a thread: the monitor's output is read here meanwhile).
    let writer = std::thread::spawn(move || {
        link.write_all(&bulk).unwrap();
    });
    let rest = read_lines(&mut stdout, usize::MAX);
    writer.join().unwrap();
    let status = child.wait().unwrap();
    let _ = stalled.kill();
    let _ = stalled.wait();
    let err = stderr.join().unwrap();
    assert_eq!(status.code(), Some(0), "{err}");
    assert_eq!(rest.len(), bulk_stamps.len(), "{err}");
    assert!(err.contains("input dropped 0 B"), "{err}");
}

#[test]
fn the_suggested_layout_plots_fields_that_exist() {
    let layout: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../docs/foxglove-layout.json"
        ))
        .unwrap(),
    )
    .unwrap();
    let set = RuntimeSet::load(MESSAGES).unwrap();
    let link: serde_json::Value = serde_json::from_str(pprz_ground::viewer::LINK_SCHEMA).unwrap();
    let mut checked = 0;
    for panel in layout["configById"].as_object().unwrap().values() {
        for path in panel["paths"].as_array().into_iter().flatten() {
            let value = path["value"].as_str().unwrap();
            let (topic, field) = value.split_once('.').unwrap();
            let field = field.split(['.', '[']).next().unwrap();
            let properties = match topic.rsplit('/').next().unwrap() {
                "link" => link["properties"].clone(),
                name => {
                    let desc = set
                        .find_by_name("telemetry", name)
                        .unwrap_or_else(|| panic!("{value}"));
                    let schema: serde_json::Value =
                        serde_json::from_str(&pprz_ground::json::schema(desc)).unwrap();
                    schema["properties"].clone()
                }
            };
            assert!(properties.get(field).is_some(), "{value}: no field {field}");
            checked += 1;
        }
    }
    assert!(checked >= 10, "{checked}");
}

#[test]
fn hostile_names_are_refused_before_anything_is_served_or_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out.mcap");
    for (name, field) in [
        ("A/../B", "x"),
        ("A B", "x"),
        ("A", "x&quot;y"),
        ("A", "x&#10;y"),
    ] {
        let xml = tmp.path().join("hostile.xml");
        std::fs::write(
            &xml,
            format!(
                r#"<protocol><msg_class name="telemetry" id="1"><message name="{name}" id="5"><field name="{field}" type="uint8"/></message></msg_class></protocol>"#
            ),
        )
        .unwrap();
        let (code, _, err) = run(monitor()
            .args(["--stdin", "--foxglove", "127.0.0.1:0", "--messages"])
            .arg(&xml)
            .arg("--mcap")
            .arg(&out));
        assert_eq!(code, Some(1), "{err}");
        assert!(err.contains("not a valid identifier"), "{err}");
        assert!(!err.contains("serving"), "{err}");
        assert!(!out.exists());
    }
}

/// Starts `pprz-monitor --stdin --foxglove 127.0.0.1:0` (the input stays open until
/// the returned stdin is dropped); gives the child, its stdin, the server's address and
/// the thread reading its standard error.
fn serving_monitor(
    extra: &[&str],
) -> (
    Child,
    std::process::ChildStdin,
    String,
    std::thread::JoinHandle<String>,
) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_pprz-monitor"))
        .args([
            "--stdin",
            "--lines",
            "--messages",
            MESSAGES,
            "--foxglove",
            "127.0.0.1:0",
        ])
        .args(extra)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdin = child.stdin.take().unwrap();
    let (url, stderr) = viewer_tools::served_url(child.stderr.take().unwrap());
    let addr = url.strip_prefix("ws://").unwrap().to_owned();
    (child, stdin, addr, stderr)
}

/// Opens a connection and sends a Foxglove WebSocket handshake; gives the stream and the
/// status line of the answer (empty when the server closed without one).
fn ws_connect(addr: &str) -> (std::net::TcpStream, String) {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    // A hang guard only.
    s.set_read_timeout(Some(std::time::Duration::from_secs(20)))
        .unwrap();
    let request = format!(
        "GET / HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
    );
    let _ = s.write_all(request.as_bytes());
    let mut line = Vec::new();
    let mut byte = [0u8; 1];
    while !line.ends_with(b"\r\n") {
        match s.read(&mut byte) {
            Ok(1) => line.push(byte[0]),
            _ => break,
        }
    }
    (s, String::from_utf8_lossy(&line).trim().to_owned())
}

/// Reads until the server closes the connection: `true`, or `false` when it stays
/// open (the read's hang guard expires).
fn closed_by_server(s: &mut std::net::TcpStream) -> bool {
    let mut buf = vec![0u8; 64 * 1024];
    loop {
        match s.read(&mut buf) {
            Ok(0) => return true,
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return true,
            Err(_) => return false,
        }
    }
}

/// Ends a monitor started by [`serving_monitor`]: its status and standard error.
fn end_monitor(
    mut child: Child,
    stdin: std::process::ChildStdin,
    stderr: std::thread::JoinHandle<String>,
) -> (Option<i32>, String) {
    drop(stdin);
    let status = child.wait().unwrap();
    (status.code(), stderr.join().unwrap())
}

/// Peak resident memory of a process, kB (`VmHWM`); `None` without `/proc`.
fn peak_rss_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

#[test]
fn the_client_over_the_limit_is_refused_and_counted() {
    let max = pprz_ground::viewer::DEFAULT_MAX_CLIENTS;
    let (child, stdin, addr, stderr) = serving_monitor(&[]);
    let mut clients = Vec::new();
    for i in 0..max {
        let (s, status) = ws_connect(&addr);
        assert!(status.starts_with("HTTP/1.1 101"), "client {i}: {status:?}");
        clients.push(s);
    }
    let (mut extra, status) = ws_connect(&addr);
    assert!(
        status.starts_with("HTTP/1.1 503"),
        "client {max}: {status:?}"
    );
    assert!(closed_by_server(&mut extra));
    // A client that leaves frees its place (bounded retries while the place is freed).
    drop(clients.pop());
    let mut accepted = false;
    for _ in 0..100 {
        let (s, status) = ws_connect(&addr);
        if status.starts_with("HTTP/1.1 101") {
            clients.push(s);
            accepted = true;
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    assert!(accepted, "a place freed is taken again");
    drop(clients);
    let (code, err) = end_monitor(child, stdin, stderr);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("clients refused "), "{err}");
    assert!(!err.contains("clients refused 0 "), "{err}");
}

#[test]
fn a_fragmented_message_over_the_bound_closes_its_connection() {
    let (child, stdin, addr, stderr) = serving_monitor(&[]);
    let (mut hostile, status) = ws_connect(&addr);
    assert!(status.starts_with("HTTP/1.1 101"), "{status:?}");
    let before = peak_rss_kb(child.id());
    // One text message in fragments of 1 MiB (masked, as a client's must be), 16 in
    // all: 16 times the bound.
    let fragment = |first: bool| {
        let mut f = vec![if first { 0x01 } else { 0x00 }, 0x80 | 127];
        f.extend((1u64 << 20).to_be_bytes());
        f.extend([0u8; 4]); // a zero mask: the payload as it is
        f.resize(f.len() + (1 << 20), b' ');
        f
    };
    let mut sent = 0;
    for i in 0..16 {
        if hostile.write_all(&fragment(i == 0)).is_err() {
            break;
        }
        sent += 1;
    }
    assert!(
        closed_by_server(&mut hostile),
        "still open after {sent} MiB"
    );
    if let (Some(before), Some(after)) = (before, peak_rss_kb(child.id())) {
        // Unbounded, the server would hold the 16 MiB.
        assert!(after < before + 8 * 1024, "{before} kB, then {after} kB");
    }
    // The others are still served.
    let (_other, status) = ws_connect(&addr);
    assert!(status.starts_with("HTTP/1.1 101"), "{status:?}");
    let (code, err) = end_monitor(child, stdin, stderr);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("closed 1 (request too long"), "{err}");
}
