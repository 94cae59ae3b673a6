//! Generates the full PPRZLINK reference message set (all classes), if present.
//!
//! Without the data (a user's clone has no `../shared`), the crate builds empty and its
//! tests print why they are skipped; with `PPRZ_REQUIRE_REFERENCE` set (CI), missing data
//! fails the build.

use std::path::Path;

fn main() {
    println!("cargo:rustc-check-cfg=cfg(pprz_reference)");
    println!(
        "cargo:rerun-if-env-changed={}",
        pprz_codegen::reference::DIR_VAR
    );
    println!(
        "cargo:rerun-if-env-changed={}",
        pprz_codegen::reference::REQUIRE_VAR
    );
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let default = Path::new(&manifest).join("../../../shared/pprzlink");
    let dir = match pprz_codegen::reference::locate("pprz-reference-check", &default) {
        Ok(Some(dir)) => dir,
        Ok(None) => {
            println!(
                "cargo:warning=PPRZLINK reference data not found in {}: reference tests are skipped",
                pprz_codegen::reference::dir(&default).display()
            );
            return;
        }
        Err(reason) => {
            eprintln!("{reason}");
            std::process::exit(1);
        }
    };
    let messages = dir.join("messages.xml");
    let units = dir.join("units.xml");
    let mut generator = pprz_codegen::Generator::new(&messages);
    if units.is_file() {
        generator = generator.units(&units);
    }
    match generator.write_to_out_dir("reference.rs") {
        Ok(_) => println!("cargo:rustc-cfg=pprz_reference"),
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    }
}
