//! Every validation error, triggered by a small bad XML file, with its message checked:
//! the file, line and column, the message and field, and what is wrong.

use std::path::Path;

use pprz_codegen::{ErrorKind, Generator};

fn errors(fixture: &str) -> (Vec<ErrorKind>, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(fixture);
    let err = Generator::new(&path)
        .generate()
        .expect_err("the fixture is invalid");
    let text = err
        .to_string()
        .replace(&path.display().to_string(), fixture);
    (
        err.diagnostics().iter().map(|d| d.kind.clone()).collect(),
        text,
    )
}

#[test]
fn duplicate_message_id() {
    let (kinds, text) = errors("duplicate_id.xml");
    assert!(matches!(
        kinds[..],
        [ErrorKind::Duplicate {
            what: "message id",
            ..
        }]
    ));
    assert_eq!(
        text,
        "error: duplicate_id.xml:4:5: message SECOND: duplicate message id `10` (first defined on line 3)"
    );
}

#[test]
fn duplicate_message_name() {
    let (_, text) = errors("duplicate_name.xml");
    assert_eq!(
        text,
        "error: duplicate_name.xml:4:5: message SAME: duplicate message name `SAME` (first defined on line 3)\n\
         error: duplicate_name.xml:4:5: message SAME: duplicate Rust type name of message `Same` (first defined on line 3)"
    );
}

#[test]
fn duplicate_field_name() {
    let (_, text) = errors("duplicate_field.xml");
    assert!(
        text.starts_with(
            "error: duplicate_field.xml:5:7: message TWICE, field x: duplicate field name `x` (first defined on line 4)"
        ),
        "{text}"
    );
}

#[test]
fn unknown_type() {
    let (kinds, text) = errors("unknown_type.xml");
    assert_eq!(kinds, [ErrorKind::UnknownType("uint24".into())]);
    assert!(
        text.starts_with(
            "error: unknown_type.xml:4:7: message ODD, field speed: unknown type `uint24`: expected one of int8 uint8"
        ),
        "{text}"
    );
}

#[test]
fn malformed_array() {
    let (_, text) = errors("malformed_array.xml");
    assert_eq!(
        text,
        "error: malformed_array.xml:4:7: message ARR, field samples: malformed array type `int16[4`: expected T[N] with N in 1..=255, or T[]"
    );
}

#[test]
fn payload_too_large_for_pprz_v2() {
    let (kinds, text) = errors("too_large.xml");
    assert_eq!(
        kinds,
        [ErrorKind::PayloadTooLarge {
            min_len: 249,
            max: 247
        }]
    );
    assert_eq!(
        text,
        "error: too_large.xml:3:5: message HUGE: payload of at least 249 bytes cannot fit a PPRZ v2 frame (247 bytes of fields at most)"
    );
}

#[test]
fn priority_out_of_range() {
    let (_, text) = errors("priority_out_of_range.xml");
    assert_eq!(
        text,
        "error: priority_out_of_range.xml:3:5: message LOUD: priority `300` is out of range: expected an integer 0..=255"
    );
}

#[test]
fn missing_attributes_are_all_reported() {
    let (_, text) = errors("missing_attribute.xml");
    assert_eq!(
        text,
        "error: missing_attribute.xml:3:5: message NOID: <message> is missing the required attribute `id`\n\
         error: missing_attribute.xml:7:7: message NOTYPE, field y: <field> is missing the required attribute `type`"
    );
}

#[test]
fn malformed_xml() {
    let (kinds, text) = errors("malformed_xml.xml");
    assert!(matches!(kinds[..], [ErrorKind::Xml(_)]));
    assert!(text.starts_with("error: malformed_xml.xml:4:"), "{text}");
}

#[test]
fn unknown_selection_and_missing_file() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/small.xml");
    let err = Generator::new(&path)
        .messages(["NOPE"])
        .classes(["ground"])
        .generate()
        .unwrap_err();
    let kinds: Vec<_> = err.diagnostics().iter().map(|d| d.kind.clone()).collect();
    assert_eq!(
        kinds,
        [
            ErrorKind::UnknownSelection("ground".into()),
            ErrorKind::UnknownSelection("NOPE".into())
        ]
    );
    let err = Generator::new("/nonexistent/messages.xml")
        .generate()
        .unwrap_err();
    assert!(
        err.to_string()
            .starts_with("error: /nonexistent/messages.xml: cannot read file:"),
        "{err}"
    );
}

#[test]
fn inline_errors_name_the_source() {
    let xml = r#"<protocol><msg_class name="telemetry" id="1">
<message name="9LIVES" id="300"><field name="bad name" type="float"/></message>
<bogus/></msg_class><msg_class name="telemetry" id="1"/></protocol>"#;
    let err = Generator::from_str("inline.xml", xml)
        .generate()
        .unwrap_err();
    let text = err.to_string();
    for expected in [
        "inline.xml:2:1: name `9LIVES` is not a valid identifier",
        "inline.xml:2:1: attribute `id` = `300` is not an integer in 0..=255",
        "inline.xml:2:33: name `bad name` is not a valid identifier",
        "inline.xml:3:1: unexpected element <bogus>, expected <message>",
        "duplicate class name `telemetry`",
        "duplicate class id `1`",
    ] {
        assert!(text.contains(expected), "missing `{expected}` in:\n{text}");
    }
}

#[test]
fn too_many_values_for_the_type() {
    let labels: Vec<String> = (0..129).map(|i| format!("L{i}")).collect();
    let xml = format!(
        r#"<protocol><msg_class name="telemetry" id="1"><message name="E" id="1">
<field name="v" type="int8" values="{}"/></message></msg_class></protocol>"#,
        labels.join("|")
    );
    let err = Generator::from_str("values.xml", &xml)
        .generate()
        .unwrap_err();
    assert_eq!(
        err.diagnostics()[0].kind,
        ErrorKind::TooManyValues {
            count: 129,
            ty: "int8".into()
        }
    );
}

#[test]
fn class_ids_above_15_are_refused() {
    let (kinds, text) = errors("class_id_out_of_range.xml");
    assert_eq!(kinds, [ErrorKind::ClassIdOutOfRange { id: 16, max: 15 }]);
    assert_eq!(
        text,
        "error: class_id_out_of_range.xml:7:3: class id 16 does not fit a PPRZ v2 frame: class ids are 4 bits (0..=15)"
    );
    let xml = r#"<protocol><msg_class name="a" id="0"/><msg_class name="b" id="15"/></protocol>"#;
    assert!(pprz_codegen::Protocol::parse("ids.xml", xml).is_ok());
    let xml = r#"<protocol><msg_class name="a" id="255"/></protocol>"#;
    let err = pprz_codegen::Protocol::parse("ids.xml", xml).unwrap_err();
    assert_eq!(
        err.diagnostics()[0].kind,
        ErrorKind::ClassIdOutOfRange { id: 255, max: 15 }
    );
}

#[test]
fn elements_inside_fields_and_second_descriptions_are_refused() {
    let (kinds, text) = errors("field_content.xml");
    assert_eq!(
        kinds,
        [
            ErrorKind::UnexpectedElement {
                found: "field".into(),
                expected: "only text inside <field>"
            },
            ErrorKind::UnexpectedElement {
                found: "unit".into(),
                expected: "only text inside <field>"
            },
            ErrorKind::DuplicateElement {
                element: "description",
                first_line: 7
            },
        ]
    );
    assert_eq!(
        text,
        "error: field_content.xml:9:9: message NESTED, field outer: unexpected element <field>, expected only text inside <field>\n\
         error: field_content.xml:11:38: message NESTED, field odd: unexpected element <unit>, expected only text inside <field>\n\
         error: field_content.xml:12:7: message NESTED: duplicate <description> (first defined on line 7): only one is allowed"
    );
}

#[test]
fn the_reference_messages_xml_passes() {
    let Some(dir) =
        pprz_test_support::reference::locate_for_test("the_reference_messages_xml_passes")
    else {
        return;
    };
    let p = pprz_codegen::Protocol::from_file(dir.join("messages.xml")).expect("valid");
    assert_eq!(p.message_count(), 367);
    // Text inside <field> is its description.
    let gps = p.message("telemetry", "GPS").unwrap();
    assert!(gps.fields.iter().any(|f| f.description.is_some()));
}

#[test]
fn write_errors_name_the_output_file() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/small.xml");
    let err = Generator::new(&path)
        .write_to("/nonexistent/dir/x.rs")
        .unwrap_err();
    assert!(matches!(err.diagnostics()[0].kind, ErrorKind::Write(_)));
    let text = err.to_string();
    assert!(
        text.starts_with("error: /nonexistent/dir/x.rs: cannot write output file: ")
            && text.contains("os error"),
        "{text}"
    );
}
