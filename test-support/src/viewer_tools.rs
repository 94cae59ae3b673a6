//! Locating the independent readers of the viewer tests: PyPI's `mcap` and `jsonschema`
//! in a Python virtual environment, and npm's `@foxglove/ws-protocol` client under Node.
//!
//! `ground/tests/foxglove/setup.sh` installs both: the virtual environment in
//! [`VENV_VAR`] (default `target/foxglove-venv` in the workspace), the npm packages in
//! `ground/tests/foxglove/node_modules`. When they are absent a test is skipped with a
//! printed reason, unless the reference requirement is set
//! ([`reference::REQUIRE_VAR`](crate::reference::REQUIRE_VAR), as CI does), which turns
//! the skip into a failure.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::reference::{REQUIRE_VAR, required};

/// Environment variable naming the Python virtual environment of the tools.
pub const VENV_VAR: &str = "PPRZ_FOXGLOVE_VENV";

/// The workspace directory.
fn workspace() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().unwrap_or(manifest).to_owned()
}

/// The directory of the tools' scripts: `ground/tests/foxglove`.
pub fn scripts() -> PathBuf {
    workspace().join("ground/tests/foxglove")
}

/// The virtual environment: `$PPRZ_FOXGLOVE_VENV`, else `target/foxglove-venv`.
pub fn venv() -> PathBuf {
    std::env::var_os(VENV_VAR)
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target/foxglove-venv"))
}

/// Skips (reason printed, `None`) or fails (`required`) for `who`.
#[track_caller]
fn missing<T>(who: &str, what: &str) -> Option<T> {
    let reason = format!(
        "{what} (install it with `bash ground/tests/foxglove/setup.sh`, or set {VENV_VAR})"
    );
    if required() {
        panic!("{who}: {reason}; {REQUIRE_VAR} is set, so this is an error");
    }
    let _ = writeln!(std::io::stderr(), "skipped {who}: {reason}");
    None
}

/// The Python of the virtual environment, with `mcap` and `jsonschema` importable, for
/// the test `who`; `None` (skip, reason printed) when absent.
///
/// # Panics
/// It is absent and required.
#[track_caller]
pub fn python(who: &str) -> Option<PathBuf> {
    let python = venv().join("bin/python");
    let ok = Command::new(&python)
        .args(["-c", "import mcap, jsonschema"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        Some(python)
    } else {
        missing(
            who,
            &format!("no Python with mcap and jsonschema at {}", python.display()),
        )
    }
}

/// The Node client script (`ws_client.mjs`), its packages installed and `node` on the
/// path, for the test `who`; `None` (skip, reason printed) when absent.
///
/// # Panics
/// It is absent and required.
#[track_caller]
pub fn node_client(who: &str) -> Option<PathBuf> {
    let dir = scripts();
    let installed = dir.join("node_modules/@foxglove/ws-protocol").is_dir();
    let node = Command::new("node")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if installed && node {
        Some(dir.join("ws_client.mjs"))
    } else {
        missing(
            who,
            &format!(
                "no node, or no @foxglove/ws-protocol in {}/node_modules",
                dir.display()
            ),
        )
    }
}

/// Reads a child's standard error to its end in a thread (so that the child never waits
/// on it), and returns the address of the Foxglove server it announces
/// (`foxglove: serving ws://...`) and the thread, which gives the whole text.
///
/// # Panics
/// No announcement within 30 s.
pub fn served_url(stderr: std::process::ChildStderr) -> (String, std::thread::JoinHandle<String>) {
    use std::io::{BufRead, BufReader};
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if let Some(url) = line.strip_prefix("foxglove: serving ") {
                let _ = tx.send(url.to_owned());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let url = rx
        .recv_timeout(std::time::Duration::from_secs(30))
        .expect("a Foxglove server is announced on standard error");
    (url, reader)
}
