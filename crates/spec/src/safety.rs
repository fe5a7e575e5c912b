//! The safety layer's configuration, [`SafetySpec`], and its range checks.

use crate::SpecError;

/// Configuration of the safety layer (`hcc_control::safety`). The defaults are on and
/// act only near singularities and limits. One line per field: why it exists,
/// its unit and range; the mechanism's module has the rest.
#[derive(Clone, Debug, PartialEq)]
pub struct SafetySpec {
    /// Master switch: off, the paper's law alone with the plain fade (no mechanism below).
    pub enabled: bool,
    /// Where the joint-limit guard (`hcc_control::safety::joint_limit_guard`) starts, before a URDF position limit (rad or m), > 0.
    pub joint_limit_margin: f64,
    /// The guard's spring torque at half the margin (N·m or N), > 0; `None`: the URDF effort limit (100 without one).
    pub joint_limit_torque: Option<f64>,
    /// The guard's damping ratio ζ against its spring's local stiffness, so it stops without bouncing, ≥ 0.
    pub joint_limit_damping_ratio: f64,
    /// f_on: the share of a URDF velocity limit where the velocity band (`hcc_control::safety::reach`) starts (governor, damping, barrier), in (0, 1).
    pub velocity_limit_fraction: f64,
    /// f_full: the share of a URDF velocity limit where the velocity band ends (all fully on), in (f_on, 1].
    pub velocity_limit_full_fraction: f64,
    /// The spring saturation (`hcc_control::safety::spring_saturation`): a large error's spring settles its damper below f_on of the velocity limits.
    pub spring_saturation: bool,
    /// The velocity governor (`hcc_control::safety::governor`): in the velocity band, the springs that drive the motion stop pushing.
    pub velocity_governor: bool,
    /// The velocity damping (`hcc_control::safety::velocity_damping`)'s rate (1/s; m_k q̇_k times it at f_full), ≥ 0, 0 off, ≤ 1/T.
    pub velocity_damping: f64,
    /// The velocity barrier (`hcc_control::safety::velocity_barrier`): a joint the torque drives too fast towards its limit is braked first.
    pub velocity_barrier: bool,
    /// The barrier's rate α (1/s): the acceleration it allows is α × the speed left to f_full, > 0, ≤ 1/T.
    pub velocity_barrier_rate: f64,
    /// The null-space damping (`hcc_control::safety::null_space_damping`)'s rate (1/s): damps what a faded level no longer controls, ≥ 0, ≤ 1/T.
    pub null_space_damping: f64,
    /// ε_c of the conflict fade (`hcc_control::safety::conflict_fade`): a level in conflict with those above fades below it, in [0, 0.01), 0 off.
    pub conflict_fade_ratio: f64,
    /// The capacity of the passive fade (`hcc_control::safety::passive_fade`)'s energy tank, which pays fade-ins (J), ≥ 0.
    pub fade_tank_max: f64,
    /// The passivity damping (`hcc_control::safety::passivity`): what the hierarchy feeds in beyond its budget is damped out.
    pub passivity_damping: bool,
    /// The energy the hierarchy may feed in after a goal or gains change before the passivity damping acts (J), ≥ 0.
    pub passivity_budget: f64,
    /// The passivity damping's largest rate (1/s), > 0, ≤ 1/T.
    pub passivity_damping_rate: f64,
    /// The energy tanks (`hcc_control::energy_tank`) of the levels below the first: what the levels above do to a level's spring is paid from its tank, so the hierarchy is passive.
    pub energy_tanks: bool,
    /// The energy each tank holds at the start and at least after a goal or gains change (J; plus half the storage then), ≥ 0: the sequential convergence of Sec. IV it pays for.
    pub tank_initial: f64,
    /// A tank's capacity (J), ≥ `tank_initial`: what is above it decays in 0.5 s, so the levels above cannot feed more into the arm from it for long.
    pub tank_max: f64,
    /// K_P (1/s): how fast a level's shifted spring point returns as its tank refills, ≥ 0, ≤ 1/T.
    pub tank_return_rate: f64,
    /// The control period T (s), for the energy per cycle and the rates the loop carries, > 0.
    pub control_period_s: f64,
    /// The torque filter's rate limit R (N·m/s; set from `[torque_filter]`), so the barrier brakes early enough; `None`: no limit.
    pub torque_rate_limit: Option<f64>,
}

impl Default for SafetySpec {
    fn default() -> Self {
        SafetySpec {
            enabled: true,
            joint_limit_margin: 0.1,
            joint_limit_torque: None,
            joint_limit_damping_ratio: 1.0,
            velocity_limit_fraction: 0.6,
            velocity_limit_full_fraction: 0.9,
            spring_saturation: false,
            velocity_governor: true,
            velocity_damping: 100.0,
            velocity_barrier: true,
            velocity_barrier_rate: 20.0,
            null_space_damping: 20.0,
            conflict_fade_ratio: 1e-5,
            fade_tank_max: 5.0,
            passivity_damping: true,
            passivity_budget: 0.25,
            passivity_damping_rate: 50.0,
            energy_tanks: true,
            tank_initial: 2.0,
            tank_max: 4.0,
            tank_return_rate: 2.0,
            control_period_s: 1e-3,
            torque_rate_limit: None,
        }
    }
}

impl SafetySpec {
    /// Checks the ranges (errors name the field).
    pub fn validate(&self) -> Result<(), SpecError> {
        let bad = |f: &str, why: &str| Err(SpecError::Spec(format!("safety.{f} {why}")));
        let pos = |x: f64| x > 0.0 && x.is_finite();
        let nonneg = |x: f64| x >= 0.0 && x.is_finite();
        if !pos(self.joint_limit_margin) {
            return bad("joint_limit_margin", "must be positive");
        }
        if let Some(t) = self.joint_limit_torque
            && !pos(t)
        {
            return bad("joint_limit_torque", "must be positive");
        }
        if !nonneg(self.joint_limit_damping_ratio) {
            return bad("joint_limit_damping_ratio", "must be non-negative");
        }
        if !(self.velocity_limit_fraction > 0.0 && self.velocity_limit_fraction < 1.0) {
            return bad("velocity_limit_fraction", "must be in (0, 1)");
        }
        if !(self.velocity_limit_full_fraction > self.velocity_limit_fraction
            && self.velocity_limit_full_fraction <= 1.0)
        {
            return bad(
                "velocity_limit_full_fraction",
                "must be in (velocity_limit_fraction, 1]",
            );
        }
        // The rates act on the joint's own inertia m_k: rate · T ≤ 1 is what the
        // control period carries (hcc_control::rate; b = rate · T).
        let t = self.control_period_s;
        // A rate (1/s): ≥ 0 (> 0 where `positive`), and at most 1/T.
        let rate = |f: &str, x: f64, positive: bool| {
            if positive && !pos(x) {
                bad(f, "must be positive")
            } else if !nonneg(x) {
                bad(f, "must be non-negative")
            } else if x * t > 1.0 {
                bad(
                    f,
                    "times the control period must be at most 1 (the rate the loop carries)",
                )
            } else {
                Ok(())
            }
        };
        rate("velocity_damping", self.velocity_damping, false)?;
        rate("velocity_barrier_rate", self.velocity_barrier_rate, true)?;
        rate("null_space_damping", self.null_space_damping, false)?;
        rate("passivity_damping_rate", self.passivity_damping_rate, true)?;
        if !(nonneg(self.conflict_fade_ratio) && self.conflict_fade_ratio < 0.01) {
            return bad("conflict_fade_ratio", "must be in [0, 0.01)");
        }
        if !nonneg(self.fade_tank_max) {
            return bad("fade_tank_max", "must be non-negative");
        }
        if !nonneg(self.passivity_budget) {
            return bad("passivity_budget", "must be non-negative");
        }
        if !nonneg(self.tank_initial) {
            return bad("tank_initial", "must be non-negative");
        }
        if !(nonneg(self.tank_max) && self.tank_max >= self.tank_initial) {
            return bad("tank_max", "must be at least tank_initial");
        }
        rate("tank_return_rate", self.tank_return_rate, false)?;
        if !pos(self.control_period_s) {
            return bad("control_period_s", "must be positive");
        }
        if let Some(r) = self.torque_rate_limit
            && !pos(r)
        {
            return bad("torque_rate_limit", "must be positive");
        }
        Ok(())
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_values_are_refused_with_the_field() {
        let mut s = SafetySpec::default();
        assert!(s.validate().is_ok());
        s.joint_limit_margin = 0.0;
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("joint_limit_margin"), "{e}");
        let s = SafetySpec {
            velocity_limit_fraction: 1.0,
            ..Default::default()
        };
        assert!(
            s.validate()
                .unwrap_err()
                .to_string()
                .contains("velocity_limit_fraction")
        );
        let s = SafetySpec {
            joint_limit_torque: Some(f64::NAN),
            ..Default::default()
        };
        assert!(s.validate().is_err());
        for bad in [-1e-6, 0.01, f64::NAN] {
            let s = SafetySpec {
                conflict_fade_ratio: bad,
                ..Default::default()
            };
            let e = s.validate().unwrap_err().to_string();
            assert!(e.contains("conflict_fade_ratio"), "{e}");
        }
    }
}
