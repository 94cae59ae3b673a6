//! The store flag, the clear flag and the store task.

mod common;

use std::sync::atomic::{AtomicBool, Ordering};

use common::*;
use embassy_futures::block_on;
use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use pprz_messages::settings::{SettingDesc, SettingType};
use pprz_settings::sequential_storage::mock_flash::MockFlashBase;
use pprz_settings::{
    ErrorKind, FlagState, Outcome, PageCache, PersistentStore, RamFlash, Request, SnapshotKey,
    StoreControl, StoreStats, buffer_len, run,
};
use pprz_telemetry::settings::Binding;

type Control = StoreControl<CriticalSectionRawMutex>;
type Flash<'m> = RamFlash<'m, 3072, 4, 1024>;
type Store<'m> = PersistentStore<Flash<'m>, PageCache<3>, { buffer_len(8) }>;

fn store(mem: &mut [u8; 3072]) -> Store<'_> {
    Store::with_page_cache(Flash::new(mem), 0..3072).unwrap()
}

/// Runs the store task with `store` until `body` finishes (the task is then waiting for
/// a request: nothing of the store is in flight when it is dropped).
fn with_task<S, C, const BUF: usize, R>(
    mut store: PersistentStore<S, C, BUF>,
    control: &Control,
    values: &[f32; K],
    body: impl AsyncFnOnce(&Control) -> R,
) -> R
where
    S: embedded_storage_async::nor_flash::NorFlash,
    C: pprz_settings::sequential_storage::cache::CacheImpl<SnapshotKey>,
{
    let vars = Vars::new(values);
    with_table(&vars, |table| {
        block_on(async {
            match select(run(&mut store, control, table), body(control)).await {
                Either::First(never) => never,
                Either::Second(r) => r,
            }
        })
    })
}

#[test]
fn setting_the_flag_stores_and_reads_back_one() {
    let mut mem = [0xFF; 3072];
    let control = Control::new();
    assert_eq!(control.store_flag(), 0.0);
    let outcome = with_task(store(&mut mem), &control, &A, async |c| {
        c.set_store_flag(1.0);
        assert_eq!(c.store_flag(), 1.0);
        assert_eq!(c.store_state(), FlagState::Pending);
        c.outcome().await
    });
    assert_eq!(
        outcome,
        Outcome {
            request: Request::Store,
            state: FlagState::Done,
            error: None
        }
    );
    assert_eq!(control.store_flag(), 1.0);
    assert_eq!(control.stats().stores, 1);
    assert_eq!(load(&mut store(&mut mem)).1, loaded(A));
    // Setting 0 afterwards stores nothing and reads 0.
    control.set_store_flag(0.0);
    assert_eq!(control.store_state(), FlagState::Idle);
    control.set_store_flag(f32::NAN);
    assert_eq!(control.store_state(), FlagState::Idle);
}

static ARMED_AT_REQUEST: AtomicBool = AtomicBool::new(true);

#[test]
fn a_refused_request_reads_back_zero_and_stores_nothing() {
    let control = Control::with_guard(|| !ARMED_AT_REQUEST.load(Ordering::Relaxed));
    control.set_store_flag(1.0);
    assert_eq!(control.store_state(), FlagState::Refused);
    assert_eq!(control.store_flag(), 0.0);
    assert!(control.request_clear().is_err());
    assert_eq!(control.clear_flag(), 0.0);
    assert_eq!(control.stats().refusals, 2);
    ARMED_AT_REQUEST.store(false, Ordering::Relaxed);
    assert!(control.request_store().is_ok());
    assert_eq!(control.store_flag(), 1.0);
}

static ARMED_LATER: AtomicBool = AtomicBool::new(false);

#[test]
fn the_task_asks_the_guard_again() {
    let mut mem = [0xFF; 3072];
    let control = Control::with_guard(|| !ARMED_LATER.load(Ordering::Relaxed));
    control.request_store().unwrap();
    // Armed before the task got to it.
    ARMED_LATER.store(true, Ordering::Relaxed);
    let outcome = with_task(store(&mut mem), &control, &A, async |c| c.outcome().await);
    assert_eq!(outcome.state, FlagState::Refused);
    assert_eq!(control.store_flag(), 0.0);
    assert_eq!(control.stats().refusals, 1);
    assert!(mem.iter().all(|b| *b == 0xFF));
}

#[test]
fn a_failed_store_reads_back_zero_with_its_reason() {
    let control = Control::new();
    // A buffer for 2 settings, a table of 5 persistent ones.
    let mut mem = [0xFF; 3072];
    let small = PersistentStore::<_, PageCache<3>, { buffer_len(2) }>::with_page_cache(
        Flash::new(&mut mem),
        0..3072,
    )
    .unwrap();
    let outcome = with_task(small, &control, &A, async |c| {
        c.set_store_flag(1.0);
        c.outcome().await
    });
    assert_eq!(outcome.state, FlagState::Failed);
    assert_eq!(outcome.error, Some(ErrorKind::TooManySettings));
    assert_eq!(control.store_flag(), 0.0);
    // A flash that fails (the power goes at its first byte written).
    type Mock = MockFlashBase<3, 4, 256>;
    let flash = Mock::new(
        pprz_settings::sequential_storage::mock_flash::WriteCountCheck::OnceOnly,
        Some(0),
        true,
    );
    let failing = PersistentStore::<_, PageCache<3>, { buffer_len(8) }>::with_page_cache(
        flash,
        Mock::FULL_FLASH_RANGE,
    )
    .unwrap();
    let (first, second) = with_task(failing, &control, &A, async |c| {
        c.set_store_flag(1.0);
        let first = c.outcome().await;
        c.set_store_flag(1.0);
        (first, c.outcome().await)
    });
    assert_eq!(first.error, Some(ErrorKind::Flash));
    assert_eq!(second.state, FlagState::Done);
    assert_eq!(
        control.stats(),
        StoreStats {
            stores: 1,
            failures: 2,
            ..StoreStats::ZERO
        }
    );
}

#[test]
fn clear_erases_and_requests_run_in_order() {
    let mut mem = [0xFF; 3072];
    let control = Control::new();
    // Store, then clear: nothing stored in the end.
    control.request_store().unwrap();
    control.request_clear().unwrap();
    // (Outcomes not awaited in time are replaced by later ones: wait for the clear.)
    let until = async |c: &Control, request| loop {
        let outcome = c.outcome().await;
        if outcome.request == request {
            break outcome;
        }
    };
    let outcome = with_task(store(&mut mem), &control, &A, async |c| {
        until(c, Request::Clear).await
    });
    assert_eq!(
        (outcome.request, outcome.state),
        (Request::Clear, FlagState::Done)
    );
    assert_eq!(control.clear_flag(), 1.0);
    let (report, values) = load(&mut store(&mut mem));
    assert_eq!((report.unwrap().entries, values), (0, DEFAULTS));
    // Clear, then store: stored.
    control.request_clear().unwrap();
    control.request_store().unwrap();
    let outcome = with_task(store(&mut mem), &control, &B, async |c| {
        until(c, Request::Store).await
    });
    assert_eq!(outcome.request, Request::Store);
    assert_eq!(load(&mut store(&mut mem)).1, loaded(B));
    let stats = control.stats();
    assert_eq!((stats.stores, stats.clears, stats.failures), (2, 2, 0));
}

#[test]
fn a_load_through_the_control_is_counted() {
    let mut mem = [0xFF; 3072];
    save(&mut store(&mut mem), &B).unwrap();
    let control = Control::new();
    let vars = Vars::new(&DEFAULTS);
    let report = with_table(&vars, |t| block_on(control.load(&mut store(&mut mem), t)));
    assert_eq!(report.unwrap().applied, 5);
    // A smaller table with a tighter bound: one refused, one unknown.
    static OTHER: [SettingDesc<'static>; 2] = [
        SettingDesc::new(0, "gain", 0.0, 5.0).persistent(true),
        SettingDesc::new(1, "trim", -1.0, 1.0).persistent(true),
    ];
    let vars = Vars::new(&[0.0, 0.0]);
    with_table_of(&OTHER, &vars, |t| {
        block_on(control.load(&mut store(&mut mem), t))
    })
    .unwrap();
    assert_eq!(
        control.stats(),
        StoreStats {
            loads: 2,
            entries_applied: 6,
            entries_refused: 1,
            entries_unknown: 3,
            ..StoreStats::ZERO
        }
    );
}

static CONTROL: StoreControl<CriticalSectionRawMutex> = StoreControl::new();
fn flag() -> f32 {
    CONTROL.store_flag()
}
fn set_flag(v: f32) {
    CONTROL.set_store_flag(v)
}
static FLAG: SettingDesc<'static> = SettingDesc::new(0, "settings_store_flag", 0.0, 1.0)
    .ty(SettingType::U8)
    .handler("StoreSettings", Some("settings"));

#[test]
fn the_flag_binds_to_a_setting_of_a_static_table() {
    static SETTINGS: pprz_telemetry::settings::Settings<'static, CriticalSectionRawMutex, 4> =
        pprz_telemetry::settings::Settings::new();
    SETTINGS
        .add_desc(&FLAG, Binding::Fns(&flag, &set_flag))
        .unwrap();
    assert_eq!(SETTINGS.get(0), Some(0.0));
    // As a SETTING from the ground: 1 asks for a store and reads back 1.
    assert_eq!(SETTINGS.try_set(0, 1.0), Ok(1.0));
    assert_eq!(CONTROL.store_state(), FlagState::Pending);
    // Out of the flag's bounds: refused, nothing asked.
    assert!(SETTINGS.try_set(0, 2.0).is_err());
}
