//! The downlink's locks on `BasepriRawMutex` (ARMv7-M): its ceiling, the downlink
//! workload with it, and a check that it excludes what it must. SysTick, pended inside a
//! lock, runs after the lock when its priority is below the ceiling and at once when it
//! is above.

use core::sync::atomic::{AtomicBool, Ordering::SeqCst};

use cortex_m::peripheral::SCB;
use cortex_m::peripheral::scb::SystemHandler;
use cortex_m_rt::exception;
use embassy_sync::blocking_mutex::raw::RawMutex;
use pprz_telemetry::mutex::{BasepriRawMutex, Ceiling};

use pprz_bench_common::downlink as dl_workload;
use pprz_bench_common::stream::MESSAGES;

use crate::hw::{Timer, Uart};
use crate::{STREAM_LEN, fail, result, timed_downlink};

/// The ceiling of the measured downlink: priority 0x80.
pub struct BenchCeiling;

// SAFETY: in this firmware only thread mode locks mutexes with this ceiling; the SysTick
// handler below touches nothing but `FIRED`.
unsafe impl Ceiling for BenchCeiling {
    const PRIORITY: u8 = 0x80;
}

/// The measured mutex.
pub type Basepri = BasepriRawMutex<BenchCeiling>;

/// Set by the SysTick handler.
static FIRED: AtomicBool = AtomicBool::new(false);

#[exception]
fn SysTick() {
    FIRED.store(true, SeqCst);
}

/// Fails the run unless SysTick pended inside a lock waits for its end at a priority
/// below the ceiling (0xC0) and runs inside it at a priority above (0x40).
pub fn check(scb: &mut SCB) {
    for (priority, runs_inside) in [(0xC0, false), (0x40, true)] {
        // SAFETY: no priority-based critical section of this firmware involves SysTick;
        // its handler only sets `FIRED`.
        unsafe { scb.set_priority(SystemHandler::SysTick, priority) };
        FIRED.store(false, SeqCst);
        let inside = Basepri::INIT.lock(|| {
            SCB::set_pendst();
            cortex_m::asm::dsb();
            cortex_m::asm::isb();
            FIRED.load(SeqCst)
        });
        cortex_m::asm::isb();
        if inside != runs_inside || !FIRED.load(SeqCst) {
            fail(if runs_inside {
                "basepri: an exception above the ceiling waited for the lock"
            } else {
                "basepri: an exception below the ceiling ran inside the lock"
            });
        }
    }
}

/// The downlink workload (workload 3) with its locks on [`Basepri`].
pub fn workload(out: &mut Uart, timer: &Timer) {
    let (stats, sink, arena, t) = timed_downlink::<Basepri>(timer, dl_workload::run_downlink);
    if stats.sent as usize != MESSAGES || sink.bytes as usize != STREAM_LEN || arena.live != 0 {
        fail("downlink, BASEPRI");
    }
    result(
        out,
        "downlink-basepri",
        t,
        MESSAGES,
        "message",
        "the same with BasepriRawMutex (interrupts above its ceiling never masked)",
    );
}
