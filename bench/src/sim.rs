//! The simulation shared by the overload and radio workloads: event-driven mock time,
//! the priority levels, and the fixed, tagged traffic of an autopilot.

use std::cell::RefCell;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::future::Future;
use std::pin::pin;
use std::task::{Context, Poll, Waker};

use embassy_time::{Duration, Instant, MockDriver, Timer};
use pprz_default::messages::telemetry::{
    Alive, Attitude, AutopilotVersion, DatalinkReport, DlValue, Energy, GpsInt, Ins, Payload,
    RotorcraftFp, RotorcraftStatus,
};
use pprz_messages::{Chars, Message, VarArray, priority};

/// The status messages of the `default` mode of `telemetry.xml` (priority 128): name,
/// period and phase in ms. Phases are staggered 100 ms apart (0, 100, 200, ... modulo the
/// period) as the generator does when none is given; ENERGY's phase is the configured
/// 0.5 s.
pub const STATUS: [(&str, u64, u64); 9] = [
    ("ALIVE", 2100, 0),
    ("ROTORCRAFT_STATUS", 1200, 100),
    ("ROTORCRAFT_FP", 250, 200),
    ("ATTITUDE", 250, 50),
    ("GPS_INT", 250, 150),
    ("INS", 250, 0),
    ("ENERGY", 2500, 500),
    ("DATALINK_REPORT", 5100, 700),
    ("AUTOPILOT_VERSION", 11_100, 800),
];

/// The three fundamental priority levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Level {
    /// Acknowledgements (priority 192 and above).
    High,
    /// Flight status telemetry (128..192).
    Normal,
    /// Payload and debug (below 128).
    Low,
}

impl Level {
    /// Every level, most important first.
    pub const ALL: [Level; 3] = [Level::High, Level::Normal, Level::Low];

    /// The level of a priority.
    pub const fn of(priority: u8) -> Level {
        if priority >= priority::HIGH {
            Level::High
        } else if priority >= priority::NORMAL {
            Level::Normal
        } else {
            Level::Low
        }
    }

    pub(crate) const fn index(self) -> usize {
        self as usize
    }

    /// A short label.
    pub const fn label(self) -> &'static str {
        match self {
            Level::High => "high (acks)",
            Level::Normal => "normal (status)",
            Level::Low => "low (payload)",
        }
    }
}

// ---------------------------------------------------------------------------------------
// Event-driven mock time.

/// The mock clock is global: simulations take this lock.
pub(crate) static MOCK_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

pub(crate) fn now_us() -> u64 {
    Instant::now().as_micros()
}

/// The deadlines the simulated tasks wait for.
#[derive(Default)]
pub(crate) struct Agenda(RefCell<BinaryHeap<Reverse<u64>>>);

impl Agenda {
    pub(crate) async fn sleep_until(&self, t_us: u64) {
        self.0.borrow_mut().push(Reverse(t_us));
        Timer::at(Instant::from_micros(t_us)).await;
    }

    /// Polls `fut` to completion, jumping the mock clock from deadline to deadline.
    pub(crate) fn run<F: Future>(&self, fut: F) -> F::Output {
        let mut fut = pin!(fut);
        let mut cx = Context::from_waker(Waker::noop());
        loop {
            if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
                return v;
            }
            let now = now_us();
            let next = loop {
                match self.0.borrow_mut().pop() {
                    Some(Reverse(t)) if t <= now => {}
                    Some(Reverse(t)) => break t,
                    None => panic!("simulation stalled at {now} µs: nothing to wait for"),
                }
            };
            MockDriver::get().advance(Duration::from_micros(next - now));
        }
    }
}

/// Nearest-rank percentile `p` (0..=100) of sorted `values`.
pub(crate) fn percentile(values: &[u64], p: u64) -> Option<u64> {
    let n = values.len() as u64;
    if n == 0 {
        return None;
    }
    let rank = (p * n).div_ceil(100).max(1);
    values.get(rank as usize - 1).copied()
}

/// µs as ms with one decimal, `-` for none (the tables of the workloads).
pub(crate) fn ms(us: Option<u64>) -> String {
    us.map_or_else(|| "-".to_owned(), |us| format!("{:.1}", us as f64 / 1000.0))
}

/// Where the traffic goes.
pub trait Submit {
    /// `msg` is submitted now; `state`: it is a periodic state sample (a newer one may
    /// take its place), else an event (acknowledgement, payload).
    fn submit<M: Message>(&mut self, state: bool, msg: &M);
}

/// The traffic's messages: every one carries a unique tag in one of its fields, so every
/// frame on the wire is traced back to its submission.
#[derive(Debug, Default)]
pub struct Traffic {
    tag: u32,
}

impl Traffic {
    /// The status messages and acknowledgement due at `ms` (acknowledgements every
    /// `ack_period_ms`, the first at half a period; status at [`STATUS`]).
    pub fn tick<S: Submit>(&mut self, ms: u64, ack_period_ms: u64, out: &mut S) {
        if ms % ack_period_ms == ack_period_ms / 2 {
            self.ack(out);
        }
        for (which, &(_, period, phase)) in STATUS.iter().enumerate() {
            if ms % period == phase {
                self.status(which, out);
            }
        }
    }

    fn next_tag(&mut self) -> u32 {
        self.tag += 1;
        self.tag
    }

    /// Submits status message `which` (an index into [`STATUS`]) to `out`.
    pub fn status<S: Submit>(&mut self, which: usize, out: &mut S) {
        let tag = self.next_tag();
        let t = tag as f32;
        match which {
            0 => {
                let mut md5 = [0u8; 16];
                md5[..4].copy_from_slice(&tag.to_le_bytes());
                out.submit(
                    true,
                    &Alive {
                        md5sum: VarArray::new(&md5),
                    },
                );
            }
            1 => out.submit(
                true,
                &RotorcraftStatus {
                    link_imu_nb_err: tag,
                    frame_rate: 100,
                    vsupply: 16.4,
                    ..Default::default()
                },
            ),
            2 => out.submit(
                true,
                &RotorcraftFp {
                    east: tag as i32,
                    up: 2560,
                    flight_time: (tag / 16) as u16,
                    ..Default::default()
                },
            ),
            3 => out.submit(
                true,
                &Attitude {
                    phi: t,
                    psi: 0.5,
                    theta: -0.1,
                },
            ),
            4 => out.submit(
                true,
                &GpsInt {
                    tow: tag,
                    numsv: 12,
                    fix: 3,
                    ..Default::default()
                },
            ),
            5 => out.submit(
                true,
                &Ins {
                    ins_x: tag as i32,
                    ..Default::default()
                },
            ),
            6 => out.submit(
                true,
                &Energy {
                    voltage: 16.2,
                    charge: t,
                    ..Default::default()
                },
            ),
            7 => out.submit(
                true,
                &DatalinkReport {
                    uplink_nb_msgs: tag as u16,
                    downlink_nb_msgs: (tag >> 16) as u16,
                    ..Default::default()
                },
            ),
            _ => out.submit(
                true,
                &AutopilotVersion {
                    version: tag,
                    desc: Chars::from_str("pprz-embassy 0.1.0"),
                },
            ),
        }
    }

    /// Submits an acknowledgement (DL_VALUE) to `out`.
    pub fn ack<S: Submit>(&mut self, out: &mut S) {
        let tag = self.next_tag();
        out.submit(
            false,
            &DlValue {
                index: tag as u8,
                value: tag as f32,
            },
        );
    }

    /// Submits a PAYLOAD message of `values` bytes to `out`.
    pub fn payload<S: Submit>(&mut self, values: usize, out: &mut S) {
        let tag = self.next_tag();
        let mut bytes = [0x5Au8; 255];
        bytes[..4].copy_from_slice(&tag.to_le_bytes());
        out.submit(
            false,
            &Payload {
                values: VarArray::new(&bytes[..values]),
            },
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_follow_the_fundamental_priorities() {
        assert_eq!(Level::of(DlValue::PRIORITY), Level::High);
        assert_eq!(Level::of(Attitude::PRIORITY), Level::Normal);
        assert_eq!(Level::of(Payload::PRIORITY), Level::Low);
    }
}
