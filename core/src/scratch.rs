//! Names and checks for files of our own beside the user's: probes of a directory, and
//! fresh private directories ([`PrivateDir`]).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// `prefix-PID-NANOS-N`: a name no earlier run, and no other process, is likely to
/// have used, and no other call in this process (`N` counts them: two threads may read
/// the same nanoseconds).
fn unique_name(prefix: &str) -> String {
    static CALLS: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let n = CALLS.fetch_add(1, Ordering::Relaxed);
    format!("{prefix}-{}-{nanos}-{n}", std::process::id())
}

/// Whether `dir` takes new files: creates a probe of our own there (never an existing
/// file) and removes it.
pub fn probe_writable(dir: &Path) -> std::io::Result<()> {
    let probe = dir.join(unique_name(".relief-probe"));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)?;
    std::fs::remove_file(&probe)
}

/// A directory this process made for itself under the system's temp dir, readable by
/// this user only, and deleted with its contents when dropped: runs do not pile up
/// directories there. Its name (`prefix-PID-NANOS-N`) is one nobody could have
/// prepared (or linked) beforehand, since creating it fails if it exists. Dropped while
/// the thread panics (a failing test's, a crash's), it is kept, for a look at what was
/// in it.
#[derive(Debug)]
pub struct PrivateDir(PathBuf);

impl PrivateDir {
    /// A fresh directory named after `prefix`.
    pub fn new(prefix: &str) -> std::io::Result<PrivateDir> {
        let dir = std::env::temp_dir().join(unique_name(prefix));
        let mut builder = std::fs::DirBuilder::new();
        #[cfg(unix)]
        std::os::unix::fs::DirBuilderExt::mode(&mut builder, 0o700);
        builder.create(&dir)?;
        Ok(PrivateDir(dir))
    }

    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl std::ops::Deref for PrivateDir {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for PrivateDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for PrivateDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            // (Nothing to do about a failure on the way out; the name is unique anyway.)
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}
