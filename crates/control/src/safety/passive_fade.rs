//! **Passive fade.** Near a singularity the torque of a level i ≥ 2 is scaled by
//! β_i ∈ [0, 1] (crate docs, "Singularities"). With the storage of the whole system
//!
//! E = ½ q̇ᵀ M q̇ + V_1 + Σ_{i≥2} β_i V_i  (= Σ_i S_i of eqs. 26, 28 when every β_i = 1),
//!
//! a fade-out (β̇_i < 0) removes the energy −β̇_i V_i ≥ 0 from E, a fade-in would add
//! β̇_i V_i. A fade-in is therefore paid from an energy tank T ≥ 0 that collects what
//! the fade-outs removed and what the damping dissipated (the levels' dampers
//! Σ β_i ẋ_iᵀ D_i ẋ_i and the null-space damping below), capped at `fade_tank_max`: β_i
//! rises only as far as T covers, so E + T never grows by a fade. β_i follows a
//! falling β(q) at once (the protection of the singular region is kept), and rises
//! only once β(q) = 1 again (hysteresis), at most at [`FADE_IN_RATE`].

use super::{FADE_IN_RATE, Safety, SafetyOutput};

impl Safety {
    /// The passive fade (module docs): `fade` holds β_i(q) on entry and the effective
    /// β_i on return; `potential` V_i; `damper_dissipation` Σ β_i ẋ_iᵀ D_i ẋ_i (W);
    /// `conditioning` r_i of each level's own inversions, for the conflict fade
    /// β_i(q) ← min(β_i(q), β_c(r_i)); `share` the law's share s of the torque
    /// the robot receives (a fade moves s β_i V_i, the storage H counts).
    pub(crate) fn passive_fade(
        &mut self,
        fade: &mut [f64],
        potential: &[f64],
        damper_dissipation: f64,
        conditioning: &[f64],
        share: f64,
        out: &mut SafetyOutput,
    ) {
        if !self.spec.enabled {
            return;
        }
        self.conflict_fade(fade, conditioning, out);
        if !self.has_prev {
            self.beta_prev.copy_from_slice(fade);
            self.has_prev = true;
        }
        let fill = (self.fill_power + damper_dissipation.max(0.0)) * self.spec.control_period_s;
        let mut tank = self.tank + fill.max(0.0);
        let mut limited = false;
        for i in 1..fade.len() {
            let (prev, v) = (self.beta_prev[i], share * potential[i].max(0.0));
            // Hysteresis: a faded level comes back only once it has left the fade
            // region (β(q) = 1), and then in at least 1 / FADE_IN_RATE s — no
            // relaxation cycles at the edge of the fade region.
            // A level faded for a conflict comes back only once the conflict
            // is over (its latch released): else its spring, back in, pulls the
            // arm into the conflict again, and it fades out again, over and over.
            let want = if fade[i] < 1.0 || self.conflict_latched[i] {
                fade[i].min(prev)
            } else {
                (prev + FADE_IN_RATE * self.spec.control_period_s).min(1.0)
            };
            let beta = if want <= prev {
                // Fade-out: the spring energy (β_prev − β) V_i leaves E for the tank.
                tank += (prev - want) * v;
                want
            } else if (want - prev) * v <= tank {
                tank -= (want - prev) * v;
                want
            } else {
                // Fade-in as far as the tank pays.
                limited = true;
                let b = prev + tank / v;
                tank = 0.0;
                b
            };
            fade[i] = beta;
            self.beta_prev[i] = beta;
        }
        self.tank = tank.min(self.spec.fade_tank_max);
        out.tank = self.tank;
        out.fade_in_limited_cycles += u64::from(limited);
    }

    /// The fade's tank (J; 0 with the safety layer off).
    pub(crate) fn fade_tank(&self) -> f64 {
        if self.spec.enabled { self.tank } else { 0.0 }
    }

    /// Puts `energy` (J, ≥ 0) into the fade's tank, up to `fade_tank_max`
    /// (the rest is dissipated); nothing with the safety layer off.
    pub(crate) fn fill_fade_tank(&mut self, energy: f64) {
        if self.spec.enabled && energy > 0.0 {
            self.tank = (self.tank + energy).min(self.spec.fade_tank_max);
        }
    }

    /// Takes up to `energy` (J) from the fade's tank; returns what it took.
    pub(crate) fn draw_fade_tank(&mut self, energy: f64) -> f64 {
        if !self.spec.enabled || energy.is_nan() {
            return 0.0;
        }
        let take = energy.clamp(0.0, self.tank);
        self.tank -= take;
        take
    }
}
