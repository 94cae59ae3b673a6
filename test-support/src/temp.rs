//! Files of a test's own in the system's temporary directory.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Files made so far in this process: each gets a name of its own (tests run at the
/// same time).
static MADE: AtomicUsize = AtomicUsize::new(0);

/// A file written for a test, removed when dropped.
#[derive(Debug)]
pub struct TempFile(PathBuf);

impl TempFile {
    /// Writes `content` to a new file whose name ends with `name`, in a directory of
    /// this process under the system's temporary directory.
    ///
    /// # Panics
    /// If the file cannot be written (a test set-up failure).
    pub fn new(name: &str, content: &str) -> Self {
        let name = format!("{}-{name}", MADE.fetch_add(1, Ordering::Relaxed));
        let dir = std::env::temp_dir().join(format!("pprz-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temporary directory");
        let path = dir.join(name);
        std::fs::write(&path, content).expect("temporary file");
        Self(path)
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.0
    }

    /// The file's path as a command-line argument.
    ///
    /// # Panics
    /// If the temporary directory's path is not UTF-8.
    pub fn arg(&self) -> &str {
        self.0.to_str().expect("a UTF-8 temporary path")
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}
