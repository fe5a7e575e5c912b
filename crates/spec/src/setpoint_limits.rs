//! The limits of setpoints (`[setpoint_limits]`, read by `hcc-config`,
//! checked by the control cycle when it takes a setpoint): per level the
//! largest stiffness, the equilibrium's peak speed and the workspace box.

/// Default peak equilibrium speed of a position task, m/s.
pub const DEFAULT_MAX_LINEAR_SPEED: f64 = 0.25;
/// Default peak equilibrium speed of an angular or joint task, rad/s.
pub const DEFAULT_MAX_ANGULAR_SPEED: f64 = 1.0;
/// Default `max_stiffness`: this factor × the largest eigenvalue of the file's K_i.
pub const DEFAULT_STIFFNESS_FACTOR: f64 = 4.0;

/// Resolved limits of one level.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelSetpointLimits {
    /// Largest eigenvalue of K_i a setpoint may ask for.
    pub max_stiffness: f64,
    /// Peak speed of the equilibrium (m/s or rad/s): a transition is
    /// stretched so that 15/8 · |Δx| / T stays below it.
    pub max_speed: f64,
    /// Box (min, max) on the task's coordinates, position tasks only.
    pub workspace: Option<(Vec<f64>, Vec<f64>)>,
}

/// Default of [`SetpointLimits::path_knots`].
pub const DEFAULT_PATH_KNOTS: usize = 256;
/// Default of [`SetpointLimits::path_check_timeout_ms`].
pub const DEFAULT_PATH_CHECK_TIMEOUT_MS: f64 = 100.0;
/// Most knots a level's run-time path may be configured to hold ahead.
pub const MAX_PATH_KNOTS: usize = 100_000;

/// Resolved `[setpoint_limits]`.
#[derive(Clone, Debug, PartialEq)]
pub struct SetpointLimits {
    /// Damp ẋ_i − ẋ_{i,d} while a goal moves.
    pub relative_damping: bool,
    /// Knots a level's run-time path holds ahead at most (docs/tracking.md).
    pub path_knots: usize,
    /// How long a run-time path message waits for its feasibility check at
    /// most before it is refused `unchecked`, ms (docs/tracking.md).
    pub path_check_timeout_ms: f64,
    /// One per level.
    pub levels: Vec<LevelSetpointLimits>,
}
