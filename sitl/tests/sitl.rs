//! The simulated aircraft and the ground monitor talking over real loopback UDP sockets:
//! telemetry arrives decoded, PING gets its PONG, SETTING its DL_VALUE acknowledgement,
//! and under a 10x overload only low-priority messages are shed.

use std::net::UdpSocket;
use std::path::PathBuf;
use std::process::Command;

use serde_json::Value;

/// Two free loopback UDP ports (bound then released; the test runs them at once).
fn free_ports() -> (u16, u16) {
    let a = UdpSocket::bind("127.0.0.1:0").unwrap();
    let b = UdpSocket::bind("127.0.0.1:0").unwrap();
    (
        a.local_addr().unwrap().port(),
        b.local_addr().unwrap().port(),
    )
}

fn run_sitl(extra: &[&str]) -> String {
    run_sitl_for("6", "3", extra)
}

/// Runs the simulation with the monitor (one line per message) for `duration` simulated
/// seconds at `speed`, plus `extra` options; returns its output.
fn run_sitl_for(duration: &str, speed: &str, extra: &[&str]) -> String {
    // The ports are free when chosen, but another test may take one before the SITL
    // binds it: such a run is repeated with new ports (at most twice).
    for _ in 0..2 {
        let (ok, stdout, stderr) = run_sitl_once(duration, speed, extra);
        if ok || !stderr.to_lowercase().contains("in use") {
            assert!(ok, "sitl failed: {stderr}\n{stdout}");
            return stdout;
        }
    }
    let (ok, stdout, stderr) = run_sitl_once(duration, speed, extra);
    assert!(ok, "sitl failed: {stderr}\n{stdout}");
    stdout
}

/// One run of the simulation on fresh ports: success, standard output and error.
fn run_sitl_once(duration: &str, speed: &str, extra: &[&str]) -> (bool, String, String) {
    let (ground, uplink) = free_ports();
    let ground = format!("127.0.0.1:{ground}");
    let uplink = format!("127.0.0.1:{uplink}");
    let mut args = vec![
        "--duration",
        duration,
        "--speed",
        speed,
        "--lines",
        "--ground",
        &ground,
        "--uplink",
        &uplink,
    ];
    args.extend_from_slice(extra);
    let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
        .args(&args)
        .output()
        .expect("the simulation runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A path for a summary in the temporary directory, unique to this test process.
fn temp_json(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("pprz-sitl-{}-{name}.json", std::process::id()))
}

/// Runs like [`run_sitl_for`] with `--summary-json`; returns the output and the summary.
fn run_sitl_json(name: &str, duration: &str, speed: &str, extra: &[&str]) -> (String, Value) {
    let path = temp_json(name);
    let path_str = path.to_str().expect("a UTF-8 temporary path").to_owned();
    let mut args = vec!["--summary-json", &path_str];
    args.extend_from_slice(extra);
    let out = run_sitl_for(duration, speed, &args);
    let text = std::fs::read_to_string(&path).expect("the summary file was written");
    let _ = std::fs::remove_file(&path);
    let json: Value = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("the summary is not valid JSON ({e}):\n{text}"));
    (out, json)
}

/// A whole number at `pointer` (JSON pointer syntax) in `json`.
fn uint(json: &Value, pointer: &str) -> u64 {
    json.pointer(pointer)
        .and_then(Value::as_u64)
        .unwrap_or_else(|| panic!("{pointer} is not a whole number in {json:#}"))
}

/// The summary row of a level: submitted, sent, shed, superseded, received (the age
/// columns after them are left out).
fn level_row(out: &str, level: &str) -> [u64; 5] {
    let line = out
        .lines()
        .find(|l| {
            let words: Vec<&str> = l.split_whitespace().collect();
            words.len() == 8 && words[0] == level && words[1].parse::<u64>().is_ok()
        })
        .unwrap_or_else(|| panic!("no summary row for {level}:\n{out}"));
    let v: Vec<u64> = line
        .split_whitespace()
        .skip(1)
        .take(5)
        .map(|x| x.parse().unwrap())
        .collect();
    [v[0], v[1], v[2], v[3], v[4]]
}

#[test]
fn telemetry_ping_and_setting_over_udp() {
    let out = run_sitl(&[]);
    let count = |name: &str| {
        out.lines()
            .filter(|l| l.starts_with(&format!("7 telemetry {name} ")))
            .count()
    };
    // ATTITUDE is periodic at 0.25 s: at most 25 in 6 simulated seconds (fewer if the
    // machine is slow to deliver the last ones before the run ends).
    assert!(
        (12..=25).contains(&count("ATTITUDE")),
        "{} ATTITUDE",
        count("ATTITUDE")
    );
    assert!(count("GPS_INT") >= 12);
    assert!(out.contains("7 telemetry ROTORCRAFT_STATUS "), "{out}");
    services_answered(&out);
    // Nothing is shed on a link that is not overloaded.
    for level in ["high", "normal", "low"] {
        assert_eq!(level_row(&out, level)[2], 0, "{level} shed:\n{out}");
    }
}

#[test]
fn overload_sheds_only_low_priority() {
    let out = run_sitl(&["--overload"]);
    let [_, _, high_shed, _, high_received] = level_row(&out, "high");
    let [_, _, normal_shed, _, _] = level_row(&out, "normal");
    let [low_submitted, _, low_shed, _, _] = level_row(&out, "low");
    assert_eq!(high_shed, 0, "{out}");
    assert_eq!(normal_shed, 0, "{out}");
    assert!(high_received >= 3);
    assert!(
        low_shed * 2 > low_submitted,
        "most of the 10x flood is shed:\n{out}"
    );
    assert!(
        out.contains("7 telemetry DL_VALUE index=2 value=2.5"),
        "{out}"
    );
}

/// Options that used to run forever (`--speed 0`), stall (`--speed 1e6`) or exit at once
/// with success (`--speed NaN`, `--speed -1`, `--duration -1`) are refused with a message
/// and a failure status, before anything starts.
#[test]
fn nonsense_options_are_refused() {
    for (option, value) in [
        ("--speed", "0"),
        ("--speed", "1e6"),
        ("--speed", "NaN"),
        ("--speed", "-1"),
        ("--speed", "inf"),
        ("--duration", "-1"),
        ("--duration", "0"),
        ("--duration", "NaN"),
        ("--duration", "1e300"),
        ("--baud", "0"),
        ("--baud", "9"),
        ("--ping-rate", "0"),
        ("--ping-rate", "1e9"),
        ("--modem-buffer", "0"),
        ("--modem-buffer", "-5"),
        ("--modem-buffer", "NaN"),
        ("--modem-buffer", "1e9"),
        ("--modem-buffer", "100000"),
        ("--modem-buffer", "2.5"),
        ("--flow-control", "rts"),
        ("--air-rate", "0"),
        ("--air-rate", "NaN"),
        ("--air-rate", "-1"),
        ("--air-rate", "4000000000"),
        ("--pacing", "maybe"),
        ("--pacing-budget", "0"),
        ("--transport", "mavlink"),
        ("--in-modem", "0"),
        ("--in-modem", "9"),
        ("--outage", "up:20..10"),
        ("--outage", "up:10..10"),
        ("--outage", "up:-1..5"),
        ("--outage", "down:NaN..5"),
        ("--outage", "both:1..inf"),
        ("--outage", "sideways:1..2"),
        ("--outage", "up:1-2"),
        ("--outage", "up"),
        ("--lost-timeout", "0"),
        ("--lost-timeout", "-3"),
        ("--lost-timeout", "NaN"),
        ("--lost-timeout", "inf"),
        ("--resume-nav", "-1"),
        ("--resume-nav", "NaN"),
        ("--setting", "1:256=1"),
        ("--setting", "1:4"),
        ("--setting", "4=1"),
        ("--setting", "-1:4=1"),
        ("--setting", "1:4=NaN"),
        ("--setting", "1:4=inf"),
        ("--fleet", "0"),
        ("--fleet", "33"),
        ("--bit-error-rate", "0.5"),
        ("--bit-error-rate", "NaN"),
        ("--zenoh", "udp/127.0.0.1:7447"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
            .args(["--headless", &format!("{option}={value}")])
            .output()
            .expect("sitl starts");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{option}={value}: {stderr}");
        assert!(
            stderr.contains(option) && stderr.contains(value),
            "{option}={value}: {stderr}"
        );
    }
}

/// A 1 kHz PING flood from the ground: the aircraft answers within its reply limit,
/// counts the PONGs it refuses, and its telemetry flows on (nothing of normal priority
/// shed, ATTITUDE still arriving).
#[test]
fn ping_flood_is_rate_limited_in_the_summary() {
    let out = run_sitl(&["--ping-rate", "1000"]);
    let refused: u64 = out
        .split("replies over the rate limit ")
        .nth(1)
        .and_then(|rest| rest.split([',', ')']).next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no rate-limit count in the summary:\n{out}"));
    assert!(refused > 1000, "{refused} refused:\n{out}");
    let [_, _, normal_shed, _, _] = level_row(&out, "normal");
    assert_eq!(normal_shed, 0, "{out}");
    let attitudes = out
        .lines()
        .filter(|l| l.starts_with("7 telemetry ATTITUDE "))
        .count();
    assert!(attitudes >= 12, "{attitudes} ATTITUDE:\n{out}");
    let pongs = out.lines().filter(|l| *l == "7 telemetry PONG").count() as u64;
    // 10 at once, then 20 per second over 6 s: well under the thousands of PINGs.
    assert!((5..=140).contains(&pongs), "{pongs} PONGs:\n{out}");
}

/// Options that make no sense together are refused before anything starts, naming the
/// options involved.
#[test]
fn contradictory_radio_options_are_refused() {
    for (args, expected) in [
        (
            &["--in-modem", "2"][..],
            &["--in-modem", "--transport xbee"][..],
        ),
        (
            &["--transport", "xbee", "--modem-buffer", "64"],
            &["--modem-buffer 64", "xbee", "109"],
        ),
        (
            &["--pacing-budget", "100"],
            &["--pacing-budget", "--pacing on"],
        ),
        (
            &["--transport", "xbee", "--secure", TEST_KEYS],
            &["--secure", "--transport pprz2"],
        ),
        (
            &["--fleet", "2", "--transport", "xbee"],
            &["--fleet 2", "--transport pprz2"],
        ),
        (
            &["--fleet", "2", "--secure", TEST_KEYS],
            &["--fleet 2", "--secure"],
        ),
        (
            &["--fleet", "32", "--secure", TEST_KEYS],
            &["--fleet 32", "--secure", "one aircraft"],
        ),
        (&["--relay"], &["--relay", "--fleet 2"]),
        (&["--fleet", "3", "--relay"], &["--relay", "--fleet 2"]),
        (&["--resume-nav", "5"], &["--resume-nav", "--headless"]),
        (&["--setting", "1:4=1"], &["--setting", "--headless"]),
        (
            &["--fleet", "2", "--settings-flash", "unused.flash"],
            &["--settings-flash", "--fleet 2"],
        ),
        (
            &[
                "--outage",
                "up:1..2",
                "--outage",
                "up:3..4",
                "--outage",
                "up:5..6",
                "--outage",
                "up:7..8",
                "--outage",
                "up:9..10",
                "--outage",
                "both:11..12",
                "--outage",
                "up:13..14",
                "--outage",
                "up:15..16",
                "--outage",
                "up:17..18",
            ],
            &["--outage", "9 windows cut up", "at most 8"],
        ),
        (
            &[
                "--pacing",
                "on",
                "--modem-buffer",
                "64",
                "--pacing-budget",
                "100",
            ],
            &["--pacing-budget 100", "64"],
        ),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
            .arg("--headless")
            .args(args)
            .output()
            .expect("sitl starts");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        for text in expected {
            assert!(stderr.contains(text), "{args:?}: no `{text}` in {stderr}");
        }
    }
}

/// An outage or `--resume-nav` after the end of the run has no effect: the run goes
/// on, and says so.
#[test]
fn link_options_after_the_end_are_reported() {
    let extra = ["--outage", "up:30..40", "--resume-nav", "1"];
    // Repeated with new ports if another test took one (as `run_sitl_for` does).
    let (mut ok, mut stderr) = (false, String::new());
    for _ in 0..3 {
        let (success, _, err) = run_sitl_once("1", "10", &extra);
        (ok, stderr) = (success, err);
        if ok || !stderr.to_lowercase().contains("in use") {
            break;
        }
    }
    assert!(ok, "{stderr}");
    for text in [
        "--outage up:30..40 starts at or after the end of the run (--duration 1)",
        "--resume-nav 1 is at or after the end of the run (--duration 1)",
    ] {
        assert!(stderr.contains(text), "no `{text}` in {stderr}");
    }
}

/// A summary file that cannot be written is reported at once, with exit code 1.
#[test]
fn unwritable_summary_path_fails_with_a_message() {
    let path = std::env::temp_dir()
        .join(format!("pprz-sitl-no-such-dir-{}", std::process::id()))
        .join("summary.json");
    let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
        .args(["--headless", "--duration", "1", "--speed", "10"])
        .arg("--summary-json")
        .arg(&path)
        .output()
        .expect("sitl starts");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("cannot write the summary") && stderr.contains("summary.json"),
        "{stderr}"
    );
}

/// `--summary-json` writes the documented fields, agreeing with the printed table.
#[test]
fn summary_json_has_the_documented_fields() {
    let (out, json) = run_sitl_json("fields", "6", "3", &[]);
    for (pointer, expected) in [
        ("/config/transport", "pprz2"),
        ("/config/flow_control", "cts"),
    ] {
        assert_eq!(
            json.pointer(pointer).and_then(Value::as_str),
            Some(expected),
            "{json:#}"
        );
    }
    assert_eq!(uint(&json, "/schema"), 1);
    for field in [
        "baud",
        "serial_rate_bytes_per_s",
        "air_rate_bytes_per_s",
        "modem_buffer_bytes",
        "flood_bytes_per_s",
    ] {
        uint(&json, &format!("/config/{field}"));
    }
    assert_eq!(json.pointer("/config/pacing"), Some(&Value::Bool(false)));
    assert_eq!(
        json.pointer("/config/pacing_budget_bytes"),
        Some(&Value::Null)
    );
    assert_eq!(json.pointer("/config/in_modem"), Some(&Value::Null));
    assert!(
        json["simulated_s"].as_f64().is_some_and(|s| s > 5.0),
        "{json:#}"
    );
    for level in ["high", "normal", "low"] {
        let row = level_row(&out, level);
        for (i, field) in ["submitted", "sent", "shed", "superseded", "received"]
            .into_iter()
            .enumerate()
        {
            let value = uint(&json, &format!("/levels/{level}/{field}"));
            // The table and the file are written from the same figures.
            assert_eq!(value, row[i], "{level} {field}:\n{out}\n{json:#}");
        }
        let aged = uint(&json, &format!("/levels/{level}/aged"));
        assert!(aged <= row[4], "{level}: more aged than received");
        uint(&json, &format!("/levels/{level}/ambiguous"));
        for field in ["age_p50_ms", "age_p99_ms"] {
            let v = &json["levels"][level][field];
            assert!(v.is_null() || v.as_f64().is_some(), "{level} {field}: {v}");
        }
    }
    // Status telemetry is aged, and on an unloaded link within a second.
    let p99 = json["levels"]["normal"]["age_p99_ms"].as_f64().unwrap();
    assert!(
        uint(&json, "/levels/normal/aged") > 50 && p99 > 0.0 && p99 < 1000.0,
        "{json:#}"
    );
    for field in [
        "dropped",
        "queue_full",
        "arena_full",
        "too_large",
        "rate_limited",
        "evicted",
    ] {
        uint(&json, &format!("/downlink/{field}"));
    }
    assert_eq!(uint(&json, "/modem/dropped_bytes"), 0);
    uint(&json, "/modem/frames_dropped");
    for field in ["uart_busy", "air_busy"] {
        let busy = json["modem"][field].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&busy), "{field} {busy}");
    }
    assert_eq!(json["delivery"], Value::Null);
    assert!(uint(&json, "/ping/sent") >= 3 && uint(&json, "/ping/answered") >= 3);
    let rtt = json["ping"]["rtt_p50_ms"].as_f64().unwrap();
    assert!(rtt > 0.0 && rtt <= json["ping"]["rtt_p99_ms"].as_f64().unwrap());
    let messages = json["messages"].as_array().unwrap();
    let attitude = messages
        .iter()
        .find(|m| m["name"] == "ATTITUDE")
        .unwrap_or_else(|| panic!("no ATTITUDE in {json:#}"));
    assert_eq!(attitude["class"], "telemetry");
    assert_eq!(attitude["level"], "normal");
    assert!(uint(attitude, "/received") >= 12);
    assert!(uint(attitude, "/submitted") >= uint(attitude, "/received"));
    assert!(attitude["max_gap_ms"].as_f64().is_some_and(|g| g < 1000.0));
    // The link: the default timeouts, no outage, up from the first PING (at 1 s) on.
    let link = &json["link"];
    assert_eq!(link["lost_timeout_s"].as_f64(), Some(5.0), "{link:#}");
    assert_eq!(link["degraded_timeout_s"].as_f64(), Some(2.0), "{link:#}");
    assert_eq!(link["resume_nav_s"], Value::Null);
    let ac = &link["aircraft"][0];
    assert_eq!(uint(ac, "/ac_id"), 7);
    assert_eq!(ac["outages"].as_array().map(Vec::len), Some(0), "{ac:#}");
    assert_eq!(states(ac), ["up"], "{ac:#}");
    assert_eq!((uint(ac, "/losses"), ac["state"].as_str()), (0, Some("up")));
    assert_eq!(ac["ap_modes"][0]["ap_mode"], "NAV", "{ac:#}");
    assert_eq!(ac["failsafes"].as_array().map(Vec::len), Some(0), "{ac:#}");
    assert_eq!(ac["silences"].as_array().map(Vec::len), Some(0), "{ac:#}");
    assert_eq!(uint(ac, "/events_omitted"), 0, "{ac:#}");
}

/// Issue 13, scenario a: a 57600-baud UART into a modem with a 2048-byte buffer that
/// sends 4000 B/s and drops what overflows (no flow control), flooded. Without pacing the
/// modem drops bytes; with pacing it drops none and every acknowledgement arrives. (The
/// run is paced by the wall clock, so the counts vary: only the difference is checked.)
#[test]
fn pacing_keeps_an_overflowing_modem_from_dropping() {
    let scenario = [
        "--baud",
        "57600",
        "--modem-buffer",
        "2048",
        "--air-rate",
        "4000",
        "--flow-control",
        "none",
        "--overload",
        "--pacing",
    ];
    let with = |pacing: &'static str| {
        let mut args = scenario.to_vec();
        args.push(pacing);
        std::thread::spawn(move || run_sitl_json(pacing, "8", "4", &args))
    };
    let (on, off) = (with("on"), with("off"));
    let (on_out, on) = on.join().unwrap();
    let (off_out, off) = off.join().unwrap();

    assert_eq!(uint(&on, "/modem/dropped_bytes"), 0, "{on_out}");
    let [_, high_sent, high_shed, _, high_received] = level_row(&on_out, "high");
    assert_eq!(high_shed, 0, "{on_out}");
    // Every acknowledgement arrives (one may still be on its way at the end).
    assert!(high_received + 1 >= high_sent && high_sent >= 5, "{on_out}");
    assert!(
        uint(&on, "/ping/answered") + 1 >= uint(&on, "/ping/sent"),
        "{on_out}"
    );
    assert_eq!(level_row(&on_out, "normal")[2], 0, "{on_out}");
    assert!(
        level_row(&on_out, "low")[2] > 0,
        "the flood is shed:\n{on_out}"
    );

    assert!(
        uint(&off, "/modem/dropped_bytes") > 0,
        "without pacing the modem overflows:\n{off_out}"
    );
    let received: u64 = ["high", "normal", "low"]
        .iter()
        .map(|l| uint(&off, &format!("/levels/{l}/received")))
        .sum();
    assert!(
        received < uint(&off, "/downlink/sent"),
        "frames lose bytes in the modem:\n{off_out}"
    );
}

/// Issue 13, scenario b: XBee 802.15.4 API with transmit statuses, flooded. Every frame
/// is reported delivered, none times out, the flood is shed in the queue (its frames
/// fit 802.15.4), acknowledgements arrive, and the uplink (PING, SETTING) goes through
/// XBee frames too.
#[test]
fn xbee_transmit_statuses_over_a_flooded_link() {
    let (out, json) = run_sitl_json(
        "xbee",
        "6",
        "3",
        &[
            "--transport",
            "xbee",
            "--in-modem",
            "2",
            "--flow-control",
            "none",
            "--overload",
        ],
    );
    assert_eq!(json["config"]["transport"], "xbee", "{json:#}");
    assert_eq!(uint(&json, "/config/in_modem"), 2);
    let delivered = uint(&json, "/delivery/delivered");
    assert!(delivered > 100, "{out}");
    assert_eq!(uint(&json, "/delivery/failed"), 0, "{out}");
    assert_eq!(uint(&json, "/delivery/timeouts"), 0, "{out}");
    assert_eq!(uint(&json, "/downlink/too_large"), 0, "{out}");
    assert_eq!(uint(&json, "/modem/frames_dropped"), 0, "{out}");
    let [_, high_sent, high_shed, _, high_received] = level_row(&out, "high");
    assert_eq!(high_shed, 0, "{out}");
    assert!(high_received + 1 >= high_sent, "{out}");
    assert!(level_row(&out, "low")[2] > 0, "the flood is shed:\n{out}");
    services_answered(&out);
}

/// The published test key set.
const TEST_KEYS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../secure/keys/INSECURE-TEST-ONLY.keys"
);

/// `--secure`: the in-process ground completes the handshake with the aircraft, the
/// telemetry arrives decrypted, PINGs and the SETTING go up encrypted and are answered;
/// the telemetry the aircraft produced before the session was refused (counted), never
/// sent in the clear; the summary has the aircraft's secure figures.
#[test]
fn secure_radio_handshake_and_services() {
    let (out, json) = run_sitl_json("secure", "6", "3", &["--secure", TEST_KEYS]);
    services_answered(&out);
    assert!(out.contains("7 telemetry GPS_INT "), "{out}");
    assert!(
        out.contains("secure link (aircraft): session up, handshakes started 1, completed 1"),
        "{out}"
    );
    assert!(
        out.contains("ground station secure link: session up"),
        "{out}"
    );
    assert!(out.contains("rejected 0 (bad tag 0"), "{out}");
    assert_eq!(json["secure"]["session"], Value::Bool(true), "{json:#}");
    assert!(uint(&json, "/secure/decrypted") >= 3, "{json:#}");
    assert_eq!(uint(&json, "/secure/rejected"), 0, "{json:#}");
    assert!(uint(&json, "/secure/encrypted") > 0);
    // Before the session, the aircraft's telemetry was refused at the wire (at least its
    // first ALIVE), and counted.
    assert!(uint(&json, "/downlink/refused") >= 1, "{json:#}");
}

/// Key files that cannot serve: exit code 2 and the reason, before the run.
#[test]
fn secure_key_file_errors_are_reported() {
    let dir = std::env::temp_dir();
    let bad = dir.join(format!("pprz-sitl-{}-bad.keys", std::process::id()));
    std::fs::write(&bad, "UAV_PUBLIC = 12\n").unwrap();
    let aircraft_only = dir.join(format!("pprz-sitl-{}-aircraft.keys", std::process::id()));
    let test_keys = std::fs::read_to_string(TEST_KEYS).unwrap();
    let without_ground: String = test_keys
        .lines()
        .filter(|l| !l.starts_with("GCS_PRIVATE"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&aircraft_only, without_ground).unwrap();
    let missing = dir.join("pprz-sitl-no-such.keys");
    for (path, headless, expected) in [
        (&bad, true, "64 hex digits"),
        (&missing, true, "cannot read"),
        (&aircraft_only, false, "ground keys"),
    ] {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_sitl"));
        cmd.arg("--secure").arg(path).args(["--duration", "1"]);
        if headless {
            cmd.arg("--headless");
        } else {
            // Ports of our own: the key file is checked before any socket is opened.
            cmd.args(["--ground", "127.0.0.1:9", "--uplink", "127.0.0.1:9"]);
        }
        let out = cmd.output().expect("sitl starts");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{path:?}: {stderr}");
        assert!(
            stderr.contains(expected),
            "{path:?}: no `{expected}` in {stderr}"
        );
    }
    let _ = std::fs::remove_file(&bad);
    let _ = std::fs::remove_file(&aircraft_only);
}

/// The in-process ground's services worked (`--lines` output): it PINGs every second and
/// PONGs come back; SETTING gain (index 2) = 2.5 at 3 s is acknowledged with DL_VALUE.
fn services_answered(out: &str) {
    assert!(
        out.lines().filter(|l| *l == "7 telemetry PONG").count() >= 3,
        "{out}"
    );
    assert!(
        out.contains("7 telemetry DL_VALUE index=2 value=2.5"),
        "{out}"
    );
}

/// `--fleet 2 --relay`: aircraft 8 reaches the ground only through aircraft 7, which relays; the
/// ground PINGs both and sets a setting on both; under a 10x overload from both, the
/// relay sheds 8's payload and nothing more important, and the summary reports it per
/// aircraft, per level and per route.
#[test]
fn a_fleet_of_two_relays_through_the_first() {
    let (out, json) = run_sitl_json(
        "fleet",
        "8",
        "4",
        &["--fleet", "2", "--relay", "--overload"],
    );
    // Lines from both aircraft (the first word of a line is its source).
    for ac in ["7", "8"] {
        assert!(
            out.lines()
                .any(|l| l.starts_with(&format!("{ac} telemetry ATTITUDE"))),
            "no ATTITUDE from {ac}:\n{out}"
        );
    }
    let fleet = json.pointer("/fleet").expect("a fleet section");
    assert_eq!(uint(fleet, "/aircraft/0/ac_id"), 7);
    assert_eq!(uint(fleet, "/aircraft/1/ac_id"), 8);
    assert_eq!(uint(fleet, "/aircraft/1/relayed_by"), 7);
    for a in 0..2 {
        // Both answered PINGs, through the relay for 8 (the last one may be in flight).
        let sent = uint(fleet, &format!("/aircraft/{a}/ping/sent"));
        let answered = uint(fleet, &format!("/aircraft/{a}/ping/answered"));
        assert!(sent >= 5 && answered + 1 >= sent, "aircraft {a}: {fleet:#}");
        // Acknowledgements and status: nothing shed anywhere.
        for level in 0..2 {
            for what in ["shed", "shed_by_relay"] {
                let n = uint(fleet, &format!("/aircraft/{a}/levels/{level}/{what}"));
                assert_eq!(n, 0, "aircraft {a} level {level} {what}: {fleet:#}");
            }
        }
        let status = uint(fleet, &format!("/aircraft/{a}/levels/1/received"));
        assert!(status > 50, "aircraft {a}: {fleet:#}");
    }
    // 8's acknowledgements were forwarded (PONGs and the DL_VALUE of the SETTING).
    assert!(uint(fleet, "/aircraft/1/levels/0/forwarded") >= 5);
    // The relay shed 8's payload, and forwarded the ground's requests to 8.
    assert!(
        uint(fleet, "/aircraft/1/levels/2/shed_by_relay") > 0,
        "{fleet:#}"
    );
    assert_eq!(
        fleet.pointer("/routes/0/to").and_then(Value::as_str),
        Some("ground")
    );
    assert!(uint(fleet, "/routes/0/shed/2") > 0);
    assert_eq!(uint(fleet, "/routes/0/shed/0"), 0);
    assert!(
        uint(fleet, "/routes/1/sent") >= 6,
        "PINGs and a SETTING for 8: {fleet:#}"
    );
    assert!(
        out.contains("ground station, aircraft 8: PINGs sent"),
        "{out}"
    );
    assert!(out.contains("relay 7 -> ground: forwarded"), "{out}");
    // Every frame of the fleet follows the rules: the relay refused none.
    assert_eq!(uint(fleet, "/relay/ac_id"), 7);
    assert_eq!(uint(fleet, "/relay/refused"), 0, "{fleet:#}");
    assert!(uint(fleet, "/relay/forwarded") > 0, "{fleet:#}");
    assert!(out.contains("relay 7 refused 0 (own source 0, "), "{out}");
}

/// The states of an aircraft's link health transitions (`link.aircraft[i]`).
fn states(aircraft: &Value) -> Vec<&str> {
    transitions(aircraft).into_iter().map(|(_, s)| s).collect()
}

/// The link health transitions of `link.aircraft[i]`: time and state.
fn transitions(aircraft: &Value) -> Vec<(f64, &str)> {
    aircraft["transitions"]
        .as_array()
        .unwrap_or_else(|| panic!("no transitions in {aircraft:#}"))
        .iter()
        .map(|t| (t["t_s"].as_f64().unwrap(), t["state"].as_str().unwrap()))
        .collect()
}

/// The times of the transitions of `aircraft` to `state`.
fn times_of(aircraft: &Value, state: &str) -> Vec<f64> {
    transitions(aircraft)
        .into_iter()
        .filter(|&(_, s)| s == state)
        .map(|(t, _)| t)
        .collect()
}

/// The `ap_mode` names the ground saw from `aircraft`, in order.
fn ap_modes(aircraft: &Value) -> Vec<&str> {
    aircraft["ap_modes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["ap_mode"].as_str().unwrap())
        .collect()
}

/// The uplink cut from 10 to 20 s, the link Lost after 3 s without the ground: the
/// ground PINGs every second, so the aircraft last heard it at 9 s and a few ms (the
/// PING of 10 s went into the cut), and its health is Degraded 2 s later and Lost 3 s
/// later, once. The failsafe flies home, and the ground sees HOME in the next
/// ROTORCRAFT_STATUS (every 1.2 s). The PING of 20 s makes the link Up again, and the
/// aircraft stays in HOME until the ground sets NAV again at 25 s (`--resume-nav`).
#[test]
fn an_uplink_outage_triggers_the_failsafe_until_the_ground_resumes_nav() {
    let (out, json) = run_sitl_json(
        "outage-up",
        "28",
        "10",
        &[
            "--outage",
            "up:10..20",
            "--lost-timeout",
            "3",
            "--resume-nav",
            "25",
        ],
    );
    let link = &json["link"];
    let ac = &link["aircraft"][0];
    assert_eq!(states(ac), ["up", "degraded", "lost", "up"], "{ac:#}");
    let [lost] = times_of(ac, "lost")[..] else {
        panic!("one loss: {ac:#}");
    };
    assert!((12.0..13.0).contains(&lost), "lost at {lost}: {ac:#}");
    let degraded = times_of(ac, "degraded")[0];
    assert!((lost - degraded - 1.0).abs() < 1e-6, "{ac:#}");
    let back = times_of(ac, "up")[1];
    assert!((20.0..21.0).contains(&back), "up again at {back}: {ac:#}");
    assert_eq!((uint(ac, "/losses"), ac["state"].as_str()), (1, Some("up")));
    assert_eq!(ac["outages"][0]["direction"], "up");
    assert_eq!(ac["outages"][0]["from_s"].as_f64(), Some(10.0));
    assert_eq!(ac["outages"][0]["until_s"].as_f64(), Some(20.0));
    // The ground saw NAV, HOME after the loss (and through the end of the cut), and NAV
    // only after 25 s.
    assert_eq!(ap_modes(ac), ["NAV", "HOME", "NAV"], "{ac:#}");
    let failsafe = &ac["failsafes"][0];
    let home = failsafe["home_s"].as_f64().unwrap();
    let nav = failsafe["nav_s"].as_f64().unwrap();
    assert!(home > lost && home < lost + 1.5, "HOME at {home}: {ac:#}");
    assert!(nav > 25.0 && nav < 27.0, "NAV at {nav}: {ac:#}");
    assert_eq!(link["resume_nav_s"].as_f64(), Some(25.0));
    // Ten PINGs went into the cut, nothing of the downlink.
    assert!(uint(link, "/lost_bytes_up") >= 10 * 8, "{link:#}");
    assert_eq!(uint(link, "/lost_bytes_down"), 0, "{link:#}");
    assert!(
        out.contains("aircraft 7 failsafe, as the ground saw it: HOME at "),
        "{out}"
    );
    assert!(
        out.contains("7 telemetry DL_VALUE index=3 value=13"),
        "{out}"
    );
}

/// The downlink cut from 10 to 20 s: the aircraft still hears the ground's PINGs and
/// stays Up (no failsafe), and the ground hears nothing from it in the window.
#[test]
fn a_downlink_outage_leaves_the_aircraft_up_and_the_ground_deaf() {
    let (out, json) = run_sitl_json("outage-down", "22", "10", &["--outage", "down:10..20"]);
    let link = &json["link"];
    let ac = &link["aircraft"][0];
    assert_eq!(states(ac), ["up"], "{ac:#}");
    assert!((1.0..2.0).contains(&times_of(ac, "up")[0]), "{ac:#}");
    assert_eq!((uint(ac, "/losses"), ac["state"].as_str()), (0, Some("up")));
    assert_eq!(ap_modes(ac), ["NAV"], "{ac:#}");
    let silences = ac["silences"].as_array().unwrap();
    assert_eq!(silences.len(), 1, "{ac:#}");
    let from = silences[0]["from_s"].as_f64().unwrap();
    let until = silences[0]["until_s"].as_f64().unwrap();
    // The last frame heard ended before the cut; the ground, on a busy machine, may
    // read it some milliseconds later.
    assert!((9.0..10.1).contains(&from), "silent from {from}: {ac:#}");
    assert!(
        (20.0..21.0).contains(&until),
        "silent until {until}: {ac:#}"
    );
    assert!(uint(link, "/lost_bytes_down") > 1000, "{link:#}");
    assert_eq!(uint(link, "/lost_bytes_up"), 0, "{link:#}");
    assert!(
        out.contains("aircraft 7: the ground heard nothing from it from "),
        "{out}"
    );
}

/// `--fleet 2 --relay`: the outage cuts aircraft 7's radio to the ground, which is aircraft 8's
/// only way to the ground too (7 relays): both lose the ground's PINGs, go Lost (with
/// a 2 s timeout, straight from Up) and fly home; both are Up again after the cut, and
/// stay in HOME.
#[test]
fn an_uplink_outage_cuts_both_aircraft_of_a_fleet() {
    let (_, json) = run_sitl_json(
        "outage-fleet",
        "10",
        "6",
        &[
            "--fleet",
            "2",
            "--relay",
            "--outage",
            "up:4..8",
            "--lost-timeout",
            "2",
        ],
    );
    let aircraft = json["link"]["aircraft"].as_array().unwrap();
    assert_eq!(aircraft.len(), 2);
    for (ac, id) in aircraft.iter().zip([7, 8]) {
        assert_eq!(uint(ac, "/ac_id"), id);
        assert_eq!(states(ac), ["up", "lost", "up"], "{ac:#}");
        let lost = times_of(ac, "lost")[0];
        assert!((5.0..6.0).contains(&lost), "{id} lost at {lost}: {ac:#}");
        let back = times_of(ac, "up")[1];
        assert!((8.0..9.0).contains(&back), "{id} up at {back}: {ac:#}");
        assert_eq!(ac["outages"][0]["from_s"].as_f64(), Some(4.0), "{ac:#}");
        assert_eq!(ap_modes(ac), ["NAV", "HOME"], "{ac:#}");
        assert_eq!(ac["failsafes"][0]["nav_s"], Value::Null, "{ac:#}");
    }
}

/// `--fleet 0` and `--fleet 33` are refused with a message naming the range.
#[test]
fn a_fleet_is_1_to_32_aircraft() {
    for n in ["0", "33"] {
        let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
            .args(["--headless", "--fleet", n])
            .output()
            .expect("sitl starts");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--fleet {n}: {stderr}");
        assert!(stderr.contains("1 to 32 aircraft"), "--fleet {n}: {stderr}");
    }
}

/// `--fleet 32`: aircraft 7 to 38, each on a radio of its own, all heard by the one
/// ground, which PINGs each (and each answers) and sets each; the summary JSON has the
/// 32 aircraft with their ids, none relayed.
#[test]
fn a_fleet_of_32_each_on_its_own_radio() {
    let (out, json) = run_sitl_json("fleet32", "5", "1", &["--fleet", "32"]);
    let aircraft = json["fleet"]["aircraft"]
        .as_array()
        .expect("a fleet section");
    assert_eq!(aircraft.len(), 32, "{json:#}");
    for (a, id) in aircraft.iter().zip(7u64..) {
        assert_eq!(uint(a, "/ac_id"), id);
        assert_eq!(a["relayed_by"], Value::Null, "{a:#}");
        let sent = uint(a, "/ping/sent");
        let answered = uint(a, "/ping/answered");
        assert!(sent >= 3 && answered + 1 >= sent, "aircraft {id}: {a:#}");
        assert!(uint(a, "/levels/1/received") > 20, "aircraft {id}: {a:#}");
        let lines = |what: &str| out.lines().any(|l| l.starts_with(&format!("{id} {what}")));
        assert!(lines("telemetry ATTITUDE"), "no ATTITUDE from {id}");
        assert!(lines("telemetry PONG"), "no PONG from {id}");
        assert!(
            lines("telemetry DL_VALUE index=2 value=2.5"),
            "no SETTING acknowledged by {id}"
        );
    }
    assert_eq!(json["fleet"]["relay"], Value::Null);
    assert_eq!(json["link"]["aircraft"].as_array().map(Vec::len), Some(32));
    assert!(
        out.contains("ground station, aircraft 38: PINGs sent"),
        "{out}"
    );
}

/// `--fleet 3`: the outage cuts every aircraft's radio to the ground: each falls
/// silent at the ground from the cut to its end, and each goes Lost (with a 1.5 s
/// timeout, straight from Up) and is Up again after it.
#[test]
fn an_outage_cuts_every_radio_of_a_fleet() {
    let (_, json) = run_sitl_json(
        "outage-fleet3",
        "6",
        "2",
        &[
            "--fleet",
            "3",
            "--outage",
            "both:2..4",
            "--lost-timeout",
            "1.5",
        ],
    );
    let aircraft = json["link"]["aircraft"].as_array().unwrap();
    assert_eq!(aircraft.len(), 3);
    for (ac, id) in aircraft.iter().zip([7, 8, 9]) {
        assert_eq!(uint(ac, "/ac_id"), id);
        assert_eq!(states(ac), ["up", "lost", "up"], "{ac:#}");
        let silence = &ac["silences"][0];
        let from = silence["from_s"].as_f64().unwrap();
        let until = silence["until_s"].as_f64().unwrap();
        assert!(
            (1.9..2.2).contains(&from),
            "{id} silent from {from}: {ac:#}"
        );
        assert!(
            (4.0..4.5).contains(&until),
            "{id} silent until {until}: {ac:#}"
        );
    }
    // Each radio lost its share of the downlink in the cut.
    assert!(uint(&json, "/link/lost_bytes_down") > 3 * 1000, "{json:#}");
}

/// The number that follows `label` in `out`.
fn number_after(out: &str, label: &str) -> u64 {
    out.split(label)
        .nth(1)
        .and_then(|rest| rest.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number after {label:?}:\n{out}"))
}

/// A usage error names the command as it is run (`sitl`), not its package, whether
/// clap finds it (an unknown option) or the radio's checks do (options that contradict
/// each other).
#[test]
fn usage_errors_name_the_command() {
    for args in [&["--bogus"][..], &["--pacing-budget", "5"]] {
        let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
            .args(args)
            .output()
            .expect("sitl starts");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains("Usage: sitl [OPTIONS]"),
            "{args:?}: {stderr}"
        );
        assert!(!stderr.contains("pprz-"), "{args:?}: {stderr}");
    }
}

/// `--help` says what the command is before its options.
#[test]
fn help_says_what_the_command_is() {
    let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
        .arg("--help")
        .output()
        .expect("sitl starts");
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{help}");
    assert!(
        help.starts_with("A simulated aircraft and its ground station, over a simulated radio."),
        "{help}"
    );
    assert!(help.contains("\nUsage: sitl [OPTIONS]\n"), "{help}");
}

/// The live table's byte rate is what the radio carried: an overloaded 57600 baud radio
/// carries 5760 B/s, and no view of the table (the first one included, taken before the
/// first bytes arrived over a meaningful time) shows more.
#[test]
fn the_live_tables_byte_rate_is_at_most_the_radios() {
    let (ground, uplink) = free_ports();
    let (ground, uplink) = (format!("127.0.0.1:{ground}"), format!("127.0.0.1:{uplink}"));
    let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
        .args(["--duration", "3", "--speed", "3", "--overload"])
        .args(["--ground", &ground, "--uplink", &uplink])
        .output()
        .expect("the simulation runs");
    let out = String::from_utf8_lossy(&out.stdout).into_owned();
    // `t=    1.5s     5412 B/s  frames ok ...`, once per view.
    let rates: Vec<(f64, f64)> = out
        .split("t=")
        .skip(1)
        .filter_map(|rest| {
            let (t, rest) = rest.split_once("s ")?;
            let (rate, _) = rest.split_once(" B/s")?;
            Some((t.trim().parse().ok()?, rate.trim().parse().ok()?))
        })
        .collect();
    assert!(rates.len() >= 2, "{out}");
    for (t, rate) in rates {
        assert!(
            rate <= 5760.0 * 1.1,
            "t={t} s: {rate} B/s over a 5760 B/s radio:\n{out}"
        );
    }
}

/// A PING flood is more than the radio's uplink carries: the ground's count of PINGs sent
/// (on UDP) and the radio's count of those that went up differ, and the summary says
/// where each of the others went.
#[test]
fn a_ping_flood_accounts_for_every_ping_the_ground_sent() {
    let out = run_sitl(&["--ping-rate", "1000"]);
    let sent = number_after(&out, "ground station, aircraft 7: PINGs sent ");
    let up = number_after(&out, "PINGs up the radio to aircraft 7: sent ");
    assert!(up < sent, "{out}");
    let missing = sent - up;
    let head =
        format!("of the {sent} PINGs the ground sent, {up} went up the radio: {missing} did not");
    let line = out
        .lines()
        .find(|l| l.contains(&head))
        .unwrap_or_else(|| panic!("no line accounts for the PINGs that did not go up:\n{out}"));
    let count = |label: &str| {
        line.split(", ")
            .find(|part| part.contains(label))
            .and_then(|part| {
                part.split(|c: char| !c.is_ascii_digit())
                    .find(|n| !n.is_empty())
                    .and_then(|n| n.parse::<u64>().ok())
            })
            .unwrap_or(0)
    };
    assert_eq!(
        count("dropped at the radio's ground end") + count("still on their way"),
        missing,
        "{line}"
    );
}

/// The value of the first DL_VALUE of setting `index` in `out` (`--lines`).
fn first_dl_value(out: &str, index: u8) -> &str {
    let prefix = format!("7 telemetry DL_VALUE index={index} value=");
    out.lines()
        .find_map(|l| l.strip_prefix(prefix.as_str()))
        // The value, without the setting's name the ground adds after it.
        .map(|rest| rest.split(' ').next().unwrap_or(rest))
        .unwrap_or_else(|| panic!("no DL_VALUE of setting {index}:\n{out}"))
}

/// `--settings-flash`: a first run sets the gain (the ground's 2.5 at 3 s, then 4.5 with
/// `--setting`) and stores it (setting 4, the store flag); a second run on the same file
/// starts with the stored gain: its first DL_VALUE of the gain (periodic, before the
/// ground sets anything) shows 4.5. Without the option, the gain starts at 1.
#[test]
fn settings_flash_keeps_the_stored_gain_from_run_to_run() {
    let path =
        std::env::temp_dir().join(format!("pprz-sitl-{}-settings.flash", std::process::id()));
    let _ = std::fs::remove_file(&path);
    let flash = path.to_str().expect("a UTF-8 temporary path");
    let store = [
        "--settings-flash",
        flash,
        "--setting",
        "3.5:2=4.5",
        "--setting",
        "4:4=1",
    ];
    let first = run_sitl_for("6", "3", &store);
    assert!(std::fs::metadata(&path).is_ok_and(|m| m.len() == 3 * 16 * 1024));
    assert_eq!(
        first_dl_value(&first, 2),
        "1",
        "nothing stored yet:\n{first}"
    );
    assert!(
        first.contains("7 telemetry DL_VALUE index=2 value=4.5"),
        "{first}"
    );
    // The acknowledgement, then the store task's DL_VALUE: both 1.
    let flags = first
        .lines()
        .filter(|l| l.starts_with("7 telemetry DL_VALUE index=4 value=1"))
        .count();
    assert!(
        flags >= 2,
        "{flags} DL_VALUE of the store flag at 1:\n{first}"
    );
    assert!(
        first.contains(&format!(
            "Settings flash {flash}: loaded 0 setting(s) at start (0 load(s) failed); stored 1 time(s), 0 failed, 0 refused"
        )),
        "{first}"
    );

    let second = run_sitl_for("4", "3", &["--settings-flash", flash]);
    assert_eq!(first_dl_value(&second, 2), "4.5", "{second}");
    assert!(
        second.contains("loaded 1 setting(s) at start (0 load(s) failed); stored 0 time(s)"),
        "{second}"
    );
    let _ = std::fs::remove_file(&path);

    let plain = run_sitl_for("4", "3", &[]);
    assert_eq!(first_dl_value(&plain, 2), "1", "{plain}");
    assert!(!plain.contains("Settings flash"), "{plain}");
}
