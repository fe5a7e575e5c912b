//! The loaded and checked [`Scenario`], and its small methods.

use std::path::PathBuf;

use hcc_model::Model;
use hcc_msgs::scenario::{JointInfo, LevelInfo, SCENARIO_SCHEMA_VERSION, ScenarioDoc};
use hcc_spec::{ControllerSpec, LevelSpec};
use nalgebra::DVector;

use crate::daemons::{ControllerDaemon, SimDaemon};
use crate::error::{ConfigError, invalid};
use crate::franka;
use crate::schedule;
use crate::schema::IpcSection;
use crate::simulation::Simulation;

/// A loaded and checked scenario. Every setting lives in one place: the hierarchy
/// and the controller options (gravity compensation, τ_μ, form, singular ratio) in
/// [`Scenario::spec`].
#[derive(Clone, Debug)]
pub struct Scenario {
    /// The scenario file.
    pub path: PathBuf,
    /// The file's text (to name the line of a field in a later check's
    /// error, [`Scenario::error_at`]).
    pub(crate) text: String,
    /// Name (from the file or its stem).
    pub name: String,
    /// Resolved URDF path.
    pub urdf_path: PathBuf,
    /// The robot model (chain root → tip, with the configured gravity).
    pub model: Model,
    /// The controller: the levels in priority order (`spec.levels`, each stacking its
    /// tasks) and `[controller]`, `[robot] gravity_compensation` (checked by
    /// `hcc_spec::ControllerSpec::validate` at load; what the law refuses at q0 by
    /// `hcc_cycle::controller_for`).
    pub spec: ControllerSpec,
    /// `[controller] rate_hz`: the control rate (Hz) of the cycle, the
    /// drivers and the bridge.
    pub rate_hz: f64,
    pub q0: DVector<f64>,
    pub qd0: DVector<f64>,
    pub simulation: Simulation,
    pub ipc: IpcSection,
    pub controller_daemon: ControllerDaemon,
    pub sim_daemon: SimDaemon,
    /// Resolved `[setpoint_limits]`.
    pub setpoint_limits: hcc_spec::setpoint_limits::SetpointLimits,
    /// Resolved `[torque_filter]`.
    pub torque_filter: hcc_spec::torque_filter::TorqueFilterSpec,
    /// The `[[setpoint]]` entries, checked and sorted by time.
    pub setpoints: Vec<schedule::ScheduledSetpoint>,
    /// Resolved `[franka]` (libfranka's defaults where not given).
    pub franka: franka::Franka,
    /// Resolved `[contact]` (the defaults where not given).
    pub contact: hcc_spec::contact::Contact,
    /// The levels' paths (`trajectory`) and feed-forward flags
    /// (docs/tracking.md).
    pub tracking: hcc_spec::tracking::Tracking,
}

impl Scenario {
    /// Overrides the simulated duration (e.g. from the command line).
    pub fn set_duration(&mut self, duration_s: f64) -> Result<(), ConfigError> {
        let cycles = duration_s * self.rate_hz;
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
        let mut sorted = available.to_vec();
        sorted.sort_unstable();
        Err(self.error_at(
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

    /// An error of a check made after loading, by the layer whose setting it
    /// is (the runtime's wait strategy, a daemon's CPU core): `path` is the
    /// dotted field (`controller_daemon.wait_strategy`), named with the file
    /// and its line as [`Scenario::load`]'s own errors are.
    pub fn error_at(&self, path: &str, message: impl Into<String>) -> ConfigError {
        invalid(&self.path, &self.text, path, message)
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

    /// The scenario file's text as loaded.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The levels' path files (`trajectory`) as the scenario names them,
    /// with their texts as loaded (what a recording and the scenario
    /// document carry, so that the scenario is built again without them).
    pub fn path_texts(&self) -> std::collections::BTreeMap<String, String> {
        self.tracking
            .paths
            .iter()
            .flatten()
            .map(|p| (p.file.clone(), p.text.clone()))
            .collect()
    }

    /// What the controller publishes on its scenario service for the tools
    /// that know only `namespace` (`hcc_msgs::ipc::ScenarioPublisher`): the
    /// file's text as loaded, the URDF's text (empty when it cannot be read
    /// again), the levels, the joints with their limits, the control rate, the
    /// levels' path files.
    pub fn document(&self, namespace: &str) -> ScenarioDoc {
        let n = self.model.nq();
        let dims = self.task_dims();
        ScenarioDoc {
            version: SCENARIO_SCHEMA_VERSION,
            name: self.name.clone(),
            namespace: namespace.to_string(),
            rate_hz: self.rate_hz,
            form: self.spec.form.name().to_string(),
            coriolis_cancellation: self.spec.coriolis_cancellation,
            gravity_compensation: self.spec.gravity_compensation,
            path: self.path.display().to_string(),
            toml: self.text.clone(),
            urdf_path: self.urdf_path.display().to_string(),
            urdf: std::fs::read_to_string(&self.urdf_path).unwrap_or_default(),
            paths: self.path_texts(),
            levels: self
                .spec
                .levels
                .iter()
                .zip(&dims)
                .map(|(l, &dim)| LevelInfo {
                    name: l.name.clone(),
                    tasks: l.tasks.iter().map(|t| t.kind().to_string()).collect(),
                    dim,
                    goal: l.goal.iter().copied().collect(),
                    // Row-major (nalgebra stores by column; K and D are symmetric).
                    stiffness: l.stiffness.transpose().iter().copied().collect(),
                    damping: l.damping.transpose().iter().copied().collect(),
                })
                .collect(),
            joints: self
                .model
                .joints
                .iter()
                .take(n)
                .map(|j| {
                    JointInfo::new(&j.name, j.lower, j.upper, j.velocity_limit, j.effort_limit)
                })
                .collect(),
        }
    }

    /// How this scenario differs from what a controller runs (its published
    /// document): the levels' names and dimensions, the joints' names, the
    /// control rate. `None` when they agree (a tool given `--config` says
    /// the difference).
    pub fn differs_from(&self, running: &ScenarioDoc) -> Option<String> {
        let mine = self.document(&running.namespace);
        let levels = |d: &ScenarioDoc| -> Vec<(String, usize)> {
            d.levels.iter().map(|l| (l.name.clone(), l.dim)).collect()
        };
        let joints =
            |d: &ScenarioDoc| -> Vec<String> { d.joints.iter().map(|j| j.name.clone()).collect() };
        let mut diffs = Vec::new();
        if levels(&mine) != levels(running) {
            diffs.push(format!(
                "levels (name, dimension) {:?}, the controller runs {:?}",
                levels(&mine),
                levels(running)
            ));
        }
        if joints(&mine) != joints(running) {
            diffs.push(format!(
                "joints {:?}, the controller's {:?}",
                joints(&mine),
                joints(running)
            ));
        }
        if mine.rate_hz != running.rate_hz {
            diffs.push(format!(
                "control rate {} Hz, the controller's {} Hz",
                mine.rate_hz, running.rate_hz
            ));
        }
        (!diffs.is_empty()).then(|| {
            format!(
                "{} is not what the controller in namespace {:?} runs ({}): {}",
                self.path.display(),
                running.namespace,
                running.path,
                diffs.join("; ")
            )
        })
    }

    /// Task dimension m_i of every level.
    pub fn task_dims(&self) -> Vec<usize> {
        self.spec.task_dims(self.model.nq())
    }

    /// Control cycles of the run: duration × control rate (the states
    /// k = 0..=cycles are sampled).
    pub fn cycles(&self) -> u64 {
        (self.simulation.duration_s * self.rate_hz).round() as u64
    }

    /// The control period T = 1 / `rate_hz` (s).
    pub fn period_s(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// The control period in whole ns (as the daemons count it): 1e9 /
    /// `rate_hz`, rounded.
    pub fn period_ns(&self) -> u64 {
        (1e9 / self.rate_hz).round() as u64
    }

    /// The `[[setpoint]]` entries due within the run, as the messages a client
    /// sends (each applied at the state of its cycle), in time order.
    pub fn scheduled_messages(&self) -> Vec<hcc_msgs::Setpoint> {
        let rate = self.rate_hz;
        self.setpoints
            .iter()
            .filter(|e| e.cycle(rate) <= self.cycles())
            .map(|e| e.message(rate))
            .collect()
    }
}
