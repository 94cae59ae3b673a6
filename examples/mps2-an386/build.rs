//! Puts `memory.x` where the linker finds it (cortex-m-rt's `link.x` includes it), as
//! cortex-m-rt's own examples do; and embeds the aircraft's keys for `aircraft-secure`
//! (`PPRZ_SECURE_KEYS`, or the published INSECURE test keys with a warning).

use std::path::PathBuf;
use std::{env, fs};

include!("../../secure/build-support/aircraft_keys.rs");

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("memory.x"), include_bytes!("memory.x")).expect("OUT_DIR is writable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    embed_aircraft_keys();
}
