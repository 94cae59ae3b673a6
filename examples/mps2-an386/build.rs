//! Puts `memory.x` where the linker finds it (cortex-m-rt's `link.x` includes it), as
//! cortex-m-rt's own examples do; and writes the aircraft's keys for `aircraft-secure`
//! to `$OUT_DIR/aircraft.keys`: the key file named by `PPRZ_SECURE_KEYS`, or the
//! repository's published INSECURE test key set, without the ground's private key.

use std::path::PathBuf;
use std::{env, fs};

/// The published test keys: anyone can read them.
const TEST_KEYS: &str = "../../secure/keys/INSECURE-TEST-ONLY.keys";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("memory.x"), include_bytes!("memory.x")).expect("OUT_DIR is writable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");

    println!("cargo:rerun-if-env-changed=PPRZ_SECURE_KEYS");
    let path = match env::var("PPRZ_SECURE_KEYS") {
        Ok(path) => path,
        Err(_) => {
            println!(
                "cargo:warning=aircraft-secure: PPRZ_SECURE_KEYS is not set: embedding the \
                 published INSECURE TEST KEYS ({TEST_KEYS}); never fly with them"
            );
            TEST_KEYS.to_owned()
        }
    };
    println!("cargo:rerun-if-changed={path}");
    let text = fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("PPRZ_SECURE_KEYS: cannot read {path}: {e}"));
    // The aircraft needs its own key pair and the ground's public key, never the
    // ground's private key: leave it out of the firmware.
    let aircraft: String = text
        .lines()
        .filter(|line| !line.trim_start().starts_with("GCS_PRIVATE"))
        .map(|line| format!("{line}\n"))
        .collect();
    fs::write(out.join("aircraft.keys"), aircraft).expect("OUT_DIR is writable");
}
