//! Plain description of a task hierarchy: what the configuration produces and
//! [`crate::Controller::new`] consumes.

use hcc_model::FrameId;
use nalgebra::{DMatrix, DVector};

/// The task of one priority level, x_i = f_i(q) with Jacobian J_i (eq. 2).
#[derive(Clone, Debug, PartialEq)]
pub enum TaskSpec {
    /// Position of a frame origin along the listed world axes (0 = x, 1 = y, 2 = z).
    /// V = ½ x̃ᵀ K x̃. Goal: the positions (m).
    Position { frame: FrameId, axes: Vec<usize> },
    /// Full orientation of a frame. Quaternion potential V = 2 εᵀ K ε, where (η, ε) is
    /// the unit quaternion of R_dᵀ R with η ≥ 0 (K in the goal frame's axes); its
    /// conjugate to the world angular velocity is R_d · 2(ηI + [ε]×) K ε. Goal:
    /// roll, pitch, yaw (rad, R_d = Rz(yaw) Ry(pitch) Rx(roll)).
    Orientation { frame: FrameId },
    /// Rotation angle of a frame about one world axis (planar robots: the sum of the
    /// joint angles for the paper's arm). V = ½ K θ̃², θ̃ wrapped to (−π, π].
    PlanarOrientation { frame: FrameId, axis: usize },
    /// Positions of the listed joints (0-based). V = ½ q̃ᵀ K q̃.
    Joints { indices: Vec<usize> },
    /// A linear combination of joints, x = W q (W is m×n), e.g. q1+q2+q3+q4.
    JointCombination { weights: DMatrix<f64> },
    /// The whole joint vector (posture).
    Posture,
}

/// One priority level: task, spring, damper and virtual equilibrium.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelSpec {
    /// Name used in messages.
    pub name: String,
    pub task: TaskSpec,
    /// K_i, symmetric positive definite, m_i × m_i.
    pub stiffness: DMatrix<f64>,
    /// D_i, symmetric positive definite, m_i × m_i.
    pub damping: DMatrix<f64>,
    /// x_{i,d}.
    pub goal: DVector<f64>,
}

/// How the null-space torques are formed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Form {
    /// The paper's form τ_i = −J̄_iᵀ Z_i J_iᵀ F_i (eq. 21).
    #[default]
    Extended,
    /// The classical projector form τ_i = −N_i J_iᵀ F_i (eqs. 8, 9), a cross-check.
    ClassicalProjector,
}

/// The whole controller.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerSpec {
    /// Levels in priority order (index 0 = level 1, the highest).
    pub levels: Vec<LevelSpec>,
    /// Add g(q) to the command (eq. 19). Off for robots whose driver adds gravity.
    pub gravity_compensation: bool,
    /// The power-conserving cancellation τ_μ (eq. 22). Off only for the ablation.
    pub coriolis_cancellation: bool,
    pub form: Form,
    /// Eigenvalue ratio of a Gram matrix (J M⁻¹ Jᵀ, J Jᵀ, Z M Zᵀ) below which the
    /// inversion is damped and the level flagged singular.
    pub singular_ratio: f64,
}

impl ControllerSpec {
    /// A spec with the paper's defaults: gravity compensation, τ_μ on, eq. (21).
    pub fn new(levels: Vec<LevelSpec>) -> ControllerSpec {
        ControllerSpec {
            levels,
            gravity_compensation: true,
            coriolis_cancellation: true,
            form: Form::Extended,
            singular_ratio: 1e-6,
        }
    }
}
