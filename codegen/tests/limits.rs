//! Large and hostile inputs: a large valid file parses (in time linear in its size: the
//! per-element work is checked by `xml::tests::positions_take_linear_work`), and inputs
//! beyond the limits of `pprz_codegen::limits` are refused with a typed error, before
//! they are expanded or even read.

use pprz_codegen::limits::{
    MAX_ATTRIBUTES, MAX_ENTITIES, MAX_ENTITY_EXPANSION, MAX_ENTITY_REFERENCES, MAX_INPUT_BYTES,
};
use pprz_codegen::{ErrorKind, Generator, Protocol};

/// A valid `messages.xml` of 15 classes of 256 messages of `fields` fields, with a
/// description of `description` bytes per message.
fn large_protocol(fields: usize, description: usize) -> String {
    let types = [
        "uint8", "int16", "float", "int32", "uint16", "char[]", "int8[3]",
    ];
    let text = "d".repeat(description);
    let mut xml = String::from(
        "<?xml version=\"1.0\"?>\n<!DOCTYPE protocol SYSTEM \"messages.dtd\">\n<protocol>\n",
    );
    for c in 1..=15 {
        xml.push_str(&format!("  <msg_class name=\"class_{c}\" id=\"{c}\">\n"));
        for m in 0..=255 {
            xml.push_str(&format!(
                "    <message name=\"MSG_{c}_{m}\" id=\"{m}\" priority=\"{}\">\n      <description>{text}</description>\n",
                m % 200
            ));
            for f in 0..fields {
                xml.push_str(&format!(
                    "      <field name=\"field_{f}\" type=\"{}\" unit=\"m\" alt_unit=\"cm\">Field {f} of message {m}</field>\n",
                    types[f % types.len()]
                ));
            }
            xml.push_str("    </message>\n");
        }
        xml.push_str("  </msg_class>\n");
    }
    xml.push_str("</protocol>\n");
    xml
}

#[test]
fn a_10_mb_file_parses() {
    let xml = large_protocol(20, 600);
    assert!(xml.len() > 10_000_000, "{} bytes", xml.len());
    let p = Protocol::parse("large.xml", &xml).expect("valid");
    assert_eq!(p.message_count(), 15 * 256);
    let last = p.message("class_15", "MSG_15_255").unwrap();
    assert_eq!(last.fields.len(), 20);
    // Lines are right at the end of the file too.
    let line = xml[..xml.find("MSG_15_255").unwrap()].lines().count() as u32;
    assert_eq!(last.line, line);
}

/// The first diagnostic of parsing `xml`, as `kind` and text.
fn refused(xml: &str) -> (ErrorKind, String) {
    let err = Protocol::parse("hostile.xml", xml).expect_err("refused");
    (err.diagnostics()[0].kind.clone(), err.to_string())
}

fn with_entities(dtd: &str, body: &str) -> String {
    format!(
        "<?xml version=\"1.0\"?>\n<!DOCTYPE protocol [\n{dtd}\n]>\n<protocol>\n<msg_class name=\"telemetry\" id=\"1\">\n<message name=\"A\" id=\"1\"><description>{body}</description></message>\n</msg_class>\n</protocol>\n"
    )
}

#[test]
fn an_entity_referenced_many_times_is_refused() {
    // 100 kB referenced 10,000 times: 1 GB once expanded, from a 150 kB file.
    let xml = with_entities(
        &format!("<!ENTITY big \"{}\">", "x".repeat(100_000)),
        &"&big;".repeat(10_000),
    );
    let (kind, text) = refused(&xml);
    assert_eq!(
        kind,
        ErrorKind::EntityExpansionTooLarge {
            max: MAX_ENTITY_EXPANSION
        }
    );
    // At the 11th reference, on line 7 after `<message name="A" id="1"><description>`.
    assert_eq!(
        text,
        "error: hostile.xml:7:89: entity references expand to more than 1048576 bytes: refused"
    );
    let xml = with_entities("<!ENTITY e \"\">", &"&e;".repeat(MAX_ENTITY_REFERENCES + 1));
    assert_eq!(
        refused(&xml).0,
        ErrorKind::TooManyEntityReferences {
            max: MAX_ENTITY_REFERENCES
        }
    );
}

#[test]
fn nested_entities_are_refused() {
    // A billion laughs: 10 levels of 10 references each.
    let mut dtd = String::from("<!ENTITY l0 \"lol\">\n");
    for i in 1..10 {
        dtd.push_str(&format!(
            "<!ENTITY l{i} \"{}\">\n",
            format!("&l{};", i - 1).repeat(10)
        ));
    }
    let (kind, text) = refused(&with_entities(&dtd, "&l9;"));
    assert_eq!(
        kind,
        ErrorKind::NestedEntity {
            name: "l1".into(),
            referenced: "l0".into()
        }
    );
    assert_eq!(
        text,
        "error: hostile.xml:4:1: entity `l1` refers to entity `l0`: nested entities are refused"
    );
    // Recursive: refused the same way, before the parser could loop.
    let (kind, _) = refused(&with_entities("<!ENTITY a \"&a;\">", "&a;"));
    assert!(matches!(kind, ErrorKind::NestedEntity { .. }), "{kind:?}");
}

#[test]
fn many_entity_declarations_are_refused() {
    let dtd: String = (0..=MAX_ENTITIES)
        .map(|i| format!("<!ENTITY e{i} \"v\">\n"))
        .collect();
    let (kind, text) = refused(&with_entities(&dtd, ""));
    assert_eq!(kind, ErrorKind::TooManyEntities { max: MAX_ENTITIES });
    assert!(
        text.starts_with(&format!("error: hostile.xml:{}:1: ", MAX_ENTITIES + 3)),
        "{text}"
    );
}

#[test]
fn small_entities_are_expanded() {
    let xml = with_entities(
        "<!ENTITY ver \"version 2\">",
        "Protocol &ver; &amp; &#38; again &ver;",
    );
    let p = Protocol::parse("entities.xml", &xml).expect("valid");
    assert_eq!(
        p.message("telemetry", "A").unwrap().description.as_deref(),
        Some("Protocol version 2 & & again version 2")
    );
}

#[test]
fn inputs_beyond_the_size_limit_are_refused() {
    let max = usize::try_from(MAX_INPUT_BYTES).unwrap();
    let mut xml = String::with_capacity(max + 1);
    xml.push_str("<protocol>");
    xml.push_str(&" ".repeat(max - "<protocol></protocol>".len() + 1));
    xml.push_str("</protocol>");
    let (kind, _) = refused(&xml);
    assert_eq!(
        kind,
        ErrorKind::InputTooLarge {
            size: MAX_INPUT_BYTES + 1,
            max: MAX_INPUT_BYTES
        }
    );
    // A file is refused from its size, without being read (a sparse file: no disk use).
    let path = std::env::temp_dir().join(format!("pprz-codegen-huge-{}.xml", std::process::id()));
    let file = std::fs::File::create(&path).unwrap();
    file.set_len(4 * MAX_INPUT_BYTES).unwrap();
    drop(file);
    let err = Generator::new(&path).generate().unwrap_err();
    let _ = std::fs::remove_file(&path);
    assert_eq!(
        err.diagnostics()[0].kind,
        ErrorKind::InputTooLarge {
            size: 4 * MAX_INPUT_BYTES,
            max: MAX_INPUT_BYTES
        }
    );
    assert!(
        err.to_string().ends_with(&format!(
            ": input of {} bytes is too large: at most {MAX_INPUT_BYTES} bytes are read",
            4 * MAX_INPUT_BYTES
        )),
        "{err}"
    );
}

#[test]
fn an_element_with_many_attributes_is_refused() {
    // The XML parser compares each attribute of an element with the others: 100,000
    // attributes (1 MB) would take it seconds, growing with the square of their number.
    let attributes: String = (0..100_000).map(|i| format!(" a{i}=\"\"")).collect();
    let xml =
        format!("<?xml version=\"1.0\"?>\n<protocol>\n  <msg_class{attributes}/>\n</protocol>\n");
    let (kind, text) = refused(&xml);
    assert_eq!(
        kind,
        ErrorKind::TooManyAttributes {
            max: MAX_ATTRIBUTES
        }
    );
    assert_eq!(
        text,
        "error: hostile.xml:3:3: too many attributes: at most 64 per element are accepted"
    );
}

#[test]
fn a_document_of_too_many_nodes_is_refused() {
    // 4 million empty elements (16 MB): memory for the tree grows with the nodes.
    let mut xml = String::from("<protocol>");
    xml.push_str(&"<a/>".repeat(usize::try_from(pprz_codegen::limits::MAX_NODES).unwrap()));
    xml.push_str("</protocol>");
    let (kind, text) = refused(&xml);
    assert_eq!(
        kind,
        ErrorKind::TooManyNodes {
            max: pprz_codegen::limits::MAX_NODES
        }
    );
    assert_eq!(
        text,
        "error: hostile.xml: too many XML nodes: at most 4000000 elements, text runs and comments are read"
    );
}
