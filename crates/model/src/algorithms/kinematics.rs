//! Forward kinematics, the forward pass that every recursion starts with: placements,
//! motion subspaces, world inertias, velocities and bias accelerations of the bodies,
//! and the world placement of a frame.

use super::data::dims_ok;
use super::spatial::{BodyInertia, axis_angle, join, motion_cross, mul3v, mul33};
use crate::{Data, FrameId, JointKind, Model};
use nalgebra::{
    DVector, Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6,
};

/// Forward kinematics: world placement of every body for configuration `q`
/// (into `data.o_m_i`; velocities set to zero).
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &DVector<f64>) {
    if !dims_ok(model, data, &[q]) {
        fill_nan_kinematics(data);
        return;
    }
    kinematics(model, data, q, None);
}

/// Forward kinematics with velocities: placements and body velocities for (`q`, `qd`).
/// `data.v[i]` is the world-frame spatial velocity `(v, ω)` of body i, `v` being the
/// velocity of the body point at the world origin (see the [module documentation]).
///
/// [module documentation]: crate::algorithms
pub fn forward_kinematics_vel(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    if !dims_ok(model, data, &[q, qd]) {
        fill_nan_kinematics(data);
        return;
    }
    kinematics(model, data, q, Some(qd));
}

/// World placement of a frame. Requires [`forward_kinematics`] first.
/// An unknown frame id gives a NaN translation.
pub fn frame_placement(model: &Model, data: &Data, frame: FrameId) -> Isometry3<f64> {
    match frame_info(model, data, frame) {
        Some((_, o_m)) => o_m,
        None => nan_placement(),
    }
}

/// Forward pass: placements, motion subspaces and world inertias; with `qd`
/// also velocities, `Ṡ` and bias accelerations (zero without `qd`).
pub(super) fn kinematics(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    qd: Option<&DVector<f64>>,
) {
    let sc = &mut data.scratch;
    // The sines and cosines of the joint angles first: independent calls, which the
    // CPU overlaps here (inside the recursion each would wait on the one before).
    for ((sc_i, joint), &qi) in sc.sin_cos.iter_mut().zip(&model.joints).zip(q.iter()) {
        if joint.kind == JointKind::Revolute {
            *sc_i = qi.sin_cos();
        }
    }
    let mut r_parent = Matrix3::identity();
    let mut p_parent = Vector3::zeros();
    let mut v_parent = Vector6::zeros();
    let mut a_parent = Vector6::zeros();
    for (i, joint) in model.joints.iter().enumerate() {
        // Joint frame before the motion, then the joint motion about/along the axis.
        let r_pre = mul33(&r_parent, &joint.placement_rotation);
        let mut p = p_parent + mul3v(&r_parent, &joint.placement.translation.vector);
        let z = mul3v(&r_pre, &joint.axis);
        let (r, s) = match joint.kind {
            JointKind::Revolute => (
                mul33(&r_pre, &axis_angle(&joint.axis, sc.sin_cos[i])),
                join(p.cross(&z), z),
            ),
            JointKind::Prismatic => {
                p += z * q[i];
                (r_pre, join(z, Vector3::zeros()))
            }
        };
        sc.s[i] = s;
        sc.inertia[i] = BodyInertia::from_body(&joint.inertia, &r, &p);
        match qd {
            Some(qd) => {
                let v = v_parent + s * qd[i];
                let sdot = motion_cross(&v, &s);
                let a = a_parent + sdot * qd[i];
                data.v[i] = v;
                sc.sdot[i] = sdot;
                sc.abias[i] = a;
                v_parent = v;
                a_parent = a;
            }
            None => {
                data.v[i] = Vector6::zeros();
                sc.sdot[i] = Vector6::zeros();
                sc.abias[i] = Vector6::zeros();
            }
        }
        data.o_m_i[i] = Isometry3::from_parts(
            Translation3::from(p),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
        );
        r_parent = r;
        p_parent = p;
    }
}

pub(super) fn fill_nan_kinematics(data: &mut Data) {
    let nan_iso = Isometry3::from_parts(
        Translation3::new(f64::NAN, f64::NAN, f64::NAN),
        UnitQuaternion::identity(),
    );
    data.o_m_i.iter_mut().for_each(|m| *m = nan_iso);
    let nan6 = Vector6::repeat(f64::NAN);
    data.v.iter_mut().for_each(|v| *v = nan6);
    let sc = &mut data.scratch;
    for buf in [&mut sc.s, &mut sc.sdot, &mut sc.abias] {
        buf.iter_mut().for_each(|v| *v = nan6);
    }
}

/// Body index and world placement of a frame; `None` for an unknown frame.
pub(super) fn frame_info(
    model: &Model,
    data: &Data,
    frame: FrameId,
) -> Option<(Option<usize>, Isometry3<f64>)> {
    let f = model.frames.get(frame)?;
    match f.body {
        None => Some((None, f.placement)),
        Some(b) => {
            let o_m = data.o_m_i.get(b)?;
            Some((Some(b), o_m * f.placement))
        }
    }
}

/// The placement of [`frame_placement`] for an unknown frame.
pub(super) fn nan_placement() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(f64::NAN, f64::NAN, f64::NAN),
        UnitQuaternion::identity(),
    )
}
