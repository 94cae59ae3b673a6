//! Periodic telemetry configurations (`telemetry.xml`): every validation error triggered
//! by a small bad file with its message checked, resolution against a message set
//! (unknown messages, skipping them), tick rounding and phase staggering, the emitted
//! tables (snapshot), the CLI, and the reference `default_rotorcraft.xml` against the
//! reference `messages.xml`.

use std::collections::HashMap;
use std::process::Command;

use pprz_codegen::telemetry::{Schedule, ScheduledMode};
use pprz_codegen::{ErrorKind, Generator};
use pprz_test_support::reference;
use proptest::prelude::*;

// Cargo runs integration tests from the package root: relative paths are stable.
const MESSAGES: &str = "tests/fixtures/telemetry/messages.xml";
const OK: &str = "tests/fixtures/telemetry/ok.xml";
const SNAPSHOT: &str = "tests/snapshots/periodic.rs";

fn fixture(name: &str) -> String {
    format!("tests/fixtures/telemetry/{name}")
}

fn generator(telemetry: &str) -> Generator {
    Generator::new(MESSAGES).telemetry(fixture(telemetry))
}

/// The errors of a bad fixture, as kinds and as the printed text.
fn errors(telemetry: &str) -> (Vec<ErrorKind>, String) {
    let err = generator(telemetry)
        .schedule()
        .expect_err("the fixture is invalid");
    (
        err.diagnostics().iter().map(|d| d.kind.clone()).collect(),
        err.to_string(),
    )
}

fn inline(telemetry: &str) -> Generator {
    Generator::new(MESSAGES).telemetry_from_str("inline.xml", telemetry)
}

fn one_mode(messages: &str) -> String {
    format!(
        r#"<telemetry><process name="Main"><mode name="m">{messages}</mode></process></telemetry>"#
    )
}

fn mode<'a>(s: &'a Schedule, process: &str, mode: &str) -> &'a ScheduledMode {
    s.processes
        .iter()
        .find(|p| p.name == process)
        .and_then(|p| p.modes.iter().find(|m| m.name == mode))
        .unwrap_or_else(|| panic!("no mode {process}.{mode}"))
}

/// (name, period ticks, phase ticks) of a mode.
fn timing(m: &ScheduledMode) -> Vec<(&str, u32, u32)> {
    m.messages
        .iter()
        .map(|x| (x.name.as_str(), x.period_ticks, x.phase_ticks))
        .collect()
}

/// Messages of one mode that share a tick with another message of the same period.
fn same_period_collisions(m: &ScheduledMode) -> Vec<(String, String)> {
    let mut first: HashMap<(u32, u32), &str> = HashMap::new();
    let mut collisions = Vec::new();
    for x in &m.messages {
        if let Some(other) = first.insert((x.period_ticks, x.phase_ticks), &x.name) {
            collisions.push((other.to_owned(), x.name.clone()));
        }
    }
    collisions
}

#[test]
fn structure_errors() {
    let (_, text) = errors("structure.xml");
    assert_eq!(
        text,
        "error: tests/fixtures/telemetry/structure.xml:4:7: unexpected element <msg>, expected <message>\n\
         error: tests/fixtures/telemetry/structure.xml:7:3: unexpected element <proc>, expected <process>\n\
         error: tests/fixtures/telemetry/structure.xml:8:3: process `Empty` has no <mode>\n\
         error: tests/fixtures/telemetry/structure.xml:9:3: name `2nd` is not a valid identifier (letters, digits and `_`, not starting with a digit)\n\
         error: tests/fixtures/telemetry/structure.xml:10:5: name `raw sensors` is not a valid identifier (letters, digits and `_`, not starting with a digit)"
    );
}

#[test]
fn wrong_root_and_malformed_xml() {
    let err = inline("<protocol/>").schedule().unwrap_err();
    assert_eq!(
        err.to_string(),
        "error: inline.xml:1:1: unexpected element <protocol>, expected <telemetry> as the root element"
    );
    let err = inline("<telemetry>\n  <process name=\"Main\">\n</telemetry>")
        .schedule()
        .unwrap_err();
    assert!(matches!(err.diagnostics()[0].kind, ErrorKind::Xml(_)));
    assert!(err.to_string().starts_with("error: inline.xml:3:"), "{err}");
}

#[test]
fn missing_attributes_are_all_reported() {
    let (kinds, text) = errors("missing_attribute.xml");
    assert_eq!(
        kinds,
        [
            ErrorKind::MissingAttribute {
                element: "process",
                attribute: "name"
            },
            ErrorKind::MissingAttribute {
                element: "mode",
                attribute: "name"
            },
            ErrorKind::MissingAttribute {
                element: "message",
                attribute: "name"
            },
            ErrorKind::MissingAttribute {
                element: "message",
                attribute: "period"
            },
        ]
    );
    assert_eq!(
        text.lines().last(),
        Some(
            "error: tests/fixtures/telemetry/missing_attribute.xml:5:7: message ALIVE: <message> is missing the required attribute `period`"
        )
    );
}

#[test]
fn periods_and_phases_are_validated() {
    let (_, text) = errors("bad_numbers.xml");
    let f = "error: tests/fixtures/telemetry/bad_numbers.xml";
    let period = "is not a finite number of seconds > 0";
    let phase = "is not a finite number of seconds >= 0 and less than the period";
    assert_eq!(
        text,
        [
            format!("{f}:4:7: message ALIVE: attribute `period` = `0` {period}"),
            format!("{f}:5:7: message ATTITUDE: attribute `period` = `-1` {period}"),
            format!("{f}:6:7: message GPS: attribute `period` = `fast` {period}"),
            format!("{f}:7:7: message ENERGY: attribute `period` = `inf` {period}"),
            format!("{f}:8:7: message DL_VALUE: attribute `phase` = `-0.5` {phase}"),
            format!("{f}:9:7: message DATALINK_REPORT: attribute `phase` = `1` {phase}"),
            format!("{f}:10:7: message IMU_GYRO_RAW: attribute `phase` = `NaN` {phase}"),
        ]
        .join("\n")
    );
}

#[test]
fn duplicates_are_reported() {
    let (kinds, text) = errors("duplicates.xml");
    assert!(matches!(
        kinds[0],
        ErrorKind::Duplicate {
            what: "message name",
            first_line: 4,
            ..
        }
    ));
    let f = "error: tests/fixtures/telemetry/duplicates.xml";
    assert_eq!(
        text,
        [
            format!(
                "{f}:5:7: message ALIVE: duplicate message name `ALIVE` (first defined on line 4)"
            ),
            format!("{f}:7:5: duplicate mode name `default` (first defined on line 3)"),
            format!(
                "{f}:9:5: duplicate constant name of mode `MODE_RAW_SENSORS` (first defined on line 8)"
            ),
            format!("{f}:11:3: duplicate process name `Main` (first defined on line 2)"),
            format!("{f}:14:3: duplicate module name of process `main` (first defined on line 2)"),
        ]
        .join("\n")
    );
}

#[test]
fn unknown_messages_are_errors_naming_each_with_file_and_line() {
    let (kinds, text) = errors("unknown.xml");
    assert_eq!(kinds.len(), 2);
    let f = "error: tests/fixtures/telemetry/unknown.xml";
    let hint = "`skip_unknown_telemetry(true)` (CLI: `--skip-unknown-telemetry`) leaves such messages out with a warning";
    assert_eq!(
        text,
        format!(
            "{f}:5:7: message ROTORCRAFT_FOO: not in class `telemetry` of `{MESSAGES}` (mode `default`, process `Main`); {hint}\n\
             {f}:9:7: message PING: not in class `telemetry` of `{MESSAGES}` (mode `debug`, process `Main`); {hint}"
        )
    );
}

#[test]
fn skipping_unknown_messages_warns_and_leaves_them_out() {
    let g = generator("unknown.xml").skip_unknown_telemetry(true);
    let s = g.schedule().unwrap();
    let warnings: Vec<String> = s.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(
        warnings,
        [
            format!(
                "tests/fixtures/telemetry/unknown.xml:5:7: message ROTORCRAFT_FOO: not in class `telemetry` of `{MESSAGES}` (mode `default`, process `Main`); left out of the schedule"
            ),
            format!(
                "tests/fixtures/telemetry/unknown.xml:9:7: message PING: not in class `telemetry` of `{MESSAGES}` (mode `debug`, process `Main`); left out of the schedule"
            ),
        ]
    );
    assert_eq!(s.warnings[1].message.as_deref(), Some("PING"));
    // Staggered as if the left-out messages were not in the file.
    assert_eq!(
        timing(mode(&s, "Main", "default")),
        [("ALIVE", 126, 0), ("GPS", 15, 6)]
    );
    assert_eq!(timing(mode(&s, "Main", "debug")), [("ATTITUDE", 15, 0)]);
    let generated = g.generate_telemetry().unwrap();
    assert_eq!(generated.warnings, s.warnings);
    assert!(!generated.code.contains("ROTORCRAFT_FOO"));
    // Without the option nothing is generated.
    assert!(generator("unknown.xml").generate_telemetry().is_err());
}

#[test]
fn messages_resolve_in_the_chosen_class() {
    let s = inline(&one_mode(r#"<message name="PING" period="1"/>"#))
        .telemetry_class("datalink")
        .schedule()
        .unwrap();
    let m = &mode(&s, "Main", "m").messages[0];
    assert_eq!((m.class_id, m.msg_id), (2, 8));
    let err = inline(&one_mode(r#"<message name="PING" period="1"/>"#))
        .telemetry_class("ground")
        .schedule()
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "error: inline.xml: class `ground` (where periodic messages are looked up) is not in `{MESSAGES}`"
        )
    );
    // Messages not selected for generation are not available to the schedule either.
    let err = inline(&one_mode(r#"<message name="ALIVE" period="1"/>"#))
        .messages(["GPS"])
        .schedule()
        .unwrap_err();
    assert!(
        err.to_string()
            .contains("message ALIVE: not in class `telemetry`"),
        "{err}"
    );
}

#[test]
fn generator_settings_are_validated() {
    let ok = one_mode(r#"<message name="ALIVE" period="1"/>"#);
    let err = inline(&ok).tick_frequency(0).schedule().unwrap_err();
    assert_eq!(
        err.to_string(),
        "error: inline.xml: the tick frequency must be at least 1 Hz"
    );
    let err = inline(&ok).stagger_interval(-0.1).schedule().unwrap_err();
    assert_eq!(
        err.to_string(),
        "error: inline.xml: the stagger interval must be a finite number of seconds >= 0, not -0.1"
    );
    let err = inline(&one_mode(r#"<message name="ALIVE" period="1e10"/>"#))
        .schedule()
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "error: inline.xml:1:48: message ALIVE: period 10000000000 s is 600000000000 ticks at 60 Hz, more than the 4294967295 a schedule holds"
    );
    let err = Generator::new(MESSAGES).schedule().unwrap_err();
    assert!(
        err.to_string().contains("no telemetry configuration given"),
        "{err}"
    );
    let err = Generator::new(MESSAGES)
        .telemetry("tests/fixtures/telemetry/absent.xml")
        .schedule()
        .unwrap_err();
    assert!(
        err.to_string()
            .starts_with("error: tests/fixtures/telemetry/absent.xml: cannot read file"),
        "{err}"
    );
}

#[test]
fn seconds_become_ticks() {
    let xml = one_mode(
        r#"<message name="ALIVE" period="4.1"/>
           <message name="ATTITUDE" period="0.075" phase="0.05"/>
           <message name="GPS" period="0.03"/>
           <message name="ENERGY" period="1" phase="0.999"/>
           <message name="DL_VALUE" period="0.005"/>"#,
    );
    let s = inline(&xml).stagger_interval(0.0).schedule().unwrap();
    // Nearest tick, halves up (4.5 -> 5), float noise ignored (245.99999999999997 -> 246),
    // at least one tick, phase modulo the period (59.94 -> 60 -> 0).
    assert_eq!(
        timing(mode(&s, "Main", "m")),
        [
            ("ALIVE", 246, 0),
            ("ATTITUDE", 5, 3),
            ("GPS", 2, 0),
            ("ENERGY", 60, 0),
            ("DL_VALUE", 1, 0)
        ]
    );
    let m = &mode(&s, "Main", "m").messages[1];
    assert_eq!((m.period_s, m.phase_s), (0.075, Some(0.05)));
    assert_eq!(
        s.warnings
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>(),
        [
            "inline.xml:5:12: message DL_VALUE: period 0.005 s is shorter than one tick at 60 Hz (16.667 ms): sent on every tick"
        ]
    );
    // Another tick frequency.
    let s = inline(&xml).tick_frequency(512).schedule().unwrap();
    assert_eq!(mode(&s, "Main", "m").messages[0].period_ticks, 2099);
    assert_eq!(s.frequency_hz, 512);
    assert_eq!(s.stagger_ticks, 51);
}

#[test]
fn automatic_phases_are_staggered_and_never_equal_for_equal_periods() {
    // Six messages of 0.5 s (30 ticks) without a phase: 0, 6, 12, 18, 24, then 30 mod 30
    // = 0 is taken, so the next free phase, 1. An explicit phase is kept and avoided.
    let xml = one_mode(
        r#"<message name="ALIVE" period="0.5"/>
           <message name="ATTITUDE" period="0.5"/>
           <message name="GPS" period="0.5" phase="0.2"/>
           <message name="ENERGY" period="0.5"/>
           <message name="DATALINK_REPORT" period="0.5"/>
           <message name="DL_VALUE" period="0.5"/>
           <message name="IMU_GYRO_RAW" period="0.5"/>"#,
    );
    let s = inline(&xml).schedule().unwrap();
    let m = mode(&s, "Main", "m");
    assert_eq!(
        timing(m),
        [
            ("ALIVE", 30, 0),
            ("ATTITUDE", 30, 6),
            ("GPS", 30, 12),
            ("ENERGY", 30, 13),
            ("DATALINK_REPORT", 30, 18),
            ("DL_VALUE", 30, 24),
            ("IMU_GYRO_RAW", 30, 1),
        ]
    );
    assert!(same_period_collisions(m).is_empty());
    // The naive rule `i * 6 mod period` would have put ALIVE and IMU_GYRO_RAW together.
}

#[test]
fn tables_match_the_snapshot() {
    // After an intended change of the emitter, regenerate with
    // `UPDATE_SNAPSHOTS=1 cargo test -p pprz-codegen --test telemetry` and review the
    // diff. The snapshot is compiled here (`snapshot_tables_compile`) and run by the
    // runtime's scheduler tests.
    let generated = Generator::new(MESSAGES)
        .telemetry(OK)
        .generate_telemetry()
        .unwrap();
    assert!(generated.warnings.is_empty());
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::write(SNAPSHOT, &generated.code).unwrap();
    }
    let expected = std::fs::read_to_string(SNAPSHOT).unwrap_or_default();
    assert!(
        generated.code == expected,
        "generated code differs from {SNAPSHOT}; rerun with UPDATE_SNAPSHOTS=1 and review the diff"
    );
}

// The tables use only `pprz_messages::schedule`, so the snapshot compiles here.
#[allow(dead_code)]
mod snapshot {
    include!("snapshots/periodic.rs");
}

#[test]
fn snapshot_tables_compile() {
    use pprz_messages::schedule::Schedule;
    let schedule: &Schedule<'static> = &snapshot::SCHEDULE;
    assert_eq!(schedule.frequency_hz, snapshot::FREQUENCY_HZ);
    assert_eq!(schedule.processes.len(), snapshot::PROCESSES);
    assert_eq!(schedule.processes[snapshot::logger::PROCESS].name, "Logger");
    let main = &schedule.processes[snapshot::main::PROCESS];
    assert_eq!(
        main.modes[snapshot::main::MODE_RAW_SENSORS].name,
        "raw_sensors"
    );
    assert_eq!(schedule.message_id("ENERGY"), Some((1, 12)));
    let energy = main.modes[0]
        .messages
        .iter()
        .find(|m| m.name == "ENERGY")
        .unwrap();
    assert_eq!((energy.period_ticks, energy.phase_ticks), (15, 6));
    assert!(energy.is_due(6) && energy.is_due(21) && !energy.is_due(15));
}

#[test]
fn tables_content() {
    let code = Generator::new(MESSAGES)
        .telemetry(OK)
        .runtime_crate("crate::rt")
        .tick_frequency(100)
        .generate_telemetry()
        .unwrap()
        .code;
    for expected in [
        "pub const FREQUENCY_HZ: u32 = 100;",
        "pub const PROCESSES: usize = 2;",
        "pub static SCHEDULE: crate::rt::schedule::Schedule<'static> = crate::rt::schedule::Schedule {",
        "        crate::rt::schedule::Process {",
        "                crate::rt::schedule::Mode {",
        "key_press: ::core::option::Option::Some(\"d\"),",
        "// ENERGY: every 0.25 s, phase 0.1 s",
        "crate::rt::schedule::Periodic { name: \"ENERGY\", class_id: 1, msg_id: 12, period_ticks: 25, phase_ticks: 10, period_s: 0.25 },",
        "// ALIVE: every 2.1 s, automatic phase",
        "crate::rt::schedule::Periodic { name: \"ALIVE\", class_id: 1, msg_id: 2, period_ticks: 210, phase_ticks: 0, period_s: 2.1 },",
        "pub mod main {",
        "pub mod logger {",
        "    pub const PROCESS: usize = 1;",
        "    pub const MODE_RAW_SENSORS: usize = 1;",
        "    pub const MODE_OFF: usize = 2;",
        "Mode `off`: no messages.",
    ] {
        assert!(code.contains(expected), "missing `{expected}` in:\n{code}");
    }
}

#[test]
fn schedule_model() {
    let s = Generator::new(MESSAGES).telemetry(OK).schedule().unwrap();
    assert_eq!(
        (s.processes.len(), s.mode_count(), s.entry_count()),
        (2, 4, 11)
    );
    assert_eq!(s.stagger_ticks, 6);
    // Explicit phases are kept (ENERGY 0.1 s = 6 ticks, DATALINK_REPORT 1.5 s = 90); the
    // others are 100 ms (6 ticks) apart in file order, modulo the period, never equal to
    // another of the same period: ATTITUDE's candidate 6 is ENERGY's, so it gets 7.
    assert_eq!(
        timing(mode(&s, "Main", "default")),
        [
            ("ALIVE", 126, 0),
            ("ATTITUDE", 15, 7),
            ("GPS", 15, 12),
            ("ENERGY", 15, 6),
            ("DL_VALUE", 66, 18),
            ("DATALINK_REPORT", 306, 90),
        ]
    );
    assert_eq!(
        timing(mode(&s, "Main", "raw_sensors")),
        [
            ("ALIVE", 126, 0),
            ("IMU_GYRO_RAW", 3, 0),
            ("IMU_ACCEL_RAW", 3, 1)
        ]
    );
    assert!(mode(&s, "Main", "off").messages.is_empty());
    assert_eq!(mode(&s, "Main", "default").key_press.as_deref(), Some("d"));
    assert_eq!(
        timing(mode(&s, "Logger", "all")),
        [("ATTITUDE", 1, 0), ("IMU_GYRO_RAW", 1, 0)]
    );
}

fn cli(args: &[&str]) -> (bool, String, String) {
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
fn cli_checks_lists_and_generates() {
    let (ok, stdout, stderr) = cli(&[MESSAGES, "--telemetry", OK, "--list"]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("Main       raw_sensors      IMU_ACCEL_RAW                   1  204     0.05       3  1 (auto)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("Main       default          ENERGY                          1   12     0.25      15  6 (0.1 s)"),
        "{stdout}"
    );
    assert!(stdout.ends_with(&format!(
        "{OK}: 2 processes, 4 modes, 11 periodic messages at 60 Hz: ok\n"
    )));
    let (ok, stdout, _) = cli(&[MESSAGES, "--telemetry", OK, "--tick-frequency", "100"]);
    assert!(ok);
    assert!(stdout.contains("pub const FREQUENCY_HZ: u32 = 100;"));
    let (ok, _, stderr) = cli(&[MESSAGES, "--telemetry", OK, "--tick-frequency", "0"]);
    assert!(!ok);
    assert!(stderr.contains("--tick-frequency"), "{stderr}");
    let (ok, stdout, stderr) = cli(&[MESSAGES, "--telemetry", OK, "--runtime-crate", "rt"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("pub static SCHEDULE: rt::schedule::Schedule<'static>"));
}

#[test]
fn cli_reports_unknown_messages_and_can_skip_them() {
    let unknown = fixture("unknown.xml");
    let (ok, stdout, stderr) = cli(&[MESSAGES, "--telemetry", &unknown, "--check"]);
    assert!(!ok);
    assert!(stdout.is_empty());
    assert_eq!(stderr.lines().count(), 2, "{stderr}");
    assert!(stderr.starts_with(&format!(
        "error: {unknown}:5:7: message ROTORCRAFT_FOO: not in class `telemetry`"
    )));
    let (ok, stdout, stderr) = cli(&[
        MESSAGES,
        "--telemetry",
        &unknown,
        "--skip-unknown-telemetry",
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("name: \"GPS\""));
    assert!(stderr.starts_with(&format!(
        "warning: {unknown}:5:7: message ROTORCRAFT_FOO: not in class `telemetry`"
    )));
    assert_eq!(stderr.lines().count(), 2, "{stderr}");
    let (ok, _, stderr) = cli(&[MESSAGES, "--skip-unknown-telemetry"]);
    assert!(!ok, "the option needs --telemetry: {stderr}");
}

#[test]
fn reference_default_rotorcraft() {
    let Some(dir) = reference::locate_for_test("reference_default_rotorcraft") else {
        return;
    };
    let telemetry = dir.join("telemetry/default_rotorcraft.xml");
    let g = Generator::new(dir.join("messages.xml")).telemetry(&telemetry);

    // Exactly the two messages absent from the reference messages.xml, with their lines.
    let err = g.schedule().unwrap_err();
    let named: Vec<(&str, u32)> = err
        .diagnostics()
        .iter()
        .map(|d| (d.message.as_deref().unwrap_or(""), d.line))
        .collect();
    assert_eq!(named, [("ACTUATORS_BEBOP", 32), ("STAB_ATTITUDE_REF", 77)]);
    let text = err.to_string();
    assert!(text.contains("(mode `ppm`, process `Main`)"), "{text}");
    assert!(
        text.contains("(mode `attitude_loop`, process `Main`)"),
        "{text}"
    );
    assert!(text.contains("--skip-unknown-telemetry"), "{text}");

    // With the option: the rest, and the two as warnings.
    let g = g.skip_unknown_telemetry(true);
    let s = g.schedule().unwrap();
    let warned: Vec<&str> = s
        .warnings
        .iter()
        .filter_map(|d| d.message.as_deref())
        .collect();
    assert_eq!(warned, ["ACTUATORS_BEBOP", "STAB_ATTITUDE_REF"]);
    let modes: Vec<&str> = s.processes[0]
        .modes
        .iter()
        .map(|m| m.name.as_str())
        .collect();
    assert_eq!(
        modes,
        [
            "default",
            "ppm",
            "raw_sensors",
            "scaled_sensors",
            "ahrs",
            "rate_loop",
            "attitude_loop",
            "vert_loop",
            "aligner",
            "tune_hover"
        ]
    );
    assert_eq!(s.entry_count(), 66 - 2);
    let default = mode(&s, "Main", "default");
    assert_eq!(default.messages.len(), 15);
    let fp = &default.messages[2];
    assert_eq!(
        (fp.name.as_str(), fp.class_id, fp.msg_id, fp.period_ticks),
        ("ROTORCRAFT_FP", 1, 147, 15)
    );
    assert_eq!(mode(&s, "Main", "attitude_loop").messages.len(), 4);
    assert_eq!(
        mode(&s, "Main", "attitude_loop").key_press.as_deref(),
        Some("a")
    );
    for m in &s.processes[0].modes {
        assert!(
            same_period_collisions(m).is_empty(),
            "mode {}: {:?}",
            m.name,
            same_period_collisions(m)
        );
    }
    let code = g.generate_telemetry().unwrap().code;
    assert!(code.contains("pub const MODE_TUNE_HOVER: usize = 9;"));
}

/// Messages M0..M39 in class telemetry, ids 0..39.
fn many_messages() -> String {
    let mut xml = String::from(r#"<protocol><msg_class name="telemetry" id="1">"#);
    for i in 0..40 {
        xml.push_str(&format!(r#"<message name="M{i}" id="{i}"/>"#));
    }
    xml.push_str("</msg_class></protocol>");
    xml
}

proptest! {
    /// For any mode: explicit phases are kept; automatic phases never equal another phase
    /// of the same period while the period has enough ticks for all its messages, and
    /// are otherwise balanced (at most `ceil(n / period)` per tick).
    #[test]
    fn staggering_separates_equal_periods(
        entries in prop::collection::vec((1u32..12, prop::option::of(0u32..12)), 1..40),
        freq in prop::sample::select(vec![10u32, 50, 60, 100, 512]),
    ) {
        let mut body = String::new();
        for (i, (period, phase)) in entries.iter().enumerate() {
            // Periods as whole ticks: period / freq seconds.
            let period_s = f64::from(*period) / f64::from(freq);
            match phase {
                Some(ph) if ph < period => body.push_str(&format!(
                    r#"<message name="M{i}" period="{period_s}" phase="{}"/>"#,
                    f64::from(*ph) / f64::from(freq)
                )),
                _ => body.push_str(&format!(r#"<message name="M{i}" period="{period_s}"/>"#)),
            }
        }
        let s = Generator::from_str("m.xml", &many_messages())
            .telemetry_from_str("t.xml", &one_mode(&body))
            .tick_frequency(freq)
            .schedule()
            .unwrap();
        let m = mode(&s, "Main", "m");
        let mut explicit_used: HashMap<(u32, u32), usize> = HashMap::new();
        let mut count: HashMap<u32, usize> = HashMap::new();
        for ((period, phase), x) in entries.iter().zip(&m.messages) {
            prop_assert_eq!(x.period_ticks, *period);
            prop_assert!(x.phase_ticks < x.period_ticks);
            *count.entry(*period).or_default() += 1;
            if let Some(ph) = phase.filter(|ph| ph < period) {
                prop_assert_eq!(x.phase_ticks, ph);
                *explicit_used.entry((*period, ph)).or_default() += 1;
            }
        }
        let mut load: HashMap<(u32, u32), usize> = HashMap::new();
        for x in &m.messages {
            *load.entry((x.period_ticks, x.phase_ticks)).or_default() += 1;
        }
        for ((period, phase), x) in entries.iter().zip(&m.messages) {
            if phase.is_some_and(|ph| ph < *period) {
                continue;
            }
            let n = count[period];
            let here = load[&(x.period_ticks, x.phase_ticks)];
            if n <= *period as usize {
                // Alone on its phase, except with explicit phases that collide among
                // themselves (the configuration's choice), which it avoids anyway.
                prop_assert_eq!(here, 1, "{} shares its tick: {:?}", x.name, timing(m));
            } else if explicit_used.is_empty() {
                prop_assert!(here <= n.div_ceil(*period as usize));
            }
        }
    }
}
