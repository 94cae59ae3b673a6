//! `pprz-monitor`: watch a Paparazzi-compatible aircraft live, from UDP, TCP, a serial
//! port, a file or standard input, with any `messages.xml`.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use clap::{Parser, ValueEnum};
use pprz_ground::monitor::Monitor;
use pprz_ground::set::RuntimeSet;
use pprz_ground::uplink;
use pprz_transports::{
    AnyTransport, Encoder, MsgHeader, PprzLog, PprzV1, PprzV2, TxMeta, XBee24, XBee868,
};

/// Transports the monitor can decode.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum Transport {
    /// PPRZ protocol v2 (source, destination, class, id).
    Pprz2,
    /// PPRZ protocol v1 (sender, id); messages are taken as telemetry.
    Pprz1,
    /// XBee API, 802.15.4 modules.
    Xbee,
    /// XBee API, 868 MHz modules.
    Xbee868,
    /// PPRZLOG records (SD card logs, recordings of this tool).
    Pprzlog,
}

impl Transport {
    fn any(self) -> AnyTransport {
        match self {
            Self::Pprz2 => PprzV2::new().into(),
            Self::Pprz1 => PprzV1::new(1).into(),
            Self::Xbee => XBee24::default().into(),
            Self::Xbee868 => XBee868::default().into(),
            Self::Pprzlog => PprzLog::TELEMETRY.into(),
        }
    }
}

/// Watch a Paparazzi-compatible aircraft: decode its telemetry live with any
/// messages.xml, measure PING round trips, send SETTINGs and see them acknowledged.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// The messages.xml to decode with (any Paparazzi file, e.g. the full PPRZLINK one).
    #[arg(long, default_value = "messages.xml")]
    messages: PathBuf,
    /// Framing of the byte stream.
    #[arg(long, value_enum, default_value = "pprz2")]
    transport: Transport,
    /// Listen for UDP datagrams on this address (Paparazzi's ground link uses port 4242).
    #[arg(long, value_name = "ADDR", group = "input")]
    udp: Option<SocketAddr>,
    /// Connect to a TCP server.
    #[arg(long, value_name = "ADDR", group = "input")]
    tcp: Option<SocketAddr>,
    /// Read a serial port (e.g. /dev/ttyUSB0).
    #[arg(long, value_name = "DEVICE", group = "input")]
    serial: Option<String>,
    /// Serial port baud rate.
    #[arg(long, default_value_t = 57_600)]
    baud: u32,
    /// Read (replay) a file, e.g. a PPRZLOG recording with `--transport pprzlog`.
    #[arg(long, value_name = "PATH", group = "input")]
    file: Option<PathBuf>,
    /// Read standard input.
    #[arg(long, group = "input")]
    stdin: bool,
    /// Where uplink frames go with --udp (the aircraft's datalink port, e.g. 127.0.0.1:4243).
    /// With --tcp or --serial they go back on the same stream.
    #[arg(long, value_name = "ADDR")]
    uplink: Option<SocketAddr>,
    /// Aircraft id for PING/SETTING.
    #[arg(long, default_value_t = 7)]
    ac_id: u8,
    /// Send a PING every this many seconds and show the round-trip time.
    #[arg(long, value_name = "SECONDS")]
    ping: Option<f64>,
    /// Send SETTING index=value at start (repeatable) and show the DL_VALUE acknowledgement.
    #[arg(long = "setting", value_name = "INDEX=VALUE", value_parser = parse_setting)]
    settings: Vec<(u8, f32)>,
    /// One line per message instead of the live table (for scripts).
    #[arg(long)]
    lines: bool,
    /// Record every received frame to this PPRZLOG file (replay it with --file and
    /// --transport pprzlog).
    #[arg(long, value_name = "PATH")]
    record: Option<PathBuf>,
    /// Stop after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    duration: Option<f64>,
}

fn parse_setting(s: &str) -> Result<(u8, f32), String> {
    let (i, v) = s
        .split_once('=')
        .ok_or_else(|| format!("expected INDEX=VALUE, got `{s}`"))?;
    let i = i
        .trim()
        .parse::<u8>()
        .map_err(|e| format!("index `{i}`: {e}"))?;
    let v = v
        .trim()
        .parse::<f32>()
        .map_err(|e| format!("value `{v}`: {e}"))?;
    Ok((i, v))
}

/// Where uplink frames are written.
enum UplinkSink {
    Udp(UdpSocket, SocketAddr),
    Stream(Box<dyn Write + Send>),
    None,
}

impl UplinkSink {
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        match self {
            Self::Udp(socket, to) => socket.send_to(frame, *to).map(drop),
            Self::Stream(w) => w.write_all(frame).and_then(|()| w.flush()),
            Self::None => Err(std::io::Error::other(
                "no uplink: give --uplink with --udp, or use --tcp/--serial",
            )),
        }
    }
}

/// Reads `reader` on a thread, sending chunks; an empty chunk means end of input.
fn spawn_reader(mut reader: Box<dyn Read + Send>, tx: mpsc::Sender<Vec<u8>>) {
    std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        loop {
            match reader.read(&mut buf) {
                Ok(0) => {
                    let _ = tx.send(Vec::new());
                    return;
                }
                Ok(n) => {
                    if tx.send(buf[..n].to_vec()).is_err() {
                        return;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => {
                    eprintln!("input error: {e}");
                    let _ = tx.send(Vec::new());
                    return;
                }
            }
        }
    });
}

fn open_input(args: &Args, tx: mpsc::Sender<Vec<u8>>) -> Result<UplinkSink, String> {
    if let Some(addr) = args.udp {
        let socket = UdpSocket::bind(addr).map_err(|e| format!("cannot bind UDP {addr}: {e}"))?;
        let recv = socket.try_clone().map_err(|e| e.to_string())?;
        std::thread::spawn(move || {
            let mut buf = [0u8; 2048];
            while let Ok((n, _)) = recv.recv_from(&mut buf) {
                if tx.send(buf[..n].to_vec()).is_err() {
                    return;
                }
            }
        });
        return Ok(match args.uplink {
            Some(to) => UplinkSink::Udp(socket, to),
            None => UplinkSink::None,
        });
    }
    if let Some(addr) = args.tcp {
        let stream =
            TcpStream::connect(addr).map_err(|e| format!("cannot connect to {addr}: {e}"))?;
        let write = stream.try_clone().map_err(|e| e.to_string())?;
        spawn_reader(Box::new(stream), tx);
        return Ok(UplinkSink::Stream(Box::new(write)));
    }
    if let Some(dev) = &args.serial {
        let port = serialport::new(dev, args.baud)
            .timeout(Duration::from_millis(100))
            .open()
            .map_err(|e| format!("cannot open serial port {dev}: {e}"))?;
        let write = port.try_clone().map_err(|e| e.to_string())?;
        spawn_reader(Box::new(port), tx);
        return Ok(UplinkSink::Stream(Box::new(write)));
    }
    if let Some(path) = &args.file {
        let file = std::fs::File::open(path)
            .map_err(|e| format!("cannot open {}: {e}", path.display()))?;
        spawn_reader(Box::new(file), tx);
        return Ok(UplinkSink::None);
    }
    spawn_reader(Box::new(std::io::stdin()), tx);
    Ok(UplinkSink::None)
}

fn main() -> ExitCode {
    let args = Args::parse();
    let set = match RuntimeSet::load(&args.messages) {
        Ok(set) => set,
        Err(e) => {
            eprintln!("{e}");
            eprintln!("(give the messages.xml of the aircraft with --messages)");
            return ExitCode::FAILURE;
        }
    };
    let transport = args.transport.any();
    let (tx, rx) = mpsc::channel();
    let mut uplink_sink = match open_input(&args, tx) {
        Ok(sink) => sink,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let mut record = match &args.record {
        Some(path) => match std::fs::File::create(path) {
            Ok(f) => Some(std::io::BufWriter::new(f)),
            Err(e) => {
                eprintln!("cannot create {}: {e}", path.display());
                return ExitCode::FAILURE;
            }
        },
        None => None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        if let Err(e) = ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)) {
            eprintln!("warning: Ctrl-C handler not installed: {e}");
        }
    }

    let start = Instant::now();
    let now = || start.elapsed().as_secs_f64();
    let mut monitor = Monitor::new(set, transport);
    let log_transport = PprzLog::TELEMETRY;
    let mut frame_buf = vec![0u8; log_transport.max_frame_len()];
    let mut send =
        |monitor: &mut Monitor, name: &str, values: &[(&str, f64)], setting: Option<u8>| {
            match uplink::frame(&set, transport, args.ac_id, name, values) {
                Ok(frame) => match uplink_sink.send(&frame) {
                    Ok(()) => match setting {
                        Some(index) => monitor.setting_sent(now(), index),
                        None => monitor.ping_sent(now()),
                    },
                    Err(e) => eprintln!("cannot send {name}: {e}"),
                },
                Err(e) => eprintln!("cannot build {name}: {e}"),
            }
        };
    for (index, value) in &args.settings {
        let values = [
            ("index", f64::from(*index)),
            ("ac_id", f64::from(args.ac_id)),
            ("value", f64::from(*value)),
        ];
        send(&mut monitor, "SETTING", &values, Some(*index));
    }
    let mut next_ping = args.ping.map(|_| 0.0);
    let mut next_render = 0.0;
    let mut ended = false;
    while !stop.load(Ordering::SeqCst) && !ended {
        let t = now();
        if args.duration.is_some_and(|d| t >= d) {
            break;
        }
        if let (Some(period), Some(at)) = (args.ping, next_ping)
            && t >= at
        {
            send(&mut monitor, "PING", &[], None);
            next_ping = Some(at + period);
        }
        match rx.recv_timeout(Duration::from_millis(50)) {
            Ok(chunk) if chunk.is_empty() => ended = true,
            Ok(chunk) => {
                monitor.feed(now(), &chunk, |line, raw| {
                    if args.lines {
                        println!("{line}");
                    }
                    if let Some(w) = record.as_mut() {
                        write_record(w, &log_transport, &mut frame_buf, now(), raw, transport);
                    }
                });
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => ended = true,
        }
        if !args.lines && now() >= next_render {
            print!("\x1b[2J\x1b[H{}", monitor.render(now()));
            let _ = std::io::stdout().flush();
            next_render = now() + 0.5;
        }
    }
    monitor.flush(now(), |line, _| {
        if args.lines {
            println!("{line}");
        }
    });
    if let Some(mut w) = record {
        let _ = w.flush();
    }
    if !args.lines {
        print!("\x1b[2J\x1b[H{}", monitor.render(now()));
    }
    eprintln!("{}", monitor.priority_summary());
    ExitCode::SUCCESS
}

/// Appends one received frame to a PPRZLOG recording (time stamp in 100 µs ticks).
fn write_record(
    w: &mut impl Write,
    log: &PprzLog,
    buf: &mut [u8],
    now: f64,
    raw: &[u8],
    transport: AnyTransport,
) {
    let Ok((frame, _)) = pprz_transports::Framing::parse(&transport, raw) else {
        return;
    };
    let header = MsgHeader::new(
        frame.source(),
        frame.destination().unwrap_or(0),
        frame.class(),
        frame.msg_id(),
    )
    .with_component(frame.component());
    let meta = TxMeta::new(header).at((now * 10_000.0) as u32);
    if let Ok(n) = log.encode(&meta, frame.payload(), buf) {
        let _ = w.write_all(&buf[..n]);
    }
}
