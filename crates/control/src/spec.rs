//! Plain description of a task hierarchy: what the configuration produces and
//! [`crate::Controller::new`] consumes.

use crate::ControlError;
use hcc_model::{FrameId, Model};
use nalgebra::{DMatrix, DVector};

/// The task of one priority level, x_i = f_i(q) with Jacobian J_i (eq. 2).
#[derive(Clone, Debug, PartialEq)]
pub enum TaskSpec {
    /// Position of a frame origin along the listed world axes (0 = x, 1 = y, 2 = z).
    /// V = ½ x̃ᵀ K x̃. Goal: the positions (m).
    Position { frame: FrameId, axes: Vec<usize> },
    /// Full orientation of a frame. Quaternion potential V = 2 εᵀ K ε, where (η, ε) is
    /// the unit quaternion of R_dᵀ R with η ≥ 0 (K in the goal frame's axes); its
    /// conjugate to the world angular velocity is R_d · 2(ηI + \[ε\]×) K ε. Goal:
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
    /// The safety layer: passive fade, null-space damping of faded levels, joint
    /// position and velocity limits ([`crate::safety`]).
    pub safety: crate::safety::SafetySpec,
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
            safety: crate::safety::SafetySpec::default(),
        }
    }

    /// Task dimension m_i of every level for a robot with `n` joints (eq. 2).
    pub fn task_dims(&self, n: usize) -> Vec<usize> {
        self.levels
            .iter()
            .map(|l| match &l.task {
                TaskSpec::Position { axes, .. } => axes.len(),
                TaskSpec::Orientation { .. } => 3,
                TaskSpec::PlanarOrientation { .. } => 1,
                TaskSpec::Joints { indices } => indices.len(),
                TaskSpec::JointCombination { weights } => weights.nrows(),
                TaskSpec::Posture => n,
            })
            .collect()
    }

    /// Checks of the hierarchy that need no configuration: frames and joint indices
    /// exist, goals, K_i and D_i have the task's dimension, K_i and D_i are symmetric
    /// positive definite, Σ_{j<r} m_j < n, `singular_ratio` in (0, 1). The rank checks
    /// at a configuration are [`crate::Controller::new`]'s. Errors name the level
    /// (1-based, with its name) and the reason.
    pub fn validate(&self, model: &Model) -> Result<(), ControlError> {
        let n = model.nq();
        let r = self.levels.len();
        if r == 0 {
            return Err(ControlError::Spec("the hierarchy has no level".into()));
        }
        if !(self.singular_ratio > 0.0 && self.singular_ratio < 1.0) {
            return Err(ControlError::Spec(
                "singular_ratio must be in (0, 1)".into(),
            ));
        }
        let dims = self.task_dims(n);
        for (i, l) in self.levels.iter().enumerate() {
            let m = dims[i];
            let bad = |why: String| ControlError::Level {
                level: format!("{} ({})", i + 1, l.name),
                why,
            };
            if m == 0 {
                return Err(bad("the task has dimension 0".into()));
            }
            match &l.task {
                TaskSpec::Position { frame, axes } => {
                    if *frame >= model.frames.len() {
                        return Err(bad(format!("unknown frame index {frame}")));
                    }
                    for (a, ax) in axes.iter().enumerate() {
                        if *ax > 2 || axes[..a].contains(ax) {
                            return Err(bad("position axes must be distinct values 0..=2".into()));
                        }
                    }
                }
                TaskSpec::Orientation { frame } | TaskSpec::PlanarOrientation { frame, .. } => {
                    if *frame >= model.frames.len() {
                        return Err(bad(format!("unknown frame index {frame}")));
                    }
                    if let TaskSpec::PlanarOrientation { axis, .. } = &l.task
                        && *axis > 2
                    {
                        return Err(bad("planar orientation axis must be 0..=2".into()));
                    }
                }
                TaskSpec::Joints { indices } => {
                    for (a, ix) in indices.iter().enumerate() {
                        if *ix >= n || indices[..a].contains(ix) {
                            return Err(bad(format!(
                                "joint indices must be distinct values below {n}"
                            )));
                        }
                    }
                }
                TaskSpec::JointCombination { weights } => {
                    if weights.ncols() != n || weights.iter().any(|x| !x.is_finite()) {
                        return Err(bad(format!("weights must be finite, with {n} columns")));
                    }
                }
                TaskSpec::Posture => {}
            }
            let goal_len = m;
            if l.goal.len() != goal_len || l.goal.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!(
                    "goal must be {goal_len} finite values, got {}",
                    l.goal.len()
                )));
            }
            let name = format!("{} ({})", i + 1, l.name);
            check_spd(&name, "stiffness", &l.stiffness, m)?;
            check_spd(&name, "damping", &l.damping, m)?;
        }
        let above: usize = dims[..r - 1].iter().sum();
        if r > 1 && above >= n {
            return Err(ControlError::Spec(format!(
                "the levels above the lowest have {above} task dimensions in all; they must be fewer than the {n} joints (Σ_{{j<r}} m_j < n)"
            )));
        }

        Ok(())
    }
}

fn check_spd(name: &str, what: &str, a: &DMatrix<f64>, m: usize) -> Result<(), ControlError> {
    let bad = |why: String| ControlError::Level {
        level: name.to_string(),
        why: format!("{what}: {why}"),
    };
    if a.shape() != (m, m) {
        return Err(bad(format!(
            "must be {m}×{m}, is {}×{}",
            a.nrows(),
            a.ncols()
        )));
    }
    if a.iter().any(|x| !x.is_finite()) {
        return Err(bad("has a non-finite entry".into()));
    }
    let scale = a.amax().max(1e-300);
    for i in 0..m {
        for j in 0..i {
            if (a[(i, j)] - a[(j, i)]).abs() > 1e-9 * scale {
                return Err(bad(format!(
                    "is not symmetric (entry ({}, {}))",
                    i + 1,
                    j + 1
                )));
            }
        }
    }
    let mut c = a.clone();
    hcc_model::linalg::cholesky_in_place(&mut c)
        .map_err(|_| bad("is not positive definite".into()))?;
    Ok(())
}
