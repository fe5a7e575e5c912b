//! The recursive Newton–Euler algorithm (RBDA Table 5.1): inverse dynamics, the
//! gravity torques g(q) and the nonlinear effects C q̇ + g.

use super::data::{Scratch, dims_ok};
use super::kinematics::kinematics;
use super::spatial::{dot6, force_cross, join};
use crate::{Data, Model};
use nalgebra::{DVector, Vector3, Vector6};

/// Recursive Newton–Euler inverse dynamics (RBDA Table 5.1): τ = M q̈ + C q̇ + g into
/// `data.tau`. Also runs [`forward_kinematics_vel`].
///
/// [`forward_kinematics_vel`]: crate::forward_kinematics_vel
pub fn rnea(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    qdd: &DVector<f64>,
) {
    if !dims_ok(model, data, &[q, qd, qdd]) {
        data.tau.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, Some(qd));
    let Data {
        scratch, v, tau, ..
    } = data;
    rnea_pass(model, scratch, v, Some(qdd), true, tau);
}

/// Gravity torques g(q) into `data.g` (RNEA with q̇ = q̈ = 0). Also runs
/// [`forward_kinematics`].
///
/// [`forward_kinematics`]: crate::forward_kinematics
pub fn gravity(model: &Model, data: &mut Data, q: &DVector<f64>) {
    if !dims_ok(model, data, &[q]) {
        data.g.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, None);
    let Data { scratch, v, g, .. } = data;
    rnea_pass(model, scratch, v, None, true, g);
}

/// Nonlinear effects C q̇ + g into `data.nle` (RNEA with q̈ = 0). Also runs
/// [`forward_kinematics_vel`].
///
/// [`forward_kinematics_vel`]: crate::forward_kinematics_vel
pub fn nle(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    if !dims_ok(model, data, &[q, qd]) {
        data.nle.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, Some(qd));
    let Data {
        scratch, v, nle, ..
    } = data;
    rnea_pass(model, scratch, v, None, true, nle);
}

/// Recursive Newton–Euler (RBDA Table 5.1, world-frame form) after [`kinematics`]:
/// `out = M q̈ + C q̇ + g` with the velocities of the last kinematics pass,
/// q̈ = 0 when `qdd` is `None`, and gravity when `with_gravity`.
pub(super) fn rnea_pass(
    model: &Model,
    sc: &mut Scratch,
    v: &[Vector6<f64>],
    qdd: Option<&DVector<f64>>,
    with_gravity: bool,
    out: &mut DVector<f64>,
) {
    let n = model.nq();
    // Gravity enters as a fictitious base acceleration −g (RBDA Ch. 5).
    let mut a = if with_gravity {
        join(-model.gravity, Vector3::zeros())
    } else {
        Vector6::zeros()
    };
    for i in 0..n {
        // a_i = a_{i−1} + Ṡ_i q̇_i + S_i q̈_i; the Ṡ q̇ terms are summed in `abias`.
        let prev_bias = if i > 0 {
            sc.abias[i - 1]
        } else {
            Vector6::zeros()
        };
        a += sc.abias[i] - prev_bias;
        if let Some(qdd) = qdd {
            a += sc.s[i] * qdd[i];
        }
        sc.a[i] = a;
        let h = sc.inertia[i].mul(&v[i]);
        sc.f[i] = sc.inertia[i].mul(&a) + force_cross(&v[i], &h);
    }
    for i in (0..n).rev() {
        out[i] = dot6(&sc.s[i], &sc.f[i]);
        if i > 0 {
            let fi = sc.f[i];
            sc.f[i - 1] += fi;
        }
    }
}

/// Gravity torques from the composite inertias: `g_k = S_kᵀ Ic_k (−g, 0)`
/// (RNEA with q̇ = q̈ = 0). Needs [`crba_pass`].
///
/// [`crba_pass`]: super::crba::crba_pass
pub(super) fn gravity_from_composite(model: &Model, data: &mut Data) {
    let a0 = join(-model.gravity, Vector3::zeros());
    let sc = &data.scratch;
    for k in 0..model.nq() {
        data.g[k] = dot6(&sc.s[k], &sc.ic[k].mul(&a0));
    }
}
