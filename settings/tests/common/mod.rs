//! A settings table for the tests: five persistent settings of several types and one that
//! is not persistent, bound to atomics.

#![allow(dead_code)]

use std::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::block_on;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embedded_storage_async::nor_flash::NorFlash;
use pprz_messages::settings::{SettingDesc, SettingType};
use pprz_settings::sequential_storage::cache::CacheImpl;
use pprz_settings::{LoadReport, PersistentStore, SaveReport, SnapshotKey, StoreError};
use pprz_telemetry::settings::{Binding, Settings};

/// Settings of the table.
pub const K: usize = 6;
/// Index of the setting that is not persistent.
pub const VOLATILE: usize = 3;

/// The table's descriptions.
pub static DESCS: [SettingDesc<'static>; K] = [
    SettingDesc::new(0, "gain", 0.0, 10.0).persistent(true),
    SettingDesc::new(1, "mode", 0.0, 3.0)
        .ty(SettingType::U8)
        .persistent(true),
    SettingDesc::new(2, "rate", -100.0, 100.0)
        .ty(SettingType::I16)
        .persistent(true),
    SettingDesc::new(3, "telemetry", 0.0, 5.0),
    SettingDesc::new(4, "trim", -1.0, 1.0).persistent(true),
    SettingDesc::new(5, "enabled", 0.0, 1.0)
        .ty(SettingType::Bool)
        .persistent(true),
];

/// Values at boot.
pub const DEFAULTS: [f32; K] = [1.0, 0.0, 5.0, 2.0, 0.0, 0.0];
/// Three snapshots, every persistent value different in each.
pub const A: [f32; K] = [2.5, 1.0, -7.0, 4.0, 0.25, 1.0];
pub const B: [f32; K] = [7.75, 3.0, 42.0, 1.0, -0.5, 0.0];
pub const C: [f32; K] = [0.125, 2.0, 99.0, 5.0, 1.0, 1.0];

/// The values a load of `snapshot` gives: its persistent values, the default for the
/// setting that is not persistent.
pub fn loaded(snapshot: [f32; K]) -> [f32; K] {
    let mut v = snapshot;
    v[VOLATILE] = DEFAULTS[VOLATILE];
    v
}

/// The variables behind a table.
pub struct Vars(Vec<AtomicU32>);

impl Vars {
    pub fn new(values: &[f32]) -> Self {
        Vars(values.iter().map(|v| AtomicU32::new(v.to_bits())).collect())
    }

    pub fn get(&self, i: usize) -> f32 {
        f32::from_bits(self.0[i].load(Ordering::Relaxed))
    }

    pub fn set(&self, i: usize, v: f32) {
        self.0[i].store(v.to_bits(), Ordering::Relaxed);
    }

    pub fn values<const N: usize>(&self) -> [f32; N] {
        std::array::from_fn(|i| self.get(i))
    }
}

/// The table type of the tests.
pub type Table<'a> = Settings<'a, NoopRawMutex, 16>;

/// Calls `f` with a table of `descs` bound to `vars`.
pub fn with_table_of<R>(
    descs: &'static [SettingDesc<'static>],
    vars: &Vars,
    f: impl FnOnce(&Table<'_>) -> R,
) -> R {
    type Get<'v> = Box<dyn Fn() -> f32 + Sync + 'v>;
    type Set<'v> = Box<dyn Fn(f32) + Sync + 'v>;
    let gets: Vec<Get<'_>> = (0..descs.len())
        .map(|i| Box::new(move || vars.get(i)) as Get<'_>)
        .collect();
    let sets: Vec<Set<'_>> = (0..descs.len())
        .map(|i| Box::new(move |v| vars.set(i, v)) as Set<'_>)
        .collect();
    let table = Table::new();
    for (i, desc) in descs.iter().enumerate() {
        table
            .add_desc(desc, Binding::Fns(&*gets[i], &*sets[i]))
            .unwrap();
    }
    f(&table)
}

/// Calls `f` with the tests' table bound to `vars`.
pub fn with_table<R>(vars: &Vars, f: impl FnOnce(&Table<'_>) -> R) -> R {
    with_table_of(&DESCS, vars, f)
}

/// Stores a snapshot of the table holding `values`.
pub fn save<S: NorFlash, C: CacheImpl<SnapshotKey>, const BUF: usize>(
    store: &mut PersistentStore<S, C, BUF>,
    values: &[f32; K],
) -> Result<SaveReport, StoreError<S::Error>> {
    let vars = Vars::new(values);
    with_table(&vars, |table| block_on(store.save(table)))
}

/// Loads into a table at its defaults; the values after the load.
pub fn load<S: NorFlash, C: CacheImpl<SnapshotKey>, const BUF: usize>(
    store: &mut PersistentStore<S, C, BUF>,
) -> (Result<LoadReport, StoreError<S::Error>>, [f32; K]) {
    let vars = Vars::new(&DEFAULTS);
    let report = with_table(&vars, |table| block_on(store.load(table)));
    (report, vars.values())
}

/// A small deterministic generator (xorshift32) for the corruption tests.
pub struct Rng(pub u32);

impl Rng {
    pub fn next(&mut self) -> u32 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        x
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next() as usize) % n
    }
}
