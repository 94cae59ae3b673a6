//! Helpers shared by the device tests: [`block_on`] for the host adapters (real
//! time), [`mock_time`] and [`run`] for the simulated radio (embassy-time's mock
//! clock). Each test binary uses a part of them.

#![allow(dead_code)]

use std::future::Future;
use std::pin::pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::task::{Context, Poll, Wake, Waker};
use std::thread::{self, Thread};
use std::time::{Duration, Instant};

struct ThreadWaker {
    thread: Thread,
    woken: AtomicBool,
}

impl Wake for ThreadWaker {
    fn wake(self: Arc<Self>) {
        self.woken.store(true, Ordering::SeqCst);
        self.thread.unpark();
    }
}

/// Runs `fut` on this thread, polling only after a wake-up; panics after 10 s
/// without completion.
pub fn block_on<F: Future>(fut: F) -> F::Output {
    let state = Arc::new(ThreadWaker {
        thread: thread::current(),
        woken: AtomicBool::new(false),
    });
    let waker = Waker::from(state.clone());
    let mut cx = Context::from_waker(&waker);
    let mut fut = pin!(fut);
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
            return v;
        }
        while !state.woken.swap(false, Ordering::SeqCst) {
            let now = Instant::now();
            assert!(now < deadline, "not woken within 10 s");
            thread::park_timeout(deadline - now);
        }
    }
}

/// The mock clock is global to a test binary: tests take this lock.
static MOCK_TIME: Mutex<()> = Mutex::new(());

/// Takes the mock clock and restarts it at 0.
pub fn mock_time() -> MutexGuard<'static, ()> {
    let guard = MOCK_TIME.lock().unwrap_or_else(|e| e.into_inner());
    embassy_time::MockDriver::get().reset();
    guard
}

/// Wakes by setting a flag.
struct Flag(AtomicBool);

impl Wake for Flag {
    fn wake(self: Arc<Self>) {
        self.0.store(true, Ordering::SeqCst);
    }
}

/// Polls `fut` to completion like an executor: again at once while it was woken,
/// otherwise after advancing mock time by `step`; panics after `max_steps` steps.
pub fn run<F: Future>(fut: F, step: embassy_time::Duration, max_steps: u64) -> F::Output {
    let flag = Arc::new(Flag(AtomicBool::new(false)));
    let waker = Waker::from(flag.clone());
    let mut cx = Context::from_waker(&waker);
    let mut fut = pin!(fut);
    for _ in 0..max_steps {
        loop {
            flag.0.store(false, Ordering::SeqCst);
            if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
                return v;
            }
            if !flag.0.load(Ordering::SeqCst) {
                break;
            }
        }
        embassy_time::MockDriver::get().advance(step);
    }
    panic!("simulation did not finish in {max_steps} steps");
}
