//! `pprz-codegen --settings FILE...`: generate, check, list; arguments that make no
//! sense with settings are refused.

mod common;

use common::run;

const THREE: &str = "tests/fixtures/settings/three.xml";
const EDGE: &str = "tests/fixtures/settings/edge.xml";

#[test]
fn generates_the_table_to_stdout_and_file() {
    let (ok, stdout, stderr) = run(&["--settings", THREE]);
    assert!(ok, "{stderr}");
    assert_eq!(
        stdout,
        std::fs::read_to_string("tests/snapshots/settings_three.rs").unwrap()
    );
    let out = std::env::temp_dir().join(format!("pprz-settings-cli-{}.rs", std::process::id()));
    let (ok, stdout, _) = run(&[
        "--settings",
        THREE,
        "--telemetry-crate",
        "crate::tm",
        "--embassy-sync-crate",
        "crate::sync",
        "--runtime-crate",
        "crate::rt",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok && stdout.is_empty());
    let written = std::fs::read_to_string(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    assert!(written.contains("crate::rt::settings::SettingDesc {"));
    assert!(written.contains("pub gain: crate::tm::settings::Binding<'a>,"));
    assert!(written.contains("M: crate::sync::blocking_mutex::raw::RawMutex"));
}

#[test]
fn checks_and_lists_every_setting() {
    let (ok, stdout, stderr) = run(&["--settings", THREE, EDGE, THREE, "--check"]);
    assert!(!ok);
    assert!(stdout.is_empty());
    assert!(
        stderr.starts_with(&format!(
            "error: {EDGE}:14:7: setting `Gain`: makes the Rust name `gain`, as `gain` does ({THREE}:6:7)"
        )),
        "{stderr}"
    );
    let (ok, stdout, stderr) = run(&["--settings", THREE, THREE, "--check"]);
    assert!(ok, "{stderr}");
    assert_eq!(
        stdout,
        "6 settings (3 variables, 4 persistent) from 2 files: ok\n"
    );
    assert!(stderr.is_empty());

    let (ok, stdout, stderr) = run(&["--settings", EDGE, "--list"]);
    assert!(ok, "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 1 + 7 + 1, "{stdout}");
    assert!(lines[0].starts_with("idx  group"), "{}", lines[0]);
    let words = |line: &str| {
        line.split_whitespace()
            .map(str::to_owned)
            .collect::<Vec<_>>()
    };
    assert_eq!(
        words(lines[1]),
        [
            "0",
            "Odd",
            "`names`",
            "type",
            "-",
            "[0,",
            "1]",
            "1",
            "float",
            "-",
            "no|\"yes\"",
            "-",
            "-"
        ]
    );
    // A control character in a name stays on its line, escaped.
    assert!(
        lines[2].contains("quote \" back\\slash \\nnewline"),
        "{}",
        lines[2]
    );
    assert!(lines[2].contains("[-3.1415927, 3.1415927]"), "{}", lines[2]);
    assert!(lines[2].contains("rad (deg x57.29578)"), "{}", lines[2]);
    assert!(
        lines[4].contains("[-2, 1]") && lines[4].contains("- (neg x-2)"),
        "{}",
        lines[4]
    );
    assert_eq!(words(lines[7])[..4], ["6", "-", "Gain", "-"]);
    assert!(lines[7].contains("[1e-6, 3.4e38]") && lines[7].ends_with("SetGain"));
    assert_eq!(
        lines[8],
        "7 settings (6 variables, 0 persistent) from 1 files: ok"
    );

    let (ok, stdout, _) = run(&["--settings", THREE, "--list"]);
    assert!(ok);
    let gain = stdout.lines().nth(1).unwrap();
    assert!(
        gain.contains("Gain") && gain.contains("persistent"),
        "{gain}"
    );
    let mode = stdout.lines().nth(3).unwrap();
    assert!(mode.contains("MANUAL|AUTO|HOME") && mode.ends_with("autopilot.SetMode"));
}

#[test]
fn warnings_go_to_stderr_and_pass() {
    let path = std::env::temp_dir().join(format!("pprz-settings-warn-{}.xml", std::process::id()));
    std::fs::write(
        &path,
        "<settings><dl_settings>\n<dl_setting var=\"a\"min=\"0\" max=\"1\" values=\"A|B|C\"/>\n</dl_settings></settings>\n",
    )
    .unwrap();
    let name = path.to_str().unwrap();
    let (ok, stdout, stderr) = run(&["--settings", name, "--check"]);
    let _ = std::fs::remove_file(&path);
    assert!(ok, "{stderr}");
    assert_eq!(
        stdout,
        "1 settings (1 variables, 0 persistent) from 1 files: ok\n"
    );
    assert_eq!(
        stderr,
        format!(
            "warning: {name}:2:20: no space before attribute `min`: accepted, as Paparazzi accepts it\n\
             warning: {name}:2:36: setting `a`: 3 `values` labels for 2 values (max - min + 1): the labels name min, min + 1, ... in order\n"
        )
    );
}

#[test]
fn nonsense_arguments_are_refused() {
    for (args, expected) in [
        (
            &["--settings"][..],
            "a value is required for '--settings <SETTINGS_XML>...'",
        ),
        (
            &["tests/fixtures/small.xml", "--settings", THREE],
            "the argument '[MESSAGES]' cannot be used with '--settings <SETTINGS_XML>...'",
        ),
        (
            &["--settings", THREE, "--class", "telemetry"],
            "cannot be used with '--class <CLASS>'",
        ),
        (
            &["--settings", THREE, "--telemetry", "telemetry.xml"],
            "cannot be used with '--telemetry <TELEMETRY_XML>'",
        ),
        (
            &["--settings", THREE, "--tick-frequency", "5"],
            "cannot be used with '--tick-frequency <TICK_FREQUENCY>'",
        ),
        (
            &["--settings", THREE, "--default-priority", "5"],
            "cannot be used with '--default-priority <DEFAULT_PRIORITY>'",
        ),
        (
            &["tests/fixtures/small.xml", "--telemetry-crate", "x"],
            "the argument '[MESSAGES]' cannot be used with '--telemetry-crate <TELEMETRY_CRATE>'",
        ),
        (
            &["--settings", THREE, "--check", "--list"],
            "the argument '--check' cannot be used with '--list'",
        ),
        (
            &[][..],
            "the following required arguments were not provided",
        ),
    ] {
        let (ok, stdout, stderr) = run(args);
        assert!(!ok, "{args:?}");
        assert!(stdout.is_empty(), "{args:?}");
        assert!(
            stderr.starts_with("error: ") && stderr.contains(expected),
            "{args:?}: {stderr}"
        );
    }
    let (ok, _, stderr) = run(&["--settings", "tests/fixtures/settings/absent.xml"]);
    assert!(!ok);
    assert!(
        stderr.starts_with("error: tests/fixtures/settings/absent.xml: cannot read file: "),
        "{stderr}"
    );
}
