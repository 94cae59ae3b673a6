//! Puts `memory.x` where the linker finds it (cortex-m-rt's `link.x` includes it): the
//! chip's memory with flash sectors 1 to 3 kept for the persistent settings. Embeds the
//! aircraft's keys for the `secure` feature (`PPRZ_SECURE_KEYS`, or the published
//! INSECURE test keys with a warning).

use std::path::PathBuf;
use std::{env, fs};

include!("../../secure/build-support/aircraft_keys.rs");

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("memory.x"), include_bytes!("memory.x")).expect("OUT_DIR is writable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    if env::var_os("CARGO_FEATURE_SECURE").is_some() {
        embed_aircraft_keys();
    }
}
