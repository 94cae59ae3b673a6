//! The persistent settings' cost: loading 100 persistent settings at boot, and storing
//! them, with `pprz-settings` over `RamFlash` of an STM32F405's geometry (three 16 KiB
//! pages, 4-byte words).
//!
//! The table is built here, as a generated one would be: 100 `SettingDesc` of float
//! settings (bounds -100 to 100, persistent) whose variables, `bench_setting_000` to
//! `bench_setting_099` (17 bytes each), are a static array of `f32` (kept as bits in
//! atomics), bound through `Binding::Fns`. The table's lock is the Cortex-M critical
//! section (an interrupt mask), as on a board.
//!
//! Before anything is measured, a first store writes a snapshot of the 100 values into
//! the erased flash. Then, each measured alone, on a new store with an empty cache over
//! the same flash (as after a reboot) unless said otherwise:
//!
//! * **read**: `PersistentStore::snapshot`: finds the snapshot and checks it (the first
//!   part of a load);
//! * **load**: the variables back at their defaults, `PersistentStore::load`: it finds
//!   the snapshot, checks it and applies its 100 entries through `Settings::try_set`;
//! * **save**: with new values, `PersistentStore::save` on the store of the load (its
//!   cache as the load left it, as for the store task after the boot load): a second
//!   snapshot after the first one in the same page, and its read-back.
//!
//! The futures are polled by `embassy_futures::block_on`; over RAM flash they finish on
//! their first poll. Each result is checked after its measurement.

use core::fmt::Write;
use core::hint::black_box;
use core::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::block_on;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use pprz_messages::settings::SettingDesc;
use pprz_settings::{LoadReport, PageCache, PersistentStore, RamFlash, buffer_len};
use pprz_telemetry::settings::{Binding, Settings};

use crate::hw::{Timer, Uart};
use crate::{fail, result, ticks};

/// Persistent settings of the table.
const SETTINGS: usize = 100;
/// The variables' names: `bench_setting_` and three digits.
const PREFIX: &[u8] = b"bench_setting_";
/// Bytes of a variable's name.
const NAME_LEN: usize = PREFIX.len() + 3;
/// Flash page (an STM32F405's sectors 1 to 3).
const PAGE: usize = 16 * 1024;
/// The settings' flash: three pages.
const FLASH_SIZE: usize = 3 * PAGE;

/// NOR flash over RAM, F405 geometry: 4-byte words, 16 KiB pages.
type Flash<'m> = RamFlash<'m, FLASH_SIZE, 4, PAGE>;
/// The store of up to [`SETTINGS`] persistent settings, with a cache of the three pages.
type Store<'m> = PersistentStore<Flash<'m>, PageCache<3>, { buffer_len(SETTINGS) }>;

/// The settings' variables, `f32` as bits.
static VALUES: [AtomicU32; SETTINGS] = [const { AtomicU32::new(0) }; SETTINGS];

/// Variable `i`.
fn value(i: usize) -> f32 {
    f32::from_bits(VALUES[i].load(Ordering::Relaxed))
}

/// Sets variable `i`.
fn set_value(i: usize, v: f32) {
    VALUES[i].store(v.to_bits(), Ordering::Relaxed);
}

/// Sets every variable to `f(i)`.
fn set_all(f: impl Fn(usize) -> f32) {
    for i in 0..SETTINGS {
        set_value(i, f(i));
    }
}

/// Whether every variable is `f(i)`.
fn all_are(f: impl Fn(usize) -> f32) -> bool {
    (0..SETTINGS).all(|i| value(i) == f(i))
}

/// The values of the first snapshot (1.0 to 50.5; the defaults are 0).
fn first(i: usize) -> f32 {
    1.0 + i as f32 * 0.5
}

/// The values of the measured store.
fn second(i: usize) -> f32 {
    -first(i)
}

/// The name of variable `i` (`i` < 1000).
fn name(i: usize) -> [u8; NAME_LEN] {
    let mut name = [0u8; NAME_LEN];
    let (prefix, digits) = name.split_at_mut(PREFIX.len());
    prefix.copy_from_slice(PREFIX);
    digits.copy_from_slice(&[
        b'0' + (i / 100 % 10) as u8,
        b'0' + (i / 10 % 10) as u8,
        b'0' + (i % 10) as u8,
    ]);
    name
}

/// Measures the boot load and a store of [`SETTINGS`] persistent settings, and prints
/// them. (Out of line, so that the code of the other workloads, which `main` inlines,
/// stays as it is without this one.)
#[inline(never)]
pub fn settings(out: &mut Uart, timer: &Timer) {
    let names: [[u8; NAME_LEN]; SETTINGS] = core::array::from_fn(name);
    let vars: [&str; SETTINGS] = core::array::from_fn(|i| {
        core::str::from_utf8(&names[i]).unwrap_or_else(|_| fail("setting name"))
    });
    let descs: [SettingDesc<'_>; SETTINGS] = core::array::from_fn(|i| {
        SettingDesc::new(i as u8, vars[i], -100.0, 100.0)
            .step(0.5)
            .persistent(true)
    });
    let gets: [_; SETTINGS] = core::array::from_fn(|i| move || value(i));
    let sets: [_; SETTINGS] = core::array::from_fn(|i| move |v| set_value(i, v));
    let table: Settings<'_, M, SETTINGS> = Settings::new();
    for (i, desc) in descs.iter().enumerate() {
        if table
            .add_desc(desc, Binding::Fns(&gets[i], &sets[i]))
            .is_err()
        {
            fail("settings table");
        }
    }
    let mut mem = [0xFF; FLASH_SIZE];
    measure(out, timer, &table, &mut mem);
}

/// A store over `mem` with an empty cache, as at boot.
fn boot(mem: &mut [u8; FLASH_SIZE]) -> Store<'_> {
    Store::with_page_cache(Flash::new(mem), 0..FLASH_SIZE as u32).unwrap_or_else(|_| fail("store"))
}

/// Stores a first snapshot into `mem` (erased), then measures finding it, loading it and
/// storing new values, each checked.
fn measure(
    out: &mut Uart,
    timer: &Timer,
    table: &Settings<'_, M, SETTINGS>,
    mem: &mut [u8; FLASH_SIZE],
) {
    // The snapshot at boot: a first store into the erased flash (not measured).
    let mut store = boot(mem);
    set_all(first);
    if !block_on(store.save(table)).is_ok_and(|r| r.entries == SETTINGS) {
        fail("first store");
    }
    let now = || timer.now();

    // Finding and checking the snapshot alone (what a load does before applying it).
    let mut store = boot(store.into_flash().into_inner());
    let (found, t_read) = ticks(now, u32::MAX, || {
        block_on(black_box(&mut store).snapshot()).map(|r| r.map(|r| r.len()))
    });
    if found != Ok(Some(SETTINGS)) {
        fail("snapshot");
    }

    // Boot: the defaults, a new store and an empty cache over the same flash.
    set_all(|_| 0.0);
    let mut store = boot(store.into_flash().into_inner());
    let (loaded, t_load) = ticks(now, u32::MAX, || {
        block_on(black_box(&mut store).load(black_box(table)))
    });
    let all_applied = LoadReport {
        found: true,
        entries: SETTINGS,
        applied: SETTINGS,
        ..LoadReport::default()
    };
    if loaded != Ok(all_applied) || !all_are(first) {
        fail("load");
    }

    // A store of new values, as the store task does it after the boot load.
    set_all(second);
    let (saved, t_save) = ticks(now, u32::MAX, || {
        block_on(black_box(&mut store).save(black_box(table)))
    });
    let Ok(saved) = saved else { fail("store") };
    // Check: a reboot loads the new values.
    set_all(|_| 0.0);
    let mut store = boot(store.into_flash().into_inner());
    if saved.entries != SETTINGS
        || block_on(store.load(table)) != Ok(all_applied)
        || !all_are(second)
    {
        fail("store does not load back");
    }

    let _ = writeln!(
        out,
        "settings: {SETTINGS} persistent f32 settings ({NAME_LEN}-byte names), record \
         {} B, {} B in flash (3 x 16 KiB pages, 4-byte words)",
        saved.record_bytes, saved.flash_bytes
    );
    result(
        out,
        "settings-read",
        t_read,
        SETTINGS,
        "setting",
        "PersistentStore::snapshot at boot: finds and checks the snapshot",
    );
    result(
        out,
        "settings-load",
        t_load,
        SETTINGS,
        "setting",
        "PersistentStore::load at boot: the same, and applies every entry",
    );
    result(
        out,
        "settings-save",
        t_save,
        SETTINGS,
        "setting",
        "PersistentStore::save after the load: second snapshot and read-back",
    );
}
