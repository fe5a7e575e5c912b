//! The joint velocity limit in discrete time behind a torque-rate limit: the
//! torque sent is accepted only if a brake the rate limit allows still keeps
//! every joint below its limit afterwards — viability one derivative up,
//! after A. Del Prete, "Joint Position and Velocity Bounds in Discrete-Time
//! Acceleration/Torque Control of Robot Manipulators", IEEE RA-L 3(1), 2018.
//!
//! With a rate limit |τ_k − τ_{k−1}| ≤ ρT per joint a torque cannot be taken
//! back within a period: a joint keeps speeding up for as many periods as the
//! rate limit needs to turn the torques, its own and — through M⁻¹ — the other
//! joints'. The one-period bound of [`crate::velocity_limit`] comes too late.
//! Instead, each period:
//!
//! 1. **The brake.** From a velocity v and a torque τ, the brake moves the
//!    torque by at most ρT per period towards
//!
//!    τ_b(v) = g + C v − β M v   (clipped to the effort limits),
//!
//!    the torque of q̈ = −β v ([`BRAKE_RATE`] = β): every joint slows at once
//!    and, in the frozen model, the kinetic energy ½ vᵀM v decays with power
//!    −β vᵀM v ≤ 0. Two rules ([`BrakeRule`]) take the step: scaled as a
//!    whole (a soft coupled mode — two nearly aligned axes — is braked as
//!    one) or clipped per joint (a light wrist brakes at its own rate, not
//!    held back by the shoulder's long way); the sweeps need both.
//! 2. **The certificate.** A torque τ is *certified* under a rule when, with
//!    this period's model frozen (M, C, g), sending τ now and braking from the
//!    next period on keeps |v_k| ≤ v̄_k = [`BRAKE_VELOCITY_FRACTION`] · v_max,k
//!    in every period, v⁺ = v + T M⁻¹(τ − g − C v), until the brake tracks
//!    τ_b exactly within the rate and effort limits — from there v decays as
//!    (1 − βT)^k and the brake stays feasible (its target moves by
//!    βT |(C − βM) v|, shrinking, per period). It fails at the first period a
//!    joint passes v̄, or when the brake does not track within [`HORIZON_S`].
//! 3. **The choice.** The law's torque τ_c (after the saturation and the
//!    filter) is sent unchanged — bit for bit — when a rule certifies it.
//!    Else, per rule, τ(s) = τ_b⁰ + s (τ_c − τ_b⁰), τ_b⁰ the rule's own brake
//!    step from the previous command, with the largest s ∈ [0, 1] the
//!    bisection ([`BISECTIONS`] steps) finds certified; the rule with the
//!    larger s is sent. Both ends lie within ρT of the previous command and
//!    within the effort limits, and so does every τ(s): the rate limit holds
//!    for what is sent. Where no rule certifies its own step (the frozen
//!    model drifted since the last period), the step of the rule whose brake
//!    goes least far past v̄ is sent (counted in
//!    [`VelocityLimitOutcome::fallback`]); v̄ is 0.92 of the limit so that
//!    such a fall-back stays below 0.95.
//!
//! **It only removes energy, where it acts.** The correction τ(s) − τ_c =
//! (1 − s)(τ_b⁰ − τ_c) moves the torque towards the brake's, whose power on
//! the frozen model is −β q̇ᵀ M q̇ ≤ 0: the share 1 − s of the law's torque it
//! replaces is replaced by one that removes kinetic energy.
//!
//! Cost: per simulated period C v, M v and two triangular solves with the
//! law's Cholesky factor of M (3 n², no second factorisation); a certified
//! law torque costs one or two simulations, usually a few periods long; one
//! that is not, at most 2 + 2 (1 + [`BISECTIONS`]).

use crate::velocity_limit::VelocityLimitOutcome;
use hcc_linalg::cholesky::cholesky_solve_in_place;
use hcc_linalg::products::gemv;
use nalgebra::{DMatrix, DVector};

/// The share of the URDF velocity limit the certificate holds the brake's
/// plan to: below the one-period limit's 0.94, for the frozen model's drift
/// over the plan's tens of periods (measured on the fast-goal sweep: a plan
/// that must fall back ends within 2 % above its bound).
pub const BRAKE_VELOCITY_FRACTION: f64 = 0.92;

/// β: the brake asks for q̈ = −β q̇ (1/s).
pub const BRAKE_RATE: f64 = 20.0;

/// The longest the brake is simulated before the certificate is refused (s).
pub const HORIZON_S: f64 = 0.3;

/// Bisection steps for the blend s (a resolution of 2⁻⁸).
pub const BISECTIONS: usize = 8;

/// What one period's certificate needs: the law's model at this state
/// (`m` = M(q), `chol` its lower Cholesky factor, `c` = C(q, q̇), `g` = g(q)
/// where τ contains gravity, else zeros), the state's velocity `qd`, the URDF
/// velocity limits `v_max` (a non-finite one: no limit), the period T
/// `period_s`, the command sent last period `previous`, the rate limit's
/// largest step per period `max_step` (ρT) and the effort limits `effort`.
#[derive(Clone, Copy, Debug)]
pub struct BrakeModel<'a> {
    pub m: &'a DMatrix<f64>,
    pub chol: &'a DMatrix<f64>,
    pub c: &'a DMatrix<f64>,
    pub g: &'a DVector<f64>,
    pub qd: &'a [f64],
    pub v_max: &'a [f64],
    pub period_s: f64,
    pub previous: &'a [f64],
    pub max_step: f64,
    pub effort: &'a [f64],
}

/// The preallocated storage of [`limit_velocity_rate_limited`] for `n` joints.
#[derive(Clone, Debug)]
pub struct BrakeWork {
    sim: Simulation,
    brake: Vec<f64>,
    blend: Vec<f64>,
}

/// The frozen model's state while the brake is simulated.
#[derive(Clone, Debug)]
struct Simulation {
    v: DVector<f64>,
    tau: DVector<f64>,
    from: DVector<f64>,
    cv: DVector<f64>,
    drive: DVector<f64>,
    acc: DVector<f64>,
}

impl BrakeWork {
    /// Storage for `n` joints (allocates).
    pub fn new(n: usize) -> BrakeWork {
        BrakeWork {
            sim: Simulation {
                v: DVector::zeros(n),
                tau: DVector::zeros(n),
                from: DVector::zeros(n),
                cv: DVector::zeros(n),
                drive: DVector::zeros(n),
                acc: DVector::zeros(n),
            },
            brake: vec![0.0; n],
            blend: vec![0.0; n],
        }
    }
}

/// How the brake steps its torque towards its target within the rate limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BrakeRule {
    /// The step scaled as a whole (its direction kept): a soft coupled mode —
    /// two nearly aligned axes — is braked as one.
    Whole,
    /// Each joint's step clipped to ρT: a light joint brakes at its own rate,
    /// not held back by a heavy one's long way.
    PerJoint,
}

const RULES: [BrakeRule; 2] = [BrakeRule::Whole, BrakeRule::PerJoint];

/// The velocity limit behind a rate limit (module docs) on the torque `tau`
/// about to be sent (saturated, rate-limited), in place. Allocation-free.
pub fn limit_velocity_rate_limited(
    p: &BrakeModel<'_>,
    tau: &mut [f64],
    w: &mut BrakeWork,
) -> VelocityLimitOutcome {
    let mut out = VelocityLimitOutcome::default();
    if RULES.iter().any(|&r| certified(p, tau, r, w).is_ok()) {
        return out;
    }
    let n = tau.len();
    // For each rule: its own step from the previous command, at today's
    // velocity, and the largest blend s it certifies; the rule with the
    // larger s wins. Where neither certifies its own step, the one whose
    // brake goes least far past v̄ is sent.
    let mut best: Option<(f64, BrakeRule)> = None;
    let mut lowest = (f64::INFINITY, BrakeRule::Whole);
    let mut brake = std::mem::take(&mut w.brake);
    let mut candidate = std::mem::take(&mut w.blend);
    for rule in RULES {
        brake_from_previous(p, rule, w, &mut brake[..n]);
        if certified(p, &brake[..n], rule, w).is_err() {
            // How far past v̄ its own brake goes, for the fall-back.
            // (The same brake run to the end: it fails again; no panic if not.)
            let peak = simulate(p, &brake[..n], rule, false, w)
                .err()
                .unwrap_or(1.0);
            if peak < lowest.0 {
                lowest = (peak, rule);
            }
            continue;
        }
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..BISECTIONS {
            let mid = 0.5 * (lo + hi);
            blend(&brake[..n], tau, mid, &mut candidate[..n]);
            if certified(p, &candidate[..n], rule, w).is_ok() {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        if best.is_none_or(|(s, _)| lo > s) {
            best = Some((lo, rule));
        }
    }
    let (s, rule) = best.unwrap_or_else(|| {
        out.fallback = true;
        (0.0, lowest.1)
    });
    brake_from_previous(p, rule, w, &mut brake[..n]);
    for k in 0..n {
        let sent = brake[k] + s * (tau[k] - brake[k]);
        out.largest_correction = out.largest_correction.max((sent - tau[k]).abs());
        tau[k] = sent;
    }
    w.brake = brake;
    w.blend = candidate;
    out.acted = true;
    out
}

/// The brake's step under `rule` from the command sent last period at
/// today's velocity, into `out`.
fn brake_from_previous(p: &BrakeModel<'_>, rule: BrakeRule, w: &mut BrakeWork, out: &mut [f64]) {
    let sim = &mut w.sim;
    sim.v.copy_from_slice(p.qd);
    sim.from.copy_from_slice(p.previous);
    brake_step(p, rule, sim);
    out.copy_from_slice(sim.tau.as_slice());
}

/// `out` = b + s (t − b).
fn blend(b: &[f64], t: &[f64], s: f64, out: &mut [f64]) {
    for ((o, b), t) in out.iter_mut().zip(b).zip(t) {
        *o = b + s * (t - b);
    }
}

/// One step of the brake under `rule` from the torque `sim.from` at the
/// velocity `sim.v` into `sim.tau`; true when it reached the brake's target
/// τ_b(v) exactly (within the rate and the effort limits). Leaves (C − βM) v
/// in `sim.drive`.
fn brake_step(p: &BrakeModel<'_>, rule: BrakeRule, sim: &mut Simulation) -> bool {
    gemv(&mut sim.cv, 1.0, p.c, &sim.v, 0.0);
    gemv(&mut sim.drive, 1.0, p.m, &sim.v, 0.0);
    // The target, clipped to the effort limits; the step towards it into
    // sim.tau first.
    let mut exact = true;
    let mut largest = 0.0_f64;
    for k in 0..sim.v.len() {
        let drive = sim.cv[k] - BRAKE_RATE * sim.drive[k];
        sim.drive[k] = drive;
        let raw = p.g[k] + drive;
        let target = raw.clamp(-p.effort[k], p.effort[k]);
        exact &= target == raw;
        sim.tau[k] = target - sim.from[k];
        largest = largest.max(sim.tau[k].abs());
    }
    exact &= largest <= p.max_step;
    let scale = match rule {
        BrakeRule::Whole if largest > p.max_step => p.max_step / largest,
        _ => 1.0,
    };
    for k in 0..sim.v.len() {
        let step = (scale * sim.tau[k]).clamp(-p.max_step, p.max_step);
        sim.tau[k] = sim.from[k] + step;
    }
    exact
}

/// Whether sending `tau0` now and braking under `rule` after it keeps every
/// joint within v̄ in the frozen model (module docs, step 2).
fn certified(
    p: &BrakeModel<'_>,
    tau0: &[f64],
    rule: BrakeRule,
    w: &mut BrakeWork,
) -> Result<(), f64> {
    simulate(p, tau0, rule, true, w)
}

/// Sends `tau0` and brakes under `rule` in the frozen model: `Ok` when every
/// joint stays within v̄ until the brake tracks its target; else the largest
/// |v_k| / v̄_k on the way (at the first excess when `stop_early`, over the
/// whole horizon otherwise; infinite for a non-finite speed).
fn simulate(
    p: &BrakeModel<'_>,
    tau0: &[f64],
    rule: BrakeRule,
    stop_early: bool,
    w: &mut BrakeWork,
) -> Result<(), f64> {
    let n = tau0.len();
    let t = p.period_s;
    if p.g.iter().zip(p.effort).any(|(g, e)| g.abs() > *e) {
        return Err(f64::INFINITY);
    }
    let sim = &mut w.sim;
    sim.v.copy_from_slice(p.qd);
    sim.tau.copy_from_slice(tau0);
    let steps = (HORIZON_S / t).ceil() as usize;
    let mut peak = 0.0_f64;
    for _ in 0..steps {
        // q̇⁺ = q̇ + T M⁻¹ (τ − g − C q̇).
        gemv(&mut sim.cv, 1.0, p.c, &sim.v, 0.0);
        for k in 0..n {
            sim.acc[k] = sim.tau[k] - p.g[k] - sim.cv[k];
        }
        if cholesky_solve_in_place(p.chol, &mut sim.acc).is_err() {
            return Err(f64::INFINITY);
        }
        for k in 0..n {
            sim.v[k] += t * sim.acc[k];
            let vbar = BRAKE_VELOCITY_FRACTION * p.v_max[k];
            // A non-finite speed is never certified; a non-finite limit holds nothing.
            if !sim.v[k].is_finite() {
                return Err(f64::INFINITY);
            }
            if vbar.is_finite() {
                peak = peak.max(sim.v[k].abs() / vbar);
            }
        }
        if peak > 1.0 && stop_early {
            return Err(peak);
        }
        sim.from.copy_from(&sim.tau);
        if brake_step(p, rule, sim) {
            // Tracking: the target moves by βT |(C − βM) v| per period from here.
            let drift = sim.drive.amax();
            if BRAKE_RATE * t * drift <= p.max_step && BRAKE_RATE * t < 1.0 {
                return if peak > 1.0 { Err(peak) } else { Ok(()) };
            }
        }
    }
    // Not tracking by the horizon: not certified.
    Err(peak.max(1.0 + f64::EPSILON))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A coupled SPD inertia with a light last joint (a wrist), a frozen
    /// Coriolis matrix and gravity. Frozen, Ṁ = 0, so C is skew (Ṁ − 2C skew).
    fn model() -> (DMatrix<f64>, DMatrix<f64>, DVector<f64>) {
        let b = DMatrix::from_fn(4, 4, |i, j| ((i * 4 + j) as f64 * 0.7).sin());
        let m = &b * b.transpose() * 0.3
            + DMatrix::from_diagonal(&DVector::from_vec(vec![2.0, 1.5, 0.6, 0.03]));
        let a = DMatrix::from_fn(4, 4, |i, j| 0.05 * ((i + 2 * j) as f64).cos());
        let c = &a - a.transpose();
        let g = DVector::from_vec(vec![0.0, -20.0, 3.0, 0.1]);
        (m, c, g)
    }

    const EFFORT: [f64; 4] = [87.0, 87.0, 87.0, 12.0];
    const V_MAX: [f64; 4] = [2.0, 2.0, 2.5, 2.6];
    const T: f64 = 1e-3;
    const MAX_STEP: f64 = 1.0;

    /// The certificate's model at velocity `qd` after the command `previous`.
    fn at<'a>(
        (m, chol, c, g): (
            &'a DMatrix<f64>,
            &'a DMatrix<f64>,
            &'a DMatrix<f64>,
            &'a DVector<f64>,
        ),
        qd: &'a [f64],
        previous: &'a [f64],
    ) -> BrakeModel<'a> {
        BrakeModel {
            m,
            chol,
            c,
            g,
            qd,
            v_max: &V_MAX,
            period_s: T,
            previous,
            max_step: MAX_STEP,
            effort: &EFFORT,
        }
    }

    /// The shipped filter's rate limit, as a whole.
    fn rate_limit(tau: &mut [f64], prev: &[f64]) {
        let largest = tau
            .iter()
            .zip(prev)
            .fold(0.0_f64, |m, (t, p)| m.max((t - p).abs()));
        if largest > MAX_STEP {
            for (t, p) in tau.iter_mut().zip(prev) {
                *t = p + MAX_STEP / largest * (*t - p);
            }
        }
    }

    /// 2 s of a law that pushes every joint at its effort limit (the wrist
    /// against the others), behind the rate limit, in the frozen model;
    /// returns the largest |v_k| / v_max,k, the largest torque step and the
    /// periods the certificate acted in.
    fn closed_loop(certify: bool) -> (f64, f64, usize) {
        let (m, c, g) = model();
        let chol = m.clone().cholesky().unwrap().l();
        let mut w = BrakeWork::new(4);
        let mut v = DVector::zeros(4);
        let mut prev = g.as_slice().to_vec();
        let (mut peak, mut step, mut acted) = (0.0_f64, 0.0_f64, 0);
        for _ in 0..2000 {
            let mut tau = [87.0, -87.0, 87.0, -12.0];
            rate_limit(&mut tau, &prev);
            if certify {
                let qd = v.as_slice().to_vec();
                let p = at((&m, &chol, &c, &g), &qd, &prev);
                acted += usize::from(limit_velocity_rate_limited(&p, &mut tau, &mut w).acted);
            }
            for (k, t) in tau.iter().enumerate() {
                step = step.max((t - prev[k]).abs());
                assert!(t.abs() <= EFFORT[k] + 1e-12, "joint {k}: {t} N·m");
            }
            let qdd = m
                .clone()
                .cholesky()
                .unwrap()
                .solve(&(DVector::from_column_slice(&tau) - &g - &c * &v));
            v += T * qdd;
            for (k, x) in v.iter().enumerate() {
                peak = peak.max(x.abs() / V_MAX[k]);
            }
            prev.copy_from_slice(&tau);
        }
        (peak, step, acted)
    }

    #[test]
    fn behind_the_rate_limit_every_joint_stays_below_the_bound() {
        let (bare, _, _) = closed_loop(false);
        assert!(
            bare > 1.5,
            "the push must pass the limits without the certificate: {bare}"
        );
        let (peak, step, acted) = closed_loop(true);
        // The model is the frozen one: the bound holds exactly.
        assert!(peak <= BRAKE_VELOCITY_FRACTION + 1e-9, "{peak} × the limit");
        assert!(step <= MAX_STEP + 1e-9, "a torque step of {step} N·m");
        assert!(acted > 0);
    }

    #[test]
    fn a_certified_torque_is_sent_bit_for_bit() {
        let (m, c, g) = model();
        let chol = m.clone().cholesky().unwrap().l();
        let mut w = BrakeWork::new(4);
        let qd = [0.1, -0.2, 0.0, 0.3];
        let previous: Vec<f64> = g.iter().map(|x| x + 0.5).collect();
        let tau0: Vec<f64> = g.iter().map(|x| x + 1.2).collect();
        let mut tau = tau0.clone();
        let p = at((&m, &chol, &c, &g), &qd, &previous);
        let out = limit_velocity_rate_limited(&p, &mut tau, &mut w);
        assert!(!out.acted, "{out:?}");
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&tau), bits(&tau0));
    }

    #[test]
    fn from_beyond_the_bound_the_brake_removes_kinetic_energy() {
        // Released beyond the bound (a push let go), the law holding only g:
        // the kinetic energy falls in every period the certificate acts, and
        // every joint is below the bound within 0.3 s.
        let (m, c, g) = model();
        let chol = m.clone().cholesky().unwrap().l();
        let mut w = BrakeWork::new(4);
        let mut v = DVector::from_vec(vec![1.9, -1.7, 2.4, -2.6]);
        let mut prev = g.as_slice().to_vec();
        let energy = |v: &DVector<f64>| 0.5 * v.dot(&(&m * v));
        let mut acted = 0;
        for k in 0..1000 {
            let mut tau = g.as_slice().to_vec();
            rate_limit(&mut tau, &prev);
            let qd = v.as_slice().to_vec();
            let p = at((&m, &chol, &c, &g), &qd, &prev);
            let out = limit_velocity_rate_limited(&p, &mut tau, &mut w);
            let e = energy(&v);
            let qdd = m
                .clone()
                .cholesky()
                .unwrap()
                .solve(&(DVector::from_column_slice(&tau) - &g - &c * &v));
            v += T * qdd;
            if out.acted {
                acted += 1;
                assert!(energy(&v) < e, "period {k}: {} J after {e} J", energy(&v));
            }
            if k >= 300 {
                for (j, x) in v.iter().enumerate() {
                    assert!(
                        x.abs() <= BRAKE_VELOCITY_FRACTION * V_MAX[j] + 1e-9,
                        "joint {j} at {x}"
                    );
                }
            }
            prev.copy_from_slice(&tau);
        }
        assert!(acted > 0);
    }
}
