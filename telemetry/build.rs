//! Generates the project's default message set (`../messages.xml`) into
//! `pprz_telemetry::messages`.

fn main() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let messages = std::path::Path::new(&manifest).join("../messages.xml");
    if let Err(e) = pprz_codegen::Generator::new(messages).write_to_out_dir("messages.rs") {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
