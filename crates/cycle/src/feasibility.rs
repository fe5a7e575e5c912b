//! Whether the hierarchy can follow a set of paths from a configuration:
//! a kinematic rollout of the levels' prioritised resolved rates along the
//! paths (docs/tracking.md, "Feasibility"), checked with the law's own
//! singularity test at every step.
//!
//! At each step of `dt` the law is evaluated at the rollout's configuration
//! q with the paths' desired values as goals ([`Controller::step`] at rest:
//! its task errors x̃_i = x_i − x_{i,d}, its Jacobians J_i and its flags). A
//! level the law reports singular there (an inversion it had to damp: a
//! kinematic or algorithmic singularity of the stacked Jacobian) makes the
//! paths infeasible at that time. Otherwise the configuration moves on by
//! the prioritised resolved rates (Siciliano & Slotine's recursion, the
//! kinematic counterpart of the hierarchy's null-space projections):
//!
//! u_i = ẋ_{i,d} − k x̃_i,  q̇ ← q̇ + (J_i N_{i−1})⁺ (u_i − J_i q̇),  N_i = N_{i−1} − (J_i N_{i−1})⁺ J_i N_{i−1},
//!
//! with N_0 = I and k = [`ROLLOUT_GAIN`]. A path level whose error grows
//! [`ROLLOUT_LAG_M`] / [`ROLLOUT_LAG_RAD`] past where it started, in any
//! coordinate, cannot be followed (out of reach, or blocked by the levels
//! above); a path may start off the arm (the start check bounds that). This is a
//! start-up check (it allocates): scenario paths are checked by
//! [`crate::controller_for`].

use hcc_control::Controller;
use hcc_spec::TaskUnit;
use hcc_trajectory::Trajectory;
use nalgebra::{DMatrix, DVector};

/// The rollout's step, s (scenario paths and paths sent at run time alike).
pub const ROLLOUT_STEP_S: f64 = 0.005;
/// The rollout's error feedback, 1/s.
pub const ROLLOUT_GAIN: f64 = 20.0;
/// The largest error of a path level's length coordinate in the rollout, m.
pub const ROLLOUT_LAG_M: f64 = 0.01;
/// The same for an angle, rad.
pub const ROLLOUT_LAG_RAD: f64 = 0.05;

/// Where and why the paths cannot be followed.
#[derive(Clone, Debug, PartialEq)]
pub struct Infeasible {
    /// The paths' time, s.
    pub t: f64,
    /// The level (0-based).
    pub level: usize,
    pub reason: Reason,
}

/// Why.
#[derive(Clone, Debug, PartialEq)]
pub enum Reason {
    /// The law is singular at the level (its inversion damped).
    Singular,
    /// The level's path runs away from the arm (this far, in its unit).
    Lags(f64),
    /// The law refused the configuration (its message).
    Refused(String),
}

impl std::fmt::Display for Infeasible {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let level = self.level;
        match &self.reason {
            Reason::Singular => write!(
                f,
                "at t = {:.3} s the hierarchy is singular at level[{level}] (the stacked \
                 Jacobian loses rank there)",
                self.t
            ),
            Reason::Lags(e) => write!(
                f,
                "at t = {:.3} s level[{level}] cannot follow its path ({e:.4} from it: out of \
                 reach, or blocked by the levels above)",
                self.t
            ),
            Reason::Refused(e) => write!(f, "at t = {:.3} s the law refused: {e}", self.t),
        }
    }
}

/// What the rollout saw along feasible paths.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Steps taken.
    pub steps: usize,
    /// The smallest conditioning of each level (the law's measure).
    pub conditioning: Vec<f64>,
}

/// One level's desired value and velocity at a rollout step (the level's
/// goal format and goal-velocity coordinates).
pub type Target<'a> = (&'a [f64], &'a [f64]);

/// A rollout in progress: the hierarchy's configuration moved step by step
/// along the targets it is handed (module docs). Built once, stepped as the
/// targets come — a whole path at once ([`check_paths`]), or a stream's
/// knots as they arrive.
#[derive(Clone)]
pub struct Rollout {
    probe: Controller,
    q: DVector<f64>,
    units: Vec<Vec<TaskUnit>>,
    /// Per level and coordinate: the error at the first step (the lag
    /// allowance's base).
    start_error: Vec<Vec<f64>>,
    summary: Summary,
}

impl Rollout {
    /// A rollout of `controller`'s hierarchy from `q0`.
    pub fn new(controller: &Controller, q0: &[f64]) -> Rollout {
        let probe = controller.clone();
        let n = probe.nq();
        let levels = probe.levels();
        let units = (0..levels)
            .map(|i| probe.spec().levels[i].units(n))
            .collect();
        Rollout {
            probe,
            q: DVector::from_column_slice(q0),
            units,
            start_error: Vec::new(),
            summary: Summary {
                steps: 0,
                conditioning: vec![f64::INFINITY; levels],
            },
        }
    }

    /// Sets level `i`'s goal (its goal format): what the level holds at the
    /// steps that hand it no target.
    pub fn hold(&mut self, i: usize, goal: &[f64]) -> Result<(), hcc_control::ControlError> {
        self.probe.set_goal(i, goal)
    }

    /// The configuration reached.
    pub fn q(&self) -> &[f64] {
        self.q.as_slice()
    }

    /// What it saw so far.
    pub fn summary(&self) -> &Summary {
        &self.summary
    }

    /// One step at time `t` (for the report) of `dt` s: the law at q with
    /// `targets` as goals (one per level; `None`: the level holds), the
    /// checks, then q moved by the prioritised resolved rates.
    pub fn step(
        &mut self,
        t: f64,
        targets: &[Option<Target<'_>>],
        dt: f64,
    ) -> Result<(), Infeasible> {
        let refused = |level: usize, e: &dyn std::fmt::Display| Infeasible {
            t,
            level,
            reason: Reason::Refused(e.to_string()),
        };
        for (i, target) in targets.iter().enumerate() {
            if let Some((goal, _)) = target {
                self.probe.set_goal(i, goal).map_err(|e| refused(i, &e))?;
            }
        }
        let n = self.probe.nq();
        let zeros = vec![0.0; n];
        let out = self
            .probe
            .step(self.q.as_slice(), &zeros)
            .map_err(|e| refused(0, &e))?;
        if let Some(level) = out.singular.iter().position(|s| *s) {
            return Err(Infeasible {
                t,
                level,
                reason: Reason::Singular,
            });
        }
        let conditioning = self.summary.conditioning.iter_mut();
        for (c, o) in conditioning.zip(&out.conditioning) {
            *c = c.min(*o);
        }
        let errors: Vec<DVector<f64>> = out.task_error.clone();
        if self.start_error.is_empty() {
            self.start_error = errors
                .iter()
                .map(|e| e.iter().map(|x| x.abs()).collect())
                .collect();
        }
        for (i, target) in targets.iter().enumerate() {
            if target.is_none() {
                continue;
            }
            let coordinates = errors[i]
                .iter()
                .zip(&self.units[i])
                .zip(&self.start_error[i]);
            for ((e, unit), e0) in coordinates {
                let limit = e0
                    + match unit {
                        TaskUnit::Length => ROLLOUT_LAG_M,
                        TaskUnit::Angle => ROLLOUT_LAG_RAD,
                    };
                if e.abs() > limit {
                    return Err(Infeasible {
                        t,
                        level: i,
                        reason: Reason::Lags(e.abs()),
                    });
                }
            }
        }
        // The prioritised resolved rates.
        let mut qd = DVector::zeros(n);
        let mut null = DMatrix::identity(n, n);
        for (i, e) in errors.iter().enumerate() {
            let j = self.probe.task_jacobian(i).clone();
            let mut u = -ROLLOUT_GAIN * e;
            if let Some(Some((_, velocity))) = targets.get(i) {
                u += DVector::from_column_slice(velocity);
            }
            let jn = &j * &null;
            let Ok(pinv) = jn.clone().pseudo_inverse(1e-9) else {
                continue;
            };
            qd += &pinv * (u - &j * &qd);
            null -= &pinv * jn;
        }
        self.q += qd * dt;
        self.summary.steps += 1;
        Ok(())
    }
}

/// Rolls `controller`'s hierarchy out from `q0` along `paths` (one per
/// level, `None`: the level holds its goal) every `dt` s until the last
/// path ends; the first step where a level is singular or a path level
/// lags (module docs).
pub fn check_paths(
    controller: &Controller,
    q0: &[f64],
    paths: &[Option<&Trajectory>],
    dt: f64,
) -> Result<Summary, Infeasible> {
    let duration = paths
        .iter()
        .flatten()
        .map(|p| p.duration())
        .fold(0.0, f64::max);
    let steps = (duration / dt).ceil() as usize;
    let mut samples: Vec<_> = paths
        .iter()
        .map(|p| p.map(Trajectory::sample_buffer))
        .collect();
    let mut rollout = Rollout::new(controller, q0);
    for k in 0..=steps {
        let t = k as f64 * dt;
        for (path, sample) in paths.iter().zip(&mut samples) {
            if let (Some(p), Some(s)) = (path, sample.as_mut()) {
                p.sample(t, s);
            }
        }
        let targets: Vec<Option<Target<'_>>> = samples
            .iter()
            .map(|s| s.as_ref().map(|s| (&s.goal[..], &s.velocity[..])))
            .collect();
        rollout.step(t, &targets, dt)?;
    }
    Ok(rollout.summary().clone())
}
