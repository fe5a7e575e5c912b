//! `SWEEP_SAFETY`: the `[safety]` and torque-filter overrides of a comparison
//! run, shared by the sweeps.

use hcc_config::Scenario;

/// `SWEEP_SAFETY=field=value,…`: the `[safety]` fields of a comparison run (numeric
/// fields, and `enabled=0` for the paper's law alone). Returns whether anything was
/// changed, and whether anything but the torque filter was.
pub fn sweep_safety_overrides(s: &mut Scenario) -> (bool, bool) {
    let Ok(v) = std::env::var("SWEEP_SAFETY") else {
        return (false, false);
    };
    let mut beyond_the_filter = false;
    for kv in v.split(',').filter(|kv| !kv.is_empty()) {
        let (k, x) = kv
            .split_once('=')
            .unwrap_or_else(|| panic!("SWEEP_SAFETY: {kv:?} is not field=value"));
        let x: f64 = x
            .parse()
            .unwrap_or_else(|e| panic!("SWEEP_SAFETY: {kv:?}: {e}"));
        let sp = &mut s.spec.safety;
        beyond_the_filter |= !matches!(k, "torque_rate_limit" | "per_joint" | "low_pass_hz");
        match k {
            "null_space_damping" => sp.null_space_damping = x,
            "conflict_fade_ratio" => sp.conflict_fade_ratio = x,
            "velocity_damping" => sp.velocity_damping = x,
            "fade_tank_max" => sp.fade_tank_max = x,
            "energy_tanks" => sp.energy_tanks = x != 0.0,
            "tank_initial" => sp.tank_initial = x,
            "tank_max" => sp.tank_max = x,
            "tank_return_rate" => sp.tank_return_rate = x,
            "passivity_damping" => sp.passivity_damping = x != 0.0,
            "passivity_budget" => sp.passivity_budget = x,
            "passivity_damping_rate" => sp.passivity_damping_rate = x,
            "velocity_limit_fraction" => sp.velocity_limit_fraction = x,
            "velocity_limit_full_fraction" => sp.velocity_limit_full_fraction = x,
            "joint_limit_margin" => sp.joint_limit_margin = x,
            "joint_limit_damping_ratio" => sp.joint_limit_damping_ratio = x,
            "enabled" => sp.enabled = x != 0.0,
            // The hierarchy's ε: where the damped inverses and the fade of the
            // lower levels and τ_μ begin (crate docs, "Singularities").
            "singular_ratio" => s.spec.singular_ratio = x,
            "velocity_governor" => sp.velocity_governor = x != 0.0,
            "velocity_barrier" => sp.velocity_barrier = x != 0.0,
            "velocity_barrier_rate" => sp.velocity_barrier_rate = x,
            "spring_saturation" => sp.spring_saturation = x != 0.0,
            // The torque filter: its rate limit (N·m/s, 0: off), per joint (1) or
            // whole (0), its low-pass (Hz, 0: off).
            // The filter and what the safety layer knows of it, together.
            "torque_rate_limit" => {
                s.torque_filter.torque_rate_limit = (x > 0.0).then_some(x);
                sp.torque_rate_limit = s.torque_filter.torque_rate_limit;
            }
            "per_joint" => {
                s.torque_filter.rate_limit_mode = if x != 0.0 {
                    hcc_spec::torque_filter::RateLimitMode::PerJoint
                } else {
                    hcc_spec::torque_filter::RateLimitMode::Whole
                }
            }
            "low_pass_hz" => s.torque_filter.low_pass_hz = (x > 0.0).then_some(x),
            // The posture level's and the TCP level's transition speeds.
            "posture_max_speed" => s.setpoint_limits.levels[2].max_speed = x,
            "tcp_max_speed" => s.setpoint_limits.levels[0].max_speed = x,
            // Every level x times faster: K_i × x², D_i × x.
            "gain_scale" => {
                for l in &mut s.spec.levels {
                    l.stiffness *= x * x;
                    l.damping *= x;
                }
            }
            _ => panic!("SWEEP_SAFETY: unknown field {k:?}"),
        }
    }
    s.spec
        .safety
        .validate()
        .unwrap_or_else(|e| panic!("SWEEP_SAFETY: {e}"));
    (true, beyond_the_filter)
}
