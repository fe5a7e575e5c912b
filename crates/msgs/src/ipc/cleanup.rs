//! Clean-up of what crashed processes leave behind, and the list of the files
//! a prefix still has.

use std::path::PathBuf;

use iceoryx2::prelude::*;

use super::error::IpcError;
use super::node::{Ipc, config};

/// Directory of POSIX shared memory on Linux.
const SHM_DIR: &str = "/dev/shm";

/// What [`cleanup_dead_nodes`] found and did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CleanupReport {
    /// Nodes alive (running processes).
    pub alive: usize,
    /// Nodes whose process is gone.
    pub dead: usize,
    /// Dead nodes whose resources were removed.
    pub removed: usize,
    /// Dead nodes whose resources could not be removed.
    pub failed: usize,
    /// Nodes that could not be inspected (other user, other version, being created).
    pub inaccessible: usize,
}

/// Lists the nodes under `file_prefix` and removes the resources (shared
/// memory, service registrations, ports) that crashed processes left behind.
pub fn cleanup_dead_nodes(file_prefix: Option<&str>) -> Result<CleanupReport, IpcError> {
    let config = config(file_prefix)?;
    let mut report = CleanupReport::default();
    Node::<Ipc>::list(&config, |state| {
        match state {
            NodeState::Alive(_) => report.alive += 1,
            NodeState::Dead(view) => {
                report.dead += 1;
                match view.try_remove_stale_resources() {
                    Ok(()) => report.removed += 1,
                    Err(_) => report.failed += 1,
                }
            }
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => report.inaccessible += 1,
        }
        CallbackProgression::Continue
    })
    .map_err(|e| IpcError::List {
        reason: format!("{e:?}"),
    })?;
    Ok(report)
}

/// A file left by iceoryx2 under a prefix, see [`leftover_files`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LeftoverFile {
    /// The file.
    pub path: PathBuf,
    /// Whether it is the per-prefix global management segment, which iceoryx2
    /// keeps by design after every process has exited.
    pub global_mgmt: bool,
}

/// All files of `file_prefix` in the shared-memory directory and, recursively,
/// in iceoryx2's root directory. After every peer has exited, only the
/// `global_mgmt` segment should remain; a test can then delete it.
pub fn leftover_files(file_prefix: &str) -> Result<Vec<LeftoverFile>, IpcError> {
    let config = config(Some(file_prefix))?;
    let root =
        PathBuf::from(String::from_utf8_lossy(config.global.root_path().as_bytes()).as_ref());
    let mut found = Vec::new();
    collect(&PathBuf::from(SHM_DIR), file_prefix, false, &mut found);
    collect(&root, file_prefix, true, &mut found);
    Ok(found
        .into_iter()
        .map(|path| LeftoverFile {
            global_mgmt: path
                .file_name()
                .map(|n| n.to_string_lossy().ends_with("global_mgmt"))
                .unwrap_or(false),
            path,
        })
        .collect())
}

fn collect(dir: &std::path::Path, prefix: &str, recurse: bool, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name();
        let matches = name.to_string_lossy().starts_with(prefix);
        let is_dir = entry.file_type().map(|t| t.is_dir()).unwrap_or(false);
        if matches {
            out.push(path.clone());
        }
        if recurse && is_dir {
            collect(&path, prefix, true, out);
        }
    }
}
