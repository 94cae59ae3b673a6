//! Locating the PPRZLINK reference data (`messages.xml`, `units.xml`, telemetry
//! configurations) for compatibility tests.
//!
//! The data is not shipped with this project (its license differs). Tests look for it in
//! the directory named by the environment variable [`DIR_VAR`], or in a default
//! directory next to the checkout. When it is absent a test is skipped with a printed
//! reason, unless [`REQUIRE_VAR`] is set (CI sets it), which turns the skip into a
//! failure.

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

/// The reference directory: `$PPRZLINK_DIR`, else `default_dir`.
pub fn dir(default_dir: impl AsRef<Path>) -> PathBuf {
    std::env::var_os(DIR_VAR)
        .map(PathBuf::from)
        .unwrap_or_else(|| default_dir.as_ref().to_path_buf())
}

/// Finds the reference directory for the test `who`.
///
/// Returns `Ok(Some(dir))` when `dir/messages.xml` exists, `Ok(None)` after printing a
/// skip reason to the real standard error (not captured by the test harness) when it does
/// not, and `Err(reason)` when it does not but [`required`] is true.
///
/// # Errors
/// The data is missing and required.
pub fn locate(who: &str, default_dir: impl AsRef<Path>) -> Result<Option<PathBuf>, String> {
    let dir = dir(default_dir);
    if dir.join("messages.xml").is_file() {
        return Ok(Some(dir));
    }
    let reason = format!(
        "PPRZLINK reference data not found: no messages.xml in {} (set {DIR_VAR} to the directory that holds it)",
        dir.display()
    );
    if required() {
        return Err(format!(
            "{who}: {reason}; {REQUIRE_VAR} is set, so this is an error"
        ));
    }
    let _ = writeln!(std::io::stderr(), "skipped {who}: {reason}");
    Ok(None)
}
