//! Forward dynamics (RBDA Ch. 6: M by the CRBA, C q̇ + g by the RNEA, then a
//! Cholesky solve) and every term of the joint-space dynamics in one pass.

use super::coriolis::coriolis_pass;
use super::crba::crba_pass;
use super::data::dims_ok;
use super::kinematics::{fill_nan_kinematics, kinematics};
use super::rnea::{gravity_from_composite, rnea_pass};
use crate::linalg::{cholesky_in_place, cholesky_solve_in_place};
use crate::{Data, Model, ModelError};
use nalgebra::DVector;

/// Forward dynamics q̈ = M⁻¹(τ − C q̇ − g) into `data.qdd` (the paper's eq. (1) with τ_ext = 0,
/// RBDA Ch. 6: M by CRBA,
/// C q̇ + g by RNEA, then an in-place Cholesky solve). Also leaves M in `data.m`,
/// C q̇ + g in `data.nle`, the Cholesky factor in `data.m_chol`, placements and
/// velocities. Errors on wrong vector lengths or an M that is not positive definite.
pub fn forward_dynamics(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<(), ModelError> {
    model.check_state(q, Some(qd), Some(tau))?;
    if data.nq() != model.nq() {
        return Err(ModelError::Dimension {
            what: "data (workspace built for another model)",
            expected: model.nq(),
            got: data.nq(),
        });
    }
    kinematics(model, data, q, Some(qd));
    crba_pass(model, data);
    {
        let Data {
            scratch, v, nle, ..
        } = data;
        rnea_pass(model, scratch, v, None, true, nle);
    }
    data.m_chol.copy_from(&data.m);
    cholesky_in_place(&mut data.m_chol)?;
    data.qdd.copy_from(tau);
    data.qdd -= &data.nle;
    cholesky_solve_in_place(&data.m_chol, &mut data.qdd)?;
    Ok(())
}

/// Everything a controller needs in one pass: placements and velocities, M, C, g and
/// C q̇ + g for (`q`, `qd`) (into `data.m`, `data.c`, `data.g`, `data.nle`). Afterwards
/// the frame functions ([`frame_placement`], [`frame_jacobian`],
/// [`frame_jacobian_time_variation`],
/// [`frame_classical_acceleration`]) can be used.
///
/// [`frame_placement`]: crate::frame_placement
/// [`frame_jacobian`]: crate::frame_jacobian
/// [`frame_jacobian_time_variation`]: crate::frame_jacobian_time_variation
/// [`frame_classical_acceleration`]: crate::frame_classical_acceleration
pub fn compute_all_terms(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    if !dims_ok(model, data, &[q, qd]) {
        fill_nan_kinematics(data);
        for m in [&mut data.m, &mut data.c] {
            m.fill(f64::NAN);
        }
        data.g.fill(f64::NAN);
        data.nle.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, Some(qd));
    crba_pass(model, data);
    coriolis_pass(model, data);
    gravity_from_composite(model, data);
    let n = model.nq();
    for k in 0..n {
        let mut s = data.g[k];
        for j in 0..n {
            s += data.c[(k, j)] * qd[j];
        }
        data.nle[k] = s;
    }
}
