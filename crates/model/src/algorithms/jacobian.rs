//! Frame Jacobians (world axes at the frame origin, Pinocchio's LOCAL_WORLD_ALIGNED),
//! their time variation and the classical acceleration of a frame origin, from the
//! motion subspaces of the last kinematics pass.

use super::kinematics::{frame_info, nan_placement};
use super::spatial::{ang, join, lin};
use crate::{Data, FrameId, Model};
use nalgebra::{DMatrix, Isometry3, Vector6};

/// 6×n frame Jacobian (rows linear then angular, world axes, reference point at the frame
/// origin) into `out`. Requires [`forward_kinematics`] first.
///
/// Column j ≤ body of the frame: `(S_j,lin + S_j,ang × p, S_j,ang)`, i.e. `z_j × (p − p_j)`
/// over `z_j` for a revolute joint (Pinocchio's LOCAL_WORLD_ALIGNED convention;
/// the task Jacobians `J_i` of the paper's eq. (2)).
/// `out` of the wrong size or an unknown frame: `out` is filled with NaN.
///
/// [`forward_kinematics`]: crate::forward_kinematics
pub fn frame_jacobian(model: &Model, data: &Data, frame: FrameId, out: &mut DMatrix<f64>) {
    let info = frame_info(model, data, frame);
    jacobian_at(model, data, info.as_ref(), out);
}

/// Time derivative J̇ of [`frame_jacobian`] (same convention) into `out`.
/// Requires [`forward_kinematics_vel`] first.
///
/// Column j: `(Ṡ_j,lin + Ṡ_j,ang × p + S_j,ang × ṗ, Ṡ_j,ang)` with `Ṡ_j = v_j × S_j`
/// and `ṗ` the velocity of the frame origin; for a revolute joint this is
/// `[(ω_j × z_j) × (p − p_j) + z_j × (ṗ − ṗ_j); ω_j × z_j]`.
/// `out` of the wrong size or an unknown frame: `out` is filled with NaN.
///
/// [`forward_kinematics_vel`]: crate::forward_kinematics_vel
pub fn frame_jacobian_time_variation(
    model: &Model,
    data: &Data,
    frame: FrameId,
    out: &mut DMatrix<f64>,
) {
    let info = frame_info(model, data, frame);
    jacobian_time_variation_at(model, data, info.as_ref(), out);
}

/// [`frame_jacobian`] into `j` and, when given, [`frame_jacobian_time_variation`] into
/// `jdot` for one frame, its world placement formed once for both; returns that
/// placement ([`frame_placement`], a NaN translation for an unknown frame), so that a
/// caller that also needs it does not form it again. Requires
/// [`forward_kinematics_vel`] first (or [`forward_kinematics`] without `jdot`).
///
/// [`frame_placement`]: crate::frame_placement
/// [`forward_kinematics_vel`]: crate::forward_kinematics_vel
/// [`forward_kinematics`]: crate::forward_kinematics
pub fn frame_jacobians(
    model: &Model,
    data: &Data,
    frame: FrameId,
    j: &mut DMatrix<f64>,
    jdot: Option<&mut DMatrix<f64>>,
) -> Isometry3<f64> {
    let info = frame_info(model, data, frame);
    jacobian_at(model, data, info.as_ref(), j);
    if let Some(jdot) = jdot {
        jacobian_time_variation_at(model, data, info.as_ref(), jdot);
    }
    match info {
        Some((_, o_m)) => o_m,
        None => nan_placement(),
    }
}

/// J̇ q̇: classical (not spatial) acceleration of the frame origin for q̈ = 0, linear then
/// angular, world axes. Requires [`forward_kinematics_vel`] first.
///
/// With the spatial bias acceleration `a = Σ Ṡ_j q̇_j` of the body (RBDA Ch. 2),
/// the classical acceleration of the point p is `(a_lin + a_ang × p + ω × ṗ, a_ang)`.
/// Unknown frame: NaN.
///
/// [`forward_kinematics_vel`]: crate::forward_kinematics_vel
pub fn frame_classical_acceleration(model: &Model, data: &Data, frame: FrameId) -> Vector6<f64> {
    match frame_info(model, data, frame) {
        None => Vector6::repeat(f64::NAN),
        Some((None, _)) => Vector6::zeros(),
        Some((Some(b), o_m)) => {
            let p = o_m.translation.vector;
            let vb = &data.v[b];
            let w = ang(vb);
            let pdot = lin(vb) + w.cross(&p);
            let a = &data.scratch.abias[b];
            join(lin(a) + ang(a).cross(&p) + w.cross(&pdot), ang(a))
        }
    }
}

/// The body of [`frame_jacobian`] for a frame's body and placement from [`frame_info`].
fn jacobian_at(
    model: &Model,
    data: &Data,
    info: Option<&(Option<usize>, Isometry3<f64>)>,
    out: &mut DMatrix<f64>,
) {
    let n = model.nq();
    let (body, o_m) = match info {
        Some(x) if out.nrows() == 6 && out.ncols() == n && data.nq() == n => x,
        _ => {
            out.fill(f64::NAN);
            return;
        }
    };
    // Column-major 6 × n: column j is out[6 j..6 j + 6].
    let out = out.as_mut_slice();
    out.fill(0.0);
    let p = o_m.translation.vector;
    if let Some(b) = *body {
        for (s, col) in data.scratch.s[..=b].iter().zip(out.chunks_exact_mut(6)) {
            let w = ang(s);
            let v = lin(s) + w.cross(&p);
            col[..3].copy_from_slice(v.as_slice());
            col[3..].copy_from_slice(w.as_slice());
        }
    }
}

/// The body of [`frame_jacobian_time_variation`] for a frame's body and placement from
/// [`frame_info`].
fn jacobian_time_variation_at(
    model: &Model,
    data: &Data,
    info: Option<&(Option<usize>, Isometry3<f64>)>,
    out: &mut DMatrix<f64>,
) {
    let n = model.nq();
    let (body, o_m) = match info {
        Some(x) if out.nrows() == 6 && out.ncols() == n && data.nq() == n => x,
        _ => {
            out.fill(f64::NAN);
            return;
        }
    };
    let out = out.as_mut_slice();
    out.fill(0.0);
    let p = o_m.translation.vector;
    if let Some(b) = *body {
        let vb = &data.v[b];
        let pdot = lin(vb) + ang(vb).cross(&p);
        let (s, sdot) = (&data.scratch.s[..=b], &data.scratch.sdot[..=b]);
        for ((s, sd), col) in s.iter().zip(sdot).zip(out.chunks_exact_mut(6)) {
            let wd = ang(sd);
            let v = lin(sd) + wd.cross(&p) + ang(s).cross(&pdot);
            col[..3].copy_from_slice(v.as_slice());
            col[3..].copy_from_slice(wd.as_slice());
        }
    }
}
