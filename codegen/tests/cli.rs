//! The `pprz-codegen` command line.

use std::process::Command;

fn run(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_pprz-codegen"))
        .args(args)
        .output()
        .expect("the CLI runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

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
