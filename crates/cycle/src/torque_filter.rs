//! The torque filter after the saturation (`[torque_filter]`),
//! allocation-free:
//!
//! ```text
//! τ (Eq. (19)) ─▶ finite? ─▶ saturation ─▶ rate limit ─▶ low-pass ─▶ command
//!                 (the law     hcc_control::   |Δτ_k| ≤ r·Δt   τ_f += α(τ − τ_f)
//!                 refuses a    saturate        (whole or       α = 1 − e^(−2π f_c Δt)
//!                 non-finite τ)                per joint)
//! ```
//!
//! The finite check is the law's own (a non-finite τ is a numerical failure
//! answered with the safe command); the saturation is the cycle's
//! ([`crate::ControlCycle`]). This module holds the two stages after it.
//! Both act on the previous command sent (Δt the nominal period), so the rate
//! limit bounds the step of what is commanded — a robot that aborts on a
//! torque discontinuity (the Franka: 1 N·m per ms) sees no larger one — and
//! both stages move between two torques within the limits, so their result
//! stays within them. The first command starts from the torque the driver
//! holds before any command comes (g(q) when the controller adds gravity,
//! else 0), so the law's torque comes in at the rate limit; the safe command
//! is never limited or filtered (a safety stop must not be delayed), and the
//! law's torque after it starts from the safe command sent.
//!
//! **Whole or per joint.** `whole` scales the increment Δτ by one factor so
//! that the largest |Δτ_k| equals r·Δt: the direction of the change — and
//! with it the null-space structure of the hierarchy's increment — is kept,
//! as the saturation keeps it for τ. `per_joint` clips each joint and is
//! faster to reach a new torque but bends the increment out of the levels'
//! subspaces. The default is `whole`.

use hcc_msgs::MAX_JOINTS;
use hcc_spec::torque_filter::{RateLimitMode, TorqueFilterSpec};

/// The rate limit in force for the stages after the filter: the command the
/// last [`TorqueFilter::apply`] stepped from and the largest step per period
/// (what a later stage must stay within).
pub struct RateLimit<'a> {
    pub previous: &'a [f64],
    pub max_step: f64,
}

/// What the stages did to one torque.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stages {
    /// The rate limit changed τ.
    pub rate_limited: bool,
    /// The low-pass filter ran.
    pub low_passed: bool,
}

/// The rate limit and the low-pass between the law and the saturation.
#[derive(Debug, Clone)]
pub struct TorqueFilter {
    /// Largest |Δτ_k| per cycle (r·Δt), or `None`.
    max_step: Option<f64>,
    mode: RateLimitMode,
    /// Low-pass coefficient α, or `None`.
    alpha: Option<f64>,
    /// The previous command's τ (the filter's state), valid if `have_prev`.
    prev: [f64; MAX_JOINTS],
    have_prev: bool,
    /// The command the last [`TorqueFilter::apply`] stepped from.
    origin: [f64; MAX_JOINTS],
}

impl TorqueFilter {
    /// The filter of `settings` at the nominal period `period_s`.
    pub fn new(settings: &TorqueFilterSpec, period_s: f64) -> TorqueFilter {
        TorqueFilter {
            max_step: settings.torque_rate_limit.map(|r| r * period_s),
            mode: settings.rate_limit_mode,
            alpha: settings
                .low_pass_hz
                .map(|f| 1.0 - (-std::f64::consts::TAU * f * period_s).exp()),
            prev: [0.0; MAX_JOINTS],
            have_prev: false,
            origin: [0.0; MAX_JOINTS],
        }
    }

    /// Whether any stage is on.
    pub fn is_active(&self) -> bool {
        self.max_step.is_some() || self.alpha.is_some()
    }

    /// Passes the law's τ (length n, finite, saturated) through the rate limit
    /// and the low-pass, in place, against the previous command. Before the
    /// first command the previous one is `hold` — the torque the driver
    /// applies while no command has come (g(q) when the controller adds
    /// gravity, else 0) — so that the first law torque comes in at the rate
    /// limit too. Allocation-free.
    pub fn apply(&mut self, tau: &mut [f64], hold: &[f64]) -> Stages {
        let n = tau.len().min(MAX_JOINTS);
        let mut stages = Stages::default();
        if !self.have_prev {
            self.prev[..n].copy_from_slice(&hold[..n]);
            self.have_prev = true;
        }
        self.origin[..n].copy_from_slice(&self.prev[..n]);
        if let Some(max_step) = self.max_step {
            stages.rate_limited = limit_rate(&mut tau[..n], &self.prev[..n], max_step, self.mode);
        }
        if let Some(alpha) = self.alpha {
            for (t, p) in tau[..n].iter_mut().zip(&self.prev[..n]) {
                *t = p + alpha * (*t - p);
            }
            stages.low_passed = true;
        }
        self.prev[..n].copy_from_slice(&tau[..n]);
        stages
    }

    /// The previous command's τ (first n entries valid) once there was one and
    /// a rate limit is on: what the robot applies until the next command, from
    /// which the next command is at most one rate step away.
    pub fn rate_limited_previous(&self) -> Option<&[f64; MAX_JOINTS]> {
        (self.have_prev && self.max_step.is_some()).then_some(&self.prev)
    }

    /// The rate limit's largest step per period (r·Δt), if it is on.
    pub fn max_step(&self) -> Option<f64> {
        self.max_step
    }

    /// The rate limit in force (first `n` joints), if one is on: a later
    /// stage stays within one rate step of the command the last
    /// [`TorqueFilter::apply`] stepped from.
    pub fn rate_limit(&self, n: usize) -> Option<RateLimit<'_>> {
        self.max_step.map(|max_step| RateLimit {
            previous: &self.origin[..n],
            max_step,
        })
    }

    /// A command that did not come through [`TorqueFilter::apply`] was sent
    /// (the safe command, never delayed), or a later stage changed the one
    /// that did (the velocity limit): the next law torque starts from it.
    pub fn bypass(&mut self, sent: &[f64]) {
        let n = sent.len().min(MAX_JOINTS);
        self.prev[..n].copy_from_slice(&sent[..n]);
        self.have_prev = true;
    }
}

/// Limits |τ_k − prev_k| to `max_step`, as a whole or per joint; true if τ changed.
fn limit_rate(tau: &mut [f64], prev: &[f64], max_step: f64, mode: RateLimitMode) -> bool {
    let largest = tau
        .iter()
        .zip(prev)
        .fold(0.0_f64, |m, (t, p)| m.max((t - p).abs()));
    if largest <= max_step {
        return false;
    }
    match mode {
        RateLimitMode::Whole => {
            let scale = max_step / largest;
            for (t, p) in tau.iter_mut().zip(prev) {
                *t = p + scale * (*t - p);
            }
        }
        RateLimitMode::PerJoint => {
            for (t, p) in tau.iter_mut().zip(prev) {
                *t = t.clamp(p - max_step, p + max_step);
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filter(rate: Option<f64>, mode: RateLimitMode, low_pass: Option<f64>) -> TorqueFilter {
        let settings = TorqueFilterSpec {
            torque_rate_limit: rate,
            rate_limit_mode: mode,
            low_pass_hz: low_pass,
        };
        TorqueFilter::new(&settings, 1e-3)
    }

    #[test]
    fn off_by_default_changes_nothing() {
        let mut p = filter(None, RateLimitMode::Whole, None);
        assert!(!p.is_active());
        for k in 0..5 {
            let mut tau = [k as f64 * 100.0, -3.0];
            let before = tau;
            assert_eq!(p.apply(&mut tau, &[0.0, 0.0]), Stages::default());
            assert_eq!(tau, before);
        }
    }

    #[test]
    fn whole_keeps_the_direction_per_joint_clips() {
        // 1000 N·m/s at 1 kHz: at most 1 N·m per cycle.
        let mut whole = filter(Some(1000.0), RateLimitMode::Whole, None);
        let mut per = filter(Some(1000.0), RateLimitMode::PerJoint, None);
        // The first command comes in from the held torque (here 2, 0), at the rate.
        let hold = [2.0, 0.0];
        let mut first = [6.0, 0.5];
        assert!(whole.apply(&mut first, &hold).rate_limited);
        assert_eq!(first, [3.0, 0.125], "from the held torque, as a whole");
        let mut first = [6.0, 0.5];
        assert!(per.apply(&mut first, &hold).rate_limited);
        assert_eq!(first, [3.0, 0.5], "from the held torque, per joint");
        whole.bypass(&[0.0, 0.0]);
        per.bypass(&[0.0, 0.0]);
        let mut a = [4.0, 2.0];
        let mut b = [4.0, 2.0];
        assert!(whole.apply(&mut a, &hold).rate_limited);
        assert!(per.apply(&mut b, &hold).rate_limited);
        assert_eq!(a, [1.0, 0.5], "scaled as a whole");
        assert_eq!(b, [1.0, 1.0], "clipped per joint");
        // Within the limit: untouched.
        let mut c = [1.5, 1.0];
        assert!(!whole.apply(&mut c, &hold).rate_limited);
        assert_eq!(c, [1.5, 1.0]);
        // A safe command sent in between (never filtered): the next law
        // torque starts from it.
        whole.bypass(&[50.0, -50.0]);
        let mut d = [50.5, -50.0];
        assert!(!whole.apply(&mut d, &hold).rate_limited);
        assert_eq!(d, [50.5, -50.0]);
        let mut e = [0.0, 0.0];
        assert!(whole.apply(&mut e, &hold).rate_limited);
        let step = [e[0] - 50.5, e[1] + 50.0];
        assert!((step[0] + 1.0).abs() < 1e-12, "{e:?}");
        assert!(
            (step[1] - 50.0 / 50.5).abs() < 1e-12,
            "the direction kept: {e:?}"
        );
    }

    #[test]
    fn the_low_pass_is_first_order() {
        let mut p = filter(None, RateLimitMode::Whole, Some(100.0));
        p.bypass(&[0.0]);
        let alpha = 1.0 - (-std::f64::consts::TAU * 100.0 * 1e-3).exp();
        let mut y = 0.0;
        for _ in 0..50 {
            let mut tau = [1.0];
            assert!(p.apply(&mut tau, &[0.0]).low_passed);
            y += alpha * (1.0 - y);
            assert!((tau[0] - y).abs() < 1e-15);
        }
        assert!(y > 0.99, "step response settles within 50 ms at 100 Hz");
    }
}
