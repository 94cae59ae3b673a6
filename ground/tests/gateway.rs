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
use std::io::{BufRead, BufReader, Write};
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

/// The frames a link's uplink received: (class, id, payload).
struct UplinkLog {
    stop: Arc<AtomicBool>,
    frames: Arc<Mutex<Vec<(u8, u8, Vec<u8>)>>>,
    thread: Option<JoinHandle<()>>,
}

impl UplinkLog {
    fn frames(&self) -> Vec<(u8, u8, Vec<u8>)> {
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
                if v["event"] == "sample" && v["key"].as_str().is_some_and(|k| k.contains(key_part)) {
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
            (key, payload, v["attachment"].as_str().unwrap_or("").to_owned())
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
        &["subscribe", "pprz/*/telemetry/GPS_INT"],
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
    let _ = gw.stop();
}
