//! The crate path options of `pprz-codegen` (`--runtime-crate`, `--telemetry-crate`,
//! `--embassy-sync-crate`), pasted into the generated code, must be Rust paths: other
//! values are refused with an error naming the option and the value, escaped.

mod common;

use common::run;

const SMALL: &str = "tests/fixtures/small.xml";
const THREE: &str = "tests/fixtures/settings/three.xml";

const REFUSED: [(&str, &str); 8] = [
    ("", "``"),
    ("a b", "`a b`"),
    ("a\nb", "`a\\nb`"),
    ("a::", "`a::`"),
    ("1x", "`1x`"),
    ("::", "`::`"),
    ("pprz_messages;\u{1b}[2J", "`pprz_messages;\\x1b[2J`"),
    ("a::fn", "`a::fn`"),
];

#[test]
fn runtime_crate_is_checked() {
    for ok in [
        "pprz_messages",
        "::my_crate::rt",
        "crate",
        "crate::rt",
        "super::m",
    ] {
        let (success, stdout, stderr) = run(&[SMALL, "--runtime-crate", ok]);
        assert!(success, "{ok}: {stderr}");
        assert!(
            stdout.contains(&format!("use {ok} as __rt;")),
            "{ok}: not in the code"
        );
    }
    for (bad, shown) in REFUSED {
        let (success, stdout, stderr) = run(&[SMALL, &format!("--runtime-crate={bad}")]);
        assert!(!success && stdout.is_empty(), "{bad:?}");
        assert!(
            stderr.starts_with(&format!(
                "error: --runtime-crate {shown} is not a Rust path: "
            )),
            "{bad:?}: {stderr}"
        );
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(
            !stderr.trim_end().chars().any(char::is_control),
            "{stderr:?}"
        );
    }
}

#[test]
fn settings_crate_paths_are_checked() {
    for option in [
        "--runtime-crate",
        "--telemetry-crate",
        "--embassy-sync-crate",
    ] {
        let (success, stdout, stderr) = run(&["--settings", THREE, option, "::my_crate::rt"]);
        assert!(success, "{option}: {stderr}");
        assert!(stdout.contains("::my_crate::rt::"), "{option}");
        for (bad, shown) in REFUSED {
            let (success, stdout, stderr) = run(&["--settings", THREE, &format!("{option}={bad}")]);
            assert!(!success && stdout.is_empty(), "{option} {bad:?}");
            assert!(
                stderr.starts_with(&format!("error: {option} {shown} is not a Rust path: ")),
                "{option} {bad:?}: {stderr}"
            );
            assert!(
                !stderr.trim_end().chars().any(char::is_control),
                "{stderr:?}"
            );
        }
    }
}
