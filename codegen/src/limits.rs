//! Limits on what the generator reads, so that a hostile or broken input is refused
//! quickly, with a typed error ([`crate::ErrorKind`]), instead of exhausting time or
//! memory.
//!
//! Every XML input (`messages.xml`, `units.xml`, `telemetry.xml`) is checked, in this
//! order, before it is parsed:
//!
//! 1. its size: at most [`MAX_INPUT_BYTES`] ([`ErrorKind::InputTooLarge`]; a file is
//!    refused from its size, before it is read);
//! 2. its entities: an internal document type definition may declare entities
//!    (`<!ENTITY name "value">`), but at most [`MAX_ENTITIES`] of them
//!    ([`ErrorKind::TooManyEntities`]), whose values do not refer to other entities
//!    ([`ErrorKind::NestedEntity`]: nesting is how a file of a few hundred bytes expands
//!    to gigabytes), referred to at most [`MAX_ENTITY_REFERENCES`] times in all
//!    ([`ErrorKind::TooManyEntityReferences`]), and expanding to at most
//!    [`MAX_ENTITY_EXPANSION`] bytes in all ([`ErrorKind::EntityExpansionTooLarge`]);
//!    character references (`&#38;`) and the predefined entities (`&amp;`, `&lt;`, ...)
//!    are not limited;
//! 3. while it is parsed, its number of XML nodes: at most [`MAX_NODES`]
//!    ([`ErrorKind::TooManyNodes`]).
//!
//! The entity check scans the text once and counts conservatively: a declaration or a
//! reference inside a comment or a CDATA section counts as well.
//!
//! ```
//! let xml = format!(
//!     "<!DOCTYPE protocol [<!ENTITY big \"{}\">]>\n<protocol>{}</protocol>",
//!     "x".repeat(100_000),
//!     "&big;".repeat(100)
//! );
//! let err = pprz_codegen::Protocol::parse("hostile.xml", &xml).unwrap_err();
//! assert_eq!(
//!     err.diagnostics()[0].kind,
//!     pprz_codegen::ErrorKind::EntityExpansionTooLarge {
//!         max: pprz_codegen::limits::MAX_ENTITY_EXPANSION
//!     }
//! );
//! ```

use std::collections::HashMap;

use crate::error::ErrorKind;

/// Largest input read, in bytes (64 MiB; the full PPRZLINK `messages.xml` is about
/// 200 kB).
pub const MAX_INPUT_BYTES: u64 = 64 * 1024 * 1024;

/// Largest number of XML nodes (elements, text runs, comments...) of a document. A
/// `messages.xml` has at most 16 classes of 256 messages of at most 247 fields, about
/// 2 million nodes with the text between them.
pub const MAX_NODES: u32 = 4_000_000;

/// Largest number of entity declarations.
pub const MAX_ENTITIES: usize = 256;

/// Largest number of references to declared entities.
pub const MAX_ENTITY_REFERENCES: usize = 100_000;

/// Largest total size of the values of the entities referred to, counted once per
/// reference, in bytes (1 MiB).
pub const MAX_ENTITY_EXPANSION: usize = 1024 * 1024;

/// Entities every XML parser knows, which are character references.
const PREDEFINED: [&str; 5] = ["amp", "lt", "gt", "apos", "quot"];

/// The entity references of `text`: byte offset of each `&` and the name up to `;`.
/// Character references (`&#...;`) and malformed references are skipped. Each byte is
/// looked at a bounded number of times (a name stops at the first byte that cannot be
/// in one), so this is linear in the length of `text`.
fn references(text: &str) -> impl Iterator<Item = (usize, &str)> {
    let bytes = text.as_bytes();
    bytes
        .iter()
        .enumerate()
        .filter(|&(_, &b)| b == b'&')
        .filter_map(move |(at, _)| {
            let start = at + 1;
            let len = bytes[start..]
                .iter()
                .position(|&b| {
                    b == b';'
                        || b == b'&'
                        || b == b'<'
                        || b == b'>'
                        || b == b'"'
                        || b == b'\''
                        || b.is_ascii_whitespace()
                })
                .unwrap_or(bytes.len() - start);
            let end = start + len;
            let name = text.get(start..end)?;
            (bytes.get(end) == Some(&b';') && !name.is_empty() && !name.starts_with('#'))
                .then_some((at, name))
        })
}

/// An entity declaration found at the start of `rest` (just after `<!ENTITY`): its
/// name and, for an internal entity, its value. Lenient on purpose: it accepts every
/// declaration the XML parser accepts, and more.
fn declaration(rest: &str) -> Option<(&str, Option<&str>)> {
    let rest = rest.trim_start();
    let rest = rest.strip_prefix('%').unwrap_or(rest).trim_start();
    let name_len = rest
        .find(|c: char| c.is_whitespace() || c == '"' || c == '\'' || c == '>')
        .unwrap_or(rest.len());
    let (name, rest) = rest.split_at(name_len);
    if name.is_empty() {
        return None;
    }
    let rest = rest.trim_start();
    let value = rest.chars().next().and_then(|quote| {
        if quote != '"' && quote != '\'' {
            return None; // external (`SYSTEM`, `PUBLIC`): not resolved by the parser
        }
        let body = &rest[1..];
        body.find(quote).map(|end| &body[..end])
    });
    Some((name, value))
}

/// Checks the entity declarations and references of `text` against the limits; on a
/// violation, the byte offset where it is and what it is.
pub(crate) fn check_entities(text: &str) -> Result<(), (usize, ErrorKind)> {
    const DECL: &str = "<!ENTITY";
    // Declared entities and the size of their value (the largest, if declared twice).
    let mut entities: HashMap<&str, usize> = HashMap::new();
    let mut from = 0;
    while let Some(found) = text[from..].find(DECL) {
        let at = from + found;
        from = at + DECL.len();
        let Some((name, value)) = declaration(&text[from..]) else {
            continue;
        };
        if entities.len() >= MAX_ENTITIES && !entities.contains_key(name) {
            return Err((at, ErrorKind::TooManyEntities { max: MAX_ENTITIES }));
        }
        let value = value.unwrap_or("");
        if let Some((_, referenced)) = references(value).find(|(_, r)| !PREDEFINED.contains(r)) {
            return Err((
                at,
                ErrorKind::NestedEntity {
                    name: name.to_owned(),
                    referenced: referenced.to_owned(),
                },
            ));
        }
        let size = entities.entry(name).or_default();
        *size = (*size).max(value.len());
    }
    if entities.is_empty() {
        return Ok(());
    }
    let (mut count, mut expanded) = (0usize, 0usize);
    for (at, name) in references(text) {
        if PREDEFINED.contains(&name) {
            continue;
        }
        let Some(&size) = entities.get(name) else {
            continue;
        };
        count += 1;
        if count > MAX_ENTITY_REFERENCES {
            return Err((
                at,
                ErrorKind::TooManyEntityReferences {
                    max: MAX_ENTITY_REFERENCES,
                },
            ));
        }
        expanded = expanded.saturating_add(size);
        if expanded > MAX_ENTITY_EXPANSION {
            return Err((
                at,
                ErrorKind::EntityExpansionTooLarge {
                    max: MAX_ENTITY_EXPANSION,
                },
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(dtd: &str, body: &str) -> String {
        format!(
            "<?xml version=\"1.0\"?>\n<!DOCTYPE protocol [\n{dtd}\n]>\n<protocol>{body}</protocol>"
        )
    }

    #[test]
    fn small_entities_pass() {
        let text = doc(
            "<!ENTITY a \"alpha &amp; &#38;\">\n<!-- c --><!ENTITY % p 'x'>\n<!ENTITY ext SYSTEM \"e.xml\">",
            "<x n=\"&a;\">&a;&a;&amp;&lt;&#x41;&unknown; & ;</x>",
        );
        assert_eq!(check_entities(&text), Ok(()));
        assert_eq!(check_entities("<protocol>&amp;&#1;</protocol>"), Ok(()));
    }

    #[test]
    fn nested_entities_are_refused() {
        let text = doc("<!ENTITY a \"lol\">\n<!ENTITY b \"&a;&a;\">", "&b;");
        let (at, kind) = check_entities(&text).unwrap_err();
        assert_eq!(
            kind,
            ErrorKind::NestedEntity {
                name: "b".into(),
                referenced: "a".into()
            }
        );
        assert!(text[at..].starts_with("<!ENTITY b"));
    }

    #[test]
    fn expansion_is_limited() {
        let big = "x".repeat(MAX_ENTITY_EXPANSION / 4 + 1);
        let text = doc(
            &format!("<!ENTITY big '{big}'>"),
            "&big;&big;&big;<y/>&big;",
        );
        let (at, kind) = check_entities(&text).unwrap_err();
        assert_eq!(
            kind,
            ErrorKind::EntityExpansionTooLarge {
                max: MAX_ENTITY_EXPANSION
            }
        );
        assert!(text[at..].starts_with("&big;</protocol>"));
        let text = doc("<!ENTITY e ''>", &"&e;".repeat(MAX_ENTITY_REFERENCES + 1));
        assert_eq!(
            check_entities(&text).unwrap_err().1,
            ErrorKind::TooManyEntityReferences {
                max: MAX_ENTITY_REFERENCES
            }
        );
        let decls: String = (0..=MAX_ENTITIES)
            .map(|i| format!("<!ENTITY e{i} 'v'>"))
            .collect();
        assert_eq!(
            check_entities(&doc(&decls, "")).unwrap_err().1,
            ErrorKind::TooManyEntities { max: MAX_ENTITIES }
        );
    }

    #[test]
    fn malformed_references_stay_linear() {
        // No `;` anywhere: each `&` looks at most up to the next one.
        let text = doc("<!ENTITY e 'v'>", &"&e".repeat(200_000));
        assert_eq!(check_entities(&text), Ok(()));
    }
}
