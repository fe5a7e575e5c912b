//! Where the cycle meets the energy tanks (crate::energy_tank): w_i and κ_i of
//! every level below the first from the decomposition, the valve and the
//! shift of its spring point, F_i with the damper on dx̂_i/dt, the booking.

use super::Controller;
use crate::energy_tank::{TANK_BAND, TANK_FLOOR, TANK_TRANSIENT_SHARE, TankTerms};
use crate::spec::Form;
use hcc_linalg::products::{gemv, gemv_t};
use nalgebra::DVector;

impl Controller {
    /// The energy tanks act: the extended form (eq. 21, whose power splits
    /// into κ_i and w_i) with the safety layer and its tanks on.
    pub(super) fn tanks_on(&self) -> bool {
        let s = &self.spec.safety;
        s.enabled && s.energy_tanks && self.spec.form == Form::Extended
    }

    /// Every level i ≥ 2: κ_i = J_i Z_iᵀ v_i (v_i of this cycle), w_i =
    /// J_i q̇ − κ_i; the tank plans the cycle (F_i with the damper on dx̂_i/dt,
    /// the rate of V_i at x̂_i) and books it. After the fades, before the level
    /// torques (which read F_i).
    pub(super) fn energy_tanks(&mut self, qd: &DVector<f64>) {
        if !self.tanks_on() {
            return;
        }
        let s = &self.spec.safety;
        let (period, return_rate, max) = (s.control_period_s, s.tank_return_rate, s.tank_max);
        self.out.command_input.refill = 0.0;
        if self.tank_refill {
            // Start, goal or gains change.
            let e = self.refill_level(qd);
            let mut added = 0.0;
            for l in self.levels.iter_mut().skip(1) {
                added += (e - l.tank.energy).max(0.0);
                l.tank.refill(e);
            }
            self.out.command_input.refill = added;
            self.tank_refill = false;
        }
        // A goal setpoint's grant; a transition's top-ups (`command_tank.rs`).
        self.command_tank_sample(qd);
        // What a transition's tanks hold above `tank_max` was granted for it.
        let max = if self.commands_hold_tanks() {
            f64::INFINITY
        } else {
            max
        };
        for i in 1..self.levels.len() {
            let l = &mut self.levels[i];
            l.tank_at_sample = l.tank.energy;
            gemv_t(&mut self.tmp_n, 1.0, &l.z, &l.v, 0.0);
            gemv(&mut l.kappa, 1.0, &l.j, &self.tmp_n, 0.0);
            // J_i q̇ = ẋ_i, which `xdot` holds relative to a moving goal.
            l.w_up.copy_from(&l.xdot);
            if l.goal_moving {
                l.w_up += &l.goal_velocity;
            }
            l.w_up -= &l.kappa;
            if self.track.active && l.track.on {
                // Tracking: the drag relative to what the levels above are
                // meant to induce, w̃_i = w_i − J_i q̇_d^{(i−1)} (docs/tracking.md).
                l.w_up -= &l.track.w_d;
            }
            let terms = TankTerms {
                w: &l.w_up,
                damping: &l.damping,
                return_rate,
                // The torque's share the robot receives: its fade, and
                // what a contact hold leaves of the law.
                fade: self.out.fade[i] * self.law_share,
                period,
            };
            l.tank_planned = l.tank.plan(&terms, &mut l.f);
            // The damper's velocity e = ẋ_i − ẋ_{i,d} − δ̇_i (κ_i is no longer
            // needed: its buffer holds e).
            l.kappa.copy_from(&l.xdot);
            if l.tank_planned {
                l.kappa -= &l.tank.shift_rate;
                l.spring_rate -= l.grad.dot(&l.tank.shift_rate);
            }
            l.tank.book(&terms, &l.f, &l.kappa, l.tank_planned, max);
            self.out.tank[i] = l.tank_at_sample;
            self.out.tank_valve[i] = l.tank.valve;
        }
    }

    /// Σ E_i of the levels' tanks and the command tank E_c at this cycle's
    /// sample (J; 0 when they are off): the content the state's storage is counted with, before this
    /// cycle books the coming period.
    pub(super) fn tank_energy(&self) -> f64 {
        if !self.tanks_on() {
            return 0.0;
        }
        self.levels
            .iter()
            .skip(1)
            .map(|l| l.tank_at_sample)
            .sum::<f64>()
            + self.command.at_sample
    }

    /// What the fade's tank holds and the levels' tanks hold above the band
    /// their valves open over (J; 0 when the tanks are off): what the stages
    /// after the law may draw when their own tank is empty without closing
    /// any level's valve, so that no level loses accuracy for it (hcc-cycle's
    /// output tank).
    pub fn tank_spare(&self) -> f64 {
        if !self.tanks_on() {
            return 0.0;
        }
        let spare = |l: &super::level::Level| (l.tank.energy - TANK_FLOOR - TANK_BAND).max(0.0);
        self.safety.fade_tank() + self.levels.iter().skip(1).map(spare).sum::<f64>()
    }

    /// Takes up to `energy` (J) of the [spare](Controller::tank_spare): the
    /// fade's tank first (it overflows at `fade_tank_max`), then the lowest
    /// level first (its accuracy matters least); returns what it took.
    /// H is unchanged by it: the energy moves from one tank to another.
    pub fn draw_tank_spare(&mut self, energy: f64) -> f64 {
        if !self.tanks_on() || energy.is_nan() || energy <= 0.0 {
            return 0.0;
        }
        let mut left = energy - self.safety.draw_fade_tank(energy);
        for l in self.levels.iter_mut().skip(1).rev() {
            if left <= 0.0 {
                break;
            }
            let keep = TANK_FLOOR + TANK_BAND;
            let take = (l.tank.energy - keep).max(0.0).min(left);
            if take > 0.0 {
                // Never below the band's top, rounding included: the valve
                // stays open.
                l.tank.energy = (l.tank.energy - take).max(keep);
                left -= take;
            }
        }
        energy - left
    }

    /// Books a change `energy` (J) of the storage H that no motion makes: the
    /// model's (a load announced at run time, hcc-cycle's `load_ramp`) or a
    /// spring's (a gains transition, [`Controller::ramp_gains`]): a rise
    /// is paid from the [spare](Controller::tank_spare), a fall goes into the
    /// fade's tank, so that H plus the tanks does not change by it. Returns
    /// false, and books nothing, when the spare cannot pay the rise: the
    /// change must wait. Always true with the tanks off (nothing is booked).
    pub fn book_model_change(&mut self, energy: f64) -> bool {
        if !self.tanks_on() || energy.is_nan() || energy == 0.0 {
            return true;
        }
        if energy < 0.0 {
            self.safety.fill_fade_tank(-energy);
            return true;
        }
        if self.tank_spare() < energy {
            return false;
        }
        self.draw_tank_spare(energy);
        true
    }

    /// The kinetic energy `load`, held at the tip, has at the tip's twist
    /// J_tip q̇ (J): ½ m |v_c|² + ½ ωᵀ R I_c Rᵀ ω with v_c = v + ω × R c, at
    /// the state (`q`, `qd`) (0 with the tip on the root link). The mixture
    /// of two loads is linear in their parameters, and so is this energy:
    /// what the model's storage gains as a load ramps in. Allocation-free.
    pub fn load_kinetic_energy(&mut self, load: &hcc_model::Load, q: &[f64], qd: &[f64]) -> f64 {
        self.load_kinetic_energy_change(&hcc_model::Load::none(), load, q, qd)
    }

    /// T(`to`) − T(`from`) of [`Controller::load_kinetic_energy`], from one
    /// tip twist: the storage a load's ramp adds per unit of its progress at
    /// the state (`q`, `qd`) the next cycle's storage counts (the tip's
    /// kinematics are computed at `q`; the next step recomputes every model
    /// term). 0 while the tanks are off (nothing books it). Allocation-free.
    pub fn load_kinetic_energy_change(
        &mut self,
        from: &hcc_model::Load,
        to: &hcc_model::Load,
        q: &[f64],
        qd: &[f64],
    ) -> f64 {
        let is_none =
            |l: &hcc_model::Load| l.mass == 0.0 && l.inertia == nalgebra::Matrix3::zeros();
        if (is_none(from) && is_none(to))
            || hcc_model::load::tip_body(&self.model).is_none()
            || qd.len() != self.n
            || q.len() != self.n
        {
            return 0.0;
        }
        self.tmp_n2.copy_from_slice(q);
        hcc_model::forward_kinematics(&self.model, &mut self.data, &self.tmp_n2);
        let tip = self.model.tip_frame();
        hcc_model::frame_jacobian(&self.model, &self.data, tip, &mut self.load_jacobian);
        let twist: [f64; 6] = std::array::from_fn(|k| {
            (0..self.n)
                .map(|j| self.load_jacobian[(k, j)] * qd[j])
                .sum()
        });
        let v = nalgebra::Vector3::new(twist[0], twist[1], twist[2]);
        let w = nalgebra::Vector3::new(twist[3], twist[4], twist[5]);
        let rot = hcc_model::frame_placement(&self.model, &self.data, tip).rotation;
        let wl = rot.inverse() * w;
        let energy = |l: &hcc_model::Load| {
            let vc = v + w.cross(&(rot * l.com));
            0.5 * l.mass * vc.norm_squared() + 0.5 * wl.dot(&(l.inertia * wl))
        };
        energy(to) - energy(from)
    }

    /// Whether model changes are booked by the tanks
    /// ([`Controller::book_model_change`] does something).
    pub fn books_model_changes(&self) -> bool {
        self.tanks_on()
    }

    /// What a refill fills each level's tank to: `tank_initial` plus a share
    /// of the storage ½ q̇ᵀ M q̇ + Σ V_i (crate::energy_tank; J).
    pub(super) fn refill_level(&mut self, qd: &DVector<f64>) -> f64 {
        gemv(&mut self.tmp_n, 1.0, &self.data.m, qd, 0.0);
        let storage =
            0.5 * qd.dot(&self.tmp_n) + self.levels.iter().map(|l| l.potential).sum::<f64>();
        self.spec.safety.tank_initial + TANK_TRANSIENT_SHARE * storage.max(0.0)
    }

    /// A goal or gains changed (a command, an input): in the next cycle every
    /// tank holds at least `tank_initial` plus a share of the storage again.
    pub(super) fn refill_tanks(&mut self) {
        self.tank_refill = true;
    }

    /// Every tank empty, every spring at x_i; refilled in the next cycle.
    pub(super) fn reset_tanks(&mut self) {
        for l in self.levels.iter_mut() {
            l.tank.reset(0.0);
        }
        self.reset_command_tank();
        self.tank_refill = true;
    }
}
