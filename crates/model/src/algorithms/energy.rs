//! The mechanical energy of the robot: kinetic plus potential.

use crate::{Data, Model};
use nalgebra::{DVector, Point3};

impl Model {
    /// Kinetic plus potential energy ½ q̇ᵀ M q̇ − Σ mᵢ gᵀ cᵢ for (`q`, `qd`), with M in
    /// `data.m` from [`crba`] (or [`compute_all_terms`]) at the same `q`.
    /// Needs [`forward_kinematics`] at `q`. Potential zero at the world origin.
    ///
    /// [`crba`]: crate::crba
    /// [`compute_all_terms`]: crate::compute_all_terms
    /// [`forward_kinematics`]: crate::forward_kinematics
    pub fn energy(&self, data: &Data, qd: &DVector<f64>) -> f64 {
        let n = self.nq();
        if qd.len() != n || data.nq() != n {
            return f64::NAN;
        }
        let mut kinetic = 0.0;
        for i in 0..n {
            for j in 0..n {
                kinetic += 0.5 * qd[i] * data.m[(i, j)] * qd[j];
            }
        }
        let mut potential = 0.0;
        for (joint, o_m) in self.joints.iter().zip(&data.o_m_i) {
            let c = o_m * Point3::from(joint.inertia.com);
            potential -= joint.inertia.mass * self.gravity.dot(&c.coords);
        }
        kinetic + potential
    }
}
