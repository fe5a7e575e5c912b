//! The simulated robot: the rigid-body dynamics (paper eq. 1)
//!
//! M(q) q̈ + C(q, q̇) q̇ + g(q) = τ + τ_ext − F_v q̇
//!
//! integrated with the classical fourth-order Runge–Kutta method on the state
//! (q, q̇), with viscous joint friction F_v = diag(friction) and external
//! wrenches applied through the frame Jacobian of the link they act on,
//! τ_ext = Jᵀ [f; m] (force at the link frame origin, world axes). The external
//! wrenches exist only here: a controller never sees them.
//!
//! Every buffer is allocated in [`Plant::new`]; [`Plant::step`] does not allocate.

use crate::SimError;
use hcc_model::{Data, FrameId, Model};
use nalgebra::{DMatrix, DVector, Point3, Vector3, Vector6};

/// A wrench applied to a link frame during `[start_s, start_s + duration_s)`.
#[derive(Clone, Debug, PartialEq)]
pub struct ExternalWrench {
    /// Start time in s.
    pub start_s: f64,
    /// Duration in s.
    pub duration_s: f64,
    /// Frame the wrench acts on (its origin is the point of application).
    pub frame: FrameId,
    /// Force in N, world axes.
    pub force: Vector3<f64>,
    /// Torque in Nm, world axes.
    pub torque: Vector3<f64>,
}

impl ExternalWrench {
    /// Whether the wrench acts at time `t`.
    pub fn active_at(&self, t: f64) -> bool {
        t >= self.start_s && t < self.start_s + self.duration_s
    }
}

/// Kinetic and potential energy of the plant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantEnergy {
    /// ½ q̇ᵀ M(q) q̇.
    pub kinetic: f64,
    /// −Σ_k m_k gᵀ c_k (c_k: world position of the centre of mass of body k);
    /// zero at the height of the world origin.
    pub potential: f64,
}

impl PlantEnergy {
    /// Kinetic plus potential energy.
    pub fn total(&self) -> f64 {
        self.kinetic + self.potential
    }
}

/// A load the plant's tip takes at `start_s` (what the tip carries from then
/// on; a zero mass lets go).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedLoad {
    pub start_s: f64,
    pub load: hcc_model::Load,
}

/// The plant: model, state, and preallocated integration workspace.
#[derive(Clone, Debug)]
pub struct Plant {
    model: Model,
    data: Data,
    t: f64,
    q: DVector<f64>,
    qd: DVector<f64>,
    friction: DVector<f64>,
    wrenches: Vec<ExternalWrench>,
    /// Loads the tip takes at their time ([`Plant::set_loads`]), by time, and
    /// how many of them it has taken.
    loads: Vec<TimedLoad>,
    loads_taken: usize,
    // RK4 workspace.
    q_stage: DVector<f64>,
    qd_stage: DVector<f64>,
    k_q: [DVector<f64>; 4],
    k_qd: [DVector<f64>; 4],
    tau_total: DVector<f64>,
    tau_ext: DVector<f64>,
    jac: DMatrix<f64>,
    /// Joint end stops at the URDF limits and the violation counters (crate::end_stops).
    end_stops: crate::end_stops::EndStops,
}

impl Plant {
    /// A plant at state (`q0`, `qd0`), t = 0, with viscous joint friction coefficients
    /// `friction` (Nms/rad per joint, ≥ 0) and no external wrench.
    pub fn new(
        model: Model,
        q0: &DVector<f64>,
        qd0: &DVector<f64>,
        friction: &DVector<f64>,
    ) -> Result<Plant, SimError> {
        let n = model.nq();
        for (what, v) in [("q0", q0), ("qd0", qd0), ("friction", friction)] {
            if v.len() != n {
                return Err(SimError::Dimension {
                    what,
                    expected: n,
                    got: v.len(),
                });
            }
            if let Some(k) = v.iter().position(|x| !x.is_finite()) {
                return Err(SimError::NonFinite { what, index: k });
            }
        }
        if let Some(k) = friction.iter().position(|x| *x < 0.0) {
            return Err(SimError::Invalid(format!(
                "friction[{k}] = {} is negative",
                friction[k]
            )));
        }
        let data = Data::new(&model);
        let z = DVector::zeros(n);
        Ok(Plant {
            data,
            t: 0.0,
            q: q0.clone(),
            qd: qd0.clone(),
            friction: friction.clone(),
            wrenches: Vec::new(),
            loads: Vec::new(),
            loads_taken: 0,
            q_stage: z.clone(),
            qd_stage: z.clone(),
            k_q: [z.clone(), z.clone(), z.clone(), z.clone()],
            k_qd: [z.clone(), z.clone(), z.clone(), z.clone()],
            tau_total: z.clone(),
            tau_ext: z,
            jac: DMatrix::zeros(6, n),
            end_stops: crate::end_stops::EndStops::new(&model),
            model,
        })
    }

    /// Replaces the external wrenches (checked: known frame, finite values, duration ≥ 0).
    pub fn set_wrenches(&mut self, wrenches: Vec<ExternalWrench>) -> Result<(), SimError> {
        for (i, w) in wrenches.iter().enumerate() {
            if w.frame >= self.model.frames.len() {
                return Err(SimError::Invalid(format!(
                    "wrench {i}: frame id {} does not exist",
                    w.frame
                )));
            }
            let finite = w.start_s.is_finite()
                && w.duration_s.is_finite()
                && w.force.iter().chain(w.torque.iter()).all(|x| x.is_finite());
            if !finite || w.duration_s < 0.0 {
                return Err(SimError::Invalid(format!(
                    "wrench {i}: values must be finite and the duration non-negative"
                )));
            }
        }
        self.wrenches = wrenches;
        Ok(())
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }
    /// Simulated time in s.
    pub fn t(&self) -> f64 {
        self.t
    }
    /// Sets the simulated time (e.g. to re-anchor it to an exact sample time).
    pub fn set_time(&mut self, t: f64) {
        self.t = t;
    }
    /// Joint positions.
    pub fn q(&self) -> &DVector<f64> {
        &self.q
    }
    /// Joint velocities.
    pub fn qd(&self) -> &DVector<f64> {
        &self.qd
    }

    /// Sets the state and time (lengths must match, values finite).
    pub fn set_state(
        &mut self,
        t: f64,
        q: &DVector<f64>,
        qd: &DVector<f64>,
    ) -> Result<(), SimError> {
        let n = self.model.nq();
        for (what, v) in [("q", q), ("qd", qd)] {
            if v.len() != n {
                return Err(SimError::Dimension {
                    what,
                    expected: n,
                    got: v.len(),
                });
            }
            if let Some(k) = v.iter().position(|x| !x.is_finite()) {
                return Err(SimError::NonFinite { what, index: k });
            }
        }
        self.t = t;
        self.q.copy_from(q);
        self.qd.copy_from(qd);
        Ok(())
    }

    /// External joint torque τ_ext = Σ Jᵀ[f; m] of the wrenches active at time `t`,
    /// evaluated at `q_stage` (into `tau_ext`).
    fn external_torque(&mut self, t: f64) {
        self.tau_ext.fill(0.0);
        if !self.wrenches.iter().any(|w| w.active_at(t)) {
            return;
        }
        hcc_model::forward_kinematics(&self.model, &mut self.data, &self.q_stage);
        for w in &self.wrenches {
            if !w.active_at(t) {
                continue;
            }
            hcc_model::frame_jacobian(&self.model, &self.data, w.frame, &mut self.jac);
            let wrench = Vector6::new(
                w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z,
            );
            // τ_ext += Jᵀ w (gemv_tr does not allocate).
            self.tau_ext.gemv_tr(1.0, &self.jac, &wrench, 1.0);
        }
    }

    /// Derivative of the state at (`q_stage`, `qd_stage`, `t`) into stage `s`:
    /// k_q = q̇, k_qd = M⁻¹(τ + τ_ext − F_v q̇ − C q̇ − g).
    fn derivative(&mut self, s: usize, t: f64, tau: &DVector<f64>) -> Result<(), SimError> {
        self.external_torque(t);
        self.tau_total.copy_from(tau);
        self.tau_total += &self.tau_ext;
        for k in 0..self.tau_total.len() {
            self.tau_total[k] -= self.friction[k] * self.qd_stage[k];
        }
        // End stops: nothing is added where no joint is beyond a limit.
        self.end_stops
            .add_torque(&self.q_stage, &self.qd_stage, &mut self.tau_total);
        hcc_model::forward_dynamics(
            &self.model,
            &mut self.data,
            &self.q_stage,
            &self.qd_stage,
            &self.tau_total,
        )?;
        if self.data.qdd.iter().any(|x| !x.is_finite()) {
            return Err(SimError::Diverged { t });
        }
        self.k_q[s].copy_from(&self.qd_stage);
        self.k_qd[s].copy_from(&self.data.qdd);
        Ok(())
    }

    /// Loads the tip takes at their times (each replacing the one before;
    /// checked: finite times ≥ 0, physical loads). A load is taken at the
    /// first step that begins at or after its time.
    pub fn set_loads(&mut self, mut loads: Vec<TimedLoad>) -> Result<(), SimError> {
        for (i, l) in loads.iter().enumerate() {
            if !(l.start_s.is_finite() && l.start_s >= 0.0) {
                return Err(SimError::Invalid(format!(
                    "load {i}: start {} s",
                    l.start_s
                )));
            }
            l.load
                .check(f64::INFINITY)
                .map_err(|e| SimError::Invalid(format!("load {i}: {e}")))?;
        }
        loads.sort_by(|a, b| a.start_s.total_cmp(&b.start_s));
        self.loads = loads;
        self.loads_taken = 0;
        Ok(())
    }

    /// Takes the loads whose time has come (allocation-free).
    fn take_loads(&mut self) {
        while let Some(l) = self.loads.get(self.loads_taken) {
            if l.start_s > self.t + 1e-12 {
                break;
            }
            hcc_model::set_load(&mut self.model, &l.load);
            self.loads_taken += 1;
        }
    }

    /// Advances the state by `dt` with the joint torque `tau` held constant (RK4).
    /// On error the state is left unchanged.
    pub fn step(&mut self, tau: &DVector<f64>, dt: f64) -> Result<(), SimError> {
        self.take_loads();
        let n = self.model.nq();
        if tau.len() != n {
            return Err(SimError::Dimension {
                what: "tau",
                expected: n,
                got: tau.len(),
            });
        }
        if let Some(k) = tau.iter().position(|x| !x.is_finite()) {
            return Err(SimError::NonFinite {
                what: "tau",
                index: k,
            });
        }
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(SimError::Invalid(format!(
                "time step {dt} must be positive"
            )));
        }
        const C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
        for (s, c) in C.iter().enumerate() {
            self.q_stage.copy_from(&self.q);
            self.qd_stage.copy_from(&self.qd);
            if s > 0 {
                let h = c * dt;
                self.q_stage.axpy(h, &self.k_q[s - 1], 1.0);
                self.qd_stage.axpy(h, &self.k_qd[s - 1], 1.0);
            }
            self.derivative(s, self.t + c * dt, tau)?;
        }
        let w = dt / 6.0;
        for k in 0..n {
            self.q[k] +=
                w * (self.k_q[0][k] + 2.0 * self.k_q[1][k] + 2.0 * self.k_q[2][k] + self.k_q[3][k]);
            self.qd[k] += w
                * (self.k_qd[0][k]
                    + 2.0 * self.k_qd[1][k]
                    + 2.0 * self.k_qd[2][k]
                    + self.k_qd[3][k]);
        }
        self.t += dt;
        self.end_stops.record(&self.q, &self.qd);
        Ok(())
    }

    /// The end stops and what they counted (contacts, steps beyond a position
    /// limit, steps faster than a velocity limit).
    pub fn end_stops(&self) -> &crate::end_stops::EndStops {
        &self.end_stops
    }

    /// The end stops, to switch them off (`set_enabled`).
    pub fn end_stops_mut(&mut self) -> &mut crate::end_stops::EndStops {
        &mut self.end_stops
    }

    /// Kinetic and potential energy at the current state (does not allocate).
    pub fn energy(&mut self) -> PlantEnergy {
        hcc_model::crba(&self.model, &mut self.data, &self.q);
        let n = self.model.nq();
        let m = &self.data.m;
        let mut kinetic = 0.0;
        for i in 0..n {
            for j in 0..n {
                kinetic += 0.5 * self.qd[i] * m[(i, j)] * self.qd[j];
            }
        }
        let mut potential = 0.0;
        for (joint, o_m) in self.model.joints.iter().zip(&self.data.o_m_i) {
            let c = o_m * Point3::from(joint.inertia.com);
            potential -= joint.inertia.mass * self.model.gravity.dot(&c.coords);
        }
        PlantEnergy { kinetic, potential }
    }
}
