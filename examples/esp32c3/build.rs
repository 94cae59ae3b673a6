//! Links the binaries with esp-hal's `linkall.x` (the ESP32-C3's memory map, the
//! esp-riscv-rt runtime and the ROM functions). The linker argument lives here rather
//! than in `.cargo/config.toml`, so board crates of the same target build with the same
//! flags and can share one target directory.

fn main() {
    println!("cargo:rustc-link-arg-bins=-Tlinkall.x");
    println!("cargo:rerun-if-changed=build.rs");
}
