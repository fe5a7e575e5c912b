//! The scenario file as written (serde view of the TOML). Every table rejects
//! unknown fields. Values are checked and resolved against the robot model in
//! [`crate::Scenario::load`].

use serde::Deserialize;

/// Root of a scenario file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Scenario name (default: the file stem).
    pub name: Option<String>,
    /// Free text.
    pub description: Option<String>,
    pub robot: RobotSection,
    /// Levels in priority order: the first `[[level]]` has the highest priority.
    #[serde(rename = "level")]
    pub levels: Vec<LevelSection>,
    #[serde(default)]
    pub controller: ControllerSection,
    pub initial: InitialSection,
    #[serde(default)]
    pub simulation: SimulationSection,
    #[serde(default)]
    pub ipc: IpcSection,
    #[serde(default)]
    pub controller_daemon: ControllerDaemonSection,
    #[serde(default)]
    pub sim_daemon: SimDaemonSection,
    /// `[safety]`: the controller's safety layer (every field optional).
    #[serde(default)]
    pub safety: SafetySection,
    /// `[setpoint_limits]`: limits of setpoints sent while the controller runs.
    #[serde(default)]
    pub setpoint_limits: crate::setpoint_limits::SetpointLimitsSection,
    /// `[torque_filter]`: the torque-rate limit and low-pass after the law.
    #[serde(default)]
    pub torque_filter: crate::torque_filter::TorqueFilterSection,
    /// The former names of `[setpoint_limits]` and `[torque_filter]`: read
    /// only to refuse them with the new name.
    #[serde(default)]
    pub commanding: Option<toml::Value>,
    #[serde(default)]
    pub output: Option<toml::Value>,
    /// `[contact]`: the external-torque observer and contact detection.
    #[serde(default)]
    pub contact: crate::contact::ContactSection,
    /// `[[setpoint]]`: setpoints scheduled in time.
    #[serde(default, rename = "setpoint")]
    pub setpoints: Vec<crate::schedule::SetpointSection>,
    /// `[franka]`: the Franka driver's settings (every field optional).
    #[serde(default)]
    pub franka: crate::franka::FrankaSection,
}

/// `[robot]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    /// URDF path, relative to the scenario file.
    pub urdf: String,
    /// Root link of the chain (default: the URDF's root link).
    pub root_link: Option<String>,
    /// Tip link of the chain.
    pub tip_link: String,
    /// Gravity in world coordinates, m/s² (default (0, 0, −9.81)).
    pub gravity: Option<Vec<f64>>,
    /// Whether the controller adds the gravity torque g(q) (eq. 19). Set to false for
    /// robots whose torque interface compensates gravity itself.
    #[serde(default = "yes")]
    pub gravity_compensation: bool,
    /// The heaviest load the robot may carry at its tip, kg (default: no limit).
    pub payload_kg: Option<f64>,
    /// The load the tip frame carries from the start (default: none).
    pub load: Option<LoadSection>,
}

/// `[[simulation.load]]`: from `start_s` on, the plant's tip carries this
/// load (replacing the one before; `mass = 0.0` lets it go).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimedLoadSection {
    pub start_s: f64,
    /// As `[robot.load]`'s.
    pub mass: f64,
    pub com: Option<Vec<f64>>,
    pub inertia: Option<Vec<f64>>,
}

impl TimedLoadSection {
    /// The load, as `[robot.load]` writes it.
    pub fn load(&self) -> LoadSection {
        LoadSection {
            mass: self.mass,
            com: self.com.clone(),
            inertia: self.inertia.clone(),
        }
    }
}

/// `[robot.load]`: a load held rigidly at the tip frame.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSection {
    /// Mass, kg.
    pub mass: f64,
    /// Centre of mass in the tip frame, m (default: the tip frame's origin).
    pub com: Option<Vec<f64>>,
    /// Rotational inertia about the centre of mass, tip axes, kg·m², as a
    /// URDF gives it: ixx, ixy, ixz, iyy, iyz, izz (default: a point mass).
    pub inertia: Option<Vec<f64>>,
}

fn yes() -> bool {
    true
}

pub use crate::values::{GainValue, PerJoint};

/// Kind of task (the `task` key of a `[[level]]`, the `kind` key of a `[[level.task]]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskKind {
    /// Cartesian position of a frame origin (world axes), optionally a subset of axes.
    Position,
    /// Orientation of a frame: 3-D (goal as roll-pitch-yaw in rad), or the rotation
    /// angle about one world axis for planar arms (`axes = ["z"]`, goal one angle).
    Orientation,
    /// Position and orientation of a frame (6-D, goal x, y, z, roll, pitch, yaw).
    Pose,
    /// Joint positions of the listed joints (default: all joints, the posture).
    Joint,
    /// A linear combination of joint positions, x = W q (`weights`: m rows of n).
    JointCombination,
}

/// The `task` of a `[[level]]`: one kind (`task = "pose"`), or the stacked tasks of
/// the level as `[[level.task]]` tables.
#[derive(Clone, Debug)]
pub enum LevelTasks {
    Kind(TaskKind),
    Stack(Vec<TaskTable>),
}

impl<'de> Deserialize<'de> for LevelTasks {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = LevelTasks;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a task kind (e.g. \"position\") or [[level.task]] tables")
            }
            fn visit_str<E: serde::de::Error>(self, s: &str) -> Result<LevelTasks, E> {
                use serde::de::IntoDeserializer;
                TaskKind::deserialize(s.into_deserializer()).map(LevelTasks::Kind)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, a: A) -> Result<LevelTasks, A::Error> {
                Vec::<TaskTable>::deserialize(serde::de::value::SeqAccessDeserializer::new(a))
                    .map(LevelTasks::Stack)
            }
        }
        d.deserialize_any(V)
    }
}

/// `[[level.task]]`: one of the stacked tasks of a level. Its gains and goal are
/// either given here (the level's K_i and D_i are then block-diagonal) or for the
/// whole level.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskTable {
    pub kind: TaskKind,
    /// Frame (link) of a Cartesian task (default: the tip link).
    pub frame: Option<String>,
    /// Axes of a position task, or the single axis of a planar orientation task.
    pub axes: Option<Vec<AxisName>>,
    /// Joints of a joint task (default: all).
    pub joints: Option<Vec<String>>,
    /// Rows of W for a joint-combination task (each of length n).
    pub weights: Option<Vec<Vec<f64>>>,
    pub stiffness: Option<GainValue>,
    pub damping: Option<GainValue>,
    pub goal: Option<Vec<f64>>,
}

/// A Cartesian axis name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AxisName {
    X,
    Y,
    Z,
}

impl AxisName {
    /// Index 0, 1, 2.
    pub fn index(self) -> usize {
        match self {
            AxisName::X => 0,
            AxisName::Y => 1,
            AxisName::Z => 2,
        }
    }
}

/// `[[level]]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelSection {
    /// Name for reports (default from the task).
    pub name: Option<String>,
    pub task: LevelTasks,
    /// Frame (link) of a Cartesian task (default: the tip link).
    pub frame: Option<String>,
    /// Axes of a position task (default x, y, z), or the single rotation axis of a
    /// planar orientation task.
    pub axes: Option<Vec<AxisName>>,
    /// Joints of a joint task (default: all).
    pub joints: Option<Vec<String>>,
    /// Rows of W for a joint-combination task (each of length n).
    pub weights: Option<Vec<Vec<f64>>>,
    /// Stiffness K_i (N/m, Nm/rad): scalar, diagonal or full symmetric positive
    /// definite over the level's (stacked) coordinates.
    pub stiffness: Option<GainValue>,
    /// Damping D_i (Ns/m, Nms/rad): scalar, diagonal or full symmetric positive definite.
    pub damping: Option<GainValue>,
    /// Virtual equilibrium x_{i,d} (task dimension; roll-pitch-yaw for 3-D orientation).
    pub goal: Option<Vec<f64>>,
    /// A desired path in place of `goal`: a CSV file relative to the scenario
    /// (docs/tracking.md).
    pub trajectory: Option<String>,
    /// Whether the level gets the tracking feed-forward while a level follows a
    /// path (default true; false: its goal is pulled along).
    pub feed_forward: Option<bool>,
}

/// `[controller]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerSection {
    /// Add the power-conserving Coriolis cancellation τ_μ (eq. 22).
    #[serde(default = "yes")]
    pub coriolis_cancellation: bool,
    /// Form of the null-space torques (`extended`, `projector`, `kinematic_projector`).
    #[serde(default)]
    pub form: hcc_spec::Form,
    #[serde(default)]
    pub singularity: SingularitySection,
    /// The control rate (Hz): the cycle's, the drivers' and the bridge's
    /// period is its inverse; default 1000.
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
}

impl Default for ControllerSection {
    fn default() -> Self {
        ControllerSection {
            rate_hz: default_rate(),
            coriolis_cancellation: true,
            form: hcc_spec::Form::Extended,
            singularity: SingularitySection::default(),
        }
    }
}

/// `[controller.singularity]`: handling of (near-)singular task Jacobians.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SingularitySection {
    /// Eigenvalue ratio λ_min/λ_max of a Gram matrix (J M⁻¹ Jᵀ, J Jᵀ, Z M Zᵀ) below
    /// which its inversion is damped and the level flagged singular; in (0, 1).
    #[serde(default = "default_singular_ratio")]
    pub singular_ratio: f64,
}

fn default_singular_ratio() -> f64 {
    1e-6
}

impl Default for SingularitySection {
    fn default() -> Self {
        SingularitySection {
            singular_ratio: default_singular_ratio(),
        }
    }
}

/// `[initial]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialSection {
    /// Initial joint positions (n).
    pub q0: Vec<f64>,
    /// Initial joint velocities (n, default 0).
    pub qd0: Option<Vec<f64>>,
}

/// `[simulation]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSection {
    #[serde(default = "default_duration")]
    pub duration_s: f64,
    /// Moved to `[controller] rate_hz` (the rate is the controller's, also
    /// with a real robot): refused with that name.
    pub control_rate_hz: Option<toml::Value>,
    #[serde(default = "default_dt")]
    pub integrator_dt_s: f64,
    /// Viscous joint friction in the plant, Nms/rad (scalar or per joint, default 0).
    pub joint_friction: Option<PerJoint>,
    /// External wrenches (`[[simulation.wrench]]`), applied in the plant only.
    #[serde(default)]
    pub wrench: Vec<WrenchSection>,
    /// Loads the plant's tip takes at a time (`[[simulation.load]]`), in the
    /// plant only: what the controller is not told.
    #[serde(default)]
    pub load: Vec<TimedLoadSection>,
}

fn default_duration() -> f64 {
    3.0
}
fn default_rate() -> f64 {
    1000.0
}
fn default_dt() -> f64 {
    1e-4
}

impl Default for SimulationSection {
    fn default() -> Self {
        SimulationSection {
            duration_s: default_duration(),
            control_rate_hz: None,
            integrator_dt_s: default_dt(),
            joint_friction: None,
            wrench: Vec::new(),
            load: Vec::new(),
        }
    }
}

/// `[[simulation.wrench]]`: force/torque at a link frame origin, world axes.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WrenchSection {
    pub start_s: f64,
    pub duration_s: f64,
    pub link: String,
    /// N, world axes (default 0).
    pub force: Option<Vec<f64>>,
    /// Nm, world axes (default 0).
    pub torque: Option<Vec<f64>>,
}

/// `[ipc]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IpcSection {
    /// Namespace prefixed to every shared-memory service name.
    #[serde(default = "default_namespace")]
    pub namespace: String,
}

fn default_namespace() -> String {
    "hcc".to_string()
}

impl Default for IpcSection {
    fn default() -> Self {
        IpcSection {
            namespace: default_namespace(),
        }
    }
}

/// `[controller_daemon]`
#[derive(Clone, Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ControllerDaemonSection {
    /// CPU core to pin the control thread to; the daemon refuses to start
    /// when this core is not available to it.
    pub cpu_core: Option<usize>,
    /// SCHED_FIFO priority 1..=99 (none: normal scheduling).
    pub sched_priority: Option<i32>,
    /// Lock memory (mlockall).
    #[serde(default)]
    pub mlock: bool,
    /// How the control loop waits for a new joint state (`event` or
    /// `hybrid`, the default): the runtime's to check (`hcc_rt::WaitStrategy`).
    pub wait_strategy: Option<String>,
    /// Torque limits, Nm (scalar or per joint; default: the URDF effort limits).
    pub torque_limits: Option<PerJoint>,
    /// No joint state for this long: the driver is declared lost, ms
    /// (default three control periods, 3 ms at 1 kHz).
    pub stale_timeout_ms: Option<f64>,
    /// Hybrid wait: warm the caches once per cycle, in the spin shortly
    /// before the next state (early enough to be over when it comes), by
    /// stepping a copy of the law on the last state (default true).
    pub warm_up: Option<bool>,
}

/// Pacing of the simulator daemon.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SimMode {
    /// Advance with the wall clock at the control rate.
    #[default]
    Realtime,
    /// Advance one control period per received torque command.
    Lockstep,
}

/// `[sim_daemon]`
#[derive(Clone, Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SimDaemonSection {
    /// CPU core to pin the simulator thread to (checked like
    /// `controller_daemon.cpu_core`).
    pub cpu_core: Option<usize>,
    #[serde(default)]
    pub mode: SimMode,
    /// Control periods the last torque is held when no new command arrives (default 3).
    pub hold_cycles: Option<u32>,
    /// After that, τ = g(q) − D q̇ with this damping, Nms/rad (scalar or per joint, default 2).
    pub fallback_damping: Option<PerJoint>,
}

/// `[safety]`: the controller's safety layer (passive fade, null-space damping of
/// faded levels, joint position and velocity limits from the URDF). Every field is
/// optional; the defaults are those of `hcc_spec::SafetySpec` and act only near
/// singularities and limits.
#[derive(Clone, Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SafetySection {
    /// Switch the safety layer off (default on).
    pub enabled: Option<bool>,
    /// Distance from a URDF position limit at which the guard starts (rad or m).
    pub joint_limit_margin: Option<f64>,
    /// Guard spring torque at half the margin (default: the URDF effort limit).
    pub joint_limit_torque: Option<f64>,
    /// Damping ratio of the guard at full penetration.
    pub joint_limit_damping_ratio: Option<f64>,
    /// Fraction of the URDF velocity limit at which the velocity governor comes in.
    pub velocity_limit_fraction: Option<f64>,
    /// Fraction of the URDF velocity limit at which the velocity governor is fully on.
    pub velocity_limit_full_fraction: Option<f64>,
    /// The spring saturation (each level's spring force capped from the velocity limits).
    pub spring_saturation: Option<bool>,
    /// The velocity governor (the springs stop driving a joint near its velocity limit).
    pub velocity_governor: Option<bool>,
    /// The velocity barrier (default true).
    pub velocity_barrier: Option<bool>,
    /// The velocity barrier's rate α, 1/s (default 20).
    pub velocity_barrier_rate: Option<f64>,
    /// Velocity-limit joint damping rate, 1/s (default 100; 0: off).
    pub velocity_damping: Option<f64>,
    /// Null-space damping rate of faded levels, 1/s.
    pub null_space_damping: Option<f64>,
    /// Conditioning of a level's own Λ_i at which the conflict fade has faded it out
    /// (default 1e-5; 0: off).
    pub conflict_fade_ratio: Option<f64>,
    /// Capacity of the energy tank that pays fade-ins, J.
    pub fade_tank_max: Option<f64>,
    /// The passivity damping (default true).
    pub passivity_damping: Option<bool>,
    /// Energy the hierarchy may feed into the arm after a goal or gains change
    /// before the passivity damping acts, J (default 0.25).
    pub passivity_budget: Option<f64>,
    /// The passivity damping's largest rate, 1/s (default 50).
    pub passivity_damping_rate: Option<f64>,
    /// The energy tanks of the levels below the first (default true).
    pub energy_tanks: Option<bool>,
    /// A tank's energy at the start and after a goal or gains change, J, plus half the
    /// storage then (default 2).
    pub tank_initial: Option<f64>,
    /// A tank's capacity, J (default 4).
    pub tank_max: Option<f64>,
    /// K_P, the return rate of a level's shifted spring point, 1/s (default 2).
    pub tank_return_rate: Option<f64>,
}
