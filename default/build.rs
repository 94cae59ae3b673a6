//! Generates the default message set (`messages.xml`) into `pprz_default::messages`, and
//! its periodic telemetry schedule (`telemetry.xml`, resolved against that message set)
//! into `pprz_default::periodic`.
//!
//! Both files are the repository's top-level ones, read through the links in this package
//! (`messages.xml -> ../messages.xml`): the build reads nothing outside its package, and
//! `cargo package` copies the files the links point to into the published crate.

use std::path::Path;

fn main() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let dir = Path::new(&manifest);
    let generator = pprz_codegen::Generator::new(dir.join("messages.xml"));
    if let Err(e) = generator.write_to_out_dir("messages.rs") {
        eprintln!("{e}");
        std::process::exit(1);
    }
    // Warnings (none expected) are printed as `cargo:warning=`.
    if let Err(e) = generator
        .telemetry(dir.join("telemetry.xml"))
        .write_telemetry_to_out_dir("periodic.rs")
    {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
