//! The `pprz-codegen` command line.

mod common;

use common::run;

#[test]
fn lists_a_valid_file() {
    let (ok, stdout, _) = run(&["tests/fixtures/small.xml", "--list"]);
    assert!(ok);
    assert!(stdout.contains("telemetry    7  MIXED"), "{stdout}");
    assert!(stdout.ends_with("tests/fixtures/small.xml: 2 classes, 7 messages: ok\n"));
}

#[test]
fn generates_to_stdout_and_file() {
    let (ok, stdout, _) = run(&["tests/fixtures/small.xml", "--class", "datalink"]);
    assert!(ok);
    assert!(stdout.contains("pub struct Ping;"));
    let out = std::env::temp_dir().join(format!("pprz-codegen-cli-{}.rs", std::process::id()));
    let (ok, _, _) = run(&["tests/fixtures/small.xml", "-o", out.to_str().unwrap()]);
    assert!(ok);
    let written = std::fs::read_to_string(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    assert!(written.contains("pub struct Mixed<'a>"));
}

#[test]
fn reports_errors_and_fails() {
    let (ok, stdout, stderr) = run(&["tests/fixtures/unknown_type.xml", "--check"]);
    assert!(!ok);
    assert!(stdout.is_empty());
    assert!(
        stderr.starts_with(
            "error: tests/fixtures/unknown_type.xml:4:7: message ODD, field speed: unknown type `uint24`"
        ),
        "{stderr}"
    );
}

#[test]
fn check_fails_for_what_would_not_compile_or_send() {
    let (ok, stdout, stderr) = run(&["tests/fixtures/unusable_names.xml", "--check"]);
    assert!(!ok);
    assert!(stdout.is_empty());
    assert!(
        stderr.starts_with(
            "error: tests/fixtures/unusable_names.xml:6:5: message SELF: message name `SELF` cannot be used: its Rust name `Self` is a keyword\n"
        ),
        "{stderr}"
    );
    let (ok, _, stderr) = run(&["tests/fixtures/class_id_out_of_range.xml", "--check"]);
    assert!(!ok);
    assert!(
        stderr.starts_with("error: tests/fixtures/class_id_out_of_range.xml:7:3: class id 16"),
        "{stderr}"
    );
    let (ok, _, stderr) = run(&["tests/fixtures/field_content.xml", "--check"]);
    assert!(!ok);
    assert_eq!(stderr.lines().count(), 3, "{stderr}");
    // Names Rust gives a meaning to, but that the generator escapes, pass.
    let (ok, stdout, stderr) = run(&["tests/fixtures/hostile_names.xml", "--check"]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.ends_with("16 classes, 64 messages: ok\n"),
        "{stdout}"
    );
}

#[test]
fn an_unwritable_output_is_a_write_error() {
    let (ok, stdout, stderr) = run(&["tests/fixtures/small.xml", "-o", "/nonexistent/dir/x.rs"]);
    assert!(!ok);
    assert!(stdout.is_empty());
    assert!(
        stderr.starts_with("error: /nonexistent/dir/x.rs: cannot write output file: ")
            && stderr.contains("(os error 2)"),
        "{stderr}"
    );
}
