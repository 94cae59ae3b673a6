//! Workload 4: a 57 600-baud radio overloaded ten times by low-priority payload for 60
//! simulated seconds, through the priority stack and through the reference firmware's
//! FIFO that drops a message when its whole frame does not fit (how the reference
//! firmware transmits: it checks the UART buffer for room for the whole frame, else counts an
//! overrun).
//!
//! # Traffic (fixed)
//! * **Status** (priority 128): the priority-128 messages of the `default` mode of
//!   `telemetry.xml` at their nominal periods ([`STATUS`]): ALIVE, ROTORCRAFT_STATUS,
//!   ROTORCRAFT_FP, ATTITUDE, GPS_INT, INS, ENERGY, DATALINK_REPORT, AUTOPILOT_VERSION
//!   (about 14 % of the link).
//! * **Acknowledgements** (priority 192): DL_VALUE at 2 Hz.
//! * **Payload** (priority 64): PAYLOAD frames of 25..=209 bytes (fixed seed) offered at
//!   [`OVERLOAD`] times the link capacity, in 1 ms steps.
//!
//! Every message carries a unique tag in one of its fields, so every frame on the wire
//! is traced back to the moment it was submitted. Latency is measured from the
//! submission to the moment the frame's first byte goes on the wire. After the 60 s of
//! traffic the queues drain, so every message is either sent or shed.
//!
//! # Simulation
//! embassy-time's mock driver, the producer and the writer polled by hand (as in
//! `telemetry/tests/saturation.rs`), but event-driven: every timer deadline is recorded
//! in an agenda and the clock jumps straight to the next one, so there is no stepping
//! error and the run takes a fraction of a second. The link is a UART that takes
//! [`wire_time_us`] per frame (8N1, 10 bits per byte, rounded up to the microsecond).
//!
//! # Systems compared
//! * The stack: `Downlink` with a [`PRIO_ARENA`]-byte frame arena and a queue of
//!   [`PRIO_QUEUE`] frames, `run_writer` writing to the UART.
//! * FIFO drop-when-full with the same memory ([`PRIO_ARENA`] bytes), and with a small
//!   UART ring ([`SMALL_FIFO`] bytes, the size of a typical autopilot TX buffer). A byte of
//!   the ring is free again once it is on the wire, as with an interrupt-driven UART.

use std::cell::{Cell, RefCell};
use std::collections::{HashMap, VecDeque};
use std::convert::Infallible;
use std::fmt::Write as _;
use std::future::poll_fn;
use std::task::Poll;

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time::MockDriver;
use pprz_messages::Message;
use pprz_telemetry::stats::DeviceStats;
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, run_writer};
use pprz_transports::PprzV2;

use crate::rng::Rng;
use crate::sim::{Agenda, MOCK_TIME, Submit, Traffic, ms, now_us, percentile};
pub use crate::sim::{Level, STATUS};
use crate::stream::{AC_ID, encode_frame};

/// Link speed in baud (8N1: 10 bits per byte).
pub const BAUD: u64 = 57_600;
/// Link capacity in bytes per second.
pub const LINK_BYTES_PER_S: u64 = BAUD / 10;
/// Simulated seconds of traffic.
pub const SECONDS: u64 = 60;
/// Payload offered, as a multiple of the link capacity.
pub const OVERLOAD: u64 = 10;
/// Period of the acknowledgements (2 Hz), in ms; the first one at half a period.
pub const ACK_PERIOD_MS: u64 = 500;
/// Time allowed after the traffic for the queues to drain, in ms.
pub const DRAIN_MS: u64 = 5_000;
/// Frame arena of the stack (bytes).
pub const PRIO_ARENA: usize = 4096;
/// Queue capacity of the stack (frames).
pub const PRIO_QUEUE: usize = 32;
/// The small FIFO of the comparison (bytes).
pub const SMALL_FIFO: usize = 256;
/// Field bytes of the payload messages (inclusive range); frames are 9 bytes longer.
pub const PAYLOAD_VALUES: (usize, usize) = (16, 200);
/// Seed of the payload sizes.
pub const SEED: u64 = 0x0F10_0D5E;

/// Wire time of `bytes` bytes at [`BAUD`], in µs (rounded up).
pub const fn wire_time_us(bytes: usize) -> u64 {
    (bytes as u64 * 10 * 1_000_000).div_ceil(BAUD)
}

/// The acknowledgement latency target: two maximum-size (255-byte) frame times, in µs.
pub const ACK_TARGET_US: u64 = 2 * wire_time_us(255);

/// Figures of one priority level in one system.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LevelReport {
    /// Messages submitted.
    pub submitted: u32,
    /// Frames that went on the wire.
    pub sent: u32,
    /// Messages that never did (dropped or evicted).
    pub shed: u32,
    /// Latencies (submission to first byte on the wire) of the sent frames, sorted, µs.
    pub latencies_us: Vec<u64>,
}

impl LevelReport {
    /// Nearest-rank percentile `p` (0..=100) of the latencies, µs.
    pub fn percentile_us(&self, p: u64) -> Option<u64> {
        percentile(&self.latencies_us, p)
    }

    /// Largest latency, µs.
    pub fn max_us(&self) -> Option<u64> {
        self.latencies_us.last().copied()
    }
}

/// Figures of one system.
#[derive(Debug, Clone, PartialEq)]
pub struct SystemReport {
    /// What was simulated.
    pub name: String,
    /// Per level, in [`Level::ALL`] order.
    pub levels: [LevelReport; 3],
    /// Fraction of the time the link was busy while frames were waiting (between the
    /// first frame and the end of the traffic).
    pub utilisation_backlogged: f64,
    /// Fraction of the traffic period the link was busy.
    pub utilisation: f64,
    /// Frames on the wire.
    pub frames: u32,
    /// Bytes on the wire.
    pub wire_bytes: u64,
    /// The stack's device statistics (only for the stack).
    pub device_stats: Option<DeviceStats>,
}

impl SystemReport {
    /// The figures of `level`.
    pub fn level(&self, level: Level) -> &LevelReport {
        &self.levels[level.index()]
    }
}

/// Everything workload 4 measured.
#[derive(Debug, Clone, PartialEq)]
pub struct OverloadReport {
    /// Payload bytes offered per second (frames, on the wire).
    pub offered_payload_bytes_per_s: u64,
    /// The stack first, then the FIFOs.
    pub systems: Vec<SystemReport>,
}

/// One frame on the wire.
struct WireRecord {
    start_us: u64,
    end_us: u64,
    bytes: Vec<u8>,
    /// Whether frames were waiting when this one ended.
    backlog_after: bool,
}

/// The simulated UART: one frame time per write, every write recorded.
struct SimUart<'s> {
    agenda: &'s Agenda,
    backlog: &'s dyn Fn() -> bool,
    log: Vec<WireRecord>,
}

impl embedded_io_async::ErrorType for SimUart<'_> {
    type Error = Infallible;
}

impl embedded_io_async::Write for SimUart<'_> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        let start_us = now_us();
        let end_us = start_us + wire_time_us(buf.len());
        self.agenda.sleep_until(end_us).await;
        self.log.push(WireRecord {
            start_us,
            end_us,
            bytes: buf.to_vec(),
            backlog_after: (self.backlog)(),
        });
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------
// Systems under test.

/// A transmit path: takes messages (with their frame), writes frames to the UART.
trait TxPath {
    /// Submits a message whose PPRZ v2 frame is `frame`; `false` if it was dropped at once.
    fn submit<M: Message>(&self, msg: &M, frame: &[u8]) -> bool;
    /// Whether frames are waiting.
    fn backlog(&self) -> bool;
    /// The writer: runs forever.
    async fn write_loop(&self, uart: &mut SimUart<'_>);
}

type StackDownlink<'a> = Downlink<'a, CriticalSectionRawMutex, 1, PRIO_QUEUE>;

impl TxPath for StackDownlink<'_> {
    fn submit<M: Message>(&self, msg: &M, _frame: &[u8]) -> bool {
        self.send(msg).is_ok()
    }

    fn backlog(&self) -> bool {
        self.stats(0).is_some_and(|s| s.waiting > 0)
    }

    async fn write_loop(&self, uart: &mut SimUart<'_>) {
        match self.ports() {
            Ok([mut port]) => run_writer(&mut port, uart).await,
            Err(e) => panic!("{e}"),
        }
    }
}

/// The reference firmware's transmit path: a byte FIFO; a message whose whole frame does
/// not fit is dropped (an overrun).
struct DropFifo {
    capacity: usize,
    frames: RefCell<VecDeque<Vec<u8>>>,
    /// Bytes of the waiting frames.
    queued: Cell<usize>,
    /// The frame on the wire: when it ends.
    in_flight_end_us: Cell<u64>,
    overruns: Cell<u32>,
}

impl DropFifo {
    fn new(capacity: usize) -> Self {
        Self {
            capacity,
            frames: RefCell::new(VecDeque::new()),
            queued: Cell::new(0),
            in_flight_end_us: Cell::new(0),
            overruns: Cell::new(0),
        }
    }

    /// Bytes of the frame on the wire that are not sent yet (still in the ring).
    fn in_flight_bytes(&self) -> usize {
        let left_us = self.in_flight_end_us.get().saturating_sub(now_us());
        (left_us * BAUD).div_ceil(10 * 1_000_000) as usize
    }
}

impl TxPath for DropFifo {
    fn submit<M: Message>(&self, _msg: &M, frame: &[u8]) -> bool {
        let used = self.queued.get() + self.in_flight_bytes();
        if used + frame.len() > self.capacity {
            self.overruns.set(self.overruns.get() + 1);
            return false;
        }
        self.frames.borrow_mut().push_back(frame.to_vec());
        self.queued.set(self.queued.get() + frame.len());
        true
    }

    fn backlog(&self) -> bool {
        !self.frames.borrow().is_empty()
    }

    async fn write_loop(&self, uart: &mut SimUart<'_>) {
        use embedded_io_async::Write;
        loop {
            // Everything is polled again after every event, so no waker is needed.
            let frame = poll_fn(|_| match self.frames.borrow_mut().pop_front() {
                Some(f) => Poll::Ready(f),
                None => Poll::Pending,
            })
            .await;
            self.queued.set(self.queued.get() - frame.len());
            self.in_flight_end_us
                .set(now_us() + wire_time_us(frame.len()));
            let Ok(()) = uart.write_all(&frame).await;
        }
    }
}

// ---------------------------------------------------------------------------------------
// The producer.

/// What the producer submitted: frame bytes -> (submission time, level).
type Submitted = HashMap<Vec<u8>, (u64, Level)>;

struct Producer<'p, P: TxPath> {
    path: &'p P,
    submitted: Submitted,
    counts: [u32; 3],
    frame: Vec<u8>,
}

impl<P: TxPath> Submit for Producer<'_, P> {
    /// The FIFO and workload 4's stack have no latest-value-wins: `state` is not used.
    fn submit<M: Message>(&mut self, _state: bool, msg: &M) {
        self.frame.resize(255, 0);
        let len = encode_frame(&PprzV2::new(), msg, &mut self.frame).expect("frames fit");
        self.frame.truncate(len);
        let level = Level::of(M::PRIORITY);
        let previous = self.submitted.insert(self.frame.clone(), (now_us(), level));
        assert!(previous.is_none(), "every frame is unique (tagged)");
        self.counts[level.index()] += 1;
        // Whether it was dropped at once or later is told by the wire log.
        let _ = self.path.submit(msg, &self.frame);
    }
}

/// Runs the traffic through `path` and measures it.
fn simulate<P: TxPath>(name: String, path: &P) -> (SystemReport, u64) {
    let _clock = MOCK_TIME.lock().unwrap_or_else(|e| e.into_inner());
    MockDriver::get().reset();
    let agenda = Agenda::default();
    let backlog = || path.backlog();
    let mut uart = SimUart {
        agenda: &agenda,
        backlog: &backlog,
        log: Vec::new(),
    };
    let mut producer = Producer {
        path,
        submitted: HashMap::new(),
        counts: [0; 3],
        frame: Vec::new(),
    };
    let mut offered_payload = 0u64;
    let mut traffic_tags = Traffic::default();
    let traffic = async {
        let mut rng = Rng::new(SEED);
        // Payload credit in tenths of a byte: OVERLOAD x capacity per ms.
        let per_ms = OVERLOAD * LINK_BYTES_PER_S * 10 / 1000;
        let mut credit = 0u64;
        let mut next_values = rng.range(PAYLOAD_VALUES.0, PAYLOAD_VALUES.1);
        for ms in 0..SECONDS * 1000 {
            traffic_tags.tick(ms, ACK_PERIOD_MS, &mut producer);
            credit += per_ms;
            // A payload frame is 9 bytes longer than its values.
            while credit >= (next_values as u64 + 9) * 10 {
                traffic_tags.payload(next_values, &mut producer);
                credit -= (next_values as u64 + 9) * 10;
                offered_payload += next_values as u64 + 9;
                next_values = rng.range(PAYLOAD_VALUES.0, PAYLOAD_VALUES.1);
            }
            agenda.sleep_until((ms + 1) * 1000).await;
        }
        agenda.sleep_until((SECONDS * 1000 + DRAIN_MS) * 1000).await;
    };
    let writer = path.write_loop(&mut uart);
    match agenda.run(select(traffic, writer)) {
        Either::First(()) => {}
        Either::Second(()) => unreachable!("the writer runs forever"),
    }
    let submitted = std::mem::take(&mut producer.submitted);
    let counts = producer.counts;
    drop(producer);
    (
        report(name, counts, submitted, &uart.log),
        offered_payload / SECONDS,
    )
}

/// Traces the wire log back to the submissions.
fn report(
    name: String,
    counts: [u32; 3],
    mut submitted: Submitted,
    log: &[WireRecord],
) -> SystemReport {
    let mut levels: [LevelReport; 3] = Default::default();
    for (level, count) in levels.iter_mut().zip(counts) {
        level.submitted = count;
    }
    let traffic_end = SECONDS * 1_000_000;
    let (mut busy, mut idle_backlogged, mut busy_all) = (0u64, 0u64, 0u64);
    for (i, record) in log.iter().enumerate() {
        let (at, level) = submitted
            .remove(&record.bytes)
            .expect("every frame on the wire was submitted once");
        let l = &mut levels[level.index()];
        l.sent += 1;
        l.latencies_us.push(record.start_us - at);
        if record.start_us < traffic_end {
            let end = record.end_us.min(traffic_end);
            busy += end - record.start_us;
            busy_all += end - record.start_us;
            if record.backlog_after {
                let next = log.get(i + 1).map_or(traffic_end, |r| r.start_us);
                idle_backlogged += next.min(traffic_end).saturating_sub(record.end_us);
            }
        }
    }
    for l in &mut levels {
        l.shed = l.submitted - l.sent;
        l.latencies_us.sort_unstable();
    }
    SystemReport {
        name,
        levels,
        utilisation_backlogged: busy as f64 / (busy + idle_backlogged).max(1) as f64,
        utilisation: busy_all as f64 / traffic_end as f64,
        frames: log.len() as u32,
        wire_bytes: log.iter().map(|r| r.bytes.len() as u64).sum(),
        device_stats: None,
    }
}

/// Workload 4: the stack, then the FIFO with the same memory, then the small FIFO.
pub fn run_overload() -> OverloadReport {
    let arena: FrameArena<CriticalSectionRawMutex, PRIO_ARENA> = FrameArena::new();
    let downlink: StackDownlink<'_> =
        Downlink::new(&arena, AC_ID, [DeviceConfig::new(PprzV2::new().into())]);
    let (mut stack, offered) = simulate(
        format!("stack (arena {PRIO_ARENA} B, queue {PRIO_QUEUE})"),
        &downlink,
    );
    stack.device_stats = downlink.stats(0);
    let mut systems = vec![stack];
    for bytes in [PRIO_ARENA, SMALL_FIFO] {
        let fifo = DropFifo::new(bytes);
        let (mut report, _) = simulate(format!("FIFO drop-when-full ({bytes} B)"), &fifo);
        // The FIFO's own overrun counter must agree with the wire log.
        let shed: u32 = report.levels.iter().map(|l| l.shed).sum();
        assert_eq!(shed, fifo.overruns.get(), "FIFO accounting");
        report.device_stats = None;
        systems.push(report);
    }
    OverloadReport {
        offered_payload_bytes_per_s: offered,
        systems,
    }
}

/// The report as a text table, the systems side by side.
pub fn render(report: &OverloadReport) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "overload: {BAUD} baud ({LINK_BYTES_PER_S} B/s), {SECONDS} s of mock time, payload \
         offered at {:.1}x the link ({} B/s); latency = submission to first byte on the wire",
        report.offered_payload_bytes_per_s as f64 / LINK_BYTES_PER_S as f64,
        report.offered_payload_bytes_per_s,
    );
    let width = 30;
    let _ = write!(out, "{:<16} {:<10}", "level", "figure");
    for s in &report.systems {
        let _ = write!(out, " | {:>width$}", s.name);
    }
    out.push('\n');
    type Row = (&'static str, fn(&LevelReport) -> String);
    let rows: [Row; 6] = [
        ("submitted", |l| l.submitted.to_string()),
        ("sent", |l| l.sent.to_string()),
        ("shed", |l| l.shed.to_string()),
        ("p50 ms", |l| ms(l.percentile_us(50))),
        ("p99 ms", |l| ms(l.percentile_us(99))),
        ("max ms", |l| ms(l.max_us())),
    ];
    for level in Level::ALL {
        for (i, (figure, f)) in rows.iter().enumerate() {
            let label = if i == 0 { level.label() } else { "" };
            let _ = write!(out, "{label:<16} {figure:<10}");
            for s in &report.systems {
                let _ = write!(out, " | {:>width$}", f(s.level(level)));
            }
            out.push('\n');
        }
    }
    let _ = write!(out, "{:<27}", "link busy while backlogged");
    for s in &report.systems {
        let _ = write!(
            out,
            " | {:>width$}",
            format!("{:.2} %", s.utilisation_backlogged * 100.0)
        );
    }
    out.push('\n');
    let _ = write!(out, "{:<27}", "link busy (whole 60 s)");
    for s in &report.systems {
        let _ = write!(
            out,
            " | {:>width$}",
            format!("{:.2} %", s.utilisation * 100.0)
        );
    }
    out.push('\n');
    let _ = write!(out, "{:<27}", "ack p99 vs target");
    for s in &report.systems {
        let p99 = s.level(Level::High).percentile_us(99);
        let text = match p99 {
            Some(us) => format!(
                "{} ms / {:.1} ms {}",
                ms(Some(us)),
                ACK_TARGET_US as f64 / 1000.0,
                if us <= ACK_TARGET_US { "ok" } else { "MISSED" }
            ),
            None => "no ack sent".to_owned(),
        };
        let _ = write!(out, " | {text:>width$}");
    }
    out.push('\n');
    if let Some(stats) = report.systems.first().and_then(|s| s.device_stats) {
        let _ = writeln!(
            out,
            "stack device statistics: submitted {}, sent {}, dropped {:?}, evicted {:?}",
            stats.submitted, stats.sent, stats.dropped, stats.evicted
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wire_times_and_target() {
        assert_eq!(wire_time_us(1), 174);
        assert_eq!(wire_time_us(5760), 1_000_000);
        // Two 255-byte frames: 88.5 ms.
        assert_eq!(ACK_TARGET_US, 88_542);
    }

    #[test]
    fn percentiles_use_the_nearest_rank() {
        let l = LevelReport {
            latencies_us: (1..=200).collect(),
            ..LevelReport::default()
        };
        assert_eq!(l.percentile_us(50), Some(100));
        assert_eq!(l.percentile_us(99), Some(198));
        assert_eq!(l.max_us(), Some(200));
    }
}
