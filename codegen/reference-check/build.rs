//! Generates the full PPRZLINK reference message set (all classes), if present.
//!
//! The reference data is located by `pprz_test_support::reference` (`PPRZLINK_DIR`, or a
//! default location next to the workspace). Without it, the crate builds empty and its
//! tests print why they are skipped; with `PPRZ_REQUIRE_REFERENCE` set (CI), missing data
//! fails the build.

use pprz_test_support::reference;

fn main() {
    println!("cargo:rustc-check-cfg=cfg(pprz_reference)");
    println!("cargo:rerun-if-env-changed={}", reference::DIR_VAR);
    println!("cargo:rerun-if-env-changed={}", reference::REQUIRE_VAR);
    let dir = match reference::locate("pprz-reference-check") {
        Ok(Some(dir)) => dir,
        Ok(None) => {
            println!(
                "cargo:warning=PPRZLINK reference data not found in {}: reference tests are skipped",
                reference::dir().display()
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
