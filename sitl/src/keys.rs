//! `--secure`: the keys of both ends, read from one key file.

use std::path::Path;

use pprz_ground::secure::key_file_from_path;

/// The keys of `--secure`: the aircraft's, and the ground's unless `headless`.
pub struct SitlKeys {
    /// The aircraft's.
    pub aircraft: pprz_secure::AircraftKeys,
    /// The in-process ground's (`None` with `--headless`).
    pub ground: Option<pprz_secure::GroundKeys>,
}

/// Reads the key file (`pprz_ground::secure::key_file_from_path`: bounded, UTF-8,
/// cleared after parsing) and takes the keys each end needs.
pub fn load(path: &Path, headless: bool) -> Result<SitlKeys, String> {
    let file = key_file_from_path(path).map_err(|e| e.to_string())?;
    let aircraft = file.aircraft().map_err(|e| format!("aircraft keys: {e}"))?;
    let ground = if headless {
        None
    } else {
        Some(file.ground().map_err(|e| format!("ground keys: {e}"))?)
    };
    Ok(SitlKeys { aircraft, ground })
}
