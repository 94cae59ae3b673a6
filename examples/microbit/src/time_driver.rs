//! An embassy-time driver on the nRF51's TIMER0, tickless.
//!
//! TIMER0 counts microseconds (the 16 MHz clock, prescaler 4) in 32 bits and runs
//! freely; the driver extends the count to 64 bits, so time never wraps, and keeps its
//! compare channel 0 on the earliest timer. The interrupt comes only when a timer
//! expires (or, with no timer pending, every 2^30 µs, about 18 minutes, so that the
//! 32-bit count is read at least once per wrap), not once per tick: the guest sleeps
//! between timers, which keeps QEMU light. Timers wait in `embassy-time-queue-utils`'
//! queue, integrated into the executor's tasks (one entry per task, no fixed capacity).
//!
//! The count is read with the CAPTURE task (the TIMER has no counter register): CAPTURE1
//! copies it into CC1. The nRF51 has no RTC in QEMU's model, so the TIMER is also the
//! choice that runs both there and on the chip (where it keeps the 16 MHz clock on).
//!
//! Every piece of state is read and written in critical sections: no atomic
//! read-modify-write is needed (the Cortex-M0 has none).

use core::cell::RefCell;
use core::task::Waker;

use cortex_m::peripheral::NVIC;
use critical_section::Mutex;
use embassy_time_driver::{Driver, TICK_HZ};
use embassy_time_queue_utils::Queue;

use crate::board::Irq;

/// TIMER0's register block.
const TIMER0_BASE: usize = 0x4000_8000;

/// The TIMER registers used here (offsets from the block's base; all 32 bits wide).
#[derive(Debug, Clone, Copy)]
#[repr(usize)]
enum Reg {
    /// Write 1: start counting.
    TasksStart = 0x000,
    /// Write 1: stop counting.
    TasksStop = 0x004,
    /// Write 1: reset the count to 0.
    TasksClear = 0x00C,
    /// Write 1: copy the count into CC1.
    TasksCapture1 = 0x044,
    /// The count reached CC0 (1); write 0 to clear.
    EventsCompare0 = 0x140,
    /// Write 1s: enable those interrupts (COMPARE0 is bit 16).
    IntenSet = 0x304,
    /// Write 1s: disable those interrupts.
    IntenClr = 0x308,
    /// 0: timer (counts the prescaled clock).
    Mode = 0x504,
    /// 3: 32 bits.
    BitMode = 0x508,
    /// The clock is 16 MHz >> PRESCALER.
    Prescaler = 0x510,
    /// Compare channel 0: the alarm.
    Cc0 = 0x540,
    /// Compare channel 1: where CAPTURE1 puts the count.
    Cc1 = 0x544,
}

const INT_COMPARE0: u32 = 1 << 16;
const BITMODE_32: u32 = 3;
/// 16 MHz >> 4 = 1 MHz.
const PRESCALER_1MHZ: u32 = 4;
/// The farthest the alarm is set ahead of now, in µs (ticks): well within a wrap of the
/// 32-bit count, so that the count is extended at least once per wrap.
const MAX_AHEAD: u64 = 1 << 30;

fn read(reg: Reg) -> u32 {
    // Safety: TIMER0's registers are mapped for the whole program on the nRF51
    // (0x4000_8000, QEMU `nrf51_soc.c`); `reg` is an aligned 32-bit register of it, and
    // only this module accesses them. A volatile read has no effect on Rust-visible
    // memory.
    unsafe { core::ptr::read_volatile((TIMER0_BASE + reg as usize) as *const u32) }
}

fn write(reg: Reg, value: u32) {
    // Safety: as in `read`; a volatile write has no effect on Rust-visible memory.
    unsafe { core::ptr::write_volatile((TIMER0_BASE + reg as usize) as *mut u32, value) }
}

/// The driver's state, shared by the interrupt handler and the tasks.
struct State {
    /// The 32-bit count when last read.
    last: u32,
    /// Microseconds since [`init`], as of `last`.
    now: u64,
    /// The time of the earliest timer (`u64::MAX`: none).
    alarm: u64,
    /// The timers.
    queue: Queue,
}

impl State {
    /// Reads the count and extends it to 64 bits. Correct as long as it is called at
    /// least once per wrap of the 32-bit count (71 minutes): the alarm sees to it.
    fn now(&mut self) -> u64 {
        write(Reg::TasksCapture1, 1);
        let count = read(Reg::Cc1);
        self.now += u64::from(count.wrapping_sub(self.last));
        self.last = count;
        self.now
    }

    /// Sets compare channel 0 to the alarm, or [`MAX_AHEAD`] from now if it is later.
    /// If the compare time has already passed when it is set (a count never comes back
    /// to it before wrapping), pends the interrupt, whose handler expires the timers.
    fn arm(&mut self) {
        let now = self.now();
        if self.alarm <= now {
            NVIC::pend(Irq::Timer0);
            return;
        }
        let ahead = (self.alarm - now).min(MAX_AHEAD) as u32;
        let at = self.last.wrapping_add(ahead);
        write(Reg::Cc0, at);
        // The count may have reached `at` while it was written.
        write(Reg::TasksCapture1, 1);
        let left = at.wrapping_sub(read(Reg::Cc1)) as i32;
        if left <= 0 {
            NVIC::pend(Irq::Timer0);
        }
    }
}

/// The TIMER0 time driver.
struct Timer0Driver {
    state: Mutex<RefCell<State>>,
}

impl Timer0Driver {
    const fn new() -> Self {
        Self {
            state: Mutex::new(RefCell::new(State {
                last: 0,
                now: 0,
                alarm: u64::MAX,
                queue: Queue::new(),
            })),
        }
    }

    /// Runs `f` on the state, in a critical section.
    fn with<R>(&self, f: impl FnOnce(&mut State) -> R) -> R {
        critical_section::with(|cs| f(&mut self.state.borrow_ref_mut(cs)))
    }

    /// The compare interrupt: wake the timers that expired and arm for the next one.
    fn on_interrupt(&self) {
        write(Reg::EventsCompare0, 0);
        self.with(|state| {
            let now = state.now();
            state.alarm = state.queue.next_expiration(now);
            state.arm();
        });
    }
}

impl Driver for Timer0Driver {
    fn now(&self) -> u64 {
        self.with(|state| state.now())
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        self.with(|state| {
            if state.queue.schedule_wake(at, waker) {
                // The earliest deadline may have changed (and may already be past: then
                // `next_expiration` wakes the task right away).
                let now = state.now();
                state.alarm = state.queue.next_expiration(now);
                state.arm();
            }
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: Timer0Driver = Timer0Driver::new());

/// Starts the clock: TIMER0 in 32-bit timer mode at 1 MHz from 0, its compare interrupt
/// enabled (the board unmasks IRQ 8 in the NVIC).
pub fn init() {
    const _: () = assert!(TICK_HZ == 1_000_000, "TIMER0 counts microseconds");
    write(Reg::TasksStop, 1);
    write(Reg::Mode, 0);
    write(Reg::BitMode, BITMODE_32);
    write(Reg::Prescaler, PRESCALER_1MHZ);
    write(Reg::IntenClr, !0);
    write(Reg::EventsCompare0, 0);
    write(Reg::TasksClear, 1);
    write(Reg::IntenSet, INT_COMPARE0);
    write(Reg::TasksStart, 1);
    DRIVER.with(|state| {
        state.last = 0;
        state.now = 0;
        state.arm();
    });
}

/// TIMER0's interrupt handler's body.
pub fn on_interrupt() {
    DRIVER.on_interrupt();
}
