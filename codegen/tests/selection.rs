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
        [
            "telemetry.PONG",
            "telemetry.MIXED",
            "telemetry.DATALINK_REPORT",
            "telemetry.DL_VALUE",
            "datalink.SETTING",
            "datalink.PING",
            "datalink.GET_SETTING"
        ]
    );
}

#[test]
fn by_class_name_or_id_and_by_message() {
    let datalink = ["datalink.SETTING", "datalink.PING", "datalink.GET_SETTING"];
    assert_eq!(
        names(Generator::new(FIXTURE).classes(["datalink"])),
        datalink
    );
    assert_eq!(names(Generator::new(FIXTURE).classes(["2"])), datalink);
    assert_eq!(
        names(Generator::new(FIXTURE).messages(["MIXED", "datalink.PING"])),
        ["telemetry.MIXED", "datalink.PING"]
    );
    assert_eq!(
        names(
            Generator::new(FIXTURE)
                .classes(["datalink"])
                .messages(["telemetry.PONG"])
        ),
        [
            "telemetry.PONG",
            "datalink.SETTING",
            "datalink.PING",
            "datalink.GET_SETTING"
        ]
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
        .messages(["MIXED", "PONG"])
        .default_priority(7)
        .generate()
        .unwrap();
    assert!(
        code.contains("const PRIORITY: u8 = 7;"),
        "MIXED has no attribute"
    );
    assert!(
        code.contains("const PRIORITY: u8 = 192;"),
        "PONG keeps its own"
    );
}
