//! The safety layer: passive singularity handling, joint position and velocity
//! limits. Everything here only ever removes energy (or, for the joint-limit
//! spring, stores it in a potential of its own), and nothing acts away from
//! singularities and limits: there the torque is bit-identical to the paper's law.
//!
//! **Passive fade.** Near a singularity the torque of a level i ≥ 2 is scaled by
//! β_i ∈ [0, 1] (crate docs, "Singularities"). With the storage of the whole system
//!
//! E = ½ q̇ᵀ M q̇ + V_1 + Σ_{i≥2} β_i V_i  (= Σ_i S_i of eqs. 26, 28 when every β_i = 1),
//!
//! a fade-out (β̇_i < 0) removes the energy −β̇_i V_i ≥ 0 from E, a fade-in would add
//! β̇_i V_i. A fade-in is therefore paid from an energy tank T ≥ 0 that collects what
//! the fade-outs removed and what the damping dissipated (the levels' dampers
//! Σ β_i ẋ_iᵀ D_i ẋ_i and the null-space damping below), capped at `fade_tank_max`: β_i
//! rises only as far as T covers, so E + T never grows by a fade. β_i follows a
//! falling β(q) at once (the protection of the singular region is kept), and rises
//! only once β(q) = 1 again (hysteresis), at most at [`FADE_IN_RATE`].
//!
//! **Conflict fade.** A level i ≥ 2 whose goal is unreachable given the levels
//! above it (an algorithmic conflict: Λ_i = Z_i M Z_iᵀ of eq. 18 becomes singular,
//! its conditioning r_i = `StepOutput::conditioning` falls, while the levels above stay
//! regular) keeps pulling in the direction it lost through the damped inverse: the
//! arm creeps along the self-motion that makes the conflict worse (e.g. a wrist
//! centre pulled beyond reach by the orientation level stretches the elbow). With
//! `conflict_fade_ratio` = ε_c > 0 its fade is lowered to
//!
//! β_i(q) ← min(β_i(q), β_c(r_i)),  β_c(r) = smoothstep(log_100(r / ε_c)) (0 at ε_c, 1 from 100 ε_c),
//!
//! before the passive fade below. r_i is the smaller eigenvalue ratio of Λ_i and of
//! G = J_aug M⁻¹ J_augᵀ of the levels above (the ratio the null-space damping uses),
//! so near a singularity of the levels above the level fades from 100 ε_c on as
//! well, earlier than the plain fade (100 `singular_ratio`). The same storage
//! function, so the same argument
//! holds — a fade-out removes −β̇_i V_i ≥ 0 from E, a fade-in (once r_i ≥ 100 ε_c
//! again) is paid from the tank, and the null-space damping (c_i from β_i) takes the
//! faded level's place. β_c is C¹ in log r_i (no torque jump); 1 wherever
//! r_i ≥ 100 ε_c, so a regular hierarchy is untouched bit for bit.
//!
//! **Null-space damping of faded levels.** A faded level no longer damps the motion it
//! controlled (the self-motion the levels above it leave free). In its place, level i
//! adds the joint damping c_i M q̇ projected into the null space of the levels above
//! it with the dynamically consistent projector,
//!
//! τ_N,i = −c_i Nᵀ_i M N_i q̇ = −c_i (M q̇ − J_augᵀ G⁻¹ J_aug q̇),  G = J_aug M⁻¹ J_augᵀ
//!
//! (eq. 8; N_i = I − M⁻¹ J_augᵀ G⁻¹ J_aug), with c_i = (1 − min(β_i, β(r_i))) ·
//! `null_space_damping`, where β(r_i) is the fade function of the level's own
//! conditioning r_i (`StepOutput::conditioning`): a level in an algorithmic singularity
//! (Λ_i = Z_i M Z_iᵀ singular) keeps its torque but no longer controls the
//! direction it lost, which is damped in its place.
//! J_aug M⁻¹ τ_N,i = 0: the levels above are not disturbed, and its power
//! −c_i (q̇ᵀ M q̇ − ẋ_augᵀ G⁻¹ ẋ_aug) ≤ 0 — also with the damped inverse (G + δI)⁻¹ ≤ G⁺
//! that is used where G is singular, since ẋᵀ G⁺ ẋ ≤ q̇ᵀ M q̇ for ẋ = J_aug q̇.
//!
//! **Passivity damping.** The paper's law is passive only conditionally (Sec. IV,
//! Proposition 1): level i's projected spring–damper (eqs. 20, 21) can feed energy
//! into the arm while the levels above it still move, and stops doing so once they
//! have converged. In free motion they do; held at a joint limit (the guard, or an
//! end stop) level 1 cannot converge, and the exchange can keep an oscillation going
//! for good — the storage E rising in every swing although every damper dissipates.
//! With the hierarchy's power into E
//!
//! P_h = q̇ᵀ (Σ_i τ_i + τ_μ) + Σ_i β_i (∂V_i/∂x_i) J_i q̇
//!
//! (the dampers' dissipation included; a moving goal's work left out, and while a
//! goal moves nothing is counted), the energy the hierarchy may feed in is
//! budgeted: after a goal or gains change (and once a moving goal stands) the
//! budget is `passivity_budget` plus [`PASSIVITY_TRANSIENT_SHARE`] of E — the
//! sequential convergence of Sec. IV feeds energy while it lasts (the paper's
//! simulations 9 % and 21 % of their E, within 0.25 s) — and that share decays
//! with [`PASSIVITY_TRANSIENT_TIME`]. Each cycle with P_h > 0 pays P_h T from it.
//! As the last half of `passivity_budget` ([`PASSIVITY_ONSET`]) runs out, a
//! growing share w P_h (w the smoothstep of the spent fraction: no torque jump)
//! is damped out instead — first in the null space of level 1 with the
//! dynamically consistent projector, −α (M q̇ − J_1ᵀ G⁻¹ J_1 q̇), then, as far as
//! the motion is level 1's own, over the whole arm, −α' M q̇; α, α' ≤
//! `passivity_damping_rate`. Once the budget is spent, E no longer grows but by
//! what the rate cap leaves; the equilibria are the law's. A regular hierarchy
//! (P_h ≤ 0, or within the budget) is untouched bit for bit.
//!
//! **Joint-limit guard.** A dissipative safety layer below the hierarchy (not a task of
//! it): within `joint_limit_margin` of a URDF position limit, with penetration
//! p = q − (upper − margin) (resp. (lower + margin) − q) ≥ 0, the joint gets the
//! spring torque k p² (k = torque / (margin/2)², `torque` = `joint_limit_torque` or the
//! URDF effort limit, i.e. the effort limit at half the margin and four times it at the
//! limit) and the damping −s(p/(0.1 margin)) · min(2ζ √(2 k p · m_k), m_k / T) q̇ — the
//! damping ratio ζ against the spring's local stiffness 2 k p, brought in over the
//! first tenth of the margin ([`GUARD_RAMP`]) — with s the smoothstep,
//! m_k = 1/(M⁻¹)_kk the joint's effective inertia and T the control period (a damping
//! above m_k / T is more than the sampled loop carries, crate::rate). Both vanish with
//! their first derivative at p = 0: no torque jump and no torque-rate jump at
//! activation. The spring has the potential k p³/3 (in [`SafetyOutput::guard_potential`]).
//!
//! **Velocity limits: the spring saturation.** A large task error pulls hard, and
//! the damper D_i lets a level settle at the task speed D_i⁻¹ ∂V_i/∂x_i. Each level's
//! potential is therefore replaced beyond the radius r_0,i by its linear extension
//! (a Huber function of r = √(2 V_i)):
//!
//! V_i,sat = V_i for r ≤ r_0,  r_0 r − r_0²/2 beyond,  ∂V_i,sat/∂x_i = min(1, r_0/r) ∂V_i/∂x_i,
//!
//! with r_0,i = d_min(D_i) v_i / √λ_max(K_i), so that ‖∂V_i,sat/∂x_i‖ ≤ d_min v_i:
//! the speed the damper settles at is at most v_i, the task speed whose
//! least-squares joint velocity J_i⁺ ẋ_i keeps every joint within f_full of its
//! velocity limit at the initial configuration (computed at construction).
//! V_i,sat is a potential (the force keeps its direction and is its gradient), so
//! the paper's passivity argument holds unchanged with S_i (eqs. 26, 28) built on V_i,sat, and
//! the equilibria are the law's. V_i,sat is C¹ and its force continuous in the
//! state (no torque jump; crossing r_0 only bends the torque's rate; at t = 0 it
//! only lowers the initial torque). Without a finite velocity limit (the
//! paper's planar arm) r_0 = ∞ and nothing changes.
//!
//! **Velocity limits: the governor.** The dynamics can still carry a joint faster
//! (inertia shifting between joints, several levels adding up): near a velocity
//! limit the springs stop driving the motion. With x_k = (|q̇_k| − f_on v_k) / ((f_full − f_on) v_k) (f_on =
//! `velocity_limit_fraction`, f_full = `velocity_limit_full_fraction`, v_k the URDF
//! velocity limit), the gain g = 1 − Π_k (1 − s(x_k)) ∈ [0, 1] (0 below f_on, 1 as
//! soon as one joint is at f_full) scales the spring force of each level,
//!
//! F_i = σ_i ∂V_i/∂x_i + D_i ẋ_i (in τ_i of eqs. 20, 21),  σ_i = 1 − g · s(c_i / c_0),
//!
//! where c_i = −q̇ᵀ J_iᵀ ∂V_i/∂x_i / (‖J_iᵀ ∂V_i/∂x_i‖ ‖q̇‖) is the cosine between the
//! motion and the spring's torque ([`GOVERNOR_COSINE`] = c_0): only a spring that
//! drives the motion (its potential falls, ẋ_iᵀ ∂V_i/∂x_i < 0) is scaled, one that
//! brakes or acts across the motion is kept. What the spring no longer puts into
//! motion, (1 − σ_i) ẋ_iᵀ ∂V_i/∂x_i ≤ 0, leaves the storage Σ S_i (for level 1
//! exactly: d/dt (½ q̇ᵀMq̇ + V_1) gains (1 − σ_1) ẋ_1ᵀ ∂V_1/∂x_1 ≤ 0); it goes to the
//! fade's tank with the dampers' dissipation. The dampers D_i are untouched and
//! brake. s is the smoothstep, so σ_i is C¹ in q̇ with σ_i = 1, σ̇_i = 0 at the onset:
//! no torque jump and no torque-rate jump. The equilibria are the law's (σ_i = 1 at
//! rest), and below f_on of every limit nothing changes (bit for bit).
//!
//! **Velocity limits: the damping.** A joint in the band is also damped,
//! −s(x_k) · `velocity_damping` · m_k q̇_k (default 100 1/s, 0 switches it off):
//! dissipative and C¹ at the onset.
//!
//! **Velocity limits: the barrier.** Governor and damping act on the speed; the
//! barrier on what the law's torque is about to do to it. With the acceleration
//! the law's torque τ produces on the model, q̈ = M⁻¹ (τ − C q̇ − g), a joint k in the
//! band (x_k > 0) may accelerate away from rest (sign(q̇_k) q̈_k) at most at
//!
//! a_k = min(α h_k, √(2 (R/m_k) h_k)),  h_k = f_full v_k − |q̇_k|,
//!
//! (α = `velocity_barrier_rate`; R the torque filter's rate limit when there is
//! one: the applied torque, and with it the acceleration, changes at most at R/m_k
//! per second, and braking from a_k at that jerk gains a_k² m_k/(2R) ≤ h_k of speed).
//! The excess Δ_k is removed by −s(x_k) m_k Δ_k sign(q̇_k): it only ever opposes the
//! motion (power ≤ 0), scaled in by the smoothstep (no torque jump), zero below
//! f_on (bit for bit).
//!
//! Allocation-free after `Safety::new`.

use crate::ControlError;
use hcc_linalg::products::gemv;
use hcc_linalg::spd::{SpdWork, damped_spd_inverse_only};
use hcc_model::Model;
use nalgebra::{DMatrix, DVector};

/// Configuration of the safety layer (see the module docs). The defaults are on and
/// act only near singularities and limits.
#[derive(Clone, Debug, PartialEq)]
pub struct SafetySpec {
    /// Master switch (off: the paper's law alone, with the plain fade).
    pub enabled: bool,
    /// Distance from a URDF position limit at which the guard starts (rad or m), > 0.
    pub joint_limit_margin: f64,
    /// Guard spring torque at half the margin (N·m or N); `None`: the URDF effort
    /// limit, or 100 where the URDF gives none.
    pub joint_limit_torque: Option<f64>,
    /// Damping ratio ζ of the guard (against its spring's local stiffness), ≥ 0.
    pub joint_limit_damping_ratio: f64,
    /// Fraction f_on of the URDF velocity limit at which the velocity governor
    /// (and the velocity damping) comes in, in (0, 1).
    pub velocity_limit_fraction: f64,
    /// Fraction f_full of the URDF velocity limit at which the velocity governor
    /// (and the velocity damping) is fully on, in (f_on, 1].
    pub velocity_limit_full_fraction: f64,
    /// The spring saturation: each level's spring force is capped so that the speed
    /// its damper settles at stays under f_on of the joint velocity limits (module
    /// docs).
    pub spring_saturation: bool,
    /// The velocity governor: between f_on and f_full of a joint's velocity limit
    /// the levels' springs stop driving the motion (module docs).
    pub velocity_governor: bool,
    /// Velocity-limit joint damping rate (1/s; the torque is this times m_k q̇_k
    /// at f_full), ≥ 0; 0 switches it off.
    pub velocity_damping: f64,
    /// The velocity barrier: above f_on of a joint's velocity limit the
    /// acceleration the law asks of it away from rest is held at most at
    /// α (f_full v_k − |q̇_k|) (module docs).
    pub velocity_barrier: bool,
    /// The barrier's rate α (1/s), > 0; α·T ≤ 1 at the control period T.
    pub velocity_barrier_rate: f64,
    /// Null-space damping rate of fully faded levels (1/s), ≥ 0.
    pub null_space_damping: f64,
    /// The conflict fade: a level i ≥ 2 whose own Λ_i is near-singular (an
    /// algorithmic conflict with the levels above) fades by its own conditioning r_i,
    /// fully off at r_i ≤ this ratio ε_c and untouched from 100 ε_c up, with the
    /// null-space damping in its place (module docs); in [0, 0.01), 0 switches it off.
    pub conflict_fade_ratio: f64,
    /// Capacity of the energy tank that pays fade-ins (J), ≥ 0.
    pub fade_tank_max: f64,
    /// The passivity damping: once the hierarchy has fed `passivity_budget`
    /// into the storage E since the last goal or gains change, what it feeds in
    /// more is damped out in the null space of level 1 (module docs).
    pub passivity_damping: bool,
    /// Energy (J) the hierarchy may feed into E after a goal or gains change
    /// before the passivity damping acts (on top of a decaying share of E for
    /// the transient, module docs), ≥ 0.
    pub passivity_budget: f64,
    /// The passivity damping's largest rate (1/s), > 0; rate · T ≤ 1.
    pub passivity_damping_rate: f64,
    /// Control period (s), for the energy the tank collects per cycle, > 0.
    pub control_period_s: f64,
    /// The rate limit R (N·m/s per joint) of the torque filter that follows the
    /// law (`[torque_filter] torque_rate_limit`; `None`: no limit). The applied
    /// torque follows the law's at most at R, so a joint's acceleration changes
    /// at most at R / m_k: the velocity barrier brakes early enough for that
    /// (module docs). Set by the scenario loader from the torque filter.
    pub torque_rate_limit: Option<f64>,
}

impl Default for SafetySpec {
    fn default() -> Self {
        SafetySpec {
            enabled: true,
            joint_limit_margin: 0.1,
            joint_limit_torque: None,
            joint_limit_damping_ratio: 1.0,
            velocity_limit_fraction: 0.6,
            velocity_limit_full_fraction: 0.9,
            spring_saturation: false,
            velocity_governor: true,
            velocity_damping: 100.0,
            velocity_barrier: true,
            velocity_barrier_rate: 20.0,
            null_space_damping: 20.0,
            conflict_fade_ratio: 1e-5,
            fade_tank_max: 5.0,
            passivity_damping: true,
            passivity_budget: 0.25,
            passivity_damping_rate: 50.0,
            control_period_s: 1e-3,
            torque_rate_limit: None,
        }
    }
}

impl SafetySpec {
    /// Checks the ranges (errors name the field).
    pub fn validate(&self) -> Result<(), ControlError> {
        let bad = |f: &str, why: &str| Err(ControlError::Spec(format!("safety.{f} {why}")));
        let pos = |x: f64| x > 0.0 && x.is_finite();
        let nonneg = |x: f64| x >= 0.0 && x.is_finite();
        if !pos(self.joint_limit_margin) {
            return bad("joint_limit_margin", "must be positive");
        }
        if let Some(t) = self.joint_limit_torque
            && !pos(t)
        {
            return bad("joint_limit_torque", "must be positive");
        }
        if !nonneg(self.joint_limit_damping_ratio) {
            return bad("joint_limit_damping_ratio", "must be non-negative");
        }
        if !(self.velocity_limit_fraction > 0.0 && self.velocity_limit_fraction < 1.0) {
            return bad("velocity_limit_fraction", "must be in (0, 1)");
        }
        if !(self.velocity_limit_full_fraction > self.velocity_limit_fraction
            && self.velocity_limit_full_fraction <= 1.0)
        {
            return bad(
                "velocity_limit_full_fraction",
                "must be in (velocity_limit_fraction, 1]",
            );
        }
        // The rates act on the joint's own inertia m_k: rate · T ≤ 1 is what the
        // control period carries (crate::rate; b = rate · T).
        let t = self.control_period_s;
        // A rate (1/s): ≥ 0 (> 0 where `positive`), and at most 1/T.
        let rate = |f: &str, x: f64, positive: bool| {
            if positive && !pos(x) {
                bad(f, "must be positive")
            } else if !nonneg(x) {
                bad(f, "must be non-negative")
            } else if x * t > 1.0 {
                bad(
                    f,
                    "times the control period must be at most 1 (the rate the loop carries)",
                )
            } else {
                Ok(())
            }
        };
        rate("velocity_damping", self.velocity_damping, false)?;
        rate("velocity_barrier_rate", self.velocity_barrier_rate, true)?;
        rate("null_space_damping", self.null_space_damping, false)?;
        rate("passivity_damping_rate", self.passivity_damping_rate, true)?;
        if !(nonneg(self.conflict_fade_ratio) && self.conflict_fade_ratio < 0.01) {
            return bad("conflict_fade_ratio", "must be in [0, 0.01)");
        }
        if !nonneg(self.fade_tank_max) {
            return bad("fade_tank_max", "must be non-negative");
        }
        if !nonneg(self.passivity_budget) {
            return bad("passivity_budget", "must be non-negative");
        }
        if !pos(self.control_period_s) {
            return bad("control_period_s", "must be positive");
        }
        if let Some(r) = self.torque_rate_limit
            && !pos(r)
        {
            return bad("torque_rate_limit", "must be positive");
        }
        Ok(())
    }
}

/// What the safety layer did in the last cycle (part of [`crate::StepOutput`]).
#[derive(Clone, Debug)]
pub struct SafetyOutput {
    /// τ_safety: null-space damping + passivity damping + joint-limit guard +
    /// velocity damping, added to τ.
    pub tau: DVector<f64>,
    /// Any of its parts acted in this cycle (else `tau` is zero and τ untouched).
    pub active: bool,
    /// The joint-limit guard acted (a joint within the margin of a limit).
    pub joint_limit_active: bool,
    /// The velocity governor scaled a spring or the velocity damping acted (a joint
    /// above f_on of its velocity limit).
    pub velocity_limit_active: bool,
    /// A level's spring force was capped by the spring saturation in this cycle.
    pub spring_saturated: bool,
    /// Cycles in which the spring saturation acted, since construction.
    pub spring_saturated_cycles: u64,
    /// The governor's gain g ∈ [0, 1] of this cycle (0: the springs untouched).
    pub velocity_governor: f64,
    /// Per level: the factor σ_i its spring force was scaled by (1: untouched).
    pub spring_scale: Vec<f64>,
    /// τ_barrier of this cycle (module docs; zero where it does not act,
    /// included in `tau`).
    pub barrier_tau: DVector<f64>,
    /// The velocity barrier acted in this cycle.
    pub barrier_active: bool,
    /// Cycles in which the velocity barrier acted, since construction.
    pub barrier_cycles: u64,
    /// A faded level's null-space damping acted.
    pub null_space_damping_active: bool,
    /// The conflict fade lowered a level's β_i(q) in this cycle (its own Λ_i
    /// near-singular).
    pub conflict_fade_active: bool,
    /// Cycles in which the conflict fade acted, since construction.
    pub conflict_fade_cycles: u64,
    /// Cycles in which the guard acted, since construction.
    pub joint_limit_cycles: u64,
    /// Cycles in which the governor or the velocity damping acted, since construction.
    pub velocity_limit_cycles: u64,
    /// Cycles in which a fade-in was held back by an empty tank, since construction.
    pub fade_in_limited_cycles: u64,
    /// Energy in the tank that pays fade-ins (J).
    pub tank: f64,
    /// The hierarchy's power into E (W; module docs, "Passivity damping").
    pub hierarchy_power: f64,
    /// What is left of the passivity budget (J).
    pub passivity_budget: f64,
    /// The passivity damping acted in this cycle.
    pub passivity_active: bool,
    /// Cycles in which the passivity damping acted, since construction.
    pub passivity_cycles: u64,
    /// Potential of the guard springs, Σ k p³/3 (J).
    pub guard_potential: f64,
    /// E = ½ q̇ᵀ M q̇ + V_1 + Σ β_i V_i + guard potential (J; module docs).
    pub energy: f64,
    /// q̇ᵀ τ_safety (W): ≤ 0 but for the guard spring's exchange with its potential.
    pub power: f64,
}

impl SafetyOutput {
    pub(crate) fn new(n: usize, levels: usize) -> SafetyOutput {
        SafetyOutput {
            tau: DVector::zeros(n),
            barrier_tau: DVector::zeros(n),
            barrier_active: false,
            barrier_cycles: 0,
            active: false,
            joint_limit_active: false,
            velocity_limit_active: false,
            spring_saturated: false,
            spring_saturated_cycles: 0,
            velocity_governor: 0.0,
            spring_scale: vec![1.0; levels],
            null_space_damping_active: false,
            conflict_fade_active: false,
            conflict_fade_cycles: 0,
            joint_limit_cycles: 0,
            velocity_limit_cycles: 0,
            fade_in_limited_cycles: 0,
            tank: 0.0,
            hierarchy_power: 0.0,
            passivity_budget: 0.0,
            passivity_active: false,
            passivity_cycles: 0,
            guard_potential: 0.0,
            energy: 0.0,
            power: 0.0,
        }
    }
}

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
    /// the radius r_0,i of the saturated potential (module docs).
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
/// velocity governor scales that spring fully (module docs).
pub const GOVERNOR_COSINE: f64 = 0.25;

/// The velocity governor's factor σ_i = 1 − g · s(c_i / [`GOVERNOR_COSINE`]) of a
/// level's spring force (module docs): `g` the governor's gain, `power` =
/// ẋ_iᵀ ∂V_i/∂x_i = q̇ᵀ J_iᵀ ∂V_i/∂x_i (the rate of V_i), `torque_norm` =
/// ‖J_iᵀ ∂V_i/∂x_i‖, `speed` = ‖q̇‖, c_i = −power / (torque_norm · speed).
/// 1 exactly when g = 0 or the spring does not drive the motion (power ≥ 0).
pub(crate) fn spring_scale(g: f64, power: f64, torque_norm: f64, speed: f64) -> f64 {
    // `!(power < 0.0)` also catches a NaN power.
    if g <= 0.0 || power >= 0.0 || power.is_nan() {
        return 1.0;
    }
    let denom = torque_norm * speed;
    if denom.is_nan() || denom <= 0.0 {
        return 1.0;
    }
    1.0 - g * smoothstep(-power / denom / GOVERNOR_COSINE)
}

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

    /// The spring saturation's task speed of each level from its Jacobian `j` at the
    /// initial configuration: v_i = f_full · min_k v_k / ‖(J_i⁺)_k‖, the largest task
    /// speed whose least-squares joint velocity J_i⁺ ẋ_i keeps every joint k within
    /// f_full of its velocity limit v_k, whatever the direction of ẋ_i (∞ without a
    /// finite velocity limit or with the saturation off). Allocates (construction).
    pub(crate) fn set_task_speeds(&mut self, jacobians: &[&DMatrix<f64>]) {
        for (i, &j) in jacobians.iter().enumerate() {
            let mut v = f64::INFINITY;
            if self.spec.enabled
                && self.spec.spring_saturation
                && let Ok(pinv) = j.clone().pseudo_inverse(1e-9)
            {
                for (k, &vk) in self.velocity_limit.iter().enumerate() {
                    let row = pinv.row(k).norm();
                    if vk.is_finite() && row > 0.0 {
                        v = v.min(self.spec.velocity_limit_full_fraction * vk / row);
                    }
                }
            }
            self.task_speed[i] = v;
        }
    }

    /// r_0,i = F_max,i / √λ_max(K_i) with F_max,i = d_min(D_i) · v_i, for the gains
    /// `stiffness`, `damping` of level `i` (λ_max bounded by the largest absolute row
    /// sum, d_min the smallest diagonal entry). Allocation-free (also for
    /// `set_gains`).
    pub(crate) fn set_spring_radius(
        &mut self,
        i: usize,
        stiffness: &DMatrix<f64>,
        damping: &DMatrix<f64>,
    ) {
        let v = self.task_speed[i];
        if !v.is_finite() {
            self.spring_radius[i] = f64::INFINITY;
            return;
        }
        let m = stiffness.nrows();
        let mut kmax: f64 = 0.0;
        for a in 0..m {
            let mut row = 0.0;
            for b in 0..m {
                row += stiffness[(a, b)].abs();
            }
            kmax = kmax.max(row);
        }
        let dmin = (0..damping.nrows())
            .map(|a| damping[(a, a)])
            .fold(f64::INFINITY, f64::min);
        self.spring_radius[i] = if kmax > 0.0 && dmin > 0.0 {
            dmin * v / kmax.sqrt()
        } else {
            f64::INFINITY
        };
    }

    /// The spring saturation of level `i` (module docs): with r = √(2 V_i) beyond
    /// r_0,i, the gradient `grad` is scaled by r_0/r in place and the saturated
    /// potential r_0 r − r_0²/2 returned; else V_i unchanged. Returns (V, scale).
    pub(crate) fn saturate_spring(
        &self,
        i: usize,
        potential: f64,
        grad: &mut DVector<f64>,
    ) -> (f64, f64) {
        let r0 = self.spring_radius[i];
        if !r0.is_finite() {
            return (potential, 1.0);
        }
        let r = (2.0 * potential.max(0.0)).sqrt();
        if r <= r0 {
            return (potential, 1.0);
        }
        let scale = r0 / r;
        *grad *= scale;
        (r0 * r - 0.5 * r0 * r0, scale)
    }

    /// Forgets the fade memory (the next cycle takes β(q) as it is) and empties the tank.
    /// Level `i` has a new goal: a conflict it was faded for may be over.
    pub(crate) fn release_conflict(&mut self, i: usize) {
        if let Some(l) = self.conflict_latched.get_mut(i) {
            *l = false;
        }
    }

    pub(crate) fn reset(&mut self) {
        self.has_prev = false;
        self.governor_prev = 0.0;
        self.conflict_latched.fill(false);
        self.tank = 0.0;
        self.fill_power = 0.0;
        self.refill_passivity_budget();
    }

    /// A goal or gains changed: the hierarchy may feed `passivity_budget` into E
    /// again before the passivity damping acts.
    pub(crate) fn refill_passivity_budget(&mut self) {
        self.budget = f64::NAN;
    }

    /// The effective β_i of the last cycle (1 before the first).
    pub(crate) fn last_fade(&self, i: usize) -> f64 {
        if self.has_prev {
            self.beta_prev[i]
        } else {
            1.0
        }
    }

    /// The passive fade (module docs): `fade` holds β_i(q) on entry and the effective
    /// β_i on return; `potential` V_i; `damper_dissipation` Σ β_i ẋ_iᵀ D_i ẋ_i (W);
    /// `conditioning` r_i of each level's own inversions, for the conflict fade
    /// β_i(q) ← min(β_i(q), β_c(r_i)).
    pub(crate) fn passive_fade(
        &mut self,
        fade: &mut [f64],
        potential: &[f64],
        damper_dissipation: f64,
        conditioning: &[f64],
        out: &mut SafetyOutput,
    ) {
        if !self.spec.enabled {
            return;
        }
        let eps_c = self.spec.conflict_fade_ratio;
        out.conflict_fade_active = false;
        if eps_c > 0.0 {
            // The conflict fade: a level whose own Λ_i (eq. 18) is near-singular has
            // lost a direction to the levels above; its spring fades with r_i.
            let release = CONFLICT_RELEASE_FACTOR * crate::FADE_RANGE * eps_c;
            for i in 1..fade.len() {
                let own = crate::fade::fade_factor(conditioning[i], eps_c);
                if own < fade[i] {
                    fade[i] = own;
                    out.conflict_fade_active = true;
                }
                // The conflict is over only well out of its fade region (or
                // with a new goal: `release_conflict`).
                if own < 1.0 {
                    self.conflict_latched[i] = true;
                } else if conditioning[i] >= release {
                    self.conflict_latched[i] = false;
                }
            }
        }
        out.conflict_fade_cycles += u64::from(out.conflict_fade_active);
        if !self.has_prev {
            self.beta_prev.copy_from_slice(fade);
            self.has_prev = true;
        }
        let fill = (self.fill_power + damper_dissipation.max(0.0)) * self.spec.control_period_s;
        let mut tank = self.tank + fill.max(0.0);
        let mut limited = false;
        for i in 1..fade.len() {
            let (prev, v) = (self.beta_prev[i], potential[i].max(0.0));
            // Hysteresis: a faded level comes back only once it has left the fade
            // region (β(q) = 1), and then in at least 1 / FADE_IN_RATE s — no
            // relaxation cycles at the edge of the fade region.
            // A level faded for a conflict comes back only once the conflict
            // is over (its latch released): else its spring, back in, pulls the
            // arm into the conflict again, and it fades out again, over and over.
            let want = if fade[i] < 1.0 || self.conflict_latched[i] {
                fade[i].min(prev)
            } else {
                (prev + FADE_IN_RATE * self.spec.control_period_s).min(1.0)
            };
            let beta = if want <= prev {
                // Fade-out: the spring energy (β_prev − β) V_i leaves E for the tank.
                tank += (prev - want) * v;
                want
            } else if (want - prev) * v <= tank {
                tank -= (want - prev) * v;
                want
            } else {
                // Fade-in as far as the tank pays.
                limited = true;
                let b = prev + tank / v;
                tank = 0.0;
                b
            };
            fade[i] = beta;
            self.beta_prev[i] = beta;
        }
        self.tank = tank.min(self.spec.fade_tank_max);
        out.tank = self.tank;
        out.fade_in_limited_cycles += u64::from(limited);
    }

    /// τ_safety of this cycle into `out` (module docs); `out.active` says whether it
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
        let mut potential = c.potential.first().copied().unwrap_or(0.0);
        for i in 1..c.potential.len() {
            potential += c.fade[i] * c.potential[i];
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
        out.energy = kinetic + potential + out.guard_potential;
    }

    /// τ_N,i = −c_i (M q̇ − J_augᵀ G⁻¹ J_aug q̇) for every faded level i ≥ 2.
    fn null_space_damping(&mut self, c: &CycleTerms, out: &mut SafetyOutput) {
        let rate = self.spec.null_space_damping;
        if rate == 0.0 {
            return;
        }
        for i in 1..c.fade.len() {
            // Faded, or singular itself (Λ_i, eq. 18): the motion it no longer controls.
            let own = crate::fade::fade_factor(c.conditioning[i], c.singular_ratio);
            let beta = c.fade[i].min(own);
            if beta >= 1.0 {
                continue;
            }
            self.project_above(i, c);
            let ci = (1.0 - beta) * rate;
            let p = self.add_null_space_damping(ci, c, out);
            self.fill_power += p;
            out.null_space_damping_active = true;
        }
    }

    /// y = G⁻¹ J_aug q̇ (damped inverse where G is singular) for the levels
    /// above level `i`, and from it `null_momentum` = M q̇ − J_augᵀ y.
    fn project_above(&mut self, i: usize, c: &CycleTerms) {
        let ktop = c.jtop.nrows();
        let k = self.k_above[i].min(ktop);
        if !self.xdot_fresh {
            gemv(&mut self.xdot, 1.0, c.jtop, c.qd, 0.0);
            self.xdot_fresh = true;
        }
        let g = &mut self.g[i];
        for a in 0..k {
            for b in 0..k {
                g[(a, b)] = c.w[(a, b)];
            }
        }
        damped_spd_inverse_only(
            g,
            &mut self.g_inv[i],
            &mut self.spd[i],
            c.singular_ratio,
            1e-12,
        );
        for a in 0..k {
            let mut s = 0.0;
            for b in 0..k {
                s += self.g_inv[i][(a, b)] * self.xdot[b];
            }
            self.y[a] = s;
        }
        for col in 0..c.qd.len() {
            let mut jty = 0.0;
            for a in 0..k {
                jty += c.jtop[(a, col)] * self.y[a];
            }
            self.null_momentum[col] = self.mqd[col] - jty;
        }
    }

    /// Adds −rate (M q̇ − J_augᵀ y) (after [`Safety::project_above`]) to
    /// `out.tau`; returns the power it removes, rate (q̇ᵀ M q̇ − ẋ_augᵀ G⁻¹ ẋ_aug) ≥ 0.
    fn add_null_space_damping(&self, rate: f64, c: &CycleTerms, out: &mut SafetyOutput) -> f64 {
        let mut p = 0.0;
        for col in 0..c.qd.len() {
            let t = -rate * self.null_momentum[col];
            out.tau[col] += t;
            p -= t * c.qd[col];
        }
        p.max(0.0)
    }

    /// 2 × the kinetic energy in the null space of the levels above (after
    /// [`Safety::project_above`]): q̇ᵀ M q̇ − ẋ_augᵀ G⁻¹ ẋ_aug ≥ 0.
    fn null_space_kinetic2(&self, c: &CycleTerms) -> f64 {
        let mut s = 0.0;
        for col in 0..c.qd.len() {
            s += c.qd[col] * self.null_momentum[col];
        }
        s.max(0.0)
    }

    /// The passivity damping (module docs): the hierarchy's power into E is paid
    /// from the budget; what the budget does not cover is damped out in the null
    /// space of level 1, at most at `passivity_damping_rate`.
    /// `energy`: E of this cycle (J).
    fn passivity(&mut self, c: &CycleTerms, energy: f64, out: &mut SafetyOutput) {
        if !self.spec.passivity_damping || c.fade.len() < 2 {
            return;
        }
        if c.goal_moving {
            // A moving goal works on the arm; the law is judged once it stands.
            self.refill_passivity_budget();
        }
        let t = self.spec.control_period_s;
        let base = self.spec.passivity_budget;
        if self.budget.is_nan() {
            // Refilled: the budget and a share of the storage for the transient.
            self.budget = base + PASSIVITY_TRANSIENT_SHARE * energy.max(0.0);
        } else if self.budget > base {
            // The transient's share decays: what is above the budget proper.
            self.budget = base + (self.budget - base) * (-t / PASSIVITY_TRANSIENT_TIME).exp();
        }
        let p = c.hierarchy_power;
        // A NaN power counts as none.
        if c.goal_moving || p.is_nan() || p <= 0.0 {
            return;
        }
        // The damping takes over as the budget's last half runs out, smoothly
        // (no torque jump): it pays w p, the budget (1 − w) p.
        let soft = PASSIVITY_ONSET * base;
        let w = if self.budget >= soft {
            0.0
        } else if soft > 0.0 {
            smoothstep(1.0 - self.budget / soft)
        } else {
            1.0
        };
        self.budget = (self.budget - (1.0 - w) * p * t).max(0.0);
        let excess = w * p;
        if excess.is_nan() || excess <= 0.0 {
            return;
        }
        // Not to the fade's tank: this is the energy the hierarchy fed in.
        let cap = self.spec.passivity_damping_rate;
        self.project_above(1, c);
        let k2 = self.null_space_kinetic2(c);
        let mut left = excess;
        if k2 > 0.0 {
            let rate = (excess / k2).min(cap);
            left -= self.add_null_space_damping(rate, c, out);
            out.passivity_active = true;
        }
        // What the null space of level 1 cannot take (the motion is level 1's
        // own): the whole arm's −α M q̇, power −α q̇ᵀ M q̇.
        let kinetic2 = c.qd.dot(&self.mqd);
        if left > 0.0 && kinetic2 > 0.0 {
            let rate = (left / kinetic2).min(cap);
            for col in 0..c.qd.len() {
                out.tau[col] -= rate * self.mqd[col];
            }
            out.passivity_active = true;
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

    /// Whether the velocity barrier needs the acceleration of this cycle: it is
    /// on and a joint is above f_on of its velocity limit, or a torque rate
    /// limit follows (then a hard acceleration below the band counts too).
    pub(crate) fn barrier_needs_acceleration(&self, qd: &DVector<f64>) -> bool {
        self.spec.enabled
            && self.spec.velocity_barrier
            && (self.spec.torque_rate_limit.is_some()
                || (0..qd.len()).any(|k| self.speed_band(k) > 0.0))
    }

    /// The speed each joint reaches (`reach`, module docs) at this cycle's
    /// state: |q̇_k|, plus, with a torque rate limit R and the applied torque's
    /// acceleration q̈_a driving it away from rest, the a² M_kk / (2R) it gains
    /// while the applied torque brakes at the rate limit (M_kk ≥ m_k: an
    /// upper bound). Call once per cycle before the other parts. Allocation-free.
    pub(crate) fn set_reach(
        &mut self,
        qd: &DVector<f64>,
        applied_qdd: Option<&DVector<f64>>,
        chol: &DMatrix<f64>,
    ) {
        for k in 0..qd.len() {
            let mut v = qd[k].abs();
            if let (Some(rate), Some(qa)) = (self.spec.torque_rate_limit, applied_qdd)
                && self.spec.enabled
            {
                let a = qd[k].signum() * qa[k];
                if a > 0.0 {
                    v += a * a * diagonal_of_llt(chol, k) / (2.0 * rate);
                }
            }
            self.reach[k] = v;
        }
    }

    /// Position of the joint's reach (`set_reach`) in the velocity band: 0 at
    /// f_on · v_max, 1 at f_full · v_max (not clamped; 0 for a joint without a
    /// velocity limit).
    fn speed_band(&self, k: usize) -> f64 {
        let qd = self.reach[k];
        let vmax = self.velocity_limit[k];
        if !vmax.is_finite() {
            return 0.0;
        }
        let (on, full) = (
            self.spec.velocity_limit_fraction,
            self.spec.velocity_limit_full_fraction,
        );
        (qd.abs() - on * vmax) / ((full - on) * vmax)
    }

    /// The velocity governor's gain g = 1 − Π_k (1 − s(x_k)) of this cycle (module
    /// docs): 0 while every joint is below f_on of its velocity limit (or the
    /// governor is off), 1 once one is at f_full; C¹ in q̇.
    pub(crate) fn governor_gain(&mut self, qd: &DVector<f64>) -> f64 {
        if !self.spec.enabled || !self.spec.velocity_governor {
            return 0.0;
        }
        let mut keep = 1.0;
        for k in 0..qd.len() {
            let x = self.speed_band(k);
            if x > 0.0 {
                keep *= 1.0 - smoothstep(x);
            }
        }
        // It follows a rise at once and falls at most at GOVERNOR_RELEASE_RATE:
        // an arm swinging through the band keeps its springs held back
        // instead of switching them on and off every few cycles.
        let release = GOVERNOR_RELEASE_RATE * self.spec.control_period_s;
        let g = (1.0 - keep).max(self.governor_prev - release).max(0.0);
        self.governor_prev = g;
        g
    }

    /// The velocity barrier (module docs): for every joint above f_on of its
    /// velocity limit whose predicted acceleration `qdd` (the law's torque on
    /// the model, M⁻¹ (τ − C q̇ − g)) drives it faster than α (f_full v_k −
    /// |q̇_k|), the torque m_k Δ_k sign(q̇_k) that removes the excess Δ_k
    /// (scaled in by the smoothstep of the band) into `out.barrier_tau`, and
    /// added to `out.tau`. Returns whether it acted. Allocation-free.
    pub(crate) fn velocity_barrier(
        &mut self,
        qd: &DVector<f64>,
        qdd: &DVector<f64>,
        applied_qdd: Option<&DVector<f64>>,
        chol: &DMatrix<f64>,
        out: &mut SafetyOutput,
    ) -> bool {
        if out.barrier_active {
            out.barrier_tau.fill(0.0);
        }
        out.barrier_active = false;
        if !(self.spec.enabled && self.spec.velocity_barrier) {
            return false;
        }
        let (alpha, full) = (
            self.spec.velocity_barrier_rate,
            self.spec.velocity_limit_full_fraction,
        );
        for k in 0..qd.len() {
            if !self.velocity_limit[k].is_finite() {
                continue;
            }
            let sign = qd[k].signum();
            // Acceleration away from rest, and the speed left below f_full v_k.
            let a = sign * qdd[k];
            let headroom = full * self.velocity_limit[k] - qd[k].abs();
            let x = self.speed_band(k);
            let mut m_k = None;
            let mut excess: f64 = 0.0;
            if x > 0.0 {
                let m = self.effective_inertia(chol, k);
                m_k = Some(m);
                excess = smoothstep(x) * (a - alpha * headroom);
            }
            // The applied torque lags the law's behind the rate limit: brake for
            // the faster of the two.
            let a_jerk = applied_qdd.map_or(a, |qa| a.max(sign * qa[k]));
            if let Some(rate) = self.spec.torque_rate_limit
                && a_jerk > 0.0
                && a_jerk * a_jerk * diagonal_of_llt(chol, k) > 2.0 * rate * headroom
            {
                // m_k ≤ M_kk: only a joint that might not stop in time gets its m_k.
                let m = *m_k.get_or_insert_with(|| self.effective_inertia(chol, k));
                excess = excess.max(a_jerk - (2.0 * rate / m * headroom.max(0.0)).sqrt());
            }
            if excess.is_nan() || excess <= 0.0 {
                continue;
            }
            let t = -sign * m_k.unwrap_or(0.0) * excess;
            out.barrier_tau[k] = t;
            out.tau[k] += t;
            out.barrier_active = true;
        }
        if out.barrier_active {
            out.active = true;
            out.velocity_limit_active = true;
            out.barrier_cycles += 1;
            out.power += out.barrier_tau.dot(qd);
        }
        out.barrier_active
    }

    /// The joint-limit guard and the velocity damping.
    fn joint_limits(&mut self, c: &CycleTerms, out: &mut SafetyOutput) {
        let margin = self.spec.joint_limit_margin;
        for k in 0..c.q.len() {
            let (q, qd) = (c.q[k], c.qd[k]);
            // Penetration into the margin (positive: towards the upper limit).
            let up = q - (self.upper[k] - margin);
            let lo = (self.lower[k] + margin) - q;
            let (p, sign) = if up > 0.0 {
                (up, 1.0)
            } else if lo > 0.0 {
                (lo, -1.0)
            } else {
                (0.0, 0.0)
            };
            // The velocity damping acts only when switched on (rate > 0).
            let x = if self.spec.velocity_damping > 0.0 {
                self.speed_band(k)
            } else {
                0.0
            };
            if p <= 0.0 && x <= 0.0 {
                continue;
            }
            let m_k = self.effective_inertia(c.chol, k);
            if p > 0.0 {
                let kg = self.k_guard[k];
                // At most m_k / T: a heavier damping than the joint's own inertia
                // carries at the control period would drive an oscillation
                // (crate::rate, b ≤ 1).
                // The damping ratio ζ against the spring's local stiffness 2 k p
                // wherever it is deeper than GUARD_RAMP · margin (a joint resting
                // shallow in the margin is damped as well as a deep one).
                let d = (self.spec.joint_limit_damping_ratio * 2.0 * (2.0 * kg * p * m_k).sqrt())
                    .min(m_k / self.spec.control_period_s);
                out.tau[k] += -sign * kg * p * p - smoothstep(p / (GUARD_RAMP * margin)) * d * qd;
                out.guard_potential += kg * p * p * p / 3.0;
                out.joint_limit_active = true;
            }
            if x > 0.0 {
                out.tau[k] -= smoothstep(x) * self.spec.velocity_damping * m_k * qd;
                out.velocity_limit_active = true;
            }
        }
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

    #[test]
    fn bad_values_are_refused_with_the_field() {
        let mut s = SafetySpec::default();
        assert!(s.validate().is_ok());
        s.joint_limit_margin = 0.0;
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("joint_limit_margin"), "{e}");
        let s = SafetySpec {
            velocity_limit_fraction: 1.0,
            ..Default::default()
        };
        assert!(
            s.validate()
                .unwrap_err()
                .to_string()
                .contains("velocity_limit_fraction")
        );
        let s = SafetySpec {
            joint_limit_torque: Some(f64::NAN),
            ..Default::default()
        };
        assert!(s.validate().is_err());
        for bad in [-1e-6, 0.01, f64::NAN] {
            let s = SafetySpec {
                conflict_fade_ratio: bad,
                ..Default::default()
            };
            let e = s.validate().unwrap_err().to_string();
            assert!(e.contains("conflict_fade_ratio"), "{e}");
        }
    }
}
