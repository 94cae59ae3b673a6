//! Puts `memory.x` where the linker finds it (cortex-m-rt's `link.x` includes it) and
//! passes the linker arguments of the binaries: cortex-m-rt's `link.x`, embassy-rp's
//! `link-rp.x` (places the second-stage bootloader in `BOOT2`), and `--nmagic` (no
//! page alignment of the output sections: `FLASH` starts 256 bytes into the flash, after
//! `BOOT2`, not on a page boundary). Here rather than in
//! `.cargo/config.toml`, so that board crates of different chips can share a target
//! directory.

use std::path::PathBuf;
use std::{env, fs};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("memory.x"), include_bytes!("memory.x")).expect("OUT_DIR is writable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tlink-rp.x");
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
}
