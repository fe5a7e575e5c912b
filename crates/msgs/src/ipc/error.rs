//! The one error of the transport: what failed (node, prefix, service, port,
//! listing) and why, in plain words.

use thiserror::Error;

/// Failure to set up or use the hcc services, naming the service (or node)
/// and the reason in plain words.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum IpcError {
    /// The node could not be created.
    #[error("ipc node {name:?}: {reason}")]
    Node { name: String, reason: String },
    /// The file prefix is not usable as the start of a file name.
    #[error(
        "ipc file prefix {prefix:?} is invalid: use 1 to 32 characters of [A-Za-z0-9_-] (got {reason})"
    )]
    FilePrefix { prefix: String, reason: String },
    /// A service could not be opened or created.
    #[error("service {service:?}: {reason}")]
    Service { service: String, reason: String },
    /// A port (publisher, subscriber, notifier, listener) could not be created.
    #[error("service {service:?}: cannot create a {port}: {reason}")]
    Port {
        service: String,
        port: &'static str,
        reason: String,
    },
    /// A sample could not be sent.
    #[error("service {service:?}: send failed: {reason}")]
    Send { service: String, reason: String },
    /// A subscriber's queue could not be read.
    #[error("service {service:?}: receive failed: {reason}")]
    Receive { service: String, reason: String },
    /// Listing the nodes (for cleanup) failed.
    #[error("cannot list the ipc nodes: {reason}")]
    List { reason: String },
}
