//! `pprz-monitor --zenoh`: the monitor as a client of a `pprz-gateway` on the Zenoh bus.
//! A fake aircraft plays on loopback UDP behind a real gateway; the monitor sees its
//! telemetry from the bus, and its PINGs and SETTINGs reach the aircraft as bus
//! commands that the gateway frames (PONG and DL_VALUE come back the same way).

use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, TcpListener, UdpSocket};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};

mod common;

use common::{MESSAGES, monitor, run};

/// A PPRZ v2 telemetry frame from `source` to the ground.
fn frame_from(source: u8, id: u8, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(source, 0, 1, id));
    let n = PprzV2::new().encode(&meta, payload, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// A loopback port free now (TCP or UDP).
fn free_port(udp: bool) -> u16 {
    if udp {
        UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    } else {
        TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    }
}

/// A `pprz-gateway` with one UDP link, killed when dropped.
struct Gateway {
    child: Child,
    /// Its Zenoh endpoint.
    zenoh: String,
    /// Where it reads the aircraft's datagrams.
    udp: SocketAddr,
}

impl Gateway {
    /// Starts one whose uplink goes to `aircraft`, and waits until it listens on the
    /// bus (a port taken in between: tried again on others).
    fn start(aircraft: SocketAddr) -> Self {
        for _ in 0..3 {
            let udp: SocketAddr = format!("127.0.0.1:{}", free_port(true)).parse().unwrap();
            let zenoh = format!("tcp/127.0.0.1:{}", free_port(false));
            let mut child = Command::new(env!("CARGO_BIN_EXE_pprz-gateway"))
                .args(["--messages", MESSAGES, "--duration", "20"])
                .args(["--udp", &udp.to_string(), "--uplink", &aircraft.to_string()])
                .args(["--zenoh-listen", &zenoh])
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .expect("the gateway runs");
            let (tx, rx) = mpsc::channel();
            let stderr = BufReader::new(child.stderr.take().unwrap());
            std::thread::spawn(move || {
                for line in stderr.lines().map_while(Result::ok) {
                    let _ = tx.send(line);
                }
            });
            let ready = std::iter::from_fn(|| rx.recv_timeout(Duration::from_secs(5)).ok())
                .any(|l| l.starts_with("zenoh: listening on"));
            if ready {
                return Self { child, zenoh, udp };
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        panic!("the gateway did not start");
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A fake aircraft 7 on loopback UDP: an ALIVE (md5sum n, 173, n counting) every
/// 20 ms to the gateway, a PONG for each PING, a DL_VALUE with the value set for each
/// SETTING. Stopped with its flag; gives the uplink frames it received (class, id,
/// fields).
struct Aircraft {
    socket: UdpSocket,
    stop: Arc<AtomicBool>,
}

/// What the fake aircraft received: class, message id, fields.
type Received = Vec<(u8, u8, Vec<u8>)>;

impl Aircraft {
    fn new() -> Self {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        Self {
            socket,
            stop: Arc::new(AtomicBool::new(false)),
        }
    }

    fn addr(&self) -> SocketAddr {
        self.socket.local_addr().unwrap()
    }

    fn fly(self, gateway: SocketAddr) -> (Arc<AtomicBool>, JoinHandle<Received>) {
        let stop = self.stop.clone();
        let socket = self.socket;
        let flying = std::thread::spawn(move || {
            let mut received = Vec::new();
            let mut buf = [0u8; 512];
            let mut n = 0u8;
            while !stop.load(Ordering::SeqCst) {
                socket
                    .send_to(&frame_from(7, 2, &[2, n, 0xAD]), gateway)
                    .unwrap();
                n = n.wrapping_add(1);
                let Ok((len, _)) = socket.recv_from(&mut buf) else {
                    continue;
                };
                // PPRZ v2: 99 len source destination class id fields... ck_a ck_b
                let f = &buf[..len];
                if len < 8 || f[3] != 7 {
                    continue;
                }
                received.push((f[4], f[5], f[6..len - 2].to_vec()));
                let reply = match (f[4], f[5]) {
                    (2, 8) => frame_from(7, 3, &[]),
                    // SETTING index ac_id value: applied.
                    (2, 4) if len == 14 => frame_from(7, 31, &[f[6], f[8], f[9], f[10], f[11]]),
                    _ => continue,
                };
                socket.send_to(&reply, gateway).unwrap();
            }
            received
        });
        (self.stop, flying)
    }
}

/// The ALIVE counters of the monitor's lines, in order.
fn alive_counters(out: &str) -> Vec<u8> {
    out.lines()
        .filter_map(|l| l.strip_prefix("7 telemetry ALIVE md5sum="))
        .filter_map(|rest| rest.split(',').next()?.parse().ok())
        .collect()
}

#[test]
fn telemetry_pings_and_settings_go_through_the_gateway() {
    let aircraft = Aircraft::new();
    let gateway = Gateway::start(aircraft.addr());
    let (stop, flying) = aircraft.fly(gateway.udp);
    // The gateway routes commands to the link it heard the aircraft on.
    std::thread::sleep(Duration::from_millis(200));
    let dir = std::env::temp_dir().join(format!("pprz-monitor-zenoh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (record, mcap) = (dir.join("fleet.log"), dir.join("fleet.mcap"));
    let (code, out, err) = run(monitor().args([
        "--record",
        record.to_str().unwrap(),
        "--mcap",
        mcap.to_str().unwrap(),
        "--messages",
        MESSAGES,
        "--zenoh",
        &gateway.zenoh,
        "--lines",
        "--duration",
        "2",
        "--ac-id",
        "7",
        "--ping",
        "0.2",
        "--setting",
        "2=1.5",
    ]));
    stop.store(true, Ordering::SeqCst);
    let received = flying.join().unwrap();
    assert_eq!(code, Some(0), "{err}");
    assert!(alive_counters(&out).len() > 20, "{out}");
    assert!(out.contains("7 telemetry PONG"), "{out}");
    assert!(err.contains("] PONG: round trip"), "{err}");
    assert!(
        err.contains("] DL_VALUE index=2 value=1.5: SETTING acknowledged"),
        "{err}"
    );
    assert!(err.contains("settings: acknowledged 1"), "{err}");
    assert!(err.contains("unexpected pongs 0"), "{err}");
    // What the aircraft received: PINGs, and the one SETTING index 2, ac_id 7, 1.5.
    assert!(received.iter().filter(|r| (r.0, r.1) == (2, 8)).count() >= 3);
    let settings: Vec<_> = received.iter().filter(|r| (r.0, r.1) == (2, 4)).collect();
    assert_eq!(settings.len(), 1, "{received:?}");
    assert_eq!(settings[0].2, [2, 7, 0, 0, 0xC0, 0x3F]);
    // The recordings take the fleet from the bus like any input.
    let recorded = |what: &str| {
        let line = err
            .lines()
            .find(|l| l.starts_with("recorded ") && l.contains(what))
            .expect(&err);
        line.split(' ').nth(1).unwrap().parse::<u32>().unwrap()
    };
    assert!(recorded(" frames to ") > 20, "{err}");
    assert!(recorded(" messages to ") > 20, "{err}");
    assert!(std::fs::metadata(&mcap).unwrap().len() > 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn two_monitors_watch_one_gateway() {
    let aircraft = Aircraft::new();
    let gateway = Gateway::start(aircraft.addr());
    let (stop, flying) = aircraft.fly(gateway.udp);
    let watch = || {
        monitor()
            .args(["--messages", MESSAGES, "--zenoh", &gateway.zenoh])
            .args(["--lines", "--duration", "1.5"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the monitor runs")
    };
    let (a, b) = (watch(), watch());
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    stop.store(true, Ordering::SeqCst);
    flying.join().unwrap();
    let mut seen = Vec::new();
    for m in [&a, &b] {
        let err = String::from_utf8_lossy(&m.stderr);
        assert_eq!(m.status.code(), Some(0), "{err}");
        let counters = alive_counters(&String::from_utf8_lossy(&m.stdout));
        // Every message from the first one seen on: nothing lost on the way.
        assert!(counters.len() > 20, "{counters:?}");
        assert!(
            counters.windows(2).all(|w| w[1] == w[0].wrapping_add(1)),
            "{counters:?}"
        );
        seen.push(counters);
    }
    let shared = seen[0].iter().filter(|n| seen[1].contains(n)).count();
    assert!(shared > 20, "{seen:?}");
}

#[test]
fn secure_another_transport_and_no_gateway_are_refused_clearly() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port(false));
    let with = |extra: &[&str]| {
        run(monitor()
            .args(["--messages", MESSAGES, "--zenoh", &endpoint, "--lines"])
            .args(extra))
    };
    let (code, _, err) = with(&["--secure", "ground.keys"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--secure does not apply to --zenoh"), "{err}");
    let (code, _, err) = with(&["--transport", "xbee"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--zenoh carries PPRZ v2 frames"), "{err}");
    let (code, _, err) = with(&["--udp", "127.0.0.1:0"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("cannot be used with"), "{err}");
    let (code, _, err) = run(monitor().args(["--zenoh", "udp/127.0.0.1:7447"]));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("not a Zenoh TCP endpoint"), "{err}");
    // Nothing listens there: one clear line naming the endpoint, exit status 1.
    let (code, out, err) = with(&["--duration", "1"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(out.is_empty(), "{out}");
    assert_eq!(err.lines().count(), 1, "{err}");
    let says = format!(
        "error: cannot reach the gateway at {endpoint} (is pprz-gateway listening there?): zenoh: "
    );
    assert!(err.starts_with(&says), "{err}");
    assert!(!err.contains(".rs:"), "no place in Zenoh's source: {err}");
}
