//! Errors of model loading and of the algorithms.

/// What went wrong, naming the file and the URDF element where there is one.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("{0}")]
    Todo(String),
}
