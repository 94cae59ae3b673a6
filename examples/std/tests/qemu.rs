//! The emulated firmwares under QEMU, with this test as their ground station: the
//! Cortex-M4 one (`examples/mps2-an386`, QEMU's `mps2-an386` machine) and the Cortex-M0
//! one, a core without compare-and-swap (`examples/microbit`, QEMU's `microbit` machine,
//! nRF51822 with 32 KiB of RAM). QEMU carries the firmware's UART0 over a socket; the
//! test decodes the telemetry, sends PING and SETTING frames up, and checks that PONG and
//! the DL_VALUE acknowledgement come back and that the periodic telemetry of
//! `telemetry.xml` arrives at its configured rates, measured on the guest's own clock
//! (GPS_INT's `tow` field). A second test cuts the uplink: the firmware's link-loss
//! failsafe flies home, and the `ap_mode` setting brings it back to NAV. Both run on
//! each board. On mps2-an386 only, a third stores the gain in the firmware's settings
//! flash (the machine's PSRAM, kept in a file), kills QEMU, starts it again on the same
//! file and reads the gain back, and a fourth runs the secure firmware.
//!
//! QEMU's serial port is a Unix socket of this test's own (a path unique to the process
//! and the test), so tests running side by side never race for a TCP port.
//!
//! Needs `qemu-system-arm` (or `PPRZ_QEMU`) and the firmware ELFs, built first with
//! `cargo build --release` in `examples/mps2-an386` and `examples/microbit` (or named by
//! `PPRZ_QEMU_FIRMWARE` and `PPRZ_QEMU_MICROBIT_FIRMWARE`). Without them a test is
//! skipped with a note on stderr, unless `PPRZ_REQUIRE_QEMU=1` (CI) makes that a
//! failure. QEMU is killed at the end, also when the test fails.

use std::io::{ErrorKind, Read, Write as _};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use pprz_default::messages::telemetry::values::RotorcraftStatusApMode as ApMode;
use pprz_default::messages::telemetry::{DlValue, GpsInt, Pong, RotorcraftStatus};
use pprz_default::periodic::SCHEDULE;
use pprz_example_app::AC_ID;
use pprz_ground::monitor::{Event, Monitor};
use pprz_ground::secure::GroundSecure;
use pprz_ground::set::RuntimeSet;
use pprz_ground::settings::Answer;
use pprz_ground::uplink;
use pprz_messages::{Decode, Message};
use pprz_secure::KeyFile;
use pprz_transports::{AnyTransport, Decoder, PprzV2};

/// Guest time over which the periodic rates are measured, in ms (GPS_INT `tow`).
const WINDOW_MS: u32 = 6_000;
/// Wall-clock bound of the exchange, from the connection on (the guest starts then). A
/// run takes the window plus a fraction of a second; QEMU is slower to start and its
/// guest clock lags on a loaded machine, hence the margin.
const DEADLINE: Duration = Duration::from_secs(20);
/// The SETTING sent: index 2 is the example application's `gain`.
const GAIN_INDEX: u8 = 2;
const GAIN: f32 = 2.5;

/// An emulated board: its QEMU machine and the crate of its firmware.
#[derive(Debug, Clone, Copy)]
struct Board {
    /// QEMU's machine (`-M`), also the board's name in sockets and messages.
    machine: &'static str,
    /// QEMU's other machine options.
    options: &'static [&'static str],
    /// The firmware crate's directory, in `examples/`.
    crate_dir: &'static str,
    /// The firmware's Rust target.
    target: &'static str,
    /// The variable that names another firmware ELF.
    firmware_var: &'static str,
    /// Whether the machine has a PSRAM QEMU can keep in a file.
    psram: bool,
}

/// The emulated Cortex-M4 (ARM MPS2 with the AN386 image).
const MPS2_AN386: Board = Board {
    machine: "mps2-an386",
    options: &[],
    crate_dir: "mps2-an386",
    target: "thumbv7em-none-eabihf",
    firmware_var: "PPRZ_QEMU_FIRMWARE",
    psram: true,
};

/// The emulated Cortex-M0 without compare-and-swap (BBC micro:bit, nRF51822), with the
/// nRF51822-QFAC's 32 KiB of RAM (QEMU's default is 16 KiB, too little for the firmware).
const MICROBIT: Board = Board {
    machine: "microbit",
    options: &["-global", "nrf51-soc.sram-size=32768"],
    crate_dir: "microbit",
    target: "thumbv6m-none-eabi",
    firmware_var: "PPRZ_QEMU_MICROBIT_FIRMWARE",
    psram: false,
};

/// QEMU, killed and reaped when dropped (so also when the test panics).
struct Qemu {
    child: Child,
}

impl Qemu {
    /// QEMU emulating `board`, running `firmware`, its UART0 on `socket`; with `psram`,
    /// the machine's PSRAM (the firmware's settings flash) is that file, which keeps what
    /// the guest writes.
    fn start(
        qemu: &str,
        board: Board,
        firmware: &Path,
        socket: &Path,
        psram: Option<&Path>,
    ) -> std::io::Result<Self> {
        let mut command = Command::new(qemu);
        match psram {
            Some(file) => {
                assert!(board.psram, "{} has no PSRAM", board.machine);
                command
                    .arg("-M")
                    .arg(format!("{},memory-backend=psram", board.machine))
                    .arg("-object")
                    .arg(format!(
                        "memory-backend-file,id=psram,size=16M,mem-path={},share=on",
                        file.display()
                    ))
            }
            None => command.args(["-M", board.machine]),
        };
        let child = command
            .args(board.options)
            .args(["-nographic", "-monitor", "none", "-serial"])
            .arg(format!("unix:{},server=on,wait=on", socket.display()))
            .arg("-kernel")
            .arg(firmware)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()?;
        Ok(Self { child })
    }

    /// Connects to the serial port QEMU listens on (it starts the guest once we are
    /// connected). `Err` with QEMU's stderr if it exited first.
    fn connect(&mut self, socket: &Path) -> Result<UnixStream, String> {
        let start = Instant::now();
        loop {
            if let Some(exit) = self.exited() {
                return Err(exit);
            }
            match UnixStream::connect(socket) {
                Ok(stream) => return Ok(stream),
                Err(e) if start.elapsed() > Duration::from_secs(10) => {
                    return Err(format!(
                        "cannot connect to QEMU's serial port {}: {e}",
                        socket.display()
                    ));
                }
                Err(_) => std::thread::sleep(Duration::from_millis(20)),
            }
        }
    }

    /// QEMU's exit status and stderr if it has exited.
    fn exited(&mut self) -> Option<String> {
        let status = self.child.try_wait().ok()??;
        let mut stderr = String::new();
        if let Some(mut pipe) = self.child.stderr.take() {
            let _ = pipe.read_to_string(&mut stderr);
        }
        Some(format!("QEMU exited ({status}): {}", stderr.trim()))
    }
}

/// The guest's UART0 as the test's serial link: QEMU and the connection to it. A failed
/// read or write panics with QEMU's exit status and stderr if it exited.
struct Serial {
    qemu: Qemu,
    stream: UnixStream,
}

impl Serial {
    /// Writes `bytes` (`what` names them in a failure).
    fn send(&mut self, bytes: &[u8], what: &str) {
        if let Err(e) = self.stream.write_all(bytes) {
            panic!("{}", self.failure(what, &e));
        }
    }

    /// Reads what the guest sent into `buf` (0 bytes when nothing came within the read
    /// timeout).
    fn receive(&mut self, buf: &mut [u8]) -> usize {
        match self.stream.read(buf) {
            Ok(0) => panic!(
                "QEMU closed the serial connection ({:?})",
                self.qemu.exited()
            ),
            Ok(n) => n,
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => 0,
            Err(e) => panic!("{}", self.failure("reading QEMU's serial port", &e)),
        }
    }

    /// Why the serial connection failed with `e`: QEMU's exit if it exited.
    fn failure(&mut self, what: &str, e: &std::io::Error) -> String {
        std::thread::sleep(Duration::from_millis(100));
        let exit = self
            .qemu
            .exited()
            .unwrap_or_else(|| "QEMU still running".to_owned());
        format!("{what}: {e} ({exit})")
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Skips the test with `reason`, or fails it if the environment requires QEMU.
fn skip(reason: &str) {
    if std::env::var("PPRZ_REQUIRE_QEMU").is_ok_and(|v| v == "1") {
        panic!("PPRZ_REQUIRE_QEMU=1 but {reason}");
    }
    // The real stderr: the test harness captures `eprintln!`.
    let _ = writeln!(std::io::stderr(), "qemu test skipped: {reason}");
}

/// The firmware binary `name` of `board`: its variable (`PPRZ_QEMU_FIRMWARE` for
/// mps2-an386, with `-secure` appended for the secure one), else the release build in the
/// firmware crate's own target directory, else in `CARGO_TARGET_DIR` (where it lands
/// when that is set).
fn firmware_path(board: Board, name: &str) -> PathBuf {
    if let Some(path) = std::env::var_os(board.firmware_var) {
        let mut path = path;
        path.push(name.strip_prefix("aircraft").unwrap_or_default());
        return PathBuf::from(path);
    }
    let elf = format!("{}/release/{name}", board.target);
    let local = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(board.crate_dir)
        .join("target")
        .join(&elf);
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) if !local.is_file() => Path::new(&dir).join(elf),
        _ => local,
    }
}

/// Boots firmware `name` of `board` under QEMU and connects to its UART0 (a socket named
/// after the board and `test`, which no other test of the process uses), or `None` (the
/// test is skipped, or fails where QEMU is required) when QEMU or the firmware is
/// missing.
fn boot(board: Board, name: &str, test: &str) -> Option<Serial> {
    boot_with(board, name, test, None)
}

/// [`boot`], the machine's PSRAM in the file `psram` if given.
fn boot_with(board: Board, name: &str, test: &str, psram: Option<&Path>) -> Option<Serial> {
    let qemu = std::env::var("PPRZ_QEMU").unwrap_or_else(|_| "qemu-system-arm".to_owned());
    let firmware = firmware_path(board, name);
    if !firmware.is_file() {
        skip(&format!(
            "no {} firmware at {} (build it: cd examples/{} && cargo build --release)",
            board.machine,
            firmware.display(),
            board.crate_dir
        ));
        return None;
    }
    if Command::new(&qemu)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map_or(true, |s| !s.success())
    {
        skip(&format!("{qemu} is not installed"));
        return None;
    }
    let socket = std::env::temp_dir().join(format!(
        "pprz-qemu-{}-{}-{test}.sock",
        std::process::id(),
        board.machine
    ));
    let _ = std::fs::remove_file(&socket);
    let mut guard = Qemu::start(&qemu, board, &firmware, &socket, psram).expect("QEMU starts");
    let stream = guard.connect(&socket).unwrap_or_else(|e| panic!("{e}"));
    // The connection is made: the path is no longer needed.
    let _ = std::fs::remove_file(&socket);
    stream
        .set_read_timeout(Some(Duration::from_millis(20)))
        .expect("socket timeout");
    Some(Serial {
        qemu: guard,
        stream,
    })
}

/// The ground's requests: a PING, and the SETTING of the gain to [`GAIN`] (plain frames).
fn requests(set: &RuntimeSet) -> (Vec<u8>, Vec<u8>) {
    let transport = AnyTransport::from(PprzV2::new());
    let ping = uplink::frame(set, transport, AC_ID, "PING", &[]).expect("PING frame");
    (ping, setting(set, GAIN_INDEX, GAIN))
}

/// The SETTING of setting `index` to `value` (a plain frame).
fn setting(set: &RuntimeSet, index: u8, value: f32) -> Vec<u8> {
    uplink::frame(
        set,
        AnyTransport::from(PprzV2::new()),
        AC_ID,
        "SETTING",
        &[
            ("index", f64::from(index)),
            ("ac_id", f64::from(AC_ID)),
            ("value", f64::from(value)),
        ],
    )
    .expect("SETTING frame")
}

/// The project's default message set, as the ground tools load it.
fn default_set() -> RuntimeSet {
    RuntimeSet::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../../messages.xml"))
        .expect("messages.xml loads")
}

/// One received message: its id and, for GPS_INT, the guest time it was sent at.
struct Received {
    class: u8,
    id: u8,
    tow_ms: Option<u32>,
}

#[test]
fn firmware_answers_and_sends_telemetry_at_configured_rates() {
    answers_and_sends_telemetry_at_configured_rates(MPS2_AN386);
}

/// [`firmware_answers_and_sends_telemetry_at_configured_rates`] on the Cortex-M0 without
/// compare-and-swap.
#[test]
fn microbit_firmware_answers_and_sends_telemetry_at_configured_rates() {
    answers_and_sends_telemetry_at_configured_rates(MICROBIT);
}

/// The firmware of `board` answers PING and SETTING, and sends the periodic telemetry at
/// the configured rates on its own clock.
fn answers_and_sends_telemetry_at_configured_rates(board: Board) {
    let Some(mut serial) = boot(board, "aircraft", "rates") else {
        return;
    };
    let set = default_set();
    let transport = AnyTransport::from(PprzV2::new());
    let (ping, setting) = requests(&set);

    // The ground tool's monitor (PONG and DL_VALUE events) and a typed decoder (guest
    // time stamps) read the same bytes.
    let mut monitor = Monitor::new(set, transport);
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut received: Vec<Received> = Vec::new();
    let mut pong_rtt: Option<f64> = None;
    let mut monitor_saw_gain = false;
    let mut ack: Option<(f64, Option<f64>)> = None;
    let mut next_ping = 0.0;
    let mut next_setting = 0.0;
    let mut setting_first_sent: Option<f64> = None;
    let mut buf = [0u8; 1024];
    let mut first_byte: Option<f64> = None;
    let start = Instant::now();
    // Guest time of the first and the latest GPS_INT.
    let mut tows: Option<(u32, u32)> = None;
    while start.elapsed() < DEADLINE {
        let now = start.elapsed().as_secs_f64();
        // PING once the aircraft talks, again every second until a PONG; then the
        // SETTING, again every second until acknowledged.
        if !received.is_empty() && pong_rtt.is_none() && now >= next_ping {
            serial.send(&ping, "send PING");
            monitor.ping_sent(None, now);
            next_ping = now + 1.0;
        }
        if pong_rtt.is_some() && ack.is_none() && now >= next_setting {
            serial.send(&setting, "send SETTING");
            monitor.setting_sent(None, now, GAIN_INDEX, f64::from(GAIN));
            setting_first_sent.get_or_insert(now);
            next_setting = now + 1.0;
        }

        let n = serial.receive(&mut buf);
        let bytes = &buf[..n];
        let now = start.elapsed().as_secs_f64();
        if n > 0 {
            first_byte.get_or_insert(now);
        }
        monitor.feed(now, bytes, |_| {});
        let mut input = bytes;
        while let Some(frame) = decoder.feed(&mut input) {
            assert_eq!(frame.source(), AC_ID, "frame from another aircraft");
            let (class, id) = (frame.class(), frame.msg_id());
            let tow_ms = ((class, id) == (GpsInt::CLASS_ID, GpsInt::ID)).then(|| {
                GpsInt::decode(frame.payload())
                    .expect("GPS_INT decodes")
                    .tow
            });
            if (class, id) == (DlValue::CLASS_ID, DlValue::ID) {
                let v = DlValue::decode(frame.payload()).expect("DL_VALUE decodes");
                if v.index == GAIN_INDEX && v.value == GAIN && ack.is_none() {
                    // The gain starts at 1.0: 2.5 is the SETTING applied.
                    let after = setting_first_sent.map(|t| now - t);
                    ack = Some((now, after));
                }
            }
            if let Some(tow) = tow_ms {
                tows = Some(tows.map_or((tow, tow), |(first, _)| (first, tow)));
            }
            received.push(Received { class, id, tow_ms });
        }
        // The monitor keeps its latest events only: look at them after every read.
        for (_, event) in monitor.events() {
            match event {
                Event::Pong { rtt } => {
                    pong_rtt.get_or_insert(*rtt);
                }
                Event::DlValue {
                    index,
                    value,
                    answer,
                } => {
                    // The monitor takes it as the acknowledgement of the value set.
                    monitor_saw_gain |= *index == GAIN_INDEX
                        && *value == f64::from(GAIN)
                        && matches!(answer, Answer::Acknowledged { .. });
                }
                Event::SecureSession { .. } => panic!("a secure session on a plain link"),
                Event::SettingsRead { .. } => panic!("no settings read was asked for"),
            }
        }
        if pong_rtt.is_some()
            && ack.is_some()
            && tows.is_some_and(|(first, last)| last.saturating_sub(first) >= WINDOW_MS)
        {
            break;
        }
    }
    let wall = start.elapsed().as_secs_f64();

    // The link is clean: every byte belongs to a verified frame the set knows.
    let stats = *monitor.decoder_stats();
    assert!(
        stats.frames > 0,
        "no telemetry from the firmware in {wall:.1} s"
    );
    assert_eq!(stats.errors(), 0, "decoder errors: {stats:?}");
    assert_eq!(stats.dropped_bytes, 0, "bytes outside frames: {stats:?}");
    assert_eq!(monitor.unknown(), 0, "unknown messages");
    assert_eq!(monitor.malformed(), 0, "malformed messages");

    // The datalink services answered.
    let rtt = pong_rtt.unwrap_or_else(|| panic!("no PONG in {wall:.1} s"));
    let (_, ack_after) =
        ack.unwrap_or_else(|| panic!("no DL_VALUE acknowledging gain = {GAIN} in {wall:.1} s"));
    let ack_after = ack_after.expect("DL_VALUE with the new gain only after the SETTING");
    assert!(monitor_saw_gain, "the monitor missed the DL_VALUE");
    assert!(
        ack_after < 1.0,
        "acknowledged {ack_after:.3} s after the SETTING"
    );

    // Periodic telemetry at the rates of telemetry.xml's default mode, on the guest's
    // clock: between the first and the last GPS_INT (whose `tow` is the guest's time in
    // ms), a message of period P arrives span / P times, give or take one at the edges.
    let gps: Vec<(usize, u32)> = received
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.tow_ms.map(|t| (i, t)))
        .collect();
    let (Some(&(first_i, first_tow)), Some(&(last_i, last_tow))) = (gps.first(), gps.last()) else {
        panic!("no GPS_INT");
    };
    let span_ms = last_tow - first_tow;
    assert!(
        span_ms >= WINDOW_MS,
        "only {span_ms} ms of guest time in {wall:.1} s of wall-clock time"
    );
    let mode = &SCHEDULE.processes[0].modes[0];
    let period_ms =
        |ticks: u32| f64::from(ticks.max(1)) * 1000.0 / f64::from(SCHEDULE.frequency_hz);
    let gps_period = mode
        .messages
        .iter()
        .find(|m| m.is(GpsInt::CLASS_ID, GpsInt::ID))
        .map(|m| period_ms(m.period_ticks))
        .expect("GPS_INT is in the default mode");
    for pair in gps.windows(2) {
        let dt = f64::from(pair[1].1 - pair[0].1);
        assert!(
            (dt - gps_period).abs() <= gps_period / 10.0,
            "GPS_INT {dt} ms after the previous one, configured every {gps_period} ms"
        );
    }
    let mut report = Vec::new();
    for m in mode.messages {
        let period = period_ms(m.period_ticks);
        // DL_VALUE is also an acknowledgement; rates need two periods in the window.
        if m.name == "DL_VALUE" || 2.0 * period > f64::from(span_ms) {
            continue;
        }
        let count = received[first_i + 1..=last_i]
            .iter()
            .filter(|r| m.is(r.class, r.id))
            .count();
        let expected = f64::from(span_ms) / period;
        report.push(format!("{} {count} (expected {expected:.1})", m.name));
        assert!(
            (count as f64 - expected).abs() <= 1.0 + 1e-6,
            "{}: {count} in {span_ms} ms of guest time, configured every {period} ms",
            m.name
        );
    }
    let _ = writeln!(
        std::io::stderr(),
        "qemu {}: {} frames in {wall:.1} s (first byte after {:.0} ms; guest clock at the \
         end {last_tow} ms); PONG after {:.1} ms, gain acknowledged after {:.1} ms; over \
         {span_ms} ms: {}",
        board.machine,
        stats.frames,
        first_byte.unwrap_or(0.0) * 1e3,
        rtt * 1e3,
        ack_after * 1e3,
        report.join(", ")
    );
}

/// The secure firmware (`aircraft-secure`): nothing but its key exchange until this test,
/// as the ground, completes the handshake with the published test keys; then encrypted
/// telemetry, an encrypted PING answered by an encrypted PONG, and an encrypted SETTING
/// acknowledged. Every frame on the wire is secure (`0x55` encrypted or `0xAA` key
/// exchange), and none is rejected by the ground.
#[test]
fn secure_firmware_completes_the_handshake_and_answers_encrypted_pings() {
    let Some(mut serial) = boot(MPS2_AN386, "aircraft-secure", "secure") else {
        return;
    };
    let keys = KeyFile::parse(pprz_secure::keys::INSECURE_TEST_KEY_FILE).expect("test keys");
    let ground = GroundSecure::new(AC_ID, keys.ground().expect("ground keys"));
    let set = default_set();
    let transport = AnyTransport::from(PprzV2::new());
    let (ping, setting) = requests(&set);
    let mut monitor = Monitor::new(set, transport)
        .with_secure(ground)
        .expect("PPRZ v2 takes a secure link");
    let mut wire: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut crypto_bytes = Vec::new();
    let mut session_at = None;
    let mut pong_rtt = None;
    let mut acked = false;
    let mut next_request = 0.0;
    let mut buf = [0u8; 1024];
    let start = Instant::now();
    while start.elapsed() < DEADLINE && !(pong_rtt.is_some() && acked) {
        let now = start.elapsed().as_secs_f64();
        for frame in monitor.poll_secure(now) {
            serial.send(&frame, "send a key exchange");
        }
        if monitor.uplink_ready() && now >= next_request {
            let request = if pong_rtt.is_none() { &ping } else { &setting };
            let sealed = monitor.seal_uplink(request).expect("a session seals");
            serial.send(&sealed, "send a request");
            if pong_rtt.is_none() {
                monitor.ping_sent(None, now);
            } else {
                monitor.setting_sent(None, now, GAIN_INDEX, f64::from(GAIN));
            }
            next_request = now + 1.0;
        }
        let n = serial.receive(&mut buf);
        let bytes = &buf[..n];
        let mut input = bytes;
        while let Some(frame) = wire.feed(&mut input) {
            crypto_bytes.push(frame.data()[0]);
        }
        let now = start.elapsed().as_secs_f64();
        monitor.feed(now, bytes, |_| {});
        for (_, event) in monitor.events() {
            match event {
                Event::SecureSession { .. } => {
                    session_at.get_or_insert(now);
                }
                Event::Pong { rtt } => {
                    pong_rtt.get_or_insert(*rtt);
                }
                Event::DlValue { index, answer, .. } => {
                    acked |= *index == GAIN_INDEX && matches!(answer, Answer::Acknowledged { .. });
                }
                Event::SettingsRead { .. } => panic!("no settings read was asked for"),
            }
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let session_at = session_at
        .unwrap_or_else(|| panic!("no session in {wall:.1} s: {:?}", monitor.secure_lines()));
    let rtt = pong_rtt.unwrap_or_else(|| panic!("no encrypted PONG in {wall:.1} s"));
    assert!(
        acked,
        "no DL_VALUE acknowledging the encrypted SETTING in {wall:.1} s"
    );
    let status = monitor.secure_status().expect("secure");
    assert!(status.stats.channel.decrypted > 0);
    assert_eq!(status.stats.channel.rejected(), 0, "{:?}", status.stats);
    assert!(
        crypto_bytes.iter().all(|&b| b == 0x55 || b == 0xAA),
        "a frame in the clear: {crypto_bytes:x?}"
    );
    assert_eq!(monitor.decoder_stats().errors(), 0);
    assert_eq!(monitor.unknown(), 0, "unknown messages");
    let _ = writeln!(
        std::io::stderr(),
        "qemu secure: session after {:.0} ms, encrypted PONG after {:.1} ms, {} frames \
         decrypted, {} in plaintext (key exchange)",
        session_at * 1e3,
        rtt * 1e3,
        status.stats.channel.decrypted,
        crypto_bytes.iter().filter(|&&b| b == 0xAA).count(),
    );
}

/// The example application's `ap_mode` setting (its fourth) and the ROTORCRAFT_STATUS
/// `ap_mode` values the test sees.
const AP_MODE_INDEX: u8 = 3;
const NAV: u8 = ApMode::Nav.raw();
const HOME: u8 = ApMode::Home.raw();
/// The firmwares' lost timeout (`HEALTH` in their `board.rs`), in ms of guest time: after
/// this long without a frame from the ground, the vehicle flies home.
const LOST_AFTER_MS: u32 = 2_000;
/// Seconds between the test's PINGs while it keeps the link up (the firmware's link is
/// Degraded after 1 s of silence).
const PING_EVERY: f64 = 0.5;

/// The steps of the link-loss test, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// PINGs every [`PING_EVERY`] until a PONG and, after it, a ROTORCRAFT_STATUS.
    Up,
    /// Nothing sent, until a ROTORCRAFT_STATUS reports HOME.
    Silent,
    /// The SETTING `ap_mode` = NAV, again every second until its DL_VALUE.
    Setting,
    /// PINGs every [`PING_EVERY`] until a ROTORCRAFT_STATUS reports NAV.
    Back,
    /// All seen.
    Done,
}

impl Step {
    fn next(self) -> Self {
        match self {
            Step::Up => Step::Silent,
            Step::Silent => Step::Setting,
            Step::Setting => Step::Back,
            Step::Back | Step::Done => Step::Done,
        }
    }
}

/// The ground's side of the link-loss test: the step it is in, and what the aircraft
/// reported. A frame's guest time is the `tow` (ms) of the latest GPS_INT received before
/// it. Frames leave in the order they were queued, higher priorities first, and the UART
/// is not paced, so the queue is short: a frame of GPS_INT's priority or higher (STATUS,
/// PONG) was queued at that time or up to one GPS_INT period later.
struct LinkLoss {
    step: Step,
    /// The `tow` of the latest GPS_INT.
    tow: Option<u32>,
    /// The guest time of the latest PONG (the last frame the aircraft heard).
    pong_tow: Option<u32>,
    /// The guest time of the first ROTORCRAFT_STATUS reporting HOME.
    home_tow: Option<u32>,
    /// Every ROTORCRAFT_STATUS's `ap_mode`, with the step it came in.
    statuses: Vec<(Step, u8)>,
    /// The wall-clock time (s) at which each step ended, for the report.
    ended: Vec<(Step, f64)>,
}

impl LinkLoss {
    fn new() -> Self {
        Self {
            step: Step::Up,
            tow: None,
            pong_tow: None,
            home_tow: None,
            statuses: Vec::new(),
            ended: Vec::new(),
        }
    }

    fn advance(&mut self, now: f64) {
        self.ended.push((self.step, now));
        self.step = self.step.next();
    }

    /// Takes in one message from the aircraft, received at wall-clock time `now`.
    fn message(&mut self, (class, id): (u8, u8), payload: &[u8], now: f64) {
        let is = |class_id, msg_id| (class, id) == (class_id, msg_id);
        if is(GpsInt::CLASS_ID, GpsInt::ID) {
            self.tow = Some(GpsInt::decode(payload).expect("GPS_INT decodes").tow);
        } else if is(Pong::CLASS_ID, Pong::ID) {
            // A PONG still on its way when the test fell silent counts; those of step
            // Back do not (the link was lost before them).
            if matches!(self.step, Step::Up | Step::Silent) {
                self.pong_tow = self.tow;
            }
        } else if is(DlValue::CLASS_ID, DlValue::ID) {
            let v = DlValue::decode(payload).expect("DL_VALUE decodes");
            // The acknowledgement (the periodic DL_VALUE cannot report NAV before it).
            if self.step == Step::Setting && v.index == AP_MODE_INDEX && v.value == f32::from(NAV) {
                self.advance(now);
            }
        } else if is(RotorcraftStatus::CLASS_ID, RotorcraftStatus::ID) {
            let mode = RotorcraftStatus::decode(payload)
                .expect("ROTORCRAFT_STATUS decodes")
                .ap_mode;
            self.statuses.push((self.step, mode));
            match (self.step, mode) {
                (Step::Up, _) if self.pong_tow.is_some() => self.advance(now),
                (Step::Silent, HOME) => {
                    self.home_tow = self.tow;
                    self.advance(now);
                }
                (Step::Back, NAV) => self.advance(now),
                _ => {}
            }
        }
    }

    /// The `ap_mode` of every ROTORCRAFT_STATUS that came in `step`.
    fn modes(&self, step: Step) -> Vec<u8> {
        self.statuses
            .iter()
            .filter(|(s, _)| *s == step)
            .map(|&(_, mode)| mode)
            .collect()
    }
}

/// The period of message `M` in telemetry.xml's default mode, in ms.
fn default_period_ms<M: Message>() -> u32 {
    let mode = &SCHEDULE.processes[0].modes[0];
    let ticks = mode
        .messages
        .iter()
        .find(|m| m.is(M::CLASS_ID, M::ID))
        .map(|m| m.period_ticks.max(1))
        .unwrap_or_else(|| panic!("{} is in the default mode", M::NAME));
    ticks * 1000 / SCHEDULE.frequency_hz
}

/// The link-loss failsafe: with its link Up (the test PINGs it), the aircraft reports
/// NAV; once the test is silent for longer than the firmware's lost timeout, it reports
/// HOME, no earlier than the timeout after the last frame it heard (on the guest's
/// clock); it stays HOME until the SETTING `ap_mode` = NAV, which it acknowledges, and
/// then reports NAV again. Only the aircraft's reports are checked; the wall clock only
/// bounds the test against hangs.
#[test]
fn firmware_flies_home_when_the_link_is_lost_and_back_to_nav_on_the_setting() {
    flies_home_when_the_link_is_lost_and_back_to_nav_on_the_setting(MPS2_AN386);
}

/// [`firmware_flies_home_when_the_link_is_lost_and_back_to_nav_on_the_setting`] on the
/// Cortex-M0 without compare-and-swap.
#[test]
fn microbit_firmware_flies_home_when_the_link_is_lost_and_back_to_nav_on_the_setting() {
    flies_home_when_the_link_is_lost_and_back_to_nav_on_the_setting(MICROBIT);
}

/// The link-loss failsafe of the firmware of `board` (see
/// [`firmware_flies_home_when_the_link_is_lost_and_back_to_nav_on_the_setting`]).
fn flies_home_when_the_link_is_lost_and_back_to_nav_on_the_setting(board: Board) {
    let Some(mut serial) = boot(board, "aircraft", "link-loss") else {
        return;
    };
    let set = default_set();
    let (ping, _) = requests(&set);
    let nav = setting(&set, AP_MODE_INDEX, f32::from(NAV));
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut ground = LinkLoss::new();
    let mut next_send = 0.0;
    let mut buf = [0u8; 1024];
    let start = Instant::now();
    while ground.step != Step::Done && start.elapsed() < DEADLINE {
        let now = start.elapsed().as_secs_f64();
        // PINGs once the guest clock runs (a GPS_INT came).
        if ground.tow.is_some() && now >= next_send {
            match ground.step {
                Step::Up | Step::Back => {
                    serial.send(&ping, "send PING");
                    next_send = now + PING_EVERY;
                }
                Step::Setting => {
                    serial.send(&nav, "send SETTING ap_mode");
                    next_send = now + 1.0;
                }
                Step::Silent | Step::Done => {}
            }
        }
        let n = serial.receive(&mut buf);
        let now = start.elapsed().as_secs_f64();
        let mut input = &buf[..n];
        while let Some(frame) = decoder.feed(&mut input) {
            assert_eq!(frame.source(), AC_ID, "frame from another aircraft");
            let step = ground.step;
            ground.message((frame.class(), frame.msg_id()), frame.payload(), now);
            if ground.step != step {
                // The next step's first request goes at once.
                next_send = now;
            }
        }
    }
    let wall = start.elapsed().as_secs_f64();
    assert_eq!(
        ground.step,
        Step::Done,
        "in {wall:.1} s, stuck in step {:?}; ap_mode of every ROTORCRAFT_STATUS: {:?}",
        ground.step,
        ground.statuses
    );

    // Before the ground was heard, and while it was, NAV; HOME only once the link was
    // lost, and kept until the SETTING.
    let (up, silent, setting) = (
        ground.modes(Step::Up),
        ground.modes(Step::Silent),
        ground.modes(Step::Setting),
    );
    assert!(up.iter().all(|&m| m == NAV), "link up: ap_mode {up:?}");
    assert!(
        matches!(silent.split_last(), Some((&HOME, before)) if before.iter().all(|&m| m == NAV)),
        "silent: ap_mode {silent:?}"
    );
    assert!(
        setting.iter().all(|&m| m == HOME),
        "until the SETTING: ap_mode {setting:?}"
    );
    // After the acknowledgement, NAV: a ROTORCRAFT_STATUS queued just before the SETTING
    // came may still leave after the acknowledgement (a reply, queued ahead), no more.
    let back = ground.modes(Step::Back);
    let late_home = |before: &[u8]| before.len() <= 1 && before.iter().all(|&m| m == HOME);
    assert!(
        matches!(back.split_last(), Some((&NAV, before)) if late_home(before)),
        "after the SETTING: ap_mode {back:?}"
    );

    // On the guest's clock, HOME came after the lost timeout, within a ROTORCRAFT_STATUS
    // period of it. Each stamp is up to a GPS_INT period early; a scheduler tick of slack.
    let (Some(pong_tow), Some(home_tow)) = (ground.pong_tow, ground.home_tow) else {
        panic!("no GPS_INT before the PONG or the HOME report");
    };
    let silence = home_tow.saturating_sub(pong_tow);
    let gps = default_period_ms::<GpsInt>();
    let status = default_period_ms::<RotorcraftStatus>();
    let slack = 1000 / SCHEDULE.frequency_hz + 1;
    assert!(
        silence + gps + slack >= LOST_AFTER_MS,
        "HOME {silence} ms (guest clock) after the last PONG, before the lost timeout of \
         {LOST_AFTER_MS} ms"
    );
    assert!(
        silence <= LOST_AFTER_MS + status + gps + slack,
        "HOME {silence} ms (guest clock) after the last PONG, long after the lost timeout \
         of {LOST_AFTER_MS} ms"
    );
    let ended: Vec<String> = ground
        .ended
        .iter()
        .map(|(step, t)| format!("{step:?} {t:.2} s"))
        .collect();
    let _ = writeln!(
        std::io::stderr(),
        "qemu {} link loss: HOME {silence} ms of guest time after the last PONG (lost after \
         {LOST_AFTER_MS} ms); ap_mode up {up:?}, silent {silent:?}, until the SETTING \
         {setting:?}, after it {back:?}; steps ended (wall clock): {}; {wall:.1} s in all",
        board.machine,
        ended.join(", ")
    );
}

/// The example application's store flag (setting 4, `settings_store_flag`).
const STORE_FLAG_INDEX: u8 = 4;
/// The gain the persistence test stores.
const STORED_GAIN: f32 = 4.5;

/// A file for the machine's PSRAM (16 MiB, QEMU's required size), filled with `0xFF`
/// (erased flash) and unique to the process and the test; removed when dropped.
struct PsramFile(PathBuf);

impl PsramFile {
    fn new(test: &str) -> Self {
        let path =
            std::env::temp_dir().join(format!("pprz-qemu-{}-{test}.psram", std::process::id()));
        std::fs::write(&path, vec![0xFF_u8; 16 << 20]).expect("the PSRAM file is written");
        Self(path)
    }

    /// Whether the guest wrote to the settings flash (its first 48 KiB).
    fn written(&self) -> bool {
        let bytes = std::fs::read(&self.0).expect("the PSRAM file reads");
        bytes[..48 << 10].iter().any(|&b| b != 0xFF)
    }
}

impl Drop for PsramFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The ground's side of a QEMU session: every DL_VALUE received (index, value), and
/// whether the guest sent anything yet.
struct Values {
    decoder: Decoder<PprzV2>,
    values: Vec<(u8, f32)>,
    talked: bool,
}

impl Values {
    fn new() -> Self {
        Self {
            decoder: Decoder::new(PprzV2::new()),
            values: Vec::new(),
            talked: false,
        }
    }

    /// Reads what the guest sent (up to the read timeout) and takes in its DL_VALUEs.
    fn pump(&mut self, serial: &mut Serial) {
        let mut buf = [0u8; 1024];
        let n = serial.receive(&mut buf);
        let mut input = &buf[..n];
        while let Some(frame) = self.decoder.feed(&mut input) {
            self.talked = true;
            if (frame.class(), frame.msg_id()) == (DlValue::CLASS_ID, DlValue::ID) {
                let v = DlValue::decode(frame.payload()).expect("DL_VALUE decodes");
                self.values.push((v.index, v.value));
            }
        }
    }

    /// The values of setting `index` received from the `from`th DL_VALUE on.
    fn of(&self, index: u8, from: usize) -> Vec<f32> {
        self.values[from..]
            .iter()
            .filter(|(i, _)| *i == index)
            .map(|&(_, v)| v)
            .collect()
    }
}

/// First boot of the persistence test: SETTING gain = [`STORED_GAIN`] until
/// acknowledged, then SETTING store flag = 1, once; returns when the flag's
/// acknowledgement and the store task's DL_VALUE (both 1: stored) have come.
fn set_and_store(serial: &mut Serial, set: &RuntimeSet) -> Values {
    let gain = setting(set, GAIN_INDEX, STORED_GAIN);
    let store = setting(set, STORE_FLAG_INDEX, 1.0);
    let mut ground = Values::new();
    let mut store_from: Option<usize> = None;
    let mut next = 0.0;
    let start = Instant::now();
    while start.elapsed() < DEADLINE {
        ground.pump(serial);
        let now = start.elapsed().as_secs_f64();
        match store_from {
            None if ground.of(GAIN_INDEX, 0).contains(&STORED_GAIN) => {
                serial.send(&store, "send SETTING store flag");
                store_from = Some(ground.values.len());
            }
            None if ground.talked && now >= next => {
                serial.send(&gain, "send SETTING gain");
                next = now + 1.0;
            }
            Some(from) if ground.of(STORE_FLAG_INDEX, from).len() >= 2 => break,
            _ => {}
        }
    }
    let flags = store_from.map(|from| ground.of(STORE_FLAG_INDEX, from));
    assert_eq!(
        flags.as_deref(),
        Some(&[1.0, 1.0][..]),
        "the store flag's DL_VALUEs after the SETTING (acknowledgement, then stored); \
         every DL_VALUE: {:?}",
        ground.values
    );
    ground
}

/// The persistent settings in the emulated flash: the gain set and stored (the store
/// flag's DL_VALUE says 1 once stored) is, after QEMU is killed and started again on
/// the same PSRAM file, the gain the firmware starts with: GET_SETTING answers it, and
/// so does every DL_VALUE of the gain.
#[test]
fn firmware_keeps_the_stored_gain_across_a_restart() {
    let psram = PsramFile::new("persist");
    let Some(mut serial) = boot_with(MPS2_AN386, "aircraft", "persist", Some(&psram.0)) else {
        return;
    };
    let set = default_set();
    let start = Instant::now();
    let first = set_and_store(&mut serial, &set);
    let stored_after = start.elapsed().as_secs_f64();
    // Killed: what the guest wrote is in the file (a shared mapping).
    drop(serial);
    assert!(psram.written(), "nothing in the settings flash");

    let mut serial = boot_with(MPS2_AN386, "aircraft", "persist-again", Some(&psram.0))
        .expect("QEMU booted once already");
    let get = uplink::frame(
        &set,
        AnyTransport::from(PprzV2::new()),
        AC_ID,
        "GET_SETTING",
        &[
            ("index", f64::from(GAIN_INDEX)),
            ("ac_id", f64::from(AC_ID)),
        ],
    )
    .expect("GET_SETTING frame");
    let mut ground = Values::new();
    let mut next = 0.0;
    let restart = Instant::now();
    while restart.elapsed() < DEADLINE && ground.of(GAIN_INDEX, 0).is_empty() {
        let now = restart.elapsed().as_secs_f64();
        if ground.talked && now >= next {
            serial.send(&get, "send GET_SETTING");
            next = now + 1.0;
        }
        ground.pump(&mut serial);
    }
    let gains = ground.of(GAIN_INDEX, 0);
    assert_eq!(
        gains.first(),
        Some(&STORED_GAIN),
        "the gain after the restart; every DL_VALUE: {:?}",
        ground.values
    );
    assert!(gains.iter().all(|&g| g == STORED_GAIN), "{gains:?}");
    let _ = writeln!(
        std::io::stderr(),
        "qemu persistence: gain {STORED_GAIN} stored after {stored_after:.1} s ({} DL_VALUEs); \
         after the restart, read back in {:.1} s",
        first.values.len(),
        restart.elapsed().as_secs_f64()
    );
}
