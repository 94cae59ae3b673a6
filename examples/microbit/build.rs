//! Puts `memory.x` where the linker finds it (cortex-m-rt's `link.x` includes it), as
//! cortex-m-rt's own examples do, and passes the linker script to the binaries (here,
//! not in `.cargo/config.toml`, so that board crates of one target can share a target
//! directory).

use std::path::PathBuf;
use std::{env, fs};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("memory.x"), include_bytes!("memory.x")).expect("OUT_DIR is writable");
    println!("cargo:rustc-link-search={}", out.display());
    // cortex-m-rt's linker script; sections need not be page-aligned in flash.
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
}
