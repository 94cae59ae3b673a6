//! Escaping of everything the monitor prints that it did not write itself: text
//! fields sent by the aircraft, and names, units and labels read from `messages.xml`.
//!
//! A terminal interprets control characters (escape sequences clear the screen, set
//! the window title...), and a line break in a message would let an aircraft forge a
//! whole line of the `--lines` output. Every such character is written as a visible
//! escape instead (`\n`, `\x1b`, `\u{202e}`), and a backslash as `\\`, so the printed
//! text is unambiguous and contains no control character.
//!
//! Two forms:
//!
//! * [`quoted`]: free text (a `char[]` field) between double quotes; inside, `"` is
//!   written `\"`, so spaces and `=` cannot split the text into fake fields.
//! * [`token`]: a bare word (a name, a unit, a label) that must not contain the
//!   separators of a line either: white space, `=`, `,`, `"`, brackets and
//!   parentheses are escaped too.
//!
//! ```
//! use pprz_ground::escape;
//! assert_eq!(escape::quoted("ok\n7 x=1\x1b[2J"), r#""ok\n7 x=1\x1b[2J""#);
//! assert_eq!(escape::token("deg C"), r"deg\x20C");
//! assert!(!escape::quoted("\u{202e}\u{85}").chars().any(escape::is_unsafe));
//! ```

use std::fmt::Write as _;

/// Whether `c` must not reach a terminal or a log as is: control characters (C0, DEL,
/// C1) and the invisible formatting characters that reorder or hide text (the same set
/// as the code generator's diagnostics escape).
pub use pprz_codegen::escape::is_unsafe;

/// Whether `c` separates the parts of a `--lines` line or of a field
/// (`name=value [unit]`, arrays `1,2`, labels `3(ON)`, text `"..."`).
fn is_separator(c: char) -> bool {
    c.is_whitespace() || matches!(c, '=' | ',' | '"' | '[' | ']' | '(' | ')')
}

/// Appends the escape of `c`: `\n`, `\t`, `\r`, `\xHH` for other ASCII, `\u{H}` for
/// the rest.
fn push_escape(out: &mut String, c: char) {
    match c {
        '\n' => out.push_str("\\n"),
        '\t' => out.push_str("\\t"),
        '\r' => out.push_str("\\r"),
        '\\' => out.push_str("\\\\"),
        '"' => out.push_str("\\\""),
        c if c.is_ascii() => {
            let _ = write!(out, "\\x{:02x}", u32::from(c));
        }
        c => {
            let _ = write!(out, "\\u{{{:x}}}", u32::from(c));
        }
    }
}

/// Appends `text` to `out` with every unsafe character and backslash escaped, and
/// also the characters for which `extra` is true.
fn push_escaped(out: &mut String, text: &str, extra: impl Fn(char) -> bool) {
    for c in text.chars() {
        if is_unsafe(c) || c == '\\' || extra(c) {
            push_escape(out, c);
        } else {
            out.push(c);
        }
    }
}

/// Free text between double quotes, with unsafe characters, `\` and `"` escaped.
pub fn quoted(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    out.push('"');
    push_escaped(&mut out, text, |c| c == '"');
    out.push('"');
    out
}

/// A bare word: unsafe characters, `\` and the separators of a line escaped.
pub fn token(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    push_escaped(&mut out, text, is_separator);
    out
}

/// Text for a human, e.g. an error message quoting a file: unsafe characters and `\`
/// escaped, except the line breaks between its lines, which are kept.
pub fn lines(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.split('\n').enumerate() {
        if i > 0 {
            out.push('\n');
        }
        push_escaped(&mut out, line, |_| false);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forged_line_and_terminal_codes_are_escaped() {
        // An INFO_MSG text that would forge a line, clear the screen and set the window
        // title if printed raw.
        let hostile = "ok\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;pwned\x07";
        let q = quoted(hostile);
        assert_eq!(
            q,
            r#""ok\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;pwned\x07""#
        );
        assert!(!q.chars().any(is_unsafe));
        assert_eq!(q.lines().count(), 1);
    }

    #[test]
    fn quotes_backslashes_and_invisible_characters() {
        assert_eq!(quoted(r#"a"b\c"#), r#""a\"b\\c""#);
        assert_eq!(
            quoted("\u{85}\u{202e}x\u{feff}"),
            r#""\u{85}\u{202e}x\u{feff}""#
        );
        assert_eq!(quoted("\r\t\x7f"), r#""\r\t\x7f""#);
        assert_eq!(quoted("héllo wörld"), "\"héllo wörld\"");
    }

    #[test]
    fn tokens_have_no_separator() {
        assert_eq!(token("GPS"), "GPS");
        assert_eq!(token("m/s^2"), "m/s^2");
        assert_eq!(
            token("a b=c,d\"[e](f)"),
            r#"a\x20b\x3dc\x2cd\"\x5be\x5d\x28f\x29"#
        );
        assert_eq!(token("x\n7 y"), r"x\n7\x20y");
        for c in token("\u{a0}\u{2028} \t").chars() {
            assert!(!is_unsafe(c) && !c.is_whitespace(), "{c:?}");
        }
    }

    #[test]
    fn lines_keeps_line_breaks_only() {
        assert_eq!(lines("a\x1b[2J\nb\\"), "a\\x1b[2J\nb\\\\");
        assert!(!lines("x\ry\u{9b}").chars().any(is_unsafe));
    }
}
