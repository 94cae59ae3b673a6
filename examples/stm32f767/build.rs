//! Links the binaries with cortex-m-rt's `link.x` (which includes the `memory.x` that
//! embassy-stm32's `memory-x` feature writes for the STM32F767ZI). The linker argument
//! lives here rather than in `.cargo/config.toml`, so board crates of the same target
//! build with the same flags and can share one target directory.

fn main() {
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rerun-if-changed=build.rs");
}
