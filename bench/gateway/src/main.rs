//! `gateway-bench`: the load figures of `pprz-gateway` (BENCHMARKS.md, section
//! "Fleet gateway").
//!
//! 32 aircraft's telemetry, in the proportions of Paparazzi's default rotorcraft
//! telemetry ([`MIX`]), is sent as UDP datagrams (one PPRZ v2 frame each) into a real
//! `pprz-gateway` process at increasing rates; a Zenoh client session in this process
//! subscribes to `pprz/*/telemetry/*` over loopback TCP and stamps each sample's
//! arrival. Each sample's attachment (the frame as the link received it) identifies
//! the frame sent, so the added latency is arrival minus send, on one clock. With
//! `--links 2` every frame goes on two links (the gateway merges them).
//!
//! ```text
//! taskset -c 1 target/release/gateway-bench [--links 1|2] [--seconds S] [--rates R,R,...]
//! ```
//!
//! The gateway runs under `taskset -c 0` (one core); this program should run on the
//! other core. Needs the PPRZLINK reference `messages.xml` (`PPRZLINK_DIR`) and
//! `pprz-gateway` built in release beside this binary.

use std::collections::HashMap;
use std::hash::{BuildHasher, BuildHasherDefault, DefaultHasher};
use std::io::{BufRead, BufReader};
use std::net::{TcpListener, UdpSocket};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use pprz_ground::set::RuntimeSet;
use pprz_messages::MessageDescriptor;
use pprz_test_support::rng::Rng;
use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};
use zenoh::Wait;

/// The telemetry of each aircraft: Paparazzi's `default_rotorcraft.xml`, mode
/// `default` (message, period in seconds): 18.3 messages a second per aircraft.
const MIX: [(&str, f64); 15] = [
    ("DL_VALUE", 1.1),
    ("ROTORCRAFT_STATUS", 1.2),
    ("ROTORCRAFT_FP", 0.25),
    ("ALIVE", 2.1),
    ("INS_REF", 5.1),
    ("ROTORCRAFT_NAV_STATUS", 1.6),
    ("WP_MOVED", 1.3),
    ("ROTORCRAFT_CAM", 1.0),
    ("GPS_INT", 0.25),
    ("INS", 0.25),
    ("I2C_ERRORS", 4.1),
    ("UART_ERRORS", 3.1),
    ("SUPERBITRF", 3.0),
    ("ENERGY", 2.5),
    ("DATALINK_REPORT", 5.1),
];

/// Aircraft in the fleet.
const AIRCRAFT: u8 = 32;

/// Seconds the last frames of a step may take to arrive.
const DRAIN: f64 = 1.5;

type Hashes = BuildHasherDefault<DefaultHasher>;

fn hash(bytes: &[u8]) -> u64 {
    Hashes::default().hash_one(bytes)
}

/// The command line.
struct Args {
    links: usize,
    seconds: f64,
    rates: Vec<u32>,
    gateway: PathBuf,
    messages: PathBuf,
}

fn parse_args() -> Result<Args, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let mut a = Args {
        links: 1,
        seconds: 3.0,
        rates: vec![1_000, 10_000, 25_000, 50_000, 75_000, 100_000],
        gateway: exe.with_file_name("pprz-gateway"),
        messages: pprz_test_support::reference::dir().join("messages.xml"),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().ok_or(format!("{flag:?} needs a value"))?;
        let bad = |e: &dyn std::fmt::Display| format!("{flag} {value:?}: {e}");
        match flag.as_str() {
            "--links" => a.links = value.parse().map_err(|e| bad(&e))?,
            "--seconds" => a.seconds = value.parse().map_err(|e| bad(&e))?,
            "--rates" => {
                a.rates = value
                    .split(',')
                    .map(|r| r.parse().map_err(|e| bad(&e)))
                    .collect::<Result<_, _>>()?;
            }
            "--gateway" => a.gateway = value.into(),
            "--messages" => a.messages = value.into(),
            _ => return Err(format!("unknown option {flag:?}")),
        }
    }
    if !((1..=2).contains(&a.links) && a.seconds > 0.0 && a.seconds <= 60.0) {
        return Err("--links 1 or 2; --seconds 0 to 60".into());
    }
    Ok(a)
}

/// The frames of one step: `n` frames of the fleet's mix, each distinct.
fn fleet_frames(set: &RuntimeSet, n: usize, seed: u64) -> Vec<Vec<u8>> {
    let descs: Vec<(&MessageDescriptor<'_>, f64)> = MIX
        .iter()
        .map(|&(name, period)| {
            let d = set
                .find_by_name("telemetry", name)
                .unwrap_or_else(|| panic!("{name} is not in the messages.xml"));
            (d, 1.0 / period)
        })
        .collect();
    let total: f64 = descs.iter().map(|d| d.1).sum();
    let mut rng = Rng::new(seed);
    let mut seen = std::collections::HashSet::with_capacity(n);
    let mut frames = Vec::with_capacity(n);
    let t = PprzV2::new();
    while frames.len() < n {
        let ac = 1 + rng.below(usize::from(AIRCRAFT)) as u8;
        let mut pick = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64 * total;
        let desc = descs
            .iter()
            .find(|d| {
                pick -= d.1;
                pick <= 0.0
            })
            .unwrap_or(&descs[0])
            .0;
        let mut payload = [0u8; 255];
        let Ok(len) =
            pprz_messages::dynamic::synthesize(desc, &mut payload, 16, || rng.next_u64() as u8)
        else {
            continue;
        };
        let meta = TxMeta::new(MsgHeader::new(ac, 0, desc.class_id, desc.id));
        let mut buf = vec![0u8; 300];
        let Ok(m) = t.encode(&meta, &payload[..len], &mut buf) else {
            continue;
        };
        buf.truncate(m);
        if seen.insert(hash(&buf)) {
            frames.push(buf);
        }
    }
    frames
}

/// The running gateway, on core 0.
struct Gateway {
    child: Child,
    links: Vec<(UdpSocket, std::net::SocketAddr)>,
    endpoint: String,
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap_or(17_447)
}

fn start_gateway(args: &Args) -> Result<Gateway, String> {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut cmd = Command::new("taskset");
    cmd.args(["-c", "0"]).arg(&args.gateway);
    cmd.arg("--messages").arg(&args.messages);
    let mut links = Vec::new();
    for i in 0..args.links {
        let socket = UdpSocket::bind("127.0.0.1:0").map_err(|e| e.to_string())?;
        let port = UdpSocket::bind("127.0.0.1:0")
            .and_then(|s| s.local_addr())
            .map_err(|e| e.to_string())?;
        let uplink = socket.local_addr().map_err(|e| e.to_string())?;
        cmd.arg("--link")
            .arg(format!("l{i}=udp:{port},uplink={uplink}"));
        links.push((socket, port));
    }
    cmd.args(["--zenoh-listen", &endpoint])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("{}: {e}", args.gateway.display()))?;
    let stderr = child.stderr.take().ok_or("no stderr")?;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if line.starts_with("zenoh: listening on") {
                let _ = tx.send(());
            }
        }
    });
    rx.recv_timeout(Duration::from_secs(30))
        .map_err(|_| "the gateway did not start".to_owned())?;
    Ok(Gateway {
        child,
        links,
        endpoint,
    })
}

/// A figure of `/proc/<pid>/status` in kB.
fn status_kb(pid: u32, field: &str) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix(field))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// CPU seconds the process used (all threads).
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let after = stat.rsplit_once(')').map(|x| x.1).unwrap_or("");
    // After the name come fields 3 (state) onwards: utime and stime are 14 and 15.
    let f: Vec<&str> = after.split_whitespace().collect();
    let field = |k: usize| {
        f.get(k - 3)
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0)
    };
    let ticks = field(14) + field(15);
    ticks as f64 / 100.0
}

/// What one step measured.
struct Step {
    rate: u32,
    sent: usize,
    achieved: f64,
    received: usize,
    duplicates: usize,
    latency_ms: [f64; 3],
    cpu: f64,
    rss_kb: u64,
}

type Arrivals = Arc<Mutex<Vec<(u64, Instant)>>>;

/// Sends `frames` at `rate` a second on every link, paced by the millisecond; the
/// send time of each.
fn send(gw: &Gateway, frames: &[Vec<u8>], rate: u32) -> Vec<Instant> {
    let mut sent = Vec::with_capacity(frames.len());
    let start = Instant::now();
    let per_ms = f64::from(rate) / 1000.0;
    let mut next = 0usize;
    let mut ms = 0u64;
    while next < frames.len() {
        ms += 1;
        let due = ((ms as f64 * per_ms) as usize).min(frames.len());
        for f in &frames[next..due] {
            let now = Instant::now();
            for (socket, to) in &gw.links {
                let _ = socket.send_to(f, to);
            }
            sent.push(now);
        }
        next = due;
        let at = start + Duration::from_millis(ms);
        if let Some(wait) = at.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    sent
}

fn run_step(gw: &Gateway, set: &RuntimeSet, rate: u32, seconds: f64, arrivals: &Arrivals) -> Step {
    let n = (f64::from(rate) * seconds) as usize;
    let frames = fleet_frames(set, n, u64::from(rate));
    let index: HashMap<u64, usize> = frames
        .iter()
        .enumerate()
        .map(|(i, f)| (hash(f), i))
        .collect();
    arrivals.lock().unwrap().clear();
    let pid = gw.child.id();
    let cpu0 = cpu_seconds(pid);
    let t0 = Instant::now();
    let sent = send(gw, &frames, rate);
    let achieved = n as f64 / t0.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_secs_f64(DRAIN));
    let cpu = (cpu_seconds(pid) - cpu0) / t0.elapsed().as_secs_f64();
    let got = std::mem::take(&mut *arrivals.lock().unwrap());
    let mut seen = vec![false; n];
    let mut duplicates = 0;
    let mut lat: Vec<f64> = Vec::with_capacity(got.len());
    for (h, at) in got {
        let Some(&i) = index.get(&h) else { continue };
        if std::mem::replace(&mut seen[i], true) {
            duplicates += 1;
            continue;
        }
        lat.push(at.saturating_duration_since(sent[i]).as_secs_f64() * 1e3);
    }
    lat.sort_by(f64::total_cmp);
    let q = |p: f64| {
        lat.get(((lat.len() as f64 - 1.0) * p) as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    Step {
        rate,
        sent: n,
        achieved,
        received: lat.len(),
        duplicates,
        latency_ms: [q(0.5), q(0.99), lat.last().copied().unwrap_or(f64::NAN)],
        cpu,
        rss_kb: status_kb(pid, "VmRSS:"),
    }
}

fn main() -> std::process::ExitCode {
    match bench() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("gateway-bench: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn bench() -> Result<(), String> {
    let args = parse_args()?;
    let set = RuntimeSet::load(&args.messages)
        .map_err(|e| format!("{}: {e}", args.messages.display()))?;
    let mut gw = start_gateway(&args)?;
    let arrivals: Arrivals = Arc::new(Mutex::new(Vec::new()));
    let session = zenoh::open(client_config(&gw.endpoint)?)
        .wait()
        .map_err(|e| e.to_string())?;
    let sink = arrivals.clone();
    let _sub = session
        .declare_subscriber("pprz/*/telemetry/*")
        .callback(move |sample| {
            let at = Instant::now();
            if let Some(a) = sample.attachment() {
                let h = hash(&a.to_bytes());
                sink.lock().unwrap().push((h, at));
            }
        })
        .wait()
        .map_err(|e| e.to_string())?;
    std::thread::sleep(Duration::from_millis(500));
    println!(
        "| offered msg/s | sent msg/s | delivered | lost | duplicates | latency p50 / p99 / max (ms) | gateway CPU (cores) | gateway RSS (MiB) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for &rate in &args.rates {
        let s = run_step(&gw, &set, rate, args.seconds, &arrivals);
        println!(
            "| {} | {:.0} | {} / {} | {} | {} | {:.2} / {:.2} / {:.2} | {:.2} | {:.1} |",
            s.rate,
            s.achieved,
            s.received,
            s.sent,
            s.sent - s.received,
            s.duplicates,
            s.latency_ms[0],
            s.latency_ms[1],
            s.latency_ms[2],
            s.cpu,
            s.rss_kb as f64 / 1024.0
        );
    }
    let pid = gw.child.id();
    println!(
        "gateway peak RSS (VmHWM): {:.1} MiB; links: {}; {} aircraft",
        status_kb(pid, "VmHWM:") as f64 / 1024.0,
        args.links,
        AIRCRAFT
    );
    let _ = gw.child.kill();
    let _ = gw.child.wait();
    Ok(())
}

/// A client session to `endpoint` only, no scouting.
fn client_config(endpoint: &str) -> Result<zenoh::Config, String> {
    let mut c = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"client\"".to_owned()),
        ("connect/endpoints", format!("[\"{endpoint}\"]")),
        ("listen/endpoints", "[]".to_owned()),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("scouting/gossip/enabled", "false".to_owned()),
    ] {
        c.insert_json5(k, &v).map_err(|e| format!("{k}: {e}"))?;
    }
    Ok(c)
}
