//! Workload 7 (`workloads --mode radio`): radios that do not push back, for 60 s of mock
//! time, each scenario side by side with today's behaviour (no pacing, no transmit
//! status, no latest-value-wins).
//!
//! # Scenarios
//! * **a. Transparent radio without flow control** ([`SCENARIO_A`]): a 57 600-baud UART
//!   into a modem with a 2048-byte buffer and an air rate of 4000 B/s (a SiK radio with
//!   ECC); the modem drops the bytes that do not fit. Low-priority payload offered at 10x
//!   the air rate. The stack is paced ([`Pacing`], budget [`BUDGET_A`] bytes).
//! * **b. XBee 802.15.4 in API mode** ([`SCENARIO_B`]): the same UART and load (payload
//!   frames within the 100-byte RF payload); the modem answers every frame with a transmit
//!   status, and the stack keeps at most K frames in it ([`DeliveryWindow`], K = 1 and 2).
//!   The RF side (250 kbit/s) is faster than the UART, so the UART is the bottleneck.
//! * **c. A 4800-baud flow-controlled radio** ([`SCENARIO_C`]): no payload; the status
//!   telemetry alone (about 700 B/s) exceeds the link (480 B/s). The stack sends the
//!   status with `SendOptions::latest`.
//!
//! Scenario d of the issue (no regression) is workload 4 ([`crate::overload`]) and the
//! telemetry crate's saturation test, unchanged.
//!
//! # Traffic
//! The tagged traffic of workload 4 ([`crate::sim::Traffic`]): status messages at their
//! periods (priority 128), acknowledgements (DL_VALUE, priority 192) at 2 Hz, payload
//! (priority 64). After the 60 s the queues drain for [`DRAIN_MS`].
//!
//! # What is measured
//! At the ground: every byte the modem puts on the air goes through the real decoder
//! of the transport (PPRZ v2, or XBee API), so a frame with a byte dropped in the modem is
//! lost the way it is on a real link. Each decoded message is traced back to its
//! submission by its tag (with latest-value-wins, to the newest sample, whose bytes it
//! carries). **Age** = arrival of the frame's last byte at the ground minus submission.
//! **Delivered** = decoded at the ground, as a share of the messages not superseded.
//! **Excess age** = age minus the time the same frame takes on an idle link.
//! **Busy while backlogged**: sampled every millisecond while frames wait in the stack's
//! queue, the fraction of samples where the air (resp. the UART) carries a byte.
//!
//! # Simulation
//! Event-driven mock time as workload 4, plus a 1 ms tick through the whole run: the
//! stack's own timers (pacing, status timeouts) fire on that tick, at most 1 ms late (as on
//! a 1 kHz tick). The modem models are exact per byte: a transparent modem accepts a byte
//! when its buffer has room (with flow control the UART waits for room instead), and sends
//! its bytes in order at the air rate; the XBee modem takes a whole API frame from the
//! UART, sends it after a fixed CSMA backoff at 250 kbit/s with the 802.15.4 overhead and
//! the MAC acknowledgement, then writes the transmit status (7 bytes) on its UART output,
//! which the stack's real `Reader` decodes and hands to the writer.

use pprz_telemetry::SendOptions;
use std::cell::{Cell, RefCell};
use std::collections::{HashMap, VecDeque};
use std::convert::Infallible;
use std::fmt::Write as _;
use std::future::poll_fn;
use std::task::Poll;

use embassy_futures::select::{Either3, select3};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time::MockDriver;
use pprz_messages::Message;
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::stats::DeviceStats;
use pprz_telemetry::{
    DeliveryStats, DeliveryWindow, Device, DeviceConfig, Downlink, FrameArena, Pacing, run_writer,
};
use pprz_transports::xbee::{self, TX_STATUS_FRAME_LEN};
use pprz_transports::{AnyTransport, Decoder, Framing, PprzV2, XBee24};

use crate::rng::Rng;
pub use crate::sim::Level;
use crate::sim::{Agenda, MOCK_TIME, STATUS, Submit, Traffic, ms, now_us, percentile};
use crate::stream::{AC_ID, encode_frame};

/// Simulated seconds of traffic.
pub const SECONDS: u64 = 60;
/// Time allowed after the traffic for the queues to drain, in ms.
pub const DRAIN_MS: u64 = 5_000;
/// Period of the acknowledgements (2 Hz), in ms.
pub const ACK_PERIOD_MS: u64 = 500;
/// Frame arena of the stack (bytes).
pub const ARENA: usize = 4096;
/// Queue capacity of the stack (frames).
pub const QUEUE: usize = 32;
/// Seed of the payload sizes.
pub const SEED: u64 = 0x0F10_0D5E;
/// Largest PPRZ v2 frame (bytes).
pub const MAX_PPRZ_FRAME: usize = 255;
/// Largest XBee 802.15.4 API transmit frame: start, length, 5 bytes of TX16 header, a
/// 100-byte RF payload, checksum.
pub const MAX_XBEE_FRAME: usize = 3 + 5 + xbee::MAX_RF_PAYLOAD_24 + 1;
/// Modem budget of scenario a: a little more than the longest frame (218 bytes), so the
/// modem never runs dry between two frames, and an acknowledgement waits for at most
/// this many bytes of air time (75 ms at 4000 B/s).
pub const BUDGET_A: u16 = 300;
/// Status timeout of the XBee delivery window (ms).
pub const STATUS_TIMEOUT_MS: u32 = 500;
/// Serial receive buffer of an XBee 802.15.4 module (bytes).
pub const XBEE_BUFFER: usize = 202;

/// 802.15.4 timing of the XBee model, in ns: a byte at 250 kbit/s.
const RF_BYTE_NS: u64 = 32_000;
/// PHY and MAC bytes around an RF payload (preamble, SFD, length, MAC header with 16-bit
/// addresses, FCS).
const RF_OVERHEAD_BYTES: u64 = 17;
/// Mean CSMA-CA backoff plus clear channel assessment (fixed, so runs are deterministic).
const RF_BACKOFF_NS: u64 = 1_120_000;
/// Turnaround and MAC acknowledgement (11 bytes).
const RF_ACK_NS: u64 = 192_000 + 11 * RF_BYTE_NS;

/// The radio between the stack's UART and the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Radio {
    /// A transparent modem (SiK, XBee in transparent mode, serial-to-LoRa bridge).
    Transparent {
        /// Over-the-air rate, bytes per second.
        air_rate: u32,
        /// The modem's buffer, bytes.
        buffer: usize,
        /// RTS/CTS: the UART waits for room instead of the modem dropping bytes.
        flow_control: bool,
    },
    /// An XBee 802.15.4 module in API mode, answering transmit statuses.
    XBee,
}

/// One scenario: the link and the load.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Scenario {
    /// Short name (a, b, c).
    pub name: &'static str,
    /// UART baud rate (8N1).
    pub baud: u32,
    /// The radio.
    pub radio: Radio,
    /// Payload offered, bytes per second (frames as on a PPRZ v2 wire); 0: none.
    pub payload_bytes_per_s: u64,
    /// Field bytes of the payload messages (inclusive range).
    pub payload_values: (usize, usize),
}

/// Scenario a: SiK-like radio, no flow control, payload at 10x the air rate.
pub const SCENARIO_A: Scenario = Scenario {
    name: "a",
    baud: 57_600,
    radio: Radio::Transparent {
        air_rate: 4000,
        buffer: 2048,
        flow_control: false,
    },
    payload_bytes_per_s: 40_000,
    payload_values: (16, 200),
};

/// Scenario b: XBee API with transmit status, the same load (frames within the RF
/// payload).
pub const SCENARIO_B: Scenario = Scenario {
    name: "b",
    baud: 57_600,
    radio: Radio::XBee,
    payload_bytes_per_s: 40_000,
    payload_values: (16, 90),
};

/// Scenario c: 4800 baud, flow control, no payload.
pub const SCENARIO_C: Scenario = Scenario {
    name: "c",
    baud: 4800,
    radio: Radio::Transparent {
        air_rate: 480,
        buffer: 64,
        flow_control: true,
    },
    payload_bytes_per_s: 0,
    payload_values: (16, 200),
};

impl Scenario {
    /// Whether the transport is XBee API.
    pub const fn is_xbee(&self) -> bool {
        matches!(self.radio, Radio::XBee)
    }

    /// The rate of the link's bottleneck, bytes per second (the slower of the UART and
    /// the air).
    pub fn bottleneck_bytes_per_s(&self) -> u64 {
        let uart = u64::from(self.baud) / 10;
        match self.radio {
            Radio::Transparent { air_rate, .. } => uart.min(u64::from(air_rate)),
            Radio::XBee => uart,
        }
    }

    /// The acknowledgement target: two maximum-size frames of the transport at the
    /// bottleneck rate, µs.
    pub fn ack_target_us(&self) -> u64 {
        let max = if self.is_xbee() {
            MAX_XBEE_FRAME
        } else {
            MAX_PPRZ_FRAME
        } as u64;
        (2 * max * 1_000_000).div_ceil(self.bottleneck_bytes_per_s())
    }

    /// Bytes on the wire of a frame carrying `data` bytes (message header + fields).
    const fn frame_len(&self, data: usize) -> usize {
        if self.is_xbee() { data + 9 } else { data + 4 }
    }

    /// ns of one byte on the UART.
    fn uart_ns(&self, bytes: u64) -> u64 {
        bytes * 10_000_000_000 / u64::from(self.baud)
    }
}

/// How the stack is used in one run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Setup {
    /// Column title.
    pub label: &'static str,
    /// Pacing of the radio device.
    pub pacing: Option<Pacing>,
    /// Transmit status window (XBee).
    pub window: Option<DeliveryWindow>,
    /// Status sent as latest values (`SendOptions::latest`; else `send`).
    pub latest: bool,
}

/// Today's behaviour: no pacing, no status window, status sent with `send`.
pub const TODAY: Setup = Setup {
    label: "pacing off (today)",
    pacing: None,
    window: None,
    latest: false,
};

/// The setups compared in `scenario`: today's first.
pub fn setups(scenario: &Scenario) -> Vec<Setup> {
    match scenario.radio {
        Radio::Transparent {
            air_rate,
            flow_control: false,
            ..
        } => vec![
            TODAY,
            Setup {
                label: "paced, latest",
                pacing: Some(Pacing::new(air_rate, BUDGET_A)),
                window: None,
                latest: true,
            },
            // The air rate configured 5 % off, either way.
            Setup {
                label: "paced, rate 5 % low",
                pacing: Some(Pacing::new(air_rate * 95 / 100, BUDGET_A)),
                window: None,
                latest: true,
            },
            Setup {
                label: "paced, rate 5 % high",
                pacing: Some(Pacing::new(air_rate * 105 / 100, BUDGET_A)),
                window: None,
                latest: true,
            },
        ],
        Radio::Transparent { .. } => vec![
            TODAY,
            Setup {
                label: "latest value wins",
                pacing: None,
                window: None,
                latest: true,
            },
        ],
        Radio::XBee => vec![
            TODAY,
            Setup {
                label: "status window K=1",
                pacing: None,
                window: Some(DeliveryWindow::new(1, STATUS_TIMEOUT_MS)),
                latest: true,
            },
            Setup {
                label: "status window K=2",
                pacing: None,
                window: Some(DeliveryWindow::new(2, STATUS_TIMEOUT_MS)),
                latest: true,
            },
        ],
    }
}

/// Figures of one priority level in one run.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LevelFigures {
    /// Messages submitted.
    pub submitted: u32,
    /// Replaced by a newer sample while waiting.
    pub superseded: u32,
    /// Dropped or evicted by the stack.
    pub shed: u32,
    /// Frames the stack wrote to the UART.
    pub sent: u32,
    /// Messages decoded at the ground.
    pub delivered: u32,
    /// Ages at the ground (submission to arrival), sorted, µs.
    pub ages_us: Vec<u64>,
    /// Ages minus the frame's time on an idle link, sorted, µs.
    pub excess_us: Vec<u64>,
}

impl LevelFigures {
    /// Delivered, as a fraction of the messages that were not superseded (1 when none).
    pub fn delivered_ratio(&self) -> f64 {
        let expected = self.submitted.saturating_sub(self.superseded);
        if expected == 0 {
            1.0
        } else {
            f64::from(self.delivered) / f64::from(expected)
        }
    }

    /// Nearest-rank percentile `p` (0..=100) of the ages, µs.
    pub fn age_us(&self, p: u64) -> Option<u64> {
        percentile(&self.ages_us, p)
    }

    /// Nearest-rank percentile `p` (0..=100) of the excess ages, µs.
    pub fn excess_us(&self, p: u64) -> Option<u64> {
        percentile(&self.excess_us, p)
    }
}

/// The longest time one status message type went without a delivery.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TypeGap {
    /// Message name.
    pub name: &'static str,
    /// Its period, ms.
    pub period_ms: u64,
    /// The longest gap between two deliveries (or from the start of the traffic to the
    /// first, or from the last to the end of the traffic), µs.
    pub max_gap_us: u64,
}

impl TypeGap {
    /// The no-starvation bound: 2 s, or the period plus 1 s for slower messages.
    pub const fn bound_us(&self) -> u64 {
        let by_period = (self.period_ms + 1000) * 1000;
        if by_period > 2_000_000 {
            by_period
        } else {
            2_000_000
        }
    }
}

/// Everything one run measured.
#[derive(Debug, Clone)]
pub struct RunReport {
    /// The setup.
    pub setup: Setup,
    /// Per level, in [`Level::ALL`] order.
    pub levels: [LevelFigures; 3],
    /// Bytes the modem dropped (buffer full).
    pub modem_dropped_bytes: u64,
    /// Air busy while frames waited in the stack's queue (fraction of the samples).
    pub air_busy_backlogged: f64,
    /// UART busy while frames waited in the stack's queue (fraction of the samples).
    pub uart_busy_backlogged: f64,
    /// Samples (ms) during which frames waited in the stack's queue.
    pub backlogged_ms: u64,
    /// Per status type, the longest gap between deliveries.
    pub gaps: Vec<TypeGap>,
    /// Messages decoded at the ground that match no submission (must be 0).
    pub unmatched: u32,
    /// The stack's device statistics.
    pub device: DeviceStats,
    /// Transmit statuses (XBee).
    pub delivery: DeliveryStats,
}

impl RunReport {
    /// The figures of `level`.
    pub fn level(&self, level: Level) -> &LevelFigures {
        &self.levels[level.index()]
    }

    /// The worst gap over its bound, as (name, gap µs, bound µs), if any type starved.
    pub fn starved(&self) -> Option<(&'static str, u64, u64)> {
        self.gaps
            .iter()
            .filter(|g| g.max_gap_us > g.bound_us())
            .max_by_key(|g| g.max_gap_us - g.bound_us())
            .map(|g| (g.name, g.max_gap_us, g.bound_us()))
    }
}

/// One scenario, every setup.
#[derive(Debug, Clone)]
pub struct ScenarioReport {
    /// The scenario.
    pub scenario: Scenario,
    /// One run per setup, today's first.
    pub runs: Vec<RunReport>,
}

// ---------------------------------------------------------------------------------------
// The modems.

/// A transparent modem: a byte buffer drained at the air rate.
struct TransparentModem {
    air_ns: u64,
    buffer: usize,
    flow_control: bool,
    /// Departure times (ns) of the accepted bytes not yet on the air, in order.
    queued: VecDeque<u64>,
    /// When the air finishes the last accepted byte.
    air_free_ns: u64,
    /// Bytes dropped (buffer full).
    dropped: u64,
    /// Departure times of the bytes not yet sampled as gone (for [`Self::air_busy`]:
    /// `queued` may already be drained ahead of the sampling clock by a write).
    on_air: VecDeque<u64>,
}

impl TransparentModem {
    fn new(air_rate: u32, buffer: usize, flow_control: bool) -> Self {
        Self {
            air_ns: 1_000_000_000 / u64::from(air_rate.max(1)),
            buffer: buffer.max(1),
            flow_control,
            queued: VecDeque::new(),
            air_free_ns: 0,
            dropped: 0,
            on_air: VecDeque::new(),
        }
    }

    /// `bytes` arrive from a UART writing from `start_ns` at `byte_ns(i)` per byte index;
    /// every byte that makes it goes to `air` with its departure time. Returns the end of
    /// the UART write (later than the byte times with flow control).
    fn write(
        &mut self,
        start_ns: u64,
        bytes: &[u8],
        byte_ns: impl Fn(u64) -> u64,
        air: &mut Vec<(u64, u8)>,
    ) -> u64 {
        // With flow control the UART is held back: byte i leaves it `byte_ns(1)` after
        // the previous one, and not before the modem has room.
        let mut uart_at = start_ns;
        for (i, &b) in bytes.iter().enumerate() {
            let mut arrival = if self.flow_control {
                uart_at + byte_ns(1)
            } else {
                start_ns + byte_ns(i as u64 + 1)
            };
            self.drain(arrival);
            if self.queued.len() >= self.buffer {
                if self.flow_control {
                    // CTS: the byte waits for the first one in the modem to leave.
                    arrival = self.queued.pop_front().unwrap_or(arrival);
                } else {
                    self.dropped += 1;
                    uart_at = arrival;
                    continue;
                }
            }
            let departure = self.air_free_ns.max(arrival) + self.air_ns;
            self.air_free_ns = departure;
            self.queued.push_back(departure);
            self.on_air.push_back(departure);
            air.push((departure, b));
            uart_at = arrival;
        }
        uart_at
    }

    fn drain(&mut self, now_ns: u64) {
        while self.queued.front().is_some_and(|&d| d <= now_ns) {
            self.queued.pop_front();
        }
    }

    /// Whether a byte is on the air at `now_ns` (called with a clock that only goes
    /// forward).
    fn air_busy(&mut self, now_ns: u64) -> bool {
        while self.on_air.front().is_some_and(|&d| d <= now_ns) {
            self.on_air.pop_front();
        }
        self.on_air
            .front()
            .is_some_and(|&d| d - self.air_ns <= now_ns)
    }
}

/// An XBee 802.15.4 module in API mode.
struct XBeeModem {
    byte_ns: u64,
    /// Frames in the serial buffer until their RF transmission ends: (end ns, bytes).
    frames: VecDeque<(u64, usize)>,
    rf_free_ns: u64,
    /// Start of the RF transmission of each frame, with its end (for sampling).
    rf_slots: VecDeque<(u64, u64)>,
    /// The module's UART output is free from then.
    out_free_ns: u64,
    dropped: u64,
}

impl XBeeModem {
    fn new(baud: u32) -> Self {
        Self {
            byte_ns: 10_000_000_000 / u64::from(baud),
            frames: VecDeque::new(),
            rf_free_ns: 0,
            rf_slots: VecDeque::new(),
            out_free_ns: 0,
            dropped: 0,
        }
    }

    /// The API frame `bytes` arrived whole at `end_ns`; it goes on the air (to `air`)
    /// and its transmit status, if it asked for one, to `statuses`.
    fn write(
        &mut self,
        end_ns: u64,
        bytes: &[u8],
        air: &mut Vec<(u64, u8)>,
        statuses: &RefCell<VecDeque<(u64, Vec<u8>)>>,
    ) {
        while self.frames.front().is_some_and(|&(end, _)| end <= end_ns) {
            self.frames.pop_front();
        }
        let held: usize = self.frames.iter().map(|&(_, n)| n).sum();
        if held + bytes.len() > XBEE_BUFFER {
            // The bytes past the buffer are lost: so is the frame.
            self.dropped += (held + bytes.len() - XBEE_BUFFER) as u64;
            return;
        }
        // TX16: start, length (2), API id, frame id, address (2), options, data, checksum.
        let rf_len = bytes.len().saturating_sub(9) as u64;
        let start = self.rf_free_ns.max(end_ns) + RF_BACKOFF_NS;
        let end = start + (RF_OVERHEAD_BYTES + rf_len) * RF_BYTE_NS + RF_ACK_NS;
        self.rf_free_ns = end;
        self.rf_slots.push_back((start, end));
        self.frames.push_back((end, bytes.len()));
        air.extend(bytes.iter().map(|&b| (end, b)));
        let frame_id = bytes.get(4).copied().unwrap_or(0);
        if frame_id != xbee::NO_FRAME_ID {
            let mut status = vec![0u8; TX_STATUS_FRAME_LEN];
            if let Ok(n) = xbee::encode_tx_status_24(frame_id, xbee::status::SUCCESS, &mut status) {
                status.truncate(n);
                let out_end = self.out_free_ns.max(end) + self.byte_ns * status.len() as u64;
                self.out_free_ns = out_end;
                statuses.borrow_mut().push_back((out_end, status));
            }
        }
    }

    fn air_busy(&mut self, now_ns: u64) -> bool {
        while self.rf_slots.front().is_some_and(|&(_, end)| end <= now_ns) {
            self.rf_slots.pop_front();
        }
        self.rf_slots
            .front()
            .is_some_and(|&(start, _)| start <= now_ns)
    }
}

enum Modem {
    Transparent(TransparentModem),
    XBee(XBeeModem),
}

impl Modem {
    fn new(scenario: &Scenario) -> Self {
        match scenario.radio {
            Radio::Transparent {
                air_rate,
                buffer,
                flow_control,
            } => Modem::Transparent(TransparentModem::new(air_rate, buffer, flow_control)),
            Radio::XBee => Modem::XBee(XBeeModem::new(scenario.baud)),
        }
    }

    fn dropped(&self) -> u64 {
        match self {
            Modem::Transparent(m) => m.dropped,
            Modem::XBee(m) => m.dropped,
        }
    }

    fn air_busy(&mut self, now_ns: u64) -> bool {
        match self {
            Modem::Transparent(m) => m.air_busy(now_ns),
            Modem::XBee(m) => m.air_busy(now_ns),
        }
    }
}

/// Time (ns) a frame of `len` bytes takes from the start of its UART write to the
/// arrival of its last byte at the ground, on an idle link.
fn idle_delivery_ns(scenario: &Scenario, len: usize) -> u64 {
    let bytes = vec![0u8; len];
    let mut air = Vec::new();
    match scenario.radio {
        Radio::Transparent {
            air_rate,
            buffer,
            flow_control,
        } => {
            let mut m = TransparentModem::new(air_rate, buffer, flow_control);
            m.write(0, &bytes, |i| scenario.uart_ns(i), &mut air);
        }
        Radio::XBee => {
            let statuses = RefCell::new(VecDeque::new());
            let mut m = XBeeModem::new(scenario.baud);
            m.write(scenario.uart_ns(len as u64), &bytes, &mut air, &statuses);
        }
    }
    air.last().map_or(0, |&(t, _)| t)
}

// ---------------------------------------------------------------------------------------
// The stack's side: UART, status input, producer.

/// The shared state of one run.
struct World<'s> {
    scenario: Scenario,
    agenda: &'s Agenda,
    modem: RefCell<Modem>,
    /// Bytes on the air, with the time they reach the ground (ns), in order.
    air: RefCell<Vec<(u64, u8)>>,
    /// Transmit statuses on their way to the stack's UART input: (arrival ns, bytes).
    statuses: RefCell<VecDeque<(u64, Vec<u8>)>>,
    /// The stack's UART output is busy until then (ns).
    uart_busy_until: Cell<u64>,
}

/// The stack's UART output into the modem.
struct Uart<'w, 's>(&'w World<'s>);

impl embedded_io_async::ErrorType for Uart<'_, '_> {
    type Error = Infallible;
}

impl embedded_io_async::Write for Uart<'_, '_> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        let w = self.0;
        let start = now_us() * 1000;
        let end_ns = {
            let mut modem = w.modem.borrow_mut();
            let mut air = w.air.borrow_mut();
            match &mut *modem {
                Modem::Transparent(m) => m.write(start, buf, |i| w.scenario.uart_ns(i), &mut air),
                Modem::XBee(m) => {
                    let end = start + w.scenario.uart_ns(buf.len() as u64);
                    m.write(end, buf, &mut air, &w.statuses);
                    end
                }
            }
        };
        w.uart_busy_until.set(end_ns);
        w.agenda.sleep_until(end_ns.div_ceil(1000)).await;
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// The stack's UART input: the modem's transmit statuses.
struct UartIn<'w, 's> {
    world: &'w World<'s>,
    pending: Vec<u8>,
}

impl embedded_io_async::ErrorType for UartIn<'_, '_> {
    type Error = Infallible;
}

impl embedded_io_async::Read for UartIn<'_, '_> {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        loop {
            if !self.pending.is_empty() {
                let n = buf.len().min(self.pending.len());
                buf[..n].copy_from_slice(&self.pending[..n]);
                self.pending.drain(..n);
                return Ok(n);
            }
            let next = self.world.statuses.borrow().front().map(|&(t, _)| t);
            match next {
                Some(t) if t.div_ceil(1000) <= now_us() => {
                    if let Some((_, bytes)) = self.world.statuses.borrow_mut().pop_front() {
                        self.pending = bytes;
                    }
                }
                Some(t) => self.world.agenda.sleep_until(t.div_ceil(1000)).await,
                None => {
                    // Everything is polled again after every event: look again then.
                    let mut first = true;
                    poll_fn(|_| {
                        if std::mem::take(&mut first) {
                            Poll::Pending
                        } else {
                            Poll::Ready(())
                        }
                    })
                    .await;
                }
            }
        }
    }
}

type RadioDownlink<'a> = Downlink<'a, CriticalSectionRawMutex, 1, QUEUE>;

/// Submission of one tagged message.
#[derive(Clone, Copy)]
struct Submission {
    at_us: u64,
    level: Level,
}

struct Producer<'d> {
    device: Device<'d>,
    latest: bool,
    /// Message data (header + fields, unique by its tag) -> submission.
    submitted: HashMap<Vec<u8>, Submission>,
    counts: [u32; 3],
    frame: Vec<u8>,
}

impl Submit for Producer<'_> {
    fn submit<M: Message>(&mut self, state: bool, msg: &M) {
        self.frame.resize(MAX_PPRZ_FRAME, 0);
        let len = encode_frame(&PprzV2::new(), msg, &mut self.frame).expect("frames fit");
        // PPRZ v2: STX, length, data, two checksum bytes.
        let data = self.frame[2..len - 2].to_vec();
        let level = Level::of(M::PRIORITY);
        let previous = self.submitted.insert(
            data,
            Submission {
                at_us: now_us(),
                level,
            },
        );
        assert!(previous.is_none(), "every message is unique (tagged)");
        self.counts[level.index()] += 1;
        // Dropped or not, the stack counts it; the ground tells what arrived.
        let _ = if state && self.latest {
            self.device.send_with(msg, SendOptions::new().latest())
        } else {
            self.device.send(msg)
        };
    }
}

/// Runs `scenario` with `setup`.
pub fn run(scenario: &Scenario, setup: &Setup) -> RunReport {
    let _clock = MOCK_TIME.lock().unwrap_or_else(|e| e.into_inner());
    MockDriver::get().reset();
    let transport = if scenario.is_xbee() {
        AnyTransport::XBee24(XBee24::new())
    } else {
        AnyTransport::PprzV2(PprzV2::new())
    };
    let config = DeviceConfig::new(transport)
        .pacing(setup.pacing)
        .delivery(setup.window);
    let arena: FrameArena<CriticalSectionRawMutex, ARENA> = FrameArena::new();
    let downlink: RadioDownlink<'_> = Downlink::new(&arena, AC_ID, [config]);
    let Ok([mut port]) = downlink.ports() else {
        unreachable!("the ports of a new downlink are there")
    };
    let device = port.device();
    let datalink: Datalink<'_, CriticalSectionRawMutex, 1> = Datalink::new(AC_ID);

    let agenda = Agenda::default();
    let world = World {
        scenario: *scenario,
        agenda: &agenda,
        modem: RefCell::new(Modem::new(scenario)),
        air: RefCell::new(Vec::new()),
        statuses: RefCell::new(VecDeque::new()),
        uart_busy_until: Cell::new(0),
    };
    let mut producer = Producer {
        device,
        latest: setup.latest,
        submitted: HashMap::new(),
        counts: [0; 3],
        frame: Vec::new(),
    };
    let (mut backlogged, mut air_busy, mut uart_busy) = (0u64, 0u64, 0u64);
    let traffic = async {
        let mut tags = Traffic::default();
        let mut rng = Rng::new(SEED);
        // Payload credit in thousandths of a byte per ms.
        let per_ms = scenario.payload_bytes_per_s;
        let (lo, hi) = scenario.payload_values;
        let mut credit = 0u64;
        let mut next_values = rng.range(lo, hi);
        for ms in 0..(SECONDS * 1000 + DRAIN_MS) {
            if ms < SECONDS * 1000 {
                tags.tick(ms, ACK_PERIOD_MS, &mut producer);
                credit += per_ms;
                // Counted as PPRZ v2 frames: 9 bytes more than the values.
                while per_ms > 0 && credit >= (next_values as u64 + 9) * 1000 {
                    tags.payload(next_values, &mut producer);
                    credit -= (next_values as u64 + 9) * 1000;
                    next_values = rng.range(lo, hi);
                }
                let now_ns = ms * 1_000_000;
                if device.stats().waiting > 0 {
                    backlogged += 1;
                    air_busy += u64::from(world.modem.borrow_mut().air_busy(now_ns));
                    uart_busy += u64::from(world.uart_busy_until.get() > now_ns);
                }
            }
            agenda.sleep_until((ms + 1) * 1000).await;
        }
    };
    let mut uart = Uart(&world);
    let writer = run_writer(&mut port, &mut uart);
    let mut reader: Reader<'_, UartIn<'_, '_>, XBee24> = Reader::new(
        UartIn {
            world: &world,
            pending: Vec::new(),
        },
        XBee24::new(),
        device,
    );
    let reader = reader.run(&datalink);
    match agenda.run(select3(traffic, writer, reader)) {
        Either3::First(()) => {}
        Either3::Second(never) | Either3::Third(never) => match never {},
    }
    let submitted = std::mem::take(&mut producer.submitted);
    let counts = producer.counts;
    drop(producer);
    let air = world.air.take();
    let modem = world.modem.into_inner();
    let device_stats = device.stats();
    report(
        scenario,
        *setup,
        Ground {
            counts,
            submitted,
            air,
            modem_dropped_bytes: modem.dropped(),
        },
        device_stats,
        device.delivery_stats(),
        [backlogged, air_busy, uart_busy],
    )
}

/// What the ground got, with what was submitted.
struct Ground {
    counts: [u32; 3],
    submitted: HashMap<Vec<u8>, Submission>,
    air: Vec<(u64, u8)>,
    modem_dropped_bytes: u64,
}

/// Decodes the air bytes and traces every message back to its submission.
fn report(
    scenario: &Scenario,
    setup: Setup,
    mut ground: Ground,
    device: DeviceStats,
    delivery: DeliveryStats,
    [backlogged, air_busy, uart_busy]: [u64; 3],
) -> RunReport {
    let mut levels: [LevelFigures; 3] = Default::default();
    for (i, l) in levels.iter_mut().enumerate() {
        let stats = &device.levels[i];
        l.submitted = ground.counts[i];
        assert_eq!(
            stats.submitted, ground.counts[i],
            "the stack saw every submission"
        );
        l.superseded = stats.superseded;
        l.shed = stats.lost;
        l.sent = stats.sent;
    }
    let mut arrivals: HashMap<(u8, u8), Vec<u64>> = HashMap::new();
    let mut unmatched = 0;
    let mut deliver = |data: &[u8], at_ns: u64| {
        let Some(s) = ground.submitted.remove(data) else {
            unmatched += 1;
            return;
        };
        let at_us = at_ns.div_ceil(1000);
        let age = at_us.saturating_sub(s.at_us);
        let idle = idle_delivery_ns(scenario, scenario.frame_len(data.len())).div_ceil(1000);
        let l = &mut levels[s.level.index()];
        l.delivered += 1;
        l.ages_us.push(age);
        l.excess_us.push(age.saturating_sub(idle));
        if s.level == Level::Normal && data.len() >= 4 {
            // Header: source, destination, class|component, message id.
            arrivals
                .entry((data[2] & 0x0F, data[3]))
                .or_default()
                .push(at_us);
        }
    };
    if scenario.is_xbee() {
        decode(
            Decoder::<XBee24>::new(XBee24::new()),
            &ground.air,
            &mut deliver,
        );
    } else {
        decode(
            Decoder::<PprzV2>::new(PprzV2::new()),
            &ground.air,
            &mut deliver,
        );
    }
    for l in &mut levels {
        l.ages_us.sort_unstable();
        l.excess_us.sort_unstable();
    }
    let gaps = status_gaps(&arrivals);
    let ratio = |n: u64| n as f64 / backlogged.max(1) as f64;
    RunReport {
        setup,
        levels,
        modem_dropped_bytes: ground.modem_dropped_bytes,
        air_busy_backlogged: ratio(air_busy),
        uart_busy_backlogged: ratio(uart_busy),
        backlogged_ms: backlogged,
        gaps,
        unmatched,
        device,
        delivery,
    }
}

/// Feeds the air bytes to `decoder` one by one; each message goes to `deliver` with the
/// arrival time of its last byte.
fn decode<F: Framing>(
    mut decoder: Decoder<F>,
    air: &[(u64, u8)],
    deliver: &mut impl FnMut(&[u8], u64),
) {
    for &(t, b) in air {
        let byte = [b];
        let mut input = &byte[..];
        while !input.is_empty() {
            if let Some(frame) = decoder.feed(&mut input) {
                deliver(frame.data(), t);
            }
        }
    }
}

/// Per status type, the longest time without a delivery during the traffic.
fn status_gaps(arrivals: &HashMap<(u8, u8), Vec<u64>>) -> Vec<TypeGap> {
    use pprz_default::messages::telemetry as t;
    let ids: [(u8, u8); 9] = [
        (t::Alive::CLASS_ID, t::Alive::ID),
        (t::RotorcraftStatus::CLASS_ID, t::RotorcraftStatus::ID),
        (t::RotorcraftFp::CLASS_ID, t::RotorcraftFp::ID),
        (t::Attitude::CLASS_ID, t::Attitude::ID),
        (t::GpsInt::CLASS_ID, t::GpsInt::ID),
        (t::Ins::CLASS_ID, t::Ins::ID),
        (t::Energy::CLASS_ID, t::Energy::ID),
        (t::DatalinkReport::CLASS_ID, t::DatalinkReport::ID),
        (t::AutopilotVersion::CLASS_ID, t::AutopilotVersion::ID),
    ];
    let end = SECONDS * 1_000_000;
    STATUS
        .iter()
        .zip(ids)
        .map(|(&(name, period_ms, _), key)| {
            let mut last = 0;
            let mut max_gap = 0;
            for &at in arrivals.get(&key).into_iter().flatten() {
                if at > end {
                    break;
                }
                max_gap = max_gap.max(at - last);
                last = at;
            }
            max_gap = max_gap.max(end - last);
            TypeGap {
                name,
                period_ms,
                max_gap_us: max_gap,
            }
        })
        .collect()
}

/// Runs every setup of `scenario`.
pub fn run_scenario(scenario: &Scenario) -> ScenarioReport {
    ScenarioReport {
        scenario: *scenario,
        runs: setups(scenario).iter().map(|s| run(scenario, s)).collect(),
    }
}

/// Workload 7: scenarios a, b and c.
pub fn run_radio() -> Vec<ScenarioReport> {
    [SCENARIO_A, SCENARIO_B, SCENARIO_C]
        .iter()
        .map(run_scenario)
        .collect()
}

/// One scenario as a text table, the setups side by side.
pub fn render(report: &ScenarioReport) -> String {
    let s = &report.scenario;
    let mut out = String::new();
    let link = match s.radio {
        Radio::Transparent {
            air_rate,
            buffer,
            flow_control,
        } => format!(
            "transparent modem, air {air_rate} B/s, buffer {buffer} B, flow control {}",
            if flow_control { "RTS/CTS" } else { "none" }
        ),
        Radio::XBee => format!(
            "XBee 802.15.4 API, RF 250 kbit/s, serial buffer {XBEE_BUFFER} B, transmit status"
        ),
    };
    let _ = writeln!(
        out,
        "radio scenario {}: UART {} baud, {link}; payload {} B/s; {SECONDS} s of mock time",
        s.name, s.baud, s.payload_bytes_per_s
    );
    let width = 22;
    let _ = write!(out, "{:<16} {:<14}", "level", "figure");
    for r in &report.runs {
        let _ = write!(out, " | {:>width$}", r.setup.label);
    }
    out.push('\n');
    type Row = (&'static str, fn(&LevelFigures) -> String);
    let rows: [Row; 9] = [
        ("submitted", |l| l.submitted.to_string()),
        ("superseded", |l| l.superseded.to_string()),
        ("shed", |l| l.shed.to_string()),
        ("sent", |l| l.sent.to_string()),
        ("delivered", |l| l.delivered.to_string()),
        ("delivered %", |l| {
            format!("{:.2}", l.delivered_ratio() * 100.0)
        }),
        ("age p50 ms", |l| ms(l.age_us(50))),
        ("age p99 ms", |l| ms(l.age_us(99))),
        ("excess p99 ms", |l| ms(l.excess_us(99))),
    ];
    for level in Level::ALL {
        for (i, (figure, f)) in rows.iter().enumerate() {
            let label = if i == 0 { level.label() } else { "" };
            let _ = write!(out, "{label:<16} {figure:<14}");
            for r in &report.runs {
                let _ = write!(out, " | {:>width$}", f(r.level(level)));
            }
            out.push('\n');
        }
    }
    type Line = (&'static str, fn(&RunReport, &Scenario) -> String);
    let lines: [Line; 7] = [
        ("modem dropped bytes", |r, _| {
            r.modem_dropped_bytes.to_string()
        }),
        ("air busy, backlogged", |r, _| {
            format!("{:.2} %", r.air_busy_backlogged * 100.0)
        }),
        ("UART busy, backlogged", |r, _| {
            format!("{:.2} %", r.uart_busy_backlogged * 100.0)
        }),
        ("ack p99 vs target", |r, s| {
            let target = s.ack_target_us();
            match r.level(Level::High).age_us(99) {
                Some(us) => format!(
                    "{} / {} {}",
                    ms(Some(us)),
                    ms(Some(target)),
                    if us <= target { "ok" } else { "MISSED" }
                ),
                None => "none".to_owned(),
            }
        }),
        ("worst status gap", |r, _| match r.starved() {
            Some((name, gap, _)) => format!("{name} {} s", gap / 1_000_000),
            None => "within bounds".to_owned(),
        }),
        ("tx status ok/fail/t.o.", |r, _| {
            format!(
                "{}/{}/{}",
                r.delivery.delivered, r.delivery.failed, r.delivery.timeouts
            )
        }),
        ("unmatched at ground", |r, _| r.unmatched.to_string()),
    ];
    for (name, f) in lines {
        let _ = write!(out, "{name:<31}");
        for r in &report.runs {
            let _ = write!(out, " | {:>width$}", f(r, s));
        }
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_transparent_modem_drops_what_does_not_fit() {
        // 10 bytes into a 4-byte modem at 1000 B/s from a UART ten times faster.
        let mut m = TransparentModem::new(1000, 4, false);
        let mut air = Vec::new();
        let end = m.write(0, &[0; 10], |i| i * 100_000, &mut air);
        assert_eq!(end, 1_000_000);
        // The first byte leaves at 1.1 ms; by then the UART has brought all 10: the
        // modem holds 4, the other 6 are dropped.
        assert_eq!(air.len() as u64 + m.dropped, 10);
        assert_eq!(m.dropped, 6);
        assert_eq!(air[0].0, 1_100_000);
        assert_eq!(air[1].0, 2_100_000);
    }

    #[test]
    fn with_flow_control_the_uart_waits_and_nothing_is_lost() {
        let mut m = TransparentModem::new(1000, 4, true);
        let mut air = Vec::new();
        let end = m.write(0, &[0; 10], |i| i * 100_000, &mut air);
        assert_eq!((air.len(), m.dropped), (10, 0));
        // The last byte enters when the sixth leaves (the modem holds 4).
        assert_eq!(end, air[5].0);
        assert_eq!(air[9].0, 10_100_000);
    }

    #[test]
    fn the_xbee_modem_answers_each_frame_after_its_rf_time() {
        let statuses = RefCell::new(VecDeque::new());
        let mut m = XBeeModem::new(57_600);
        let mut air = Vec::new();
        // A TX16 frame with frame id 5 and 20 bytes of data.
        let mut frame = vec![0x7E, 0, 25, 0x01, 5, 0, 0, 0];
        frame.extend([0u8; 20]);
        frame.push(0);
        m.write(1_000_000, &frame, &mut air, &statuses);
        let rf_end = 1_000_000 + RF_BACKOFF_NS + (17 + 20) * RF_BYTE_NS + RF_ACK_NS;
        assert_eq!(air.len(), frame.len());
        assert!(air.iter().all(|&(t, _)| t == rf_end));
        let (at, bytes) = statuses.borrow_mut().pop_front().unwrap();
        assert_eq!(at, rf_end + 7 * m.byte_ns);
        assert_eq!(bytes, [0x7E, 0, 3, 0x89, 5, 0, 0x71]);
    }

    #[test]
    fn targets_follow_the_bottleneck() {
        // a: two 255-byte frames at 4000 B/s.
        assert_eq!(SCENARIO_A.ack_target_us(), 127_500);
        // b: two 109-byte API frames at 5760 B/s.
        assert_eq!(SCENARIO_B.ack_target_us(), 37_848);
        // c: two 255-byte frames at 480 B/s.
        assert_eq!(SCENARIO_C.ack_target_us(), 1_062_500);
    }
}
