//! The SITL's ground names the settings after `--settings`: the DL_VALUE lines of
//! `--lines`, the live view's settings with their labels and bounds; a settings file
//! with an error stops the run before it starts, naming the file, line and column.

use std::io::Write as _;
use std::net::UdpSocket;
use std::process::Command;

/// The example application's settings file (what the aircraft of the SITL runs).
const FIXTURE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/app/settings.xml");

/// A free loopback UDP address (bound then released).
fn free_addr() -> String {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.local_addr().unwrap().to_string()
}

/// Runs the SITL for 6 simulated seconds at speed 3 with `extra`: success, standard
/// output and standard error. A run whose ports were taken meanwhile is repeated.
fn sitl(extra: &[&str]) -> (bool, String, String) {
    let mut last = (false, String::new(), String::new());
    for _ in 0..3 {
        let (ground, uplink) = (free_addr(), free_addr());
        let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
            .args(["--duration", "6", "--speed", "3"])
            .args(["--ground", &ground, "--uplink", &uplink])
            .args(extra)
            .output()
            .expect("the simulation runs");
        last = (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        );
        if last.0 || !last.2.to_lowercase().contains("in use") {
            break;
        }
    }
    last
}

#[test]
fn the_ground_names_the_settings_in_its_lines_and_live_view() {
    let (ok, out, err) = sitl(&["--lines", "--settings", FIXTURE]);
    assert!(ok, "{err}");
    // The SETTING of `gain` at 3 s, acknowledged; the periodic values named too.
    assert!(
        out.lines()
            .any(|l| l == "7 telemetry DL_VALUE index=2 value=2.5 setting=gain"),
        "{out}"
    );
    assert!(
        out.lines()
            .filter(|l| l.starts_with("7 telemetry DL_VALUE "))
            .all(|l| l.contains(" setting=")),
        "{out}"
    );
    let (ok, out, err) = sitl(&["--settings", FIXTURE]);
    assert!(ok, "{err}");
    for expected in [
        "settings: ",
        "    2 gain                     2.5                  [0, 10]",
        "DL_VALUE gain (index 2) = 2.5: SETTING acknowledged after",
    ] {
        assert!(out.contains(expected), "{expected}\n{out}");
    }
}

#[test]
fn a_settings_file_with_an_error_stops_the_run_with_its_location() {
    let mut bad = tempfile_path("bad.xml");
    let path = bad.0.clone();
    bad.1
        .write_all(b"<settings><dl_settings>\n <dl_setting var=\"gain\" max=\"1\"/>\n</dl_settings></settings>\n")
        .unwrap();
    drop(bad.1);
    let (ok, _, err) = sitl(&["--lines", "--settings", &path]);
    let _ = std::fs::remove_file(&path);
    assert!(!ok);
    assert!(err.contains(&format!("sitl: error: {path}:2:2: ")), "{err}");
}

/// A new file in the temporary directory, unique to this test process.
fn tempfile_path(name: &str) -> (String, std::fs::File) {
    let path = std::env::temp_dir().join(format!("pprz-sitl-{}-{name}", std::process::id()));
    let file = std::fs::File::create(&path).unwrap();
    (path.to_str().unwrap().to_owned(), file)
}
