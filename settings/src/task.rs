//! Storing on request: Paparazzi's `settings_store_flag` and `settings_clear_flag` with an
//! asynchronous store.
//!
//! In Paparazzi, setting the store flag to 1 stores the persistent settings at once, in
//! the SETTING handler, and the flag reads back 1 if the store succeeded and 0 if not.
//! Here a setter cannot wait for the flash, so:
//!
//! * setting the flag to 1 asks the store task for a store, unless the application's
//!   `can_store()` predicate refuses (Paparazzi stores only with the motors killed); the
//!   flag reads back 1 while the store is pending, and 0 if it was refused;
//! * the store task ([`run`]) stores, and the flag then reads 1 (stored) or 0 (failed, or
//!   refused by `can_store()` when the task got to it); [`StoreControl::outcome`] wakes
//!   whoever tells the ground (an unsolicited DL_VALUE);
//! * setting it to 0 changes nothing stored; the flag reads 0 unless a store is pending.
//!
//! The clear flag works the same way, and forgets the stored snapshot
//! ([`PersistentStore::clear`]): the next boot keeps the defaults.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_messages::settings::{SettingDesc, SettingType};
//! use pprz_settings::StoreControl;
//! use pprz_telemetry::settings::{Binding, Settings};
//! use core::sync::atomic::{AtomicBool, Ordering};
//!
//! static ARMED: AtomicBool = AtomicBool::new(false);
//! fn motors_off() -> bool { !ARMED.load(Ordering::Relaxed) }
//! static STORE: StoreControl<M> = StoreControl::with_guard(motors_off);
//!
//! // The store-flag setting of the settings.xml, bound to the control.
//! fn store_flag() -> f32 { STORE.store_flag() }
//! fn set_store_flag(v: f32) { STORE.set_store_flag(v) }
//! static FLAG: SettingDesc<'static> = SettingDesc::new(0, "settings_store_flag", 0.0, 1.0)
//!     .ty(SettingType::U8)
//!     .handler("StoreSettings", Some("settings"));
//! static SETTINGS: Settings<'static, M, 8> = Settings::new();
//! SETTINGS.add_desc(&FLAG, Binding::Fns(&store_flag, &set_store_flag)).unwrap();
//!
//! assert_eq!(SETTINGS.set(0, 1.0), Some(1.0)); // pending: the store task will store
//! ARMED.store(true, Ordering::Relaxed);
//! STORE.set_clear_flag(1.0);
//! assert_eq!(STORE.clear_flag(), 0.0); // refused: the motors are armed
//! ```

use core::cell::Cell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::signal::Signal;
use embedded_storage_async::nor_flash::NorFlash;
use pprz_telemetry::settings::Settings;
use sequential_storage::cache::CacheImpl;

use crate::store::{ErrorKind, LoadReport, PersistentStore, SnapshotKey, StoreError};

/// What a flag shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FlagState {
    /// Nothing asked (reads 0).
    #[default]
    Idle,
    /// Asked, not done yet (reads 1).
    Pending,
    /// Done (reads 1).
    Done,
    /// Failed (reads 0).
    Failed,
    /// Refused by `can_store()` (reads 0).
    Refused,
}

impl FlagState {
    /// The value the flag setting reads back: 1 while pending or after success.
    pub const fn value(self) -> f32 {
        match self {
            FlagState::Pending | FlagState::Done => 1.0,
            FlagState::Idle | FlagState::Failed | FlagState::Refused => 0.0,
        }
    }
}

/// What the store task is asked to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Request {
    /// Store a snapshot of the persistent settings.
    Store,
    /// Forget the stored snapshot ([`PersistentStore::clear`]).
    Clear,
}

/// A request the store task finished.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Outcome {
    /// The request.
    pub request: Request,
    /// [`FlagState::Done`], [`FlagState::Failed`] or [`FlagState::Refused`].
    pub state: FlagState,
    /// Why it failed.
    pub error: Option<ErrorKind>,
}

/// A request `can_store()` refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Refused;

impl core::fmt::Display for Refused {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("the application refuses to store settings now")
    }
}

impl core::error::Error for Refused {}

/// Counters of the store (saturating).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StoreStats {
    /// Snapshots stored.
    pub stores: u32,
    /// Stores cleared.
    pub clears: u32,
    /// Stores and clears that failed.
    pub failures: u32,
    /// Requests `can_store()` refused.
    pub refusals: u32,
    /// Loads that read the flash (a snapshot found or not).
    pub loads: u32,
    /// Loads that failed.
    pub load_failures: u32,
    /// Entries loads applied.
    pub entries_applied: u32,
    /// Entries loads did not apply because their setting refused the value.
    pub entries_refused: u32,
    /// Entries loads ignored: no persistent setting of the table has their key, or it has
    /// another type now.
    pub entries_unknown: u32,
}

impl StoreStats {
    /// Every counter 0.
    pub const ZERO: Self = Self {
        stores: 0,
        clears: 0,
        failures: 0,
        refusals: 0,
        loads: 0,
        load_failures: 0,
        entries_applied: 0,
        entries_refused: 0,
        entries_unknown: 0,
    };
}

fn add(counter: &mut u32, n: usize) {
    *counter = counter.saturating_add(u32::try_from(n).unwrap_or(u32::MAX));
}

#[derive(Clone, Copy, Default)]
struct State {
    store: FlagState,
    clear: FlagState,
    /// Pending requests, oldest first.
    queue: [Option<Request>; 2],
    stats: StoreStats,
}

impl State {
    fn flag(&mut self, request: Request) -> &mut FlagState {
        match request {
            Request::Store => &mut self.store,
            Request::Clear => &mut self.clear,
        }
    }

    /// Queues `request` last (a request asked again moves behind the other).
    fn push(&mut self, request: Request) {
        let others = self.queue.into_iter().flatten().filter(|r| *r != request);
        let mut queue = [None; 2];
        for (slot, r) in queue.iter_mut().zip(others.chain([request])) {
            *slot = Some(r);
        }
        self.queue = queue;
    }

    fn pop(&mut self) -> Option<Request> {
        let [first, second] = self.queue;
        self.queue = [second, None];
        first
    }
}

/// The link between the settings (flag setters, application calls) and the store task:
/// `const`, so it can be a `static`. `M` is the mutex kind guarding its state.
pub struct StoreControl<M: RawMutex> {
    state: Mutex<M, Cell<State>>,
    wake: Signal<M, ()>,
    outcome: Signal<M, Outcome>,
    can_store: fn() -> bool,
}

fn always() -> bool {
    true
}

impl<M: RawMutex> StoreControl<M> {
    /// A control that accepts every request.
    pub const fn new() -> Self {
        Self::with_guard(always)
    }

    /// A control that asks `can_store` (e.g. "the motors are off") before accepting a
    /// request, and again before the task acts on it.
    pub const fn with_guard(can_store: fn() -> bool) -> Self {
        Self {
            state: Mutex::new(Cell::new(State {
                store: FlagState::Idle,
                clear: FlagState::Idle,
                queue: [None; 2],
                stats: StoreStats::ZERO,
            })),
            wake: Signal::new(),
            outcome: Signal::new(),
            can_store,
        }
    }

    fn update<R>(&self, f: impl FnOnce(&mut State) -> R) -> R {
        self.state.lock(|cell| {
            let mut state = cell.get();
            let r = f(&mut state);
            cell.set(state);
            r
        })
    }

    fn request(&self, request: Request) -> Result<(), Refused> {
        if !(self.can_store)() {
            self.update(|s| {
                *s.flag(request) = FlagState::Refused;
                add(&mut s.stats.refusals, 1);
            });
            return Err(Refused);
        }
        self.update(|s| {
            *s.flag(request) = FlagState::Pending;
            s.push(request);
        });
        self.wake.signal(());
        Ok(())
    }

    /// Asks the store task to store the persistent settings.
    ///
    /// # Errors
    /// [`Refused`] if `can_store()` refuses (the store flag then reads 0).
    pub fn request_store(&self) -> Result<(), Refused> {
        self.request(Request::Store)
    }

    /// Asks the store task to forget the stored snapshot.
    ///
    /// # Errors
    /// [`Refused`] if `can_store()` refuses (the clear flag then reads 0).
    pub fn request_clear(&self) -> Result<(), Refused> {
        self.request(Request::Clear)
    }

    fn set_flag(&self, request: Request, value: f32) {
        if value.is_finite() && value != 0.0 {
            // A refusal shows in the flag.
            let _ = self.request(request);
        } else {
            self.update(|s| {
                let flag = s.flag(request);
                if *flag != FlagState::Pending {
                    *flag = FlagState::Idle;
                }
            });
        }
    }

    /// The store flag's value, for the setting's getter.
    pub fn store_flag(&self) -> f32 {
        self.store_state().value()
    }

    /// Sets the store flag, for the setting's setter: nonzero asks for a store.
    pub fn set_store_flag(&self, value: f32) {
        self.set_flag(Request::Store, value);
    }

    /// The clear flag's value, for the setting's getter.
    pub fn clear_flag(&self) -> f32 {
        self.clear_state().value()
    }

    /// Sets the clear flag, for the setting's setter: nonzero asks for a clear.
    pub fn set_clear_flag(&self, value: f32) {
        self.set_flag(Request::Clear, value);
    }

    /// The store flag's state.
    pub fn store_state(&self) -> FlagState {
        self.state.lock(|s| s.get().store)
    }

    /// The clear flag's state.
    pub fn clear_state(&self) -> FlagState {
        self.state.lock(|s| s.get().clear)
    }

    /// The counters.
    pub fn stats(&self) -> StoreStats {
        self.state.lock(|s| s.get().stats)
    }

    /// Waits until the store task finishes a request (the latest one, if several
    /// finished since the last call).
    pub async fn outcome(&self) -> Outcome {
        self.outcome.wait().await
    }

    /// Loads the stored snapshot into `table` (see [`PersistentStore::load`]) and counts
    /// it. Call it at boot, before the ground can change settings, and run it to
    /// completion.
    ///
    /// # Errors
    /// As [`PersistentStore::load`].
    pub async fn load<
        S: NorFlash,
        C: CacheImpl<SnapshotKey>,
        const BUF: usize,
        TM: RawMutex,
        const N: usize,
    >(
        &self,
        store: &mut PersistentStore<S, C, BUF>,
        table: &Settings<'_, TM, N>,
    ) -> Result<LoadReport, StoreError<S::Error>> {
        let result = store.load(table).await;
        self.update(|s| {
            let stats = &mut s.stats;
            add(&mut stats.loads, 1);
            match &result {
                Ok(report) => {
                    add(&mut stats.entries_applied, report.applied);
                    add(&mut stats.entries_refused, report.refused);
                    add(
                        &mut stats.entries_unknown,
                        report.unknown + report.mismatched,
                    );
                }
                Err(_) => add(&mut stats.load_failures, 1),
            }
        });
        result
    }

    /// Records the end of `request`: `state` is Done, Failed or Refused.
    fn finish(&self, request: Request, state: FlagState, error: Option<ErrorKind>) {
        self.update(|s| {
            *s.flag(request) = state;
            let stats = &mut s.stats;
            match (state, request) {
                (FlagState::Refused, _) => add(&mut stats.refusals, 1),
                (FlagState::Done, Request::Store) => add(&mut stats.stores, 1),
                (FlagState::Done, Request::Clear) => add(&mut stats.clears, 1),
                _ => add(&mut stats.failures, 1),
            }
        });
        self.outcome.signal(Outcome {
            request,
            state,
            error,
        });
    }
}

impl<M: RawMutex> Default for StoreControl<M> {
    fn default() -> Self {
        Self::new()
    }
}

/// The store task: waits for requests from `control` and stores `table`'s persistent
/// settings (or clears the store) in `store`, one request at a time, in the order they
/// were asked.
///
/// Spawn it as a task of its own, and never put it (or any future of the store) in a
/// `select`, a timeout or anything else that may drop it: sequential-storage's
/// operations are not cancel-safe, and a store dropped mid-way leaves the flash to be
/// repaired and the outcome unknown. While it waits for a request, nothing is in flight.
pub async fn run<S, C, const BUF: usize, M, TM, const N: usize>(
    store: &mut PersistentStore<S, C, BUF>,
    control: &StoreControl<M>,
    table: &Settings<'_, TM, N>,
) -> !
where
    S: NorFlash,
    C: CacheImpl<SnapshotKey>,
    M: RawMutex,
    TM: RawMutex,
{
    loop {
        control.wake.wait().await;
        while let Some(request) = control.update(State::pop) {
            if !(control.can_store)() {
                control.finish(request, FlagState::Refused, None);
                continue;
            }
            let error = match request {
                Request::Store => store.save(table).await.err(),
                Request::Clear => store.clear().await.err(),
            };
            let state = match error {
                None => FlagState::Done,
                Some(_) => FlagState::Failed,
            };
            control.finish(request, state, error.as_ref().map(StoreError::kind));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn queue_keeps_request_order_and_moves_repeats_last() {
        let mut s = State::default();
        s.push(Request::Store);
        s.push(Request::Clear);
        assert_eq!(s.queue, [Some(Request::Store), Some(Request::Clear)]);
        s.push(Request::Store);
        assert_eq!(s.queue, [Some(Request::Clear), Some(Request::Store)]);
        s.push(Request::Store);
        assert_eq!(s.queue, [Some(Request::Clear), Some(Request::Store)]);
        assert_eq!(s.pop(), Some(Request::Clear));
        assert_eq!(s.pop(), Some(Request::Store));
        assert_eq!(s.pop(), None);
    }

    #[test]
    fn flag_values_follow_paparazzi() {
        assert_eq!(FlagState::Idle.value(), 0.0);
        assert_eq!(FlagState::Pending.value(), 1.0);
        assert_eq!(FlagState::Done.value(), 1.0);
        assert_eq!(FlagState::Failed.value(), 0.0);
        assert_eq!(FlagState::Refused.value(), 0.0);
    }
}
