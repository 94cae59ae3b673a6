//! Writes a new key set for the secure link: fresh Ed25519 seeds for the ground and the
//! aircraft from the operating system's RNG, and their public keys.
//!
//! ```text
//! cargo run -p pprz-secure --example keygen -- my.keys      # the whole set
//! cargo run -p pprz-secure --example keygen -- --split my   # my.aircraft.keys, my.ground.keys
//! cargo run -p pprz-secure --example keygen                 # the whole set on stdout
//! ```
//!
//! The whole set holds both private keys. With `--split`, each end gets only what it
//! needs: the aircraft's file has no ground private key, the ground's no aircraft
//! private key. Files are created new (never overwritten), readable by their owner only.
//! Never commit them.

use std::fs::OpenOptions;
use std::io::Write;
use std::process::ExitCode;

use pprz_secure::rand_core::{OsRng, TryRngCore};
use pprz_secure::{KeyFile, KeyName};

fn text(keys: &KeyFile) -> String {
    let mut s = String::new();
    keys.write_to(&mut s)
        .expect("writing to a String cannot fail");
    s
}

fn create(path: &str, contents: &str) -> std::io::Result<()> {
    let mut options = OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o600);
    options.open(path)?.write_all(contents.as_bytes())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let keys = KeyFile::generate(&mut OsRng.unwrap_err());
    let result = match args.as_slice() {
        [] => {
            print!("{}", text(&keys));
            Ok(())
        }
        [flag, prefix] if flag == "--split" => {
            let aircraft = KeyFile::parse(&text(&keys))
                .expect("a generated file parses")
                .without(KeyName::GcsPrivate);
            let ground = keys.without(KeyName::UavPrivate);
            create(&format!("{prefix}.aircraft.keys"), &text(&aircraft))
                .and_then(|()| create(&format!("{prefix}.ground.keys"), &text(&ground)))
        }
        [path] if !path.starts_with('-') => create(path, &text(&keys)),
        _ => {
            eprintln!("usage: keygen [FILE | --split PREFIX]");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("keygen: {e}");
            ExitCode::FAILURE
        }
    }
}
