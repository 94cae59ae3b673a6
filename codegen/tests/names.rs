//! Names from `messages.xml` that Rust gives a meaning to: those the generator accepts
//! make code that compiles (checked by building it in a scratch crate), the others are
//! refused with their line.

mod scratch;

use std::path::{Path, PathBuf};

use pprz_codegen::{ErrorKind, Generator};
use scratch::ScratchCrate;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// Code at the place the generated file is included that shadows the standard names
/// the generated code uses: it must name them by their full path.
const SHADOWS: &str = "
#[allow(dead_code)]
type Result = ();
#[allow(dead_code)]
struct Option;
#[allow(dead_code)]
struct Some;
#[allow(dead_code)]
struct None;
#[allow(dead_code)]
struct Ok;
#[allow(dead_code)]
struct Err;
#[allow(dead_code)]
struct Default;
#[allow(dead_code)]
struct From;
#[allow(dead_code)]
struct TryFrom;
";

/// Uses of the generated items, so that they are type-checked as a user would use them.
const USES: &str = r#"
pub fn uses() {
    use ::pprz_messages::{Decode, Message};
    use generated::*;
    let m = crate_::Result { ok: 1, err: 2 };
    let mut buf = [0u8; 8];
    let n = m.encode(&mut buf).unwrap();
    assert_eq!(crate_::Result::decode(&buf[..n]), core::result::Result::Ok(m));
    let _: crate_::Some = crate_::Some;
    let _: crate_::None = crate_::None;
    let _ = crate_::Default::default();
    let t = crate_::Try { from: 0 };
    assert_eq!(t.from_value(), core::option::Option::Some(crate_::values::TryFrom::SelfValue));
    assert_eq!(crate_::values::TryFrom::try_from(9u8), core::result::Result::Ok(crate_::values::TryFrom::Result));
    let k = super_::Keywords::default();
    let _ = (k.self_, k.type_, k.match_, k.async_, k.crate_, k.super_, k.self_value(), k.type_value());
    let l = super_::Locals::default();
    let _ = (l._1st, l.core, l.u8, l.str, l.self_, l.rt, l.result, l.default, l.raw_value());
    let _ = (core_::A, std_::A, u8_::A, str_::A, type_::A, result::A, option::A, set::A);
    let _ = (any_message::A, pprz_messages::A, rt::A, usize_::A, async_::A, messages::A);
    let any = AnyMessage::decode(0, 1, &buf[..n]).unwrap();
    assert_eq!(any, AnyMessage::Crate(crate_::AnyMessage::Result(m)));
    let _ = AnyMessage::U8(u8_::AnyMessage::A(u8_::A));
    let _ = (MESSAGES.len(), Set);
}
"#;

#[test]
fn hostile_names_generate_code_that_compiles() {
    let code = Generator::new(fixture("hostile_names.xml"))
        .generate()
        .expect("the names are usable");
    for item in [
        "pub mod crate_ {",
        "pub mod core_ {",
        "pub mod u8_ {",
        "pub mod usize_ {",
        "pub mod type_ {",
        "pub mod pprz_messages {",
        "    pub struct Result {",
        "    pub struct Some;",
        "        pub type_: u8,",
    ] {
        assert!(code.contains(item), "missing `{item}`");
    }

    let lib = format!(
        "#![no_std]\n#![deny(warnings)]\n\n/// The generated code.\n#[allow(missing_docs)]\npub mod generated {{\n{SHADOWS}\ninclude!(\"generated.rs\");\n}}\n{USES}"
    );
    let result = ScratchCrate::new("hostile-names")
        .write("generated.rs", &code)
        .write("lib.rs", &lib)
        .check();
    if let Err(stderr) = result {
        panic!("the generated code does not compile:\n{stderr}");
    }
}

#[test]
fn unusable_names_are_refused_with_their_line() {
    let path = fixture("unusable_names.xml");
    let err = Generator::new(&path).generate().unwrap_err();
    let text = err
        .to_string()
        .replace(&path.display().to_string(), "unusable_names.xml");
    let expected = [
        "error: unusable_names.xml:6:5: message SELF: message name `SELF` cannot be used: its Rust name `Self` is a keyword",
        "error: unusable_names.xml:7:5: message _: message name `_` cannot be used: it has no letter or digit to make a Rust name from",
        "error: unusable_names.xml:8:5: message _1ST: message name `_1ST` cannot be used: its Rust name `1St` would start with a digit (the `_` before it is dropped)",
        "error: unusable_names.xml:9:5: message ANY_MESSAGE: message name `ANY_MESSAGE` cannot be used: its Rust type name `AnyMessage` is that of the enum of the messages of its class",
        "error: unusable_names.xml:11:7: message FIELDS, field _: field name `_` cannot be used: it has no letter or digit to make a Rust name from",
        "error: unusable_names.xml:12:7: message FIELDS, field __: field name `__` cannot be used: it has no letter or digit to make a Rust name from",
        "error: unusable_names.xml:14:7: message FIELDS, field fooBar: duplicate Rust name of field `foo_bar` (first defined on line 13)",
        "error: unusable_names.xml:17:5: message FOO__BAR: duplicate Rust type name of message `FooBar` (first defined on line 16)",
        "error: unusable_names.xml:18:5: message fooBar: duplicate Rust type name of message `FooBar` (first defined on line 16)",
        "error: unusable_names.xml:19:5: name `Ünïcode` is not a valid identifier (letters, digits and `_`, not starting with a digit)",
        "error: unusable_names.xml:20:5: name `r#type` is not a valid identifier (letters, digits and `_`, not starting with a digit)",
        "error: unusable_names.xml:22:3: class name `self` cannot be used: its Rust name `Self` is a keyword",
        "error: unusable_names.xml:23:3: class name `_` cannot be used: it has no letter or digit to make a Rust name from",
        "error: unusable_names.xml:25:3: duplicate module name of class `foo_bar` (first defined on line 24)",
        "error: unusable_names.xml:25:3: duplicate Rust variant name of class `FooBar` (first defined on line 24)",
        "error: unusable_names.xml:27:3: duplicate module name of class `u8_` (first defined on line 26)",
        "error: unusable_names.xml:27:3: duplicate Rust variant name of class `U8` (first defined on line 26)",
    ];
    let lines: Vec<&str> = text.lines().collect();
    for e in expected {
        assert!(lines.contains(&e), "missing `{e}` in:\n{text}");
    }
    assert_eq!(lines.len(), expected.len(), "{text}");
    assert!(err.diagnostics().iter().any(|d| matches!(
        &d.kind,
        ErrorKind::UnusableName { what: "message", name, .. } if name == "SELF"
    )));
}

#[test]
fn telemetry_process_names_are_escaped_or_refused() {
    let messages = r#"<protocol><msg_class name="telemetry" id="1"><message name="ALIVE" id="2"/></msg_class></protocol>"#;
    let telemetry = r#"<telemetry>
<process name="u32"><mode name="default"><message name="ALIVE" period="1"/></mode></process>
<process name="_"><mode name="default"/></process>
</telemetry>"#;
    let g = Generator::from_str("messages.xml", messages)
        .telemetry_from_str("telemetry.xml", telemetry);
    let err = g.generate_telemetry().unwrap_err();
    assert_eq!(
        err.to_string(),
        "error: telemetry.xml:3:1: process name `_` cannot be used: it has no letter or digit to make a Rust name from"
    );
    let telemetry = r#"<telemetry><process name="u32"><mode name="default">
<message name="ALIVE" period="1"/></mode></process></telemetry>"#;
    let code = Generator::from_str("messages.xml", messages)
        .telemetry_from_str("telemetry.xml", telemetry)
        .generate_telemetry()
        .unwrap()
        .code;
    // `pub const FREQUENCY_HZ: u32` next to it still names the primitive type.
    assert!(code.contains("pub mod u32_ {"), "{code}");
}
