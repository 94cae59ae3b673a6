//! Spoofed frames on the ground's uplink of a fleet (`--fleet 2 --relay`): aircraft 7 relays
//! between the ground and aircraft 8, and refuses what its rules forbid. Each refusal
//! must show, per reason, in the summary and in `--summary-json`.
//!
//! The test is the ground (`--headless`): it binds the ground's UDP port and sends to
//! the radio bridge's uplink port, on loopback only.

use std::io::ErrorKind;
use std::net::UdpSocket;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use pprz_default::messages::datalink::{Block, Ping};
use pprz_default::messages::telemetry::Pong;
use pprz_messages::Message;
use pprz_transports::{PprzV2, PprzV2Decoder};
use serde_json::Value;

/// The relay (aircraft 7), the aircraft behind it (8), the ground (0).
const RELAY: u8 = 7;
const SECOND: u8 = 8;
const GROUND: u8 = 0;
/// A destination no route leads to (but back to the ground).
const NOWHERE: u8 = 42;

/// Datagrams of the attack; each carries one frame of every kind below.
const DATAGRAMS: usize = 750;
/// Kinds of spoofed frames in each datagram.
const KINDS: usize = 5;
/// Datagrams sent before the test waits for the relay to have read them (a PING's PONG):
/// their bytes stay well inside the radio bridge's 4 KiB UDP input, so none is dropped.
const BATCH: usize = 50;

/// A PPRZ v2 frame: source, destination, class (component 0), message id and fields.
fn frame(source: u8, destination: u8, class: u8, id: u8, fields: &[u8]) -> Vec<u8> {
    let mut f = vec![
        0x99,
        (fields.len() + 8) as u8,
        source,
        destination,
        class,
        id,
    ];
    f.extend_from_slice(fields);
    let (mut a, mut b) = (0u8, 0u8);
    for &byte in &f[1..] {
        a = a.wrapping_add(byte);
        b = b.wrapping_add(a);
    }
    f.extend_from_slice(&[a, b]);
    f
}

/// One datagram of the attack: a BLOCK claiming the relay's own id as its source, one
/// claiming the broadcast id, one for the ground "from aircraft 8" arriving from the
/// ground's side (a forged source: 8 is behind the relay), one for a destination no route
/// leads to, and one for 8 whose fields are cut short.
fn spoofed() -> Vec<u8> {
    let block = |src, dst, fields: &[u8]| frame(src, dst, Block::CLASS_ID, Block::ID, fields);
    [
        block(RELAY, SECOND, &[1, SECOND]),
        block(0xFF, 0xFF, &[1, 0xFF]),
        block(SECOND, GROUND, &[1, GROUND]),
        block(GROUND, NOWHERE, &[1, NOWHERE]),
        block(GROUND, SECOND, &[1]),
    ]
    .concat()
}

/// The process's peak resident set (`VmHWM`), kB.
fn peak_rss_kb(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

/// The ground's socket: telemetry comes in, uplink frames go out to the bridge.
struct Ground {
    socket: UdpSocket,
    uplink: String,
    decoder: PprzV2Decoder,
    pongs: usize,
}

impl Ground {
    /// The next datagram of telemetry, if one comes within the read timeout.
    fn recv(&mut self, buf: &mut [u8]) -> Option<usize> {
        match self.socket.recv(buf) {
            Ok(n) => Some(n),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => None,
            Err(e) => panic!("the ground's socket: {e}"),
        }
    }

    /// Waits for the aircraft's first telemetry: the radio bridge's socket is open (a
    /// hang guard of 600 reads without it).
    fn wait_telemetry(&mut self) {
        let mut buf = [0u8; 2048];
        for _ in 0..600 {
            if self.recv(&mut buf).is_some() {
                return;
            }
        }
        panic!("no telemetry from the simulation");
    }

    /// Waits for the next PONG from the relay (a hang guard of 600 reads without it).
    fn wait_pong(&mut self) {
        let mut buf = [0u8; 2048];
        for _ in 0..600 {
            let Some(n) = self.recv(&mut buf) else {
                continue;
            };
            let mut input = &buf[..n];
            let mut pongs = 0;
            while let Some(f) = self.decoder.feed(&mut input) {
                if f.source() == RELAY && (f.class(), f.msg_id()) == (Pong::CLASS_ID, Pong::ID) {
                    pongs += 1;
                }
            }
            if pongs > 0 {
                self.pongs += pongs;
                return;
            }
        }
        panic!("no PONG from aircraft {RELAY} after {} PONGs", self.pongs);
    }

    /// Sends a PING to the relay and waits for its PONG: what was sent before has been
    /// read by the relay (the uplink is one ordered stream).
    fn barrier(&mut self) {
        let ping = frame(GROUND, RELAY, Ping::CLASS_ID, Ping::ID, &[]);
        self.socket.send_to(&ping, &self.uplink).unwrap();
        self.wait_pong();
    }
}

/// The running simulation, killed if the test fails before it ends.
struct Sitl(Option<Child>);

impl Drop for Sitl {
    fn drop(&mut self) {
        if let Some(child) = &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl Sitl {
    /// Stops the simulation as Ctrl-C does and returns its output (the summary).
    fn interrupt(mut self) -> String {
        let child = self.0.take().expect("running");
        let status = Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(status.success());
        let out = child.wait_with_output().expect("the simulation ends");
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "sitl failed: {}\n{stdout}",
            String::from_utf8_lossy(&out.stderr)
        );
        stdout
    }
}

/// A whole number at `pointer` in `json`.
fn uint(json: &Value, pointer: &str) -> u64 {
    json.pointer(pointer)
        .and_then(Value::as_u64)
        .unwrap_or_else(|| panic!("{pointer} is not a whole number in {json:#}"))
}

/// The number after `label` on the line starting with `line`.
fn number_after(out: &str, line: &str, label: &str) -> u64 {
    out.lines()
        .find(|l| l.trim_start().starts_with(line))
        .and_then(|l| l.split(label).nth(1))
        .and_then(|rest| rest.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number after {label:?} on a line {line:?}:\n{out}"))
}

/// 3750 spoofed frames (750 of each kind) on the ground's uplink of `--fleet 2 --relay`: the
/// relay refuses every one, and the summary and its JSON say how many for each reason.
/// The SITL's peak RSS is printed before and after the attack.
#[test]
fn spoofed_frames_at_the_relay_are_counted_per_reason() {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let ground = socket.local_addr().unwrap().to_string();
    let uplink = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    let json_path: PathBuf =
        std::env::temp_dir().join(format!("pprz-sitl-{}-attack.json", std::process::id()));
    // A long run, ended by Ctrl-C once the relay has read every frame (the duration is
    // only a guard).
    let sitl = Sitl(Some(
        Command::new(env!("CARGO_BIN_EXE_sitl"))
            .args(["--fleet", "2", "--relay", "--headless", "--duration", "600"])
            .args(["--speed", "4", "--ground", &ground, "--uplink", &uplink])
            .arg("--summary-json")
            .arg(&json_path)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the simulation starts"),
    ));
    let pid = sitl.0.as_ref().map_or(0, Child::id);
    let mut g = Ground {
        socket,
        uplink,
        decoder: PprzV2Decoder::new(PprzV2::new()),
        pongs: 0,
    };
    g.wait_telemetry();
    g.barrier();
    let rss_before = peak_rss_kb(pid);
    let datagram = spoofed();
    for batch in 0..DATAGRAMS / BATCH {
        for _ in 0..BATCH {
            g.socket.send_to(&datagram, &g.uplink).unwrap();
        }
        g.barrier();
        assert_eq!(g.pongs, batch + 2);
    }
    let rss_after = peak_rss_kb(pid);
    let out = sitl.interrupt();
    eprintln!(
        "sitl peak RSS (VmHWM): {rss_before} kB before the attack, {rss_after} kB after {} spoofed frames",
        DATAGRAMS * KINDS
    );
    let text = std::fs::read_to_string(&json_path).expect("the summary file was written");
    let _ = std::fs::remove_file(&json_path);
    let json: Value = serde_json::from_str(&text).expect("the summary is JSON");
    let relay = json
        .pointer("/fleet/relay")
        .unwrap_or_else(|| panic!("no relay figures in the summary:\n{json:#}\n{out}"));
    let n = DATAGRAMS as u64;
    assert_eq!(uint(relay, "/ac_id"), u64::from(RELAY));
    for reason in [
        "own_source",
        "broadcast_source",
        "reverse_path",
        "no_route",
        "malformed",
    ] {
        assert_eq!(uint(relay, &format!("/{reason}")), n, "{reason}: {relay:#}");
    }
    assert_eq!(uint(relay, "/refused"), n * KINDS as u64, "{relay:#}");
    // Nothing of the attack went on to aircraft 8 (the ground sent it nothing else).
    assert_eq!(
        json.pointer("/fleet/routes/1/to").and_then(Value::as_str),
        Some("aircraft 8")
    );
    for level in 0..3 {
        assert_eq!(
            uint(&json, &format!("/fleet/routes/1/forwarded/{level}")),
            0
        );
    }
    // The relay went on forwarding 8's telemetry to the ground.
    assert!(uint(relay, "/forwarded") > 0, "{relay:#}");
    assert!(uint(&json, "/fleet/routes/0/forwarded/1") > 0, "{json:#}");
    // The printed summary says the same.
    let line = format!("relay {RELAY} refused ");
    assert_eq!(number_after(&out, &line, &line), n * KINDS as u64, "{out}");
    for label in [
        "own source ",
        "broadcast source ",
        "reverse path ",
        "no route ",
        "malformed ",
    ] {
        assert_eq!(number_after(&out, &line, label), n, "{label}:\n{out}");
    }
    // The attack costs no memory that stays: a bounded growth at most.
    assert!(
        rss_after < rss_before + 8 * 1024,
        "peak RSS grew from {rss_before} kB to {rss_after} kB"
    );
}
