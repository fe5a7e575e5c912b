//! `[controller_daemon]` and `[sim_daemon]`: the settings of the daemons.

use hcc_model::Model;
use nalgebra::DVector;

use crate::context::Ctx;
use crate::error::ConfigError;
use crate::schema::{ControllerDaemonSection, SimDaemonSection, SimMode};

/// Resolved `[controller_daemon]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerDaemon {
    pub cpu_core: Option<usize>,
    pub sched_priority: Option<i32>,
    pub mlock: bool,
    /// `wait_strategy` as written (none: the runtime's default); the
    /// runtime's to check (`hcc_rt::WaitStrategy`, at the daemon's start-up).
    pub wait_strategy: Option<String>,
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

/// Default stale timeout of the controller daemon, in control periods: the
/// peer is declared lost when the third consecutive state is missing.
pub const STALE_TIMEOUT_PERIODS: f64 = 3.0;

/// Largest CPU index a `cpu_core` may name (Linux' `CPU_SETSIZE` − 1).
pub const MAX_CPU_CORE: usize = 1023;

pub(crate) fn resolve_controller_daemon(
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
        wait_strategy: d.wait_strategy.clone(),
        torque_limits,
        stale_timeout_ms,
        warm_up: d.warm_up.unwrap_or(true),
    })
}

pub(crate) fn resolve_sim_daemon(
    cx: &Ctx,
    n: usize,
    d: &SimDaemonSection,
) -> Result<SimDaemon, ConfigError> {
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
