//! `[franka]`: the settings of the Franka driver `hcc-franka` (FR3 over FCI
//! protocol 10, Panda/FER over protocol 5). Every field is optional; the
//! defaults are libfranka's.
//!
//! ```toml
//! [franka]
//! # Collision behaviour (libfranka `Robot::setCollisionBehavior`), N·m and N.
//! # Between lower and upper: a contact in the state; above upper: a reflex.
//! lower_torque_thresholds_acceleration = [20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0]
//! upper_torque_thresholds_acceleration = [20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0]
//! lower_torque_thresholds_nominal = [20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0]
//! upper_torque_thresholds_nominal = [20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0]
//! lower_force_thresholds_acceleration = [20.0, 20.0, 20.0, 25.0, 25.0, 25.0]
//! upper_force_thresholds_acceleration = [20.0, 20.0, 20.0, 25.0, 25.0, 25.0]
//! lower_force_thresholds_nominal = [20.0, 20.0, 20.0, 25.0, 25.0, 25.0]
//! upper_force_thresholds_nominal = [20.0, 20.0, 20.0, 25.0, 25.0, 25.0]
//! # The driver's guard before the robot.
//! torque_limits = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]  # N·m
//! torque_rate_limit = 1000.0  # N·m/s, at most 1000 (1 N·m per 1 ms cycle)
//! # What the driver does without an applicable command.
//! command_window_us = 700.0  # wait this long after a state for its answer
//! hold_cycles = 3            # then hold the last torque this many cycles
//! fallback_damping = [10.0, 10.0, 10.0, 10.0, 4.0, 4.0, 1.0]  # then τ = −D q̇, N·m·s/rad
//! fallback_timeout_ms = 100.0  # then end the motion (motion_finished)
//! ```
//!
//! The collision defaults are the values libfranka's examples set
//! (`setDefaultBehavior`, `examples_common.cpp`); the torque limits are the
//! FR3's and the Panda's joint torque limits (datasheet: 87 N·m joints 1–4,
//! 12 N·m joints 5–7); 1000 N·m/s is libfranka's `kMaxTorqueRate`, above which
//! the robot aborts with `controller_torque_discontinuity`.

use std::path::Path;

use serde::Deserialize;

use crate::error::{ConfigError, invalid};

/// Joints of a Franka arm.
pub const FRANKA_JOINTS: usize = 7;

/// libfranka's default torque thresholds (N·m), for all four torque fields.
pub const DEFAULT_TORQUE_THRESHOLDS: [f64; FRANKA_JOINTS] =
    [20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0];
/// libfranka's default Cartesian force/torque thresholds (N, N·m), for all
/// four force fields.
pub const DEFAULT_FORCE_THRESHOLDS: [f64; 6] = [20.0, 20.0, 20.0, 25.0, 25.0, 25.0];
/// The joint torque limits of the FR3 and the Panda, N·m.
pub const FRANKA_TORQUE_LIMITS: [f64; FRANKA_JOINTS] = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0];
/// The largest torque rate the robot accepts, N·m/s (libfranka `kMaxTorqueRate`).
pub const FRANKA_MAX_TORQUE_RATE: f64 = 1000.0;

/// `[franka]` as written.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrankaSection {
    pub lower_torque_thresholds_acceleration: Option<Vec<f64>>,
    pub upper_torque_thresholds_acceleration: Option<Vec<f64>>,
    pub lower_torque_thresholds_nominal: Option<Vec<f64>>,
    pub upper_torque_thresholds_nominal: Option<Vec<f64>>,
    pub lower_force_thresholds_acceleration: Option<Vec<f64>>,
    pub upper_force_thresholds_acceleration: Option<Vec<f64>>,
    pub lower_force_thresholds_nominal: Option<Vec<f64>>,
    pub upper_force_thresholds_nominal: Option<Vec<f64>>,
    pub torque_limits: Option<Vec<f64>>,
    pub torque_rate_limit: Option<f64>,
    pub command_window_us: Option<f64>,
    pub hold_cycles: Option<u32>,
    pub fallback_damping: Option<Vec<f64>>,
    pub fallback_timeout_ms: Option<f64>,
}

/// The collision behaviour (the eight arrays of libfranka's
/// `setCollisionBehavior`, in its argument order).
#[derive(Clone, Debug, PartialEq)]
pub struct CollisionBehavior {
    pub lower_torque_thresholds_acceleration: [f64; FRANKA_JOINTS],
    pub upper_torque_thresholds_acceleration: [f64; FRANKA_JOINTS],
    pub lower_torque_thresholds_nominal: [f64; FRANKA_JOINTS],
    pub upper_torque_thresholds_nominal: [f64; FRANKA_JOINTS],
    pub lower_force_thresholds_acceleration: [f64; 6],
    pub upper_force_thresholds_acceleration: [f64; 6],
    pub lower_force_thresholds_nominal: [f64; 6],
    pub upper_force_thresholds_nominal: [f64; 6],
}

impl Default for CollisionBehavior {
    fn default() -> Self {
        let t = DEFAULT_TORQUE_THRESHOLDS;
        let f = DEFAULT_FORCE_THRESHOLDS;
        CollisionBehavior {
            lower_torque_thresholds_acceleration: t,
            upper_torque_thresholds_acceleration: t,
            lower_torque_thresholds_nominal: t,
            upper_torque_thresholds_nominal: t,
            lower_force_thresholds_acceleration: f,
            upper_force_thresholds_acceleration: f,
            lower_force_thresholds_nominal: f,
            upper_force_thresholds_nominal: f,
        }
    }
}

/// Resolved `[franka]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Franka {
    pub collision: CollisionBehavior,
    /// The driver's torque limits per joint, N·m (the robot's by default).
    pub torque_limits: [f64; FRANKA_JOINTS],
    /// The driver's torque-rate limit, N·m/s (≤ [`FRANKA_MAX_TORQUE_RATE`]).
    pub torque_rate_limit: f64,
    /// After a state, how long the driver waits for its answer, µs.
    pub command_window_us: f64,
    /// Cycles the last torque is held when no applicable command arrived.
    pub hold_cycles: u32,
    /// Damping D of the fallback torque −D q̇ (the robot adds gravity), N·m·s/rad.
    pub fallback_damping: [f64; FRANKA_JOINTS],
    /// Time in fallback after which the driver ends the motion, ms.
    pub fallback_timeout_ms: f64,
}

impl Default for Franka {
    fn default() -> Self {
        Franka {
            collision: CollisionBehavior::default(),
            torque_limits: FRANKA_TORQUE_LIMITS,
            torque_rate_limit: FRANKA_MAX_TORQUE_RATE,
            command_window_us: 700.0,
            hold_cycles: 3,
            fallback_damping: [10.0, 10.0, 10.0, 10.0, 4.0, 4.0, 1.0],
            fallback_timeout_ms: 100.0,
        }
    }
}

/// An optional array of `N` finite, non-negative numbers (`default` when absent).
fn array<const N: usize>(
    file: &Path,
    text: &str,
    name: &str,
    value: &Option<Vec<f64>>,
    default: [f64; N],
) -> Result<[f64; N], ConfigError> {
    let Some(v) = value else {
        return Ok(default);
    };
    let path = format!("franka.{name}");
    let out: [f64; N] = v.as_slice().try_into().map_err(|_| {
        invalid(
            file,
            text,
            &path,
            format!("has {} elements, expected {N}", v.len()),
        )
    })?;
    if let Some(k) = out.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
        return Err(invalid(
            file,
            text,
            &format!("{path}[{k}]"),
            format!("{} must be a finite number ≥ 0", out[k]),
        ));
    }
    Ok(out)
}

/// A positive, finite number in `(0, max]` (`default` when absent).
fn positive(
    file: &Path,
    text: &str,
    name: &str,
    value: Option<f64>,
    max: f64,
    default: f64,
) -> Result<f64, ConfigError> {
    match value {
        None => Ok(default),
        Some(v) if v.is_finite() && v > 0.0 && v <= max => Ok(v),
        Some(v) => Err(invalid(
            file,
            text,
            &format!("franka.{name}"),
            format!("{v} must be positive and at most {max}"),
        )),
    }
}

/// `[franka]`'s collision thresholds, each defaulting to libfranka's.
fn resolve_collision(
    file: &Path,
    text: &str,
    s: &FrankaSection,
    default: &CollisionBehavior,
) -> Result<CollisionBehavior, ConfigError> {
    macro_rules! thresholds {
        ($($name:ident),+ $(,)?) => {
            CollisionBehavior {
                $($name: array(file, text, stringify!($name), &s.$name, default.$name)?,)+
            }
        };
    }
    Ok(thresholds!(
        lower_torque_thresholds_acceleration,
        upper_torque_thresholds_acceleration,
        lower_torque_thresholds_nominal,
        upper_torque_thresholds_nominal,
        lower_force_thresholds_acceleration,
        upper_force_thresholds_acceleration,
        lower_force_thresholds_nominal,
        upper_force_thresholds_nominal,
    ))
}

/// `[franka] torque_limits`: positive and never above the robot's own limits.
fn resolve_torque_limits(
    file: &Path,
    text: &str,
    s: &FrankaSection,
    default: [f64; FRANKA_JOINTS],
) -> Result<[f64; FRANKA_JOINTS], ConfigError> {
    let torque_limits = array(file, text, "torque_limits", &s.torque_limits, default)?;
    if let Some(k) = torque_limits
        .iter()
        .zip(&FRANKA_TORQUE_LIMITS)
        .position(|(t, max)| *t == 0.0 || t > max)
    {
        return Err(invalid(
            file,
            text,
            &format!("franka.torque_limits[{k}]"),
            format!(
                "{} must be positive and at most the robot's limit {} N·m",
                torque_limits[k], FRANKA_TORQUE_LIMITS[k]
            ),
        ));
    }
    Ok(torque_limits)
}

/// Checks `[franka]` and fills in libfranka's defaults.
pub(crate) fn resolve(file: &Path, text: &str, s: &FrankaSection) -> Result<Franka, ConfigError> {
    let d = Franka::default();
    let collision = resolve_collision(file, text, s, &d.collision)?;
    check_lower_below_upper(file, text, &collision)?;
    let torque_limits = resolve_torque_limits(file, text, s, d.torque_limits)?;
    Ok(Franka {
        collision,
        torque_limits,
        torque_rate_limit: positive(
            file,
            text,
            "torque_rate_limit",
            s.torque_rate_limit,
            FRANKA_MAX_TORQUE_RATE,
            d.torque_rate_limit,
        )?,
        // A command must reach the robot within its 1 ms cycle.
        command_window_us: positive(
            file,
            text,
            "command_window_us",
            s.command_window_us,
            950.0,
            d.command_window_us,
        )?,
        hold_cycles: s.hold_cycles.unwrap_or(d.hold_cycles),
        fallback_damping: array(
            file,
            text,
            "fallback_damping",
            &s.fallback_damping,
            d.fallback_damping,
        )?,
        fallback_timeout_ms: positive(
            file,
            text,
            "fallback_timeout_ms",
            s.fallback_timeout_ms,
            10_000.0,
            d.fallback_timeout_ms,
        )?,
    })
}

/// Every lower threshold must not exceed its upper one (the robot refuses it).
fn check_lower_below_upper(
    file: &Path,
    text: &str,
    c: &CollisionBehavior,
) -> Result<(), ConfigError> {
    let pairs: [(&str, &[f64], &[f64]); 4] = [
        (
            "lower_torque_thresholds_acceleration",
            &c.lower_torque_thresholds_acceleration,
            &c.upper_torque_thresholds_acceleration,
        ),
        (
            "lower_torque_thresholds_nominal",
            &c.lower_torque_thresholds_nominal,
            &c.upper_torque_thresholds_nominal,
        ),
        (
            "lower_force_thresholds_acceleration",
            &c.lower_force_thresholds_acceleration,
            &c.upper_force_thresholds_acceleration,
        ),
        (
            "lower_force_thresholds_nominal",
            &c.lower_force_thresholds_nominal,
            &c.upper_force_thresholds_nominal,
        ),
    ];
    for (name, lower, upper) in pairs {
        if let Some(k) = lower.iter().zip(upper).position(|(l, u)| l > u) {
            return Err(invalid(
                file,
                text,
                &format!("franka.{name}[{k}]"),
                format!(
                    "{} exceeds the upper threshold {} ({})",
                    lower[k],
                    upper[k],
                    name.replacen("lower", "upper", 1)
                ),
            ));
        }
    }
    Ok(())
}
