//! Helpers shared by the report crate's tests.

use std::path::PathBuf;

/// A fresh output directory for test `name` (removed first if it exists).
pub fn out_dir(name: &str) -> PathBuf {
    let base = option_env!("CARGO_TARGET_TMPDIR")
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir);
    let d = base.join(format!("hcc-report-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}
