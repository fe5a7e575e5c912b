//! Where the cycle meets the safety layer (crate::safety): what it hands it
//! (the fade's damper power, the applied torque's acceleration, the
//! hierarchy's power into the storage E) and the torques it adds (the passive
//! fade, τ_safety, the velocity barrier).

use super::Controller;
use crate::spec::Form;
use hcc_linalg::products::gemv;
use nalgebra::{DMatrix, DVector};

impl Controller {
    /// After the initial checks: the spring saturation's task speeds from the
    /// Jacobians at q0 and each level's spring radius; the checks' cycle counts
    /// for nothing. Allocates (construction).
    pub(super) fn init_safety(&mut self) {
        let jacobians: Vec<&DMatrix<f64>> = self.levels.iter().map(|l| &l.j).collect();
        self.safety.set_task_speeds(&jacobians);
        for (i, l) in self.levels.iter().enumerate() {
            self.safety.set_spring_radius(i, &l.stiffness, &l.damping);
        }
        self.reset();
        self.out.safety = crate::safety::SafetyOutput::new(self.n, self.levels.len());
    }

    /// The passive fade of the safety layer (crate::safety): the fade factors of
    /// this cycle may only remove energy; a fade-in is paid from the energy tank.
    pub(super) fn passive_fade(&mut self) {
        // Σ β_i ẋ_iᵀ D_i ẋ_i = Σ β_i ẋ_iᵀ (F_i − ∂V_i/∂x_i) (β of the last cycle).
        // With the energy tanks, the dampers of the levels below the first
        // fill their own tanks (crate::energy_tank), not this one.
        let tanks = self.tanks_on();
        let mut p1 = 0.0;
        for (i, l) in self.levels.iter().enumerate() {
            if i == 0 || !tanks {
                let beta = self.safety.last_fade(i);
                p1 += beta * (l.xdot.dot(&l.f) - l.xdot.dot(&l.grad));
            }
            self.out.potential[i] = l.potential;
        }
        let (fade, pot) = (&mut self.out.fade, &self.out.potential);
        let cond = &self.out.conditioning;
        // The dampers act with the law's share of the torque.
        let share = self.law_share;
        self.safety
            .passive_fade(fade, pot, share * p1, cond, share, &mut self.out.safety);
    }

    /// The acceleration the applied torque ([`Controller::set_applied_torque`])
    /// gives on the model, M⁻¹ (τ_applied − g − C q̇) (g only where the
    /// controller adds it: the robot adds it itself otherwise, and then the
    /// load's alone where the controller adds that), into
    /// `applied_qdd`; `have_applied` false when there is none or the solve fails.
    pub(super) fn applied_acceleration(&mut self, qd: &DVector<f64>) {
        if !self.have_applied {
            return;
        }
        let a = &mut self.applied_qdd;
        gemv(a, -1.0, &self.data.c, qd, 0.0);
        *a += &self.applied_tau;
        if self.spec.gravity_compensation {
            *a -= &self.data.g;
        } else if self.out.load_gravity_in_tau {
            *a -= &self.out.gravity_load;
        }
        self.have_applied = hcc_model::linalg::cholesky_solve_in_place(&self.chol, a).is_ok();
    }

    /// The velocity barrier of the safety layer (crate::safety): the
    /// acceleration q̈ = M⁻¹ (τ − C q̇) that τ (gravity not yet added: it
    /// cancels g) gives on the model, and the barrier's torque added to τ
    /// where a joint in the velocity band is driven too fast (or, with a torque
    /// rate limit downstream, driven faster than it could still be stopped).
    /// Nothing is computed while every joint is below the band and no rate
    /// limit follows.
    pub(super) fn velocity_barrier(&mut self, q: &DVector<f64>, qd: &DVector<f64>) {
        if !self.safety.barrier_needs_acceleration(q, qd, &self.chol) {
            if self.out.safety.barrier_active {
                self.out.safety.barrier_tau.fill(0.0);
                self.out.safety.barrier_active = false;
            }
            return;
        }
        gemv(&mut self.barrier_qdd, 1.0, &self.data.c, qd, 0.0);
        self.barrier_qdd.neg_mut();
        // The applied torque's acceleration: M⁻¹ (τ_applied − g − C q̇) (g only
        // where the controller adds it; the robot adds it itself otherwise).
        self.barrier_qdd += &self.out.tau;
        if hcc_model::linalg::cholesky_solve_in_place(&self.chol, &mut self.barrier_qdd).is_err() {
            return;
        }
        let applied_qdd = self.have_applied.then_some(&self.applied_qdd);
        if self.safety.velocity_barrier(
            q,
            qd,
            &self.barrier_qdd,
            applied_qdd,
            &self.chol,
            &mut self.out.safety,
        ) {
            self.out.tau += &self.out.safety.barrier_tau;
        }
    }

    /// The power the hierarchy's torques (τ_i of every level, τ_μ) put into the
    /// storage E = ½ q̇ᵀ M q̇ + Σ β_i V_i through the arm's motion:
    /// q̇ᵀ (Σ τ_i + τ_μ) + Σ β_i (∂V_i/∂x_i) J_i q̇ (the dampers' dissipation
    /// included, a moving goal's work on the springs not). In free motion it is
    /// ≤ 0 once the levels above each level have converged (Sec. IV); before that
    /// the projections of eqs. (20), (21) can feed energy in.
    pub(super) fn hierarchy_power(&self, qd: &DVector<f64>) -> f64 {
        let mut p = self.out.tau_mu.dot(qd);
        for (i, l) in self.levels.iter().enumerate() {
            p += self.out.tau_level[i].dot(qd) + self.out.fade[i] * l.spring_rate;
        }
        if self.spec.form == Form::KinematicProjector {
            // The comparison law's C q̇: q̇ᵀ C q̇ = ½ q̇ᵀ Ṁ q̇.
            let n = self.n;
            let mut s = 0.0;
            for a in 0..n {
                for b in 0..n {
                    s += qd[a] * self.mdot[(a, b)] * qd[b];
                }
            }
            p += 0.5 * s;
        }
        p
    }

    /// The torque of the safety layer (crate::safety) into `out.safety`.
    pub(super) fn safety_torque(&mut self, q: &DVector<f64>, qd: &DVector<f64>) {
        let hierarchy_power = self.hierarchy_power(qd);
        let goal_moving = self.levels.iter().any(|l| l.goal_moving);
        let terms = crate::safety::CycleTerms {
            hierarchy_power,
            goal_moving,
            q,
            qd,
            m: &self.data.m,
            chol: &self.chol,
            jtop: &self.jtop,
            w: &self.w,
            fade: &self.out.fade,
            conditioning: &self.out.conditioning,
            potential: &self.out.potential,
            singular_ratio: self.spec.singular_ratio,
            level_tanks: self.tank_energy(),
            law_share: self.law_share,
        };
        self.safety.torque(&terms, &mut self.out.safety);
    }
}
