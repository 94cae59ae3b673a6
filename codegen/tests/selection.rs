//! Selecting classes and messages, so a firmware compiles only what it uses.

use pprz_codegen::Generator;

const FIXTURE: &str = "tests/fixtures/small.xml";

fn names(g: Generator) -> Vec<String> {
    let p = g.protocol().unwrap();
    p.classes
        .iter()
        .flat_map(|c| {
            c.messages
                .iter()
                .map(move |m| format!("{}.{}", c.name, m.name))
        })
        .collect()
}

#[test]
fn everything_by_default() {
    assert_eq!(
        names(Generator::new(FIXTURE)),
        ["telemetry.EMPTY", "telemetry.MIXED", "datalink.PING"]
    );
}

#[test]
fn by_class_name_or_id_and_by_message() {
    assert_eq!(
        names(Generator::new(FIXTURE).classes(["datalink"])),
        ["datalink.PING"]
    );
    assert_eq!(
        names(Generator::new(FIXTURE).classes(["2"])),
        ["datalink.PING"]
    );
    assert_eq!(
        names(Generator::new(FIXTURE).messages(["MIXED", "datalink.PING"])),
        ["telemetry.MIXED", "datalink.PING"]
    );
    assert_eq!(
        names(
            Generator::new(FIXTURE)
                .classes(["datalink"])
                .messages(["telemetry.EMPTY"])
        ),
        ["telemetry.EMPTY", "datalink.PING"]
    );
}

#[test]
fn generated_code_holds_only_the_selection() {
    let code = Generator::new(FIXTURE)
        .messages(["PING"])
        .generate()
        .unwrap();
    assert!(code.contains("pub struct Ping;"));
    assert!(!code.contains("pub struct Mixed"));
    assert!(!code.contains("pub mod telemetry"));
    assert!(code.contains("Every message of this set (1 messages)"));
}

#[test]
fn default_priority_is_configurable() {
    let code = Generator::new(FIXTURE)
        .messages(["MIXED", "EMPTY"])
        .default_priority(7)
        .generate()
        .unwrap();
    assert!(
        code.contains("const PRIORITY: u8 = 7;"),
        "MIXED has no attribute"
    );
    assert!(
        code.contains("const PRIORITY: u8 = 192;"),
        "EMPTY keeps its own"
    );
}
