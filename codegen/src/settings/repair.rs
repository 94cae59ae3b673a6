//! The missing space between two attributes (`handler="SetKiPhi"param="..."`), which
//! Paparazzi's XML reader accepts and XML does not: found in start tags, where a space
//! is inserted before parsing.
//!
//! The scan reads markup as the XML parser does (comments, CDATA sections, processing
//! instructions, declarations and end tags are skipped; quoted values are skipped whole),
//! and looks at each byte a bounded number of times: linear in the size of the text.

use crate::xml::Repaired;

/// `text` with a space inserted wherever, in a start tag, the closing quote of an
/// attribute's value is directly followed by the name of the next attribute; `None`
/// when there is no such place.
pub(crate) fn missing_spaces(text: &str) -> Option<Repaired> {
    let at = find(text.as_bytes());
    if at.is_empty() {
        return None;
    }
    let mut repaired = String::with_capacity(text.len() + at.len());
    let mut from = 0;
    for &offset in &at {
        // `offset` is at an ASCII byte (an attribute name's first): a char boundary.
        repaired.push_str(&text[from..offset]);
        repaired.push(' ');
        from = offset;
    }
    repaired.push_str(&text[from..]);
    Some(Repaired { text: repaired, at })
}

/// Offsets of the attribute names that directly follow a closing quote in a start tag.
fn find(bytes: &[u8]) -> Vec<usize> {
    let mut at = Vec::new();
    let mut i = 0;
    while let Some(found) = bytes
        .get(i..)
        .and_then(|b| b.iter().position(|&b| b == b'<'))
    {
        let start = i + found;
        let rest = &bytes[start..];
        i = if rest.starts_with(b"<!--") {
            past(bytes, start + 4, b"-->")
        } else if rest.starts_with(b"<![CDATA[") {
            past(bytes, start + 9, b"]]>")
        } else if rest.starts_with(b"<?") {
            past(bytes, start + 2, b"?>")
        } else if rest.starts_with(b"<!") || rest.starts_with(b"</") {
            // A declaration (up to the `[` of an internal subset) or an end tag.
            markup_end(bytes, start + 1, b"[>")
        } else if rest.get(1).is_some_and(|&b| name_start(b)) {
            start_tag(bytes, start + 1, &mut at)
        } else {
            start + 1
        };
    }
    at
}

/// Whether an attribute (or element) name may start with `b` (ASCII only: a missing
/// space is repaired only before such a name).
fn name_start(b: u8) -> bool {
    b.is_ascii_alphabetic() || b == b'_' || b == b':'
}

/// The offset after the first `needle` from `from`, or the end of `bytes`.
fn past(bytes: &[u8], from: usize, needle: &[u8]) -> usize {
    bytes
        .get(from..)
        .and_then(|b| b.windows(needle.len()).position(|w| w == needle))
        .map_or(bytes.len(), |p| from + p + needle.len())
}

/// The offset after the first of `stops` from `from`, outside quoted strings.
fn markup_end(bytes: &[u8], from: usize, stops: &[u8]) -> usize {
    let mut quote = None;
    for (j, &b) in bytes.iter().enumerate().skip(from) {
        match quote {
            Some(q) if b == q => quote = None,
            Some(_) => {}
            None if b == b'"' || b == b'\'' => quote = Some(b),
            None if stops.contains(&b) => return j + 1,
            None => {}
        }
    }
    bytes.len()
}

/// Reads the start tag whose name starts at `i`, recording in `at` where an attribute
/// name follows a closing quote; the offset after the tag. Anything that is not
/// `name = "value"` ends the reading: the rest of the tag is skipped (the XML parser
/// reports it).
fn start_tag(bytes: &[u8], mut i: usize, at: &mut Vec<usize>) -> usize {
    let stop = |b: u8| b.is_ascii_whitespace() || b == b'/' || b == b'>' || b == b'=';
    let skip_while = |mut i: usize, f: &dyn Fn(u8) -> bool| {
        while bytes.get(i).is_some_and(|&b| f(b)) {
            i += 1;
        }
        i
    };
    i = skip_while(i, &|b| !stop(b) && b != b'"' && b != b'\'');
    loop {
        i = skip_while(i, &|b| b.is_ascii_whitespace() || b == b'/');
        match bytes.get(i) {
            None => return bytes.len(),
            Some(b'>') => return i + 1,
            Some(&b) if !name_start(b) => return markup_end(bytes, i, b">"),
            Some(_) => {}
        }
        i = skip_while(i, &|b| !stop(b) && b != b'"' && b != b'\'');
        i = skip_while(i, &|b| b.is_ascii_whitespace());
        if bytes.get(i) != Some(&b'=') {
            return markup_end(bytes, i, b">");
        }
        i = skip_while(i + 1, &|b| b.is_ascii_whitespace());
        let Some(&quote) = bytes.get(i).filter(|&&b| b == b'"' || b == b'\'') else {
            return markup_end(bytes, i, b">");
        };
        let Some(close) = bytes[i + 1..].iter().position(|&b| b == quote) else {
            return bytes.len();
        };
        i += close + 2;
        if bytes.get(i).is_some_and(|&b| name_start(b)) {
            at.push(i);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repaired(text: &str) -> Option<(String, Vec<usize>)> {
        missing_spaces(text).map(|r| (r.text, r.at))
    }

    #[test]
    fn inserts_a_space_between_attributes() {
        let text = r#"<a x="1"y='2'  z="3"w="4"/>"#;
        let (fixed, at) = repaired(text).unwrap();
        assert_eq!(fixed, r#"<a x="1" y='2'  z="3" w="4"/>"#);
        assert_eq!(at, [8, 20]);
        assert_eq!(&text[8..9], "y");
    }

    #[test]
    fn leaves_everything_else_alone() {
        for text in [
            r#"<a x="1" y="2"/>"#,
            r#"<!-- <a x="1"y="2"/> --><b/>"#,
            r#"<![CDATA[<a x="1"y="2"/>]]>"#,
            r#"<?pi x="1"y="2"?>"#,
            r#"<!DOCTYPE a SYSTEM "a.dtd"><a/>"#,
            r#"<!DOCTYPE a [<!ENTITY e "<b x='1'y='2'/>">]><a/>"#,
            r#"<a x="1">text "q"y</a>"#,
            r#"<a x="1"/>"#,
            r#"<a x="1">"#,
            r#"<a x="1"9="2"/>"#,
            r#"<a x="a>b"/>"#,
            r#"<a x="1"#,
            "<",
            "<a",
            "<a x",
            "<a x=",
            "< a",
        ] {
            assert_eq!(repaired(text), None, "{text}");
        }
        // A value holding `>` does not end the tag.
        let (fixed, _) = repaired(r#"<a x="a>b"y="2"/>"#).unwrap();
        assert_eq!(fixed, r#"<a x="a>b" y="2"/>"#);
    }

    #[test]
    fn stays_linear() {
        let text = format!("<a{}/>", r#" x="1"y="2""#.repeat(200_000));
        let (_, at) = repaired(&text).unwrap();
        assert_eq!(at.len(), 200_000);
        let text = "<a x=\"".repeat(100_000);
        assert_eq!(repaired(&text), None);
    }
}
