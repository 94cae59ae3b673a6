//! The project's default message set (the root `messages.xml`) against the PPRZLINK
//! reference: every message it shares with the reference is wire-identical (same class,
//! id, field order and types), the messages a flight stack needs to talk to Paparazzi
//! ground tools are there, and its generated `Set` fills every role of
//! `pprz_messages::roles`.

use std::path::{Path, PathBuf};

use pprz_codegen::{Generator, Protocol};
use pprz_test_support::reference;

fn default_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../messages.xml")
}

fn default_set() -> Protocol {
    Protocol::from_file(default_file()).expect("the default messages.xml is valid")
}

#[test]
fn generated_set_fills_every_role() {
    let code = Generator::new(default_file()).generate().unwrap();
    for role in ["ServiceSet", "LinkReportSet"] {
        assert!(
            code.contains(&format!("impl ::pprz_messages::roles::{role} for Set {{")),
            "{role}"
        );
    }
    assert!(!code.contains("- no `"), "a role is not filled");
}

#[test]
fn required_messages_are_present() {
    let p = default_set();
    for name in [
        "AUTOPILOT_VERSION",
        "ALIVE",
        "PONG",
        "ATTITUDE",
        "GPS",
        "DL_VALUE",
        "DATALINK_REPORT",
        "ENERGY",
    ] {
        assert!(p.message("telemetry", name).is_some(), "telemetry {name}");
    }
    for name in ["PING", "SETTING", "GET_SETTING", "BLOCK", "MOVE_WP"] {
        assert!(p.message("datalink", name).is_some(), "datalink {name}");
    }
    let class_ids: Vec<_> = p.classes.iter().map(|c| (c.name.as_str(), c.id)).collect();
    assert_eq!(class_ids, [("telemetry", 1), ("datalink", 2)]);
}

#[test]
fn wire_identical_to_the_reference() {
    let Some(dir) = reference::locate_for_test("wire_identical_to_the_reference") else {
        return;
    };
    let reference = Protocol::from_file(dir.join("messages.xml")).unwrap();
    assert_eq!(reference.message_count(), 367);
    let ours = default_set();
    let mut compared = 0;
    for class in &ours.classes {
        let ref_class = reference
            .class(&class.name)
            .unwrap_or_else(|| panic!("class {} is not in the reference", class.name));
        assert_eq!(class.id, ref_class.id, "class {} id", class.name);
        for m in &class.messages {
            let Some(r) = ref_class.messages.iter().find(|r| r.name == m.name) else {
                continue;
            };
            assert_eq!(m.id, r.id, "{}.{} id", class.name, m.name);
            let ours: Vec<_> = m.fields.iter().map(|f| (&f.name, f.ty)).collect();
            let theirs: Vec<_> = r.fields.iter().map(|f| (&f.name, f.ty)).collect();
            assert_eq!(ours, theirs, "{}.{} fields", class.name, m.name);
            // Display metadata the ground relies on must agree too.
            for (a, b) in m.fields.iter().zip(&r.fields) {
                assert_eq!(
                    (&a.unit, &a.alt_unit, a.alt_unit_coef, &a.values),
                    (&b.unit, &b.alt_unit, b.alt_unit_coef, &b.values),
                    "{}.{}.{} metadata",
                    class.name,
                    m.name,
                    a.name
                );
            }
            compared += 1;
        }
        // No id of ours may collide with a different reference message.
        for m in &class.messages {
            if let Some(r) = ref_class.messages.iter().find(|r| r.id == m.id) {
                assert_eq!(
                    r.name, m.name,
                    "{} id {} is {} in the reference",
                    class.name, m.id, r.name
                );
            }
        }
    }
    assert_eq!(
        compared,
        ours.message_count(),
        "every default message comes from the reference"
    );
}

/// `pprz-default` builds from the root files through links in its package: a link
/// replaced by a copy would make a second default set to edit.
#[test]
fn the_default_crate_reads_the_root_files() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for name in ["messages.xml", "telemetry.xml"] {
        let link = root.join("default").join(name);
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink(),
            "default/{name} is not a link"
        );
        assert_eq!(
            std::fs::canonicalize(&link).unwrap(),
            std::fs::canonicalize(root.join(name)).unwrap(),
            "default/{name} does not lead to the root {name}"
        );
    }
}
