//! The simulation's time: embassy-time's mock clock, advanced by a thread to follow
//! wall-clock time (faster with `--speed`).

use std::time::{Duration as StdDuration, Instant as StdInstant};

use embassy_time::{Duration, MockDriver};

/// Advances the mock clock to follow wall-clock time times `speed`.
///
/// The clock moves in steps (about 0.5 ms of simulated time up to `--speed 5`, more
/// above), and a task woken within a step runs at its end: a writer whose write ended
/// early in a step starts its next write late, so a UART that the writer alone keeps
/// busy idles up to a step per frame (a few percent of its time at `--speed 5` or less).
pub fn pace(speed: f64) {
    // Wall-clock time between steps: 500 µs at normal speed, down to 100 µs.
    let nap = StdDuration::from_micros((500.0 / speed).clamp(100.0, 500.0) as u64);
    std::thread::spawn(move || {
        let start = StdInstant::now();
        let mut simulated_us: u64 = 0;
        loop {
            std::thread::sleep(nap);
            let target = (start.elapsed().as_secs_f64() * speed * 1e6) as u64;
            if target > simulated_us {
                MockDriver::get().advance(Duration::from_micros(target - simulated_us));
                simulated_us = target;
            }
        }
    });
}
