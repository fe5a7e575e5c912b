//! The energy tank of the stages after the law: what the saturation, the
//! torque filter and the velocity limit do to the law's torque is paid from a
//! tank, like a level's spring shift (hcc_control::energy_tank), so that they
//! cannot feed the arm energy the law did not.
//!
//! The law τ_law (eq. 19, after the contact reaction) is passive with respect
//! to the storage H of the law (kinetic energy, the levels' potentials and
//! tanks, the guard's potential: `SafetyOutput::h`). The robot receives
//! τ_sent: saturated, rate-limited or low-passed behind the law, corrected by
//! the velocity limit. The difference feeds the arm
//!
//! P_o = q̇ᵀ (τ_sent − τ_law),
//!
//! which has no sign: a torque that lags behind a stiff damper pushes where the
//! damper has already turned to brake (the limit cycles of the unreachable
//! sweep with the shipped rate limit). The tank books it, E_o ← E_o − T P_o (a
//! lag that takes energy out fills it, one that feeds energy in drains it),
//! so H + E_o changes only by what the law itself does, and what is above
//! `tank_max` decays in `TANK_TRANSIENT_TIME` (dissipated).
//!
//! **The spare.** Once E_o is empty the stages draw on what the fade's tank
//! holds and the levels' tanks hold above their valves' band
//! (`Controller::tank_spare`): a transfer between tanks, which leaves H as
//! it is and closes no level's valve. S below is E_o plus that spare.
//!
//! **Held back.** The stages may feed in β(S) P_o⁺ and never more than S
//! holds above the floor ((S − floor)/T; β the levels' valve, closed at
//! the floor, open a band above it: the hold comes in smoothly). What is
//! above that is taken out by a damper on the whole arm, τ ← τ − λ M q̇ with
//! λ = (P_o − allowed)/(q̇ᵀ M q̇) ≤ [`HOLD_RATE`]: it slows every joint in
//! proportion to its speed (M⁻¹ of it is −λ q̇: no joint is pushed anywhere),
//! and as a whole it is scaled into the box of the torque limits and one rate
//! step from the previous command, so the hold never makes a torque step the
//! rate limit forbids, nor leaves the limits. What it cannot take out (the
//! cap, the box) is fed in: the tanks stay empty and H rises by it, counted
//! (`energy_unpaid_mj`). At rest (q̇ = 0) nothing is held: the equilibria
//! are the law's. While the tank pays, the command is the stages' bit for
//! bit.
//!
//! On with the levels' tanks (`[safety] enabled`, `energy_tanks`), filled with
//! `tank_initial` at the start and after a new peer. Allocation-free.

use hcc_control::energy_tank::{TANK_FLOOR, TANK_TRANSIENT_TIME, valve};
use hcc_model::linalg::products::gemv_slices;
use hcc_msgs::MAX_JOINTS;
use nalgebra::DMatrix;

use crate::torque_filter::RateLimit;

/// The tank of the stages after the law (module docs).
#[derive(Debug, Clone)]
pub struct OutputTank {
    on: bool,
    /// E_o (J, ≥ 0; what the stages feed in beyond it is `unpaid`).
    energy: f64,
    /// E_o at the last booked cycle's sample, before it booked the coming
    /// period (what H counts with that state's storage).
    at_sample: f64,
    initial: f64,
    max: f64,
    period: f64,
    /// τ_law of this cycle (the first n entries).
    law: [f64; MAX_JOINTS],
    /// M q̇ and the box the held command stays in (scratch).
    u: [f64; MAX_JOINTS],
    lo: [f64; MAX_JOINTS],
    hi: [f64; MAX_JOINTS],
    /// The energy the stages fed in beyond what the tank held (J, total).
    unpaid: f64,
}

/// The fastest the hold decelerates the arm (1/s): −λ M q̇ with λ at most
/// this, a damper that halves every joint's speed in no less than 14 ms.
pub const HOLD_RATE: f64 = 50.0;

impl OutputTank {
    /// A tank holding `initial` (J), of capacity `max`, booked every `period`
    /// (s); `on`: whether it acts (off: it books nothing and holds nothing).
    pub fn new(on: bool, initial: f64, max: f64, period: f64) -> OutputTank {
        OutputTank {
            on,
            energy: if on { initial } else { 0.0 },
            at_sample: if on { initial } else { 0.0 },
            initial,
            max,
            period,
            law: [0.0; MAX_JOINTS],
            u: [0.0; MAX_JOINTS],
            lo: [0.0; MAX_JOINTS],
            hi: [0.0; MAX_JOINTS],
            unpaid: 0.0,
        }
    }

    /// E_o at the last booked cycle's sample (J; 0 when off): the content
    /// before that cycle booked the period it starts, which H adds to the
    /// storage of the same state.
    pub fn energy_at_sample(&self) -> f64 {
        self.at_sample
    }

    /// A new peer: the tank holds `tank_initial` again.
    pub fn reset(&mut self) {
        if self.on {
            self.energy = self.initial;
            self.at_sample = self.initial;
        }
    }

    /// The law's torque of this cycle, before the stages.
    pub fn set_law(&mut self, tau: &[f64]) {
        let n = tau.len().min(MAX_JOINTS);
        self.law[..n].copy_from_slice(&tau[..n]);
    }

    /// P_o = q̇ᵀ (τ − τ_law) (W).
    fn power(&self, qd: &[f64], tau: &[f64]) -> f64 {
        qd.iter()
            .zip(tau)
            .zip(&self.law)
            .map(|((v, t), l)| v * (t - l))
            .sum()
    }

    /// Holds back what the stages would feed in beyond what the tank pays
    /// (module docs): `tau` (length n) the command after the filter, within
    /// `limits` and `rate`'s box; `m` the inertia M(q); `spare` what the
    /// fade's and the levels' tanks may give when this one is empty
    /// (`Controller::tank_spare`). Returns whether it changed `tau`.
    pub fn hold(
        &mut self,
        qd: &[f64],
        m: &DMatrix<f64>,
        spare: f64,
        tau: &mut [f64],
        limits: &[f64],
        rate: Option<RateLimit<'_>>,
    ) -> bool {
        if !self.on {
            return false;
        }
        let n = tau.len().min(MAX_JOINTS);
        if m.shape() != (n, n) {
            return false;
        }
        let (qd, tau) = (&qd[..n], &mut tau[..n]);
        let p = self.power(qd, tau);
        // Its own content, and the levels' spare once that is gone.
        let available = self.energy + spare.max(0.0);
        let room = ((available - TANK_FLOOR) / self.period).max(0.0);
        let allowed = (valve(available) * p).min(room).max(0.0);
        if p.is_nan() || p <= allowed {
            return false;
        }
        // u = M q̇; the hold −λ u takes 2λ of the kinetic energy's rate.
        gemv_slices(&mut self.u[..n], 1.0, m, qd, 0.0);
        let kinetic2: f64 = qd.iter().zip(&self.u).map(|(v, u)| v * u).sum();
        if kinetic2.is_nan() || kinetic2 <= 0.0 {
            return false;
        }
        let lambda = ((p - allowed) / kinetic2).min(HOLD_RATE);
        // The hold as a whole scaled into the box (its direction kept).
        let mut scale: f64 = 1.0;
        for k in 0..n {
            let (mut lo, mut hi) = (-limits[k], limits[k]);
            if let Some(r) = &rate {
                lo = lo.max(r.previous[k] - r.max_step);
                hi = hi.min(r.previous[k] + r.max_step);
            }
            // τ is within the box but for rounding: the box never excludes it.
            (self.lo[k], self.hi[k]) = (lo.min(tau[k]), hi.max(tau[k]));
            let c = -lambda * self.u[k];
            if c > 0.0 {
                scale = scale.min((self.hi[k] - tau[k]) / c);
            } else if c < 0.0 {
                scale = scale.min((self.lo[k] - tau[k]) / c);
            }
        }
        if scale.is_nan() || scale <= 0.0 {
            return false;
        }
        let bounds = self.lo.iter().zip(&self.hi);
        for ((t, u), (lo, hi)) in tau.iter_mut().zip(&self.u).zip(bounds) {
            // Bounded: the scaled step may overshoot a bound by a rounding.
            *t = (*t - scale * lambda * u).max(*lo).min(*hi);
        }
        true
    }

    /// Books the command sent: E_o ← E_o − T q̇ᵀ (τ_sent − τ_law), the
    /// excess above the capacity decaying; what the tank does not hold is
    /// asked of `draw` (J asked → J given: the levels' spare,
    /// `Controller::draw_tank_spare`), the rest counted as fed in.
    pub fn book(&mut self, qd: &[f64], sent: &[f64], draw: impl FnOnce(f64) -> f64) {
        if !self.on {
            return;
        }
        self.at_sample = self.energy;
        let n = sent.len().min(MAX_JOINTS);
        let p = self.power(&qd[..n], &sent[..n]);
        if !p.is_finite() {
            return;
        }
        let mut e = self.energy - self.period * p;
        if e > self.max {
            e = self.max + (e - self.max) * (-self.period / TANK_TRANSIENT_TIME).exp();
        }
        if e < 0.0 {
            // Beyond the tank: from the levels' spare, else H rises by it
            // (counted).
            let given = draw(-e).clamp(0.0, -e);
            self.unpaid -= e + given;
            e = 0.0;
        }
        self.energy = e;
    }

    /// The energy the stages fed in beyond what the tank held, in total (J).
    pub fn unpaid(&self) -> f64 {
        self.unpaid
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_tank_pays_and_changes_nothing() {
        let mut t = OutputTank::new(true, 2.0, 4.0, 1e-3);
        t.set_law(&[1.0, 2.0]);
        let mut tau = [1.5, 2.0];
        let m = DMatrix::identity(2, 2);
        assert!(!t.hold(&[1.0, 0.0], &m, 0.0, &mut tau, &[100.0, 100.0], None));
        assert_eq!(tau, [1.5, 2.0]);
        t.book(&[1.0, 0.0], &tau, |_| 0.0);
        assert!((t.energy - (2.0 - 0.5e-3)).abs() < 1e-15);
    }

    #[test]
    fn an_empty_tank_holds_back_along_m_qd() {
        let mut t = OutputTank::new(true, 0.0, 4.0, 1e-3);
        t.set_law(&[0.0, 0.0, 0.0]);
        let m = DMatrix::from_row_slice(3, 3, &[2.0, 0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let qd = [0.1, -0.2, 0.0];
        // The filter lags: it feeds 0.1·3 + (−0.2)(−1) = 0.5 W in.
        let mut tau = [3.0, -1.0, 7.0];
        assert!(t.hold(&qd, &m, 0.0, &mut tau, &[100.0; 3], None));
        let p: f64 = qd.iter().zip(&tau).map(|(v, x)| v * x).sum();
        assert!(p.abs() < 1e-12, "nothing fed in: {p} {tau:?}");
        // M q̇ = (0.1, −0.15, 0), q̇ᵀ M q̇ = 0.04: λ = 12.5.
        assert!((tau[0] - (3.0 - 1.25)).abs() < 1e-12, "{tau:?}");
        assert!((tau[1] - (-1.0 + 1.875)).abs() < 1e-12, "{tau:?}");
        assert_eq!(tau[2], 7.0);
        t.book(&qd, &tau, |_| 0.0);
        assert!(t.energy.abs() < 1e-15);
        assert!(t.unpaid().abs() < 1e-15);
    }

    #[test]
    fn the_hold_stays_in_the_box_and_what_it_cannot_take_out_is_counted() {
        let mut t = OutputTank::new(true, 0.0, 4.0, 1e-3);
        t.set_law(&[-10.0]);
        let m = DMatrix::from_element(1, 1, 1.0);
        let qd = [1.0];
        let mut tau = [0.0];
        let previous = [0.5];
        let rate = RateLimit {
            previous: &previous,
            max_step: 1.0,
        };
        // λ = 10 (below the cap), but one rate step allows only down to −0.5.
        assert!(t.hold(&qd, &m, 0.0, &mut tau, &[100.0], Some(rate)));
        assert_eq!(tau, [-0.5]);
        t.book(&qd, &tau, |_| 0.0);
        assert_eq!(t.energy, 0.0);
        assert!((t.unpaid() - 9.5e-3).abs() < 1e-15, "{}", t.unpaid());
        // The cap: at most HOLD_RATE.
        let mut tau = [0.0];
        let qd = [0.01];
        assert!(t.hold(&qd, &m, 0.0, &mut tau, &[100.0], None));
        assert!((tau[0] + HOLD_RATE * 0.01).abs() < 1e-12, "{tau:?}");
    }

    #[test]
    fn at_rest_or_off_nothing_is_held() {
        let mut t = OutputTank::new(true, 0.0, 4.0, 1e-3);
        t.set_law(&[0.0]);
        let m = DMatrix::from_element(1, 1, 1.0);
        let mut tau = [5.0];
        assert!(!t.hold(&[0.0], &m, 0.0, &mut tau, &[100.0], None));
        let mut off = OutputTank::new(false, 2.0, 4.0, 1e-3);
        off.set_law(&[0.0]);
        assert!(!off.hold(&[1.0], &m, 0.0, &mut tau, &[100.0], None));
        off.book(&[1.0], &tau, |_| 0.0);
        assert_eq!(off.energy, 0.0);
        assert_eq!(tau, [5.0]);
    }

    #[test]
    fn above_the_capacity_the_excess_decays() {
        let mut t = OutputTank::new(true, 4.0, 4.0, 1e-3);
        t.set_law(&[1.0]);
        t.book(&[1.0], &[0.0], |_| 0.0);
        let e = 4.0 + 1e-3 * (-1e-3 / TANK_TRANSIENT_TIME).exp();
        assert!((t.energy - e).abs() < 1e-15);
    }

    #[test]
    fn an_empty_tank_draws_on_the_levels_spare_before_it_holds() {
        let mut t = OutputTank::new(true, 0.0, 4.0, 1e-3);
        t.set_law(&[0.0]);
        let m = DMatrix::from_element(1, 1, 1.0);
        let qd = [1.0];
        // The filter lags by 2 N·m along the motion: 2 W, 2 mJ this period.
        let mut tau = [2.0];
        // The levels hold 1 J to spare: nothing is held back…
        assert!(!t.hold(&qd, &m, 1.0, &mut tau, &[100.0], None));
        assert_eq!(tau, [2.0]);
        // …and the booking draws the 2 mJ from them: nothing unpaid.
        let mut asked = 0.0;
        t.book(&qd, &tau, |e| {
            asked = e;
            e
        });
        assert!((asked - 2e-3).abs() < 1e-15, "{asked}");
        assert_eq!(t.energy, 0.0);
        assert_eq!(t.unpaid(), 0.0);
        // What the levels cannot give is counted.
        t.book(&qd, &tau, |e| 0.5 * e);
        assert!((t.unpaid() - 1e-3).abs() < 1e-15, "{}", t.unpaid());
        // Without spare an empty tank holds back.
        let mut tau = [2.0];
        assert!(t.hold(&qd, &m, 0.0, &mut tau, &[100.0], None));
        assert!(tau[0] < 2.0);
    }
}
