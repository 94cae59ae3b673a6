//! A scratch crate outside the workspace that includes generated code, depending on the
//! runtime crate by path, checked by `cargo` as a user's crate would be.

use std::path::{Path, PathBuf};
use std::process::Command;

/// A crate under the test's temporary directory.
pub struct ScratchCrate {
    dir: PathBuf,
}

impl ScratchCrate {
    /// Crate `name` depending on `pprz-messages`, its sources still to write; a binary
    /// crate if `src/main.rs` is written, else a library.
    pub fn new(name: &str) -> Self {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
        std::fs::create_dir_all(dir.join("src")).unwrap();
        let runtime = Path::new(env!("CARGO_MANIFEST_DIR")).join("../messages");
        std::fs::write(
            dir.join("Cargo.toml"),
            format!(
                "[package]\nname = \"{name}\"\nversion = \"0.0.0\"\nedition = \"2024\"\npublish = false\n\n\
                 [dependencies]\npprz-messages = {{ path = {:?} }}\n\n[workspace]\n",
                runtime.display().to_string()
            ),
        )
        .unwrap();
        // The workspace's lock file: the same dependency versions, nothing to fetch.
        let lock = Path::new(env!("CARGO_MANIFEST_DIR")).join("../Cargo.lock");
        if lock.is_file() {
            std::fs::copy(lock, dir.join("Cargo.lock")).unwrap();
        }
        Self { dir }
    }

    /// Writes `text` to `path` (relative to the crate's `src/`).
    pub fn write(&self, path: &str, text: &str) -> &Self {
        std::fs::write(self.dir.join("src").join(path), text).unwrap();
        self
    }

    /// `cargo check` of the crate, offline, without the flags of the enclosing build;
    /// the compiler's messages if it fails.
    pub fn check(&self) -> Result<(), String> {
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let out = Command::new(cargo)
            .args(["check", "--offline", "--quiet", "--manifest-path"])
            .arg(self.dir.join("Cargo.toml"))
            .arg("--target-dir")
            .arg(self.dir.join("target"))
            .env_remove("CARGO_TARGET_DIR")
            .env_remove("RUSTFLAGS")
            .env_remove("CARGO_ENCODED_RUSTFLAGS")
            .output()
            .expect("cargo runs");
        if out.status.success() {
            Ok(())
        } else {
            Err(String::from_utf8_lossy(&out.stderr).into_owned())
        }
    }
}
