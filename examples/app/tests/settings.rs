//! The application's settings: the generated table is the one `settings.xml` declares,
//! and the running application refuses what the file's bounds exclude, answering with
//! the value in force.

mod common;

use std::cell::RefCell;
use std::convert::Infallible;
use std::path::Path;

use embassy_futures::select::{Either3, select3};
use embassy_time::{Duration, Instant, MockDriver, Timer};
use pprz_default::messages::telemetry::values::RotorcraftStatusApMode as ApMode;
use pprz_default::periodic::{SCHEDULE, main};
use pprz_example_app::settings::{COUNT, SETTINGS, index};
use pprz_example_app::{AC_ID, Config, M, run_aircraft};
use pprz_messages::settings::SettingType;
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, run_writer};
use pprz_transports::PprzV2;

use common::{Air, dl_values, run_on_mock_clock, setting_frame};

/// What the generator reads from the application's `settings.xml`.
fn from_file() -> pprz_codegen::SettingsSet {
    let xml = Path::new(env!("CARGO_MANIFEST_DIR")).join("settings.xml");
    pprz_codegen::Generator::for_settings([xml])
        .settings_set()
        .unwrap_or_else(|e| panic!("settings.xml: {e}"))
}

#[test]
fn the_table_is_the_one_of_settings_xml() {
    let file = from_file();
    assert!(file.warnings.is_empty(), "warnings: {:?}", file.warnings);
    assert_eq!(file.settings.len(), COUNT);
    for (def, desc) in file.settings.iter().zip(&SETTINGS) {
        assert_eq!(usize::from(def.index), usize::from(desc.index));
        assert_eq!(def.var, desc.var);
        assert_eq!(def.shortname.as_deref(), desc.shortname);
        assert_eq!(
            (def.min, def.max, def.step),
            (desc.min, desc.max, desc.step)
        );
        assert_eq!(def.ty, desc.ty);
        assert_eq!(def.values, desc.values, "labels of {}", def.var);
        assert_eq!(def.persistent, desc.persistent, "{}", def.var);
    }

    // The indices the ground, the tests and the docs use.
    assert_eq!(
        [
            index::TELEMETRY_MODE_MAIN,
            index::PAYLOAD_FLOOD,
            index::GAIN,
            index::AP_MODE,
            index::SETTINGS_STORE_FLAG
        ],
        [0, 1, 2, 3, 4]
    );
    let bounds = |i: u8| {
        let d = &SETTINGS[usize::from(i)];
        (d.name(), d.min, d.max)
    };
    assert_eq!(bounds(index::TELEMETRY_MODE_MAIN), ("Telemetry", 0.0, 2.0));
    assert_eq!(bounds(index::PAYLOAD_FLOOD), ("flood", 0.0, 1.0));
    assert_eq!(bounds(index::GAIN), ("gain", 0.0, 10.0));
    assert_eq!(bounds(index::AP_MODE), ("ap_mode", 0.0, 19.0));
    assert_eq!(bounds(index::SETTINGS_STORE_FLAG), ("store", 0.0, 1.0));
    let flag = &SETTINGS[usize::from(index::SETTINGS_STORE_FLAG)];
    assert_eq!(flag.handler, Some("StoreSettings"));
    assert_eq!(flag.module, Some("settings"));
    assert_eq!(flag.values, ["OFF", "STORE"]);
    assert!(!flag.persistent);
    let gain = &SETTINGS[usize::from(index::GAIN)];
    assert!(gain.persistent);
    assert_eq!((gain.ty, gain.step), (SettingType::Float, 0.1));
    assert_eq!(SETTINGS.iter().filter(|d| d.persistent).count(), 1);
}

#[test]
fn the_labels_are_those_of_telemetry_xml_and_messages_xml() {
    // Telemetry modes: those of process Main, in order.
    let process = &SCHEDULE.processes[main::PROCESS];
    let mode = &SETTINGS[usize::from(index::TELEMETRY_MODE_MAIN)];
    assert_eq!(mode.var, format!("telemetry_mode_{}", process.name));
    let modes: Vec<&str> = process.modes.iter().map(|m| m.name).collect();
    assert_eq!(mode.values, modes.as_slice());

    // Autopilot modes: ROTORCRAFT_STATUS ap_mode, every value of the bounds.
    let ap = &SETTINGS[usize::from(index::AP_MODE)];
    assert_eq!(ap.ty, SettingType::U8);
    for raw in 0..=u8::MAX {
        let label = ApMode::from_raw(raw).map(ApMode::label);
        assert_eq!(ap.label(f32::from(raw)), label, "ap_mode {raw}");
    }
    assert_eq!(ap.label(f32::from(ApMode::Home.raw())), Some("HOME"));
    assert_eq!(ap.label(f32::from(ApMode::Nav.raw())), Some("NAV"));
}

/// The ground's SETTING requests: time (ms after boot), index, value, and the value the
/// aircraft must answer. Times fall between the scheduler's ticks (60 Hz), so the first
/// DL_VALUE of the index after a request is its acknowledgement.
const REQUESTS: [(u64, u8, f32, f32); 10] = [
    (1_005, index::GAIN, 11.0, 1.0),    // above 10: refused, 1 in force
    (2_005, index::GAIN, 2.5, 2.5),     // accepted
    (3_005, index::GAIN, -0.5, 2.5),    // below 0: refused
    (4_005, index::GAIN, 10.0, 10.0),   // the bound itself
    (5_005, index::AP_MODE, 5.0, 13.0), // a mode of the bounds the aircraft has not: NAV stays
    (6_005, index::AP_MODE, 2.0, 2.0),  // HOME
    (7_005, index::AP_MODE, 20.0, 2.0), // beyond GUIDED (19): refused
    (8_005, index::TELEMETRY_MODE_MAIN, 3.0, 0.0), // no fourth mode: refused
    (9_005, index::PAYLOAD_FLOOD, 1.0, 1.0),
    (9_505, index::SETTINGS_STORE_FLAG, 1.0, 0.0), // no store: nothing is stored
];

/// The ground's radio: delivers each request frame at its time, then nothing.
struct Ground {
    next: usize,
}

impl embedded_io_async::ErrorType for Ground {
    type Error = Infallible;
}

impl embedded_io_async::Read for Ground {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let Some(&(at_ms, index, value, _)) = REQUESTS.get(self.next) else {
            return core::future::pending().await;
        };
        Timer::at(Instant::from_millis(at_ms)).await;
        self.next += 1;
        let frame = setting_frame(index, value);
        buf[..frame.len()].copy_from_slice(&frame);
        Ok(frame.len())
    }
}

#[test]
fn the_aircraft_refuses_values_outside_the_bounds_of_settings_xml() {
    MockDriver::get().reset();
    static ARENA: FrameArena<M, 8192> = FrameArena::new();
    let radio = DeviceConfig::new(PprzV2::new().into());
    let downlink: Downlink<'_, M, 1, 32> = Downlink::new(&ARENA, AC_ID, [radio]);
    let [mut port] = downlink.ports().unwrap();
    let written = RefCell::new(Vec::new());
    let app = run_aircraft(port.device(), Ground { next: 0 }, Config::default());
    let writer = run_writer(&mut port, Air(&written));
    let end = Timer::at(Instant::from_millis(10_000));
    match run_on_mock_clock(select3(app, writer, end)) {
        Either3::First(Err(e)) => panic!("the application did not start: {e}"),
        Either3::First(Ok(never)) => match never {},
        Either3::Second(never) => match never {},
        Either3::Third(()) => {}
    }

    let values = dl_values(&written.into_inner());
    for (at_ms, index, value, answer) in REQUESTS {
        let at = Instant::from_millis(at_ms);
        let ack = values.iter().find(|(t, i, _)| *t >= at && *i == index);
        let Some(&(t, _, v)) = ack else {
            panic!("no DL_VALUE of setting {index} after {at_ms} ms");
        };
        assert!(
            t - at < Duration::from_millis(50),
            "setting {index} answered late"
        );
        assert_eq!(v, answer, "SETTING({index}, {value}) at {at_ms} ms");
    }
    // A refused gain was never in force.
    assert!(
        values
            .iter()
            .filter(|(_, i, _)| *i == index::GAIN)
            .all(|(_, _, v)| [1.0, 2.5, 10.0].contains(v)),
        "{values:?}"
    );
}
