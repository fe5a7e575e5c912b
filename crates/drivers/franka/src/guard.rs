//! The driver's torque guard: what the robot itself refuses is refused
//! before it.
//!
//! A Franka aborts a torque motion when a commanded torque `tau_J_d` is not
//! finite, outside the joint's range (`tau_J_range_violation`), or changes by
//! more than 1 N·m from one 1 ms cycle to the next (1000 N·m/s,
//! `controller_torque_discontinuity`; libfranka `kMaxTorqueRate`). Every
//! torque the driver writes — a command, the held torque, the fallback, the
//! ramp down of a stop — goes through [`TorqueGuard::apply`] first:
//!
//! 1. a non-finite entry (never expected: `TorqueCommand::validate` refuses
//!    such commands before they are applied) replaces the whole vector by the
//!    last torque written;
//! 2. each joint is clamped to its limit ([`hcc_config::franka::Franka::torque_limits`]);
//! 3. each joint's change from the last torque written is clipped to the
//!    rate limit times the 1 ms cycle, with franka-rs's port of libfranka's
//!    `limitRate` ([`franka::limit_rate_torques`]).
//!
//! Each step counts the cycles it changed something. The controller's own
//! torque filter (`[torque_filter] torque_rate_limit`) should already keep the
//! steps small: a clipped cycle here means the two disagree, and the
//! counters say so. Allocation-free.

use franka::rate_limiting::{DELTA_T, LIMIT_EPS};

/// Joints of a Franka arm.
pub const JOINTS: usize = 7;

/// What the guard changed, cycles counted since the start.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GuardCounts {
    /// Cycles whose torque had a non-finite entry (replaced by the last torque).
    pub non_finite: u64,
    /// Cycles in which at least one joint was clamped to its torque limit.
    pub limited: u64,
    /// Cycles in which at least one joint's step was clipped to the rate limit.
    pub rate_limited: u64,
    /// The largest step clipped away, N·m (how far the command was off).
    pub max_clipped_step: f64,
    /// The largest step written, N·m (at most the rate limit times 1 ms).
    pub max_step_written: f64,
}

/// The guard: limits, the largest derivative, and the last torque written.
#[derive(Debug, Clone)]
pub struct TorqueGuard {
    limits: [f64; JOINTS],
    max_rate: [f64; JOINTS],
    last: [f64; JOINTS],
    counts: GuardCounts,
}

impl TorqueGuard {
    /// A guard with per-joint `limits` (N·m) and a torque-rate limit
    /// `rate` (N·m/s; never more than the robot's 1000 less libfranka's
    /// `kLimitEps`). The last torque written starts at zero.
    pub fn new(limits: [f64; JOINTS], rate: f64) -> TorqueGuard {
        let rate = rate.min(hcc_config::franka::FRANKA_MAX_TORQUE_RATE - LIMIT_EPS);
        TorqueGuard {
            limits,
            max_rate: [rate; JOINTS],
            last: [0.0; JOINTS],
            counts: GuardCounts::default(),
        }
    }

    /// A new motion starts from zero torque (the robot's `tau_J_d` before
    /// its first command), so the first steps are ramped from there.
    pub fn restart(&mut self) {
        self.last = [0.0; JOINTS];
    }

    /// The last torque written.
    pub fn last(&self) -> &[f64; JOINTS] {
        &self.last
    }

    /// The counts so far.
    pub fn counts(&self) -> GuardCounts {
        self.counts
    }

    /// The largest step one cycle may make, N·m.
    pub fn max_step(&self) -> f64 {
        self.max_rate[0] * DELTA_T
    }

    /// Makes `tau` safe to write (see the module docs) and takes it as the
    /// last torque written.
    pub fn apply(&mut self, tau: &mut [f64; JOINTS]) {
        if tau.iter().any(|t| !t.is_finite()) {
            self.counts.non_finite += 1;
            *tau = self.last;
        }
        let mut limited = false;
        for (t, limit) in tau.iter_mut().zip(&self.limits) {
            let clamped = t.clamp(-limit, *limit);
            limited |= clamped != *t;
            *t = clamped;
        }
        self.counts.limited += u64::from(limited);
        let max_step = self.max_step();
        let too_fast = tau
            .iter()
            .zip(&self.last)
            .any(|(t, l)| (t - l).abs() > max_step);
        // Finite by now, so limit_rate_torques cannot fail (it refuses
        // non-finite values only). Within the rate, τ is left bit for bit.
        if too_fast && let Ok(stepped) = franka::limit_rate_torques(&self.max_rate, tau, &self.last)
        {
            let mut clipped = 0.0_f64;
            for (t, s) in tau.iter().zip(&stepped) {
                clipped = clipped.max((t - s).abs());
            }
            self.counts.rate_limited += 1;
            self.counts.max_clipped_step = self.counts.max_clipped_step.max(clipped);
            *tau = stepped;
        }
        for (t, l) in tau.iter().zip(&self.last) {
            self.counts.max_step_written = self.counts.max_step_written.max((t - l).abs());
        }
        self.last = *tau;
    }

    /// One step of a stop's ramp: moves the last torque towards zero as fast
    /// as the rate limit allows; true once it is zero.
    pub fn ramp_down(&mut self, tau: &mut [f64; JOINTS]) -> bool {
        *tau = [0.0; JOINTS];
        self.apply(tau);
        tau.iter().all(|t| *t == 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn guard() -> TorqueGuard {
        TorqueGuard::new([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0], 1000.0)
    }

    #[test]
    fn steps_are_clipped_to_one_newton_metre_per_cycle() {
        let mut g = guard();
        let mut tau = [5.0, -5.0, 0.5, 0.0, 0.0, 0.0, 0.0];
        g.apply(&mut tau);
        let step = 1.0 - LIMIT_EPS * DELTA_T;
        assert!((tau[0] - step).abs() < 1e-12, "{tau:?}");
        assert!((tau[1] + step).abs() < 1e-12);
        assert_eq!(tau[2], 0.5);
        assert_eq!(g.counts().rate_limited, 1);
        assert!((g.counts().max_clipped_step - (5.0 - step)).abs() < 1e-12);
        // Every later step stays within the limit too.
        for _ in 0..10 {
            let before = *g.last();
            let mut tau = [5.0, -5.0, 0.5, 0.0, 0.0, 0.0, 0.0];
            g.apply(&mut tau);
            for (a, b) in tau.iter().zip(&before) {
                assert!((a - b).abs() <= 1.0, "{a} after {b}");
            }
        }
        assert_eq!(g.last()[0], 5.0);
        assert!(g.counts().max_step_written <= 1.0);
        assert!((g.counts().max_step_written - step).abs() < 1e-12);
    }

    #[test]
    fn torques_are_clamped_to_the_limits() {
        let mut g = guard();
        g.last = [86.5, 0.0, 0.0, 0.0, 0.0, 0.0, 11.8];
        let mut tau = [87.4, 0.0, 0.0, 0.0, 0.0, 0.0, 15.0];
        g.apply(&mut tau);
        assert_eq!(tau[0], 87.0);
        assert_eq!(tau[6], 12.0);
        assert_eq!(g.counts().limited, 1);
        assert_eq!(g.counts().rate_limited, 0);
    }

    #[test]
    fn non_finite_torques_hold_the_last_one() {
        let mut g = guard();
        let mut tau = [0.5; JOINTS];
        g.apply(&mut tau);
        let mut bad = [0.7, f64::NAN, 0.0, f64::INFINITY, 0.0, 0.0, 0.0];
        g.apply(&mut bad);
        assert_eq!(bad, [0.5; JOINTS]);
        assert_eq!(g.counts().non_finite, 1);
    }

    #[test]
    fn a_stop_ramps_to_zero_within_the_rate() {
        let mut g = guard();
        g.last = [3.5, -2.0, 0.0, 0.0, 0.0, 0.0, 0.3];
        let mut tau = [0.0; JOINTS];
        let mut cycles = 0;
        while !g.ramp_down(&mut tau) {
            cycles += 1;
            assert!(cycles < 10);
        }
        assert_eq!(cycles, 3, "3.5 N·m take four steps");
        assert_eq!(*g.last(), [0.0; JOINTS]);
    }

    #[test]
    fn a_lower_rate_is_kept_and_a_higher_one_capped() {
        assert!((TorqueGuard::new([1.0; JOINTS], 500.0).max_step() - 0.5).abs() < 1e-12);
        assert!(TorqueGuard::new([1.0; JOINTS], 5000.0).max_step() < 1.0);
        let mut g = guard();
        g.last = [1.0; JOINTS];
        g.restart();
        assert_eq!(*g.last(), [0.0; JOINTS]);
    }
}
