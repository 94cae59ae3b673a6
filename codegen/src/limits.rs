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
//! 3. its tags: at most [`MAX_ATTRIBUTES`] attributes per element, in the document and
//!    in entity values ([`ErrorKind::TooManyAttributes`]: the XML parser compares each
//!    attribute with the others of its element, which takes time growing with the
//!    square of their number);
//! 4. while it is parsed, its number of XML nodes: at most [`MAX_NODES`]
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

/// Largest number of attributes of one element (a `<field>` has 8 at most).
pub const MAX_ATTRIBUTES: usize = 64;

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
    // A name ends at the first character that cannot be in one, so that no scan runs
    // into the next declaration (each starts with `<`): the whole check stays linear.
    let name_len = rest
        .find(|c: char| c.is_whitespace() || "\"'<>&%;".contains(c))
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

/// The byte offset of the first `needle` in `bytes` from `from`, if any.
fn find(bytes: &[u8], from: usize, needle: &[u8]) -> Option<usize> {
    bytes
        .get(from..)?
        .windows(needle.len())
        .position(|w| w == needle)
        .map(|at| from + at)
}

/// The end of the markup starting at `bytes[from]`: the byte offset after the first
/// `stop` byte, skipping quoted strings if `quoted`, and the number of `=` outside them.
fn markup_end(bytes: &[u8], from: usize, stops: &[u8], quoted: bool) -> (usize, usize) {
    let (mut quote, mut equals) = (None, 0usize);
    for (j, &b) in bytes.iter().enumerate().skip(from) {
        match quote {
            Some(q) if b == q => quote = None,
            Some(_) => {}
            None if quoted && (b == b'"' || b == b'\'') => quote = Some(b),
            None if stops.contains(&b) => return (j + 1, equals),
            None if b == b'=' => equals += 1,
            None => {}
        }
    }
    (bytes.len(), equals)
}

/// Checks that no element of `text` has more than [`MAX_ATTRIBUTES`] attributes; on a
/// violation, the byte offset of the element.
///
/// Markup is skipped as the XML parser reads it: comments, CDATA sections, processing
/// instructions, the start of a document type definition (up to its `[`, whose
/// declarations are then read one by one), entity declarations (with their quoted
/// values), other declarations and end tags (up to the first `>`); in a start tag, the
/// `=` outside quoted values are counted. Each byte is looked at once or twice: linear.
fn check_attributes(text: &str) -> Result<(), (usize, ErrorKind)> {
    let bytes = text.as_bytes();
    let mut i = 0;
    while let Some(found) = bytes
        .get(i..)
        .and_then(|b| b.iter().position(|&b| b == b'<'))
    {
        let at = i + found;
        let rest = &bytes[at..];
        let skip_to =
            |end: &[u8], from: usize| find(bytes, from, end).map_or(bytes.len(), |e| e + end.len());
        i = if rest.starts_with(b"<!--") {
            skip_to(b"-->", at + 4)
        } else if rest.starts_with(b"<![CDATA[") {
            skip_to(b"]]>", at + 9)
        } else if rest.starts_with(b"<?") {
            skip_to(b"?>", at + 2)
        } else if rest.starts_with(b"<!DOCTYPE") {
            markup_end(bytes, at, b"[>", true).0
        } else if rest.starts_with(b"<!ENTITY") {
            markup_end(bytes, at, b">", true).0
        } else if rest.starts_with(b"<!") || rest.starts_with(b"</") {
            markup_end(bytes, at, b">", false).0
        } else {
            let (end, equals) = markup_end(bytes, at, b">", true);
            if equals > MAX_ATTRIBUTES {
                return Err((
                    at,
                    ErrorKind::TooManyAttributes {
                        max: MAX_ATTRIBUTES,
                    },
                ));
            }
            end
        };
    }
    Ok(())
}

/// Checks the tags of `text` (see [`check_attributes`]) and its entity declarations and
/// references against the limits; on a violation, the byte offset where it is and what
/// it is.
pub(crate) fn check(text: &str) -> Result<(), (usize, ErrorKind)> {
    check_attributes(text)?;
    check_entities(text)
}

/// Checks the entity declarations and references of `text` against the limits; on a
/// violation, the byte offset where it is and what it is.
fn check_entities(text: &str) -> Result<(), (usize, ErrorKind)> {
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
        // The value is parsed where it is referred to: its tags count as well.
        check_attributes(value).map_err(|(_, kind)| (at, kind))?;
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
    fn malformed_declarations_are_skipped() {
        let text = format!("<a>{}</a>", "<!ENTITY".repeat(100_000));
        assert_eq!(check_entities(&text), Ok(()));
        assert_eq!(declaration(" % p 'v'>"), Some(("p", Some("v"))));
        assert_eq!(declaration(" e SYSTEM \"f\">"), Some(("e", None)));
        assert_eq!(declaration("<!ENTITY"), None);
    }

    #[test]
    fn attributes_are_limited() {
        let attrs = |n: usize| (0..n).map(|i| format!(" a{i}='=>'")).collect::<String>();
        let ok = format!(
            "<?xml version=\"1.0\"?><!DOCTYPE a [<!-- it's --><!ATTLIST a b CDATA 'it>\n<!ENTITY e '>'>]>\
             <!-- <b {} --><a{}>x > y<![CDATA[<c {}]]></a>",
            attrs(100),
            attrs(MAX_ATTRIBUTES),
            attrs(100)
        );
        assert_eq!(check(&ok), Ok(()));
        let text = format!("<a><b/><c{}/></a>", attrs(MAX_ATTRIBUTES + 1));
        assert_eq!(
            check(&text),
            Err((
                7,
                ErrorKind::TooManyAttributes {
                    max: MAX_ATTRIBUTES
                }
            ))
        );
        let text = doc(
            &format!("<!ENTITY e \"<c{}/>\">", attrs(MAX_ATTRIBUTES + 1)),
            "&e;",
        );
        let (at, kind) = check(&text).unwrap_err();
        assert_eq!(
            kind,
            ErrorKind::TooManyAttributes {
                max: MAX_ATTRIBUTES
            }
        );
        assert!(text[at..].starts_with("<!ENTITY e"));
    }

    #[test]
    fn malformed_references_stay_linear() {
        // No `;` anywhere: each `&` looks at most up to the next one.
        let text = doc("<!ENTITY e 'v'>", &"&e".repeat(200_000));
        assert_eq!(check_entities(&text), Ok(()));
    }
}
