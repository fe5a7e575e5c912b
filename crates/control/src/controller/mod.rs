//! The controller: its workspace, construction and the one call per cycle,
//! [`Controller::step`], from the measured state to the torque command. The
//! cycle runs its stages in this order ([`Controller::step`]):
//! 1. M, its Cholesky factor, Ṁ = C + Cᵀ and g (Sec. II), and the speed each
//!    joint reaches (the safety layer's input, [`crate::safety::reach`]);
//! 2. the task terms of each level, F_i of eqs. (20), (21) (`task_force.rs`);
//! 3. the decomposition: Z_i, J̄_i, Λ_i, Λ̇_i (eqs. 3–13, 15–18;
//!    `projection.rs`, `null_space.rs`);
//! 4. the fades and the safety layer's passive fade (`safety_terms.rs`), the
//!    levels' energy tanks (`tanks.rs`, crate::energy_tank);
//! 5. the level torques τ_i (eqs. 20, 21; `law.rs`) and τ_μ (eqs. 17, 22;
//!    `coriolis.rs`);
//! 6. τ_safety, τ = Σ τ_i + τ_μ + g (eq. 19), the velocity barrier.
//!
//! `setters.rs` take goals and gains between cycles, `initial_check.rs` checks
//! the hierarchy at construction, `diagnostics.rs` forms the stacked matrices.

mod command_input;
mod command_tank;
mod coriolis;
mod diagnostics;
mod initial_check;
mod law;
mod level;
mod null_space;
mod output;
mod projection;
mod safety_terms;
mod setters;
mod tanks;
mod task_force;
mod tracking;

pub use diagnostics::Diagnostics;
pub use output::{CommandInput, LevelTarget, StepOutput};

use crate::ControlError;
use crate::fade::fade_factor;
use crate::spec::{ControllerSpec, Form};
use crate::task::FrameWork;
use coriolis::MuWork;
use hcc_linalg::products::{copy, gemv};
use hcc_linalg::spd::Conditioning;
use hcc_linalg::symmetric::sym_sum_transpose;
use hcc_model::{Data, Model};
use level::Level;
use nalgebra::{DMatrix, DVector};
use null_space::NullSpace;
use tracking::TrackWork;

/// Smallest eigenvalue that counts as "not vanished" for a Gram matrix.
const GRAM_FLOOR: f64 = 1e-12;

/// The hierarchical compliance controller of Dietrich, Ott & Albu-Schäffer (IROS 2013).
///
/// Built once by [`Controller::new`] (which allocates everything), then driven by
/// [`Controller::step`], one call from the measured state to the torque command, which
/// never allocates.
#[derive(Clone, Debug)]
pub struct Controller {
    model: Model,
    data: Data,
    spec: ControllerSpec,
    n: usize,
    levels: Vec<Level>,
    /// The null space of the lowest level (empty with a single level).
    basis: NullSpace,
    /// J and J̇ of the levels above the lowest stacked (level 1 alone for r = 1),
    /// K = Σ m_i rows; J_aug of level i is its first k_i rows (eq. 6).
    jtop: DMatrix<f64>,
    jtop_dot: DMatrix<f64>,
    /// Jᵀ of the levels above the lowest (n × K).
    jtop_t: DMatrix<f64>,
    /// (J M⁻¹)ᵀ = M⁻¹ Jᵀ and its derivative M⁻¹ (J̇ᵀ − Ṁ M⁻¹ Jᵀ) (n × K; the rows of
    /// Y = J M⁻¹ and Ẏ a level needs are transposed straight out of their columns), the
    /// Gram matrix W = J M⁻¹ Jᵀ (K × K) and the columns of Ẇ the middle levels read
    /// (K × max k_i, k_i = Σ_{j<i} m_j: Ġ and Ḣ of eq. 8 lie in them).
    yt: DMatrix<f64>,
    yt_dot: DMatrix<f64>,
    w: DMatrix<f64>,
    w_dot: DMatrix<f64>,
    q: DVector<f64>,
    qd: DVector<f64>,
    /// Cholesky factor of M (M⁻¹ is applied by solves, never formed).
    chol: DMatrix<f64>,
    mdot: DMatrix<f64>,
    /// Frame Jacobians of the current cycle (shared by the tasks on one frame).
    frames: FrameWork,
    /// Ẏ and Ẇ are needed (a level between the first and the lowest exists).
    middle: bool,
    tmp_n: DVector<f64>,
    tmp_n2: DVector<f64>,
    /// Level 1's damped inversion of J_1 M⁻¹ J_1ᵀ (the Gram matrix G of level 2).
    first_cond: Conditioning,
    /// Columns per level of the τ_μ chains (eq. 22).
    mu: MuWork,
    /// Safety layer workspace and memory (crate::safety).
    safety: crate::safety::Safety,
    /// The acceleration the law's torque gives (the velocity barrier's input).
    barrier_qdd: DVector<f64>,
    /// The tip's 6×n Jacobian (the load's gravity torque, hcc_model::load_gravity).
    load_jacobian: DMatrix<f64>,
    /// The torque the robot applies now (the previous command, after the torque
    /// filter), when the cycle reports it ([`Controller::set_applied_torque`]).
    applied_tau: DVector<f64>,
    have_applied: bool,
    /// The acceleration `applied_tau` gives on the model (for the barrier).
    applied_qdd: DVector<f64>,
    /// κ, the factor on every level's spring ([`Controller::set_stiffness_scale`]).
    stiffness_scale: f64,
    /// The share of the law's torque the robot receives ([`Controller::set_law_share`]).
    law_share: f64,
    /// The energy tanks are to be refilled in the next cycle (start, reset, a
    /// goal or gains change; crate::energy_tank).
    tank_refill: bool,
    /// The command tank (`command_tank.rs`).
    command: command_tank::CommandTank,
    /// The tracking form's joint-space parts (`tracking.rs`).
    track: TrackWork,
    out: StepOutput,
}

impl Controller {
    /// Checks the hierarchy against the model and the initial configuration `q0`, and
    /// allocates every buffer. Errors name the level and the reason.
    pub fn new(
        model: &Model,
        spec: ControllerSpec,
        q0: &DVector<f64>,
    ) -> Result<Controller, ControlError> {
        spec.validate(model)?;
        let n = model.nq();
        let r = spec.levels.len();
        if q0.len() != n || q0.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::Spec(format!(
                "initial configuration must be {n} finite values, got {}",
                q0.len()
            )));
        }
        let dims = spec.task_dims(n);
        let (levels, ktop) = Level::hierarchy(&spec, &dims, n);
        let basis = NullSpace::below(r, n, ktop);
        let middle = r > 2;
        let kd = if middle { ktop } else { 0 };
        let kmid = levels.iter().map(|l| l.proj.k).max().unwrap_or(0);
        let v_dims: Vec<usize> = levels.iter().map(|l| l.d).collect();
        let out = StepOutput::new(n, &dims, &v_dims);
        // Safety layer (crate::safety): limits from the model, workspace.
        let safety = crate::safety::Safety::new(model, &spec, &dims, ktop)?;
        let mut c = Controller {
            data: Data::new(model),
            model: model.clone(),
            spec,
            n,
            levels,
            basis,
            jtop: DMatrix::zeros(ktop, n),
            jtop_dot: DMatrix::zeros(ktop, n),
            jtop_t: DMatrix::zeros(n, ktop),
            yt: DMatrix::zeros(n, ktop),
            yt_dot: DMatrix::zeros(n, kd),
            w: DMatrix::zeros(ktop, ktop),
            w_dot: DMatrix::zeros(kd, kmid),
            middle,
            q: DVector::zeros(n),
            qd: DVector::zeros(n),
            chol: DMatrix::zeros(n, n),
            mdot: DMatrix::zeros(n, n),
            frames: FrameWork::new(n),
            tmp_n: DVector::zeros(n),
            tmp_n2: DVector::zeros(n),
            first_cond: Conditioning::default(),
            mu: MuWork::new(n, r),
            safety,
            barrier_qdd: DVector::zeros(n),
            load_jacobian: DMatrix::zeros(6, n),
            applied_tau: DVector::zeros(n),
            have_applied: false,
            applied_qdd: DVector::zeros(n),
            stiffness_scale: 1.0,
            law_share: 1.0,
            tank_refill: true,
            command: command_tank::CommandTank::default(),
            track: TrackWork::new(n, dims[0]),
            out,
        };
        c.check_initial(q0)?;
        c.init_safety();
        Ok(c)
    }

    /// Forgets the null-space basis of the previous cycle (call when the state jumps,
    /// e.g. a new robot connection). The next cycle picks a fresh basis.
    pub fn reset(&mut self) {
        self.basis.has_prev = false;
        // Safety layer: forget the fade memory and empty its energy tank.
        self.safety.reset();
        // The levels' energy tanks back to their initial energy.
        self.reset_tanks();
    }

    /// Number of joints.
    pub fn nq(&self) -> usize {
        self.n
    }

    /// Number of levels r.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Task dimension m_i of level `i` (0-based).
    pub fn task_dim(&self, i: usize) -> usize {
        self.levels[i].m
    }

    /// The (stacked) task Jacobian J_i of level `i` (0-based) of the last cycle.
    pub fn task_jacobian(&self, i: usize) -> &DMatrix<f64> {
        &self.levels[i].j
    }

    /// The model the controller was built with.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The spec the controller was built with.
    pub fn spec(&self) -> &ControllerSpec {
        &self.spec
    }

    /// The model's terms at the state of the last cycle: M(q), C(q, q̇) (with
    /// Ṁ = C + Cᵀ) and g(q) in `m`, `c`, `g` (what the momentum observer of
    /// [`crate::contact`] reads). Valid after a successful [`Controller::step`].
    pub fn model_terms(&self) -> &Data {
        &self.data
    }

    /// The Cholesky factor L of M(q) at the state of the last cycle (lower
    /// triangle; M = L Lᵀ), for solves with M⁻¹ outside the law
    /// ([`crate::velocity_limit`]). Valid after a successful [`Controller::step`].
    pub fn mass_factor(&self) -> &DMatrix<f64> {
        &self.chol
    }

    /// Result of the last cycle.
    pub fn output(&self) -> &StepOutput {
        &self.out
    }

    /// One control cycle: from the measured (q, q̇) to the torque command in
    /// [`StepOutput::tau`]. Allocation-free. On non-finite input it returns an error and
    /// leaves the previous output untouched; a numerical failure (which the damping
    /// should prevent) returns an error with τ set to g (or 0 without gravity compensation).
    pub fn step(&mut self, q: &[f64], qd: &[f64]) -> Result<&StepOutput, ControlError> {
        if q.len() != self.n || qd.len() != self.n {
            return Err(ControlError::BadInput(
                "state has the wrong number of joints",
            ));
        }
        if q.iter().chain(qd.iter()).any(|x| !x.is_finite()) {
            return Err(ControlError::BadInput("state has a non-finite value"));
        }
        self.q.as_mut_slice().copy_from_slice(q);
        self.qd.as_mut_slice().copy_from_slice(qd);
        let (q, qd) = (std::mem::take(&mut self.q), std::mem::take(&mut self.qd));
        let res = self.compute(&q, &qd);
        self.q = q;
        self.qd = qd;
        match res {
            Ok(()) => Ok(&self.out),
            Err(e) => {
                let g = match (self.spec.gravity_compensation, self.out.load_gravity_in_tau) {
                    (true, _) => Some(&self.out.gravity),
                    (false, true) => Some(&self.out.gravity_load),
                    (false, false) => None,
                };
                let g = g.filter(|g| g.iter().all(|x| x.is_finite()));
                for i in 0..self.n {
                    self.out.tau[i] = g.map_or(0.0, |g| g[i]);
                }
                Err(e)
            }
        }
    }

    /// One evaluation of the law at (q, q̇) into [`Controller::output`].
    fn compute(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), ControlError> {
        let r = self.levels.len();
        let eps = self.spec.singular_ratio;
        self.dynamics(q, qd)?;

        // Safety layer: the speed each joint reaches before the rate-limited
        // applied torque can stop it (crate::safety; |q̇| without a rate limit).
        self.applied_acceleration(qd);
        let applied_qdd = self.have_applied.then_some(&self.applied_qdd);
        self.safety.set_reach(qd, applied_qdd, &self.chol);

        // Task quantities x̃_i, J_i, J̇_i, ∂V_i/∂x_i, F_i = ∂V/∂x + D ẋ (eqs. 20, 21).
        self.frames.invalidate();
        self.out.safety.spring_saturated = false;
        // Safety layer: the velocity governor's gain from the joint speeds
        // (crate::safety; 0, and the springs untouched, below the velocity band).
        let governor = self.safety.governor_gain(qd);
        self.out.safety.velocity_governor = governor;
        let speed = if governor > 0.0 { qd.norm() } else { 0.0 };
        for i in 0..r {
            self.evaluate_task(i, q, qd, governor, speed);
        }

        // Z_i, J̄_i, Λ_i of every level (eqs. 3–13, 15–18).
        self.decompose()?;
        // v_i = J̄_i q̇ (eq. 3).
        self.local_velocities(qd);
        // The tracking form's desired v_{i,d}, v̇_{i,d} and feed-forward
        // (`tracking.rs`; nothing while no level tracks a moving goal).
        self.tracking_feed_forward()?;
        // Safety layer: a fade-in is paid from the energy tank (crate::safety).
        self.passive_fade();
        // The energy tanks (crate::energy_tank): what the levels above do to a
        // level's spring is paid from its tank; F_i with the damper on dx̂_i/dt.
        self.energy_tanks(qd);
        // τ_μ involves every level's Λ_i and J̄̇_i: it fades with any of them.
        self.out.fade_mu = self
            .out
            .conditioning
            .iter()
            .map(|&c| fade_factor(c, eps))
            .product();

        self.out.safety.spring_saturated_cycles += u64::from(self.out.safety.spring_saturated);
        self.level_torques();
        self.command_power(qd);
        self.book_command_work();
        self.coriolis_cancellation(qd)?;
        // Safety layer: null-space damping of faded levels, the passivity
        // damping, joint position and velocity limits (crate::safety); zero and
        // not added where nothing acts.
        self.safety_torque(q, qd);
        self.assemble_torque(q, qd)
    }

    /// The model's terms at (q, q̇): M = L Lᵀ (M⁻¹ is only ever applied, by
    /// solves), C, Ṁ = C + Cᵀ (Sec. II) and g.
    fn dynamics(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), ControlError> {
        hcc_model::compute_all_terms(&self.model, &mut self.data, q, qd);
        copy(&mut self.chol, &self.data.m);
        hcc_model::linalg::cholesky_factor(&mut self.chol)
            .map_err(|_| ControlError::Numerical("M is not positive definite"))?;
        sym_sum_transpose(&mut self.mdot, &self.data.c);
        copy(&mut self.out.gravity, &self.data.g);
        // The driver compensates the arm's gravity with its own model, which
        // does not know the load: the law adds the load's (docs/load.md).
        let out = &mut self.out;
        out.load_gravity_in_tau = !self.spec.gravity_compensation && self.model.load.mass > 0.0;
        if out.load_gravity_in_tau {
            hcc_model::load_gravity(
                &self.model,
                &self.data,
                &mut self.load_jacobian,
                &mut out.gravity_load,
            );
        } else {
            out.gravity_load.fill(0.0);
        }
        Ok(())
    }

    /// τ = Σ τ_i + τ_μ + g (eq. 19) (+ the tracking feed-forward, τ_safety where it acts, the comparison
    /// law's C q̇, the velocity barrier on the acceleration this τ gives);
    /// an error for a non-finite torque.
    fn assemble_torque(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), ControlError> {
        copy(&mut self.out.tau, &self.out.tau_mu);
        for t in &self.out.tau_level {
            self.out.tau += t;
        }
        if self.track.active {
            self.out.tau += &self.out.tau_feed_forward;
        }
        if self.out.safety.active {
            self.out.tau += &self.out.safety.tau;
        }
        if self.spec.form == Form::KinematicProjector {
            // The comparison law adds C q̇ instead of τ_μ.
            gemv(&mut self.out.coriolis, 1.0, &self.data.c, qd, 0.0);
            self.out.tau += &self.out.coriolis;
        }
        // Safety layer: the velocity barrier, on the acceleration this τ gives.
        self.velocity_barrier(q, qd);
        if self.spec.gravity_compensation {
            self.out.tau += &self.data.g;
        } else if self.out.load_gravity_in_tau {
            self.out.tau += &self.out.gravity_load;
        }
        if self.out.tau.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::Numerical("non-finite torque"));
        }
        Ok(())
    }
}
