//! The settings code generated for `tests/fixtures/settings/*.xml` is compared with
//! reviewed snapshots, and the snapshots are compiled here as a user's crate would
//! include them (public modules, denying warnings and missing docs; `cargo clippy
//! --all-targets -D warnings` checks them too) and run against the runtime's settings
//! table. After an intended change of the emitter, regenerate them with
//! `UPDATE_SNAPSHOTS=1 cargo test -p pprz-codegen --test settings_snapshot` and review
//! the diff.

#![deny(warnings, missing_docs)]

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use pprz_messages::settings::{SettingType, fnv1a};
use pprz_telemetry::settings::{Binding, Refusal, Settings, SettingsError};

/// Three settings: a gain, a trim in degrees for the ground and radians aboard, a mode.
pub mod three {
    include!("snapshots/settings_three.rs");
}

/// Names and numbers that are awkward in Rust.
pub mod edge {
    include!("snapshots/settings_edge.rs");
}

/// No settings at all.
pub mod empty {
    include!("snapshots/settings_empty.rs");
}

// Private and unused, as in a binary crate that includes the code and uses only part of
// it: nothing may be reported as dead code.
mod unused {
    include!("snapshots/settings_edge.rs");
}

#[test]
fn fixtures_match_snapshots() {
    for name in ["three", "edge", "empty"] {
        let fixture = format!("tests/fixtures/settings/{name}.xml");
        let snapshot = format!("tests/snapshots/settings_{name}.rs");
        let code = pprz_codegen::Generator::for_settings([&fixture])
            .generate_settings()
            .unwrap()
            .code;
        if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
            std::fs::write(&snapshot, &code).unwrap();
        }
        let expected = std::fs::read_to_string(&snapshot).unwrap_or_default();
        assert!(
            code == expected,
            "generated code differs from {snapshot}; rerun with UPDATE_SNAPSHOTS=1 and review the diff"
        );
    }
}

/// A value stored as bits, read and written through a binding.
struct Cell(AtomicU32);

impl Cell {
    const fn new() -> Self {
        Self(AtomicU32::new(0))
    }
    fn get(&self) -> f32 {
        f32::from_bits(self.0.load(Ordering::Relaxed))
    }
    fn set(&self, v: f32) {
        self.0.store(v.to_bits(), Ordering::Relaxed);
    }
}

#[test]
fn register_adds_every_setting_with_its_bounds() {
    let (gain, trim, mode) = (Cell::new(), Cell::new(), Cell::new());
    let (gain_get, gain_set) = (|| gain.get(), |v| gain.set(v));
    let (trim_get, trim_set) = (|| trim.get(), |v| trim.set(v));
    // The mode accepts only whole values (a handler's choice).
    let (mode_get, mode_set) = (|| mode.get(), |v: f32| mode.set(v.round()));
    let bindings = three::Bindings {
        gain: Binding::Fns(&gain_get, &gain_set),
        trim_roll: Binding::Fns(&trim_get, &trim_set),
        ap_mode: Binding::Fns(&mode_get, &mode_set),
    };
    let table: Settings<'_, NoopRawMutex, { three::COUNT }> = Settings::new();
    three::register(&table, &bindings).unwrap();
    assert_eq!(table.len(), 3);
    assert_eq!(
        (
            three::index::GAIN,
            three::index::TRIM_ROLL,
            three::index::AP_MODE
        ),
        (0, 1, 2)
    );

    // Bounds are refused, not clamped; the value in force is answered.
    assert_eq!(table.try_set(three::index::GAIN, 2.5), Ok(2.5));
    assert_eq!(
        table.try_set(three::index::GAIN, 12.0),
        Err(Refusal::OutOfBounds(2.5))
    );
    // 5 degrees on the ground is the bound aboard, in radians (converted in f64).
    let deg = 180.0 / core::f64::consts::PI;
    let five_deg = (5.0 / deg) as f32;
    assert_eq!(
        table.try_set(three::index::TRIM_ROLL, five_deg),
        Ok(five_deg)
    );
    assert_eq!(
        table.try_set(three::index::TRIM_ROLL, 5.0),
        Err(Refusal::OutOfBounds(five_deg))
    );
    assert_eq!(table.try_set(three::index::AP_MODE, 1.4), Ok(1.0));

    let entry = table.entry(three::index::GAIN).unwrap();
    assert_eq!(entry.name, "Gain");
    let desc = entry.desc.unwrap();
    assert!(desc.persistent);
    assert_eq!(desc.key(), fnv1a(b"gain"));
    let mode_desc = table.entry(2).unwrap().desc.unwrap();
    assert_eq!(mode_desc.ty, SettingType::U8);
    assert_eq!(mode_desc.label(2.0), Some("HOME"));
    assert_eq!(mode_desc.handler, Some("SetMode"));
    let trim_desc = &three::SETTINGS[1];
    assert_eq!(
        (trim_desc.alt_unit, trim_desc.alt_unit_coef),
        (Some("deg"), deg as f32)
    );
}

#[test]
fn register_wants_an_empty_table_large_enough() {
    let cell = Cell::new();
    let (get, set) = (|| cell.get(), |v| cell.set(v));
    let b = Binding::Fns(&get, &set);
    let bindings = three::Bindings {
        gain: b,
        trim_roll: b,
        ap_mode: b,
    };
    let small: Settings<'_, NoopRawMutex, 2> = Settings::new();
    assert_eq!(
        three::register(&small, &bindings),
        Err(SettingsError::Full { capacity: 2 })
    );
    let used: Settings<'_, NoopRawMutex, 8> = Settings::new();
    used.add("mine", &get, &set).unwrap();
    assert_eq!(
        three::register(&used, &bindings),
        Err(SettingsError::OutOfOrder { index: 0, next: 1 })
    );
}

#[test]
fn a_repeated_variable_has_one_binding_and_two_indices() {
    let (ty, other) = (Cell::new(), Cell::new());
    let (ty_get, ty_set) = (|| ty.get(), |v| ty.set(v));
    let (get, set) = (|| other.get(), |v| other.set(v));
    let b = Binding::Fns(&get, &set);
    let bindings = edge::Bindings {
        type_: Binding::Fns(&ty_get, &ty_set),
        self_: b,
        buf_0: b,
        ctl_gain: b,
        _4wd: b,
        gain: b,
    };
    let table: Settings<'_, NoopRawMutex, { edge::COUNT }> = Settings::new();
    edge::register(&table, &bindings).unwrap();
    assert_eq!(edge::index::TYPE_, 0);
    assert_eq!(edge::SETTINGS[5].var, "type");
    // Setting 5 is the same variable with its own bounds.
    assert_eq!(table.try_set(5, 3.0), Ok(3.0));
    assert_eq!(table.get(0), Some(3.0));
    assert_eq!(table.try_set(0, 3.0), Err(Refusal::OutOfBounds(3.0)));
    // A negative coefficient swaps the bounds: -2..4 shown is -2..1 aboard.
    let ctl = &edge::SETTINGS[usize::from(edge::index::CTL_GAIN)];
    assert_eq!((ctl.min, ctl.max, ctl.step), (-2.0, 1.0, 0.25));
    assert_eq!(
        edge::SETTINGS[1].shortname,
        Some("quote \" back\\slash \nnewline")
    );
    assert_eq!(edge::SETTINGS[0].values, ["no", "\"yes\""]);
}

#[test]
fn no_settings_register_nothing() {
    let table: Settings<'_, NoopRawMutex, 1> = Settings::new();
    let bindings = empty::Bindings {
        nothing: core::marker::PhantomData,
    };
    empty::register(&table, &bindings).unwrap();
    assert!(table.is_empty());
    assert_eq!(empty::SETTINGS.len(), empty::COUNT);
}
