//! The code generated from the full PPRZLINK reference `messages.xml`: every message
//! compiles (the build proves it), round-trips, and rejects malformed payloads.

#[cfg(pprz_reference)]
#[path = "../../../telemetry/tests/common/roundtrip.rs"]
mod roundtrip;

#[cfg(not(pprz_reference))]
#[test]
fn reference_data_missing() {
    // The build script found no reference data (and was not told to require it): the
    // reference tests were not compiled. Skip them visibly, or fail when the data is
    // required or has appeared since the build.
    if let Some(dir) = pprz_test_support::reference::locate_for_test("pprz-reference-check tests") {
        panic!(
            "reference data found in {} but the crate was built without it: rebuild it (touch codegen/reference-check/build.rs)",
            dir.display()
        );
    }
}

#[cfg(pprz_reference)]
mod with_reference {
    use pprz_messages::{Decode, Message, VarArray};
    use pprz_reference_check::{AnyMessage, MESSAGES, telemetry};

    #[test]
    fn all_367_messages_in_5_classes() {
        assert_eq!(MESSAGES.len(), 367);
        assert!(MESSAGES.is_sorted());
        let per_class = |c: u8| {
            MESSAGES
                .messages()
                .iter()
                .filter(|m| m.class_id == c)
                .count()
        };
        assert_eq!(
            [
                per_class(1),
                per_class(2),
                per_class(3),
                per_class(4),
                per_class(5)
            ],
            [246, 60, 42, 2, 17]
        );
    }

    #[test]
    fn every_message_round_trips() {
        super::roundtrip::check_all(&MESSAGES, 48, &|class, id, payload, out| {
            let msg = AnyMessage::decode(class, id, payload)?;
            assert_eq!((msg.class_id(), msg.id()), (class, id));
            Ok(msg.encode(out).expect("a decoded message re-encodes"))
        });
    }

    #[test]
    fn fields_after_a_variable_array_decode_at_the_right_offset() {
        // Find a telemetry message with a fixed-size field after a variable array and
        // check that decoding lands every later field at a computed offset.
        let desc = MESSAGES
            .messages()
            .iter()
            .find(|m| {
                m.class_id == 1
                    && m.fields
                        .iter()
                        .position(|f| matches!(f.ty, pprz_messages::FieldType::Vector(_)))
                        .is_some_and(|i| i + 1 < m.fields.len())
            })
            .expect("the reference has such messages");
        let mut payload = [0u8; 512];
        let mut counter = 0u8;
        let n = pprz_messages::dynamic::synthesize(desc, &mut payload, 5, || {
            counter = counter.wrapping_add(1);
            counter
        })
        .unwrap();
        let generic: Vec<String> = pprz_messages::dynamic::fields(desc, &payload[..n])
            .map(|f| f.unwrap().1.to_string())
            .collect();
        let typed = AnyMessage::decode(desc.class_id, desc.id, &payload[..n]).unwrap();
        let mut out = [0u8; 512];
        assert_eq!(typed.encode(&mut out), Ok(n));
        assert_eq!(&out[..n], &payload[..n]);
        assert_eq!(generic.len(), desc.fields.len());
    }

    #[test]
    fn set_roles_name_the_reference_messages() {
        use pprz_messages::roles::{LinkReport, LinkReportSet, ServiceSet, SettingValue};
        use pprz_reference_check::Set;
        fn ids<M: Message>() -> (u8, u8, &'static str) {
            (M::CLASS_ID, M::ID, M::NAME)
        }
        assert_eq!(ids::<<Set as ServiceSet>::Ping>(), (2, 8, "PING"));
        assert_eq!(ids::<<Set as ServiceSet>::Pong>(), (1, 3, "PONG"));
        assert_eq!(ids::<<Set as ServiceSet>::Setting>(), (2, 4, "SETTING"));
        assert_eq!(
            ids::<<Set as ServiceSet>::GetSetting>(),
            (2, 16, "GET_SETTING")
        );
        assert_eq!(ids::<<Set as ServiceSet>::DlValue>(), (1, 31, "DL_VALUE"));
        assert_eq!(
            ids::<<Set as LinkReportSet>::DatalinkReport>(),
            (1, 30, "DATALINK_REPORT")
        );
        let value = <<Set as ServiceSet>::DlValue as SettingValue>::new(2, 0.5);
        assert_eq!((value.index, value.value), (2, 0.5));
        let report = <Set as LinkReportSet>::DatalinkReport::from(LinkReport {
            downlink_ovrn: 9,
            ..LinkReport::default()
        });
        assert_eq!(report.downlink_ovrn, 9);
    }

    #[test]
    fn typed_struct_with_units_from_units_xml() {
        // ATTITUDE has unit rad, alt_unit deg and no coefficient in messages.xml: the
        // default comes from units.xml.
        let phi = telemetry::Attitude::DESCRIPTOR.field("phi").unwrap();
        assert_eq!(phi.alt_unit_coef, Some(57.2957795131));
        let alive = telemetry::Alive {
            md5sum: VarArray::new(&[1; 16]),
        };
        let mut buf = [0u8; 17];
        assert_eq!(alive.encode(&mut buf), Ok(17));
        assert_eq!(telemetry::Alive::decode(&buf).unwrap(), alive);
    }
}
