//! What the tests of the transport share: a file prefix of their own, and the
//! clean-up of the one file iceoryx2 keeps by design.

use super::cleanup::{LeftoverFile, leftover_files};

pub(super) fn unique_prefix(tag: &str) -> String {
    use std::sync::atomic::{AtomicU32, Ordering};
    static K: AtomicU32 = AtomicU32::new(0);
    format!(
        "hcct{tag}{}x{}_",
        std::process::id(),
        K.fetch_add(1, Ordering::Relaxed)
    )
}

pub(super) fn remove_global_mgmt(prefix: &str) -> Vec<LeftoverFile> {
    let files = leftover_files(prefix).unwrap();
    let (mgmt, rest): (Vec<_>, Vec<_>) = files.into_iter().partition(|f| f.global_mgmt);
    for f in mgmt {
        let _ = std::fs::remove_file(&f.path);
    }
    rest
}
