//! The safety layer: passive singularity handling, joint position and velocity
//! limits. Everything here only ever removes energy (or, for the joint-limit
//! spring, stores it in a potential of its own), and nothing acts away from
//! singularities and limits: there the torque is bit-identical to the paper's law.
//!
//! One mechanism per file, in the order the cycle applies them
//! (`crate::controller`):
//! 1. [`reach`]: the speed each joint reaches this cycle (with a torque rate
//!    limit downstream, what it gains before the applied torque can stop it)
//!    and its place in the velocity band — the input of 3, 8, 9;
//! 2. [`spring_saturation`]: each level's potential made linear beyond a
//!    radius, so a damper settles below the velocity limits;
//! 3. [`governor`]: near a velocity limit, the springs that drive the motion
//!    are scaled down (2 and 3 act in the levels' F_i);
//! 4. [`conflict_fade`]: a level in an algorithmic conflict fades out;
//! 5. [`passive_fade`]: the fades remove energy only, a fade-in is paid from
//!    an energy tank;
//! 6. [`null_space_damping`]: a faded level's self-motion is damped in its
//!    place;
//! 7. [`passivity`]: the energy the hierarchy feeds in is budgeted, the excess
//!    damped out;
//! 8. [`joint_limit_guard`] and [`velocity_damping`]: per joint, a spring and
//!    damper in a position limit's margin and a damping in the velocity band;
//! 9. [`velocity_barrier`]: on the acceleration the whole torque gives, a
//!    joint driven too fast towards its velocity limit is braked.
//!
//! 6–8 form τ_safety ([`SafetyOutput::tau`]), added to τ where one acts; 9
//! comes after τ = Σ τ_i + τ_μ (eq. 19). [`SafetySpec`] (from `hcc-spec`) switches and
//! tunes them; [`output`] reports what acted.
//!
//! Allocation-free after `Safety::new`.

pub mod conflict_fade;
pub mod governor;
pub mod joint_limit_guard;
pub mod null_space_damping;
pub mod output;
pub mod passive_fade;
pub mod passivity;
pub mod reach;
pub mod spring_saturation;
pub mod velocity_barrier;
pub mod velocity_damping;

pub(crate) use governor::spring_scale;
pub use hcc_spec::SafetySpec;
pub use output::SafetyOutput;

use crate::ControlError;
use hcc_linalg::products::gemv;
use hcc_linalg::spd::SpdWork;
use hcc_model::Model;
use nalgebra::{DMatrix, DVector};

/// The state the controller hands the safety layer each cycle.
pub(crate) struct CycleTerms<'a> {
    /// The hierarchy's power into E (W; `Controller::hierarchy_power`).
    pub hierarchy_power: f64,
    /// A level's goal moves (its work on the arm is not the law's).
    pub goal_moving: bool,
    pub q: &'a DVector<f64>,
    pub qd: &'a DVector<f64>,
    /// M and its Cholesky factor.
    pub m: &'a DMatrix<f64>,
    pub chol: &'a DMatrix<f64>,
    /// The stacked Jacobians of the levels above the lowest and W = J M⁻¹ Jᵀ.
    pub jtop: &'a DMatrix<f64>,
    pub w: &'a DMatrix<f64>,
    /// The effective fade β_i per level.
    pub fade: &'a [f64],
    /// The smallest eigenvalue ratio of each level's inversions (`StepOutput::conditioning`).
    pub conditioning: &'a [f64],
    /// V_i per level.
    pub potential: &'a [f64],
    pub singular_ratio: f64,
    /// Σ E_i of the levels' energy tanks (J; crate::energy_tank).
    pub level_tanks: f64,
    /// The share s of the law's torque (and τ_safety's) the robot receives
    /// (`Controller::set_law_share`): the law's storages count with it.
    pub law_share: f64,
}

/// Workspace and memory of the safety layer.
#[derive(Clone, Debug)]
pub(crate) struct Safety {
    spec: SafetySpec,
    lower: Vec<f64>,
    upper: Vec<f64>,
    velocity_limit: Vec<f64>,
    /// Per joint: the speed it reaches this cycle (`Safety::set_reach`).
    reach: Vec<f64>,
    /// Guard spring constant per joint.
    k_guard: Vec<f64>,
    /// Per level: the task speed v_i its damper may settle at (∞: no saturation) and
    /// the radius r_0,i of the saturated potential ([`spring_saturation`]).
    task_speed: Vec<f64>,
    spring_radius: Vec<f64>,
    /// Rows of J_aug above each level (Σ_{j<i} m_j; only i ≥ 1 is used).
    k_above: Vec<usize>,
    /// G, its damped inverse and workspace per level (k_i × k_i).
    g: Vec<DMatrix<f64>>,
    g_inv: Vec<DMatrix<f64>>,
    spd: Vec<SpdWork>,
    beta_prev: Vec<f64>,
    has_prev: bool,
    /// The governor's gain of the last cycle.
    governor_prev: f64,
    /// Per level: faded for a conflict, not yet released.
    conflict_latched: Vec<bool>,
    tank: f64,
    /// What the hierarchy may still feed into E (J; NaN: refilled, to be set
    /// from this cycle's E).
    budget: f64,
    /// Power dissipated in the last cycle that goes to the tank (W).
    fill_power: f64,
    /// ẋ_aug = J_aug q̇ of the stacked levels above the lowest, and whether it
    /// is this cycle's.
    xdot: DVector<f64>,
    xdot_fresh: bool,
    y: DVector<f64>,
    mqd: DVector<f64>,
    /// M q̇ − J_augᵀ y after [`Safety::project_above`]: the momentum in the
    /// null space of the levels above (its power against q̇ is 2 × their
    /// null-space kinetic energy).
    null_momentum: DVector<f64>,
    e: DVector<f64>,
}

/// A level faded for a conflict (its own Λ_i near-singular) may come back
/// once its conditioning is this many times the top of the conflict fade's
/// region (`FADE_RANGE` · ε_c), or when its goal changes.
pub const CONFLICT_RELEASE_FACTOR: f64 = 5.0;

/// Fastest fall of the velocity governor's gain (1/s): from 1 to 0 in at
/// least 0.2 s.
pub const GOVERNOR_RELEASE_RATE: f64 = 5.0;

/// The share of the joint-limit margin over which the guard's damping comes in.
pub const GUARD_RAMP: f64 = 0.1;

/// The share of the storage E at a goal change that the hierarchy may feed in
/// while it converges level by level (Sec. IV) — on top of `passivity_budget`,
/// decaying with [`PASSIVITY_TRANSIENT_TIME`]. The paper's two simulations feed
/// 9 % and 21 % of theirs within 0.25 s.
pub const PASSIVITY_TRANSIENT_SHARE: f64 = 0.5;

/// Time constant (s) of the decay of that allowance.
pub const PASSIVITY_TRANSIENT_TIME: f64 = 0.5;

/// The share of `passivity_budget` over which the passivity damping comes in
/// (from nothing at this much left to all of the excess at none).
pub const PASSIVITY_ONSET: f64 = 0.5;

/// Fastest rise of an effective fade β_i (1/s).
pub const FADE_IN_RATE: f64 = 1.0;

/// Cosine between q̇ and a level's spring torque −J_iᵀ ∂V_i/∂x_i at which the
/// velocity governor scales that spring fully ([`governor`]).
pub const GOVERNOR_COSINE: f64 = 0.25;

/// M_kk from the Cholesky factor L of M (lower triangle): Σ_j L_kj².
fn diagonal_of_llt(chol: &DMatrix<f64>, k: usize) -> f64 {
    (0..=k).map(|j| chol[(k, j)] * chol[(k, j)]).sum()
}

/// Smoothstep 3x² − 2x³ on [0, 1] (0 below, 1 above).
fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

impl Safety {
    /// `dims`: task dimensions m_i; `ktop`: rows of the stacked `jtop`.
    pub(crate) fn new(
        model: &Model,
        spec: &crate::ControllerSpec,
        dims: &[usize],
        ktop: usize,
    ) -> Result<Safety, ControlError> {
        let s = spec.safety.clone();
        s.validate()?;
        let half = 0.5 * s.joint_limit_margin;
        let k_guard = model
            .joints
            .iter()
            .map(|j| {
                let t = s
                    .joint_limit_torque
                    .unwrap_or(if j.effort_limit.is_finite() {
                        j.effort_limit
                    } else {
                        100.0
                    });
                t / (half * half)
            })
            .collect();
        let r = dims.len();
        let mut k_above = vec![0; r];
        for i in 1..r {
            k_above[i] = (k_above[i - 1] + dims[i - 1]).min(ktop);
        }
        Ok(Safety {
            lower: model.joints.iter().map(|j| j.lower).collect(),
            upper: model.joints.iter().map(|j| j.upper).collect(),
            velocity_limit: model.joints.iter().map(|j| j.velocity_limit).collect(),
            reach: vec![0.0; model.joints.len()],
            k_guard,
            task_speed: vec![f64::INFINITY; r],
            spring_radius: vec![f64::INFINITY; r],
            g: k_above.iter().map(|&k| DMatrix::zeros(k, k)).collect(),
            g_inv: k_above.iter().map(|&k| DMatrix::zeros(k, k)).collect(),
            spd: k_above.iter().map(|&k| SpdWork::new(k)).collect(),
            k_above,
            beta_prev: vec![1.0; r],
            has_prev: false,
            governor_prev: 0.0,
            conflict_latched: vec![false; r],
            tank: 0.0,
            budget: f64::NAN,
            fill_power: 0.0,
            xdot: DVector::zeros(ktop),
            xdot_fresh: false,
            y: DVector::zeros(ktop),
            mqd: DVector::zeros(model.nq()),
            null_momentum: DVector::zeros(model.nq()),
            e: DVector::zeros(model.nq()),
            spec: s,
        })
    }

    /// Forgets the fade memory (the next cycle takes β(q) as it is) and empties the tank.
    pub(crate) fn reset(&mut self) {
        self.has_prev = false;
        self.governor_prev = 0.0;
        self.conflict_latched.fill(false);
        self.tank = 0.0;
        self.fill_power = 0.0;
        self.refill_passivity_budget();
    }

    /// The effective β_i of the last cycle (1 before the first).
    pub(crate) fn last_fade(&self, i: usize) -> f64 {
        if self.has_prev {
            self.beta_prev[i]
        } else {
            1.0
        }
    }

    /// τ_safety of this cycle into `out` (parts 6–8 above); `out.active` says whether it
    /// is to be added to τ. Also E and the power of τ_safety.
    pub(crate) fn torque(&mut self, c: &CycleTerms, out: &mut SafetyOutput) {
        out.tau.fill(0.0);
        out.active = false;
        out.joint_limit_active = false;
        out.velocity_limit_active = false;
        out.null_space_damping_active = false;
        out.guard_potential = 0.0;
        out.power = 0.0;
        self.fill_power = 0.0;
        self.xdot_fresh = false;
        gemv(&mut self.mqd, 1.0, c.m, c.qd, 0.0);
        let kinetic = 0.5 * c.qd.dot(&self.mqd);
        let mut potential = 0.0;
        // The springs act with the law's share s of the torque (a contact
        // hold blends the rest away): their storage is s β_i V_i.
        for (i, (v, stored)) in c.potential.iter().zip(&mut out.level_potential).enumerate() {
            *stored = c.law_share * if i == 0 { *v } else { c.fade[i] * v };
            potential += *stored;
        }
        out.hierarchy_power = c.hierarchy_power;
        out.passivity_active = false;
        if self.spec.enabled {
            self.null_space_damping(c, out);
            self.passivity(c, kinetic + potential, out);
            self.joint_limits(c, out);
            out.active = out.null_space_damping_active
                || out.passivity_active
                || out.joint_limit_active
                || out.velocity_limit_active;
            out.power = out.tau.dot(c.qd);
            // The governor scaled a spring (in the levels' F_i, not in τ_safety).
            out.velocity_limit_active |= out.spring_scale.iter().any(|&s| s < 1.0);
        }
        out.passivity_cycles += u64::from(out.passivity_active);
        out.passivity_budget = if self.budget.is_nan() {
            self.spec.passivity_budget
        } else {
            self.budget
        };
        out.joint_limit_cycles += u64::from(out.joint_limit_active);
        out.velocity_limit_cycles += u64::from(out.velocity_limit_active);
        out.energy = kinetic + potential + c.law_share * out.guard_potential;
        out.h = out.energy + self.tank + c.level_tanks;
    }

    /// The joint-space parts, joint by joint (one m_k each): the joint-limit
    /// guard, then the velocity damping.
    fn joint_limits(&mut self, c: &CycleTerms, out: &mut SafetyOutput) {
        for k in 0..c.q.len() {
            let (q, qd) = (c.q[k], c.qd[k]);
            let (p, sign) = self.penetration(k, q);
            let x = self.velocity_damping_band(k);
            if p <= 0.0 && x <= 0.0 {
                continue;
            }
            let m_k = self.effective_inertia(c.chol, k);
            if p > 0.0 {
                self.guard(k, (p, sign), m_k, qd, out);
            }
            if x > 0.0 {
                self.velocity_damping(k, x, m_k, qd, out);
            }
        }
    }

    /// Effective inertia 1/(M⁻¹)_kk of joint k.
    fn effective_inertia(&mut self, chol: &DMatrix<f64>, k: usize) -> f64 {
        self.e.fill(0.0);
        self.e[k] = 1.0;
        if hcc_model::linalg::cholesky_solve_in_place(chol, &mut self.e).is_err()
            || self.e[k] <= 0.0
        {
            return 0.0;
        }
        1.0 / self.e[k]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothstep_is_c1_at_its_ends() {
        assert_eq!(smoothstep(-1.0), 0.0);
        assert_eq!(smoothstep(0.0), 0.0);
        assert_eq!(smoothstep(1.0), 1.0);
        assert_eq!(smoothstep(2.0), 1.0);
        let h = 1e-6;
        assert!(smoothstep(h) / h < 1e-5);
        assert!((1.0 - smoothstep(1.0 - h)) / h < 1e-5);
    }
}
