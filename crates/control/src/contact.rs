//! Feeling contact without a sensor: the generalized-momentum observer of the
//! external joint torque, and a contact detector on its estimate.
//!
//! # The observer
//!
//! De Luca & Mattone, "Sensorless robot collision detection and hybrid
//! force/motion control", ICRA 2005; Haddadin, De Luca & Albu-Schäffer,
//! "Robot Collisions: A Survey on Detection, Isolation, and Identification",
//! T-RO 2017, Sec. IV. With the generalized momentum p = M(q) q̇ and the
//! robot's dynamics M q̈ + C q̇ + g = τ + τ_ext, Ṁ = C + Cᵀ gives
//! ṗ = τ + Cᵀ(q, q̇) q̇ − g(q) + τ_ext, and the residual
//!
//! r(t) = K_O [p(t) − p(0) − ∫₀ᵗ (τ + Cᵀ q̇ − g + r) ds]
//!
//! obeys ṙ = K_O (τ_ext − r): a first-order low-pass estimate of τ_ext with
//! time constant 1/K_O per joint, from M, C and g — which the law computes every
//! cycle anyway — and the measured q̇ alone (no acceleration).
//!
//! # Discretisation
//!
//! The command τ_{k−1} answering state k−1 is held over [t_{k−1}, t_k] (the
//! zero-order hold of the message contract), so the momentum balance over one
//! period is exact in τ: the mean external torque over the period is
//!
//! y_k = (p_k − p_{k−1}) / T − τ_{k−1} − ½ (β_{k−1} + β_k),  β = Cᵀ q̇ − g,
//!
//! with the trapezoidal rule the only approximation (of the smooth β; C
//! satisfies Ṁ = C + Cᵀ, hcc-model's `coriolis_matrix`). The residual is the
//! exact discretisation of ṙ = K_O (y − r) for y held over the period:
//!
//! r_k = r_{k−1} + α ⊙ (y_k − r_{k−1}),  α_j = 1 − exp(−K_{O,j} T).
//!
//! For K_O T ≪ 1, α ≈ K_O T and this is the forward-Euler sum of the integral
//! form above (the same recursion, unrolled). r_0 = 0 (τ_ext assumed zero at
//! the first state), and no q̇ is ever differentiated: p_k − p_{k−1} enters
//! scaled by α / T ≈ K_O, as in the integral form.
//!
//! **Gravity.** When the driver adds g itself, it applies τ + g, so g cancels
//! from the balance: β = Cᵀ q̇ and τ is the command as sent
//! ([`ObserverInput::gravity_in_command`]); where the command carries the
//! load's gravity torque (the driver's model does not know the load), that
//! part enters as −g would.
//!
//! **Measured joint torques.** A driver's `tau_measured` is not used: the
//! observer needs only what was commanded, which is what a torque-controlled
//! joint applies (its inner torque loop); friction downstream of the torque
//! sensor and model errors show up in r, and the thresholds are chosen above
//! them (docs/contact.md).
//!
//! # Allocation
//!
//! [`MomentumObserver::new`] allocates its workspace (Pinocchio's shape: an
//! algorithm over the model's terms and a data struct); [`observe`] allocates
//! nothing.

use hcc_model::Data;
use nalgebra::DVector;

/// The observer's gains, state and workspace ([`observe`]).
#[derive(Clone, Debug)]
pub struct MomentumObserver {
    /// K_O per joint, 1/s.
    gain: DVector<f64>,
    /// α_j = 1 − exp(−K_{O,j} T) for the period T of `alpha_period`.
    alpha: DVector<f64>,
    alpha_period: f64,
    /// r, the estimate of τ_ext.
    r: DVector<f64>,
    /// p and β = Cᵀ q̇ − g of the previous update (valid when `primed`).
    p_prev: DVector<f64>,
    beta_prev: DVector<f64>,
    p: DVector<f64>,
    beta: DVector<f64>,
    primed: bool,
}

/// What one update of the observer reads besides the model's terms.
#[derive(Clone, Copy, Debug)]
pub struct ObserverInput<'a> {
    /// q̇ at the state, length n.
    pub qd: &'a [f64],
    /// The torque applied since the previous update (the previous command as
    /// sent), length n; ignored at the first update after a (re)start.
    pub tau_applied: &'a [f64],
    /// The gravity torque `tau_applied` contains, which enters the balance
    /// with −: g when the controller adds gravity; the load's alone when the
    /// driver adds the arm's (its model without the load: what it adds and
    /// the arm's own gravity cancel); `None` when the driver adds it all.
    pub gravity_in_command: Option<&'a [f64]>,
    /// The time since the previous update, s (the control period).
    pub dt: f64,
}

impl MomentumObserver {
    /// An observer of gains `gain` (K_O per joint, 1/s, positive), r = 0,
    /// waiting for its first state. Allocates its workspace.
    pub fn new(gain: &[f64]) -> MomentumObserver {
        let n = gain.len();
        MomentumObserver {
            gain: DVector::from_column_slice(gain),
            alpha: DVector::zeros(n),
            alpha_period: f64::NAN,
            r: DVector::zeros(n),
            p_prev: DVector::zeros(n),
            beta_prev: DVector::zeros(n),
            p: DVector::zeros(n),
            beta: DVector::zeros(n),
            primed: false,
        }
    }

    /// r, the estimate of the external joint torque τ_ext (N·m).
    pub fn residual(&self) -> &[f64] {
        self.r.as_slice()
    }

    /// K_O per joint, 1/s.
    pub fn gain(&self) -> &[f64] {
        self.gain.as_slice()
    }

    /// Forgets everything (r = 0): the next update only primes the momentum
    /// (a new peer, a fault).
    pub fn reset(&mut self) {
        self.r.fill(0.0);
        self.primed = false;
    }

    /// Keeps r but restarts the momentum balance at the next update (a state
    /// missed, a torque the controller did not command): that update only
    /// primes, the one after resumes the estimate.
    pub fn reanchor(&mut self) {
        self.primed = false;
    }

    /// Whether the next update will estimate (a previous state is known).
    pub fn is_primed(&self) -> bool {
        self.primed
    }
}

/// One update of the observer at a state: `terms` holds M(q), C(q, q̇) and g(q)
/// at that state (`hcc_model::compute_all_terms`, as the law computes them),
/// `input` the velocity and the torque applied since the previous update.
/// Returns whether r was updated (false: the update primed the momentum
/// only, or an input was not finite, which reanchors). Allocation-free.
pub fn observe(obs: &mut MomentumObserver, terms: &Data, input: &ObserverInput<'_>) -> bool {
    let n = obs.r.len();
    let qd = input.qd;
    let tau = input.tau_applied;
    let finite = qd.len() == n
        && tau.len() == n
        && input.dt > 0.0
        && input.dt.is_finite()
        && qd.iter().chain(tau).all(|x| x.is_finite());
    if !finite {
        obs.primed = false;
        return false;
    }
    // p = M q̇, β = Cᵀ q̇ − g (− g only when the command carries g).
    for i in 0..n {
        let mut p = 0.0;
        let mut b = 0.0;
        for (j, v) in qd.iter().enumerate() {
            p += terms.m[(i, j)] * v;
            b += terms.c[(j, i)] * v;
        }
        obs.p[i] = p;
        obs.beta[i] = match input.gravity_in_command {
            Some(g) => b - g[i],
            None => b,
        };
    }
    if !(obs.p.iter().chain(obs.beta.iter()).all(|x| x.is_finite())) {
        obs.primed = false;
        return false;
    }
    let updated = obs.primed;
    if obs.primed {
        if input.dt != obs.alpha_period {
            for (a, k) in obs.alpha.iter_mut().zip(obs.gain.iter()) {
                *a = -(-k * input.dt).exp_m1();
            }
            obs.alpha_period = input.dt;
        }
        for (i, t) in tau.iter().enumerate() {
            let y =
                (obs.p[i] - obs.p_prev[i]) / input.dt - t - 0.5 * (obs.beta_prev[i] + obs.beta[i]);
            obs.r[i] += obs.alpha[i] * (y - obs.r[i]);
        }
    }
    std::mem::swap(&mut obs.p, &mut obs.p_prev);
    std::mem::swap(&mut obs.beta, &mut obs.beta_prev);
    obs.primed = true;
    updated
}

/// Contact detection on the estimate r: per-joint thresholds with hysteresis.
/// Contact begins when some |r_j| > threshold_j and ends when every
/// |r_j| < release × threshold_j (a gap between the two levels, so that an
/// estimate near a threshold does not chatter).
#[derive(Clone, Debug)]
pub struct ContactDetector {
    on: DVector<f64>,
    off: DVector<f64>,
    in_contact: bool,
}

/// What [`ContactDetector::update`] saw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactChange {
    /// No change of the contact flag.
    None,
    /// Contact began in this update.
    Began,
    /// Contact ended in this update.
    Ended,
}

impl ContactDetector {
    /// A detector with `threshold` per joint (N·m, positive) and release
    /// fraction `release` in (0, 1]. Allocates.
    pub fn new(threshold: &[f64], release: f64) -> ContactDetector {
        let on = DVector::from_column_slice(threshold);
        let off = &on * release;
        ContactDetector {
            on,
            off,
            in_contact: false,
        }
    }

    /// Whether a contact is flagged.
    pub fn in_contact(&self) -> bool {
        self.in_contact
    }

    /// Clears the flag (with the observer's reset).
    pub fn reset(&mut self) {
        self.in_contact = false;
    }

    /// Whether every entry of `r` is at or below its release threshold (a
    /// contact would end; none would begin).
    pub fn below_release(&self, r: &[f64]) -> bool {
        r.iter().zip(self.off.iter()).all(|(&x, &t)| x.abs() <= t)
    }

    /// Updates the flag from the estimate `r` (length n; a non-finite entry
    /// counts as above every threshold). Allocation-free.
    pub fn update(&mut self, r: &[f64]) -> ContactChange {
        let above = |x: f64, t: f64| x.is_nan() || x.abs() > t;
        if self.in_contact {
            let released = r.iter().zip(self.off.iter()).all(|(&x, &t)| !above(x, t));
            if released {
                self.in_contact = false;
                return ContactChange::Ended;
            }
        } else if r.iter().zip(self.on.iter()).any(|(&x, &t)| above(x, t)) {
            self.in_contact = true;
            return ContactChange::Began;
        }
        ContactChange::None
    }
}
