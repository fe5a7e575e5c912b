//! The value shapes of the scenario file that several tables share: a gain
//! (scalar, diagonal or full matrix) and a per-joint quantity. Their own
//! module, below the tables and the schema that hold them.

use serde::Deserialize;

/// A task-space gain (stiffness or damping): a scalar (times identity), the
/// diagonal, or the full symmetric matrix (rows).
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum GainValue {
    Scalar(f64),
    Diagonal(Vec<f64>),
    Matrix(Vec<Vec<f64>>),
}

/// A per-joint quantity: one value for every joint, or one per joint.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum PerJoint {
    Scalar(f64),
    Vector(Vec<f64>),
}
