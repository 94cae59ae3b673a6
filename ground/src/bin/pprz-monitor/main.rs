//! `pprz-monitor`: watch one or several Paparazzi-compatible aircraft live, from UDP,
//! TCP, a serial port, a file or standard input, or a whole fleet from a
//! `pprz-gateway` on the Zenoh bus, with any `messages.xml`.
//!
//! Exit status: 0 after a complete run (end of input, `--duration`, Ctrl-C), 1 when
//! the input, the output or the recording failed, 2 for invalid options (an unusable
//! `--secure` key file, a settings file with errors, a `--setting` refused included).

use std::fs::File;
use std::io::{BufWriter, ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

mod bus;
mod record;

use pprz_ground::cli::{Args, SettingValue};
use pprz_ground::device::{self, Source, Uplink as UplinkSink};
use pprz_ground::escape;
use pprz_ground::input::{Drops, End, InputQueue, Overflow, Pop};
use pprz_ground::monitor::{Decoded, IDLE_FLUSH, MAX_EVENTS, Monitor, Notice};
use pprz_ground::secure::GroundSecure;
use pprz_ground::set::RuntimeSet;
use pprz_ground::settings::{SettingsTable, SweepConfig};
use pprz_ground::uplink;
use pprz_ground::viewer::{self, Viewer};
use pprz_transports::AnyTransport;
use record::{FileId, Recorder};

/// The identities of the input files (which the recording must not overwrite), each
/// with a description.
type Inputs = Vec<(FileId, String)>;

/// Opens the input (with `--zenoh`, a session on the bus whose commands are built
/// with `set`); returns it, the uplink, and the input files.
fn open_input(args: &Args, set: RuntimeSet) -> Result<(Source, UplinkSink, Inputs), String> {
    let mut inputs = Vec::new();
    if let Ok(id) = FileId::of_path(&args.link.messages) {
        inputs.push((
            id,
            format!("the messages file {}", args.link.messages.display()),
        ));
    }
    match (&args.link.serial, &args.link.file) {
        (Some(device), _) => {
            if let Ok(id) = FileId::of_path(Path::new(device)) {
                inputs.push((id, format!("the serial port {device}")));
            }
        }
        (None, Some(path)) => {
            let file = device::open_file(path)?;
            let id = FileId::of_file(path, &file)
                .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
            inputs.push((id, format!("the --file input {}", path.display())));
        }
        (None, None) if args.zenoh.is_none() && (!args.link.given() || args.link.stdin) => {
            if let Some(id) = FileId::of_stdin() {
                inputs.push((id, "the file standard input reads".to_owned()));
            }
        }
        _ => {}
    }
    let (source, sink) = match &args.zenoh {
        Some(endpoint) => bus::open(endpoint, set)?,
        None => args.link.endpoint().open()?,
    };
    Ok((source, sink, inputs))
}

/// Where decoded messages go: standard output (`--lines`) and the recording. Keeps
/// the first error of each.
struct Output {
    lines: bool,
    stdout: BufWriter<std::io::Stdout>,
    stdout_error: Option<std::io::Error>,
    recorder: Option<Recorder<BufWriter<File>>>,
    record_path: Option<PathBuf>,
    record_error: Option<String>,
    /// `--foxglove` and `--mcap`.
    viewer: Option<Viewer>,
    /// The first error of the viewer's recording.
    viewer_error: Option<String>,
    /// The start of the run, in nanoseconds since the Unix epoch.
    epoch_ns: u64,
    /// The time of the latest message for the viewer, in nanoseconds.
    last_ns: u64,
}

impl Output {
    fn message(&mut self, now: f64, m: &Decoded<'_>) {
        if self.lines
            && self.stdout_error.is_none()
            && let Err(e) = writeln!(self.stdout, "{}", m.line)
        {
            self.stdout_error = Some(e);
        }
        if let Some(r) = self.recorder.as_mut()
            && self.record_error.is_none()
            && let Err(e) = r.record(now, m.raw)
        {
            self.record_error = Some(self.record_failure(&e));
        }
        if let Some(v) = self.viewer.as_mut() {
            // PPRZLOG time stamps when replaying a log, else the reception time.
            let ns = match m.log_time {
                Some(t) => u64::try_from(t.as_nanos()).unwrap_or(u64::MAX),
                None => self.epoch_ns.saturating_add((now * 1e9) as u64),
            };
            self.last_ns = ns;
            v.message(ns, m);
        }
    }

    /// Publishes the link statistics and closes the recording's chunk (every second).
    fn viewer_tick(&mut self, monitor: &Monitor, now: f64, live: bool) {
        let ns = if live {
            self.epoch_ns.saturating_add((now * 1e9) as u64)
        } else {
            self.last_ns
        };
        if let Some(v) = self.viewer.as_mut() {
            v.link_stats(ns, monitor, now, |_| None);
            if self.viewer_error.is_none()
                && let Err(e) = v.flush()
            {
                self.viewer_error = Some(e.to_string());
            }
        }
    }

    fn record_failure(&self, e: &dyn std::fmt::Display) -> String {
        let path = self.record_path.as_deref().unwrap_or(Path::new("?"));
        format!("recording to {} failed: {e}", path.display())
    }

    fn flush_stdout(&mut self) {
        if self.stdout_error.is_none()
            && let Err(e) = self.stdout.flush()
        {
            self.stdout_error = Some(e);
        }
    }

    /// Whether the run must stop: the output or the recording failed.
    fn failed(&self) -> bool {
        self.stdout_error.is_some() || self.record_error.is_some() || self.viewer_error.is_some()
    }

    /// Writes the table view.
    fn screen(&mut self, text: &str) {
        if self.stdout_error.is_none()
            && let Err(e) =
                write!(self.stdout, "\x1b[2J\x1b[H{text}").and_then(|()| self.stdout.flush())
        {
            self.stdout_error = Some(e);
        }
    }
}

/// In `--lines` mode (where standard output carries only messages), writes the events
/// and notices that arrived since the last call to standard error (named after their
/// aircraft when there are several); `seen` counts those already written. Input dropped
/// is reported by the rate-limited overload warning.
fn report_new(monitor: &Monitor, seen: &mut (u64, u64)) {
    let new_events = (monitor.event_count() - seen.0).min(MAX_EVENTS as u64) as usize;
    let events: Vec<_> = monitor.events_with_aircraft().collect();
    for (t, ac, e) in &events[events.len().saturating_sub(new_events)..] {
        eprintln!("[{t:7.1}s] {}", monitor.event_line(*ac, e));
    }
    let new_notices = (monitor.notice_count() - seen.1).min(MAX_EVENTS as u64) as usize;
    let notices: Vec<_> = monitor.notices_with_aircraft().collect();
    for (t, ac, n) in &notices[notices.len().saturating_sub(new_notices)..] {
        if !matches!(n, Notice::InputDropped(_)) {
            eprintln!("[{t:7.1}s] {}", monitor.notice_line(*ac, n));
        }
    }
    *seen = (monitor.event_count(), monitor.notice_count());
}

/// Seconds between two reports of the secure link's counters in `--lines` mode (a
/// change of state is reported at once).
const SECURE_REPORT_PERIOD: f64 = 5.0;

/// In `--lines` mode, writes the secure link's status to standard error when its state
/// changes, and its counters every [`SECURE_REPORT_PERIOD`] when they changed.
#[derive(Default)]
struct SecureReport {
    last: Option<(pprz_secure::InitiatorState, [String; 2])>,
    next: f64,
}

impl SecureReport {
    fn update(&mut self, monitor: &Monitor, t: f64) {
        let Some(status) = monitor.secure_status() else {
            return;
        };
        let lines = status.lines();
        let (changed_state, changed) = match &self.last {
            Some((state, last)) => (*state != status.state, *last != lines),
            None => (true, true),
        };
        if changed_state || (changed && t >= self.next) {
            for line in &lines {
                eprintln!("[{t:7.1}s] {line}");
            }
            self.last = Some((status.state, lines));
            self.next = t + SECURE_REPORT_PERIOD;
        }
    }
}

/// Builds uplink message `name`, seals it on a secure link, and writes it; `false`
/// (reported on standard error) if it was not sent.
fn send(
    monitor: &mut Monitor,
    sink: &mut UplinkSink,
    transport: AnyTransport,
    ac_id: u8,
    name: &str,
    values: &[(&str, f64)],
) -> bool {
    let frame = match uplink::frame(monitor.set(), transport, ac_id, name, values) {
        Ok(frame) => frame,
        Err(e) => {
            eprintln!("cannot build {name}: {}", escape::lines(&e.to_string()));
            return false;
        }
    };
    let frame = match monitor.seal_uplink(&frame) {
        Ok(frame) => frame,
        Err(e) => {
            eprintln!("cannot send {name}: {e}");
            return false;
        }
    };
    match sink.send(&frame) {
        Ok(()) => true,
        Err(e) => {
            eprintln!("cannot send {name}: {}", escape::lines(&e.to_string()));
            false
        }
    }
}

/// Writes the secure link's handshake frames due at `t`.
fn send_secure(monitor: &mut Monitor, sink: &mut UplinkSink, t: f64) {
    for frame in monitor.poll_secure(t) {
        if let Err(e) = sink.send(&frame) {
            eprintln!(
                "cannot send the key exchange: {}",
                escape::lines(&e.to_string())
            );
        }
    }
}

/// Opens `--mcap` (after checking it is no input) and starts `--foxglove`, naming the
/// settings after `table`.
fn open_viewer(
    args: &Args,
    inputs: &Inputs,
    uplink: bool,
    table: Option<&Arc<SettingsTable>>,
) -> Result<Option<Viewer>, String> {
    if args.mcap.is_none() && args.foxglove.is_none() {
        return Ok(None);
    }
    let mut viewer = Viewer::new().max_clients(args.foxglove_clients);
    if let Some(table) = table {
        viewer = viewer.settings_table(table.clone());
    }
    if let Some(path) = &args.mcap {
        let file = record::open_recording(path, inputs).map_err(|e| e.to_string())?;
        viewer
            .record(file, &path.display().to_string())
            .map_err(|e| e.to_string())?;
    }
    if let Some(addr) = args.foxglove {
        let bound = viewer
            .serve(addr, "pprz-monitor", uplink)
            .map_err(|e| e.to_string())?;
        eprintln!("foxglove: serving ws://{bound}");
    }
    Ok(Some(viewer))
}

/// What the options give once checked: the settings files' table (its warnings
/// printed) and the `--setting`s resolved against it.
struct Prepared {
    table: Option<Arc<SettingsTable>>,
    settings: Vec<SettingValue>,
}

/// Reads `--settings` and resolves `--setting`, before anything is sent; the error lines
/// to print otherwise (exit status 2).
fn prepare(args: &Args) -> Result<Prepared, String> {
    let table = if args.settings_files.is_empty() {
        None
    } else {
        // The diagnostics escape the text they quote (their `Display`): printed as
        // they are, not escaped twice.
        let table = SettingsTable::load(&args.settings_files).map_err(|e| {
            let lines: Vec<String> = e
                .diagnostics()
                .iter()
                .map(|d| format!("error: {d}"))
                .collect();
            lines.join("\n")
        })?;
        for w in table.warnings() {
            eprintln!("warning: {w}");
        }
        Some(Arc::new(table))
    };
    let settings = args
        .setting
        .iter()
        .map(|s| s.resolve(table.as_deref()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| format!("error: {e}"))?;
    Ok(Prepared { table, settings })
}

fn main() -> ExitCode {
    let args: Args = pprz_codegen::cli::parse();
    if let Err(e) = args.check() {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    let prepared = match prepare(&args) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let secure = match (&args.secure, args.aircraft().as_slice()) {
        (None, _) => None,
        // `check` made sure there is one aircraft.
        (Some(path), &[ac_id, ..]) => match GroundSecure::from_key_file(path, ac_id) {
            Ok(s) => Some(s),
            Err(e) => {
                eprintln!("error: --secure: {}", escape::lines(&e.to_string()));
                return ExitCode::from(2);
            }
        },
        (Some(_), []) => {
            eprintln!("error: --secure needs an --ac-id");
            return ExitCode::from(2);
        }
    };
    let set = match load_set(&args.link.messages) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    match run(&args, set, secure, prepared) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", escape::lines(&e));
            ExitCode::FAILURE
        }
    }
}

fn run(
    args: &Args,
    set: RuntimeSet,
    secure: Option<GroundSecure>,
    prepared: Prepared,
) -> Result<(), String> {
    let transport: AnyTransport = args.link.transport.any();
    let (source, uplink_sink, mut inputs) = open_input(args, set)?;
    let recorder = open_recorder(args, &mut inputs, transport)?;
    let has_uplink = !matches!(uplink_sink, UplinkSink::None);
    let viewer = open_viewer(args, &inputs, has_uplink, prepared.table.as_ref())?;
    let queue = source.start();
    let stop = pprz_ground::cli::stop_on_ctrl_c();
    let live = queue.overflow() == Overflow::DropOldest;
    let mut monitor = Monitor::new(set, transport)
        .with_stale_after(args.stale_after)
        .map_err(|e| e.to_string())?;
    if !live {
        // A file or standard input: a recording, whose PINGs another station sent.
        monitor = monitor.replaying();
    }
    if let Some(secure) = secure {
        monitor = monitor.with_secure(secure).map_err(|e| e.to_string())?;
    }
    if let Some(table) = &prepared.table {
        monitor = monitor.with_settings(table.clone());
        if args.read_settings {
            for ac_id in args.aircraft() {
                monitor.read_settings(ac_id, table.len(), SweepConfig::default());
            }
        }
    }
    let out = Output {
        lines: args.lines,
        stdout: BufWriter::new(std::io::stdout()),
        stdout_error: None,
        recorder,
        record_path: args.record.clone(),
        record_error: None,
        viewer,
        viewer_error: None,
        epoch_ns: viewer::unix_ns(),
        last_ns: 0,
    };
    let mut run = Run::new(args, monitor, out, uplink_sink, transport, live);
    run.settings = prepared.settings;
    while !stop.load(Ordering::SeqCst) && !run.out.failed() {
        let t = run.now();
        if args.duration.is_some_and(|d| t >= d) {
            break;
        }
        run.send_requests(t);
        if !run.read_input(&queue) {
            break;
        }
        run.refresh_output();
    }
    run.finish(queue)
}

/// Reads the message set; a failure is one line per problem, with the hint to give
/// `--messages` (the diagnostics escape the text they quote: printed as they are).
fn load_set(path: &Path) -> Result<RuntimeSet, String> {
    RuntimeSet::load(path).map_err(|e| {
        let problems: Vec<String> = e.diagnostics().iter().map(ToString::to_string).collect();
        format!(
            "{} (give the messages.xml of the aircraft with --messages)",
            problems.join("\n")
        )
    })
}

/// Opens `--record` (and empties it) only after checking it is no input, which it
/// becomes.
fn open_recorder(
    args: &Args,
    inputs: &mut Inputs,
    transport: AnyTransport,
) -> Result<Option<Recorder<BufWriter<File>>>, String> {
    let Some(path) = &args.record else {
        return Ok(None);
    };
    let file = record::open_recording(path, inputs).map_err(|e| e.to_string())?;
    if let Ok(id) = FileId::of_file(path, &file) {
        inputs.push((id, format!("the --record file {}", path.display())));
    }
    Ok(Some(Recorder::new(BufWriter::new(file), transport)))
}

/// A run of the monitor: its state, its outputs, and when each periodic task is due.
struct Run<'a> {
    args: &'a Args,
    monitor: Monitor,
    out: Output,
    uplink: UplinkSink,
    transport: AnyTransport,
    aircraft: Vec<u8>,
    /// A live link (not a file or standard input).
    live: bool,
    start: Instant,
    /// `--setting`, resolved.
    settings: Vec<SettingValue>,
    /// The SETTINGs go at start, or once the secure session is up.
    settings_pending: bool,
    /// `--read-settings` in `--lines` mode: when the progress is next written, and the
    /// settings read per aircraft when it was last written.
    next_sweep_report: f64,
    sweep_reported: std::collections::BTreeMap<u8, usize>,
    secure_report: SecureReport,
    next_ping: Option<f64>,
    next_render: f64,
    next_flush: f64,
    next_drop_warning: f64,
    next_viewer: f64,
    input_error: Option<String>,
    last_data: Option<f64>,
    /// Events and notices already reported (`--lines`).
    seen: (u64, u64),
}

impl<'a> Run<'a> {
    fn new(
        args: &'a Args,
        monitor: Monitor,
        out: Output,
        uplink: UplinkSink,
        transport: AnyTransport,
        live: bool,
    ) -> Self {
        Self {
            args,
            monitor,
            out,
            uplink,
            transport,
            aircraft: args.aircraft(),
            live,
            start: Instant::now(),
            settings: Vec::new(),
            settings_pending: true,
            next_sweep_report: 0.0,
            sweep_reported: std::collections::BTreeMap::new(),
            secure_report: SecureReport::default(),
            next_ping: args.ping.map(|_| 0.0),
            next_render: 0.0,
            next_flush: 0.0,
            next_drop_warning: 0.0,
            next_viewer: 1.0,
            input_error: None,
            last_data: None,
            seen: (0, 0),
        }
    }

    /// Seconds since the start of the run.
    fn now(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// Sends what is due at `t`: the secure link's handshake, `--setting`, the settings
    /// requested from the viewer, `--ping`.
    fn send_requests(&mut self, t: f64) {
        self.monitor.tick(t);
        send_secure(&mut self.monitor, &mut self.uplink, t);
        if self.args.lines {
            self.secure_report.update(&self.monitor, t);
        }
        if self.settings_pending && self.monitor.uplink_ready() {
            self.settings_pending = false;
            self.send_settings();
        }
        self.send_viewer_requests(t);
        self.send_pings(t);
        if self.monitor.uplink_ready() {
            self.send_sweeps(t);
        }
    }

    /// Sends the GET_SETTINGs of `--read-settings` due at `t`, and in `--lines` mode
    /// writes the progress (at most once a second, when it changed).
    fn send_sweeps(&mut self, t: f64) {
        for (ac_id, index) in self.monitor.sweep_requests(t) {
            let values = [("index", f64::from(index)), ("ac_id", f64::from(ac_id))];
            let (monitor, sink) = (&mut self.monitor, &mut self.uplink);
            if send(monitor, sink, self.transport, ac_id, "GET_SETTING", &values) {
                monitor.get_setting_sent(Some(ac_id), t, index);
            }
        }
        if !self.args.lines || t < self.next_sweep_report {
            return;
        }
        self.next_sweep_report = t + 1.0;
        let several = self.aircraft.len() > 1;
        for &ac_id in &self.aircraft {
            let Some(sweep) = self.monitor.aircraft_state(ac_id).and_then(|a| a.sweep()) else {
                continue;
            };
            let last = self.sweep_reported.insert(ac_id, sweep.read());
            if sweep.done() || last == Some(sweep.read()) {
                continue;
            }
            let about = if several {
                format!("aircraft {ac_id}: ")
            } else {
                String::new()
            };
            let line = sweep.line(self.monitor.settings_table());
            eprintln!("[{t:7.1}s] {about}{line}");
        }
    }

    /// Sends `--setting` to every aircraft.
    fn send_settings(&mut self) {
        for &ac_id in &self.aircraft {
            for &SettingValue { index, value } in &self.settings {
                let values = [
                    ("index", f64::from(index)),
                    ("ac_id", f64::from(ac_id)),
                    ("value", f64::from(value)),
                ];
                let (monitor, sink) = (&mut self.monitor, &mut self.uplink);
                if send(monitor, sink, self.transport, ac_id, "SETTING", &values) {
                    let now = self.start.elapsed().as_secs_f64();
                    monitor.setting_sent(Some(ac_id), now, index, f64::from(value));
                }
            }
        }
    }

    /// Sends the settings read and written from the viewer.
    fn send_viewer_requests(&mut self, t: f64) {
        let requests = match self.out.viewer.as_mut() {
            Some(v) => v.setting_requests(t),
            None => Vec::new(),
        };
        for request in requests {
            let why = if self.monitor.uplink_ready() {
                let (name, values) = request.message();
                let (monitor, sink) = (&mut self.monitor, &mut self.uplink);
                if send(
                    monitor,
                    sink,
                    self.transport,
                    request.ac_id(),
                    name,
                    &values,
                ) {
                    request.sent(monitor, self.start.elapsed().as_secs_f64());
                    continue;
                }
                "the uplink failed (see the monitor's messages)"
            } else {
                "no secure session yet"
            };
            if let Some(v) = self.out.viewer.as_mut() {
                v.setting_not_sent(&request, why);
            }
        }
    }

    /// Sends a PING to every aircraft when one is due at `t`.
    fn send_pings(&mut self, t: f64) {
        let (Some(period), Some(at)) = (self.args.ping, self.next_ping) else {
            return;
        };
        if t < at {
            return;
        }
        // On a secure link, no PING before the session is up.
        if self.monitor.uplink_ready() {
            for &ac_id in &self.aircraft {
                let (monitor, sink) = (&mut self.monitor, &mut self.uplink);
                if send(monitor, sink, self.transport, ac_id, "PING", &[]) {
                    monitor.ping_sent(Some(ac_id), self.start.elapsed().as_secs_f64());
                }
            }
        }
        // After a stall, the next PING is one period from now, not a burst.
        let next = at + period;
        self.next_ping = Some(if next > t { next } else { t + period });
    }

    /// Decodes what the input gives within 50 ms; `false` at its end.
    fn read_input(&mut self, queue: &InputQueue) -> bool {
        match queue.pop(Duration::from_millis(50)) {
            Pop::Data {
                bytes,
                dropped_before,
            } => {
                let t = self.now();
                if !dropped_before.is_empty() {
                    self.warn_dropped(t, dropped_before);
                    let out = &mut self.out;
                    self.monitor
                        .input_gap(t, dropped_before, |m| out.message(t, m));
                }
                let out = &mut self.out;
                self.monitor.feed(t, &bytes, |m| out.message(t, m));
                self.last_data = Some(t);
            }
            Pop::Idle => {
                // A silent link: decode the frames held behind a false start.
                let t = self.now();
                if self.live && self.last_data.is_some_and(|at| t - at >= IDLE_FLUSH) {
                    let out = &mut self.out;
                    self.monitor.flush(t, |m| out.message(t, m));
                    self.last_data = None;
                }
            }
            Pop::End(End::Eof) => return false,
            Pop::End(End::Error(e)) => {
                self.input_error = Some(e);
                return false;
            }
        }
        true
    }

    /// In `--lines` mode, warns of input dropped under overload (once a second).
    fn warn_dropped(&mut self, t: f64, dropped: Drops) {
        if self.args.lines && t >= self.next_drop_warning {
            let d = self.monitor.input_dropped();
            eprintln!(
                "warning: input overload at t={t:.1}s: dropped {} bytes in {} reads so far",
                d.bytes + dropped.bytes,
                d.reads + dropped.reads
            );
            self.next_drop_warning = t + 1.0;
        }
    }

    /// Reports events, flushes the lines, redraws the table, feeds the viewer, each
    /// when due.
    fn refresh_output(&mut self) {
        if self.args.lines {
            report_new(&self.monitor, &mut self.seen);
            self.secure_report.update(&self.monitor, self.now());
        }
        let t = self.now();
        if self.args.lines && (self.live || t >= self.next_flush) {
            self.out.flush_stdout();
            self.next_flush = t + 0.1;
        }
        if !self.args.lines && t >= self.next_render {
            self.out.screen(&self.monitor.render(t));
            self.next_render = t + 0.5;
        }
        if t >= self.next_viewer {
            self.out.viewer_tick(&self.monitor, t, self.live);
            self.next_viewer = t + 1.0;
        }
    }

    /// Ends the run: decodes what was read, writes the last view, closes the recordings
    /// and prints the summary; the errors of the run, one a line.
    fn finish(mut self, queue: InputQueue) -> Result<(), String> {
        // Input read but not decoded (a run stopped by --duration or Ctrl-C, or by an
        // error) counts as dropped too.
        let t = self.now();
        let lost = queue.close();
        let out = &mut self.out;
        self.monitor.input_gap(t, lost, |m| out.message(t, m));
        if !self.out.failed() {
            let out = &mut self.out;
            self.monitor.flush(t, |m| out.message(t, m));
        }
        self.monitor.tick(t);
        if self.args.lines {
            report_new(&self.monitor, &mut self.seen);
        } else {
            self.out.screen(&self.monitor.render(t));
        }
        self.out.flush_stdout();
        let mut errors = Vec::new();
        if let Some(e) = self.input_error.take() {
            errors.push(format!("input error: {e}"));
        }
        errors.extend(self.finish_recording());
        errors.extend(self.finish_viewer(t));
        match self.out.stdout_error.take() {
            Some(e) if e.kind() == ErrorKind::BrokenPipe => {} // the reader has seen enough
            Some(e) => errors.push(format!("cannot write the output: {e}")),
            None => {}
        }
        eprintln!("{}", self.monitor.summary(t));
        if errors.is_empty() {
            Ok(())
        } else {
            Err(errors.join("\n"))
        }
    }

    /// Closes `--record`; its error, if any.
    fn finish_recording(&mut self) -> Option<String> {
        let out = &mut self.out;
        if let Some(r) = out.recorder.take() {
            let records = r.records();
            match r.finish() {
                Ok(_) if out.record_error.is_none() => {
                    if let Some(path) = &self.args.record {
                        eprintln!("recorded {records} frames to {}", path.display());
                    }
                }
                Ok(_) => {}
                Err(e) => {
                    if out.record_error.is_none() {
                        out.record_error = Some(out.record_failure(&e));
                    }
                }
            }
        }
        out.record_error.take()
    }

    /// Publishes the last statistics and closes `--mcap` and `--foxglove`; the error,
    /// if any.
    fn finish_viewer(&mut self, t: f64) -> Option<String> {
        if self.out.viewer.is_some() {
            self.out.viewer_tick(&self.monitor, t, self.live);
        }
        if let Some(v) = self.out.viewer.take() {
            let c = v.counts();
            eprintln!("{c}");
            match v.finish() {
                Ok(_) => {
                    if let Some(path) = &self.args.mcap
                        && self.out.viewer_error.is_none()
                    {
                        eprintln!("recorded {} messages to {}", c.messages, path.display());
                    }
                }
                Err(e) => {
                    self.out.viewer_error.get_or_insert(e.to_string());
                }
            }
        }
        self.out.viewer_error.take()
    }
}
