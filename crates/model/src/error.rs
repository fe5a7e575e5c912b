//! Errors of model loading and of the algorithms.

use crate::linalg::LinalgError;

/// What went wrong, naming the file and the URDF element where there is one.
///
/// `file` is the path of the URDF file, or `<urdf string>` for
/// [`crate::Model::from_urdf_str`].
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The URDF file could not be read.
    #[error("{file}: cannot read URDF file")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    /// The XML is malformed or does not follow the URDF schema.
    #[error("{file}: invalid URDF: {message}")]
    Parse { file: String, message: String },
    /// A requested root/tip link (or a link a joint refers to) does not exist.
    #[error("{file}: {what} link '{link}' does not exist")]
    UnknownLink {
        file: String,
        /// "root", "tip", or "parent of joint 'x'" / "child of joint 'x'".
        what: String,
        link: String,
    },
    /// The tip link is not a descendant of the root link (or equals it).
    #[error("{file}: tip link '{tip}' is not below root link '{root}'")]
    TipNotBelowRoot {
        file: String,
        root: String,
        tip: String,
    },
    /// The links and joints do not form a tree (several parents, a cycle,
    /// duplicate names, no or several root links).
    #[error("{file}: links and joints do not form a tree: {element}: {reason}")]
    NotATree {
        file: String,
        element: String,
        reason: String,
    },
    /// Physically impossible or non-finite inertial data of a link.
    #[error("{file}: link '{link}': invalid inertial: {reason}")]
    InvalidInertial {
        file: String,
        link: String,
        reason: String,
    },
    /// A joint type this crate cannot model on the chain (floating, planar, spherical).
    #[error(
        "{file}: joint '{joint}': unsupported joint type '{kind}' on the chain from root to tip"
    )]
    UnsupportedJoint {
        file: String,
        joint: String,
        kind: String,
    },
    /// A movable joint with a zero (or non-finite) axis.
    #[error("{file}: joint '{joint}': axis must be a finite non-zero vector")]
    ZeroAxis { file: String, joint: String },
    /// Other invalid joint data (non-finite origin, lower limit above upper limit, ...).
    #[error("{file}: joint '{joint}': {reason}")]
    InvalidJoint {
        file: String,
        joint: String,
        reason: String,
    },
    /// The chain from root to tip has no movable joint.
    #[error("{file}: the chain from '{root}' to '{tip}' has no movable joint")]
    NoMovableJoint {
        file: String,
        root: String,
        tip: String,
    },
    /// The gravity vector is not finite.
    #[error("gravity must be finite, got {0:?}")]
    InvalidGravity([f64; 3]),
    /// A state vector or output buffer has the wrong size.
    #[error("{what} has length {got}, expected {expected}")]
    Dimension {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// A dense linear-algebra step failed (e.g. M not positive definite).
    #[error("linear algebra: {0}")]
    Linalg(#[from] LinalgError),
}
