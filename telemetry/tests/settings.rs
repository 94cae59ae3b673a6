//! The settings table with descriptions from a `settings.xml`: values outside the bounds
//! and non-finite values are refused, answered with the value in force and counted;
//! descriptions go in index order.

mod common;

use std::sync::atomic::{AtomicU32, Ordering};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use pprz_default::messages::Set;
use pprz_default::messages::datalink::Setting;
use pprz_messages::settings::SettingDesc;
use pprz_telemetry::pprz_transports::PprzV2;
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::services::Services;
use pprz_telemetry::settings::{Binding, Refusal, SettingsError};
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena};

use common::frames::{dl_value_frame, uplink_frame};
use common::sim::mock_time;

const AC_ID: u8 = 7;

static GAIN: AtomicU32 = AtomicU32::new(0);
fn get_gain() -> f32 {
    f32::from_bits(GAIN.load(Ordering::Relaxed))
}
fn set_gain(v: f32) {
    GAIN.store(v.to_bits(), Ordering::Relaxed);
}

static DESCS: [SettingDesc<'static>; 2] = [
    SettingDesc::new(0, "gain", 0.0, 10.0),
    SettingDesc::new(1, "offset", -1.0, 1.0),
];

#[test]
fn settings_out_of_bounds_are_refused_answered_and_counted() {
    let _clock = mock_time();
    GAIN.store(2.0f32.to_bits(), Ordering::Relaxed);
    static ARENA: FrameArena<M, 2048> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 16> =
        Downlink::new(&ARENA, AC_ID, [DeviceConfig::new(PprzV2::new().into())]);
    let [mut port] = downlink.ports().unwrap();
    let services: Services<'_, Set, M, 4> = Services::new(AC_ID);
    services
        .settings()
        .add_desc(&DESCS[0], Binding::Fns(&get_gain, &set_gain))
        .unwrap();
    let datalink: Datalink<'_, M, 4> = Datalink::new(AC_ID);
    services.subscribe(datalink.registry()).unwrap();
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), port.device());

    for value in [3.5, 100.0, -0.5, f32::NAN, 10.0] {
        let frame = uplink_frame(
            &Setting {
                index: 0,
                ac_id: AC_ID,
                value,
            },
            AC_ID,
        );
        reader.feed(&frame, &datalink);
    }
    let mut replies = Vec::new();
    while let Some(frame) = port.try_next() {
        replies.push(frame.to_vec());
        frame.finish(true);
    }
    assert_eq!(
        replies,
        [3.5, 3.5, 3.5, 3.5, 10.0]
            .iter()
            .map(|v| dl_value_frame(AC_ID, 0, *v))
            .collect::<Vec<_>>(),
        "every SETTING answered with the value in force"
    );
    let s = services.stats();
    assert_eq!((s.settings, s.out_of_bounds, s.non_finite), (2, 2, 1));
    assert_eq!(get_gain(), 10.0);
}

#[test]
fn descriptions_go_in_index_order_and_refusals_say_why() {
    static ONE: AtomicU32 = AtomicU32::new(0);
    let get = || f32::from_bits(ONE.load(Ordering::Relaxed));
    let set = |v: f32| ONE.store(v.to_bits(), Ordering::Relaxed);
    let services: Services<'_, Set, M, 2> = Services::new(AC_ID);
    let table = services.settings();
    assert_eq!(
        table.add_desc(&DESCS[1], Binding::Fns(&get, &set)),
        Err(SettingsError::OutOfOrder { index: 1, next: 0 })
    );
    assert_eq!(table.add_desc(&DESCS[0], Binding::Fns(&get, &set)), Ok(0));
    assert_eq!(table.add_desc(&DESCS[1], Binding::Fns(&get, &set)), Ok(1));
    assert_eq!(
        table.add("third", &get, &set),
        Err(SettingsError::Full { capacity: 2 })
    );
    assert_eq!(table.entry(1).unwrap().name, "offset");
    assert_eq!(table.try_set(1, 0.5), Ok(0.5));
    assert_eq!(table.try_set(1, 1.5), Err(Refusal::OutOfBounds(0.5)));
    assert_eq!(table.try_set(1, f32::NAN), Err(Refusal::NonFinite(0.5)));
    assert_eq!(table.try_set(9, 0.0), Err(Refusal::UnknownIndex));
    let mut names = Vec::new();
    table.for_each(|i, e| names.push((i, e.name)));
    assert_eq!(names, [(0, "gain"), (1, "offset")]);
}
