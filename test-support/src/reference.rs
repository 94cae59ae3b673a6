//! Locating the PPRZLINK reference data (`messages.xml`, `units.xml`, telemetry
//! configurations) for compatibility tests.
//!
//! The data is not shipped with this project (its license differs). Tests look for it in
//! the directory named by the environment variable [`DIR_VAR`], or else in
//! [`default_dir`]: `shared/pprzlink` next to the workspace directory, a default data
//! location only. When it is absent a test is skipped with a printed reason, unless
//! [`REQUIRE_VAR`] is set (CI sets it), which turns the skip into a failure. A test that
//! needs something else the machine may lack (a device file) follows the same rule
//! through [`skip_test`].
//!
//! ```no_run
//! // In a test:
//! let Some(dir) = pprz_test_support::reference::locate_for_test("my_test") else {
//!     return; // skipped, the reason is printed
//! };
//! let messages = dir.join("messages.xml");
//! ```

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Environment variable naming the directory that holds the reference `messages.xml`.
pub const DIR_VAR: &str = "PPRZLINK_DIR";

/// Environment variable that, set to anything but `0` or empty, makes missing reference
/// data an error instead of a skip.
pub const REQUIRE_VAR: &str = "PPRZ_REQUIRE_REFERENCE";

/// Whether missing reference data must fail rather than skip.
pub fn required() -> bool {
    std::env::var(REQUIRE_VAR).is_ok_and(|v| !v.is_empty() && v != "0")
}

/// The default reference directory: `shared/pprzlink` in the directory that contains
/// the workspace (`<workspace>/../shared/pprzlink`).
pub fn default_dir() -> PathBuf {
    // This crate is `<workspace>/test-support`.
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    match manifest.parent().and_then(Path::parent) {
        Some(above_workspace) => above_workspace.join("shared/pprzlink"),
        None => manifest.join("../../shared/pprzlink"),
    }
}

/// The reference directory: `$PPRZLINK_DIR`, else [`default_dir`].
pub fn dir() -> PathBuf {
    std::env::var_os(DIR_VAR)
        .map(PathBuf::from)
        .unwrap_or_else(default_dir)
}

/// Finds the reference directory for the test (or build script) `who`.
///
/// Returns `Ok(Some(dir))` when `dir/messages.xml` exists, `Ok(None)` after printing a
/// skip reason to the real standard error (not captured by the test harness) when it does
/// not, and `Err(reason)` when it does not but [`required`] is true.
///
/// # Errors
/// The data is missing and required.
pub fn locate(who: &str) -> Result<Option<PathBuf>, String> {
    let dir = dir();
    if dir.join("messages.xml").is_file() {
        return Ok(Some(dir));
    }
    let reason = format!(
        "PPRZLINK reference data not found: no messages.xml in {} (set {DIR_VAR} to the directory that holds it)",
        dir.display()
    );
    skip(who, &reason).map(|()| None)
}

/// The precondition of the test (or build script) `who` is missing, for `reason`:
/// prints `skipped {who}: {reason}` to the real standard error (not captured by the test
/// harness) and returns `Ok(())`, or returns `Err` with the reason when [`required`] is
/// true. The one rule of every test that needs something the machine may lack.
///
/// # Errors
/// [`required`] is true.
pub fn skip(who: &str, reason: &str) -> Result<(), String> {
    if required() {
        return Err(format!(
            "{who}: {reason}; {REQUIRE_VAR} is set, so this is an error"
        ));
    }
    let _ = writeln!(std::io::stderr(), "skipped {who}: {reason}");
    Ok(())
}

/// [`skip`] for a test: prints the skip reason, the test then returns.
///
/// ```no_run
/// let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
///     pprz_test_support::reference::skip_test("full_disk", "no /dev/full here");
///     return;
/// };
/// # let _ = full;
/// ```
///
/// # Panics
/// [`required`] is true: the test fails with the reason.
#[track_caller]
pub fn skip_test(who: &str, reason: &str) {
    if let Err(reason) = skip(who, reason) {
        panic!("{reason}");
    }
}

/// [`locate`] for a test: the directory, or `None` (skip, reason printed).
///
/// # Panics
/// The data is missing and [`required`]: the test fails with the reason.
#[track_caller]
pub fn locate_for_test(who: &str) -> Option<PathBuf> {
    match locate(who) {
        Ok(dir) => dir,
        Err(reason) => panic!("{reason}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::Command;

    #[test]
    fn default_dir_is_next_to_the_workspace() {
        let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        assert!(workspace.join("Cargo.toml").is_file());
        assert_eq!(
            default_dir(),
            workspace.parent().unwrap().join("shared/pprzlink")
        );
    }

    /// Set in the child process of [`skips_fails_or_finds`].
    const CHILD_VAR: &str = "PPRZ_TEST_SUPPORT_CHILD";

    /// Runs `locate("child")` in a child process (the environment is per process) with
    /// `PPRZLINK_DIR=dir` and `PPRZ_REQUIRE_REFERENCE=require`: its outcome and stderr.
    fn child(dir: &Path, require: Option<&str>) -> (String, String) {
        let mut cmd = Command::new(std::env::current_exe().unwrap());
        cmd.args([
            "--exact",
            "reference::tests::skips_fails_or_finds",
            "--nocapture",
        ])
        .env(CHILD_VAR, "1")
        .env(DIR_VAR, dir)
        .env_remove(REQUIRE_VAR);
        if let Some(v) = require {
            cmd.env(REQUIRE_VAR, v);
        }
        let out = cmd.output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        let outcome = stdout
            .lines()
            .find_map(|l| l.strip_prefix("outcome: "))
            .unwrap_or_else(|| panic!("no outcome in {stdout}"))
            .to_owned();
        (outcome, String::from_utf8_lossy(&out.stderr).into_owned())
    }

    #[test]
    fn skips_fails_or_finds() {
        if std::env::var_os(CHILD_VAR).is_some() {
            let outcome = match locate("child") {
                Ok(Some(dir)) => format!("found {}", dir.display()),
                Ok(None) => "skipped".to_owned(),
                Err(reason) => format!("error {reason}"),
            };
            println!("outcome: {outcome}");
            return;
        }
        let missing =
            std::env::temp_dir().join(format!("pprz-no-reference-{}", std::process::id()));
        let reason = format!(
            "PPRZLINK reference data not found: no messages.xml in {} (set PPRZLINK_DIR to the directory that holds it)",
            missing.display()
        );
        for require in [None, Some(""), Some("0")] {
            let (outcome, stderr) = child(&missing, require);
            assert_eq!(outcome, "skipped", "{require:?}");
            assert!(
                stderr.contains(&format!("skipped child: {reason}")),
                "{stderr}"
            );
        }
        let (outcome, _) = child(&missing, Some("1"));
        assert_eq!(
            outcome,
            format!("error child: {reason}; PPRZ_REQUIRE_REFERENCE is set, so this is an error")
        );

        let present = std::env::temp_dir().join(format!("pprz-reference-{}", std::process::id()));
        std::fs::create_dir_all(&present).unwrap();
        std::fs::write(present.join("messages.xml"), "<protocol/>").unwrap();
        let (outcome, stderr) = child(&present, Some("1"));
        let _ = std::fs::remove_dir_all(&present);
        assert_eq!(outcome, format!("found {}", present.display()));
        assert!(!stderr.contains("skipped"), "{stderr}");
    }
}
