//! A scratch directory for the command line's tests (the library's own is not part of its
//! API).

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Scratch directories made by this process so far.
static COUNTER: AtomicUsize = AtomicUsize::new(0);

/// A directory under the system's temporary directory, unique to one test and removed when
/// dropped.
pub struct ScratchDir {
    path: PathBuf,
}

impl ScratchDir {
    /// Creates `gbc-<label>-<pid>-<count>` in the temporary directory.
    pub fn new(label: &str) -> std::io::Result<Self> {
        let count = COUNTER.fetch_add(1, Ordering::Relaxed);
        let name = format!("gbc-cli-{label}-{}-{count}", std::process::id());
        let path = std::env::temp_dir().join(name);
        std::fs::create_dir_all(&path)?;
        Ok(ScratchDir { path })
    }

    /// A path inside the directory.
    pub fn join(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.path);
    }
}
