//! Embeds the aircraft's keys for the `secure` feature (`PPRZ_SECURE_KEYS`, or the
//! published INSECURE test keys with a warning).

include!("../../secure/build-support/aircraft_keys.rs");

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if std::env::var_os("CARGO_FEATURE_SECURE").is_some() {
        embed_aircraft_keys();
    }
}
