//! Generates this firmware's message set from its own `messages.xml` (in this package)
//! into `$OUT_DIR/messages.rs`, as any firmware with its own messages does.

use std::path::Path;

fn main() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let xml = Path::new(&manifest).join("messages.xml");
    if let Err(e) = pprz_codegen::Generator::new(xml).write_to_out_dir("messages.rs") {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
