//! **Energy tanks per level** — passivity by construction where the levels
//! above a level cannot converge (Dietrich, Wu, Bussmann, Ott, Albu-Schäffer,
//! "Passive hierarchical impedance control via energy tanks", IEEE RA-L 2(2),
//! 2017).
//!
//! With q̇ = Σ_j Z_jᵀ v_j (eqs. 3–13) level i's velocity splits into its own,
//! κ_i = J_i Z_iᵀ v_i, and the one the levels above induce,
//! w_i = ẋ_i − κ_i = J_i Σ_{j<i} Z_jᵀ v_j (J_i Z_jᵀ = 0 for j > i). Level i's
//! torque τ_i = −J̄_iᵀ Z_i J_iᵀ F_i (eq. 21) has the power q̇ᵀτ_i = −κ_iᵀ F_i,
//! so its spring V_i(x_i) changes by
//!
//! V̇_i = −q̇ᵀτ_i − ẋ_iᵀ D_i ẋ_i + w_iᵀ F_i:
//!
//! the last term has no sign — the levels above drag level i's spring and can
//! feed energy into the arm (the paper's Sec. IV proves stability once they
//! have converged, w_i → 0). The tank pays for it. Level i's spring acts at a
//! point x̂_i = x_i − δ_i,
//!
//! dx̂_i/dt = β_i ŵ_i + κ_i,  ŵ_i = w_i + K_P δ_i,
//! F_i = ∂V_i/∂x̂_iᵀ(x̂_i) + D_i dx̂_i/dt,
//!
//! i.e. δ̇_i = (1 − β_i) w_i − β_i K_P δ_i, and the torque is eq. (21)'s with
//! this F_i. Then V̇_i(x̂_i) = −q̇ᵀτ_i − dx̂ᵀ D_i dx̂ + β_i ŵ_iᵀ F_i, and with the
//! tank
//!
//! Ė_i = ρ dx̂ᵀ D_i dx̂ − β_i ŵ_iᵀ F_i  (above E_max the excess decays: dissipated)
//!
//! V_i(x̂_i) + E_i never grows but by −q̇ᵀτ_i: each level is passive, a share
//! 1 − ρ of its damper's power is dissipated for good (so the arm comes to
//! rest: the storage falls while anything moves), and the whole arm's storage
//! H = ½ q̇ᵀ M q̇ + Σ V_i + Σ E_i cannot rise without external input. The valve
//! β_i opens smoothly over the band [`TANK_FLOOR`] … + [`TANK_BAND`] of E_i;
//! while every tank holds more than that and no spring point is shifted
//! (δ_i = 0), β_i = 1, δ̇_i = 0 and the torque is the paper's law bit for bit.
//! The valve opens at most at [`VALVE_OPEN_RATE`] (a refilled tank gives the
//! damper back smoothly).
//! An empty tank costs level i accuracy (its spring point follows what the
//! levels above do to it), never passivity; K_P pulls x̂_i back to x_i as the
//! tank refills, and a shift below [`SHIFT_SNAP`] with the valve open is
//! dropped (the paper's law again).
//!
//! In discrete time the valve is also capped so that one period's drain
//! β_i ŵᵀF_i T never exceeds what the tank holds (F_i is affine in β_i:
//! F_i(β) = F_0 − D_i w_i + β D_i ŵ_i, the drain a quadratic in β).
//! With a fade β_i^f of the level (crate docs, "Singularities") every power
//! above is scaled by it, as τ_i is.
//!
//! The tank starts, and is refilled at every goal or gains change (a command:
//! an input), with `tank_initial` plus [`TANK_TRANSIENT_SHARE`] of the storage
//! at that moment — the sequential convergence of Sec. IV feeds energy while it
//! lasts; what is above `tank_max` decays in [`TANK_TRANSIENT_TIME`].
//!
//! Allocation-free after [`EnergyTank::new`].

use hcc_linalg::products::gemv;
use nalgebra::{DMatrix, DVector};

/// The tank's floor (J): the valve is closed at or below it (E_i = ½ s_i² of
/// the paper stays away from 0).
pub const TANK_FLOOR: f64 = 0.01;

/// The band over which the valve opens (J): β_i = smoothstep((E_i − floor)/band);
/// wide enough that a drain of 100 W closes it over 5 ms (the damper's share
/// of F_i, D_i (1 − β_i) w_i, changes with it).
pub const TANK_BAND: f64 = 0.5;

/// ρ: the share of level i's damper power that fills its tank; the rest is
/// dissipated, so the storage falls while the arm moves.
pub const TANK_FILL_SHARE: f64 = 0.5;

/// The share of the storage (½ q̇ᵀ M q̇ + Σ V_i) a tank receives on top of
/// `tank_initial` at the start and at a goal or gains change: what the
/// sequential convergence of Sec. IV feeds through a level's spring (the
/// paper's two simulations: 9 % and 21 % of their storage, within 0.25 s).
pub const TANK_TRANSIENT_SHARE: f64 = 0.5;

/// Time constant (s) with which a tank's content above its capacity decays
/// (dissipated): the transient's share lasts about as long as the transient.
pub const TANK_TRANSIENT_TIME: f64 = 0.5;

/// The fastest the valve opens (1/s): a tank refilled at once (a goal or gains
/// change) gives its level's damper back over at least 50 ms, not in a step.
pub const VALVE_OPEN_RATE: f64 = 20.0;

/// A shift δ_i with every entry below this (m or rad) is dropped once the valve
/// is fully open.
pub const SHIFT_SNAP: f64 = 1e-9;

/// The valve β(E) ∈ [0, 1]: closed at the floor, open a band above it, C² in
/// between (the quintic smoothstep 6u⁵ − 15u⁴ + 10u³).
pub fn valve(energy: f64) -> f64 {
    let u = ((energy - TANK_FLOOR) / TANK_BAND).clamp(0.0, 1.0);
    u * u * u * (u * (6.0 * u - 15.0) + 10.0)
}

/// Level i's tank and its spring point's shift.
#[derive(Clone, Debug)]
pub struct EnergyTank {
    /// E_i (J).
    pub energy: f64,
    /// β_i of this cycle.
    pub valve: f64,
    /// δ_i = x_i − x̂_i (the coordinates of ẋ_i; world angular velocity on
    /// quaternion rows).
    pub shift: DVector<f64>,
    /// Some entry of `shift` is not zero: the spring acts at x̂_i.
    pub shifted: bool,
    /// δ̇_i of this cycle.
    pub shift_rate: DVector<f64>,
    /// ŵ_i = w_i + K_P δ_i and D_i ŵ_i (scratch; D_i e in the booking).
    w_hat: DVector<f64>,
    d_w: DVector<f64>,
    /// F_0 − D_i w_i (scratch).
    f_base: DVector<f64>,
}

/// What a level hands its tank each cycle.
pub struct TankTerms<'a> {
    /// w_i, the velocity the levels above induce in level i's coordinates.
    pub w: &'a DVector<f64>,
    /// D_i.
    pub damping: &'a DMatrix<f64>,
    /// K_P (1/s), the pull of x̂_i back to x_i.
    pub return_rate: f64,
    /// The level's fade β_i^f (its torque's factor).
    pub fade: f64,
    /// The control period T (s).
    pub period: f64,
}

impl EnergyTank {
    /// A tank of `m` task coordinates holding `energy` (J), the spring at x_i.
    pub fn new(m: usize, energy: f64) -> EnergyTank {
        EnergyTank {
            energy,
            valve: 1.0,
            shift: DVector::zeros(m),
            shifted: false,
            shift_rate: DVector::zeros(m),
            w_hat: DVector::zeros(m),
            d_w: DVector::zeros(m),
            f_base: DVector::zeros(m),
        }
    }

    /// The spring point's shift δ_i, if the spring acts anywhere but at x_i.
    pub fn spring_shift(&self) -> Option<&DVector<f64>> {
        self.shifted.then_some(&self.shift)
    }

    /// Plans the cycle: the valve β_i from E_i (capped so that this period's
    /// drain is within E_i), δ̇_i, and F_i ← F_i − D_i δ̇_i (`f` holds F_0, the
    /// spring at x̂_i plus the damper on ẋ_i − ẋ_{i,d}). Returns whether F_i
    /// changed (nothing does while the valve is open and δ_i = 0).
    pub fn plan(&mut self, c: &TankTerms<'_>, f: &mut DVector<f64>) -> bool {
        let beta_open = valve(self.energy).min(self.valve + VALVE_OPEN_RATE * c.period);
        let scale = c.fade * c.period;
        if beta_open == 1.0 && !self.shifted && c.w.dot(f) * scale <= self.energy - TANK_FLOOR {
            // The tank pays the paper's law this period: it runs bit for bit.
            self.valve = 1.0;
            self.shift_rate.fill(0.0);
            return false;
        }
        // ŵ = w + K_P δ; F(β) = (F_0 − D w) + β D ŵ.
        self.w_hat.copy_from(c.w);
        self.w_hat.axpy(c.return_rate, &self.shift, 1.0);
        gemv(&mut self.d_w, 1.0, c.damping, &self.w_hat, 0.0);
        self.f_base.copy_from(f);
        gemv(&mut self.f_base, -1.0, c.damping, c.w, 1.0);
        // The drain over the period: β (a + β b) β^f T with a = ŵᵀ(F_0 − D w),
        // b = ŵᵀ D ŵ ≥ 0; at most E.
        let a = self.w_hat.dot(&self.f_base);
        let b = self.w_hat.dot(&self.d_w).max(0.0);
        let mut beta = beta_open;
        if scale > 0.0 && beta * (a + beta * b) * scale > self.energy {
            let cap = self.energy.max(0.0) / scale;
            let most = if b > 0.0 {
                (-a + (a * a + 4.0 * b * cap).sqrt()) / (2.0 * b)
            } else if a > 0.0 {
                cap / a
            } else {
                beta
            };
            beta = beta.min(most).clamp(0.0, 1.0);
        }
        self.valve = beta;
        // δ̇ = (1 − β) w − β K_P δ, and F = F_0 − D δ̇ = F_base + β D ŵ.
        self.shift_rate.copy_from(c.w);
        self.shift_rate *= 1.0 - beta;
        self.shift_rate
            .axpy(-beta * c.return_rate, &self.shift, 1.0);
        f.copy_from(&self.f_base);
        f.axpy(beta, &self.d_w, 1.0);
        true
    }

    /// Books the cycle: E_i += T β^f (ρ eᵀ D_i e − β_i ŵ_iᵀ F_i) with the
    /// damper's velocity e = ẋ_i − ẋ_{i,d} − δ̇_i (`damper_velocity`), ≥ 0;
    /// what is above `max` decays with [`TANK_TRANSIENT_TIME`]; δ_i += T δ̇_i,
    /// dropped below [`SHIFT_SNAP`] with the valve open. `f`: F_i as applied;
    /// `planned`: [`EnergyTank::plan`] acted this cycle.
    pub fn book(
        &mut self,
        c: &TankTerms<'_>,
        f: &DVector<f64>,
        damper_velocity: &DVector<f64>,
        planned: bool,
        max: f64,
    ) {
        // The damper's power eᵀ D e (`d_w` is free once `plan` is done).
        gemv(&mut self.d_w, 1.0, c.damping, damper_velocity, 0.0);
        let fill = TANK_FILL_SHARE * damper_velocity.dot(&self.d_w).max(0.0);
        let drain = if planned {
            self.valve * self.w_hat.dot(f)
        } else {
            // Valve open, no shift: ŵ = w, β = 1.
            c.w.dot(f)
        };
        let mut e = self.energy + c.period * c.fade * (fill - drain);
        if e > max {
            // Above the capacity: the excess decays (is dissipated).
            e = max + (e - max) * (-c.period / TANK_TRANSIENT_TIME).exp();
        }
        self.energy = e.max(0.0);
        if planned {
            self.shift.axpy(c.period, &self.shift_rate, 1.0);
            if self.valve == 1.0 && self.shift.amax() < SHIFT_SNAP {
                self.shift.fill(0.0);
            }
            self.shifted = self.shift.iter().any(|&x| x != 0.0);
        }
    }

    /// Refills the tank to at least `energy` (J).
    pub fn refill(&mut self, energy: f64) {
        self.energy = self.energy.max(energy);
    }

    /// Back to `energy` (J), the spring at x_i.
    pub fn reset(&mut self, energy: f64) {
        self.energy = energy;
        self.valve = 1.0;
        self.shift.fill(0.0);
        self.shifted = false;
        self.shift_rate.fill(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_valve_is_closed_at_the_floor_open_a_band_above_and_smooth() {
        assert_eq!(valve(0.0), 0.0);
        assert_eq!(valve(TANK_FLOOR), 0.0);
        assert_eq!(valve(TANK_FLOOR + TANK_BAND), 1.0);
        assert_eq!(valve(10.0), 1.0);
        let h = 1e-7;
        assert!(valve(TANK_FLOOR + h) < 1e-12);
        assert!(1.0 - valve(TANK_FLOOR + TANK_BAND - h) < 1e-12);
        let mid = valve(TANK_FLOOR + 0.5 * TANK_BAND);
        assert!((mid - 0.5).abs() < 1e-12);
    }
}
