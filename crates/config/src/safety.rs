//! `[safety]`: the safety layer of the controller over its defaults.

use crate::context::Ctx;
use crate::error::ConfigError;
use crate::schema;

/// `[safety]` over the defaults of `hcc_spec::SafetySpec`, the control period from
/// the control rate, the torque rate limit from `[torque_filter]`.
pub(crate) fn safety_spec(
    cx: &Ctx,
    s: &schema::SafetySection,
    control_rate_hz: f64,
    torque_rate_limit: Option<f64>,
) -> Result<hcc_spec::SafetySpec, ConfigError> {
    let d = hcc_spec::SafetySpec::default();
    let spec = hcc_spec::SafetySpec {
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
        velocity_barrier: s.velocity_barrier.unwrap_or(d.velocity_barrier),
        velocity_barrier_rate: s.velocity_barrier_rate.unwrap_or(d.velocity_barrier_rate),
        null_space_damping: s.null_space_damping.unwrap_or(d.null_space_damping),
        conflict_fade_ratio: s.conflict_fade_ratio.unwrap_or(d.conflict_fade_ratio),
        fade_tank_max: s.fade_tank_max.unwrap_or(d.fade_tank_max),
        passivity_damping: s.passivity_damping.unwrap_or(d.passivity_damping),
        passivity_budget: s.passivity_budget.unwrap_or(d.passivity_budget),
        passivity_damping_rate: s.passivity_damping_rate.unwrap_or(d.passivity_damping_rate),
        energy_tanks: s.energy_tanks.unwrap_or(d.energy_tanks),
        tank_initial: s.tank_initial.unwrap_or(d.tank_initial),
        tank_max: s.tank_max.unwrap_or(d.tank_max),
        tank_return_rate: s.tank_return_rate.unwrap_or(d.tank_return_rate),
        control_period_s: 1.0 / control_rate_hz,
        torque_rate_limit,
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
