//! Periodic telemetry: a scheduler that ticks at a fixed frequency and, for the active
//! mode of each process, calls the callbacks registered for each message that is due,
//! like Paparazzi's periodic telemetry.
//!
//! ```text
//!  telemetry.xml ──pprz-codegen──► static Schedule { frequency_hz, processes: [Process { modes: [Mode { messages: [Periodic] }] }] }
//!                                          │
//!  start-up: register("ALIVE", &send_alive)│            ground: SETTING(mode) ──► set_mode(process, mode)
//!                                          ▼                                            │
//!  run(): every 1/frequency s ──► tick(): for each process, its active mode ◄───────────┘
//!                                   for each message due on this tick
//!                                     every callback registered for it ──► downlink.send(&msg)
//! ```
//!
//! # Timing
//! Ticks are counted from 0 since the scheduler started (the first [`tick`] is tick 0).
//! A [`Periodic`] message is due on tick `t` when `t % period_ticks == phase_ticks`,
//! relative to this global tick count. Hence a message fires `period_ticks` ticks apart
//! whatever happens, every process and mode sees the same time base, and over `n` ticks a
//! message fires exactly `ceil((n - phase_ticks) / period_ticks)` times (0 if
//! `n <= phase_ticks`) while its mode is active. (This is the reference firmware's per-message counters, started together and
//! never reset.)
//!
//! [`run`](Scheduler::run) ticks at the schedule's frequency without drift: tick `k` is
//! due `k / frequency_hz` seconds after the start, computed exactly in timer ticks (an
//! embassy-time `Ticker` of `Duration::from_hz` would drift where the timer frequency is
//! not a multiple of the schedule's). When the task is late (a slow callback, a busy
//! executor), the missed ticks run at once, so the tick count stays locked to time.
//!
//! # Modes
//! Each process has an active mode, the first one at start-up, held in a [`Modes`] that
//! the scheduler reads. [`set_mode`] (or the ground, through a [`ModeSetting`] in the
//! settings table) switches it; the switch takes
//! effect from the next tick on (a callback switching modes does not change the tick that
//! is running). Because phases are relative to the global tick count, switching is
//! immediate and deterministic: the messages of the new mode fire on their next due tick,
//! and a message present in both modes with the same period and phase keeps its cadence.
//!
//! # Callbacks
//! Several callbacks may be registered per message, at start-up, from anywhere
//! ([`register`] takes `&self`, so a scheduler in a `static` works, as Paparazzi modules
//! register their messages from their init functions). They are plain
//! `&(dyn Fn() + Sync)`, typically calling `downlink.send(&msg)` (which never blocks).
//! On a tick, they are called in process order, then in the order of the mode's messages,
//! then in registration order; no lock is held while they run, so they may call any
//! method of the scheduler but [`tick`](Scheduler::tick) and [`run`](Scheduler::run)
//! (a tick inside a tick would run the next ticks early, and recurse without end for a
//! message due every tick).
//!
//! # Example
//! ```
//! use core::sync::atomic::{AtomicU32, Ordering};
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
//! use pprz_default::periodic::{self, main}; // any generated schedule
//! use pprz_telemetry::scheduler::{Modes, Scheduler};
//!
//! static MODES: Modes<'static, { periodic::PROCESSES }> = Modes::new(&periodic::SCHEDULE);
//! static SCHEDULER: Scheduler<'static, CriticalSectionRawMutex, { periodic::PROCESSES }, 8> =
//!     Scheduler::new(&MODES);
//! static ALIVE_SENT: AtomicU32 = AtomicU32::new(0);
//!
//! fn send_alive() {
//!     // downlink.send(&Alive { .. }) in a firmware.
//!     ALIVE_SENT.fetch_add(1, Ordering::Relaxed);
//! }
//!
//! let registered = SCHEDULER.register("ALIVE", &send_alive).unwrap();
//! assert!(registered.is_scheduled());
//! for _ in 0..60 * periodic::FREQUENCY_HZ {
//!     SCHEDULER.tick(); // or spawn a task running `SCHEDULER.run().await`
//! }
//! // ALIVE every 2.1 s in the default mode: ticks 0, 126, ... over a minute.
//! assert_eq!(ALIVE_SENT.load(Ordering::Relaxed), 29);
//! MODES.set_mode(main::PROCESS, main::MODE_DEBUG).unwrap(); // or SETTING from the ground
//! assert_eq!(MODES.mode(main::PROCESS), Some(main::MODE_DEBUG));
//! ```
//!
//! [`tick`]: Scheduler::tick
//! [`set_mode`]: Modes::set_mode
//! [`register`]: Scheduler::register

use core::cell::RefCell;
use core::fmt;
use core::sync::atomic::{AtomicUsize, Ordering};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Duration, Instant, TICK_HZ, Timer};
use pprz_messages::Message;
pub use pprz_messages::schedule::{Mode, Periodic, Process, Schedule};

/// A periodic callback: usually sends one message, e.g. `&|| { let _ = downlink.send(&msg); }`
/// or `&send_alive` for a `fn send_alive()`.
pub type Callback<'a> = &'a (dyn Fn() + Sync);

/// Which message a callback is for: by name (looked up in the schedule) or by id.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MessageKey<'k> {
    /// Message name, as in `messages.xml`.
    Name(&'k str),
    /// Class id and message id.
    Id {
        /// Class id.
        class_id: u8,
        /// Message id within the class.
        msg_id: u8,
    },
}

impl<'k> From<&'k str> for MessageKey<'k> {
    fn from(name: &'k str) -> Self {
        Self::Name(name)
    }
}

impl From<(u8, u8)> for MessageKey<'_> {
    fn from((class_id, msg_id): (u8, u8)) -> Self {
        Self::Id { class_id, msg_id }
    }
}

/// All `C` callback slots of the scheduler are taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SchedulerFull;

impl fmt::Display for SchedulerFull {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("every callback slot of the scheduler is taken")
    }
}

impl core::error::Error for SchedulerFull {}

/// What a registration did.
#[must_use = "a callback for a message that no mode schedules never fires"]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Registered {
    /// Number of modes (of the processes the callback is registered for) that schedule
    /// the message. 0: the message is in no mode, the callback never fires and took no
    /// slot (counted in [`SchedulerStats::unscheduled`]).
    pub modes: usize,
}

impl Registered {
    /// Whether the callback can ever fire.
    pub const fn is_scheduled(&self) -> bool {
        self.modes > 0
    }
}

/// A mode change that is not possible.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ModeError {
    /// No process has this index (or name).
    UnknownProcess,
    /// The process has no mode with this index (or name).
    UnknownMode,
    /// A setting value that is not a whole number (a mode index).
    NotAnIndex,
}

impl fmt::Display for ModeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::UnknownProcess => "no such process in the telemetry schedule",
            Self::UnknownMode => "no such mode in the process",
            Self::NotAnIndex => "a telemetry mode is set by its index, a whole number",
        })
    }
}

impl core::error::Error for ModeError {}

/// What one [`tick`](Scheduler::tick) did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickReport {
    /// The tick number (0 for the first tick).
    pub tick: u64,
    /// Messages due in the active modes.
    pub due: usize,
    /// Callbacks called.
    pub calls: usize,
}

/// Counters of a scheduler.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SchedulerStats {
    /// Ticks run.
    pub ticks: u64,
    /// Messages that were due in the active modes, over all ticks.
    pub due: u64,
    /// Callbacks called, over all ticks.
    pub calls: u64,
    /// Registered callbacks (slots taken).
    pub callbacks: usize,
    /// Registrations for a message that no mode (of the processes concerned) schedules.
    pub unscheduled: u32,
}

/// Object-safe access to the active modes of a scheduler of any type, so a settings
/// table can hold them (see [`ModeSetting`]).
pub trait ModeControl {
    /// Number of processes.
    fn processes(&self) -> usize;
    /// Number of modes of `process`.
    fn modes(&self, process: usize) -> Option<usize>;
    /// Active mode of `process`.
    fn mode(&self, process: usize) -> Option<usize>;
    /// Switches `process` to `mode` from the next tick on.
    ///
    /// # Errors
    /// Unknown process or mode.
    fn set_mode(&self, process: usize, mode: usize) -> Result<(), ModeError>;
}

/// The active mode of one process as a setting (a float value, as in the SETTING and
/// DL_VALUE messages): what the settings table of the datalink services holds so the
/// ground can switch telemetry modes.
#[derive(Clone, Copy)]
pub struct ModeSetting<'s> {
    control: &'s (dyn ModeControl + Sync),
    process: usize,
}

impl fmt::Debug for ModeSetting<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ModeSetting")
            .field("process", &self.process)
            .field("mode", &self.control.mode(self.process))
            .finish()
    }
}

impl<'s> ModeSetting<'s> {
    /// The mode setting of `process` of `control`.
    ///
    /// # Errors
    /// [`ModeError::UnknownProcess`].
    pub fn new(control: &'s (dyn ModeControl + Sync), process: usize) -> Result<Self, ModeError> {
        if process < control.processes() {
            Ok(Self { control, process })
        } else {
            Err(ModeError::UnknownProcess)
        }
    }

    /// The process index.
    pub fn process(&self) -> usize {
        self.process
    }

    /// Number of modes: valid values are `0.0 ..= modes - 1`.
    pub fn modes(&self) -> usize {
        self.control.modes(self.process).unwrap_or(0)
    }

    /// The active mode index, as a setting value.
    pub fn get(&self) -> f32 {
        self.control.mode(self.process).unwrap_or(0) as f32
    }

    /// Sets the active mode from a setting value (a mode index), from the next tick on.
    ///
    /// # Errors
    /// [`ModeError::NotAnIndex`] for a value that is not a whole number >= 0,
    /// [`ModeError::UnknownMode`] for an index past the last mode.
    pub fn set(&self, value: f32) -> Result<(), ModeError> {
        if !(value.is_finite() && value >= 0.0 && value == (value as u32) as f32) {
            return Err(ModeError::NotAnIndex);
        }
        self.control.set_mode(self.process, value as usize)
    }
}

#[derive(Clone, Copy)]
struct Entry<'a> {
    class_id: u8,
    msg_id: u8,
    /// `None`: every process.
    process: Option<usize>,
    callback: Callback<'a>,
}

struct Inner<'a, const C: usize> {
    stats: SchedulerStats,
    /// Registered callbacks in `entries[..stats.callbacks]`, in registration order.
    /// (A plain array: the scheduler has no drop glue, so a callback may borrow the
    /// scheduler it is registered in.)
    entries: [Option<Entry<'a>>; C],
}

/// The active mode of each process of a [`Schedule`] (at most `P` processes; the
/// generated `PROCESSES` constant), separate from the [`Scheduler`] that reads it, so
/// the settings table (which the ground writes through) can switch modes without
/// borrowing the scheduler and its callbacks. `const`, so it can be a `static`; every
/// process starts in its first mode.
pub struct Modes<'a, const P: usize> {
    schedule: &'a Schedule<'a>,
    active: [AtomicUsize; P],
}

impl<'a, const P: usize> Modes<'a, P> {
    /// The modes of `schedule`, every process in its first mode.
    ///
    /// # Panics
    /// If the schedule has more than `P` processes or a tick frequency of 0 (at compile
    /// time when evaluated in a constant context, e.g. a `static`).
    pub const fn new(schedule: &'a Schedule<'a>) -> Self {
        assert!(
            schedule.processes.len() <= P,
            "the schedule has more processes than the modes' P"
        );
        assert!(schedule.frequency_hz > 0, "the tick frequency is 0 Hz");
        Self {
            schedule,
            active: [const { AtomicUsize::new(0) }; P],
        }
    }

    /// The schedule.
    pub fn schedule(&self) -> &'a Schedule<'a> {
        self.schedule
    }

    /// The active mode of `process`.
    pub fn mode(&self, process: usize) -> Option<usize> {
        if process >= self.schedule.processes.len() {
            return None;
        }
        self.active.get(process).map(|m| m.load(Ordering::Relaxed))
    }

    /// Switches `process` to `mode` (indices in the schedule; the generated
    /// `periodic::<process>::PROCESS` and `MODE_*` constants), from the scheduler's next
    /// tick on.
    ///
    /// # Errors
    /// Unknown process or mode.
    pub fn set_mode(&self, process: usize, mode: usize) -> Result<(), ModeError> {
        let p = self
            .schedule
            .processes
            .get(process)
            .ok_or(ModeError::UnknownProcess)?;
        if mode >= p.modes.len() {
            return Err(ModeError::UnknownMode);
        }
        let slot = self.active.get(process).ok_or(ModeError::UnknownProcess)?;
        slot.store(mode, Ordering::Relaxed);
        Ok(())
    }

    /// Switches a process to a mode by their names; as [`set_mode`](Self::set_mode).
    ///
    /// # Errors
    /// Unknown process or mode.
    pub fn set_mode_by_name(&self, process: &str, mode: &str) -> Result<(), ModeError> {
        let p = self
            .schedule
            .process_index(process)
            .ok_or(ModeError::UnknownProcess)?;
        let m = self.schedule.processes[p]
            .mode_index(mode)
            .ok_or(ModeError::UnknownMode)?;
        self.set_mode(p, m)
    }

    /// The active mode of `process` as a setting, for the settings table of the
    /// datalink services
    /// ([`Settings::add_mode`](crate::settings::Settings::add_mode)).
    ///
    /// # Errors
    /// [`ModeError::UnknownProcess`].
    pub fn setting(&self, process: usize) -> Result<ModeSetting<'_>, ModeError> {
        ModeSetting::new(self, process)
    }
}

/// Runs a [`Schedule`] whose active modes are in a [`Modes`] of `P` processes; `C` is
/// the number of callbacks.
///
/// `M` protects the counters and the callback list (each lock is
/// short and never held while a callback runs): `CriticalSectionRawMutex` to share the
/// scheduler between tasks and interrupts (e.g. a `static`), `NoopRawMutex` within one
/// executor.
///
/// Cost of a tick: for each message of the active modes one modulo of a `u64`; for each
/// due message one scan of the `C` callback slots.
pub struct Scheduler<'a, M: RawMutex, const P: usize, const C: usize> {
    schedule: &'a Schedule<'a>,
    modes: &'a Modes<'a, P>,
    inner: Mutex<M, RefCell<Inner<'a, C>>>,
}

impl<'a, M: RawMutex, const P: usize, const C: usize> Scheduler<'a, M, P, C> {
    /// A scheduler for the schedule of `modes`, no callbacks.
    pub const fn new(modes: &'a Modes<'a, P>) -> Self {
        Self {
            schedule: modes.schedule,
            modes,
            inner: Mutex::new(RefCell::new(Inner {
                stats: SchedulerStats {
                    ticks: 0,
                    due: 0,
                    calls: 0,
                    callbacks: 0,
                    unscheduled: 0,
                },
                entries: [None; C],
            })),
        }
    }

    /// The schedule.
    pub fn schedule(&self) -> &'a Schedule<'a> {
        self.schedule
    }

    /// Registers `callback` for `message` (a name, or `(class_id, msg_id)`) in every
    /// process; it is called each time the message is due in an active mode. Several
    /// callbacks may be registered per message; they are called in registration order.
    ///
    /// A message that no mode schedules is accepted but never fires: the callback takes
    /// no slot, and the returned [`Registered::modes`] is 0.
    ///
    /// # Errors
    /// [`SchedulerFull`] when `C` callbacks are already registered.
    pub fn register<'k>(
        &self,
        message: impl Into<MessageKey<'k>>,
        callback: Callback<'a>,
    ) -> Result<Registered, SchedulerFull> {
        self.add(None, message.into(), callback)
    }

    /// Registers `callback` for `message` in process `process` only (e.g. a process
    /// whose callbacks send to another device). As [`register`](Self::register); an
    /// unknown process schedules nothing.
    ///
    /// # Errors
    /// [`SchedulerFull`] when `C` callbacks are already registered.
    pub fn register_in<'k>(
        &self,
        process: usize,
        message: impl Into<MessageKey<'k>>,
        callback: Callback<'a>,
    ) -> Result<Registered, SchedulerFull> {
        self.add(Some(process), message.into(), callback)
    }

    /// Registers `callback` for the message type `T` in every process; as
    /// [`register`](Self::register).
    ///
    /// # Errors
    /// [`SchedulerFull`] when `C` callbacks are already registered.
    pub fn register_message<T: Message>(
        &self,
        callback: Callback<'a>,
    ) -> Result<Registered, SchedulerFull> {
        self.add(None, (T::CLASS_ID, T::ID).into(), callback)
    }

    fn add(
        &self,
        process: Option<usize>,
        message: MessageKey<'_>,
        callback: Callback<'a>,
    ) -> Result<Registered, SchedulerFull> {
        let id = match message {
            MessageKey::Name(name) => self.schedule.message_id(name),
            MessageKey::Id { class_id, msg_id } => Some((class_id, msg_id)),
        };
        let modes = id.map_or(0, |(c, m)| self.schedule.modes_with(process, c, m));
        self.inner.lock(|inner| {
            let mut inner = inner.borrow_mut();
            match id {
                Some((class_id, msg_id)) if modes > 0 => {
                    let n = inner.stats.callbacks;
                    let slot = inner.entries.get_mut(n).ok_or(SchedulerFull)?;
                    *slot = Some(Entry {
                        class_id,
                        msg_id,
                        process,
                        callback,
                    });
                    inner.stats.callbacks = n + 1;
                }
                _ => inner.stats.unscheduled = inner.stats.unscheduled.saturating_add(1),
            }
            Ok(Registered { modes })
        })
    }

    /// The active modes this scheduler runs.
    pub fn modes(&self) -> &'a Modes<'a, P> {
        self.modes
    }

    /// Counters since start-up.
    pub fn stats(&self) -> SchedulerStats {
        self.inner.lock(|inner| inner.borrow().stats)
    }

    /// Runs one tick: calls the callbacks of every message due in the active mode of
    /// each process (see the [module docs](self) for timing and order), and counts.
    pub fn tick(&self) -> TickReport {
        let tick = self.inner.lock(|inner| {
            let mut inner = inner.borrow_mut();
            let tick = inner.stats.ticks;
            inner.stats.ticks += 1;
            tick
        });
        // The modes in force for the whole tick, even if a callback switches one.
        let modes: [usize; P] = core::array::from_fn(|p| self.modes.mode(p).unwrap_or(0));
        let mut report = TickReport {
            tick,
            due: 0,
            calls: 0,
        };
        for (p, process) in self.schedule.processes.iter().enumerate() {
            let Some(mode) = modes.get(p).and_then(|&m| process.modes.get(m)) else {
                continue;
            };
            for msg in mode.messages.iter().filter(|m| m.is_due(tick)) {
                report.due += 1;
                let mut next = 0;
                while let Some((callback, after)) = self.find_callback(p, msg, next) {
                    callback();
                    report.calls += 1;
                    next = after;
                }
            }
        }
        self.inner.lock(|inner| {
            let mut inner = inner.borrow_mut();
            inner.stats.due += report.due as u64;
            inner.stats.calls += report.calls as u64;
        });
        report
    }

    /// The first callback for `msg` in process `process` from slot `from` on, and the
    /// slot after it; the lock is released before the callback is called.
    fn find_callback(
        &self,
        process: usize,
        msg: &Periodic<'_>,
        from: usize,
    ) -> Option<(Callback<'a>, usize)> {
        self.inner.lock(|inner| {
            let inner = inner.borrow();
            let entries = inner.entries.get(from..inner.stats.callbacks)?;
            entries.iter().enumerate().find_map(|(i, e)| {
                e.filter(|e| {
                    e.class_id == msg.class_id
                        && e.msg_id == msg.msg_id
                        && e.process.is_none_or(|p| p == process)
                })
                .map(|e| (e.callback, from + i + 1))
            })
        })
    }

    /// The scheduler task: ticks at the schedule's frequency forever, tick `k` (from 0)
    /// at `(k + 1) / frequency_hz` s after the call, exactly in timer ticks (no drift);
    /// missed ticks run at once.
    pub async fn run(&self) -> ! {
        let hz = u64::from(self.schedule.frequency_hz.max(1));
        // Tick k is due at start + (k + 1) * TICK_HZ / hz timer ticks: whole and
        // remainder parts, accumulated without overflow or rounding drift.
        let (step, rem) = (TICK_HZ / hz, TICK_HZ % hz);
        let start = Instant::now();
        let (mut offset, mut acc) = (0u64, 0u64);
        loop {
            offset += step;
            acc += rem;
            if acc >= hz {
                acc -= hz;
                offset += 1;
            }
            Timer::at(start + Duration::from_ticks(offset)).await;
            self.tick();
        }
    }
}

impl<const P: usize> ModeControl for Modes<'_, P> {
    fn processes(&self) -> usize {
        self.schedule.processes.len()
    }

    fn modes(&self, process: usize) -> Option<usize> {
        self.schedule.processes.get(process).map(|p| p.modes.len())
    }

    fn mode(&self, process: usize) -> Option<usize> {
        Modes::mode(self, process)
    }

    fn set_mode(&self, process: usize, mode: usize) -> Result<(), ModeError> {
        Modes::set_mode(self, process, mode)
    }
}
