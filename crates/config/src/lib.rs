//! Scenario configuration of the hierarchical compliance controller (Dietrich,
//! Ott & Albu-Schäffer, IROS 2013): one TOML file describes the robot, the task
//! hierarchy (levels in priority order with stiffness K_i, damping D_i and
//! virtual equilibrium x_{i,d}, eqs. 20–21), the controller options, the initial
//! state, the in-process simulation, and the settings of the daemons.
//!
//! [`Scenario::load`] parses the file (unknown fields are errors), checks every
//! value against the robot model built from the URDF, and returns the model
//! together with the resolved levels. Errors name the file, the dotted field
//! path and the line.
//!
//! ```toml
//! [robot]
//! urdf = "planar4.urdf"          # relative to this file
//! tip_link = "tcp"
//! gravity = [0.0, -9.81, 0.0]
//!
//! [[level]]                      # level 1 = highest priority
//! task = "position"
//! axes = ["x", "y"]
//! stiffness = [1000.0, 1000.0]   # scalar, diagonal or full matrix
//! damping = [40.0, 40.0]
//! goal = [0.90, 0.80]
//!
//! [[level]]
//! task = "orientation"
//! axes = ["z"]                   # planar: rotation angle about z
//! stiffness = 800.0
//! damping = 5.0
//! goal = [-1.57]
//!
//! [initial]
//! q0 = [0.4, -0.5, -1.6, 0.4]
//! ```
//!
//! A level may stack several tasks: `task = "pose"` (position and orientation of a
//! frame, goal x, y, z, roll, pitch, yaw), or `[[level.task]]` tables (each with
//! `kind` and the task keys) with per-task gains and goals (K_i, D_i block-diagonal)
//! or one gain and goal for the whole level. The resolved hierarchy is
//! [`Scenario::spec`] (`hcc_control::ControllerSpec`).

pub mod commanding;
pub mod error;
pub mod franka;
pub mod output;
pub mod schedule;
pub mod schema;

pub use error::ConfigError;
/// How a daemon loop waits (`[controller_daemon] wait_strategy`): the one
/// type of the runtime, re-exported.
pub use hcc_rt::WaitStrategy;
pub use schema::*;

pub use hcc_control::{ControllerSpec, Form, LevelSpec, TaskSpec, TaskUnit};

use error::{from_toml, invalid};
use hcc_model::{FrameId, Model};
use nalgebra::{DMatrix, DVector, Vector3};
use std::path::{Path, PathBuf};

/// An external wrench of the simulation, resolved to a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Wrench {
    pub start_s: f64,
    pub duration_s: f64,
    pub link: String,
    pub frame_id: FrameId,
    pub force: Vector3<f64>,
    pub torque: Vector3<f64>,
}

/// Resolved `[simulation]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    pub duration_s: f64,
    pub control_rate_hz: f64,
    pub integrator_dt_s: f64,
    /// Plant steps per control period (control period / integrator dt, an integer).
    pub substeps: usize,
    /// Viscous friction per joint.
    pub joint_friction: DVector<f64>,
    pub wrenches: Vec<Wrench>,
}

/// Resolved `[controller_daemon]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerDaemon {
    pub cpu_core: Option<usize>,
    pub sched_priority: Option<i32>,
    pub mlock: bool,
    pub wait_strategy: WaitStrategy,
    /// Per joint, Nm (URDF effort limits unless configured; may be +inf).
    pub torque_limits: DVector<f64>,
    pub stale_timeout_ms: f64,
    /// Hybrid wait: the cache warm-up before each state (default true).
    pub warm_up: bool,
}

/// Resolved `[sim_daemon]`.
#[derive(Clone, Debug, PartialEq)]
pub struct SimDaemon {
    pub cpu_core: Option<usize>,
    pub mode: SimMode,
    pub hold_cycles: u32,
    pub fallback_damping: DVector<f64>,
}

/// A loaded and checked scenario. Every setting lives in one place: the hierarchy
/// and the controller options (gravity compensation, τ_μ, form, singular ratio) in
/// [`Scenario::spec`].
#[derive(Clone, Debug)]
pub struct Scenario {
    /// The scenario file.
    pub path: PathBuf,
    /// Name (from the file or its stem).
    pub name: String,
    /// Resolved URDF path.
    pub urdf_path: PathBuf,
    /// The robot model (chain root → tip, with the configured gravity).
    pub model: Model,
    /// The controller: the levels in priority order (`spec.levels`, each stacking its
    /// tasks) and `[controller]`, `[robot] gravity_compensation` (checked by
    /// `hcc_control::Controller::new` at load).
    pub spec: ControllerSpec,
    pub q0: DVector<f64>,
    pub qd0: DVector<f64>,
    pub simulation: Simulation,
    pub ipc: IpcSection,
    pub controller_daemon: ControllerDaemon,
    pub sim_daemon: SimDaemon,
    /// Resolved `[commanding]`.
    pub commanding: commanding::Commanding,
    /// Resolved `[output]`.
    pub output: output::Output,
    /// The `[[setpoint]]` entries, checked and sorted by time.
    pub setpoints: Vec<schedule::ScheduledSetpoint>,
    /// Resolved `[franka]` (libfranka's defaults where not given).
    pub franka: franka::Franka,
}

/// Loader context: the file, its text, and helpers that build located errors.
#[derive(Clone, Copy)]
struct Ctx<'a> {
    file: &'a Path,
    text: &'a str,
    /// Resolving a level of `[[level.task]]` tables (errors name the table).
    stacked: bool,
}

impl Ctx<'_> {
    fn err(&self, path: &str, message: impl Into<String>) -> ConfigError {
        invalid(self.file, self.text, path, message)
    }

    fn finite(&self, path: &str, v: &[f64]) -> Result<(), ConfigError> {
        match v.iter().position(|x| !x.is_finite()) {
            Some(k) => Err(self.err(&format!("{path}[{k}]"), "must be a finite number")),
            None => Ok(()),
        }
    }

    fn vector(
        &self,
        path: &str,
        v: &[f64],
        len: usize,
        what: &str,
    ) -> Result<DVector<f64>, ConfigError> {
        if v.len() != len {
            return Err(self.err(
                path,
                format!("has {} elements, expected {len} ({what})", v.len()),
            ));
        }
        self.finite(path, v)?;
        Ok(DVector::from_column_slice(v))
    }

    fn per_joint(
        &self,
        path: &str,
        v: &PerJoint,
        n: usize,
        allow_inf: bool,
    ) -> Result<DVector<f64>, ConfigError> {
        let out = match v {
            PerJoint::Scalar(s) => DVector::from_element(n, *s),
            PerJoint::Vector(v) => {
                if v.len() != n {
                    return Err(self.err(
                        path,
                        format!(
                            "has {} elements, expected {n} (one per joint) or a scalar",
                            v.len()
                        ),
                    ));
                }
                DVector::from_column_slice(v)
            }
        };
        for (k, x) in out.iter().enumerate() {
            let p = match v {
                PerJoint::Scalar(_) => path.to_string(),
                PerJoint::Vector(_) => format!("{path}[{k}]"),
            };
            if x.is_nan() || (!allow_inf && x.is_infinite()) {
                return Err(self.err(&p, "must be a finite number"));
            }
            if *x < 0.0 {
                return Err(self.err(&p, format!("must not be negative, got {x}")));
            }
        }
        Ok(out)
    }

    /// A stiffness or damping matrix of size m: symmetric positive definite.
    fn gain(&self, path: &str, g: &GainValue, m: usize) -> Result<DMatrix<f64>, ConfigError> {
        let mat = match g {
            GainValue::Scalar(s) => DMatrix::from_diagonal_element(m, m, *s),
            GainValue::Diagonal(d) => {
                if d.len() != m {
                    return Err(self.err(
                        path,
                        format!(
                            "has {} diagonal elements, expected {m} (the task dimension)",
                            d.len()
                        ),
                    ));
                }
                DMatrix::from_diagonal(&DVector::from_column_slice(d))
            }
            GainValue::Matrix(rows) => {
                if rows.len() != m || rows.iter().any(|r| r.len() != m) {
                    return Err(self.err(
                        path,
                        format!(
                            "must be a {m}×{m} matrix (the task dimension), a diagonal or a scalar"
                        ),
                    ));
                }
                DMatrix::from_fn(m, m, |i, j| rows[i][j])
            }
        };
        if mat.iter().any(|x| !x.is_finite()) {
            return Err(self.err(path, "must contain finite numbers only"));
        }
        for i in 0..m {
            for j in 0..i {
                let (a, b) = (mat[(i, j)], mat[(j, i)]);
                if (a - b).abs() > 1e-12 * a.abs().max(b.abs()).max(1.0) {
                    return Err(self.err(
                        path,
                        format!("must be symmetric: element ({i},{j}) = {a} but ({j},{i}) = {b}"),
                    ));
                }
            }
        }
        let mut l = mat.clone();
        if hcc_model::linalg::cholesky_in_place(&mut l).is_err() {
            let what = if (0..m).any(|i| mat[(i, i)] < 0.0) {
                "must be positive definite (a diagonal element is negative)"
            } else {
                "must be positive definite"
            };
            return Err(self.err(path, what));
        }
        Ok(mat)
    }
}

impl Scenario {
    /// Loads, checks and resolves a scenario file; builds the robot model from its URDF.
    pub fn load(path: impl AsRef<Path>) -> Result<Scenario, ConfigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Io {
            file: path.to_path_buf(),
            error,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Like [`Scenario::load`] for TOML text; `path` names the file in errors and is
    /// the base for the relative URDF path.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Scenario, ConfigError> {
        let file: ScenarioFile = toml::from_str(text).map_err(|e| from_toml(path, text, &e))?;
        let cx = Ctx {
            file: path,
            text,
            stacked: false,
        };
        let (model, urdf_path) = load_model(&cx, &file.robot)?;
        let n = model.nq();

        // [[level]]
        if file.levels.is_empty() {
            return Err(cx.err("level", "at least one [[level]] is required"));
        }
        let mut levels = Vec::with_capacity(file.levels.len());
        for (i, l) in file.levels.iter().enumerate() {
            levels.push(resolve_level(&cx, &model, i, l)?);
        }
        check_hierarchy(&cx, &levels, n)?;

        // [controller]
        let ratio = file.controller.singularity.singular_ratio;
        if !(ratio > 0.0 && ratio < 1.0) {
            return Err(cx.err(
                "controller.singularity.singular_ratio",
                format!("must be in (0, 1), got {ratio}"),
            ));
        }

        let (q0, qd0) = resolve_initial(&cx, &model, &file.initial)?;
        let simulation = resolve_simulation(&cx, &model, &file.simulation)?;
        check_namespace(&cx, &file.ipc.namespace)?;

        let spec = ControllerSpec {
            levels,
            gravity_compensation: file.robot.gravity_compensation,
            coriolis_cancellation: file.controller.coriolis_cancellation,
            form: file.controller.form,
            singular_ratio: ratio,
            safety: safety_spec(&cx, &file.safety, simulation.control_rate_hz)?,
        };
        check_with_controller(&cx, &model, &spec, &q0)?;

        let controller_daemon = resolve_controller_daemon(
            &cx,
            &model,
            &file.controller_daemon,
            simulation.control_rate_hz,
        )?;
        let sim_daemon = resolve_sim_daemon(&cx, n, &file.sim_daemon)?;
        let commanding = commanding::resolve(cx.file, cx.text, &file.commanding, &spec.levels, n)?;
        let output = output::resolve(cx.file, cx.text, &file.output)?;
        let setpoints = schedule::resolve(cx.file, cx.text, &file.setpoints, &spec.levels, n)?;
        let franka = franka::resolve(cx.file, cx.text, &file.franka)?;

        let name = file.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scenario".to_string())
        });
        Ok(Scenario {
            path: path.to_path_buf(),
            name,
            urdf_path,
            model,
            spec,
            q0,
            qd0,
            simulation,
            ipc: file.ipc,
            controller_daemon,
            sim_daemon,
            commanding,
            output,
            setpoints,
            franka,
        })
    }
}

/// `[robot]`: the model from the URDF (path relative to the scenario file).
fn load_model(cx: &Ctx, robot: &RobotSection) -> Result<(Model, PathBuf), ConfigError> {
    let gravity = match &robot.gravity {
        Some(g) => {
            let v = cx.vector("robot.gravity", g, 3, "x, y, z")?;
            Some(Vector3::new(v[0], v[1], v[2]))
        }
        None => None,
    };
    let base = cx.file.parent().unwrap_or(Path::new("."));
    let urdf_path = base.join(&robot.urdf);
    let model = Model::from_urdf_file(
        &urdf_path,
        robot.root_link.as_deref(),
        &robot.tip_link,
        gravity,
    )
    .map_err(|error| {
        let field = match &error {
            hcc_model::ModelError::UnknownLink { what, .. } if what == "root" => "robot.root_link",
            hcc_model::ModelError::UnknownLink { what, .. } if what == "tip" => "robot.tip_link",
            hcc_model::ModelError::TipNotBelowRoot { .. } => "robot.tip_link",
            _ => "robot.urdf",
        };
        ConfigError::Model {
            file: cx.file.to_path_buf(),
            line: error::locate_path(cx.text, field),
            error,
        }
    })?;
    Ok((model, urdf_path))
}

/// `[initial]`: q0 (within the joint limits) and q̇0.
fn resolve_initial(
    cx: &Ctx,
    model: &Model,
    initial: &InitialSection,
) -> Result<(DVector<f64>, DVector<f64>), ConfigError> {
    let n = model.nq();
    let q0 = cx.vector("initial.q0", &initial.q0, n, "one per joint")?;
    let qd0 = match &initial.qd0 {
        Some(v) => cx.vector("initial.qd0", v, n, "one per joint")?,
        None => DVector::zeros(n),
    };
    for (k, j) in model.joints.iter().enumerate() {
        if q0[k] < j.lower - 1e-9 || q0[k] > j.upper + 1e-9 {
            return Err(cx.err(
                &format!("initial.q0[{k}]"),
                format!(
                    "{} is outside the limits [{}, {}] of joint '{}'",
                    q0[k], j.lower, j.upper, j.name
                ),
            ));
        }
    }
    Ok((q0, qd0))
}

/// `[ipc] namespace`: non-empty, letters, digits, '_' and '-'.
fn check_namespace(cx: &Ctx, ns: &str) -> Result<(), ConfigError> {
    if ns.is_empty()
        || !ns
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Err(cx.err(
            "ipc.namespace",
            format!("{ns:?} must be non-empty and use only letters, digits, '_' and '-'"),
        ));
    }
    Ok(())
}

/// Lets the controller check the hierarchy as it will run it (ranks at q0).
fn check_with_controller(
    cx: &Ctx,
    model: &Model,
    spec: &ControllerSpec,
    q0: &DVector<f64>,
) -> Result<(), ConfigError> {
    if let Err(e) = hcc_control::Controller::new(model, spec.clone(), q0) {
        let field = match &e {
            hcc_control::ControlError::Level { level, .. } => level
                .split_whitespace()
                .next()
                .and_then(|k| k.parse::<usize>().ok())
                .map(|k| format!("level[{}]", k.saturating_sub(1)))
                .unwrap_or_else(|| "level".to_string()),
            hcc_control::ControlError::Spec(_) if spec.form == Form::KinematicProjector => {
                "controller.form".to_string()
            }
            hcc_control::ControlError::Spec(_) => "level".to_string(),
            _ => "initial.q0".to_string(),
        };
        return Err(cx.err(&field, format!("rejected by the controller: {e}")));
    }
    Ok(())
}

impl Scenario {
    /// Overrides the simulated duration (e.g. from the command line).
    pub fn set_duration(&mut self, duration_s: f64) -> Result<(), ConfigError> {
        let cycles = duration_s * self.simulation.control_rate_hz;
        if !(duration_s.is_finite() && (1.0..=1e8).contains(&cycles)) {
            return Err(ConfigError::Invalid {
                file: self.path.clone(),
                line: None,
                path: "simulation.duration_s".into(),
                message: format!(
                    "override {duration_s} s must be finite and cover 1 to 1e8 control periods"
                ),
            });
        }
        self.simulation.duration_s = duration_s;
        Ok(())
    }

    /// Checks a daemon's `cpu_core` (`section` is `"controller_daemon"` or
    /// `"sim_daemon"`) against the cores this process may run on (`available`,
    /// e.g. from `sched_getaffinity`). A configured core that is not available
    /// is an error naming the field and its line: a real-time thread that
    /// silently ran unpinned would not be what the scenario asks for. Called
    /// by the daemons at start-up, not by [`Scenario::load`], so that a
    /// robot's scenario can still be simulated in process on another machine.
    pub fn check_cpu_core(&self, section: &str, available: &[usize]) -> Result<(), ConfigError> {
        let core = match section {
            "controller_daemon" => self.controller_daemon.cpu_core,
            "sim_daemon" => self.sim_daemon.cpu_core,
            _ => None,
        };
        let Some(core) = core else {
            return Ok(());
        };
        if available.contains(&core) {
            return Ok(());
        }
        let path = format!("{section}.cpu_core");
        let text = std::fs::read_to_string(&self.path).unwrap_or_default();
        let mut sorted = available.to_vec();
        sorted.sort_unstable();
        Err(invalid(
            &self.path,
            &text,
            &path,
            format!(
                "CPU core {core} is not available to this process (available: {})",
                if sorted.is_empty() {
                    "unknown".to_string()
                } else {
                    sorted
                        .iter()
                        .map(|c| c.to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            ),
        ))
    }

    /// Switches the Coriolis cancellation τ_μ (eq. 22) on or off (e.g. for the ablation).
    pub fn set_coriolis_cancellation(&mut self, on: bool) -> Result<(), ConfigError> {
        self.spec.coriolis_cancellation = on;
        Ok(())
    }

    /// The levels in priority order (those of [`Scenario::spec`]).
    pub fn levels(&self) -> &[LevelSpec] {
        &self.spec.levels
    }

    /// Task dimension m_i of every level.
    pub fn task_dims(&self) -> Vec<usize> {
        self.spec.task_dims(self.model.nq())
    }
}

/// The keys that select what one task measures: those of a single-task `[[level]]`
/// or of one `[[level.task]]` table.
struct TaskKeys<'a> {
    kind: TaskKind,
    frame: Option<&'a String>,
    axes: Option<&'a Vec<AxisName>>,
    joints: Option<&'a Vec<String>>,
    weights: Option<&'a Vec<Vec<f64>>>,
}

fn frame_of(
    cx: &Ctx,
    model: &Model,
    path: &str,
    name: Option<&String>,
) -> Result<FrameId, ConfigError> {
    let name = name.cloned().unwrap_or_else(|| model.tip_link.clone());
    match model.frame_id(&name) {
        Some(id) => Ok(id),
        None => Err(cx.err(
            path,
            format!("unknown link '{name}' (not on the chain of the robot model)"),
        )),
    }
}

/// One task from its keys; `p` is the dotted path of the table holding them.
fn resolve_task(cx: &Ctx, model: &Model, p: &str, t: &TaskKeys) -> Result<TaskSpec, ConfigError> {
    let f = |field: &str| format!("{p}.{field}");
    let unused = |field: &str, present: bool| -> Result<(), ConfigError> {
        if present {
            Err(cx.err(
                &f(field),
                format!("is not used by a task of kind {:?}", t.kind),
            ))
        } else {
            Ok(())
        }
    };
    if matches!(t.kind, TaskKind::Joint | TaskKind::JointCombination) {
        unused("frame", t.frame.is_some())?;
        unused("axes", t.axes.is_some())?;
    }
    if t.kind != TaskKind::Joint {
        unused("joints", t.joints.is_some())?;
    }
    if t.kind != TaskKind::JointCombination {
        unused("weights", t.weights.is_some())?;
    }
    Ok(match t.kind {
        TaskKind::Position => {
            let frame = frame_of(cx, model, &f("frame"), t.frame)?;
            let axes: Vec<usize> = match t.axes {
                None => vec![0, 1, 2],
                Some(a) => a.iter().map(|a| a.index()).collect(),
            };
            if axes.is_empty() {
                return Err(cx.err(&f("axes"), "must list at least one axis"));
            }
            for (k, a) in axes.iter().enumerate() {
                if axes[..k].contains(a) {
                    return Err(cx.err(&f("axes"), "lists an axis twice"));
                }
            }
            TaskSpec::Position { frame, axes }
        }
        TaskKind::Pose => {
            unused("axes", t.axes.is_some())?;
            TaskSpec::Pose {
                frame: frame_of(cx, model, &f("frame"), t.frame)?,
            }
        }
        TaskKind::Orientation => {
            let frame = frame_of(cx, model, &f("frame"), t.frame)?;
            match t.axes {
                None => TaskSpec::Orientation { frame },
                Some(a) if a.len() == 1 => TaskSpec::PlanarOrientation {
                    frame,
                    axis: a[0].index(),
                },
                Some(_) => {
                    return Err(cx.err(
                        &f("axes"),
                        "an orientation task takes either no axes (3-D) or exactly one (planar)",
                    ));
                }
            }
        }
        TaskKind::JointCombination => {
            let n = model.nq();
            let rows = t
                .weights
                .ok_or_else(|| cx.err(&f("weights"), "is required for a joint_combination task"))?;
            if rows.is_empty() {
                return Err(cx.err(&f("weights"), "must have at least one row"));
            }
            for (k, row) in rows.iter().enumerate() {
                let rp = format!("{p}.weights[{k}]");
                if row.len() != n {
                    return Err(cx.err(
                        &rp,
                        format!("has {} elements, expected {n} (one per joint)", row.len()),
                    ));
                }
                cx.finite(&rp, row)?;
            }
            TaskSpec::JointCombination {
                weights: DMatrix::from_fn(rows.len(), n, |a, b| rows[a][b]),
            }
        }
        TaskKind::Joint => match t.joints {
            None => TaskSpec::Posture,
            Some(names) => TaskSpec::Joints {
                indices: joint_indices(cx, model, p, names)?,
            },
        },
    })
}

fn joint_indices(
    cx: &Ctx,
    model: &Model,
    p: &str,
    names: &[String],
) -> Result<Vec<usize>, ConfigError> {
    let mut idx = Vec::with_capacity(names.len());
    for (k, name) in names.iter().enumerate() {
        let jp = format!("{p}.joints[{k}]");
        match model.joints.iter().position(|j| &j.name == name) {
            Some(j) if !idx.contains(&j) => idx.push(j),
            Some(_) => return Err(cx.err(&jp, format!("joint '{name}' is listed twice"))),
            None => {
                return Err(cx.err(
                    &jp,
                    format!("unknown joint '{name}' (not a movable joint of the chain)"),
                ));
            }
        }
    }
    if idx.is_empty() {
        return Err(cx.err(&format!("{p}.joints"), "must list at least one joint"));
    }
    Ok(idx)
}

/// A level's gain (`what` = "stiffness" or "damping") over its stacked coordinates:
/// the level's own value, or block-diagonal from the value of every task table.
fn level_gain(
    cx: &Ctx,
    p: &str,
    what: &str,
    level: Option<&GainValue>,
    tasks: &[(Option<&GainValue>, usize)],
) -> Result<DMatrix<f64>, ConfigError> {
    let m: usize = tasks.iter().map(|t| t.1).sum();
    if let Some(g) = level {
        if let Some(k) = tasks.iter().position(|t| t.0.is_some()) {
            return Err(cx.err(
                &format!("{p}.task[{k}].{what}"),
                format!("is also given for the whole level: give the {what} once"),
            ));
        }
        return cx.gain(&format!("{p}.{what}"), g, m);
    }
    let mut out = DMatrix::zeros(m, m);
    let mut o = 0;
    for (k, (g, d)) in tasks.iter().enumerate() {
        let path = if tasks.len() == 1 && !cx.stacked {
            format!("{p}.{what}")
        } else {
            format!("{p}.task[{k}].{what}")
        };
        let g =
            g.ok_or_else(|| cx.err(&path, format!("is required (or a {what} for the level)")))?;
        out.view_mut((o, o), (*d, *d))
            .copy_from(&cx.gain(&path, g, *d)?);
        o += d;
    }
    Ok(out)
}

/// A level's goal: the level's own value or the tasks' goals stacked.
fn level_goal(
    cx: &Ctx,
    p: &str,
    level: Option<&Vec<f64>>,
    tasks: &[(Option<&Vec<f64>>, usize)],
) -> Result<DVector<f64>, ConfigError> {
    let m: usize = tasks.iter().map(|t| t.1).sum();
    if let Some(g) = level {
        if let Some(k) = tasks.iter().position(|t| t.0.is_some()) {
            return Err(cx.err(
                &format!("{p}.task[{k}].goal"),
                "is also given for the whole level: give the goal once",
            ));
        }
        return cx.vector(&format!("{p}.goal"), g, m, "the task dimension");
    }
    let mut out = DVector::zeros(m);
    let mut o = 0;
    for (k, (g, d)) in tasks.iter().enumerate() {
        let path = if tasks.len() == 1 && !cx.stacked {
            format!("{p}.goal")
        } else {
            format!("{p}.task[{k}].goal")
        };
        let g = g.ok_or_else(|| cx.err(&path, "is required (or a goal for the level)"))?;
        out.rows_mut(o, *d)
            .copy_from(&cx.vector(&path, g, *d, "the task dimension")?);
        o += d;
    }
    Ok(out)
}

fn resolve_level(
    cx: &Ctx,
    model: &Model,
    i: usize,
    l: &LevelSection,
) -> Result<LevelSpec, ConfigError> {
    let p = format!("level[{i}]");
    let n = model.nq();
    let level_keys = TaskKeys {
        kind: TaskKind::Joint,
        frame: l.frame.as_ref(),
        axes: l.axes.as_ref(),
        joints: l.joints.as_ref(),
        weights: l.weights.as_ref(),
    };
    let (tasks, stiffness, damping, goal) = match &l.task {
        LevelTasks::Kind(kind) => {
            let task = resolve_task(
                cx,
                model,
                &p,
                &TaskKeys {
                    kind: *kind,
                    ..level_keys
                },
            )?;
            let m = task.dim(n);
            let stiffness = level_gain(cx, &p, "stiffness", None, &[(l.stiffness.as_ref(), m)])?;
            let damping = level_gain(cx, &p, "damping", None, &[(l.damping.as_ref(), m)])?;
            let goal = level_goal(cx, &p, None, &[(l.goal.as_ref(), m)])?;
            (vec![task], stiffness, damping, goal)
        }
        LevelTasks::Stack(tables) => {
            for (field, present) in [
                ("frame", l.frame.is_some()),
                ("axes", l.axes.is_some()),
                ("joints", l.joints.is_some()),
                ("weights", l.weights.is_some()),
            ] {
                if present {
                    return Err(cx.err(
                        &format!("{p}.{field}"),
                        "belongs in a [[level.task]] table when the level stacks tasks",
                    ));
                }
            }
            if tables.is_empty() {
                return Err(cx.err(&format!("{p}.task"), "must hold at least one task"));
            }
            let mut tasks = Vec::with_capacity(tables.len());
            for (k, t) in tables.iter().enumerate() {
                let keys = TaskKeys {
                    kind: t.kind,
                    frame: t.frame.as_ref(),
                    axes: t.axes.as_ref(),
                    joints: t.joints.as_ref(),
                    weights: t.weights.as_ref(),
                };
                tasks.push(resolve_task(cx, model, &format!("{p}.task[{k}]"), &keys)?);
            }
            let dims: Vec<usize> = tasks.iter().map(|t| t.dim(n)).collect();
            let cxs = Ctx {
                stacked: true,
                ..*cx
            };
            let gains =
                |f: fn(&TaskTable) -> Option<&GainValue>| -> Vec<(Option<&GainValue>, usize)> {
                    tables.iter().zip(&dims).map(|(t, &d)| (f(t), d)).collect()
                };
            let stiffness = level_gain(
                &cxs,
                &p,
                "stiffness",
                l.stiffness.as_ref(),
                &gains(|t| t.stiffness.as_ref()),
            )?;
            let damping = level_gain(
                &cxs,
                &p,
                "damping",
                l.damping.as_ref(),
                &gains(|t| t.damping.as_ref()),
            )?;
            let goals: Vec<_> = tables
                .iter()
                .zip(&dims)
                .map(|(t, &d)| (t.goal.as_ref(), d))
                .collect();
            let goal = level_goal(&cxs, &p, l.goal.as_ref(), &goals)?;
            (tasks, stiffness, damping, goal)
        }
    };
    let name = l
        .name
        .clone()
        .unwrap_or_else(|| default_name(model, &tasks));
    Ok(LevelSpec {
        name,
        tasks,
        stiffness,
        damping,
        goal,
    })
}

fn default_name(model: &Model, tasks: &[TaskSpec]) -> String {
    const AX: [&str; 3] = ["x", "y", "z"];
    let frame = |f: &FrameId| model.frames[*f].name.clone();
    let names: Vec<String> = tasks
        .iter()
        .map(|t| match t {
            TaskSpec::Position { frame: f, axes } => {
                let a: String = axes.iter().map(|&k| AX[k]).collect();
                format!("{} position {a}", frame(f))
            }
            TaskSpec::Orientation { frame: f } => format!("{} orientation", frame(f)),
            TaskSpec::Pose { frame: f } => format!("{} pose", frame(f)),
            TaskSpec::PlanarOrientation { frame: f, axis } => {
                format!("{} rotation about {}", frame(f), AX[*axis])
            }
            TaskSpec::Posture => "joint posture".to_string(),
            TaskSpec::JointCombination { .. } => "joint combination".to_string(),
            TaskSpec::Joints { indices } => {
                let names: Vec<&str> = indices
                    .iter()
                    .map(|&j| model.joints[j].name.as_str())
                    .collect();
                format!("joint {}", names.join(", "))
            }
        })
        .collect();
    names.join(" + ")
}

/// Dimension rules of the hierarchy (Sec. II): every level but the last must leave a
/// null space, Σ_{i<r} m_i < n; the last level may be of any dimension.
fn check_hierarchy(cx: &Ctx, levels: &[LevelSpec], n: usize) -> Result<(), ConfigError> {
    let mut sum = 0;
    let r = levels.len();
    for (i, l) in levels.iter().enumerate() {
        let m = l.dim(n);
        if m > n {
            return Err(cx.err(
                &format!("level[{i}]"),
                format!("task dimension {m} exceeds the {n} joints of the robot"),
            ));
        }
        sum += m;
        if i + 1 < r && sum >= n {
            return Err(cx.err(
                &format!("level[{}]", i + 1),
                format!(
                    "no null space left: levels 1..{} already use {sum} of {n} degrees of freedom; only the last level may exhaust them",
                    i + 1
                ),
            ));
        }
    }
    Ok(())
}

fn resolve_simulation(
    cx: &Ctx,
    model: &Model,
    s: &SimulationSection,
) -> Result<Simulation, ConfigError> {
    let positive = |name: &str, v: f64| -> Result<(), ConfigError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(cx.err(
                &format!("simulation.{name}"),
                format!("must be a positive finite number, got {v}"),
            ))
        }
    };
    positive("duration_s", s.duration_s)?;
    positive("control_rate_hz", s.control_rate_hz)?;
    positive("integrator_dt_s", s.integrator_dt_s)?;
    let period = 1.0 / s.control_rate_hz;
    let ratio = period / s.integrator_dt_s;
    let substeps = ratio.round();
    if substeps < 1.0 || (ratio - substeps).abs() > 1e-6 * ratio {
        return Err(cx.err(
            "simulation.integrator_dt_s",
            format!(
                "{} s must divide the control period 1/{} Hz = {period} s into a whole number of steps",
                s.integrator_dt_s, s.control_rate_hz
            ),
        ));
    }
    if s.duration_s * s.control_rate_hz < 1.0 {
        return Err(cx.err(
            "simulation.duration_s",
            "is shorter than one control period",
        ));
    }
    if s.duration_s * s.control_rate_hz > 1e8 {
        return Err(cx.err(
            "simulation.duration_s",
            "is too long (more than 1e8 control cycles)",
        ));
    }
    let n = model.nq();
    let joint_friction = match &s.joint_friction {
        Some(f) => cx.per_joint("simulation.joint_friction", f, n, false)?,
        None => DVector::zeros(n),
    };
    let mut wrenches = Vec::with_capacity(s.wrench.len());
    for (i, w) in s.wrench.iter().enumerate() {
        let p = |f: &str| format!("simulation.wrench[{i}].{f}");
        if !(w.start_s.is_finite() && w.start_s >= 0.0) {
            return Err(cx.err(&p("start_s"), "must be a finite non-negative time"));
        }
        if !(w.duration_s.is_finite() && w.duration_s >= 0.0) {
            return Err(cx.err(&p("duration_s"), "must be a finite non-negative duration"));
        }
        let frame_id = model.frame_id(&w.link).ok_or_else(|| {
            cx.err(
                &p("link"),
                format!("unknown link '{}' (not a link of the robot model)", w.link),
            )
        })?;
        let v3 = |name: &str, v: &Option<Vec<f64>>| -> Result<Vector3<f64>, ConfigError> {
            match v {
                None => Ok(Vector3::zeros()),
                Some(v) => {
                    let d = cx.vector(&p(name), v, 3, "x, y, z in world axes")?;
                    Ok(Vector3::new(d[0], d[1], d[2]))
                }
            }
        };
        wrenches.push(Wrench {
            start_s: w.start_s,
            duration_s: w.duration_s,
            link: w.link.clone(),
            frame_id,
            force: v3("force", &w.force)?,
            torque: v3("torque", &w.torque)?,
        });
    }
    Ok(Simulation {
        duration_s: s.duration_s,
        control_rate_hz: s.control_rate_hz,
        integrator_dt_s: s.integrator_dt_s,
        substeps: substeps as usize,
        joint_friction,
        wrenches,
    })
}

/// Default stale timeout of the controller daemon, in control periods: the
/// peer is declared lost when the third consecutive state is missing.
pub const STALE_TIMEOUT_PERIODS: f64 = 3.0;

/// Largest CPU index a `cpu_core` may name (Linux' `CPU_SETSIZE` − 1).
pub const MAX_CPU_CORE: usize = 1023;

fn resolve_controller_daemon(
    cx: &Ctx,
    model: &Model,
    d: &ControllerDaemonSection,
    control_rate_hz: f64,
) -> Result<ControllerDaemon, ConfigError> {
    if let Some(p) = d.sched_priority
        && !(1..=99).contains(&p)
    {
        return Err(cx.err(
            "controller_daemon.sched_priority",
            format!("must be in 1..=99 (SCHED_FIFO), got {p}"),
        ));
    }
    let torque_limits = match &d.torque_limits {
        Some(t) => {
            let v = cx.per_joint("controller_daemon.torque_limits", t, model.nq(), true)?;
            if let Some(k) = v.iter().position(|x| *x == 0.0) {
                return Err(cx.err(
                    &format!("controller_daemon.torque_limits[{k}]"),
                    "must be positive",
                ));
            }
            v
        }
        None => model.effort_limits(),
    };
    if let Some(core) = d.cpu_core
        && core > MAX_CPU_CORE
    {
        return Err(cx.err(
            "controller_daemon.cpu_core",
            format!("{core} is not a CPU index (at most {MAX_CPU_CORE})"),
        ));
    }
    let stale_timeout_ms = d
        .stale_timeout_ms
        .unwrap_or(STALE_TIMEOUT_PERIODS * 1e3 / control_rate_hz);
    if !(stale_timeout_ms.is_finite() && stale_timeout_ms > 0.0) {
        return Err(cx.err(
            "controller_daemon.stale_timeout_ms",
            format!("must be a positive finite number, got {stale_timeout_ms}"),
        ));
    }
    Ok(ControllerDaemon {
        cpu_core: d.cpu_core,
        sched_priority: d.sched_priority,
        mlock: d.mlock,
        wait_strategy: d.wait_strategy,
        torque_limits,
        stale_timeout_ms,
        warm_up: d.warm_up.unwrap_or(true),
    })
}

fn resolve_sim_daemon(cx: &Ctx, n: usize, d: &SimDaemonSection) -> Result<SimDaemon, ConfigError> {
    if let Some(core) = d.cpu_core
        && core > MAX_CPU_CORE
    {
        return Err(cx.err(
            "sim_daemon.cpu_core",
            format!("{core} is not a CPU index (at most {MAX_CPU_CORE})"),
        ));
    }
    let fallback_damping = match &d.fallback_damping {
        Some(f) => cx.per_joint("sim_daemon.fallback_damping", f, n, false)?,
        None => DVector::from_element(n, 2.0),
    };
    Ok(SimDaemon {
        cpu_core: d.cpu_core,
        mode: d.mode,
        hold_cycles: d.hold_cycles.unwrap_or(3),
        fallback_damping,
    })
}

/// `[safety]` over the defaults of `hcc_control::SafetySpec`, the control period from
/// the control rate.
fn safety_spec(
    cx: &Ctx,
    s: &schema::SafetySection,
    control_rate_hz: f64,
) -> Result<hcc_control::SafetySpec, ConfigError> {
    let d = hcc_control::SafetySpec::default();
    let spec = hcc_control::SafetySpec {
        enabled: s.enabled.unwrap_or(d.enabled),
        joint_limit_margin: s.joint_limit_margin.unwrap_or(d.joint_limit_margin),
        joint_limit_torque: s.joint_limit_torque.or(d.joint_limit_torque),
        joint_limit_damping_ratio: s
            .joint_limit_damping_ratio
            .unwrap_or(d.joint_limit_damping_ratio),
        velocity_limit_fraction: s
            .velocity_limit_fraction
            .unwrap_or(d.velocity_limit_fraction),
        velocity_limit_full_fraction: s
            .velocity_limit_full_fraction
            .unwrap_or(d.velocity_limit_full_fraction),
        spring_saturation: s.spring_saturation.unwrap_or(d.spring_saturation),
        velocity_governor: s.velocity_governor.unwrap_or(d.velocity_governor),
        velocity_damping: s.velocity_damping.unwrap_or(d.velocity_damping),
        null_space_damping: s.null_space_damping.unwrap_or(d.null_space_damping),
        conflict_fade_ratio: s.conflict_fade_ratio.unwrap_or(d.conflict_fade_ratio),
        fade_tank_max: s.fade_tank_max.unwrap_or(d.fade_tank_max),
        control_period_s: 1.0 / control_rate_hz,
    };
    spec.validate().map_err(|e| {
        let msg = e.to_string();
        let field = msg
            .split_whitespace()
            .next()
            .unwrap_or("safety")
            .to_string();
        cx.err(&field, msg)
    })?;
    Ok(spec)
}
