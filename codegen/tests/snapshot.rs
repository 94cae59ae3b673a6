//! The generated code for `tests/fixtures/small.xml` is compared with a reviewed
//! snapshot, and the snapshot itself is compiled and exercised here. After an intended
//! change of the emitter, regenerate it with
//! `UPDATE_SNAPSHOTS=1 cargo test -p pprz-codegen --test snapshot` and review the diff.

// Cargo runs integration tests from the package root, so relative paths are stable and
// the snapshot does not depend on where the repository is checked out.
const FIXTURE: &str = "tests/fixtures/small.xml";
const SNAPSHOT: &str = "tests/snapshots/small.rs";

// Private here, so items this test does not touch would be reported as dead code.
#[allow(missing_docs, dead_code)]
mod small {
    include!("snapshots/small.rs");
}

#[test]
fn small_fixture_matches_snapshot() {
    let code = pprz_codegen::Generator::new(FIXTURE).generate().unwrap();
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::write(SNAPSHOT, &code).unwrap();
    }
    let expected = std::fs::read_to_string(SNAPSHOT).unwrap_or_default();
    assert!(
        code == expected,
        "generated code differs from {SNAPSHOT}; rerun with UPDATE_SNAPSHOTS=1 and review the diff"
    );
}

#[test]
fn snapshot_code_works() {
    use pprz_messages::{Chars, Decode, Message, VarArray};
    use small::telemetry::{Mixed, Pong, values::MixedMode};

    let samples = [-1i16, 2, 300];
    let m = Mixed {
        mode: MixedMode::V3D.raw(),
        samples: VarArray::new(&samples),
        type_: [1.0, 2.0, 3.0],
        name: Chars::from_str("ab"),
        tag: *b"TAG1",
        big: [9; 40],
        lat: -5,
    };
    let mut buf = [0u8; 128];
    let n = m.encode(&mut buf).unwrap();
    // mode, then the variable array (count 3 + 6 bytes), then the fields after it.
    assert_eq!(n, 1 + (1 + 6) + 12 + (1 + 2) + 4 + 40 + 4);
    assert_eq!(&buf[..9], &[2, 3, 0xFF, 0xFF, 2, 0, 0x2C, 0x01, 0]);
    let back = Mixed::decode(&buf[..n]).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.mode_value(), Some(MixedMode::V3D));
    assert_eq!(MixedMode::V2D.label(), "2D");
    assert_eq!(Mixed::default().big, [0; 40]);
    assert_eq!(
        (Mixed::MIN_LEN, Mixed::MAX_LEN),
        (1 + 1 + 12 + 1 + 4 + 40 + 4, 63 + 510 + 255)
    );
    assert_eq!(Mixed::PRIORITY, pprz_messages::priority::DEFAULT);
    assert_eq!(Pong::PRIORITY, 192);
    assert_eq!(small::datalink::Ping::PRIORITY, 10);
    let lat = Mixed::DESCRIPTOR.field("lat").unwrap();
    assert_eq!(lat.to_alt_unit(-5.0), -5e-7);
    assert_eq!(small::MESSAGES.len(), 7);
    let any = small::AnyMessage::decode(1, 7, &buf[..n]).unwrap();
    assert_eq!((any.class_id(), any.id(), any.name()), (1, 7, "MIXED"));
    assert_eq!(any, small::AnyMessage::Telemetry(m.into()));
    for cut in 0..n {
        assert!(Mixed::decode(&buf[..cut]).is_err());
    }
}

#[test]
fn snapshot_set_fills_the_roles() {
    use pprz_messages::roles::{
        GetSettingRequest, LinkReport, LinkReportSet, Pong, ServiceSet, SettingRequest,
        SettingValue,
    };
    use pprz_messages::{Decode, Message};
    use small::{Set, datalink, telemetry};

    // Compiles only if `Set` fills both roles with these types.
    fn services<
        S: ServiceSet<
                Ping = datalink::Ping,
                Pong = telemetry::Pong,
                Setting = datalink::Setting,
                GetSetting = datalink::GetSetting,
                DlValue = telemetry::DlValue,
            >,
    >() {
    }
    fn link_report<S: LinkReportSet<DatalinkReport = telemetry::DatalinkReport>>() {}
    services::<Set>();
    link_report::<Set>();

    assert_eq!(<Set as ServiceSet>::Pong::pong(), telemetry::Pong);
    let setting = <Set as ServiceSet>::Setting::decode(&[3, 7, 0, 0, 0xC0, 0x3F]).unwrap();
    assert_eq!(
        (setting.index(), setting.ac_id(), setting.value()),
        (3, 7, 1.5)
    );
    let get = <Set as ServiceSet>::GetSetting::decode(&[4, 9]).unwrap();
    assert_eq!((get.index(), get.ac_id()), (4, 9));
    let value = <Set as ServiceSet>::DlValue::new(3, 1.5);
    assert_eq!(
        value,
        telemetry::DlValue {
            index: 3,
            value: 1.5
        }
    );
    let mut buf = [0u8; 16];
    assert_eq!(value.encode(&mut buf), Ok(5));
    assert_eq!(&buf[..5], &[3, 0, 0, 0xC0, 0x3F]);

    let report = LinkReport {
        uplink_lost_time: 1,
        uplink_nb_msgs: 2,
        downlink_nb_msgs: 3,
        downlink_rate: 4,
        uplink_rate: 5,
        downlink_ovrn: 6,
    };
    let msg = <Set as LinkReportSet>::DatalinkReport::from(report);
    assert_eq!(msg.encode(&mut buf), Ok(11));
    assert_eq!(&buf[..11], &[1, 0, 2, 0, 3, 0, 4, 0, 5, 0, 6]);
}
