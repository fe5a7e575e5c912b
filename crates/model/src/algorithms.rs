//! The algorithms. Each is a free function over an immutable [`Model`] and a
//! preallocated [`Data`]; none allocates.

use crate::{Data, FrameId, Model, ModelError};
use nalgebra::{DMatrix, DVector, Isometry3, Vector6};

/// Per-body scratch buffers used by the recursive algorithms (sized in `Data::new`).
#[derive(Clone, Debug, Default)]
pub struct Scratch {}

impl Data {
    /// Allocates every buffer the algorithms need for `model`.
    pub fn new(model: &Model) -> Data {
        let _ = model;
        todo!()
    }
}

/// Forward kinematics: world placement of every body for configuration `q`.
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let _ = (model, data, q);
    todo!()
}

/// Forward kinematics with velocities: placements and body velocities for (`q`, `qd`).
pub fn forward_kinematics_vel(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    let _ = (model, data, q, qd);
    todo!()
}

/// World placement of a frame. Requires [`forward_kinematics`] first.
pub fn frame_placement(model: &Model, data: &Data, frame: FrameId) -> Isometry3<f64> {
    let _ = (model, data, frame);
    todo!()
}

/// 6×n frame Jacobian (rows linear then angular, world axes, reference point at the frame
/// origin) into `out`. Requires [`forward_kinematics`] first.
pub fn frame_jacobian(model: &Model, data: &Data, frame: FrameId, out: &mut DMatrix<f64>) {
    let _ = (model, data, frame, out);
    todo!()
}

/// Time derivative J̇ of [`frame_jacobian`] (same convention) into `out`.
/// Requires [`forward_kinematics_vel`] first.
pub fn frame_jacobian_time_variation(
    model: &Model,
    data: &Data,
    frame: FrameId,
    out: &mut DMatrix<f64>,
) {
    let _ = (model, data, frame, out);
    todo!()
}

/// J̇ q̇: classical (not spatial) acceleration of the frame origin for q̈ = 0, linear then
/// angular, world axes. Requires [`forward_kinematics_vel`] first.
pub fn frame_classical_acceleration(model: &Model, data: &Data, frame: FrameId) -> Vector6<f64> {
    let _ = (model, data, frame);
    todo!()
}

/// Composite rigid-body algorithm: joint-space inertia M into `data.m`.
pub fn crba(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let _ = (model, data, q);
    todo!()
}

/// Coriolis matrix C(q, q̇) with Ṁ = C + Cᵀ into `data.c`.
pub fn coriolis_matrix(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    let _ = (model, data, q, qd);
    todo!()
}

/// Gravity torques g(q) into `data.g`.
pub fn gravity(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let _ = (model, data, q);
    todo!()
}

/// Nonlinear effects C q̇ + g into `data.nle` (RNEA with q̈ = 0).
pub fn nle(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    let _ = (model, data, q, qd);
    todo!()
}

/// Recursive Newton–Euler inverse dynamics: τ = M q̈ + C q̇ + g into `data.tau`.
pub fn rnea(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    qdd: &DVector<f64>,
) {
    let _ = (model, data, q, qd, qdd);
    todo!()
}

/// Forward dynamics q̈ = M⁻¹(τ − C q̇ − g) into `data.qdd`.
pub fn forward_dynamics(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<(), ModelError> {
    let _ = (model, data, q, qd, tau);
    todo!()
}

/// Everything a controller needs in one pass: placements and velocities, M, C, g and
/// C q̇ + g for (`q`, `qd`).
pub fn compute_all_terms(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    let _ = (model, data, q, qd);
    todo!()
}
