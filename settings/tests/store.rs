//! Load and save semantics of the persistent store, over RAM flash.

mod common;

use common::*;
use embassy_futures::block_on;
use pprz_messages::settings::{SettingDesc, SettingType};
use pprz_settings::record::{ENTRY_LEN, HEADER_LEN, Record, RecordError};
use pprz_settings::sequential_storage::cache::Cache;
use pprz_settings::sequential_storage::map::{MapConfig, MapConfigError, MapStorage};
use pprz_settings::{
    ConfigError, LoadReport, PageCache, PersistentStore, RamFlash, SNAPSHOT_KEY, SnapshotKey,
    StoreError, buffer_len,
};

const SIZE: usize = 3 * 1024;
type Flash<'m> = RamFlash<'m, SIZE, 4, 1024>;
type Store<'m> = PersistentStore<Flash<'m>, PageCache<3>, { buffer_len(16) }>;

fn store(mem: &mut [u8; SIZE]) -> Store<'_> {
    Store::with_page_cache(Flash::new(mem), 0..SIZE as u32).unwrap()
}

#[test]
fn a_snapshot_survives_a_reboot() {
    let mut mem = [0xFF; SIZE];
    let report = save(&mut store(&mut mem), &A).unwrap();
    assert_eq!(report.entries, 5);
    assert_eq!(report.record_bytes, HEADER_LEN + 5 * ENTRY_LEN);
    // 8-byte item header, then the record padded to the 4-byte word (the key has no
    // bytes).
    assert_eq!(report.flash_bytes, 8 + 49usize.next_multiple_of(4));

    let (report, values) = load(&mut store(&mut mem));
    assert_eq!(
        report.unwrap(),
        LoadReport {
            found: true,
            entries: 5,
            applied: 5,
            ..LoadReport::default()
        }
    );
    assert_eq!(values, loaded(A));
}

#[test]
fn without_a_snapshot_defaults_are_kept() {
    let mut mem = [0xFF; SIZE];
    let (report, values) = load(&mut store(&mut mem));
    assert_eq!(
        report.unwrap(),
        LoadReport {
            found: false,
            missing: 5,
            ..LoadReport::default()
        }
    );
    assert_eq!(values, DEFAULTS);
    assert!(block_on(store(&mut mem).snapshot()).unwrap().is_none());
}

#[test]
fn the_newest_snapshot_wins_across_many_pages() {
    let mut mem = [0xFF; SIZE];
    let mut s = store(&mut mem);
    for i in 0..200 {
        let mut v = A;
        v[0] = (i % 10) as f32;
        save(&mut s, &v).unwrap();
    }
    save(&mut s, &B).unwrap();
    let _ = s.into_flash();
    assert_eq!(load(&mut store(&mut mem)).1, loaded(B));
}

/// The same variables, changed: `gain` bounds now 0..5, `mode` a float, `rate` gone,
/// `offset` new.
static CHANGED: [SettingDesc<'static>; 5] = [
    SettingDesc::new(0, "gain", 0.0, 5.0).persistent(true),
    SettingDesc::new(1, "mode", 0.0, 3.0).persistent(true),
    SettingDesc::new(2, "offset", -1.0, 1.0).persistent(true),
    SettingDesc::new(3, "trim", -1.0, 1.0).persistent(true),
    SettingDesc::new(4, "enabled", 0.0, 1.0)
        .ty(SettingType::Bool)
        .persistent(true),
];

#[test]
fn entries_match_by_key_and_type_and_bounds_apply() {
    let mut mem = [0xFF; SIZE];
    // gain 7.75 (now out of bounds), mode 3 as uint8 (now a float), rate 42 (gone).
    save(&mut store(&mut mem), &B).unwrap();
    let defaults = [1.0, 0.0, 0.5, 0.0, 1.0];
    let vars = Vars::new(&defaults);
    let report = with_table_of(&CHANGED, &vars, |t| block_on(store(&mut mem).load(t)));
    assert_eq!(
        report.unwrap(),
        LoadReport {
            found: true,
            entries: 5,
            applied: 2,    // trim, enabled
            refused: 1,    // gain
            unknown: 1,    // rate
            mismatched: 1, // mode
            missing: 1,    // offset
        }
    );
    assert_eq!(vars.values::<5>(), [1.0, 0.0, 0.5, -0.5, 0.0]);
}

#[test]
fn a_value_that_is_not_finite_is_stored_and_refused_at_load() {
    let mut mem = [0xFF; SIZE];
    let mut v = A;
    v[0] = f32::NAN;
    save(&mut store(&mut mem), &v).unwrap();
    let (report, values) = load(&mut store(&mut mem));
    let report = report.unwrap();
    assert_eq!((report.applied, report.refused), (4, 1));
    assert_eq!(values[0], DEFAULTS[0]);
    assert_eq!(values[1..], loaded(A)[1..]);
}

static TWICE: [SettingDesc<'static>; 3] = [
    SettingDesc::new(0, "gain", 0.0, 10.0).persistent(true),
    SettingDesc::new(1, "other", 0.0, 10.0).persistent(true),
    SettingDesc::new(2, "gain", 0.0, 10.0).persistent(true),
];

#[test]
fn a_variable_bound_twice_is_stored_once() {
    let mut mem = [0xFF; SIZE];
    let vars = Vars::new(&[3.0, 4.0, 3.0]);
    let report = with_table_of(&TWICE, &vars, |t| block_on(store(&mut mem).save(t)));
    assert_eq!(report.unwrap().entries, 2);
    let vars = Vars::new(&[0.0, 0.0, 0.0]);
    let report = with_table_of(&TWICE, &vars, |t| block_on(store(&mut mem).load(t)));
    let report = report.unwrap();
    assert_eq!((report.entries, report.applied, report.missing), (2, 2, 0));
    // The first setting of the variable is set (here the two are distinct atomics).
    assert_eq!(vars.values::<3>(), [3.0, 4.0, 0.0]);
}

#[test]
fn too_many_settings_for_the_buffer_writes_nothing() {
    let mut mem = [0xFF; SIZE];
    let mut small = PersistentStore::<Flash<'_>, PageCache<3>, { buffer_len(2) }>::with_page_cache(
        Flash::new(&mut mem),
        0..SIZE as u32,
    )
    .unwrap();
    // buffer_len(2) = 32 bytes: 32 - 4 = 28 = three entries.
    assert_eq!(
        PersistentStore::<Flash<'_>, PageCache<3>, { buffer_len(2) }>::capacity(),
        3
    );
    assert_eq!(
        save(&mut small, &A),
        Err(StoreError::TooManySettings {
            persistent: 5,
            capacity: 3
        })
    );
    let _ = small.into_flash();
    assert!(mem.iter().all(|b| *b == 0xFF));
}

#[test]
fn a_snapshot_larger_than_the_buffer_is_a_typed_error() {
    let mut mem = [0xFF; SIZE];
    save(&mut store(&mut mem), &A).unwrap();
    let mut small = PersistentStore::<Flash<'_>, PageCache<3>, { buffer_len(2) }>::with_page_cache(
        Flash::new(&mut mem),
        0..SIZE as u32,
    )
    .unwrap();
    let (report, values) = load(&mut small);
    assert!(matches!(
        report,
        Err(StoreError::BufferTooSmall { needed: 52 })
    ));
    assert_eq!(values, DEFAULTS);
    // Clearing erases the range: the map cannot take an empty snapshot it cannot read.
    block_on(small.clear()).unwrap();
    assert_eq!(
        load(&mut small).0.unwrap(),
        LoadReport {
            missing: 5,
            ..LoadReport::default()
        }
    );
}

#[test]
fn stored_bytes_that_are_not_a_record_are_a_typed_error() {
    let mut mem = [0xFF; SIZE];
    let mut map = MapStorage::<SnapshotKey, _, _>::new(
        Flash::new(&mut mem),
        MapConfig::new(0..SIZE as u32),
        Cache::new_uncached(),
    );
    let mut buf = [0u8; 64];
    let garbage: &[u8] = b"XY\x01\x00";
    block_on(map.store_item(&mut buf, &SNAPSHOT_KEY, &garbage)).unwrap();
    let _ = map.destroy();
    let (report, values) = load(&mut store(&mut mem));
    assert_eq!(
        report,
        Err(StoreError::Record(RecordError::BadMagic { found: *b"XY" }))
    );
    assert_eq!(values, DEFAULTS);
    // Storing over it works.
    save(&mut store(&mut mem), &A).unwrap();
    assert_eq!(load(&mut store(&mut mem)).1, loaded(A));
}

#[test]
fn clear_forgets_and_the_store_keeps_working() {
    let mut mem = [0xFF; SIZE];
    let mut s = store(&mut mem);
    // Fill part of a page so the cache points into it.
    for _ in 0..5 {
        save(&mut s, &A).unwrap();
    }
    assert!(load(&mut s).0.unwrap().found);
    block_on(s.clear()).unwrap();
    let (report, values) = load(&mut s);
    assert_eq!(
        report.unwrap(),
        LoadReport {
            found: true,
            entries: 0,
            missing: 5,
            ..LoadReport::default()
        }
    );
    assert_eq!(values, DEFAULTS);
    // After a clear, the same store (same cache) stores where a reboot finds it.
    save(&mut s, &B).unwrap();
    save(&mut s, &C).unwrap();
    let _ = s.into_flash();
    assert_eq!(load(&mut store(&mut mem)).1, loaded(C));
}

#[test]
fn the_snapshot_is_readable_as_a_record() {
    let mut mem = [0xFF; SIZE];
    save(&mut store(&mut mem), &A).unwrap();
    let mut s = store(&mut mem);
    let record: Record<'_> = block_on(s.snapshot()).unwrap().unwrap();
    assert_eq!(record.len(), 5);
    let gain = record.find(DESCS[0].key()).unwrap();
    assert_eq!((gain.ty, gain.value), (SettingType::Float, A[0]));
    let mode = record.find(DESCS[1].key()).unwrap();
    assert_eq!((mode.ty, mode.value), (SettingType::U8, A[1]));
    assert!(record.find(DESCS[VOLATILE].key()).is_none());
}

#[test]
fn bad_configurations_are_refused() {
    let mut mem = [0xFF; SIZE];
    assert!(matches!(
        Store::with_page_cache(Flash::new(&mut mem), 512..SIZE as u32),
        Err(ConfigError::Map(
            MapConfigError::StartRangeNotAtPageBoundary
        ))
    ));
    assert!(matches!(
        Store::with_page_cache(Flash::new(&mut mem), 0..1024),
        Err(ConfigError::Map(MapConfigError::RangeTooSmall))
    ));
    assert!(matches!(
        PersistentStore::<Flash<'_>, PageCache<2>, 64>::with_page_cache(
            Flash::new(&mut mem),
            0..SIZE as u32
        ),
        Err(ConfigError::PageCount { pages: 3, cache: 2 })
    ));
    assert!(matches!(
        PersistentStore::<Flash<'_>, PageCache<3>, 2>::with_page_cache(
            Flash::new(&mut mem),
            0..SIZE as u32
        ),
        Err(ConfigError::Buffer { len: 2, min: 4 })
    ));
    // A reversed range (sequential-storage's own check would underflow).
    #[allow(clippy::reversed_empty_ranges)]
    let reversed = 2048..0;
    assert!(matches!(
        Store::with_page_cache(Flash::new(&mut mem), reversed.clone()),
        Err(ConfigError::Map(MapConfigError::RangeTooSmall))
    ));
    assert!(matches!(
        PersistentStore::<_, _, { buffer_len(8) }>::new(
            Flash::new(&mut mem),
            reversed,
            Cache::new_uncached
        ),
        Err(ConfigError::Map(MapConfigError::RangeTooSmall))
    ));
    // Without a cache.
    let mut s = PersistentStore::<_, _, { buffer_len(8) }>::new(
        Flash::new(&mut mem),
        0..SIZE as u32,
        Cache::new_uncached,
    )
    .unwrap();
    save(&mut s, &A).unwrap();
    assert_eq!(load(&mut s).1, loaded(A));
}

#[test]
fn capacity_follows_the_buffer_and_the_word() {
    type Word4<'m> = PersistentStore<Flash<'m>, PageCache<3>, { buffer_len(16) }>;
    type Word32<'m> =
        PersistentStore<RamFlash<'m, 4096, 32, 2048>, PageCache<2>, { buffer_len(16) }>;
    assert_eq!(buffer_len(16), 160);
    assert_eq!(Word4::capacity(), 17);
    assert_eq!(Word32::capacity(), 17);
    assert_eq!(buffer_len(100), 928);
    assert_eq!(
        PersistentStore::<Flash<'_>, PageCache<3>, { buffer_len(300) }>::capacity(),
        255
    );
}

#[test]
fn a_32_byte_word_flash_works() {
    type Store32<'m> =
        PersistentStore<RamFlash<'m, 4096, 32, 2048>, PageCache<2>, { buffer_len(8) }>;
    fn make(mem: &mut [u8; 4096]) -> Store32<'_> {
        Store32::with_page_cache(RamFlash::new(mem), 0..4096).unwrap()
    }
    let mut mem = [0xFF; 4096];
    let report = save(&mut make(&mut mem), &A).unwrap();
    // 32-byte item header, key and record padded to 64.
    assert_eq!(report.flash_bytes, 32 + 64);
    for _ in 0..50 {
        save(&mut make(&mut mem), &B).unwrap();
    }
    save(&mut make(&mut mem), &C).unwrap();
    assert_eq!(load(&mut make(&mut mem)).1, loaded(C));
}

#[test]
fn erase_empties_the_range_and_the_store_keeps_working_with_its_cache() {
    let mut mem = [0xFF; SIZE];
    let mut s = store(&mut mem);
    // Fill part of a page so the cache points into it.
    for _ in 0..5 {
        save(&mut s, &A).unwrap();
    }
    block_on(s.erase()).unwrap();
    assert!(!load(&mut s).0.unwrap().found);
    // After an erase, the same store (its cache renewed) stores where a reboot finds it.
    save(&mut s, &B).unwrap();
    save(&mut s, &C).unwrap();
    let _ = s.into_flash();
    assert_eq!(load(&mut store(&mut mem)).1, loaded(C));
    // The range holds the last two snapshots only.
    let used = mem.iter().filter(|b| **b != 0xFF).count();
    assert!(used < 2 * 64, "{used} bytes used");
}

#[test]
fn an_empty_item_in_flash_is_a_typed_error_and_clear_recovers() {
    // An item of length 0 with matching checksums, newest in the map (after a real
    // snapshot): sequential-storage hands back a buffer that was never written for it.
    let mut mem = [0xFF; SIZE];
    save(&mut store(&mut mem), &A).unwrap();
    let mut map = MapStorage::<SnapshotKey, _, _>::new(
        Flash::new(&mut mem),
        MapConfig::new(0..SIZE as u32),
        Cache::new_uncached(),
    );
    let mut buf = [0u8; 64];
    let empty: &[u8] = &[];
    block_on(map.store_item(&mut buf, &SNAPSHOT_KEY, &empty)).unwrap();
    let _ = map.destroy();
    let (report, values) = load(&mut store(&mut mem));
    assert_eq!(
        report,
        Err(StoreError::Record(RecordError::TooShort { len: 0 }))
    );
    assert_eq!(values, DEFAULTS);
    block_on(store(&mut mem).clear()).unwrap();
    assert_eq!(load(&mut store(&mut mem)).1, DEFAULTS);
    save(&mut store(&mut mem), &B).unwrap();
    assert_eq!(load(&mut store(&mut mem)).1, loaded(B));
}

/// Thirteen persistent floats, `s0` to `s12`.
static MANY: [SettingDesc<'static>; 13] = {
    const NAMES: [&str; 13] = [
        "s0", "s1", "s2", "s3", "s4", "s5", "s6", "s7", "s8", "s9", "s10", "s11", "s12",
    ];
    let mut descs = [SettingDesc::new(0, "", 0.0, 1.0); 13];
    let mut i = 0;
    while i < 13 {
        descs[i] = SettingDesc::new(i as u8, NAMES[i], -100.0, 100.0).persistent(true);
        i += 1;
    }
    descs
};

#[test]
fn in_two_pages_a_snapshot_over_half_a_page_is_refused_before_writing() {
    // Two pages of 256 bytes, 4-byte words: 248 usable bytes a page. Twelve settings
    // take 8 + 112 = 120 bytes in flash, two fit in a page; thirteen take 132.
    const TWO: usize = 512;
    type Two<'m> = PersistentStore<RamFlash<'m, TWO, 4, 256>, PageCache<2>, { buffer_len(13) }>;
    for n in [12, 13] {
        let mut mem = [0xFF; TWO];
        let values: Vec<f32> = (0..n).map(|i| i as f32).collect();
        let vars = Vars::new(&values);
        let outcomes: Vec<_> = with_table_of(&MANY[..n], &vars, |t| {
            (0..20)
                .map(|round| {
                    vars.set(0, round as f32);
                    let mut s =
                        Two::with_page_cache(RamFlash::new(&mut mem), 0..TWO as u32).unwrap();
                    block_on(s.save(t)).map(|r| r.flash_bytes)
                })
                .collect()
        });
        if n == 12 {
            assert!(outcomes.iter().all(|o| *o == Ok(120)), "{outcomes:?}");
        } else {
            assert!(
                outcomes.iter().all(|o| *o == Err(StoreError::TooBig)),
                "{outcomes:?}"
            );
            assert!(mem.iter().all(|b| *b == 0xFF), "nothing written");
        }
    }
}

/// Two variables whose names have the same FNV-1a key.
static COLLIDING: [SettingDesc<'static>; 2] = [
    SettingDesc::new(0, "liquid", 0.0, 100.0).persistent(true),
    SettingDesc::new(1, "costarring", 0.0, 100.0).persistent(true),
];

#[test]
fn two_variables_with_one_key_are_refused_before_writing() {
    assert_eq!(COLLIDING[0].key(), COLLIDING[1].key());
    let mut mem = [0xFF; SIZE];
    let vars = Vars::new(&[11.0, 22.0]);
    let report = with_table_of(&COLLIDING, &vars, |t| block_on(store(&mut mem).save(t)));
    assert_eq!(
        report,
        Err(StoreError::KeyCollision {
            key: COLLIDING[0].key()
        })
    );
    assert!(mem.iter().all(|b| *b == 0xFF), "nothing written");
}
