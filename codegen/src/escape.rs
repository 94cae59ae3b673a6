//! Escaping of text read from the inputs (names, types, values, entity names, file
//! names) before it is shown to a person.
//!
//! A hostile `messages.xml` or `settings.xml` may put control characters in a name
//! or a type (an ESC starts a terminal escape sequence that clears the screen or sets
//! the window title; a line break would forge a `cargo:warning=` or `cargo:rustc-...`
//! line of a build script). The `Display` of every diagnostic ([`crate::Diagnostic`],
//! [`crate::ErrorKind`], [`crate::SettingProblem`], [`crate::Error`]) therefore writes
//! each such character as a visible escape: `\n`, `\t`, `\r`, `\x1b` for the other
//! ASCII ones, `\u{9b}` for the rest. Every printer of a diagnostic is safe without
//! escaping it again; [`text`] escapes other text the same way (the command line uses
//! it for what it lists).
//!
//! A backslash is kept as is (file names on Windows keep their look), so escaping twice
//! changes nothing.
//!
//! ```
//! use pprz_codegen::escape;
//! assert_eq!(escape::text("a\x1b[2J\nb\u{9b}"), r"a\x1b[2J\nb\u{9b}");
//! assert_eq!(escape::text(r"C:\messages.xml"), r"C:\messages.xml");
//! assert!(!escape::text("\u{202e}x\u{85}").chars().any(escape::is_unsafe));
//! ```

use std::fmt::{self, Write as _};

/// Whether `c` must not reach a terminal as is: control characters (C0, DEL, C1) and
/// the invisible formatting characters that reorder or hide text (bidirectional
/// overrides and isolates, zero-width characters, line and paragraph separators, the
/// byte order mark).
pub fn is_unsafe(c: char) -> bool {
    c.is_control()
        || matches!(
            c,
            '\u{200B}'..='\u{200F}'
                | '\u{2028}'..='\u{202E}'
                | '\u{2060}'..='\u{206F}'
                | '\u{FEFF}'
                | '\u{FFF9}'..='\u{FFFB}'
        )
}

/// `text` with every unsafe character (see [`is_unsafe`]) written as an escape.
pub fn text(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    // Writing to a `String` does not fail.
    let _ = Escaping(&mut out).write_str(text);
    out
}

/// A writer that passes text on to the inner writer with every unsafe character
/// escaped.
pub(crate) struct Escaping<W>(pub(crate) W);

impl<W: fmt::Write> fmt::Write for Escaping<W> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let mut safe_from = 0;
        for (at, c) in s.char_indices() {
            if !is_unsafe(c) {
                continue;
            }
            self.0.write_str(&s[safe_from..at])?;
            safe_from = at + c.len_utf8();
            match c {
                '\n' => self.0.write_str("\\n")?,
                '\t' => self.0.write_str("\\t")?,
                '\r' => self.0.write_str("\\r")?,
                c if c.is_ascii() => write!(self.0, "\\x{:02x}", u32::from(c))?,
                c => write!(self.0, "\\u{{{:x}}}", u32::from(c))?,
            }
        }
        self.0.write_str(&s[safe_from..])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_unsafe_character_is_escaped_and_the_rest_kept() {
        assert_eq!(
            text("ok\x1b]0;t\x07\r\t\0\x7f\u{85}\u{9b}\u{202e}\u{feff}é€"),
            r"ok\x1b]0;t\x07\r\t\x00\x7f\u{85}\u{9b}\u{202e}\u{feff}é€"
        );
        assert_eq!(text(r#"back\slash "q""#), r#"back\slash "q""#);
        for c in (0..=0x10FFFF).filter_map(char::from_u32) {
            let e = text(&c.to_string());
            assert!(!e.chars().any(is_unsafe), "{c:?}: {e:?}");
            assert_eq!(text(&e), e, "escaping twice changes nothing");
        }
    }
}
