//! The hierarchical compliance controller of Dietrich, Ott & Albu-Schäffer,
//! "Multi-Objective Compliance Control of Redundant Manipulators: Hierarchy,
//! Control, and Stability" (IROS 2013), as a library a 1 kHz loop calls.
//!
//! A hierarchy of r levels, each a spring–damper task x_i = f_i(q) with
//! stiffness K_i, damping D_i and goal x_{i,d} ([`spec`]). Per cycle
//! ([`Controller::step`]):
//! - the local null-space velocities v_i = J̄_i q̇ (eq. 3) with J̄_1 = J_1 and the
//!   dynamically consistent J̄_i = (Z_i M Z_iᵀ)⁻¹ Z_i M (eq. 5), Z_i = J_i M⁻¹ N_i
//!   (eq. 11, equal to eq. 12) with the projector of eq. (8),
//!   N_i = I − J_augᵀ (J_aug M⁻¹ J_augᵀ)⁻¹ J_aug M⁻¹, for 2 ≤ i < r — k-dimensional
//!   blocks of one stacked J M⁻¹ Jᵀ, no n × n projector and no basis — and
//!   Z_r = V_{r−1}ᵀ for the lowest level, V_{r−1} an orthonormal basis of the null
//!   space of the augmented Jacobian (eq. 6);
//! - the block-diagonal inertia Λ_i (eqs. 16, 18) and the Coriolis matrix μ (eq. 17),
//!   with J̄̇ computed analytically from J̇_i, Ṁ = C + Cᵀ, d/dt M⁻¹ = −M⁻¹ Ṁ M⁻¹ and
//!   the parallel-transport derivative of the basis, V̇ = −J⁺ J̇ V;
//! - τ = Σ τ_i + τ_μ + g (eq. 19) with τ_1 = −J_1ᵀ F_1 (eq. 20),
//!   τ_i = −J̄_iᵀ Z_i J_iᵀ F_i (eq. 21), F_i = ∂V_i/∂x_iᵀ + D_i ẋ_i, and the
//!   power-conserving τ_μ = Σ_i J̄_iᵀ Σ_{j≠i} μ_ij v_j (eq. 22).
//!
//! **Tracking.** A level may track a desired x_{i,d}(t) with ẋ_{i,d}, ẍ_{i,d}
//! ([`Controller::set_goal_acceleration`]): the desired local velocities
//! v_{i,d} = J̄_i q̇_d are formed level by level and the feed-forward
//! J̄_iᵀ (Λ_i v̇_{i,d} + μ_ii v_{i,d}) makes each level's error follow
//! Λ_i ṽ̇_i + μ_ii ṽ_i + Z_i J_iᵀ F_i = 0 (docs/tracking.md); with no moving goal
//! it is the law above, bit for bit.
//!
//! **Levels of several tasks.** A level stacks the rows of its tasks ([`TaskSpec`],
//! e.g. the 6-D [`TaskSpec::Pose`] or a position and an orientation): x_i, J_i and
//! J̇_i are stacked, V_i = ½ eᵀ K_i e over the stacked errors (e = 2ε on quaternion
//! rows), K_i and D_i are m_i × m_i over the stacked coordinates; everything above
//! holds for the stacked level. [`task::jacobian`] assembles J_i (one routine for the
//! law and the recorders).
//!
//! **Comparison form.** [`Form::KinematicProjector`] (for comparison only, r = 2) is
//! the common Cartesian impedance law τ = −J_1ᵀ F_1 + (I − J_1ᵀ (J_1ᵀ)⁺) τ_2 + C q̇,
//! with the Moore–Penrose pseudo-inverse and no τ_μ: its posture torque disturbs
//! level 1 (J_1 M⁻¹ τ_2 ≠ 0), which eqs. (5), (21) avoid.
//!
//! **Basis continuity.** Z_i for i < r does not depend on a basis (only on the
//! subspace, eq. 11), but Z_r = V_{r−1}ᵀ does, and a QR basis is not a
//! continuous function of q. Each cycle the previous basis is therefore projected onto
//! the new null space, W = (I − J⁺J) V_prev, and orthonormalised by its polar factor —
//! the orthonormal basis of the new null space closest to V_prev (the orthogonal
//! Procrustes solution), a first-order approximation of parallel transport whose
//! derivative V̇ = −J⁺ J̇ V is the one used in J̄̇, so no derivative ever straddles a
//! sign flip. It also stays continuous where the augmented Jacobian loses rank. The
//! first cycle (and the one after [`Controller::reset`], for a jump of the state)
//! takes a Householder QR basis, which is deterministic for a given q.
//!
//! **Singularities.** Every Gram matrix that is inverted (J_1 M⁻¹ J_1ᵀ,
//! J_aug M⁻¹ J_augᵀ, J_aug J_augᵀ, Z_i M Z_iᵀ) goes through a damped inverse
//! `(A + δI)⁻¹` whose damping δ rises smoothly from 0 as the eigenvalue ratio
//! λ_min/λ_max falls below
//! `singular_ratio` (damped least squares on the Gram matrix). Away from
//! singularities the law is exact; near one the torques stay finite and bounded and
//! [`StepOutput::singular`] flags the level. The strict hierarchy and the zero power of τ_μ
//! are then only approximate, and the damped null-space projections of the lower
//! levels are no longer passive: near a singularity they can feed energy into the
//! self-motion (an arm pulled straight whips round). So the lower levels' torques and
//! τ_μ **fade out** inside the singular region: level i ≥ 2 is scaled by β of the
//! eigenvalue ratio of J_aug M⁻¹ J_augᵀ (resp. J_aug J_augᵀ for the lowest level) of
//! the levels above it — the inversion its projection depends on — and τ_μ by the
//! product of β over every level's ratio, where β rises smoothly (a smoothstep on the
//! log scale) from 0 at `singular_ratio` to 1 at [`FADE_RANGE`] × `singular_ratio`
//! ([`StepOutput::fade`], [`StepOutput::fade_mu`]). In the singular region the robot is
//! then held by level 1, τ_1 = −J_1ᵀ F_1, which involves no inversion and is passive
//! (with gravity compensation the energy ½ q̇ᵀ M q̇ + V_1 cannot grow), and the lower
//! tasks resume as it is left. Away from singularities every β_j is exactly 1 and the
//! law is the paper's. The safety layer ([`safety`]) makes the fade passive and also
//! fades a level whose own Λ_i (eq. 18) turns singular (the conflict fade).
//!
//! **Allocation.** [`Controller::new`] allocates every buffer (an own
//! `hcc_model::Data` included); [`Controller::step`] allocates nothing. M⁻¹ is never
//! formed: it is applied by Cholesky solves.

pub mod brake_certificate;
pub mod contact;
pub mod controller;
pub mod energy_tank;
mod fade;
pub mod rate;
pub mod safety;
pub mod saturation;
pub mod spec;
pub mod task;
pub mod transition;
pub mod velocity_limit;

pub use brake_certificate::{BrakeModel, BrakeWork, limit_velocity_rate_limited};
pub use contact::{ContactChange, ContactDetector, MomentumObserver, ObserverInput, observe};
pub use controller::{CommandInput, Controller, Diagnostics, LevelTarget, StepOutput};
pub use fade::FADE_RANGE;
pub use rate::GainRate;
pub use safety::{SafetyOutput, SafetySpec};
pub use saturation::saturate;
pub use spec::{ControllerSpec, Form, LevelSpec, SpecError, TaskSpec, TaskUnit};
pub use velocity_limit::{VelocityLimitOutcome, VelocityLimitWork, limit_velocity};

/// Errors of construction and of a cycle.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// A level of the hierarchy is invalid (which level and why).
    #[error("level {level}: {why}")]
    Level { level: String, why: String },
    /// The hierarchy as a whole is invalid.
    #[error("{0}")]
    Spec(String),
    /// A cycle's input was rejected (the output is left untouched).
    #[error("input rejected: {0}")]
    BadInput(&'static str),
    /// A numerical failure in a cycle (τ falls back to g, or 0).
    #[error("numerical failure: {0}")]
    Numerical(&'static str),
}

impl From<SpecError> for ControlError {
    fn from(e: SpecError) -> Self {
        match e {
            SpecError::Level { level, why } => ControlError::Level { level, why },
            SpecError::Spec(s) => ControlError::Spec(s),
        }
    }
}
