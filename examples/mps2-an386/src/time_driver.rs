//! An embassy-time driver on the Cortex-M SysTick timer.
//!
//! SysTick interrupts once per tick (`embassy_time_driver::TICK_HZ`, 1 kHz here: 25 000
//! cycles of the 25 MHz core clock); the handler extends the count to 64 bits, so time
//! never wraps, and wakes the timers that expired. Timers wait in
//! `embassy-time-queue-utils`' queue, integrated into the executor's tasks (one entry per
//! task, no fixed capacity).
//!
//! Resolution is one tick: a timer fires on the first tick at or after its deadline.
//!
//! Time is the count of SysTick interrupts taken. On hardware none is lost (critical
//! sections are far shorter than a tick). Under QEMU, ticks that fall due while the
//! emulator is starved of host CPU coalesce into one pending interrupt, so the guest
//! clock can lag the wall clock on a loaded host; the firmware keeps QEMU light by
//! sleeping with WFI (see `main.rs`).

use core::cell::RefCell;
use core::task::Waker;

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use critical_section::Mutex;
use embassy_time_driver::{Driver, TICK_HZ};
use embassy_time_queue_utils::Queue;

/// The driver's state, shared by the SysTick handler and the tasks.
struct State {
    /// Ticks since [`init`].
    ticks: u64,
    /// The next tick at which a timer expires (`u64::MAX`: none).
    alarm: u64,
    /// The timers.
    queue: Queue,
}

/// The SysTick time driver.
struct SysTickDriver {
    state: Mutex<RefCell<State>>,
}

impl SysTickDriver {
    const fn new() -> Self {
        Self {
            state: Mutex::new(RefCell::new(State {
                ticks: 0,
                alarm: u64::MAX,
                queue: Queue::new(),
            })),
        }
    }

    /// One tick passed: count it and wake the timers that expired.
    fn on_tick(&self) {
        critical_section::with(|cs| {
            let mut state = self.state.borrow_ref_mut(cs);
            state.ticks += 1;
            if state.ticks >= state.alarm {
                let now = state.ticks;
                state.alarm = state.queue.next_expiration(now);
            }
        });
    }
}

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| self.state.borrow_ref(cs).ticks)
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            let mut state = self.state.borrow_ref_mut(cs);
            if state.queue.schedule_wake(at, waker) {
                // The earliest deadline may have changed (and may already be past: then
                // `next_expiration` wakes the task right away).
                let now = state.ticks;
                state.alarm = state.queue.next_expiration(now);
            }
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver::new());

/// Starts the clock: SysTick on the core clock of `sysclk_hz`, one interrupt per tick.
///
/// # Panics
///
/// If `sysclk_hz` is not a multiple of the tick rate or gives a reload value SysTick's
/// 24 bits cannot hold (a board configuration error).
pub fn init(mut syst: SYST, sysclk_hz: u32) {
    let cycles_per_tick = u64::from(sysclk_hz) / TICK_HZ;
    assert!(
        cycles_per_tick * TICK_HZ == u64::from(sysclk_hz)
            && (1..=1 << 24).contains(&cycles_per_tick),
        "the core clock must be a multiple of the tick rate, within SysTick's range"
    );
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(cycles_per_tick as u32 - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// The SysTick exception handler's body.
pub fn on_systick() {
    DRIVER.on_tick();
}
