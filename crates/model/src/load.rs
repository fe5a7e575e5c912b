//! A load held rigidly at the tip frame (a gripped part, a tool, a camera):
//! its mass, centre of mass and rotational inertia, checked as a URDF link's
//! inertial is, and lumped into the inertia of the body that carries the tip
//! frame (the parallel-axis theorem), so that every algorithm — M, C, g, the
//! Jacobians' dynamics — carries it without another change. [`set_load`]
//! replaces the load in place, allocation-free, as often as a run needs.

use nalgebra::{Matrix3, Vector3};

use crate::{Model, SpatialInertia};

/// A load at the tip frame: mass (kg), centre of mass in the tip frame (m),
/// rotational inertia about the centre of mass in the tip frame's axes
/// (kg·m²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Load {
    pub mass: f64,
    pub com: Vector3<f64>,
    pub inertia: Matrix3<f64>,
}

impl Load {
    /// No load.
    pub fn none() -> Load {
        Load {
            mass: 0.0,
            com: Vector3::zeros(),
            inertia: Matrix3::zeros(),
        }
    }

    /// A point mass `mass` at `com`.
    pub fn point(mass: f64, com: [f64; 3]) -> Load {
        Load {
            mass,
            com: Vector3::from(com),
            inertia: Matrix3::zeros(),
        }
    }

    /// Whether it is a physical load the robot may carry: finite, mass from
    /// 0 to `payload_limit` kg, the inertia symmetric, positive semidefinite,
    /// its principal moments each at most the sum of the other two.
    /// Allocation-free.
    pub fn check(&self, payload_limit: f64) -> Result<(), LoadError> {
        let values = self.inertia.iter().chain(self.com.iter());
        if !self.mass.is_finite() || !values.clone().all(|v| v.is_finite()) {
            return Err(LoadError::NonFinite);
        }
        if self.mass < 0.0 {
            return Err(LoadError::NegativeMass(self.mass));
        }
        if self.mass > payload_limit {
            return Err(LoadError::AbovePayload {
                mass: self.mass,
                limit: payload_limit,
            });
        }
        let i = &self.inertia;
        let scale = i.iter().fold(0.0_f64, |a, b| a.max(b.abs()));
        let asymmetric = (0..3)
            .flat_map(|r| (0..3).map(move |c| (r, c)))
            .any(|(r, c)| (i[(r, c)] - i[(c, r)]).abs() > 1e-9 * scale.max(1e-12));
        if asymmetric {
            return Err(LoadError::NotSymmetric);
        }
        check_rotational_inertia(i).map_err(LoadError::Inertia)
    }
}

/// Why a load is not one the robot may carry.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum LoadError {
    #[error("a value is not finite")]
    NonFinite,
    #[error("negative mass {0} kg")]
    NegativeMass(f64),
    #[error("mass {mass} kg above the robot's payload limit of {limit} kg")]
    AbovePayload { mass: f64, limit: f64 },
    #[error("the inertia is not symmetric")]
    NotSymmetric,
    #[error("{0}")]
    Inertia(InertiaError),
}

/// Why a rotational inertia is not a physical one (principal moments).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum InertiaError {
    #[error(
        "the inertia is not positive semidefinite (principal moments {:.6e}, {:.6e}, {:.6e})",
        .0[0], .0[1], .0[2]
    )]
    NotPositiveSemidefinite([f64; 3]),
    #[error(
        "principal moments {:.6e}, {:.6e}, {:.6e} violate the triangle inequality",
        .0[0], .0[1], .0[2]
    )]
    Triangle([f64; 3]),
}

/// Whether the symmetric `ic` is a physically possible rotational inertia:
/// positive semidefinite, each principal moment at most the sum of the other
/// two (to 1e-9 of the largest). Allocation-free.
pub fn check_rotational_inertia(ic: &Matrix3<f64>) -> Result<(), InertiaError> {
    let eig = ic.symmetric_eigenvalues();
    let moments = [eig[0], eig[1], eig[2]];
    let scale = moments.iter().fold(0.0_f64, |a, &b| a.max(b.abs()));
    let tol = 1e-9 * scale.max(1e-12);
    if moments.iter().any(|&e| e < -tol) {
        return Err(InertiaError::NotPositiveSemidefinite(moments));
    }
    for k in 0..3 {
        if moments[k] > moments[(k + 1) % 3] + moments[(k + 2) % 3] + tol {
            return Err(InertiaError::Triangle(moments));
        }
    }
    Ok(())
}

/// The body that carries the tip frame (`None`: the tip is the root link).
pub fn tip_body(model: &Model) -> Option<usize> {
    model.frames[model.tip_frame()].body
}

/// The tip frame carries `load` from now on (replacing the one it carried):
/// the inertia of the tip's body is its inertia without a load
/// ([`Model::unloaded_tip_body`]) with the load's added at its place in the
/// body (the parallel-axis theorem). Allocation-free. A tip on the root link
/// carries nothing that moves: only [`Model::load`] is set.
pub fn set_load(model: &mut Model, load: &Load) {
    model.load = *load;
    let Some(body) = tip_body(model) else {
        return;
    };
    let placement = model.frames[model.tip_frame()].placement;
    let r = placement.rotation.to_rotation_matrix();
    let com = placement * nalgebra::Point3::from(load.com);
    let inertia = r.matrix() * load.inertia * r.matrix().transpose();
    model.joints[body].inertia = combined(
        &model.unloaded_tip_body,
        &SpatialInertia {
            mass: load.mass,
            com: com.coords,
            inertia,
        },
    );
}

/// Two rigidly joined bodies' inertia (both in the same frame): the mass,
/// the common centre of mass and the inertia about it.
pub fn combined(a: &SpatialInertia, b: &SpatialInertia) -> SpatialInertia {
    let mass = a.mass + b.mass;
    if b.mass == 0.0 && b.inertia == Matrix3::zeros() || mass <= 0.0 {
        // Nothing added: the body as it was, bit for bit.
        return *a;
    }
    let com = (a.com * a.mass + b.com * b.mass) / mass;
    let shifted = |s: &SpatialInertia| {
        let d = s.com - com;
        s.inertia + s.mass * (d.norm_squared() * Matrix3::identity() - d * d.transpose())
    };
    let inertia = shifted(a) + shifted(b);
    SpatialInertia {
        mass,
        com,
        inertia: 0.5 * (inertia + inertia.transpose()),
    }
}

/// The gravity torque of the model's load alone, −J_cᵀ m g₀ (J_c the
/// Jacobian of its centre of mass c: the tip frame's [`frame_jacobian`]
/// shifted by ω × r, r = R_tip c; g₀ = [`Model::gravity`]), at the state of
/// the last kinematics pass, into `out` (length n). `jacobian` is the 6×n
/// workspace of the tip's Jacobian. What a controller adds when the driver
/// compensates the arm's gravity but not the load's. Zero without a load or
/// with the tip on the root link. Allocation-free.
///
/// [`frame_jacobian`]: crate::frame_jacobian
pub fn load_gravity(
    model: &Model,
    data: &crate::Data,
    jacobian: &mut nalgebra::DMatrix<f64>,
    out: &mut nalgebra::DVector<f64>,
) {
    out.fill(0.0);
    let load = &model.load;
    if load.mass == 0.0 || tip_body(model).is_none() {
        return;
    }
    let tip = model.tip_frame();
    crate::frame_jacobian(model, data, tip, jacobian);
    let r = crate::frame_placement(model, data, tip).rotation * load.com;
    // v_c = v_tip + ω × r, so J_cᵀ m g₀ = m (J_vᵀ g₀ + J_ωᵀ (r × g₀)).
    let f = load.mass * model.gravity;
    let moment = r.cross(&f);
    for (j, o) in out.iter_mut().enumerate() {
        let col = jacobian.column(j);
        let lin = col[0] * f.x + col[1] * f.y + col[2] * f.z;
        let ang = col[3] * moment.x + col[4] * moment.y + col[5] * moment.z;
        *o = -(lin + ang);
    }
}
