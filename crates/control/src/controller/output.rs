//! What a cycle hands back: [`StepOutput`] (τ of eq. 19 and its parts τ_i of
//! eqs. 20, 21 and τ_μ of eq. 22, v_i of eq. 3, the storages S_i of eqs. 26, 28,
//! the singularity flags and fades, the safety layer's report) and a level's
//! current spring–damper target, [`LevelTarget`].

use nalgebra::{DMatrix, DVector};

/// What one control cycle produced (all preallocated; valid after [`Controller::step`](super::Controller::step)).
#[derive(Clone, Debug)]
pub struct StepOutput {
    /// τ = Σ τ_i + τ_μ + g (eq. 19); g only with gravity compensation (and,
    /// when the driver compensates the arm's gravity, the load's alone:
    /// [`StepOutput::gravity_load`]).
    pub tau: DVector<f64>,
    /// τ_i of each level (eqs. 20, 21).
    pub tau_level: Vec<DVector<f64>>,
    /// τ_μ (eq. 22); zero when the cancellation is off.
    pub tau_mu: DVector<f64>,
    /// The tracking form's feed-forward Σ_i J̄_iᵀ (Λ_i v̇_{i,d} + μ_ii v_{i,d})
    /// (`controller/tracking.rs`; zero, and not added, while no level tracks).
    pub tau_feed_forward: DVector<f64>,
    /// g(q) (also when it is not added to τ).
    pub gravity: DVector<f64>,
    /// The load's own gravity torque −J_cᵀ m g₀ (hcc_model::load_gravity),
    /// added to τ when the driver compensates the arm's gravity but not the
    /// load's ([`StepOutput::load_gravity_in_tau`]); zero otherwise.
    pub gravity_load: DVector<f64>,
    /// Whether τ carries [`StepOutput::gravity_load`]: the driver compensates
    /// gravity (no gravity compensation here) and the model carries a load.
    pub load_gravity_in_tau: bool,
    /// x_i − x_{i,d} per level (orientation: 2·R_d·ε ≈ the rotation vector, world axes).
    pub task_error: Vec<DVector<f64>>,
    /// v_i = J̄_i q̇ (eq. 3); the lowest level has n − Σ_{j<r} m_j entries.
    pub v: Vec<DVector<f64>>,
    /// V_i(x̃_i), the potential of each level.
    pub potential: Vec<f64>,
    /// S_i = ½ v_iᵀ Λ_i v_i + V_i (eqs. 26, 28).
    pub storage: Vec<f64>,
    /// P_μ = τ_μᵀ q̇ (zero in theory).
    pub p_mu: f64,
    /// Per level: an inversion of this level was damped (kinematic or algorithmic singularity).
    pub singular: Vec<bool>,
    /// Any level singular.
    pub any_singular: bool,
    /// Per level: the smallest eigenvalue ratio of the Gram matrices inverted for it.
    pub conditioning: Vec<f64>,
    /// Per level: the factor its torque was scaled by as the Gram matrix of the levels
    /// above it becomes singular (always 1 for level 1, and away from singularities;
    /// see the crate docs, "Singularities").
    pub fade: Vec<f64>,
    /// The factor τ_μ was scaled by (it fades with the conditioning of every level).
    pub fade_mu: f64,
    /// Per level: the energy E_i in its energy tank (J; crate::energy_tank; 0 for
    /// level 1, which has none, and with the tanks off).
    pub tank: Vec<f64>,
    /// Per level: its tank's valve β_i ∈ [0, 1] of this cycle (1: the paper's
    /// law; 0: the spring point follows what the levels above do to it).
    pub tank_valve: Vec<f64>,
    /// What the commands put into the storage H this cycle: the moving
    /// goals' power −Σ_i β_i ẋ_{i,d}ᵀ F_i (W; their work on the springs and
    /// dampers, β_i the level's fade times the law's share) plus the tracking
    /// feed-forward's q̇ᵀ τ_ff, both over the coming period (unless the
    /// command tank pays them), what a refill put into the energy tanks and
    /// a grant into the command tank at this cycle's sample ([`CommandInput`]).
    pub command_input: CommandInput,
    /// C(q, q̇) q̇, added to τ by [`Form::KinematicProjector`](crate::Form::KinematicProjector) only (zero otherwise).
    pub coriolis: DVector<f64>,
    /// Safety layer (crate::safety): its torque (added to τ only when it acts), what
    /// acted, counters, the fade's energy tank and the total energy E.
    pub safety: crate::safety::SafetyOutput,
}

impl StepOutput {
    pub(super) fn new(n: usize, dims: &[usize], v_dims: &[usize]) -> StepOutput {
        let r = dims.len();
        StepOutput {
            tau: DVector::zeros(n),
            tau_level: (0..r).map(|_| DVector::zeros(n)).collect(),
            tau_mu: DVector::zeros(n),
            tau_feed_forward: DVector::zeros(n),
            gravity: DVector::zeros(n),
            gravity_load: DVector::zeros(n),
            load_gravity_in_tau: false,
            task_error: dims.iter().map(|&m| DVector::zeros(m)).collect(),
            v: v_dims.iter().map(|&d| DVector::zeros(d)).collect(),
            potential: vec![0.0; r],
            storage: vec![0.0; r],
            p_mu: 0.0,
            singular: vec![false; r],
            any_singular: false,
            conditioning: vec![1.0; r],
            fade: vec![1.0; r],
            fade_mu: 1.0,
            tank: vec![0.0; r],
            tank_valve: vec![1.0; r],
            command_input: CommandInput::default(),
            coriolis: DVector::zeros(n),
            safety: crate::safety::SafetyOutput::new(n, r),
        }
    }
}

/// What a command put into the storage H in one cycle
/// ([`StepOutput::command_input`]): with no command, all zero.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CommandInput {
    /// −Σ_i β_i ẋ_{i,d}ᵀ F_i, the moving goals' power over the coming period
    /// (W; the spring's share with V_i's whole gradient where the velocity
    /// governor scales it in F_i).
    pub goal_power: f64,
    /// q̇ᵀ τ_ff, the tracking feed-forward's power over the coming period (W).
    pub feed_forward_power: f64,
    /// What the energy tanks' refill added at this cycle's sample (J).
    pub refill: f64,
    /// What the command tank was granted at this cycle's sample (J; a goal
    /// setpoint taken: `Controller::grant_goal_step`).
    pub granted: f64,
    /// The command tank E_c at this cycle's sample (J; counted in H).
    pub tank: f64,
    /// The command tank pays the goals' and the feed-forward's work of the
    /// coming period (a transition runs): it is then no input of H.
    pub paid: bool,
}

/// A level's current spring–damper target ([`Controller::level_target`](super::Controller::level_target)).
#[derive(Clone, Copy, Debug)]
pub struct LevelTarget<'a> {
    /// x_{i,d} (roll, pitch, yaw for an orientation task).
    pub goal: &'a [f64],
    /// ẋ_{i,d} (zero for a fixed goal).
    pub goal_velocity: &'a [f64],
    /// K_i.
    pub stiffness: &'a DMatrix<f64>,
    /// D_i.
    pub damping: &'a DMatrix<f64>,
}
