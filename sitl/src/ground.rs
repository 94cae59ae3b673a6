//! The ground station in this process (without `--headless`): it listens for the
//! telemetry on UDP, decodes it live, runs the key exchange of `--secure`, PINGs every
//! aircraft (its PINGs keep their uplink alive), changes a setting at 3 s, sets
//! `ap_mode` back to NAV at `--resume-nav`, sends the SETTINGs of `--setting` at their
//! times, serves `--foxglove`, and shows the live table or one line per message, the
//! settings named after `--settings`. Its clock is the simulation's (the aircraft's).

use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration as StdDuration, Instant as StdInstant};

use embassy_time::Instant;
use pprz_default::messages::datalink::Ping;
use pprz_example_app::AC_ID;
use pprz_ground::escape;
use pprz_ground::monitor::Monitor;
use pprz_ground::secure::GroundSecure;
use pprz_ground::set::RuntimeSet;
use pprz_ground::settings::SettingsTable;
use pprz_ground::uplink;
use pprz_ground::viewer::{LevelFigures, Viewer, unix_ns};
use pprz_messages::Message;
use pprz_secure::GroundKeys;
use pprz_telemetry::pprz_transports::{AnyTransport, Framing, PprzV2};

use crate::fleet::{self, SECOND_AC_ID};
use crate::options::{Args, TimedSetting};
use crate::{link, persist, record};

/// Simulated seconds between two views of the live table at `--speed 1` or slower (at
/// higher speeds, that many wall-clock seconds). The first view waits as long: a byte
/// rate over the first milliseconds of a run would mean nothing.
const RENDER_PERIOD_S: f64 = 0.5;

/// Simulated time at which the ground changes a setting of every aircraft.
const SETTING_AT_S: f64 = 3.0;

/// The setting changed: index 2 is the example application's `gain`, set to 2.5.
const SETTING: (u8, f64) = (2, 2.5);

/// What the ground opens before the aircraft starts: its UDP socket (so no telemetry is
/// missed), the message set it decodes with and the settings files' table.
pub struct Station {
    socket: UdpSocket,
    set: RuntimeSet,
    table: Option<Arc<SettingsTable>>,
}

impl Station {
    /// Listens on `--ground`, loads `--messages` and the settings files (printing their
    /// warnings); fails with the message to print.
    pub fn open(args: &Args) -> Result<Self, String> {
        let table = load_settings(args)?;
        let socket = UdpSocket::bind(args.ground).map_err(|e| {
            format!(
                "cannot listen on {} ({e}); is another ground station running? Use --ground/--uplink or --headless",
                args.ground
            )
        })?;
        let set = RuntimeSet::load(&args.messages).map_err(|e| e.to_string())?;
        Ok(Self { socket, set, table })
    }

    /// The monitor (with the ground's end of `--secure`) and the viewer of `--foxglove`,
    /// ready to run; fails with the message to print.
    pub fn start(self, args: &Args, keys: Option<GroundKeys>) -> Result<Ground<'_>, String> {
        let mut monitor = Monitor::new(self.set, PprzV2::new().into());
        if let Some(table) = &self.table {
            monitor = monitor.with_settings(table.clone());
        }
        let monitor = match keys {
            Some(keys) => monitor
                .with_secure(GroundSecure::new(AC_ID, keys))
                .map_err(|e| e.to_string())?,
            None => monitor,
        };
        let viewer = match args.foxglove {
            Some(addr) => {
                let mut viewer = Viewer::new();
                if let Some(table) = &self.table {
                    viewer = viewer.settings_table(table.clone());
                }
                let bound = viewer
                    .serve(addr, "pprz sitl", true)
                    .map_err(|e| e.to_string())?;
                eprintln!("foxglove: serving ws://{bound}");
                Some(viewer)
            }
            None => None,
        };
        let secure = monitor.secure_status().is_some();
        Ok(Ground {
            args,
            socket: self.socket,
            monitor,
            viewer,
            transport: PprzV2::new().into(),
            fleet: fleet::ids(args.fleet),
            secure,
            next_ping: 1.0,
            setting_sent: false,
            resume_sent: false,
            timed: persist::timed_settings(args),
            timed_sent: 0,
            next_render: render_period(args.speed),
            next_link: 0.0,
        })
    }
}

/// The settings files of the run ([`Args::settings_files`]), their warnings printed;
/// `None` without files. Fails with every problem, each with file, line and column.
fn load_settings(args: &Args) -> Result<Option<Arc<SettingsTable>>, String> {
    let files = args.settings_files();
    if files.is_empty() {
        return Ok(None);
    }
    let table = SettingsTable::load(&files).map_err(|e| {
        let lines: Vec<String> = e
            .diagnostics()
            .iter()
            .map(|d| format!("sitl: error: {}", escape::lines(&d.to_string())))
            .collect();
        lines.join("\n")
    })?;
    for w in table.warnings() {
        eprintln!("sitl: warning: {}", escape::lines(&w.to_string()));
    }
    Ok(Some(Arc::new(table)))
}

/// Wall-clock seconds between two views of the live table, in simulated seconds.
fn render_period(speed: f64) -> f64 {
    RENDER_PERIOD_S * speed.max(1.0)
}

/// The running ground station.
pub struct Ground<'a> {
    args: &'a Args,
    socket: UdpSocket,
    monitor: Monitor,
    viewer: Option<Viewer>,
    /// What the ground speaks on UDP: PPRZ v2.
    transport: AnyTransport,
    /// The aircraft it PINGs and sets.
    fleet: Vec<u8>,
    /// `--secure`: frames are recorded here, opened (the bridge sees them sealed).
    secure: bool,
    /// Simulated times of the next PING, view and viewer link statistics.
    next_ping: f64,
    next_render: f64,
    next_link: f64,
    setting_sent: bool,
    /// `--resume-nav`: the SETTING of `ap_mode` went.
    resume_sent: bool,
    /// `--setting`, in time order, and how many went.
    timed: Vec<TimedSetting>,
    timed_sent: usize,
}

impl Ground<'_> {
    /// Runs until the end of the run (`--duration`, or `stop`, set by Ctrl-C), from
    /// `start`; `aircraft_side` gives the viewer each aircraft's own figures. Returns the
    /// monitor, for the summary.
    pub fn run(
        mut self,
        aircraft_side: &dyn Fn(u8) -> Option<[LevelFigures; 3]>,
        stop: &AtomicBool,
        start: StdInstant,
    ) -> Monitor {
        let speed = self.args.speed;
        // The simulation's clock, so that what the ground sends at a time of the run
        // (a PING at 10 s, the SETTING of `--resume-nav`) meets the radio at that time.
        let sim_now = || Instant::now().as_micros() as f64 / 1e6;
        let wall_limit = self.args.duration / speed;
        let _ = self
            .socket
            .set_read_timeout(Some(StdDuration::from_millis(20)));
        let mut buf = [0u8; 2048];
        while !stop.load(Ordering::SeqCst) && start.elapsed().as_secs_f64() < wall_limit {
            let t = sim_now();
            self.exchange_keys(t);
            self.ping(t);
            self.set_once(t);
            self.resume_nav(t);
            self.timed_settings(t);
            self.serve_viewer_requests(t);
            self.receive(&mut buf, &sim_now);
            // Stale aircraft and expired requests, also while nothing arrives.
            self.monitor.tick(sim_now());
            self.show(t, aircraft_side);
        }
        if let Some(v) = self.viewer {
            eprintln!("{}", v.counts());
            if let Err(e) = v.finish() {
                eprintln!("sitl: {e}");
            }
        }
        self.monitor
    }

    /// The key exchange (`--secure`): message 1 until answered, message 3.
    fn exchange_keys(&mut self, t: f64) {
        for frame in self.monitor.poll_secure(t) {
            let _ = self.socket.send_to(&frame, self.args.uplink);
        }
    }

    /// Every PING due by `t` to every aircraft (a flood sends many per pass; a slow pass
    /// skips none); on a secure link, from the session on, sealed.
    fn ping(&mut self, t: f64) {
        let ping_period = 1.0 / self.args.ping_rate;
        let fleet = std::mem::take(&mut self.fleet);
        while t >= self.next_ping {
            for &ac in &fleet {
                if self.send(ac, "PING", &[]) {
                    self.monitor.ping_sent(Some(ac), t);
                    if self.secure {
                        record::uplink(ac, Ping::CLASS_ID, Ping::ID, &[], Instant::now());
                    }
                }
            }
            self.next_ping += ping_period;
        }
        self.fleet = fleet;
    }

    /// The SETTING of every aircraft, once, at [`SETTING_AT_S`].
    fn set_once(&mut self, t: f64) {
        if self.setting_sent || t < SETTING_AT_S || !self.monitor.uplink_ready() {
            return;
        }
        let (index, value) = SETTING;
        self.set_all(t, index, value);
        self.setting_sent = true;
    }

    /// `--resume-nav`: `ap_mode` NAV on every aircraft, once, at its time (lost if the
    /// uplink is cut then).
    fn resume_nav(&mut self, t: f64) {
        let due = self.args.resume_nav.is_some_and(|at| t >= at);
        if self.resume_sent || !due || !self.monitor.uplink_ready() {
            return;
        }
        self.set_all(t, link::AP_MODE_SETTING, f64::from(link::NAV));
        self.resume_sent = true;
    }

    /// `--setting`: each SETTING due by `t`, once (lost if the uplink is cut then).
    fn timed_settings(&mut self, t: f64) {
        while let Some(s) = self.timed.get(self.timed_sent).copied() {
            if t < s.at_s || !self.monitor.uplink_ready() {
                return;
            }
            self.set_all(t, s.index, s.value);
            self.timed_sent += 1;
        }
    }

    /// SETTING `index` = `value` to every aircraft at `t`.
    fn set_all(&mut self, t: f64, index: u8, value: f64) {
        let fleet = std::mem::take(&mut self.fleet);
        for &ac in &fleet {
            let values = [
                ("index", f64::from(index)),
                ("ac_id", f64::from(ac)),
                ("value", value),
            ];
            if self.send(ac, "SETTING", &values) {
                self.monitor.setting_sent(Some(ac), t, index, value);
            }
        }
        self.fleet = fleet;
    }

    /// Settings read and written from the viewer.
    fn serve_viewer_requests(&mut self, t: f64) {
        let requests = match self.viewer.as_mut() {
            Some(v) => v.setting_requests(t),
            None => Vec::new(),
        };
        for request in requests {
            let (name, values) = request.message();
            if self.send(request.ac_id(), name, &values) {
                request.sent(&mut self.monitor, t);
            } else if let Some(v) = self.viewer.as_mut() {
                let why = if self.monitor.uplink_ready() {
                    "the uplink failed"
                } else {
                    "no secure session yet"
                };
                v.setting_not_sent(&request, why);
            }
        }
    }

    /// Sends the uplink message `name` with `values` to aircraft `ac` (sealed on a
    /// secure link), if the uplink is ready; whether it was sent.
    fn send(&mut self, ac: u8, name: &str, values: &[(&str, f64)]) -> bool {
        if !self.monitor.uplink_ready() {
            return false;
        }
        let Ok(frame) = uplink::frame(self.monitor.set(), self.transport, ac, name, values) else {
            return false;
        };
        let Ok(frame) = self.monitor.seal_uplink(&frame) else {
            return false;
        };
        self.socket.send_to(&frame, self.args.uplink).is_ok()
    }

    /// The telemetry of one datagram, if one comes within the socket's timeout: to the
    /// monitor (at the simulated time of its arrival), the `--lines` output, the viewer
    /// and (secure link) the record.
    fn receive(&mut self, buf: &mut [u8], sim_now: &dyn Fn() -> f64) {
        let Ok((n, _)) = self.socket.recv_from(buf) else {
            return;
        };
        let now = sim_now();
        let (lines, secure, viewer) = (self.args.lines, self.secure, &mut self.viewer);
        self.monitor.feed(now, &buf[..n], |m| {
            if lines {
                println!("{}", m.line);
            }
            if let Some(v) = viewer.as_mut() {
                v.message(unix_ns(), m);
            }
            // A secure link's frames are recorded here, opened (the radio's bridge
            // sees them encrypted).
            if secure && let Ok(f) = PprzV2::new().view(m.raw) {
                record::received(
                    f.source(),
                    f.class(),
                    f.msg_id(),
                    f.payload(),
                    Instant::now(),
                );
            }
        });
    }

    /// The live table when due, and the viewer's link statistics every simulated second.
    fn show(&mut self, t: f64, aircraft_side: &dyn Fn(u8) -> Option<[LevelFigures; 3]>) {
        if !self.args.lines && t >= self.next_render {
            print!("\x1b[2J\x1b[H{}", self.monitor.render(t));
            self.next_render = t + render_period(self.args.speed);
        }
        if let Some(v) = self.viewer.as_mut()
            && t >= self.next_link
        {
            v.link_stats(unix_ns(), &self.monitor, t, aircraft_side);
            self.next_link = t + self.args.speed;
        }
    }
}

/// Without a ground in this process (`--headless`): says where the aircraft talk and
/// waits for the end of the run.
pub fn wait_headless(args: &Args, stop: &AtomicBool, start: StdInstant) {
    let who = match args.fleet {
        1 => format!("aircraft {AC_ID}"),
        _ if args.relay => format!("aircraft {AC_ID} and {SECOND_AC_ID} (through {AC_ID})"),
        n => format!("aircraft {AC_ID} to {}", fleet::id(n - 1)),
    };
    println!(
        "{who} running: telemetry to UDP {}, uplink on UDP {} (Ctrl-C to stop)",
        args.ground, args.uplink
    );
    let wall_limit = args.duration / args.speed;
    while !stop.load(Ordering::SeqCst) && start.elapsed().as_secs_f64() < wall_limit {
        std::thread::sleep(StdDuration::from_millis(100));
    }
}
