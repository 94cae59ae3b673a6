//! The simulated aircraft and the ground monitor talking over real loopback UDP sockets:
//! telemetry arrives decoded, PING gets its PONG, SETTING its DL_VALUE acknowledgement,
//! and under a 10x overload only low-priority messages are shed.

use std::net::UdpSocket;
use std::process::Command;

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
    let (ground, uplink) = free_ports();
    let ground = format!("127.0.0.1:{ground}");
    let uplink = format!("127.0.0.1:{uplink}");
    let mut args = vec![
        "--duration",
        "6",
        "--speed",
        "3",
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
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "sitl failed: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
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
    // The ground PINGs every second: PONGs come back.
    assert!(
        out.lines().filter(|l| *l == "7 telemetry PONG").count() >= 3,
        "{out}"
    );
    // SETTING gain (index 2) = 2.5 at 3 s is acknowledged with DL_VALUE.
    assert!(
        out.contains("7 telemetry DL_VALUE index=2 value=2.5"),
        "{out}"
    );
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
        .and_then(|rest| rest.split(')').next())
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
