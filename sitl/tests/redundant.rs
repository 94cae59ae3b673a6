//! Redundant radios merged by the gateway in the SITL's ground (`--radios 2`,
//! `--frame-loss`), and the simulated fleet on a Zenoh bus (`--zenoh`).

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::net::{TcpListener, UdpSocket};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use pprz_ground::bus::{Bus, BusConfig};
use serde_json::Value;
use zenoh::Wait;

/// `n` free loopback UDP addresses (bound then released; the SITL binds them at once).
fn free_udp(n: usize) -> Vec<String> {
    let sockets: Vec<UdpSocket> = (0..n)
        .map(|_| UdpSocket::bind("127.0.0.1:0").unwrap())
        .collect();
    sockets
        .iter()
        .map(|s| s.local_addr().unwrap().to_string())
        .collect()
}

/// The SITL's options for the four UDP ports of two radios, on free ports.
fn port_options() -> Vec<String> {
    let ports = free_udp(4);
    let names = ["--ground", "--uplink", "--ground-b", "--uplink-b"];
    names
        .iter()
        .zip(ports)
        .flat_map(|(n, p)| [(*n).to_owned(), p])
        .collect()
}

/// Runs the SITL headless of output (`--lines` to a pipe) with `extra` and a summary
/// file; returns the summary. A run whose port was taken meanwhile is repeated.
fn run_json(name: &str, extra: &[&str]) -> Value {
    let path = std::env::temp_dir().join(format!("pprz-sitl-{}-{name}.json", std::process::id()));
    for attempt in 0..3 {
        let mut args: Vec<String> = port_options();
        args.extend(["--lines", "--summary-json"].map(str::to_owned));
        args.push(path.to_str().unwrap().to_owned());
        args.extend(extra.iter().map(|s| (*s).to_owned()));
        let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
            .args(&args)
            .output()
            .expect("the simulation runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        if !out.status.success() && stderr.to_lowercase().contains("in use") && attempt < 2 {
            continue;
        }
        assert!(out.status.success(), "sitl failed: {stderr}");
        let text = std::fs::read_to_string(&path).expect("the summary was written");
        let _ = std::fs::remove_file(&path);
        return serde_json::from_str(&text).expect("the summary is JSON");
    }
    unreachable!()
}

fn uint(v: &Value, pointer: &str) -> u64 {
    v.pointer(pointer)
        .and_then(Value::as_u64)
        .unwrap_or_else(|| panic!("{pointer} is not a whole number in {v:#}"))
}

/// (aired, delivered) per aircraft, from the summary's gateway section.
fn deliveries(json: &Value) -> Vec<(u64, u64, u64)> {
    json["gateway"]["aircraft"]
        .as_array()
        .expect("a gateway section")
        .iter()
        .map(|a| (uint(a, "/ac_id"), uint(a, "/aired"), uint(a, "/delivered")))
        .collect()
}

/// Two radios per aircraft, each losing 20 % of the frames on its own: the gateway
/// delivers each message once, about 96 % of what the aircraft sent (a message is lost
/// only when both radios lose it). Seeded: the losses are the same from run to run.
#[test]
fn two_lossy_radios_deliver_96_percent_once() {
    // 48 simulated seconds at 8x: about 900 messages per aircraft. PINGs every 5 s
    // (their PONG goes back on one radio), with a timeout above it.
    let json = run_json(
        "radios2",
        &[
            "--fleet",
            "4",
            "--radios",
            "2",
            "--frame-loss",
            "0.2",
            "--duration",
            "48",
            "--speed",
            "8",
            "--ping-rate",
            "0.2",
            "--lost-timeout",
            "60",
            "--seed",
            "7",
        ],
    );
    let g = &json["gateway"];
    assert_eq!(uint(g, "/radios"), 2, "{g:#}");
    let links = g["links"].as_array().expect("links");
    let names: Vec<&str> = links.iter().filter_map(|l| l["link"].as_str()).collect();
    assert_eq!(names, ["radio-a", "radio-b"]);
    let sum = |field: &str| {
        links
            .iter()
            .map(|l| uint(l, &format!("/{field}")))
            .sum::<u64>()
    };
    // Copies were dropped; every message delivered was a first.
    assert!(sum("duplicates") > 100, "{g:#}");
    assert!(sum("alone") > 0 && sum("missed") > 0, "{g:#}");
    let each = deliveries(&json);
    assert_eq!(each.iter().map(|a| a.0).collect::<Vec<_>>(), [7, 8, 9, 10]);
    let delivered: u64 = each.iter().map(|a| a.2).sum();
    let aired: u64 = each.iter().map(|a| a.1).sum();
    assert_eq!(sum("first"), delivered, "{g:#}");
    for a in g["aircraft"].as_array().unwrap() {
        // The fleet monitor decoded each delivered message once: no duplicate reached it.
        assert_eq!(uint(a, "/fleet_frames"), uint(a, "/delivered"), "{a:#}");
        let sent: Vec<u64> = a["sent"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(Value::as_u64)
            .collect();
        assert_eq!(sent.len(), 2, "{a:#}");
        assert!(
            sent[1] + 20 >= sent[0] && sent[0] >= uint(a, "/aired") - 5,
            "{a:#}"
        );
    }
    for &(ac, aired, got) in &each {
        // 96 % expected; three standard deviations below for ~900 messages.
        assert!(got * 100 >= aired * 93, "aircraft {ac}: {got} of {aired}");
        assert!(got <= aired, "aircraft {ac}: {got} of {aired}");
    }
    // The whole fleet: at least 95 % (3600 messages: 96 % +- 0.3 %).
    assert!(
        delivered * 100 >= aired * 95,
        "{delivered} of {aired}\n{g:#}"
    );
    let lost = uint(g, "/lost_frames_down");
    assert!(
        lost * 100 > aired * 2 * 15 && lost * 100 < aired * 2 * 25,
        "{g:#}"
    );
}

/// One radio losing 20 % of its frames: about 80 % delivered, no copies.
#[test]
fn one_lossy_radio_delivers_80_percent() {
    let json = run_json(
        "radios1",
        &[
            "--fleet",
            "2",
            "--frame-loss",
            "0.2",
            "--duration",
            "24",
            "--speed",
            "4",
            "--ping-rate",
            "0.2",
            "--lost-timeout",
            "60",
        ],
    );
    let g = &json["gateway"];
    assert_eq!(g["links"].as_array().map(Vec::len), Some(1), "{g:#}");
    assert_eq!(uint(g, "/links/0/duplicates"), 0, "{g:#}");
    for (ac, aired, got) in deliveries(&json) {
        let share = got as f64 / aired as f64;
        assert!(
            (0.74..0.86).contains(&share),
            "aircraft {ac}: {got} of {aired}"
        );
    }
}

/// Without `--radios 2`, `--frame-loss` or `--zenoh`, the ground is the monitor of one
/// byte stream, as before: no gateway section.
#[test]
fn one_plain_radio_has_no_gateway() {
    let json = run_json("plain", &["--duration", "3", "--speed", "3"]);
    assert_eq!(json["gateway"], Value::Null);
}

/// Options that cannot go with two radios or the bus are refused, naming them.
#[test]
fn redundant_options_are_checked() {
    let cases: [(&[&str], &str); 5] = [
        (&["--radios", "3"], "1 to 2 radios"),
        (&["--frame-loss", "0.95"], "0 to 0.9"),
        (&["--radios", "2", "--fleet", "2", "--relay"], "--relay"),
        (
            &["--radios", "2", "--transport", "xbee"],
            "--transport xbee",
        ),
        (&["--zenoh", "tcp/127.0.0.1:1", "--headless"], "--headless"),
    ];
    for (args, says) in cases {
        let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
            .args(args)
            .output()
            .expect("sitl starts");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
}

/// A free TCP port on loopback.
fn free_tcp() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Kills the SITL when the test ends, passed or not.
struct Running(Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts the SITL serving the bus on `endpoint`; returns once it says the bus is ready.
fn start_on_bus(endpoint: &str, extra: &[&str]) -> Running {
    let mut args = port_options();
    args.extend(["--zenoh", endpoint].map(str::to_owned));
    args.extend(extra.iter().map(|s| (*s).to_owned()));
    let mut child = Command::new(env!("CARGO_BIN_EXE_sitl"))
        .args(&args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("sitl starts");
    let stderr = child.stderr.take().unwrap();
    let running = Running(child);
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let want = format!("zenoh: listening on {endpoint}");
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(line) if line.contains(&want) => break,
            Ok(_) => {}
            Err(e) => panic!("the SITL never said `{want}`: {e}"),
        }
    }
    running
}

/// `--zenoh`: a client on the bus sees the telemetry of every aircraft of the fleet,
/// and a SETTING put on the uplink key of aircraft 8 comes back as its DL_VALUE.
#[test]
fn the_fleet_on_the_bus_takes_a_setting() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_tcp());
    let _sitl = start_on_bus(&endpoint, &["--fleet", "3", "--duration", "20"]);
    let bus = Bus::open(&BusConfig::client(&endpoint)).expect("the client connects");
    let (tx, rx) = mpsc::channel::<(String, Vec<u8>)>();
    let _sub = bus
        .session()
        .declare_subscriber("pprz/*/telemetry/*")
        .callback(move |s| {
            let _ = tx.send((
                s.key_expr().as_str().to_owned(),
                s.payload().to_bytes().into_owned(),
            ));
        })
        .wait()
        .expect("subscribed");
    let mut bus = bus;
    let mut seen = BTreeSet::new();
    let mut acknowledged = false;
    let mut put_at: Option<Instant> = None;
    let deadline = Instant::now() + Duration::from_secs(15);
    while Instant::now() < deadline && !acknowledged {
        let Ok((key, payload)) = rx.recv_timeout(Duration::from_millis(200)) else {
            continue;
        };
        let parts: Vec<&str> = key.split('/').collect();
        seen.insert(parts[1].to_owned());
        // After the SITL's own SETTING of 3 s (gain 2.5): from then on 1.5 is ours.
        if put_at.is_none() && seen.len() == 3 && key == "pprz/8/telemetry/DL_VALUE" {
            let v: Value = serde_json::from_slice(&payload).expect("JSON");
            if v["index"] == 2 && v["value"] == 2.5 {
                bus.put(
                    "pprz/8/uplink/SETTING",
                    r#"{"index": 2, "value": 1.5}"#,
                    None,
                );
                put_at = Some(Instant::now());
            }
        }
        if put_at.is_some() && key == "pprz/8/telemetry/DL_VALUE" {
            let v: Value = serde_json::from_slice(&payload).expect("JSON");
            acknowledged = v["index"] == 2 && v["value"] == 1.5;
        }
    }
    assert_eq!(seen, BTreeSet::from(["7", "8", "9"].map(str::to_owned)));
    assert!(put_at.is_some(), "the SITL's own SETTING never came back");
    assert!(acknowledged, "no DL_VALUE of 1.5 from aircraft 8");
}
