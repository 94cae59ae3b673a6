//! The generated default message set: golden bytes, typed API, and round trips of every
//! message.

// Shared with the reference set's tests.
#[path = "../../telemetry/tests/common/roundtrip.rs"]
mod roundtrip;

use pprz_default::messages::{AnyMessage, MESSAGES, datalink, telemetry};
use pprz_messages::{Decode, DecodeError, EncodeError, Message, VarArray, priority};

#[test]
fn gps_golden_bytes() {
    let gps = telemetry::Gps {
        mode: 3,
        utm_east: 0x0102_0304,
        utm_north: -2,
        course: 0x0506,
        alt: 0x0708_090A,
        speed: 0x0B0C,
        climb: -3,
        week: 0x0D0E,
        itow: 0x0F10_1112,
        utm_zone: 31,
        gps_nb_err: 0xEE,
    };
    let mut buf = [0u8; 64];
    let n = gps.encode(&mut buf).unwrap();
    let expected = [
        3, // mode
        0x04, 0x03, 0x02, 0x01, // utm_east, little-endian
        0xFE, 0xFF, 0xFF, 0xFF, // utm_north = -2
        0x06, 0x05, // course
        0x0A, 0x09, 0x08, 0x07, // alt
        0x0C, 0x0B, // speed
        0xFD, 0xFF, // climb = -3
        0x0E, 0x0D, // week
        0x12, 0x11, 0x10, 0x0F, // itow
        31,   // utm_zone
        0xEE, // gps_nb_err
    ];
    assert_eq!(&buf[..n], &expected);
    assert_eq!(gps.encoded_len(), 27);
    assert_eq!(telemetry::Gps::decode(&expected), Ok(gps));
}

#[test]
fn alive_matches_the_protocol_example() {
    // ALIVE with md5sum = [0, 1, 2] has the fields 03 00 01 02 (the worked example of
    // docs/wire-formats.md).
    let alive = telemetry::Alive {
        md5sum: VarArray::new(&[0, 1, 2]),
    };
    let mut buf = [0u8; 8];
    let n = alive.encode(&mut buf).unwrap();
    assert_eq!(&buf[..n], &[0x03, 0x00, 0x01, 0x02]);
    let decoded = telemetry::Alive::decode(&buf[..n]).unwrap();
    assert_eq!(decoded.md5sum.as_bytes(), &[0, 1, 2]);
    assert_eq!((telemetry::Alive::CLASS_ID, telemetry::Alive::ID), (1, 2));
}

#[test]
fn text_and_empty_messages() {
    let v = telemetry::AutopilotVersion {
        version: 60_100,
        desc: "v6.1.0".into(),
    };
    let mut buf = [0u8; 32];
    let n = v.encode(&mut buf).unwrap();
    assert_eq!(&buf[..n], b"\xC4\xEA\x00\x00\x06v6.1.0");
    let back = telemetry::AutopilotVersion::decode(&buf[..n]).unwrap();
    assert_eq!(back.desc.to_str(), Ok("v6.1.0"));

    assert_eq!(telemetry::Pong.encode(&mut buf), Ok(0));
    assert_eq!(telemetry::Pong::decode(&[]), Ok(telemetry::Pong));
    assert_eq!(
        datalink::Ping::decode(&[1]),
        Err(DecodeError::TrailingBytes {
            expected: 0,
            actual: 1
        })
    );
}

#[test]
fn errors_are_typed_and_write_nothing() {
    let mut buf = [0xAAu8; 4];
    let v = telemetry::DlValue {
        index: 1,
        value: 2.0,
    };
    assert_eq!(
        v.encode(&mut buf),
        Err(EncodeError::BufferTooSmall {
            needed: 5,
            available: 4
        })
    );
    assert_eq!(buf, [0xAA; 4], "a failed encode writes nothing");
    let big = [7u8; 256];
    let payload = telemetry::Payload {
        values: VarArray::new(&big),
    };
    let mut out = [0u8; 300];
    assert_eq!(
        payload.encode(&mut out),
        Err(EncodeError::ArrayTooLong { len: 256 })
    );
    assert_eq!(
        telemetry::DlValue::decode(&[1, 2, 3]),
        Err(DecodeError::Truncated {
            needed: 5,
            actual: 3
        })
    );
    assert_eq!(
        telemetry::Alive::decode(&[4, 1, 2]),
        Err(DecodeError::Truncated {
            needed: 5,
            actual: 3
        })
    );
    assert_eq!(
        telemetry::AnyMessage::decode(99, &[]),
        Err(DecodeError::UnknownMessage {
            class_id: 1,
            msg_id: 99
        })
    );
    assert_eq!(
        AnyMessage::decode(7, 1, &[]),
        Err(DecodeError::UnknownMessage {
            class_id: 7,
            msg_id: 1
        })
    );
}

#[test]
fn priorities_follow_the_three_levels() {
    assert_eq!(telemetry::Pong::PRIORITY, priority::HIGH);
    assert_eq!(telemetry::DlValue::PRIORITY, priority::HIGH);
    assert_eq!(telemetry::Attitude::PRIORITY, priority::NORMAL);
    assert_eq!(telemetry::Payload::PRIORITY, priority::LOW);
    assert_eq!(telemetry::ImuGyroRaw::PRIORITY, priority::LOW);
    // Datalink messages carry no attribute: they get the documented default.
    assert_eq!(datalink::Setting::PRIORITY, priority::DEFAULT);
}

#[test]
fn values_become_enums_and_units_are_metadata() {
    use telemetry::values::RotorcraftStatusApMode;
    let status = telemetry::RotorcraftStatus {
        ap_mode: RotorcraftStatusApMode::Nav.raw(),
        ..Default::default()
    };
    assert_eq!(status.ap_mode_value(), Some(RotorcraftStatusApMode::Nav));
    assert_eq!(RotorcraftStatusApMode::Nav.label(), "NAV");
    assert_eq!(RotorcraftStatusApMode::try_from(200), Err(200));
    assert_eq!(RotorcraftStatusApMode::LABELS.len(), 20);

    let gps_int = telemetry::GpsInt::DESCRIPTOR;
    let lat = gps_int.field("lat").unwrap();
    assert_eq!(lat.unit, Some("1e7deg"));
    assert_eq!(lat.alt_unit, Some("deg"));
    assert_eq!(lat.alt_unit_coef, Some(1e-7));
    assert_eq!(gps_int.field("fix").unwrap().label(3), Some("3D"));
}

#[test]
fn descriptor_table_is_sorted_and_complete() {
    assert!(MESSAGES.is_sorted());
    assert_eq!(MESSAGES.len(), 27);
    let dl = MESSAGES.find(1, 31).unwrap();
    assert_eq!(
        (dl.name, dl.priority, dl.fields.len()),
        ("DL_VALUE", priority::HIGH, 2)
    );
    assert_eq!(MESSAGES.find_by_name("datalink", "SETTING").unwrap().id, 4);
    assert!(MESSAGES.find(1, 250).is_none());
}

#[test]
fn every_message_round_trips() {
    roundtrip::check_all(&MESSAGES, 256, &|class, id, payload, out| {
        let msg = AnyMessage::decode(class, id, payload)?;
        assert_eq!((msg.class_id(), msg.id()), (class, id));
        Ok(msg.encode(out).expect("a decoded message re-encodes"))
    });
}

/// The set's `decode` (its own reader per message) and the class's `decode` (which calls
/// the message's `Decode` impl) agree on every message, for payloads of every length up
/// to past the longest fixed message, well-formed or not: same message, or same error.
#[test]
fn set_decode_matches_class_decode() {
    let by_class = |class: u8, id: u8, payload: &'static [u8]| match class {
        1 => telemetry::AnyMessage::decode(id, payload).map(AnyMessage::Telemetry),
        2 => datalink::AnyMessage::decode(id, payload).map(AnyMessage::Datalink),
        _ => unreachable!("the default set has classes 1 and 2"),
    };
    static BYTES: [u8; 80] = {
        let mut b = [0u8; 80];
        let mut i = 0;
        while i < b.len() {
            // Small values at the start (vector lengths that fit), then varied bytes.
            b[i] = if i < 4 {
                i as u8
            } else {
                (i as u8).wrapping_mul(37) ^ 0x5A
            };
            i += 1;
        }
        b
    };
    for desc in MESSAGES.messages() {
        for start in 0..4 {
            for len in 0..=BYTES.len() - start {
                let payload = &BYTES[start..start + len];
                assert_eq!(
                    AnyMessage::decode(desc.class_id, desc.id, payload),
                    by_class(desc.class_id, desc.id, payload),
                    "{} from {len} bytes at {start}",
                    desc.name
                );
            }
        }
    }
}
