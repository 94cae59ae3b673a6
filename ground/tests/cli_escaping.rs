//! `pprz-gateway` and `pprz-monitor` never print a control character read from a
//! hostile `messages.xml` or `settings.xml` (names, types, values, entity names, file
//! names) or given on their command line: their diagnostics show it escaped, once (ESC
//! as `\x1b`, U+009B, the one-byte CSI, as `\u{9b}`).

mod common;

use std::process::{Command, Stdio};

use common::{MESSAGES, monitor, run};

type Temp = pprz_test_support::temp::TempFile;

/// A `messages.xml` named with an ESC, with a U+009B in a message name and in types.
fn hostile_messages() -> Temp {
    Temp::new(
        "m\u{1b}[2J.xml",
        "<protocol><msg_class name=\"telemetry\" id=\"1\">\n\
         <message name=\"OK\u{9b}[2J\" id=\"1\"><field name=\"x\" type=\"uint9\u{9b}x\"/></message>\n\
         <message name=\"B\" id=\"2\"><field name=\"y\" type=\"uint8[\u{9b}]\"/></message>\n\
         </msg_class></protocol>\n",
    )
}

/// What a hostile messages.xml makes the tools print.
const MESSAGES_SHOWN: [&str; 4] = [
    "-m\\x1b[2J.xml:2:",
    "name `OK\\u{9b}[2J` is not a valid identifier",
    "unknown type `uint9\\u{9b}x`",
    "malformed array type `uint8[\\u{9b}]`",
];

/// A `messages.xml` whose entity name has a raw ESC (only the limits check, before the
/// XML is read, sees it).
fn hostile_entity() -> Temp {
    Temp::new(
        "entity.xml",
        "<!DOCTYPE protocol [<!ENTITY a\u{1b}[2J\u{9b} \"&b;\"><!ENTITY b \"x\">]>\n<protocol/>\n",
    )
}

const ENTITY_SHOWN: &str = "entity `a\\x1b[2J\\u{9b}` refers to entity `b`";

/// A settings file with an error quoting a U+009B.
fn bad_settings() -> Temp {
    Temp::new(
        "bad_settings.xml",
        "<settings><dl_settings>\
         <dl_setting var=\"v\" min=\"0\u{9b}[2J\" max=\"1\"/>\
         </dl_settings></settings>\n",
    )
}

const BAD_SETTINGS_SHOWN: &str = "attribute `min` = `0\\u{9b}[2J` is not a finite number";

/// Checks `out` has no control character but its line breaks, quotes each of
/// `escaped`, and escapes nothing twice.
fn assert_escaped(out: &str, escaped: &[&str]) {
    pprz_test_support::shown::assert_escaped(out, escaped);
    assert!(!out.contains("\\\\"), "escaped twice: {out:?}");
}

/// `pprz-gateway` with `args`, reading an empty standard input: its exit code and
/// standard error.
fn gateway(args: &[&str]) -> (Option<i32>, String) {
    let (code, _, stderr) = run(Command::new(env!("CARGO_BIN_EXE_pprz-gateway"))
        .args(args)
        .arg("--stdin")
        .stdin(Stdio::null()));
    (code, stderr)
}

#[test]
fn gateway_escapes_what_the_files_quote() {
    let m = hostile_messages();
    let (code, stderr) = gateway(&["--messages", m.arg()]);
    assert_eq!(code, Some(2), "{stderr}");
    assert_escaped(&stderr, &MESSAGES_SHOWN);
    let e = hostile_entity();
    let (code, stderr) = gateway(&["--messages", e.arg()]);
    assert_eq!(code, Some(2), "{stderr}");
    assert_escaped(&stderr, &[ENTITY_SHOWN]);
    let s = bad_settings();
    let (code, stderr) = gateway(&["--messages", MESSAGES, "--settings", s.arg()]);
    assert_eq!(code, Some(2), "{stderr}");
    assert_escaped(&stderr, &["pprz-gateway: ", BAD_SETTINGS_SHOWN]);
    assert!(!stderr.contains("error: "), "one prefix per line: {stderr}");
}

#[test]
fn monitor_escapes_what_the_files_quote_once() {
    let m = hostile_messages();
    let (code, _, stderr) = run(monitor().args(["--messages", m.arg(), "--stdin"]));
    assert_eq!(code, Some(1), "{stderr}");
    assert_escaped(&stderr, &MESSAGES_SHOWN);
    assert!(stderr.starts_with("error: "), "{stderr}");
    let e = hostile_entity();
    let (code, _, stderr) = run(monitor().args(["--messages", e.arg(), "--stdin"]));
    assert_eq!(code, Some(1), "{stderr}");
    assert_escaped(&stderr, &[ENTITY_SHOWN]);
    let s = bad_settings();
    let (code, _, stderr) =
        run(monitor().args(["--messages", MESSAGES, "--settings", s.arg(), "--stdin"]));
    assert_eq!(code, Some(2), "{stderr}");
    assert_escaped(&stderr, &[BAD_SETTINGS_SHOWN]);
    // Warnings, with a run that reads the empty standard input.
    let warned = Temp::new(
        "warned_settings.xml",
        "<settings><dl_settings>\
         <dl_setting var=\"v\" min=\"0\" max=\"1\" alt_unit=\"d\u{9b}\" type=\"flo\u{9b}t\"/>\
         <dl_setting var=\"w\" min=\"0\" max=\"1\" unit=\"x\u{9b}\" alt_unit=\"d\u{9b}\"/>\
         </dl_settings></settings>\n",
    );
    let (code, _, stderr) = run(monitor().args([
        "--messages",
        MESSAGES,
        "--settings",
        warned.arg(),
        "--stdin",
        "--lines",
    ]));
    assert_eq!(code, Some(0), "{stderr}");
    assert_escaped(
        &stderr,
        &[
            "warning: ",
            "alt_unit `d\\u{9b}` without alt_unit_coef nor unit",
            "type `flo\\u{9b}t` is not a setting type here",
            "no known conversion from `x\\u{9b}`",
        ],
    );
}

/// An invalid command-line value: clap's message and the option's own validator both
/// quote it, escaped (a line break in it forges no line).
#[test]
fn invalid_values_on_the_command_line_are_shown_escaped() {
    let hostile = "1\u{9b}[2J\r\nerror: forged";
    let shown = "1\\u{9b}[2J\\r\\nerror: forged";
    for (tool, args) in [
        (monitor(), vec!["--duration", hostile]),
        (monitor(), vec!["--stdin", hostile]),
        (
            Command::new(env!("CARGO_BIN_EXE_pprz-gateway")),
            vec!["--dedup-window", hostile],
        ),
    ] {
        let mut tool = tool;
        let (code, _, stderr) = run(tool.args(&args).stdin(Stdio::null()));
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        assert_escaped(&stderr, &[shown]);
        assert!(stderr.starts_with("error: "), "{stderr}");
        assert_eq!(
            stderr.matches("error: ").count(),
            1 + stderr.matches(shown).count()
        );
        assert!(
            !stderr.lines().any(|l| l.starts_with("error: forged")),
            "{stderr}"
        );
    }
}

/// PPRZLOG time stamps wrap after 2^32 ticks of 100 µs; `--help` says so.
#[test]
fn monitor_help_tells_how_record_time_stamps_wrap() {
    let (code, stdout, _) = run(monitor().arg("--help"));
    assert_eq!(code, Some(0));
    let record = stdout
        .split("\n      --")
        .find(|o| o.starts_with("record "))
        .expect("--record is documented");
    let record = record.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        record.contains("Record every received frame to this PPRZLOG file")
            && record.contains("wrap to 0 every 429 497 s (about 5 days)")
            && record.contains("a replay unwraps them"),
        "{record}"
    );
}
