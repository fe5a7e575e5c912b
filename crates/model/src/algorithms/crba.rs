//! The composite rigid-body algorithm (RBDA Table 6.2): the joint-space inertia matrix M.

use super::data::dims_ok;
use super::kinematics::kinematics;
use super::spatial::dot6;
use crate::{Data, Model};
use nalgebra::DVector;

/// Composite rigid-body algorithm (RBDA Table 6.2): joint-space inertia M into `data.m`.
/// Also runs [`forward_kinematics`] (velocities zero).
///
/// [`forward_kinematics`]: crate::forward_kinematics
pub fn crba(model: &Model, data: &mut Data, q: &DVector<f64>) {
    if !dims_ok(model, data, &[q]) {
        data.m.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, None);
    crba_pass(model, data);
}

/// Composite inertias and M (CRBA, RBDA Table 6.2, world-frame form) after [`kinematics`].
pub(super) fn crba_pass(model: &Model, data: &mut Data) {
    let n = model.nq();
    let sc = &mut data.scratch;
    for i in (0..n).rev() {
        sc.ic[i] = sc.inertia[i];
        if i + 1 < n {
            let next = sc.ic[i + 1];
            sc.ic[i].add(&next);
        }
        let f = sc.ic[i].mul(&sc.s[i]);
        sc.ics[i] = f;
        for j in 0..=i {
            let mij = dot6(&sc.s[j], &f);
            data.m[(i, j)] = mij;
            data.m[(j, i)] = mij;
        }
    }
}
