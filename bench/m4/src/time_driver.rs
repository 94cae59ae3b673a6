//! An embassy-time driver on timer 0, for the downlink workload: the telemetry runtime
//! links embassy-time (the pacing of radios without flow control, reply rate limits), but
//! the workload's device is neither paced nor sent replies, so nothing waits on a timer.
//!
//! `now` is timer 0's count since it started, in embassy-time's ticks; it wraps after
//! 171 s of virtual time, far beyond a run. A wake-up is delivered at once (the workload
//! never schedules one).

use core::task::Waker;

use embassy_time_driver::{Driver, TICK_HZ};

use crate::hw::{SYSCLK_HZ, Timer};

/// The driver: reads timer 0, started by `main` before any workload.
struct Timer0Driver;

impl Driver for Timer0Driver {
    fn now(&self) -> u64 {
        u64::from(u32::MAX - Timer.now()) * TICK_HZ / u64::from(SYSCLK_HZ)
    }

    fn schedule_wake(&self, _at: u64, waker: &Waker) {
        waker.wake_by_ref();
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: Timer0Driver = Timer0Driver);
