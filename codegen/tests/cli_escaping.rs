//! `pprz-codegen` never prints a control character read from its inputs: the names,
//! types, values and entity names a hostile file quotes in its diagnostics, warnings
//! and listings are escaped (ESC as `\x1b`, U+009B, the one-byte CSI, as `\u{9b}`).

mod common;

use common::run;

use pprz_test_support::shown::assert_escaped;

type Temp = pprz_test_support::temp::TempFile;

#[test]
fn names_and_types_of_a_messages_xml_are_escaped() {
    let xml = Temp::new(
        "m\u{1b}[2J.xml",
        "<protocol><msg_class name=\"telemetry\" id=\"1\">\n\
         <message name=\"OK\u{9b}[2J\" id=\"1\"><field name=\"x\" type=\"uint9\u{9b}x\"/></message>\n\
         <message name=\"B\" id=\"2\"><field name=\"y\" type=\"uint8[\u{9b}]\"/></message>\n\
         <message name=\"C\" id=\"3\"><field name=\"z\" type=\"uint8\" unit=\"m\" alt_unit=\"k\u{9b}\"/></message>\n\
         </msg_class></protocol>\n",
    );
    let (ok, stdout, stderr) = run(&[xml.arg(), "--check"]);
    assert!(!ok && stdout.is_empty());
    assert_escaped(
        &stderr,
        &[
            "-m\\x1b[2J.xml:2:",
            "name `OK\\u{9b}[2J` is not a valid identifier",
            "unknown type `uint9\\u{9b}x`",
            "malformed array type `uint8[\\u{9b}]`",
        ],
    );
    assert_eq!(stderr.lines().count(), 3, "{stderr}");
}

#[test]
fn an_entity_name_is_escaped_before_the_xml_is_read() {
    // A raw ESC is not XML: only the limits check, which runs first, reads it.
    let xml = Temp::new(
        "entity.xml",
        "<!DOCTYPE protocol [<!ENTITY a\u{1b}[2J\u{9b} \"&b;\"><!ENTITY b \"x\">]>\n<protocol/>\n",
    );
    let (ok, _, stderr) = run(&[xml.arg(), "--check"]);
    assert!(!ok);
    assert_escaped(
        &stderr,
        &["entity `a\\x1b[2J\\u{9b}` refers to entity `b`: nested entities are refused"],
    );
}

#[test]
fn errors_warnings_and_listing_of_settings_are_escaped() {
    let bad = Temp::new(
        "bad_settings.xml",
        "<settings><dl_settings>\
         <dl_setting var=\"v\" min=\"0\u{9b}[2J\" max=\"1\"/>\
         </dl_settings></settings>\n",
    );
    let (ok, _, stderr) = run(&["--settings", bad.arg(), "--check"]);
    assert!(!ok);
    assert_escaped(
        &stderr,
        &["attribute `min` = `0\\u{9b}[2J` is not a finite number"],
    );
    let warned = Temp::new(
        "warned_settings.xml",
        "<settings><dl_settings>\
         <dl_setting var=\"v\u{9b}\" min=\"0\" max=\"1\" alt_unit=\"d\u{9b}\" type=\"flo\u{9b}t\" shortname=\"s\u{9b}\"/>\
         <dl_setting var=\"w\" min=\"0\" max=\"1\" unit=\"x\u{9b}\" alt_unit=\"d\u{9b}\"/>\
         </dl_settings></settings>\n",
    );
    for mode in ["--check", "--list"] {
        let (ok, stdout, stderr) = run(&["--settings", warned.arg(), mode]);
        assert!(ok, "{stderr}");
        assert_escaped(
            &stderr,
            &[
                "setting `v\\u{9b}`: alt_unit `d\\u{9b}` without alt_unit_coef nor unit",
                "type `flo\\u{9b}t` is not a setting type here",
                "no known conversion from `x\\u{9b}`",
            ],
        );
        assert_escaped(&stdout, &[]);
    }
    let (_, stdout, _) = run(&["--settings", warned.arg(), "--list"]);
    assert_escaped(&stdout, &["v\\u{9b}", "s\\u{9b}", "x\\u{9b} (d\\u{9b} x1)"]);
}
