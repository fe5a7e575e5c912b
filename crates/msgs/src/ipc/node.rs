//! Node set-up: the iceoryx2 configuration with the file prefix and the node
//! every peer opens the services on.

use std::path::PathBuf;

use iceoryx2::node::NodeCreationFailure;
use iceoryx2::prelude::*;

use super::error::IpcError;

/// The iceoryx2 service type of all hcc services (inter-process, shared memory).
pub type Ipc = ipc::Service;
/// A node of the hcc services.
pub type IpcNode = Node<Ipc>;

/// Environment variable that carries the file prefix to child processes
/// (the daemons read it when no `--file-prefix` is given).
pub const FILE_PREFIX_ENV: &str = "HCC_IPC_FILE_PREFIX";

/// An iceoryx2 configuration with `file_prefix` (iceoryx2's default when `None`).
pub fn config(file_prefix: Option<&str>) -> Result<Config, IpcError> {
    let mut config = Config::default();
    if let Some(prefix) = file_prefix {
        let bad = |reason: String| IpcError::FilePrefix {
            prefix: prefix.to_owned(),
            reason,
        };
        if prefix.is_empty() || prefix.len() > 32 {
            return Err(bad(format!("{} characters", prefix.len())));
        }
        if let Some(c) = prefix
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-'))
        {
            return Err(bad(format!("the character {c:?}")));
        }
        config.global.prefix =
            FileName::new(prefix.as_bytes()).map_err(|e| bad(format!("{e:?}")))?;
    }
    Ok(config)
}

/// The file prefix from [`FILE_PREFIX_ENV`], if set and non-empty.
pub fn file_prefix_from_env() -> Option<String> {
    std::env::var(FILE_PREFIX_ENV)
        .ok()
        .filter(|s| !s.is_empty())
}

/// Creates a node named `name` with the given signal handling (use
/// `SignalHandlingMode::Disabled` when the process handles SIGINT/SIGTERM
/// itself, `HandleTerminationRequests` to let `node.wait()` report them) and
/// an optional file prefix ([`config`]).
pub fn create_node(
    name: &str,
    signal_handling: SignalHandlingMode,
    file_prefix: Option<&str>,
) -> Result<IpcNode, IpcError> {
    let config = config(file_prefix)?;
    let node_name = NodeName::new(name).map_err(|e| IpcError::Node {
        name: name.to_owned(),
        reason: format!("not a valid node name ({e:?})"),
    })?;
    NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(signal_handling)
        .config(&config)
        .create::<Ipc>()
        .map_err(|e| IpcError::Node {
            name: name.to_owned(),
            reason: match (e, root_access_problem(&config)) {
                (_, Some(problem)) => problem,
                (NodeCreationFailure::InsufficientPermissions, None) => {
                    "insufficient permissions for the iceoryx2 files (peers must run as the same user)"
                        .to_owned()
                }
                (other, None) => format!("iceoryx2 failure {other:?}"),
            },
        })
}

/// Why this process cannot use iceoryx2's directory, if it cannot: its
/// resources belong to another user (iceoryx2 creates them owner-only).
fn root_access_problem(config: &Config) -> Option<String> {
    use std::os::unix::fs::MetadataExt;
    let root =
        PathBuf::from(String::from_utf8_lossy(config.global.root_path().as_bytes()).as_ref());
    let meta = std::fs::metadata(&root).ok()?;
    let c_path = std::ffi::CString::new(root.as_os_str().as_encoded_bytes()).ok()?;
    // SAFETY: a valid NUL-terminated path; access() only reads it.
    let ok = unsafe { libc::access(c_path.as_ptr(), libc::R_OK | libc::W_OK | libc::X_OK) } == 0;
    if ok {
        return None;
    }
    // SAFETY: geteuid cannot fail.
    let me = unsafe { libc::geteuid() };
    Some(format!(
        "insufficient permissions: iceoryx2's directory {} belongs to uid {} (mode {:o}) and this process runs as uid {me}; all peers of a robot must run as the same user",
        root.display(),
        meta.uid(),
        meta.mode() & 0o7777
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn invalid_prefix_is_named() {
        let e = config(Some("a/b")).unwrap_err();
        assert!(e.to_string().contains("\"a/b\""), "{e}");
        assert!(config(Some("")).is_err());
        assert!(config(Some("ok_prefix-1")).is_ok());
    }
}
