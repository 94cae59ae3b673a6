//! `pprz-gateway` checked by independent clients: the official Zenoh Python API
//! (PyPI `eclipse-zenoh`, `ground/tests/zenoh/client.py`) in client (or peer) mode,
//! connected to the gateway's loopback endpoint only, multicast scouting off.
//!
//! The test plays the aircraft: PPRZ v2 frames on UDP links whose uplink addresses it
//! owns, answering every SETTING with a DL_VALUE where asked. Messages are the real
//! Paparazzi `messages.xml` (PPRZLINK reference data).
//!
//! * 32 aircraft's GPS_INT reach a subscriber with the values `pprz-monitor` decodes
//!   from the same frames.
//! * A SETTING put on the bus reaches the aircraft on the link that heard it first; its
//!   DL_VALUE comes back on the bus; settings queries are answered after the DL_VALUE.
//! * Two lossy links carrying the same stream: every frame either link brought is
//!   delivered once, and the per-link counters equal the loss pattern.
//! * A second session (a peer) sees the same fleet as the first (a client).
//! * Hostile commands are refused and counted by reason; an uplink flood is rate
//!   limited while the downlink keeps flowing.
//! * Nonsense command lines exit with status 2 and a message.
//!
//! Skipped (reason printed) without the reference data or the Python venv with
//! `eclipse-zenoh` (`ground/tests/foxglove/setup.sh`); failures when
//! `PPRZ_REQUIRE_REFERENCE` is set.

mod common;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use common::{monitor, run};
use pprz_ground::set::RuntimeSet;
use pprz_test_support::reference::{locate_for_test, skip_test};
use pprz_test_support::rng::Rng;
use pprz_test_support::viewer_tools;
use pprz_transports::{Decoder, Encoder, MsgHeader, PprzV2, TxMeta};
use serde_json::Value;

/// The Python client.
fn client_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/zenoh/client.py")
}

/// What the tests need: the reference `messages.xml` and a Python with `zenoh`.
struct Tools {
    python: PathBuf,
    messages: PathBuf,
    ids: Ids,
    /// Messages in the set (each has a schema on the bus).
    message_count: usize,
}

/// Message ids of the reference set.
#[derive(Clone, Copy)]
struct Ids {
    gps_int: u8,
    dl_value: u8,
    setting: u8,
}

fn tools(who: &str) -> Option<Tools> {
    let dir = locate_for_test(who)?;
    let python = viewer_tools::venv().join("bin/python");
    let ok = Command::new(&python)
        .args(["-c", "import zenoh"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        let reason = format!(
            "no Python with eclipse-zenoh at {} (install it with `bash ground/tests/foxglove/setup.sh`, or set {})",
            python.display(),
            viewer_tools::VENV_VAR
        );
        skip_test(who, &reason);
        return None;
    }
    let messages = dir.join("messages.xml");
    let set = RuntimeSet::load(&messages).unwrap();
    let id = |class: &str, name: &str| set.find_by_name(class, name).unwrap().id;
    let ids = Ids {
        gps_int: id("telemetry", "GPS_INT"),
        dl_value: id("telemetry", "DL_VALUE"),
        setting: id("datalink", "SETTING"),
    };
    Some(Tools {
        python,
        messages,
        ids,
        message_count: set.set().messages().len(),
    })
}

/// A loopback UDP port free a moment ago.
fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A loopback TCP port free a moment ago.
fn free_tcp_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A PPRZ v2 frame from `source` to the ground.
fn frame(source: u8, class: u8, id: u8, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(source, 0, class, id));
    let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// GPS_INT's payload (13 four-byte fields, pdop, numsv, fix, comp_id): random values,
/// `tow` (bytes 48..52) set to `tow`.
fn gps_int(rng: &mut Rng, tow: u32) -> Vec<u8> {
    let mut p = vec![0u8; 57];
    rng.fill_bytes(&mut p);
    p[48..52].copy_from_slice(&tow.to_le_bytes());
    p
}

/// One aircraft-side end of a gateway link: the socket the aircraft sends from, whose
/// address is the link's uplink address, and the gateway's port.
struct Link {
    name: &'static str,
    socket: UdpSocket,
    gateway: SocketAddr,
}

impl Link {
    fn new(name: &'static str) -> Self {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        let gateway = SocketAddr::from(([127, 0, 0, 1], free_udp_port()));
        Self {
            name,
            socket,
            gateway,
        }
    }

    /// The `--link` option.
    fn spec(&self) -> String {
        format!(
            "{}=udp:{},uplink={}",
            self.name,
            self.gateway,
            self.socket.local_addr().unwrap()
        )
    }

    fn send(&self, bytes: &[u8]) {
        self.socket.send_to(bytes, self.gateway).unwrap();
    }

    /// Collects the frames the gateway sends on this link; answers each SETTING with
    /// the DL_VALUE of the value set when `answer`.
    fn listen(&self, ids: Ids, answer: bool) -> UplinkLog {
        let socket = self.socket.try_clone().unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let gateway = self.gateway;
        let stop = Arc::new(AtomicBool::new(false));
        let frames = Arc::new(Mutex::new(Vec::new()));
        let (flag, log) = (stop.clone(), frames.clone());
        let thread = std::thread::spawn(move || {
            let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
            let mut buf = [0u8; 2048];
            while !flag.load(Ordering::SeqCst) {
                let Ok(n) = socket.recv(&mut buf) else {
                    continue;
                };
                let mut input = &buf[..n];
                while let Some(f) = decoder.feed(&mut input) {
                    let p = f.payload().to_vec();
                    let setting = f.class() == 2 && f.msg_id() == ids.setting && p.len() == 6;
                    if answer && setting {
                        let mut reply = vec![p[0]];
                        reply.extend_from_slice(&p[2..6]);
                        let _ = socket.send_to(&frame(p[1], 1, ids.dl_value, &reply), gateway);
                    }
                    log.lock().unwrap().push((f.class(), f.msg_id(), p));
                }
            }
        });
        UplinkLog {
            stop,
            frames,
            thread: Some(thread),
        }
    }
}

/// A frame a link's uplink received: (class, id, payload).
type UplinkFrame = (u8, u8, Vec<u8>);

/// The frames a link's uplink received.
struct UplinkLog {
    stop: Arc<AtomicBool>,
    frames: Arc<Mutex<Vec<UplinkFrame>>>,
    thread: Option<JoinHandle<()>>,
}

impl UplinkLog {
    fn frames(&self) -> Vec<UplinkFrame> {
        self.frames.lock().unwrap().clone()
    }
}

impl Drop for UplinkLog {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A running `pprz-gateway`, killed when dropped.
struct Gateway {
    child: Child,
    endpoint: String,
    stderr: Option<JoinHandle<String>>,
}

impl Gateway {
    fn start(messages: &Path, links: &[&Link], extra: &[&str]) -> Self {
        let endpoint = format!("tcp/127.0.0.1:{}", free_tcp_port());
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_pprz-gateway"));
        cmd.arg("--messages").arg(messages);
        for l in links {
            cmd.args(["--link", &l.spec()]);
        }
        cmd.args(["--zenoh-listen", &endpoint])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().expect("pprz-gateway starts");
        let stderr = child.stderr.take().unwrap();
        let (tx, rx) = channel();
        let reader = std::thread::spawn(move || {
            let mut all = String::new();
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if line.starts_with("zenoh: listening on") {
                    let _ = tx.send(());
                }
                all.push_str(&line);
                all.push('\n');
            }
            all
        });
        if rx.recv_timeout(Duration::from_secs(30)).is_err() {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "pprz-gateway did not listen: {}",
                reader.join().unwrap_or_default()
            );
        }
        Self {
            child,
            endpoint,
            stderr: Some(reader),
        }
    }

    /// Whether it still runs.
    fn running(&mut self) -> bool {
        self.child.try_wait().unwrap().is_none()
    }

    /// Stops it (Ctrl-C) and returns its standard error.
    fn stop(mut self) -> String {
        let pid = self.child.id().to_string();
        let _ = Command::new("kill").args(["-INT", &pid]).status();
        let deadline = Instant::now() + Duration::from_secs(10);
        while self.running() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        self.stderr
            .take()
            .map(|t| t.join().unwrap_or_default())
            .unwrap_or_default()
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A running Python client: its output lines, as JSON.
struct Client {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: Receiver<Value>,
    seen: Vec<Value>,
}

impl Client {
    fn start(tools: &Tools, endpoint: &str, args: &[&str]) -> Self {
        let mut child = Command::new(&tools.python)
            .arg(client_script())
            .arg(endpoint)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("python runs");
        let stdout = child.stdout.take().unwrap();
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let v = serde_json::from_str(&line).unwrap_or(Value::String(line));
                if tx.send(v).is_err() {
                    return;
                }
            }
        });
        Self {
            stdin: child.stdin.take(),
            child,
            lines: rx,
            seen: Vec::new(),
        }
    }

    /// Reads lines until one satisfies `pred` (that line), or `seconds` pass.
    fn wait_for(&mut self, seconds: u64, pred: impl Fn(&Value) -> bool) -> Option<Value> {
        let deadline = Instant::now() + Duration::from_secs(seconds);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(v) => {
                    self.seen.push(v.clone());
                    if pred(&v) {
                        return Some(v);
                    }
                }
                Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    /// Reads lines until `n` samples with keys containing `key_part` were seen, or
    /// `seconds` pass; the number seen.
    fn wait_samples(&mut self, seconds: u64, key_part: &str, n: usize) -> usize {
        let count = std::cell::Cell::new(samples(&self.seen, key_part).len());
        if count.get() < n {
            self.wait_for(seconds, |v| {
                if v["event"] == "sample" && v["key"].as_str().is_some_and(|k| k.contains(key_part))
                {
                    count.set(count.get() + 1);
                }
                count.get() >= n
            });
        }
        count.get()
    }

    /// Waits for the client's `ready` (the gateway knows its subscriptions).
    fn ready(&mut self) {
        let ready = self.wait_for(30, |v| v["event"] == "ready");
        assert!(ready.is_some(), "the client is not ready: {:?}", self.seen);
    }

    /// Closes its standard input and returns every line it printed.
    fn finish(mut self) -> Vec<Value> {
        drop(self.stdin.take());
        self.wait_for(30, |v| v["event"] == "end");
        let _ = self.child.wait();
        std::mem::take(&mut self.seen)
    }
}

impl Drop for Client {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The samples among a client's lines: (key, payload as JSON, attachment hex).
fn samples(lines: &[Value], key_part: &str) -> Vec<(String, Value, String)> {
    lines
        .iter()
        .filter(|v| v["event"] == "sample")
        .filter(|v| v["key"].as_str().is_some_and(|k| k.contains(key_part)))
        .map(|v| {
            let payload = serde_json::from_str(v["payload"].as_str().unwrap_or_default())
                .unwrap_or(Value::Null);
            let key = v["key"].as_str().unwrap_or_default().to_owned();
            (
                key,
                payload,
                v["attachment"].as_str().unwrap_or("").to_owned(),
            )
        })
        .collect()
}

/// The aircraft id of a key `pprz/<ac>/...`.
fn key_ac(key: &str) -> u8 {
    key.split('/').nth(1).unwrap().parse().unwrap()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Sends `frames` on `link`, one every `gap`.
fn send_paced(link: &Link, frames: &[Vec<u8>], gap: Duration) {
    for f in frames {
        link.send(f);
        std::thread::sleep(gap);
    }
}

/// The `name=value` fields of a monitor line.
fn line_fields(line: &str) -> HashMap<String, String> {
    line.split_whitespace()
        .filter_map(|w| w.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect()
}

#[test]
fn thirty_two_aircraft_positions_reach_a_subscriber_with_the_monitors_values() {
    let who = "pprz-ground gateway_thirty_two_aircraft";
    let Some(tools) = tools(who) else { return };
    let link = Link::new("radio");
    let gw = Gateway::start(&tools.messages, &[&link], &[]);
    let mut client = Client::start(
        &tools,
        &gw.endpoint,
        &["subscribe", "--schemas", "pprz/*/telemetry/GPS_INT"],
    );
    client.ready();

    // Three positions of each of 32 aircraft, interleaved as one radio would carry them.
    let mut rng = Rng::new(0x6A7E_0032);
    let mut frames = Vec::new();
    for round in 0..3u32 {
        for ac in 1..=32u8 {
            let payload = gps_int(&mut rng, round * 1000 + u32::from(ac));
            frames.push(frame(ac, 1, tools.ids.gps_int, &payload));
        }
    }
    send_paced(&link, &frames, Duration::from_micros(500));
    client.wait_samples(20, "/GPS_INT", frames.len());
    let lines = client.finish();
    let got = samples(&lines, "/GPS_INT");

    // The same frames, decoded by pprz-monitor from a file.
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("fleet.bin");
    std::fs::write(&file, frames.concat()).unwrap();
    let (code, out, err) = run(monitor()
        .args(["--lines", "--messages"])
        .arg(&tools.messages)
        .arg("--file")
        .arg(&file));
    assert_eq!(code, Some(0), "{err}");
    let expected: Vec<&str> = out.lines().collect();
    assert_eq!(expected.len(), 96, "{out}");

    assert_eq!(got.len(), 96, "{lines:?}");
    let aircraft: BTreeSet<u8> = got.iter().map(|(k, _, _)| key_ac(k)).collect();
    assert_eq!(aircraft, (1..=32).collect());
    // Each sample, matched by its frame, has the monitor's values.
    let by_frame: HashMap<String, &str> = frames
        .iter()
        .map(|f| hex(f))
        .zip(expected.iter().copied())
        .collect();
    for (key, fields, attachment) in &got {
        let line = by_frame
            .get(attachment)
            .unwrap_or_else(|| panic!("{key}: a frame not sent: {attachment}"));
        assert!(line.starts_with(&format!("{} telemetry GPS_INT ", key_ac(key))));
        let want = line_fields(line);
        for f in ["ecef_x", "lat", "lon", "alt", "tow", "pdop", "numsv"] {
            assert_eq!(fields[f].to_string(), want[f], "{key} {f}: {line}");
        }
    }
    // The gateway serves a JSON Schema for every message of the set, and each sample
    // is valid against its message's (checked by the Python jsonschema package).
    let served = lines.iter().find(|v| v["event"] == "schemas").unwrap();
    assert_eq!(
        served["count"].as_u64(),
        Some(tools.message_count as u64),
        "{served}"
    );
    let checked: Vec<&Value> = lines
        .iter()
        .filter(|v| {
            v["event"] == "sample" && v["key"].as_str().is_some_and(|k| k.ends_with("/GPS_INT"))
        })
        .collect();
    assert!(
        checked.iter().all(|v| v["schema"] == "valid"),
        "{checked:?}"
    );
    let _ = gw.stop();
}

/// Sends GPS_INT of aircraft `ac` every `gap` until stopped, on `first` and then (the
/// same frame, 2 ms later) on `second`: `first` always brings it first. The number sent.
fn heartbeat(
    links: Vec<Link>,
    ac: u8,
    gps_int_id: u8,
    gap: Duration,
    stop: Arc<AtomicBool>,
) -> JoinHandle<u32> {
    std::thread::spawn(move || {
        let mut rng = Rng::new(u64::from(ac));
        let mut n = 0u32;
        while !stop.load(Ordering::SeqCst) {
            let f = frame(ac, 1, gps_int_id, &gps_int(&mut rng, n));
            for (i, l) in links.iter().enumerate() {
                if i > 0 {
                    std::thread::sleep(Duration::from_millis(2));
                }
                l.send(&f);
            }
            n += 1;
            std::thread::sleep(gap);
        }
        n
    })
}

/// A copy of a link's aircraft side (same socket, same gateway port).
fn link_copy(l: &Link) -> Link {
    Link {
        name: l.name,
        socket: l.socket.try_clone().unwrap(),
        gateway: l.gateway,
    }
}

#[test]
fn a_setting_put_on_the_bus_reaches_the_aircraft_on_its_first_link_and_its_value_comes_back() {
    let who = "pprz-ground gateway_setting_round_trip";
    let Some(tools) = tools(who) else { return };
    let (a, b) = (Link::new("radio-a"), Link::new("radio-b"));
    let gw = Gateway::start(&tools.messages, &[&a, &b], &[]);
    let (log_a, log_b) = (a.listen(tools.ids, true), b.listen(tools.ids, true));
    // Aircraft 7 is heard on both links, on radio-b first.
    let stop = Arc::new(AtomicBool::new(false));
    let beat = heartbeat(
        vec![link_copy(&b), link_copy(&a)],
        7,
        tools.ids.gps_int,
        Duration::from_millis(50),
        stop.clone(),
    );
    std::thread::sleep(Duration::from_millis(200));

    let mut client = Client::start(&tools, &gw.endpoint, &["setting", "7", "2", "1.5", "2.5"]);
    let end = client.wait_for(40, |v| v["event"] == "end");
    stop.store(true, Ordering::SeqCst);
    beat.join().unwrap();
    assert!(end.is_some(), "{:?}", client.seen);
    let lines = client.finish();
    let event = |name: &str, value: Option<f64>| {
        lines
            .iter()
            .find(|v| v["event"] == name && value.is_none_or(|x| v["value"] == x))
            .unwrap_or_else(|| panic!("no {name} in {lines:?}"))
            .clone()
    };
    // The DL_VALUE the aircraft sent in answer to the command, on the bus.
    let dl = event("dl_value", None);
    assert_eq!(dl["seen"], true, "{dl}");
    // Queries: set 1.5 (in force), set 2.5 (answered on its DL_VALUE), read.
    for (e, value) in [
        (event("query", Some(1.5)), 1.5),
        (event("query", Some(2.5)), 2.5),
        (event("read", None), 2.5),
    ] {
        let replies = e["replies"].as_array().unwrap();
        assert_eq!(replies.len(), 1, "{e}");
        let ok = &replies[0]["ok"];
        assert_eq!(ok["ac_id"], 7, "{e}");
        assert_eq!(ok["index"], 2, "{e}");
        assert_eq!(ok["value"], value, "{e}");
    }

    // Every SETTING went on radio-b, none on radio-a: (index, ac_id, value).
    let settings = |log: &UplinkLog| -> Vec<(u8, u8, f32)> {
        log.frames()
            .iter()
            .filter(|(c, id, p)| *c == 2 && *id == tools.ids.setting && p.len() == 6)
            .map(|(_, _, p)| (p[0], p[1], f32::from_le_bytes([p[2], p[3], p[4], p[5]])))
            .collect()
    };
    assert_eq!(
        settings(&log_b),
        [(2, 7, 1.5), (2, 7, 1.5), (2, 7, 2.5)],
        "{:?}",
        log_b.frames()
    );
    assert!(log_a.frames().is_empty(), "{:?}", log_a.frames());
    let err = gw.stop();
    assert!(err.contains("\"commands\":3"), "{err}");
    assert!(err.contains("\"settings_answered\":3"), "{err}");
}

/// The counters of the latest gateway stats sample that satisfies `pred`.
fn stats_where(client: &mut Client, seconds: u64, pred: impl Fn(&Value) -> bool) -> Value {
    let is_stats = |v: &Value| {
        v["event"] == "sample" && v["key"].as_str().is_some_and(|k| k.ends_with("/stats"))
    };
    let found = client.wait_for(seconds, |v| {
        is_stats(v) && serde_json::from_str(v["payload"].as_str().unwrap()).is_ok_and(|s| pred(&s))
    });
    let last = client.seen.iter().rev().find(|v| is_stats(v)).cloned();
    let v = found.unwrap_or_else(|| panic!("no such counters; the last: {last:?}"));
    serde_json::from_str(v["payload"].as_str().unwrap()).unwrap()
}

#[test]
fn two_lossy_links_deliver_every_frame_once_and_count_what_each_lost() {
    let who = "pprz-ground gateway_redundant_links";
    let Some(tools) = tools(who) else { return };
    const N: u32 = 2000;
    let (a, b) = (Link::new("radio-a"), Link::new("radio-b"));
    let gw = Gateway::start(&tools.messages, &[&a, &b], &[]);
    let mut client = Client::start(
        &tools,
        &gw.endpoint,
        &["subscribe", "pprz/7/telemetry/GPS_INT"],
    );
    client.ready();

    // Each frame is lost on each link with probability 1/5, independently; radio-b
    // carries it 3 ms after radio-a.
    let mut rng = Rng::new(0x0DED_0BAD);
    let frames: Vec<Vec<u8>> = (0..N)
        .map(|i| frame(7, 1, tools.ids.gps_int, &gps_int(&mut rng, i)))
        .collect();
    let lost: Vec<(bool, bool)> = (0..N)
        .map(|_| (rng.below(5) == 0, rng.below(5) == 0))
        .collect();
    let delay = Duration::from_millis(3);
    let gap = Duration::from_millis(1);
    let start = Instant::now();
    let mut events: Vec<(Duration, &Link, usize)> = Vec::new();
    for (i, &(lost_a, lost_b)) in lost.iter().enumerate() {
        let at = gap * i as u32;
        if !lost_a {
            events.push((at, &a, i));
        }
        if !lost_b {
            events.push((at + delay, &b, i));
        }
    }
    events.sort_by_key(|e| e.0);
    for (at, link, i) in events {
        if let Some(wait) = at.checked_sub(start.elapsed()) {
            std::thread::sleep(wait);
        }
        link.send(&frames[i]);
    }

    let only_a = lost.iter().filter(|l| **l == (false, true)).count() as u64;
    let only_b = lost.iter().filter(|l| **l == (true, false)).count() as u64;
    let both = lost.iter().filter(|l| **l == (false, false)).count() as u64;
    let union = only_a + only_b + both;
    // Once every merging window closed: the exact counters.
    let stats = stats_where(&mut client, 20, |s| {
        s["delivered"] == union && s["remembered"] == 0
    });
    let lines = client.finish();
    let links = stats["links"].as_array().unwrap();
    let (la, lb) = (&links[0], &links[1]);
    assert_eq!(
        (&la["link"], &lb["link"]),
        (&"radio-a".into(), &"radio-b".into())
    );
    assert_eq!(la["alone"], only_a, "{stats}");
    assert_eq!(lb["alone"], only_b, "{stats}");
    assert_eq!(la["missed"], only_b, "{stats}");
    assert_eq!(lb["missed"], only_a, "{stats}");
    let n = |v: &Value| v.as_u64().unwrap();
    assert_eq!(n(&la["duplicates"]) + n(&lb["duplicates"]), both, "{stats}");
    assert_eq!(n(&la["first"]) + n(&lb["first"]), union, "{stats}");
    assert_eq!(stats["evicted"], 0, "{stats}");

    // The subscriber: each content at most once, at least 95 % of them (theory 96 %).
    let mut tows = BTreeMap::<u64, usize>::new();
    for (_, fields, _) in samples(&lines, "/GPS_INT") {
        *tows.entry(fields["tow"].as_u64().unwrap()).or_default() += 1;
    }
    let repeated: Vec<_> = tows.iter().filter(|(_, c)| **c > 1).collect();
    assert!(repeated.is_empty(), "delivered twice: {repeated:?}");
    assert!(
        tows.len() as u64 >= u64::from(N) * 95 / 100,
        "{} of {N} (links carried {union})",
        tows.len()
    );
    assert!(tows.keys().all(|&t| {
        let (la, lb) = lost[t as usize];
        !(la && lb)
    }));
    eprintln!(
        "redundant links: {N} frames, radio-a alone {only_a}, radio-b alone {only_b}, both {both}; the client received {}",
        tows.len()
    );
    let _ = gw.stop();
}

#[test]
fn a_second_session_sees_the_same_fleet() {
    let who = "pprz-ground gateway_two_sessions";
    let Some(tools) = tools(who) else { return };
    let link = Link::new("radio");
    let gw = Gateway::start(&tools.messages, &[&link], &[]);
    let keys = ["subscribe", "pprz/*/telemetry/*"];
    let mut first = Client::start(&tools, &gw.endpoint, &keys);
    let peer: Vec<&str> = ["--peer"].into_iter().chain(keys).collect();
    let mut second = Client::start(&tools, &gw.endpoint, &peer);
    first.ready();
    second.ready();
    let mut rng = Rng::new(0x005E_C04D);
    let mut frames = Vec::new();
    for round in 0..2 {
        for ac in 40..48u8 {
            frames.push(frame(ac, 1, tools.ids.gps_int, &gps_int(&mut rng, round)));
            let value = [round as u8, 0, 0, 0x80, 0x3F];
            frames.push(frame(ac, 1, tools.ids.dl_value, &value));
        }
    }
    send_paced(&link, &frames, Duration::from_micros(500));
    let n = frames.len();
    assert_eq!(first.wait_samples(20, "/telemetry/", n), n);
    assert_eq!(second.wait_samples(20, "/telemetry/", n), n);
    let fleet = |c: Client| {
        let lines = c.finish();
        let mut s = samples(&lines, "/telemetry/");
        s.sort_by(|x, y| (&x.0, &x.2).cmp(&(&y.0, &y.2)));
        s
    };
    let (one, two) = (fleet(first), fleet(second));
    assert_eq!(one, two);
    let aircraft: BTreeSet<u8> = one.iter().map(|(k, _, _)| key_ac(k)).collect();
    assert_eq!(aircraft, (40..48).collect());
    let _ = gw.stop();
}

#[test]
fn hostile_commands_are_refused_by_reason_and_a_flood_is_rate_limited_while_telemetry_flows() {
    let who = "pprz-ground gateway_hostile_commands";
    let Some(tools) = tools(who) else { return };
    const FLOOD: u64 = 5000;
    const RATE: f64 = 20.0;
    let link = Link::new("radio");
    let started = Instant::now();
    let mut gw = Gateway::start(&tools.messages, &[&link], &["--uplink-rate", "20"]);
    let uplink = link.listen(tools.ids, false);
    let mut downlink = Client::start(
        &tools,
        &gw.endpoint,
        &["subscribe", "pprz/7/telemetry/GPS_INT"],
    );
    downlink.ready();
    // Aircraft 7's telemetry, 500 a second, all the while.
    let stop = Arc::new(AtomicBool::new(false));
    let beat = heartbeat(
        vec![link_copy(&link)],
        7,
        tools.ids.gps_int,
        Duration::from_millis(2),
        stop.clone(),
    );

    let mut hostile = Client::start(&tools, &gw.endpoint, &["hostile", "7", "5000"]);
    let end = hostile.wait_for(60, |v| v["event"] == "end");
    stop.store(true, Ordering::SeqCst);
    let sent = beat.join().unwrap();
    assert!(end.is_some(), "{:?}", hostile.seen);
    let lines = hostile.finish();
    // Each hostile command: refused, with its reason, on pprz/gateway/gw/refused.
    let mut reasons = BTreeMap::<String, u64>::new();
    for e in lines.iter().filter(|v| v["event"] == "refused") {
        assert_eq!(e["answer"]["reason"], e["want"], "{e}");
        assert_eq!(e["answer"]["key"], e["key"], "{e}");
        *reasons
            .entry(e["want"].as_str().unwrap().to_owned())
            .or_default() += 1;
    }
    assert_eq!(reasons.values().sum::<u64>(), 10, "{lines:?}");
    let flood = lines.iter().find(|v| v["event"] == "flood").unwrap();
    eprintln!("hostile: {flood}");
    assert_eq!(flood["answered"], true, "{flood}");
    // Read queries that found the request queue full (dropped and counted as flooded).
    let dropped_reads = flood["read_tries"].as_u64().unwrap() - 1;

    // The downlink kept flowing: at least 99 % of the telemetry sent during the flood.
    let received = downlink.wait_samples(20, "/GPS_INT", sent as usize);
    assert!(
        received as f64 >= f64::from(sent) * 0.99,
        "{received} of {sent} telemetry messages"
    );
    // The counters: every hostile command by its reason; every flood command taken,
    // refused for the rate, or dropped as a flood of the request queue.
    let stats = stats_where(&mut downlink, 20, |s| {
        let n = |v: &Value| v.as_u64().unwrap_or(0);
        n(&s["settings_answered"]) == 1
            && n(&s["refused"]["rate"]) + n(&s["flooded"]) + n(&s["commands"])
                == FLOOD + dropped_reads
    });
    for (reason, count) in &reasons {
        assert_eq!(stats["refused"][reason], *count, "{reason}: {stats}");
    }
    // The rate limit held: at most a burst plus the rate over the gateway's life.
    let elapsed = started.elapsed().as_secs_f64();
    let settings = uplink
        .frames()
        .iter()
        .filter(|(c, id, _)| *c == 2 && *id == tools.ids.setting)
        .count();
    assert_eq!(stats["commands"], settings as u64, "{stats}");
    assert!(settings >= 1);
    assert!(
        settings as f64 <= RATE * elapsed + RATE,
        "{settings} SETTINGs in {elapsed:.1} s"
    );
    eprintln!("hostile: {settings} SETTINGs sent in {elapsed:.1} s; {stats}");
    assert!(gw.running(), "the gateway ended");
    drop(downlink);
    let err = gw.stop();
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn nonsense_command_lines_exit_with_status_2_and_a_message() {
    let gateway = || {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_pprz-gateway"));
        cmd.stdin(Stdio::null());
        cmd
    };
    let link = "a=udp:127.0.0.1:9,uplink=127.0.0.1:10";
    let cases: [(&[&str], &str); 9] = [
        (&["--dedup-window", "0"], "window 0 is out of range"),
        (&["--dedup-window", "nan"], "out of range"),
        (&["--uplink-rate", "-1"], "rate -1 is out of range"),
        (&["--link", "bad"], "NAME=KIND:TARGET"),
        (&["--link", link, "--link", link], "two links are named a"),
        (&["--link", link, "--udp", "127.0.0.1:11"], "not both"),
        (&["--name", "a/b"], "gateway name"),
        // Checked and printed escaped, never echoed raw.
        (
            &["--zenoh-listen", "tcp/\u{1b}[2J:1"],
            "not a Zenoh TCP endpoint",
        ),
        (
            &["--zenoh-connect", "udp/127.0.0.1:7447"],
            "not a Zenoh TCP endpoint",
        ),
    ];
    for (args, message) in cases {
        let (code, out, err) = run(gateway().args(args));
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(message), "{args:?}: {err}");
        assert!(!err.contains('\u{1b}'), "{args:?}: {err}");
        assert!(out.is_empty(), "{args:?}: {out}");
    }
}

/// More settings queries than the gateway keeps waiting (64): the extra ones are
/// refused, and their SETTING must not reach the aircraft either. The gateway sends the
/// SETTING before it checks the bound (`Service::setting_query` calls
/// `setting_request`, which sends, and refuses afterwards), so the aircraft gets 70.
#[test]
fn settings_queries_beyond_the_bound_are_refused_before_anything_is_sent() {
    let who = "pprz-ground gateway_too_many_queries";
    let Some(tools) = tools(who) else { return };
    let link = Link::new("radio");
    let gw = Gateway::start(&tools.messages, &[&link], &["--uplink-rate", "1000"]);
    let uplink = link.listen(tools.ids, false);
    link.send(&frame(7, 1, tools.ids.dl_value, &[2, 0, 0, 0, 0]));
    let mut client = Client::start(&tools, &gw.endpoint, &["queries", "7", "2", "70"]);
    let done = client.wait_for(40, |v| v["event"] == "queries");
    let outcome = done.unwrap_or_else(|| panic!("{:?}", client.seen))["outcome"].clone();
    // 64 wait and time out (the aircraft does not answer), 6 are refused at once.
    assert_eq!(
        outcome["more than 64 settings queries waiting"], 6,
        "{outcome}"
    );
    assert_eq!(outcome["no DL_VALUE"], 64, "{outcome}");
    let settings = uplink
        .frames()
        .iter()
        .filter(|(c, id, _)| *c == 2 && *id == tools.ids.setting)
        .count();
    assert_eq!(settings, 64, "SETTINGs the aircraft received");
    let _ = gw.stop();
}
