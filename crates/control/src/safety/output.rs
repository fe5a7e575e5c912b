//! What the safety layer did in a cycle ([`SafetyOutput`], part of
//! [`crate::StepOutput`]): its torque, which mechanisms acted, their counters,
//! the fade's tank, the passivity budget and the storage E.

use nalgebra::DVector;

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
    /// τ_barrier of this cycle ([`super::velocity_barrier`]; zero where it does not act,
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
    /// The hierarchy's power into E (W; [`super::passivity`]).
    pub hierarchy_power: f64,
    /// What is left of the passivity budget (J).
    pub passivity_budget: f64,
    /// The passivity damping acted in this cycle.
    pub passivity_active: bool,
    /// Cycles in which the passivity damping acted, since construction.
    pub passivity_cycles: u64,
    /// Potential of the guard springs, Σ k p³/3 (J).
    pub guard_potential: f64,
    /// E = ½ q̇ᵀ M q̇ + V_1 + Σ β_i V_i + guard potential (J; [`super::passive_fade`]).
    pub energy: f64,
    /// Per level, its potential as E counts it: V_1, β_i V_i for i ≥ 2 (J).
    pub level_potential: Vec<f64>,
    /// H = E + T + Σ E_i: the storage of the arm and the controller together,
    /// the fade's tank and the levels' energy tanks (crate::energy_tank) included (J). Without external input it can rise only by what the
    /// controller injects: the measure of passivity.
    pub h: f64,
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
            level_potential: vec![0.0; levels],
            h: 0.0,
            power: 0.0,
        }
    }
}
