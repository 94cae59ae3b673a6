//! Generates the application's settings table from its `settings.xml` (in this package)
//! into `$OUT_DIR/settings.rs`, which `src/lib.rs` includes as the `settings` module.
//! Cargo reruns this when the file changes; the file's warnings (none expected) are
//! printed as `cargo:warning=`.

use std::path::Path;

fn main() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let xml = Path::new(&manifest).join("settings.xml");
    if let Err(e) =
        pprz_codegen::Generator::for_settings([xml]).write_settings_to_out_dir("settings.rs")
    {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
