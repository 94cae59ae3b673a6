//! The periodic telemetry scheduler: exact firing counts over a simulated minute for
//! several periods and phases (by `tick()` and by the `run` task under embassy-time's
//! mock clock), mode switching (from the ground's setting and from a callback), phase
//! staggering of the generated schedules, several callbacks per message, per-process
//! callbacks, and callbacks sending on a real downlink.
//!
//! The active modes live in a `Modes` the scheduler reads (and the ground writes through
//! the settings table); each test builds one next to its scheduler.
//!
//! No wall-clock timing: `run` is polled by hand while the mock clock is advanced.

use std::future::Future;
use std::pin::{Pin, pin};
use std::sync::Mutex as StdMutex;
use std::sync::atomic::{AtomicU32, Ordering};
use std::task::{Context, Waker};

use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, NoopRawMutex};
use embassy_time::{Duration, Instant, MockDriver};
use pprz_default::messages::telemetry::{Alive, Attitude, Pong};
use pprz_default::periodic::{self, main};
use pprz_telemetry::pprz_messages::Message;
use pprz_telemetry::pprz_transports::PprzV2;
use pprz_telemetry::scheduler::{
    ModeError, Modes, Periodic, Process, Registered, Schedule, Scheduler, SchedulerFull,
};
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena};

/// The tables pprz-codegen's snapshot test generates from its `ok.xml` fixture (two
/// processes, explicit and automatic phases), compiled against this runtime here.
#[allow(dead_code)]
mod snapshot {
    include!("../../codegen/tests/snapshots/periodic.rs");
}

/// The mock clock is global: tests that use it run one at a time.
static MOCK_TIME: StdMutex<()> = StdMutex::new(());

const fn msg(name: &'static str, msg_id: u8, period: u32, phase: u32) -> Periodic<'static> {
    Periodic {
        name,
        class_id: 1,
        msg_id,
        period_ticks: period,
        phase_ticks: phase,
        period_s: period as f32 / 60.0,
    }
}

/// (period ticks, phase ticks, firings over 3600 ticks = one minute at 60 Hz).
const COMBOS: [(u32, u32, u32); 12] = [
    (1, 0, 3600),
    (3, 0, 1200),
    (3, 2, 1200),
    (7, 6, 514),
    (15, 7, 240),
    (126, 0, 29),
    (126, 100, 28),
    (306, 42, 12),
    (3600, 3599, 1),
    (4000, 0, 1),
    (4000, 3700, 0),
    // A phase past the period is taken modulo the period (13 -> 3).
    (10, 13, 360),
];

static COMBO_MESSAGES: [Periodic<'static>; 12] = {
    let mut m = [msg("", 0, 1, 0); 12];
    let mut i = 0;
    while i < COMBOS.len() {
        m[i] = msg("COMBO", 100 + i as u8, COMBOS[i].0, COMBOS[i].1);
        i += 1;
    }
    m
};

static COMBO_SCHEDULE: Schedule<'static> = Schedule {
    frequency_hz: 60,
    processes: &[Process {
        name: "Main",
        modes: &[pprz_telemetry::scheduler::Mode {
            name: "all",
            key_press: None,
            messages: &COMBO_MESSAGES,
        }],
    }],
};

/// Registers one counting callback per combo message.
fn count_combos<'a>(
    scheduler: &Scheduler<'a, NoopRawMutex, 1, 16>,
    callbacks: &'a [Box<dyn Fn() + Sync + 'a>],
) {
    for (i, cb) in callbacks.iter().enumerate() {
        let r = scheduler.register((1, 100 + i as u8), &**cb).unwrap();
        assert_eq!(r, Registered { modes: 1 });
    }
}

fn counters_and_callbacks(counters: &[AtomicU32; 12]) -> Vec<Box<dyn Fn() + Sync + '_>> {
    counters
        .iter()
        .map(|c| {
            Box::new(move || {
                c.fetch_add(1, Ordering::Relaxed);
            }) as Box<dyn Fn() + Sync>
        })
        .collect()
}

fn assert_combo_counts(counters: &[AtomicU32; 12]) {
    for (&(period, phase, expected), c) in COMBOS.iter().zip(counters) {
        assert_eq!(
            c.load(Ordering::Relaxed),
            expected,
            "period {period} ticks, phase {phase}"
        );
    }
}

#[test]
fn exact_counts_over_a_minute_per_period_and_phase() {
    let counters: [AtomicU32; 12] = Default::default();
    let callbacks = counters_and_callbacks(&counters);
    let modes = Modes::new(&COMBO_SCHEDULE);
    let scheduler: Scheduler<'_, NoopRawMutex, 1, 16> = Scheduler::new(&modes);
    count_combos(&scheduler, &callbacks);
    for t in 0..3600 {
        let report = scheduler.tick();
        assert_eq!(report.tick, t);
        assert_eq!(report.due, report.calls);
    }
    assert_combo_counts(&counters);
    let stats = scheduler.stats();
    let total: u32 = COMBOS.iter().map(|c| c.2).sum();
    assert_eq!(stats.ticks, 3600);
    assert_eq!(
        (stats.due, stats.calls),
        (u64::from(total), u64::from(total))
    );
    assert_eq!((stats.callbacks, stats.unscheduled), (12, 0));
}

/// Polls `fut` (which never completes) until it stops making progress at the current
/// mock time: a timer in the past still yields once, so a late scheduler catches up over
/// several polls, as an executor would poll it.
fn poll_idle<F: Future<Output = ()>>(fut: &mut Pin<&mut F>, ticks: impl Fn() -> u64) {
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        let before = ticks();
        for _ in 0..2 {
            assert!(fut.as_mut().poll(&mut cx).is_pending());
        }
        if ticks() == before {
            return;
        }
    }
}

#[test]
fn run_task_under_mock_time_fires_exactly_per_simulated_minute() {
    let _serial = MOCK_TIME.lock().unwrap_or_else(|e| e.into_inner());
    MockDriver::get().reset();
    let counters: [AtomicU32; 12] = Default::default();
    let callbacks = counters_and_callbacks(&counters);
    let modes = Modes::new(&COMBO_SCHEDULE);
    let scheduler: Scheduler<'_, NoopRawMutex, 1, 16> = Scheduler::new(&modes);
    count_combos(&scheduler, &callbacks);
    let start = Instant::now();
    let run = async {
        scheduler.run().await;
    };
    let mut run = pin!(run);
    let ticks = || scheduler.stats().ticks;
    poll_idle(&mut run, ticks);
    assert_eq!(ticks(), 0, "the first tick is one period after the start");
    // Advance 1 ms at a time up to just before one minute: tick k runs at k/60 s.
    while Instant::now() + Duration::from_millis(1) < start + Duration::from_secs(60) {
        MockDriver::get().advance(Duration::from_millis(1));
        poll_idle(&mut run, ticks);
        // Tick k (from 1) is due at floor(k * TICK_HZ / 60) timer ticks after the start.
        let e = (Instant::now() - start).as_ticks();
        assert_eq!(ticks(), (60 * (e + 1) - 1) / embassy_time::TICK_HZ);
    }
    MockDriver::get()
        .advance(start + Duration::from_secs(60) - Instant::now() - Duration::from_micros(1));
    poll_idle(&mut run, ticks);
    assert_eq!(ticks(), 3599);
    MockDriver::get().advance(Duration::from_micros(1));
    poll_idle(&mut run, ticks);
    assert_eq!(ticks(), 3600, "tick 3600 is due at exactly 60 s");
    assert_combo_counts(&counters);
}

#[test]
fn run_task_does_not_drift_and_catches_up() {
    // 512 Hz does not divide the 1 MHz timer: a Ticker of Duration::from_hz(512) would
    // tick every 1953 µs and gain 0.125 µs per tick; the task keeps exact time.
    static MESSAGES: [Periodic<'static>; 2] = [msg("SECOND", 1, 512, 0), msg("EVERY", 2, 1, 0)];
    static SCHEDULE: Schedule<'static> = Schedule {
        frequency_hz: 512,
        processes: &[Process {
            name: "Main",
            modes: &[pprz_telemetry::scheduler::Mode {
                name: "m",
                key_press: None,
                messages: &MESSAGES,
            }],
        }],
    };
    let _serial = MOCK_TIME.lock().unwrap_or_else(|e| e.into_inner());
    MockDriver::get().reset();
    let seconds = AtomicU32::new(0);
    let count = || {
        seconds.fetch_add(1, Ordering::Relaxed);
    };
    let modes = Modes::new(&SCHEDULE);
    let scheduler: Scheduler<'_, NoopRawMutex, 1, 4> = Scheduler::new(&modes);
    assert!(scheduler.register("SECOND", &count).unwrap().is_scheduled());
    let run = async {
        scheduler.run().await;
    };
    let mut run = pin!(run);
    let ticks = || scheduler.stats().ticks;
    poll_idle(&mut run, ticks);
    // One late wake-up after a whole second: the 512 missed ticks run at once.
    MockDriver::get().advance(Duration::from_secs(1));
    poll_idle(&mut run, ticks);
    assert_eq!(ticks(), 512);
    for _ in 1..60 {
        MockDriver::get().advance(Duration::from_millis(250));
        poll_idle(&mut run, ticks);
        MockDriver::get().advance(Duration::from_millis(750) - Duration::from_micros(1));
        poll_idle(&mut run, ticks);
        MockDriver::get().advance(Duration::from_micros(1));
        poll_idle(&mut run, ticks);
    }
    assert_eq!(ticks(), 60 * 512);
    assert_eq!(scheduler.stats().calls, 60);
    assert_eq!(seconds.load(Ordering::Relaxed), 60);
}

/// Two modes sharing X (same period and phase), Y only in A, Z only in B, W every tick in
/// A (after X in the list).
static MODES_SCHEDULE: Schedule<'static> = Schedule {
    frequency_hz: 60,
    processes: &[Process {
        name: "Main",
        modes: &[
            pprz_telemetry::scheduler::Mode {
                name: "a",
                key_press: Some("a"),
                messages: &[msg("X", 1, 10, 0), msg("Y", 2, 6, 3), msg("W", 4, 1, 0)],
            },
            pprz_telemetry::scheduler::Mode {
                name: "b",
                key_press: None,
                messages: &[msg("X", 1, 10, 0), msg("Z", 3, 4, 1)],
            },
        ],
    }],
};

/// A log of (tick, message id) firings.
struct Log {
    scheduler_tick: AtomicU32,
    fired: StdMutex<Vec<(u32, u8)>>,
}

impl Log {
    fn new() -> Self {
        Self {
            scheduler_tick: AtomicU32::new(0),
            fired: StdMutex::new(Vec::new()),
        }
    }
    fn push(&self, id: u8) {
        let t = self.scheduler_tick.load(Ordering::Relaxed);
        self.fired.lock().unwrap().push((t, id));
    }
    fn ticks_of(&self, id: u8) -> Vec<u32> {
        let fired = self.fired.lock().unwrap();
        fired
            .iter()
            .filter(|(_, i)| *i == id)
            .map(|(t, _)| *t)
            .collect()
    }
}

#[test]
fn mode_switching_is_immediate_and_keeps_shared_cadence() {
    let log = Log::new();
    let cbs: Vec<Box<dyn Fn() + Sync + '_>> = (1..=4u8)
        .map(|id| {
            let log = &log;
            Box::new(move || log.push(id)) as Box<dyn Fn() + Sync>
        })
        .collect();
    let modes: Modes<'_, 1> = Modes::new(&MODES_SCHEDULE);
    let scheduler: Scheduler<'_, CriticalSectionRawMutex, 1, 8> = Scheduler::new(&modes);
    assert!(std::ptr::eq(scheduler.modes(), &modes));
    for (i, cb) in cbs.iter().enumerate() {
        let r = scheduler.register((1, i as u8 + 1), &**cb).unwrap();
        assert_eq!(r.modes, if i == 0 { 2 } else { 1 });
    }
    assert_eq!(modes.mode(0), Some(0));
    let run = |from: u32, to: u32| {
        for t in from..to {
            log.scheduler_tick.store(t, Ordering::Relaxed);
            assert_eq!(scheduler.tick().tick, u64::from(t));
        }
    };
    run(0, 1000);
    // From the ground: the mode setting of process 0 (what SETTING writes).
    let setting = modes.setting(0).unwrap();
    assert_eq!((setting.get(), setting.modes()), (0.0, 2));
    setting.set(1.0).unwrap();
    assert_eq!((modes.mode(0), setting.get()), (Some(1), 1.0));
    run(1000, 2000);
    modes.set_mode_by_name("Main", "a").unwrap();
    run(2000, 3600);

    // X is in both modes with the same period and phase: an unbroken cadence.
    let x = log.ticks_of(1);
    assert_eq!(x, (0..3600).step_by(10).collect::<Vec<_>>());
    // Y (A only): t % 6 == 3 outside 1000..2000; Z (B only): t % 4 == 1 inside.
    let y = log.ticks_of(2);
    let expected_y: Vec<u32> = (0..3600)
        .filter(|t| t % 6 == 3 && !(1000..2000).contains(t))
        .collect();
    assert_eq!(y, expected_y);
    assert_eq!((y.len(), y[166], y[167]), (167 + 267, 999, 2001));
    let z = log.ticks_of(3);
    assert_eq!((z.len(), z[0], z[z.len() - 1]), (250, 1001, 1997));
    assert_eq!(log.ticks_of(4).len(), 1000 + 1600);

    // Invalid changes are refused and change nothing.
    assert_eq!(modes.set_mode(0, 2), Err(ModeError::UnknownMode));
    assert_eq!(modes.set_mode(1, 0), Err(ModeError::UnknownProcess));
    assert_eq!(
        modes.set_mode_by_name("Main", "c"),
        Err(ModeError::UnknownMode)
    );
    assert_eq!(
        modes.set_mode_by_name("Ap", "a"),
        Err(ModeError::UnknownProcess)
    );
    for bad in [1.5, -1.0, f32::NAN, f32::INFINITY] {
        assert_eq!(setting.set(bad), Err(ModeError::NotAnIndex), "{bad}");
    }
    assert_eq!(setting.set(2.0), Err(ModeError::UnknownMode));
    assert_eq!(modes.mode(0), Some(0));
    assert_eq!(modes.mode(1), None);
    assert_eq!(modes.setting(1).unwrap_err(), ModeError::UnknownProcess);
    // A setting is a small Copy value: the settings table can wrap it in closures.
    let (get, set) = (move || setting.get(), move |v| setting.set(v));
    set(1.0).unwrap();
    assert_eq!(get(), 1.0);
}

#[test]
fn a_switch_from_a_callback_applies_from_the_next_tick() {
    let log = Log::new();
    let modes: Modes<'_, 1> = Modes::new(&MODES_SCHEDULE);
    let scheduler: Scheduler<'_, CriticalSectionRawMutex, 1, 8> = Scheduler::new(&modes);
    let to_b = || {
        log.push(1);
        scheduler.modes().set_mode(0, 1).unwrap();
    };
    let w = || log.push(4);
    let z = || log.push(3);
    let _ = scheduler.register("X", &to_b).unwrap();
    let _ = scheduler.register("W", &w).unwrap();
    let _ = scheduler.register("Z", &z).unwrap();
    for t in 0..6 {
        log.scheduler_tick.store(t, Ordering::Relaxed);
        scheduler.tick();
    }
    // Tick 0 runs mode A to the end (X switches, W still fires); B from tick 1 on.
    assert_eq!(*log.fired.lock().unwrap(), [(0, 1), (0, 4), (1, 3), (5, 3)]);
}

/// Per tick, the (period, message) pairs that fired, for every mode of `process`.
fn firings_per_mode<const C: usize>(
    schedule: &'static Schedule<'static>,
    process: usize,
    ticks: u32,
) -> Vec<Vec<Vec<(u32, &'static str)>>> {
    let fired: StdMutex<Vec<(u8, u8)>> = StdMutex::new(Vec::new());
    let p = &schedule.processes[process];
    let mut ids: Vec<(u8, u8)> = p
        .modes
        .iter()
        .flat_map(|m| m.messages)
        .map(|m| (m.class_id, m.msg_id))
        .collect();
    ids.sort_unstable();
    ids.dedup();
    let callbacks: Vec<Box<dyn Fn() + Sync + '_>> = ids
        .iter()
        .map(|&id| {
            let fired = &fired;
            Box::new(move || fired.lock().unwrap().push(id)) as Box<dyn Fn() + Sync>
        })
        .collect();
    let mut per_mode = Vec::new();
    for (m, mode) in p.modes.iter().enumerate() {
        let modes: Modes<'_, 4> = Modes::new(schedule);
        let scheduler: Scheduler<'_, NoopRawMutex, 4, C> = Scheduler::new(&modes);
        for (&id, cb) in ids.iter().zip(&callbacks) {
            let _ = scheduler.register_in(process, id, &**cb).unwrap();
        }
        modes.set_mode(process, m).unwrap();
        let mut ticks_fired = Vec::new();
        for _ in 0..ticks {
            scheduler.tick();
            let now: Vec<(u32, &str)> = fired
                .lock()
                .unwrap()
                .drain(..)
                .map(|(c, i)| {
                    let x = mode
                        .messages
                        .iter()
                        .find(|x| x.is(c, i))
                        .expect("only messages of the active mode fire");
                    (x.period_ticks, x.name)
                })
                .collect();
            ticks_fired.push(now);
        }
        per_mode.push(ticks_fired);
    }
    per_mode
}

#[test]
fn generated_schedules_never_fire_equal_periods_together() {
    for (schedule, process) in [
        (&periodic::SCHEDULE, main::PROCESS),
        (&snapshot::SCHEDULE, snapshot::main::PROCESS),
        (&snapshot::SCHEDULE, snapshot::logger::PROCESS),
    ] {
        let p = &schedule.processes[process];
        for (m, ticks) in firings_per_mode::<32>(schedule, process, 3600)
            .iter()
            .enumerate()
        {
            let mode = &p.modes[m];
            let mut fired = 0;
            for (t, now) in ticks.iter().enumerate() {
                fired += now.len();
                for (i, a) in now.iter().enumerate() {
                    for b in &now[i + 1..] {
                        // Logger's two messages every tick (period 1) cannot be apart.
                        assert!(
                            a.0 != b.0 || a.0 == 1,
                            "{}.{} tick {t}: {} and {} (period {})",
                            p.name,
                            mode.name,
                            a.1,
                            b.1,
                            a.0
                        );
                    }
                }
            }
            let expected: usize = mode
                .messages
                .iter()
                .map(|x| (0..3600u64).filter(|&t| x.is_due(t)).count())
                .sum();
            assert_eq!(fired, expected, "{}.{}", p.name, mode.name);
        }
    }
}

#[test]
fn staggering_spreads_the_bursts_of_the_default_mode() {
    // The project's default mode, and the same messages with every phase 0.
    let mode = &periodic::SCHEDULE.processes[main::PROCESS].modes[main::MODE_DEFAULT];
    let unstaggered: &'static [Periodic<'static>] = Box::leak(
        mode.messages
            .iter()
            .map(|m| Periodic {
                phase_ticks: 0,
                ..*m
            })
            .collect::<Vec<_>>()
            .into_boxed_slice(),
    );
    let modes: &'static [pprz_telemetry::scheduler::Mode<'static>] =
        Box::leak(Box::new([pprz_telemetry::scheduler::Mode {
            messages: unstaggered,
            ..*mode
        }]));
    let processes: &'static [Process<'static>] = Box::leak(Box::new([Process {
        name: "Main",
        modes,
    }]));
    let naive: &'static Schedule<'static> = Box::leak(Box::new(Schedule {
        frequency_hz: 60,
        processes,
    }));
    // Number of ticks of a minute by number of messages firing on them.
    let histogram = |s: &'static Schedule<'static>, m: usize| {
        let mut h = [0usize; 12];
        for now in &firings_per_mode::<32>(s, 0, 3600)[m] {
            h[now.len()] += 1;
        }
        h
    };
    // Without staggering, all 11 messages start together (and 4 of 0.25 s every time).
    let naive = histogram(naive, 0);
    assert_eq!(naive[11], 1);
    assert_eq!(naive[4..].iter().sum::<usize>(), 240);
    // Staggered: never more than 4 at once (messages of different periods still meet now
    // and then: twice a minute), 3 on 14 ticks, and the 0.25-s messages always apart.
    assert_eq!(
        histogram(&periodic::SCHEDULE, main::MODE_DEFAULT),
        [2609, 845, 130, 14, 2, 0, 0, 0, 0, 0, 0, 0]
    );
}

#[test]
fn several_callbacks_per_message_in_registration_order() {
    let calls: StdMutex<Vec<&str>> = StdMutex::new(Vec::new());
    let (a, b, c, d) = (
        || calls.lock().unwrap().push("a"),
        || calls.lock().unwrap().push("b"),
        || calls.lock().unwrap().push("c"),
        || calls.lock().unwrap().push("d"),
    );
    let modes = Modes::new(&periodic::SCHEDULE);
    let scheduler: Scheduler<'_, NoopRawMutex, 1, 4> = Scheduler::new(&modes);
    // By name, by (class, id) and by type; ALIVE is in all three modes.
    assert_eq!(scheduler.register("ALIVE", &a), Ok(Registered { modes: 3 }));
    assert_eq!(
        scheduler.register((Alive::CLASS_ID, Alive::ID), &b),
        Ok(Registered { modes: 3 })
    );
    assert_eq!(
        scheduler.register_message::<Attitude>(&d),
        Ok(Registered { modes: 2 })
    );
    assert_eq!(
        scheduler.register_message::<Alive>(&c),
        Ok(Registered { modes: 3 })
    );
    // Unscheduled messages are accepted, take no slot, and are counted.
    let none = scheduler.register_message::<Pong>(&a).unwrap();
    assert!(!none.is_scheduled());
    assert_eq!(
        scheduler.register("NOT_A_MESSAGE", &a),
        Ok(Registered { modes: 0 })
    );
    assert_eq!(scheduler.register("ALIVE", &d), Err(SchedulerFull));
    let stats = scheduler.stats();
    assert_eq!((stats.callbacks, stats.unscheduled), (4, 2));

    // ALIVE (phase 0) and ATTITUDE (phase 3, period 15) in the default mode.
    let ticks: Vec<usize> = (0..16).map(|_| scheduler.tick().calls).collect();
    assert_eq!(ticks[0], 3);
    assert_eq!(ticks[3], 1);
    assert_eq!(ticks.iter().sum::<usize>(), 3 + 1);
    assert_eq!(*calls.lock().unwrap(), ["a", "b", "c", "d"]);
    assert_eq!(
        SchedulerFull.to_string(),
        "every callback slot of the scheduler is taken"
    );
}

#[test]
fn callbacks_registered_for_one_process() {
    use snapshot::{logger, main as snap_main};
    let main_calls = AtomicU32::new(0);
    let logger_calls = AtomicU32::new(0);
    let on_main = || {
        main_calls.fetch_add(1, Ordering::Relaxed);
    };
    let on_logger = || {
        logger_calls.fetch_add(1, Ordering::Relaxed);
    };
    let modes: Modes<'_, { snapshot::PROCESSES }> = Modes::new(&snapshot::SCHEDULE);
    let scheduler: Scheduler<'_, NoopRawMutex, { snapshot::PROCESSES }, 4> = Scheduler::new(&modes);
    // ATTITUDE: every 15 ticks (phase 7) in Main's default mode, every tick in Logger's.
    assert_eq!(
        scheduler.register_in(snap_main::PROCESS, "ATTITUDE", &on_main),
        Ok(Registered { modes: 1 })
    );
    assert_eq!(
        scheduler.register_in(logger::PROCESS, "ATTITUDE", &on_logger),
        Ok(Registered { modes: 1 })
    );
    assert_eq!(
        scheduler.register_in(logger::PROCESS, "DL_VALUE", &on_logger),
        Ok(Registered { modes: 0 })
    );
    assert_eq!(
        scheduler.register_in(7, "ATTITUDE", &on_logger),
        Ok(Registered { modes: 0 })
    );
    for _ in 0..3600 {
        scheduler.tick();
    }
    assert_eq!(main_calls.load(Ordering::Relaxed), 240);
    assert_eq!(logger_calls.load(Ordering::Relaxed), 3600);
    modes
        .set_mode(snap_main::PROCESS, snap_main::MODE_OFF)
        .unwrap();
    modes.set_mode(logger::PROCESS, logger::MODE_ALL).unwrap();
    for _ in 0..60 {
        scheduler.tick();
    }
    assert_eq!(main_calls.load(Ordering::Relaxed), 240);
    assert_eq!(logger_calls.load(Ordering::Relaxed), 3660);
}

#[test]
fn callbacks_send_on_the_downlink() {
    let arena: FrameArena<CriticalSectionRawMutex, 2048> = FrameArena::new();
    let downlink: Downlink<'_, CriticalSectionRawMutex, 1, 64> =
        Downlink::new(&arena, 7, [DeviceConfig::new(PprzV2::new().into())]);
    let send_alive = || {
        let _ = downlink.send(&Alive::default());
    };
    let send_attitude = || {
        let _ = downlink.send(&Attitude {
            phi: 0.1,
            psi: 0.2,
            theta: 0.3,
        });
    };
    let modes: Modes<'_, { periodic::PROCESSES }> = Modes::new(&periodic::SCHEDULE);
    let scheduler: Scheduler<'_, CriticalSectionRawMutex, { periodic::PROCESSES }, 8> =
        Scheduler::new(&modes);
    let _ = scheduler.register_message::<Alive>(&send_alive).unwrap();
    let _ = scheduler
        .register_message::<Attitude>(&send_attitude)
        .unwrap();
    // One second of the default mode: ALIVE once (tick 0), ATTITUDE 4 times (3, 18, 33, 48).
    for _ in 0..60 {
        scheduler.tick();
    }
    assert_eq!(downlink.stats(0).unwrap().submitted, 5);
    // Debug mode: ATTITUDE every 0.1 s.
    modes.set_mode(main::PROCESS, main::MODE_DEBUG).unwrap();
    for _ in 0..60 {
        scheduler.tick();
    }
    assert_eq!(downlink.stats(0).unwrap().submitted, 5 + 10);
}

#[test]
fn the_generated_project_schedule() {
    let s = &periodic::SCHEDULE;
    assert_eq!(
        (s.frequency_hz, periodic::FREQUENCY_HZ, periodic::PROCESSES),
        (60, 60, 1)
    );
    let p = &s.processes[main::PROCESS];
    assert_eq!(p.name, "Main");
    assert_eq!(p.mode_index("debug"), Some(main::MODE_DEBUG));
    assert_eq!(p.modes[main::MODE_MINIMAL].key_press, Some("m"));
    let alive = p.modes[main::MODE_DEFAULT].messages[0];
    assert_eq!(
        (
            alive.name,
            alive.class_id,
            alive.msg_id,
            alive.period_ticks,
            alive.period_s
        ),
        ("ALIVE", Alive::CLASS_ID, Alive::ID, 126, 2.1)
    );
    assert_eq!(s.message_id("IMU_GYRO_RAW"), Some((1, 203)));
    assert_eq!(s.modes_with(None, 1, 30), 3);
}
