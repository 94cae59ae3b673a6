// For a firmware's build.rs (`include!` this file, then call `embed_aircraft_keys()`):
// writes the aircraft's keys to `$OUT_DIR/aircraft.keys`, for
// `pprz_secure::const_key_file!(include_str!(concat!(env!("OUT_DIR"), "/aircraft.keys")))`.
//
// The keys come from the key file named by the environment variable `PPRZ_SECURE_KEYS`
// (never commit it), or, without it, from this repository's published INSECURE test key
// set, with a build warning. The ground's private key (`GCS_PRIVATE`) is left out: an
// aircraft needs only its own pair and the ground's public key.

/// The published test keys, relative to a firmware crate in `examples/<board>`.
const INSECURE_TEST_KEYS: &str = "../../secure/keys/INSECURE-TEST-ONLY.keys";

/// Writes `$OUT_DIR/aircraft.keys` (see the top of this file).
fn embed_aircraft_keys() {
    let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo:rerun-if-env-changed=PPRZ_SECURE_KEYS");
    let path = match std::env::var("PPRZ_SECURE_KEYS") {
        Ok(path) => path,
        Err(_) => {
            println!(
                "cargo:warning=PPRZ_SECURE_KEYS is not set: embedding the published INSECURE \
                 TEST KEYS ({INSECURE_TEST_KEYS}); never fly with them"
            );
            INSECURE_TEST_KEYS.to_owned()
        }
    };
    println!("cargo:rerun-if-changed={path}");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("PPRZ_SECURE_KEYS: cannot read {path}: {e}"));
    let aircraft: String = text
        .lines()
        .filter(|line| !line.trim_start().starts_with("GCS_PRIVATE"))
        .map(|line| format!("{line}\n"))
        .collect();
    std::fs::write(out.join("aircraft.keys"), aircraft).expect("OUT_DIR is writable");
}
