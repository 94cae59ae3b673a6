//! The ground station in this process (without `--headless`): it listens for the
//! telemetry on UDP, decodes it live, runs the key exchange of `--secure`, PINGs every
//! aircraft (its PINGs keep their uplink alive), changes a setting at 3 s, sets
//! `ap_mode` back to NAV at `--resume-nav`, sends the SETTINGs of `--setting` at their
//! times, serves `--foxglove`, and shows the live table or one line per message, the
//! settings named after `--settings`. Its clock is the simulation's (the aircraft's).
//! With `--radios 2`, `--frame-loss` or `--zenoh` it listens on each radio's link and
//! merges them with the gateway ([`crate::merge`]).

use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration as StdDuration, Instant as StdInstant};

use embassy_time::Instant;
use pprz_default::messages::datalink::Ping;
use pprz_example_app::AC_ID;
use pprz_ground::escape;
use pprz_ground::input::DATAGRAM_BUFFER;
use pprz_ground::monitor::Monitor;
use pprz_ground::secure::GroundSecure;
use pprz_ground::set::RuntimeSet;
use pprz_ground::settings::SettingsTable;
use pprz_ground::viewer::{LevelFigures, Viewer, unix_ns};
use pprz_messages::Message;
use pprz_secure::GroundKeys;
use pprz_telemetry::pprz_transports::{AnyTransport, Framing, PprzV2};

use crate::merge::{self, Merge};

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
    /// One socket per link: radio A's (`--ground`), radio B's (`--ground-b`).
    sockets: Vec<UdpSocket>,
    set: RuntimeSet,
    table: Option<Arc<SettingsTable>>,
}

impl Station {
    /// Listens on `--ground`, loads `--messages` and the settings files (printing their
    /// warnings); fails with the message to print.
    pub fn open(args: &Args) -> Result<Self, String> {
        let table = load_settings(args)?;
        let mut sockets = Vec::new();
        for addr in merge::ground_addresses(args) {
            sockets.push(UdpSocket::bind(addr).map_err(|e| {
                format!(
                    "cannot listen on {addr} ({e}); is another ground station running? Use --ground/--uplink (--ground-b/--uplink-b) or --headless"
                )
            })?);
        }
        let set = RuntimeSet::load(&args.messages).map_err(|e| e.to_string())?;
        Ok(Self {
            sockets,
            set,
            table,
        })
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
        let merge = if args.gateway() {
            Merge::gateway(args, monitor, self.table.as_ref(), &self.sockets)?
        } else {
            Merge::single(monitor)
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
        let secure = merge.monitor().secure_status().is_some();
        Ok(Ground {
            args,
            sockets: self.sockets,
            uplinks: merge::uplink_addresses(args),
            merge,
            clock: 0.0,
            next_publish: 0.0,
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
    /// One socket per link (radio A's, radio B's).
    sockets: Vec<UdpSocket>,
    /// Where each link's uplink frames go.
    uplinks: Vec<std::net::SocketAddr>,
    /// What takes the links in: the monitor, or the gateway.
    merge: Merge,
    /// The simulated time of the current turn, seconds.
    clock: f64,
    /// When the bus gets the gateway's figures next (`--zenoh`).
    next_publish: f64,
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
    /// `start`; `aircraft_side` gives the viewer each aircraft's own figures. Returns
    /// what took the links in (the monitor or the gateway), for the summary.
    pub fn run(
        mut self,
        aircraft_side: &dyn Fn(u8) -> Option<[LevelFigures; 3]>,
        stop: &AtomicBool,
        start: StdInstant,
    ) -> Merge {
        let speed = self.args.speed;
        // The simulation's clock, so that what the ground sends at a time of the run
        // (a PING at 10 s, the SETTING of `--resume-nav`) meets the radio at that time.
        let sim_now = || Instant::now().as_micros() as f64 / 1e6;
        let wall_limit = self.args.duration / speed;
        // One link waits for a datagram up to 20 ms; with two, each up to 1 ms in turn.
        let wait = if self.sockets.len() > 1 { 1 } else { 20 };
        for socket in &self.sockets {
            let _ = socket.set_read_timeout(Some(StdDuration::from_millis(wait)));
        }
        // Room for any datagram: a longer one would be cut short without an error.
        let mut buf = vec![0u8; DATAGRAM_BUFFER];
        while !stop.load(Ordering::SeqCst) && start.elapsed().as_secs_f64() < wall_limit {
            let t = sim_now();
            self.clock = t;
            self.exchange_keys(t);
            self.ping(t);
            self.set_once(t);
            self.resume_nav(t);
            self.timed_settings(t);
            self.serve_viewer_requests(t);
            for link in 0..self.sockets.len() {
                self.receive(link, &mut buf, &sim_now);
            }
            // Stale aircraft and expired requests, also while nothing arrives; the bus's
            // requests and, once a second, its figures.
            let now = sim_now();
            let publish = now >= self.next_publish;
            if publish {
                self.next_publish = now + 1.0;
            }
            self.merge.tick(now, publish);
            self.show(t, aircraft_side);
        }
        self.merge.stop();
        if let Some(v) = self.viewer {
            eprintln!("{}", v.counts());
            if let Err(e) = v.finish() {
                eprintln!("sitl: {e}");
            }
        }
        self.merge
    }

    /// The key exchange (`--secure`): message 1 until answered, message 3.
    fn exchange_keys(&mut self, t: f64) {
        let frames = self.merge.monitor_mut().poll_secure(t);
        for frame in frames {
            let _ = self.sockets[0].send_to(&frame, self.args.uplink);
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
                    self.merge.monitor_mut().ping_sent(Some(ac), t);
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
        if self.setting_sent || t < SETTING_AT_S || !self.merge.monitor().uplink_ready() {
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
        if self.resume_sent || !due || !self.merge.monitor().uplink_ready() {
            return;
        }
        self.set_all(t, link::AP_MODE_SETTING, f64::from(link::NAV));
        self.resume_sent = true;
    }

    /// `--setting`: each SETTING due by `t`, once (lost if the uplink is cut then).
    fn timed_settings(&mut self, t: f64) {
        while let Some(s) = self.timed.get(self.timed_sent).copied() {
            if t < s.at_s || !self.merge.monitor().uplink_ready() {
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
                self.merge
                    .monitor_mut()
                    .setting_sent(Some(ac), t, index, value);
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
                request.sent(self.merge.monitor_mut(), t);
            } else if let Some(v) = self.viewer.as_mut() {
                let why = if self.merge.monitor().uplink_ready() {
                    "the uplink failed"
                } else {
                    "no secure session yet"
                };
                v.setting_not_sent(&request, why);
            }
        }
    }

    /// Sends the uplink message `name` with `values` to aircraft `ac` (sealed on a
    /// secure link), if the uplink is ready, on the link(s) its route takes; whether it
    /// was sent.
    fn send(&mut self, ac: u8, name: &str, values: &[(&str, f64)]) -> bool {
        if !self.merge.monitor().uplink_ready() {
            return false;
        }
        let frames = self
            .merge
            .frames(self.clock, self.transport, ac, name, values);
        let mut sent = false;
        for (link, frame) in frames {
            if let (Some(socket), Some(to)) = (self.sockets.get(link), self.uplinks.get(link)) {
                sent |= socket.send_to(&frame, to).is_ok();
            }
        }
        sent
    }

    /// The telemetry of one datagram, if one comes within the socket's timeout: to the
    /// monitor (at the simulated time of its arrival), the `--lines` output, the viewer
    /// and (secure link) the record.
    fn receive(&mut self, link: usize, buf: &mut [u8], sim_now: &dyn Fn() -> f64) {
        let Ok((n, _)) = self.sockets[link].recv_from(buf) else {
            return;
        };
        let now = sim_now();
        let (lines, secure, viewer) = (self.args.lines, self.secure, &mut self.viewer);
        self.merge.feed(link, now, &buf[..n], |m| {
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
            print!("\x1b[2J\x1b[H{}", self.merge.monitor().render(t));
            self.next_render = t + render_period(self.args.speed);
        }
        if let Some(v) = self.viewer.as_mut()
            && t >= self.next_link
        {
            v.link_stats(unix_ns(), self.merge.monitor(), t, aircraft_side);
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
    let second = if args.radios > 1 {
        format!(
            "; radio B: telemetry to UDP {}, uplink on UDP {}",
            args.ground_b, args.uplink_b
        )
    } else {
        String::new()
    };
    println!(
        "{who} running: telemetry to UDP {}, uplink on UDP {}{second} (Ctrl-C to stop)",
        args.ground, args.uplink
    );
    let wall_limit = args.duration / args.speed;
    while !stop.load(Ordering::SeqCst) && start.elapsed().as_secs_f64() < wall_limit {
        std::thread::sleep(StdDuration::from_millis(100));
    }
}
