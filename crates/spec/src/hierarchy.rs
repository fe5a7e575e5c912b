//! Plain description of a task hierarchy: what the configuration produces and
//! the law (`hcc_control::Controller::new`) consumes.

use crate::SpecError;
use hcc_model::{FrameId, Model};
use nalgebra::{DMatrix, DVector};

/// Unit of a task coordinate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskUnit {
    /// Metres.
    Length,
    /// Radians.
    Angle,
}

/// One task, x = f(q) with Jacobian J (eq. 2). A level stacks one or more of them.
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
    /// Position and orientation of a frame (6-D): the rows of a `Position` task on all
    /// three axes followed by those of an `Orientation` task. Goal: x, y, z, roll,
    /// pitch, yaw; J = the frame Jacobian (linear rows, then angular rows).
    Pose { frame: FrameId },
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

impl TaskSpec {
    /// The task's kind, as the scenario service names it.
    pub fn kind(&self) -> &'static str {
        match self {
            TaskSpec::Position { .. } => "position",
            TaskSpec::Orientation { .. } => "orientation",
            TaskSpec::Pose { .. } => "pose",
            TaskSpec::PlanarOrientation { .. } => "planar_orientation",
            TaskSpec::Joints { .. } => "joint",
            TaskSpec::JointCombination { .. } => "joint_combination",
            TaskSpec::Posture => "posture",
        }
    }

    /// Task dimension m for a robot with `n` joints.
    pub fn dim(&self, n: usize) -> usize {
        match self {
            TaskSpec::Position { axes, .. } => axes.len(),
            TaskSpec::Orientation { .. } => 3,
            TaskSpec::Pose { .. } => 6,
            TaskSpec::PlanarOrientation { .. } => 1,
            TaskSpec::Joints { indices } => indices.len(),
            TaskSpec::JointCombination { weights } => weights.nrows(),
            TaskSpec::Posture => n,
        }
    }

    /// Unit of the task coordinate `row` (0-based).
    pub fn unit(&self, row: usize) -> TaskUnit {
        match self {
            TaskSpec::Position { .. } => TaskUnit::Length,
            TaskSpec::Pose { .. } if row < 3 => TaskUnit::Length,
            _ => TaskUnit::Angle,
        }
    }

    /// The frame of a Cartesian task.
    pub fn frame(&self) -> Option<FrameId> {
        match self {
            TaskSpec::Position { frame, .. }
            | TaskSpec::Orientation { frame }
            | TaskSpec::Pose { frame }
            | TaskSpec::PlanarOrientation { frame, .. } => Some(*frame),
            _ => None,
        }
    }

    /// Whether the task has quaternion orientation rows (rows 0..3 of `Orientation`,
    /// 3..6 of `Pose`): their offset within the task.
    pub fn quaternion_rows(&self) -> Option<usize> {
        match self {
            TaskSpec::Orientation { .. } => Some(0),
            TaskSpec::Pose { .. } => Some(3),
            _ => None,
        }
    }

    /// Checks that need no configuration: frames and joint indices exist, axes are distinct.
    fn check(&self, model: &Model) -> Result<(), String> {
        let n = model.nq();
        if let Some(frame) = self.frame()
            && frame >= model.frames.len()
        {
            return Err(format!("unknown frame index {frame}"));
        }
        match self {
            TaskSpec::Position { axes, .. } => {
                for (a, ax) in axes.iter().enumerate() {
                    if *ax > 2 || axes[..a].contains(ax) {
                        return Err("position axes must be distinct values 0..=2".into());
                    }
                }
            }
            TaskSpec::PlanarOrientation { axis, .. } if *axis > 2 => {
                return Err("planar orientation axis must be 0..=2".into());
            }
            TaskSpec::Joints { indices } => {
                for (a, ix) in indices.iter().enumerate() {
                    if *ix >= n || indices[..a].contains(ix) {
                        return Err(format!("joint indices must be distinct values below {n}"));
                    }
                }
            }
            TaskSpec::JointCombination { weights }
                if weights.ncols() != n || weights.iter().any(|x| !x.is_finite()) =>
            {
                return Err(format!("weights must be finite, with {n} columns"));
            }
            _ => {}
        }
        Ok(())
    }
}

/// One priority level: its tasks, spring, damper and virtual equilibrium. The level's
/// coordinates x_i stack the rows of its tasks in order (so do J_i and J̇_i); its
/// potential V_i = ½ eᵀ K_i e over the stacked coordinate errors e (for quaternion
/// rows e = 2ε, which gives the orientation potential 2 εᵀ K ε), which is the sum of
/// the tasks' potentials when K_i is block-diagonal.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelSpec {
    /// Name used in messages.
    pub name: String,
    /// The stacked tasks (at least one).
    pub tasks: Vec<TaskSpec>,
    /// K_i, symmetric positive definite, m_i × m_i over the stacked coordinates.
    pub stiffness: DMatrix<f64>,
    /// D_i, symmetric positive definite, m_i × m_i over the stacked coordinates.
    pub damping: DMatrix<f64>,
    /// x_{i,d}, the tasks' goals stacked.
    pub goal: DVector<f64>,
}

impl LevelSpec {
    /// A level of one task.
    pub fn single(
        name: impl Into<String>,
        task: TaskSpec,
        stiffness: DMatrix<f64>,
        damping: DMatrix<f64>,
        goal: DVector<f64>,
    ) -> LevelSpec {
        LevelSpec {
            name: name.into(),
            tasks: vec![task],
            stiffness,
            damping,
            goal,
        }
    }

    /// Task dimension m_i (the sum over the stacked tasks) for `n` joints.
    pub fn dim(&self, n: usize) -> usize {
        self.tasks.iter().map(|t| t.dim(n)).sum()
    }

    /// Unit of every stacked coordinate.
    pub fn units(&self, n: usize) -> Vec<TaskUnit> {
        self.tasks
            .iter()
            .flat_map(|t| (0..t.dim(n)).map(move |r| t.unit(r)))
            .collect()
    }

    /// The unit of the level's coordinates when they all share one (`None`: mixed).
    pub fn unit(&self, n: usize) -> Option<TaskUnit> {
        let u = self.units(n);
        u.first().copied().filter(|f| u.iter().all(|x| x == f))
    }
}

/// How the null-space torques are formed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Form {
    /// The paper's form τ_i = −J̄_iᵀ Z_i J_iᵀ F_i (eq. 21).
    #[default]
    Extended,
    /// The classical projector form τ_i = −N_i J_iᵀ F_i (eqs. 8, 9), a cross-check.
    #[serde(rename = "projector")]
    ClassicalProjector,
    /// For comparison only: the law of the widespread Cartesian impedance controller
    /// with a null-space posture, τ = −J_1ᵀ F_1 + (I − J_1ᵀ (J_1ᵀ)⁺) τ_2 + C q̇ (+ g),
    /// τ_2 = −J_2ᵀ F_2, with the Moore–Penrose pseudo-inverse (J_1ᵀ)⁺ = (J_1 J_1ᵀ)⁻¹ J_1
    /// — a kinematic, not dynamically consistent, projector — and no τ_μ. Requires
    /// exactly two levels (r = 2). The posture torque then disturbs level 1:
    /// J_1 M⁻¹ τ_2 ≠ 0.
    KinematicProjector,
}

impl Form {
    /// The name used in scenario files and reports.
    pub fn name(self) -> &'static str {
        match self {
            Form::Extended => "extended",
            Form::ClassicalProjector => "projector",
            Form::KinematicProjector => "kinematic_projector",
        }
    }
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
    /// position and velocity limits (`hcc_control::safety`).
    pub safety: crate::SafetySpec,
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
            safety: crate::SafetySpec::default(),
        }
    }

    /// Task dimension m_i of every level for a robot with `n` joints (eq. 2).
    pub fn task_dims(&self, n: usize) -> Vec<usize> {
        self.levels.iter().map(|l| l.dim(n)).collect()
    }

    /// The level at whose frame the contact wrench is estimated
    /// (F̂ = pinv(J_iᵀ) r, hcc-cycle): the first level whose tasks are all
    /// [`TaskSpec::Position`] or [`TaskSpec::Pose`], so that its rows are
    /// forces along world axes (and, for a pose, moments about them); `None`
    /// when no level is.
    pub fn wrench_level(&self) -> Option<usize> {
        self.levels.iter().position(|l| {
            !l.tasks.is_empty()
                && l.tasks
                    .iter()
                    .all(|t| matches!(t, TaskSpec::Position { .. } | TaskSpec::Pose { .. }))
        })
    }

    /// Checks of the hierarchy that need no configuration: frames and joint indices
    /// exist, goals, K_i and D_i have the task's dimension, K_i and D_i are symmetric
    /// positive definite, Σ_{j<r} m_j < n, `singular_ratio` in (0, 1), two levels
    /// for [`Form::KinematicProjector`]. The rank checks
    /// at a configuration are the law's (`hcc_control::Controller::new`). Errors name the level
    /// (1-based, with its name) and the reason.
    pub fn validate(&self, model: &Model) -> Result<(), SpecError> {
        let n = model.nq();
        let r = self.levels.len();
        if r == 0 {
            return Err(SpecError::Spec("the hierarchy has no level".into()));
        }
        if !(self.singular_ratio > 0.0 && self.singular_ratio < 1.0) {
            return Err(SpecError::Spec("singular_ratio must be in (0, 1)".into()));
        }
        if self.form == Form::KinematicProjector && r != 2 {
            return Err(SpecError::Spec(format!(
                "the kinematic projector form needs exactly two levels (a task and a posture in its null space), not {r}"
            )));
        }
        let dims = self.task_dims(n);
        for (i, l) in self.levels.iter().enumerate() {
            let m = dims[i];
            let bad = |why: String| SpecError::Level {
                level: format!("{} ({})", i + 1, l.name),
                why,
            };
            if l.tasks.is_empty() {
                return Err(bad("the level has no task".into()));
            }
            if m == 0 {
                return Err(bad("the task has dimension 0".into()));
            }
            for t in &l.tasks {
                t.check(model).map_err(bad)?;
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
            return Err(SpecError::Spec(format!(
                "the levels above the lowest have {above} task dimensions in all; they must be fewer than the {n} joints (Σ_{{j<r}} m_j < n)"
            )));
        }

        Ok(())
    }
}

fn check_spd(name: &str, what: &str, a: &DMatrix<f64>, m: usize) -> Result<(), SpecError> {
    let bad = |why: String| SpecError::Level {
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
