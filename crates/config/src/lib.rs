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
//! [`Scenario::spec`] (`hcc_spec::ControllerSpec`).

pub mod contact;
pub mod error;
pub mod franka;
pub mod schedule;
pub mod schema;
pub mod setpoint_limits;
pub mod torque_filter;
pub mod values;

mod context;
mod daemons;
mod levels;
mod load;
mod published;
mod robot;
mod safety;
mod scenario;
mod simulation;
mod tasks;
mod trajectories;

pub use daemons::{ControllerDaemon, MAX_CPU_CORE, STALE_TIMEOUT_PERIODS, SimDaemon};
pub use error::ConfigError;
pub use published::{COMPARE_WAIT, ToolScenarioError, scenario_for_tool};
pub use scenario::Scenario;
pub use schema::*;
pub use simulation::{Simulation, TimedLoad, Wrench};

pub use hcc_spec::{ControllerSpec, Form, LevelSpec, TaskSpec, TaskUnit};
