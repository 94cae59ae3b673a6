//! Generates the project's default message set (`../messages.xml`) into
//! `pprz_telemetry::messages`, and its periodic telemetry schedule (`../telemetry.xml`,
//! resolved against that message set) into `pprz_telemetry::periodic`.

use std::path::Path;

fn main() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let root = Path::new(&manifest).join("..");
    let generator = pprz_codegen::Generator::new(root.join("messages.xml"));
    if let Err(e) = generator.write_to_out_dir("messages.rs") {
        eprintln!("{e}");
        std::process::exit(1);
    }
    // Warnings (none expected) are printed as `cargo:warning=`.
    if let Err(e) = generator
        .telemetry(root.join("telemetry.xml"))
        .scheduler_crate("crate::scheduler")
        .write_telemetry_to_out_dir("periodic.rs")
    {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
