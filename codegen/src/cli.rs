//! Command-line parsing for the project's tools (feature `cli`): clap, with its error
//! messages escaped.
//!
//! clap quotes the offending value in an error ("invalid value '…' for '--duration'"),
//! and an option's validator often repeats it. A value holding control characters (from
//! a script, a copied line, a file name) would reach the terminal as is: clap strips
//! 7-bit escape sequences only, and only when standard error is not a terminal. [`parse`]
//! writes the message with every unsafe character escaped as [`escape::text`] does; a
//! line break inside a quoted value is escaped too, so it cannot forge a line.
//!
//! ```
//! use clap::Parser;
//!
//! #[derive(Parser)]
//! struct Args {
//!     #[arg(long)]
//!     rate: u32,
//! }
//!
//! let e = Args::try_parse_from(["tool", "--rate", "7\r\u{9b}2J"]).err().unwrap();
//! let shown = pprz_codegen::cli::message(&e);
//! assert!(shown.contains(r"'7\r\u{9b}2J'"));
//! assert!(!shown.contains(['\r', '\u{9b}']));
//! ```

use std::io::Write as _;

use clap::Parser;
use clap::error::ContextValue;

use crate::escape;

/// The process's arguments parsed as `P`. Help and version are printed as clap prints
/// them (exit status 0); an error is printed escaped ([`message`]) to standard error and
/// the process exits with clap's status for it (2 for invalid options).
pub fn parse<P: Parser>() -> P {
    P::try_parse().unwrap_or_else(|e| exit(&e))
}

/// Prints `e` as [`parse`] does and exits.
pub fn exit(e: &clap::Error) -> ! {
    if !e.use_stderr() {
        // Help or version: the tool's own text, styled when the terminal takes it.
        e.exit();
    }
    let mut err = std::io::stderr().lock();
    // Nothing more can be reported if standard error itself fails.
    let _ = err.write_all(message(e).as_bytes());
    let _ = err.flush();
    std::process::exit(e.exit_code());
}

/// The text of `e` without styles: wherever it quotes a value given on the command line
/// (clap's own message, or a validator's repeating it), the value is escaped, line
/// breaks included; then the unsafe characters of every line are escaped.
pub fn message(e: &clap::Error) -> String {
    let mut given: Vec<&str> = e
        .context()
        .flat_map(|(_, value)| match value {
            ContextValue::String(s) => core::slice::from_ref(s),
            ContextValue::Strings(v) => v.as_slice(),
            _ => &[],
        })
        .map(String::as_str)
        .filter(|s| s.chars().any(escape::is_unsafe))
        .collect();
    // A value inside another is escaped as part of the longer one.
    given.sort_by_key(|s| core::cmp::Reverse(s.len()));
    let mut plain = e.render().to_string();
    for value in given {
        plain = plain.replace(value, &escape::text(value));
    }
    let mut out = String::with_capacity(plain.len());
    for line in plain.split_inclusive('\n') {
        let (text, end) = line
            .strip_suffix('\n')
            .map_or((line, ""), |text| (text, "\n"));
        out.push_str(&escape::text(text));
        out.push_str(end);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Parser)]
    #[command(name = "tool")]
    struct Args {
        #[arg(long)]
        rate: u32,
        #[arg(long)]
        name: Option<String>,
        #[arg(long, value_parser = seconds)]
        duration: Option<f64>,
    }

    /// A validator that repeats the value it refuses, as the tools' do.
    fn seconds(s: &str) -> Result<f64, String> {
        s.parse()
            .map_err(|_| format!("`{s}` is not a number of seconds"))
    }

    #[test]
    fn the_offending_value_is_escaped_and_the_lines_kept() {
        // An 8-bit CSI, a carriage return, a right-to-left override and a line break:
        // clap's plain rendering keeps them (it strips 7-bit escape sequences only), and
        // the line break forges a line.
        let hostile = "\u{9b}31m\r\u{202e}x\nerror: forged";
        for args in [
            vec!["tool", "--rate", hostile],
            vec!["tool", "--rate", "1", "--name"],
            vec!["tool", hostile],
            vec!["tool", "--rate", "1", "--duration", hostile],
        ] {
            let e = Args::try_parse_from(&args).unwrap_err();
            let raw = e.render().to_string();
            let shown = message(&e);
            assert!(shown.starts_with("error: "), "{shown:?}");
            assert!(shown.ends_with('\n'), "{shown:?}");
            assert!(
                !shown.chars().any(|c| c != '\n' && escape::is_unsafe(c)),
                "{shown:?}"
            );
            if args.contains(&hostile) {
                assert!(raw.contains('\u{9b}'), "clap echoes the value raw: {raw:?}");
                assert!(shown.contains(r"\u{9b}31m\r\u{202e}x\nerror: forged"));
                let forged = raw.matches("\nerror: forged").count();
                assert!(forged > 0, "{raw:?}");
                assert_eq!(
                    shown.lines().count(),
                    raw.lines().count() - forged,
                    "{shown:?}"
                );
            } else {
                assert_eq!(shown, raw, "nothing to escape");
            }
        }
    }

    #[test]
    fn help_and_version_are_not_errors() {
        let e = Args::try_parse_from(["tool", "--help"]).unwrap_err();
        assert!(!e.use_stderr());
        let e = Args::try_parse_from(["tool", "--rate", "x"]).unwrap_err();
        assert!(e.use_stderr());
        assert_eq!(e.exit_code(), 2);
    }
}
