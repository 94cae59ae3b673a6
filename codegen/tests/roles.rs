//! The generated `Set` and the traits of `pprz_messages::roles`: implemented exactly when
//! the set has the role's messages in the right class with the right fields, and the
//! documentation of `Set` says why a role is not filled. (The snapshot test compiles and
//! uses the impls of a full set.)

use pprz_codegen::Generator;

const FIXTURE: &str = "tests/fixtures/small.xml";

fn fixture() -> String {
    std::fs::read_to_string(FIXTURE).unwrap()
}

fn generate(g: Generator) -> String {
    g.generate().unwrap()
}

/// The documentation of `Set`, as text.
fn set_doc(code: &str) -> String {
    let end = code
        .find("pub struct Set;")
        .expect("`Set` is always generated");
    let start = code[..end].rfind("\n\n").map_or(0, |i| i + 2);
    code[start..end]
        .lines()
        .filter_map(|l| l.strip_prefix("#[doc = \" ")?.strip_suffix("\"]"))
        .collect::<Vec<_>>()
        .join("\n")
}

const SERVICE_SET: &str = "impl ::pprz_messages::roles::ServiceSet for Set {";
const LINK_REPORT_SET: &str = "impl ::pprz_messages::roles::LinkReportSet for Set {";

#[test]
fn full_set_has_every_impl() {
    let code = generate(Generator::new(FIXTURE));
    for expected in [
        "impl ::pprz_messages::roles::Ping for datalink::Ping {}",
        "impl ::pprz_messages::roles::Pong for telemetry::Pong {",
        "impl ::pprz_messages::roles::SettingRequest for datalink::Setting {",
        "impl ::pprz_messages::roles::GetSettingRequest for datalink::GetSetting {",
        "impl ::pprz_messages::roles::SettingValue for telemetry::DlValue {",
        "impl ::core::convert::From<::pprz_messages::roles::LinkReport> for telemetry::DatalinkReport {",
        "impl ::pprz_messages::roles::DatalinkReport for telemetry::DatalinkReport {}",
        SERVICE_SET,
        "    type GetSetting = datalink::GetSetting;",
        LINK_REPORT_SET,
    ] {
        assert!(code.contains(expected), "missing `{expected}`");
    }
    assert_eq!(
        set_doc(&code),
        "The message set of this file, for the runtime's set-generic code: the roles of\n\
         `::pprz_messages::roles` the set fills are implemented on this type.\n\
         \n\
         - `ServiceSet`: `PING`, `PONG`, `SETTING`, `GET_SETTING` and `DL_VALUE`.\n\
         - `LinkReportSet`: `DATALINK_REPORT`."
    );
}

#[test]
fn a_missing_message_drops_the_set_role_only() {
    let code = generate(Generator::new(FIXTURE).messages([
        "PING",
        "PONG",
        "SETTING",
        "GET_SETTING",
        "DATALINK_REPORT",
    ]));
    assert!(!code.contains(SERVICE_SET));
    assert!(code.contains(LINK_REPORT_SET));
    // The messages that fit keep their own role.
    assert!(code.contains("impl ::pprz_messages::roles::Ping for datalink::Ping {}"));
    assert!(!code.contains("roles::SettingValue"));
    let doc = set_doc(&code);
    assert!(
        doc.contains(
            "\n- no `ServiceSet`: `DL_VALUE` missing.\n- `LinkReportSet`: `DATALINK_REPORT`."
        ),
        "{doc}"
    );
    assert!(
        doc.ends_with(
            "Messages that fit their role implement it without the set role: `Ping` \
             (`datalink::Ping`), `Pong` (`telemetry::Pong`), `SettingRequest` \
             (`datalink::Setting`) and `GetSettingRequest` (`datalink::GetSetting`)."
        ),
        "{doc}"
    );
}

#[test]
fn a_wrong_field_type_drops_the_impl_and_says_why() {
    let xml = fixture().replace(
        r#"<field name="ac_id" type="uint8"/>
      <field name="value" type="float"/>"#,
        r#"<field name="ac_id" type="uint8"/>
      <field name="value" type="double"/>"#,
    );
    assert!(
        xml.contains("double"),
        "the fixture changed: update this test"
    );
    let code = generate(Generator::from_str("double.xml", &xml));
    assert!(!code.contains("roles::SettingRequest"));
    assert!(!code.contains(SERVICE_SET));
    assert!(code.contains(LINK_REPORT_SET));
    let doc = set_doc(&code);
    assert!(
        doc.contains(
            "- no `ServiceSet`: `SETTING` field 3 (`value`) is `double`, the role needs `float`."
        ),
        "{doc}"
    );
}

#[test]
fn extra_fields_wrong_names_and_classes_are_explained() {
    let xml = fixture()
        .replace(
            r#"<field name="value" type="float"/>
    </message>
  </msg_class>"#,
            r#"<field name="value" type="float"/>
      <field name="extra" type="uint8"/>
    </message>
  </msg_class>"#,
        )
        .replace(
            r#"name="ac_id" type="uint8"/>
    </message>"#,
            r#"name="aircraft" type="uint8"/>
    </message>"#,
        )
        .replace(
            r#"<message name="PONG" id="3" priority="192">"#,
            r#"<message name="PONG_" id="3" priority="192">"#,
        )
        .replace(
            r#"<message name="PING" id="8" priority="10"/>"#,
            r#"<message name="PING" id="8" priority="10"/><message name="PONG" id="9"/>"#,
        );
    let code = generate(Generator::from_str("odd.xml", &xml));
    let doc = set_doc(&code);
    assert!(
        doc.contains(
            "- no `ServiceSet`: `PONG` is in class `datalink`, the role needs class `telemetry`; \
             `GET_SETTING` field 2 is `aircraft`, the role needs `ac_id`; \
             `DL_VALUE` has 3 fields, the role needs 2 (`index: uint8, value: float`).\n"
        ),
        "{doc}"
    );
    assert!(!code.contains("roles::Pong for"));
    assert!(!code.contains("roles::GetSettingRequest for"));
    assert!(!code.contains("roles::SettingValue for"));
}

#[test]
fn selecting_telemetry_only_drops_the_services() {
    let code = generate(Generator::new(FIXTURE).classes(["telemetry"]));
    assert!(!code.contains(SERVICE_SET));
    assert!(!code.contains("for datalink::"));
    assert!(code.contains(LINK_REPORT_SET));
    let doc = set_doc(&code);
    assert!(
        doc.contains("- no `ServiceSet`: `PING`, `SETTING` and `GET_SETTING` missing."),
        "{doc}"
    );
}

#[test]
fn a_set_without_role_messages_fills_nothing() {
    let code = generate(Generator::new(FIXTURE).messages(["MIXED"]));
    assert!(code.contains("pub struct Set;"));
    assert!(!code.contains(" for Set"));
    assert!(!code.contains("roles::"), "no role trait for MIXED");
    let doc = set_doc(&code);
    assert!(
        doc.contains("- no `LinkReportSet`: `DATALINK_REPORT` missing."),
        "{doc}"
    );
    assert!(!doc.contains("without the set role"), "{doc}");
}

#[test]
fn the_runtime_path_is_used_everywhere() {
    let code = generate(Generator::new(FIXTURE).runtime_crate("crate::rt"));
    assert!(!code.contains("pprz_messages"), "{code}");
    assert!(code.contains("impl crate::rt::roles::ServiceSet for Set {"));
    assert!(code.contains(
        "impl ::core::convert::From<crate::rt::roles::LinkReport> for telemetry::DatalinkReport {"
    ));
    assert!(code.contains("`crate::rt::roles` the set fills"));
}
