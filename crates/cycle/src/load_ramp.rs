//! A load announced at run time (docs/load.md): the controller's model takes
//! it over a ramp, not at once, so that the gravity torque it adds grows
//! smoothly (no torque step above the filter's rate). The ramp interpolates
//! the rigid body's parameters that add linearly — the mass m, the first
//! moment h = m c and the inertia about the tip frame's origin
//! I_O = I_c + m (|c|² 1 − c cᵀ) — by the quintic s(u) = 10u³ − 15u⁴ + 6u⁵
//! of the ramp's progress u, so every intermediate load is a physical one
//! (a mixture of the two). While it ramps the contact detection stays quiet
//! (the cycle's `contact` module): the change is announced, not a collision.
//!
//! **Energy.** The model's storage H counts the load's kinetic energy
//! T(load) at the tip's twist, linear in the parameters the ramp mixes: a
//! step Δs of the ramp changes H by Δs (T(to) − T(from)) with no power behind
//! it. The tanks book it (`Controller::book_model_change`): a rise is paid
//! from their spare, a fall fills the fade's tank; a rise they cannot pay
//! holds the ramp for the cycle (counted, `load_ramp_held`) until the arm
//! is slower — at rest (q̇ = 0) it is free.

use hcc_control::Controller;
use hcc_model::Load;
use nalgebra::{Matrix3, Vector3};

/// The ramp from one load to another.
pub(crate) struct LoadRamp {
    from: Load,
    to: Load,
    elapsed_s: f64,
    duration_s: f64,
    active: bool,
}

impl LoadRamp {
    pub(crate) fn new() -> LoadRamp {
        LoadRamp {
            from: Load::none(),
            to: Load::none(),
            elapsed_s: 0.0,
            duration_s: 0.0,
            active: false,
        }
    }

    /// From the controller's load now to `to` over `duration_s` (≤ 0: at the
    /// next cycle).
    pub(crate) fn start(&mut self, from: Load, to: Load, duration_s: f64) {
        self.from = from;
        self.to = to;
        self.elapsed_s = 0.0;
        self.duration_s = duration_s.max(0.0);
        self.active = true;
    }

    /// The ramp's progress u ∈ [0, 1] (1: none runs; 0: a ramp of no
    /// duration not yet taken).
    pub(crate) fn progress(&self) -> f64 {
        match (self.active, self.duration_s > 0.0) {
            (false, _) => 1.0,
            (true, true) => self.u_at(self.elapsed_s),
            (true, false) => 0.0,
        }
    }

    /// The progress after `elapsed` s (a ramp of no duration: done).
    fn u_at(&self, elapsed: f64) -> f64 {
        if self.duration_s > 0.0 {
            (elapsed / self.duration_s).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }

    /// Whether a ramp runs (the load is being announced).
    pub(crate) fn active(&self) -> bool {
        self.active
    }

    /// One cycle of `dt` s on at the state (`q`, `qd`): the controller's model
    /// takes the ramp's load at its new progress, its change of the storage
    /// booked by the tanks (module docs). Returns false when the tanks could
    /// not pay it and the ramp held. Allocation-free.
    pub(crate) fn advance(
        &mut self,
        dt: f64,
        controller: &mut Controller,
        q: &[f64],
        qd: &[f64],
    ) -> bool {
        if !self.active {
            return true;
        }
        let smooth = |u: f64| u * u * u * (10.0 - 15.0 * u + 6.0 * u * u);
        let step = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
        let u = self.u_at(self.elapsed_s + step);
        let s = smooth(u);
        if controller.books_model_changes() {
            let ds = s - smooth(self.u_at(self.elapsed_s));
            let gain = controller.load_kinetic_energy_change(&self.from, &self.to, q, qd);
            if !controller.book_model_change(ds * gain) {
                return false;
            }
        }
        self.elapsed_s += step;
        let load = if u >= 1.0 {
            self.active = false;
            self.to
        } else {
            mixture(&self.from, &self.to, s)
        };
        controller.set_load(&load);
        true
    }
}

/// (1 − s) a + s b in mass, first moment and inertia about the origin.
fn mixture(a: &Load, b: &Load, s: f64) -> Load {
    let about_origin = |l: &Load| {
        l.inertia
            + l.mass * (l.com.norm_squared() * Matrix3::identity() - l.com * l.com.transpose())
    };
    let mass = (1.0 - s) * a.mass + s * b.mass;
    let h: Vector3<f64> = (1.0 - s) * a.mass * a.com + s * b.mass * b.com;
    let i_o = (1.0 - s) * about_origin(a) + s * about_origin(b);
    if mass <= 0.0 {
        return Load::none();
    }
    let com = h / mass;
    let inertia = i_o - mass * (com.norm_squared() * Matrix3::identity() - com * com.transpose());
    Load {
        mass,
        com,
        inertia: 0.5 * (inertia + inertia.transpose()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mixture_of_two_loads_is_their_rigid_union_scaled() {
        let a = Load::point(1.0, [0.0, 0.0, 0.1]);
        let b = Load {
            mass: 2.0,
            com: Vector3::new(0.05, 0.0, 0.0),
            inertia: Matrix3::from_diagonal_element(0.01),
        };
        // The ends are the loads themselves.
        let m0 = mixture(&a, &b, 0.0);
        assert!((m0.com - a.com).norm() < 1e-15 && (m0.mass - 1.0).abs() < 1e-15);
        assert!(m0.inertia.norm() < 1e-15);
        let m1 = mixture(&a, &b, 1.0);
        assert!((m1.inertia - b.inertia).norm() < 1e-15 && (m1.com - b.com).norm() < 1e-15);
        // Half-way: the union of half of each, a physical load.
        let h = mixture(&a, &b, 0.5);
        assert!((h.mass - 1.5).abs() < 1e-15);
        assert!((h.com - (0.5 * a.com + 1.0 * b.com) / 1.5).norm() < 1e-15);
        assert_eq!(h.check(f64::INFINITY), Ok(()));
    }
}
