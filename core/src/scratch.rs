//! Names and checks for files of our own beside the user's: probes of a directory, and
//! fresh private directories.

use std::path::Path;

/// `prefix-PID-NANOS`: a name no earlier run, and no other process, is likely to have
/// used.
pub fn unique_name(prefix: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!("{prefix}-{}-{nanos}", std::process::id())
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
