//! What a running controller takes between cycles, allocation-free: goals
//! x_{i,d}, their velocities ẋ_{i,d}, gains K_i, D_i (eqs. 20, 21) and their
//! check against the control rate, the stiffness scale κ, the applied torque,
//! the form of the law and the τ_μ ablation.

use super::{Controller, LevelTarget};
use crate::ControlError;
use crate::rate::GainRate;
use crate::safety::spring_saturation::saturated_potential;
use crate::spec::Form;
use nalgebra::DMatrix;

impl Controller {
    /// Switches τ_μ (eq. 22) on or off (the ablation).
    pub fn set_coriolis_cancellation(&mut self, on: bool) {
        self.spec.coriolis_cancellation = on;
    }

    /// Chooses eq. (21) or the classical projector form (eqs. 8, 9).
    pub fn set_form(&mut self, form: Form) {
        self.spec.form = form;
    }

    /// The torque the robot applies until the next command (the previous
    /// command as sent, gravity included when the controller adds it), or
    /// `None` before the first. With a torque rate limit downstream the applied
    /// torque lags the law's, and the velocity barrier (crate::safety) brakes for
    /// the faster of the two accelerations. Entries beyond n are ignored; a
    /// shorter slice or a non-finite entry is ignored. Allocation-free.
    pub fn set_applied_torque(&mut self, tau: Option<&[f64]>) {
        let n = self.applied_tau.len();
        self.have_applied = match tau {
            Some(t) if t.len() >= n && t[..n].iter().all(|x| x.is_finite()) => {
                self.applied_tau.as_mut_slice().copy_from_slice(&t[..n]);
                true
            }
            _ => false,
        };
    }

    /// The load the tip frame carries from now on (hcc-model's `set_load`:
    /// M, C, g and everything the law and the observer compute follow it).
    /// The caller checks it (`Load::check`) and ramps it in. Allocation-free.
    pub fn set_load(&mut self, load: &hcc_model::Load) {
        hcc_model::set_load(&mut self.model, load);
    }

    /// Whether the control rate carries the gains of level `i` (crate::rate):
    /// the stiffness `k` and damping `d` given, the level's own where `None`, at
    /// the configuration of the last cycle (the initial one before the first).
    /// For a gains setpoint before it is taken. Allocation-free.
    pub fn check_gain_rate(
        &mut self,
        i: usize,
        k: Option<&DMatrix<f64>>,
        d: Option<&DMatrix<f64>>,
    ) -> Result<(), GainRate> {
        let period = self.spec.safety.control_period_s;
        let Some(l) = self.levels.get_mut(i) else {
            return Ok(());
        };
        if !l.rate.set_mobility(&self.chol, &l.j) {
            return Ok(());
        }
        let k = k.unwrap_or(&l.stiffness);
        let d = d.unwrap_or(&l.damping);
        crate::rate::check_level(&mut l.rate, i, k, d, period)
    }

    /// Scales every level's spring by κ in (0, 1]: V_i becomes κ V_i and its
    /// gradient κ ∂V_i/∂x_i (after the spring saturation), as if every K_i
    /// were κ K_i; the damping D_i is unchanged. With κ = 1 the law is the
    /// paper's, bit for bit. A contact reaction's softening (hcc-cycle) ramps κ
    /// smoothly; a time-varying κ adds the power κ̇ Σ V_i to the storage
    /// Σ S_i (Sec. IV), which is ≤ 0 while κ falls and at most (1 − κ_min)
    /// Σ V_i over a whole rise. A value outside (0, 1] or not finite is
    /// ignored (κ kept). Allocation-free.
    pub fn set_stiffness_scale(&mut self, kappa: f64) {
        if kappa > 0.0 && kappa <= 1.0 {
            self.stiffness_scale = kappa;
        }
    }

    /// A step of a contact reaction's κ ([`Controller::set_stiffness_scale`];
    /// hcc-cycle's reaction) booked through the energy tanks: the springs'
    /// storage changes by (κ′/κ − 1) Σ_i β_i V_i at the last cycle's stretch
    /// (β_i the fades, 1 for level 1), paid from the tanks' spare when κ
    /// rises, into the fade's tank when it falls
    /// ([`Controller::book_model_change`]), so that H with the tanks does not
    /// change by it. `false`, and κ kept, when the spare cannot pay a rise:
    /// the restore must wait. A value outside (0, 1] is ignored (`true`).
    /// Allocation-free.
    pub fn ramp_stiffness_scale(&mut self, kappa: f64) -> bool {
        if !(kappa > 0.0 && kappa <= 1.0) || kappa == self.stiffness_scale {
            return true;
        }
        let stored = self.faded_potential();
        if !self.book_model_change((kappa / self.stiffness_scale - 1.0) * stored) {
            return false;
        }
        self.stiffness_scale = kappa;
        true
    }

    /// The share s ∈ [0, 1] of the law's torque the robot receives from the
    /// next cycle on: 1 − h while a contact reaction `hold` blends the
    /// torque towards its own (hcc-cycle). The energy tanks (crate::energy_tank)
    /// book their levels' power scaled by it, as they do a fade: a level's
    /// tank neither fills from nor pays for a torque that is not applied, and
    /// H counts the springs' storage with it. Set so, the change of that
    /// storage is not booked; [`Controller::ramp_law_share`] books it. A
    /// value outside [0, 1] or not finite is ignored. Allocation-free.
    pub fn set_law_share(&mut self, share: f64) {
        if (0.0..=1.0).contains(&share) {
            self.law_share = share;
        }
    }

    /// One step of a contact hold's blend (hcc-cycle's `reaction`): the
    /// law's share s of the torque, as [`Controller::set_law_share`] takes it,
    /// with the change of the storage it makes booked through the energy
    /// tanks — the springs and the joint-limit guard act with s, so H counts
    /// s (Σ β_i V_i + the guard's potential), and a step to s′ changes it by
    /// (s′ − s) times that at the last cycle's state: a ramp into the hold
    /// (s falls) fills the fade's tank, the release (s rises) is paid from
    /// the tanks' spare ([`Controller::book_model_change`]). False, and s
    /// unchanged, when the spare cannot pay: the release must wait. A value
    /// outside [0, 1] or not finite is ignored (true). Allocation-free.
    pub fn ramp_law_share(&mut self, share: f64) -> bool {
        if !(0.0..=1.0).contains(&share) || share == self.law_share {
            return true;
        }
        let stored = self.faded_potential() + self.out.safety.guard_potential;
        if !self.book_model_change((share - self.law_share) * stored) {
            return false;
        }
        self.law_share = share;
        true
    }

    /// Σ β_i V_i at the last cycle's state (β_1 = 1; V_i with κ).
    fn faded_potential(&self) -> f64 {
        self.levels
            .iter()
            .enumerate()
            .map(|(i, l)| if i == 0 { 1.0 } else { self.out.fade[i] } * l.potential)
            .sum()
    }

    /// κ ([`Controller::set_stiffness_scale`]).
    pub fn stiffness_scale(&self) -> f64 {
        self.stiffness_scale
    }

    /// Sets the virtual equilibrium x_{i,d} of level `i` without allocating.
    pub fn set_goal(&mut self, i: usize, goal: &[f64]) -> Result<(), ControlError> {
        let Some(l) = self.levels.get_mut(i) else {
            return Err(ControlError::BadInput("no such level"));
        };
        if goal.len() != l.goal.len() || goal.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::BadInput(
                "goal has the wrong length or a non-finite value",
            ));
        }
        if l.goal.as_slice() != goal {
            l.goal.as_mut_slice().copy_from_slice(goal);
            l.pot.set_goal(&self.spec.levels[i].tasks, goal, self.n);
            self.safety.release_conflict(i);
            self.safety.refill_passivity_budget();
            self.refill_tanks();
        }
        Ok(())
    }

    /// Sets the stiffness K_i and/or the damping D_i of level `i` (m_i × m_i)
    /// of the spring–damper F_i (eqs. 20, 21) without allocating; `None`
    /// keeps one. They must be symmetric positive definite for the stability
    /// of Sec. IV: a wrong size, a non-finite or asymmetric matrix, or a
    /// diagonal entry ≤ 0 is an error and changes nothing; full positive
    /// definiteness is the caller's check (`hcc_msgs::Setpoint::validate`).
    /// A command: a change refills the energy tanks and the passivity budget
    /// (the energy a command may put in). Gains equal to those in force change
    /// nothing (no tank or budget is refilled: only a change is a command).
    /// A transition's steps go through [`Controller::ramp_gains`] instead.
    pub fn set_gains(
        &mut self,
        i: usize,
        stiffness: Option<&DMatrix<f64>>,
        damping: Option<&DMatrix<f64>>,
    ) -> Result<(), ControlError> {
        if self.gains_change(i, stiffness, damping)? {
            self.apply_gains(i, stiffness, damping);
            self.safety.refill_passivity_budget();
            self.refill_tanks();
        }
        Ok(())
    }

    /// A client's command was taken (a setpoint: hcc-cycle's setpoints): in
    /// the next cycle the energy tanks and the passivity budget are refilled,
    /// the energy a command may put in; its transition's steps are then
    /// booked against them ([`Controller::ramp_gains`]). While a transition
    /// runs ([`Controller::set_commands_active`]) the tanks are not refilled:
    /// they live on its command tank, to which the new command's grant is
    /// added ([`Controller::grant_goal_step`]) — so a stream of setpoints puts
    /// in the first one's refill and each one's grant, not a refill per
    /// message.
    pub fn command_taken(&mut self) {
        self.safety.refill_passivity_budget();
        if !self.commands_hold_tanks() {
            self.refill_tanks();
        }
    }

    /// One step of a gains transition (hcc-cycle's setpoints): the gains as
    /// [`Controller::set_gains`] checks them, but nothing is refilled — the
    /// change of the storage a new stiffness makes at the spring's present
    /// stretch ([`Controller::stiffness_change_energy`]) is booked through the
    /// energy tanks ([`Controller::book_model_change`]): a stiffening is paid
    /// from their spare, a softening fills the fade's tank, so that H plus
    /// the tanks does not change by it. `Ok(false)`, and nothing changed, when
    /// the spare cannot pay it: the transition must wait. A change of the
    /// damping alone stores nothing and is always taken — but with the
    /// spring saturation, whose radius the damping sets, where it moves the
    /// saturated spring's storage ([`Controller::gains_change_energy`]).
    /// Allocation-free.
    pub fn ramp_gains(
        &mut self,
        i: usize,
        stiffness: Option<&DMatrix<f64>>,
        damping: Option<&DMatrix<f64>>,
    ) -> Result<bool, ControlError> {
        if !self.gains_change(i, stiffness, damping)? {
            return Ok(true);
        }
        let energy = self.gains_change_energy(i, stiffness, damping);
        if !self.book_model_change(energy) {
            return Ok(false);
        }
        self.apply_gains(i, stiffness, damping);
        Ok(true)
    }

    /// The change of the storage H (J) that the stiffness `k` in place of
    /// level `i`'s makes at the spring coordinates e of the last cycle:
    /// β_i κ ½ eᵀ (k − K_i) e (V_i is linear in K_i; β_i the level's fade, 1
    /// for level 1, κ the stiffness scale); with `spring_saturation` the
    /// saturated spring's change ([`Controller::gains_change_energy`]). 0 for
    /// an unknown level or a matrix of another size. Allocation-free.
    pub fn stiffness_change_energy(&self, i: usize, k: &DMatrix<f64>) -> f64 {
        self.gains_change_energy(i, Some(k), None)
    }

    /// The change of the storage H (J) that the gains `stiffness`, `damping`
    /// (each `None`: level `i`'s own) make at the spring coordinates e of the
    /// last cycle: β_i κ (V_sat(½ eᵀ K' e, r_0') − V_sat(½ eᵀ K_i e, r_0,i)),
    /// r_0 the spring saturation's radius of the gains (∞ without it: then
    /// β_i κ ½ eᵀ (K' − K_i) e, and a damping changes nothing). 0 for an
    /// unknown level or a matrix of another size. Allocation-free.
    pub fn gains_change_energy(
        &self,
        i: usize,
        stiffness: Option<&DMatrix<f64>>,
        damping: Option<&DMatrix<f64>>,
    ) -> f64 {
        let Some(l) = self.levels.get(i) else {
            return 0.0;
        };
        let shape = l.stiffness.shape();
        if stiffness.is_some_and(|k| k.shape() != shape)
            || damping.is_some_and(|d| d.shape() != shape)
        {
            return 0.0;
        }
        let (k, d) = (
            stiffness.unwrap_or(&l.stiffness),
            damping.unwrap_or(&l.damping),
        );
        let radius = self.safety.spring_radius_for(i, k, d);
        let new = saturated_potential(l.pot.spring_energy(k), radius);
        let old = saturated_potential(
            l.pot.spring_energy(&l.stiffness),
            self.safety.spring_radius(i),
        );
        let fade = if i == 0 { 1.0 } else { self.out.fade[i] };
        fade * self.stiffness_scale * (new - old)
    }

    /// Whether `stiffness`, `damping` differ from level `i`'s gains, after
    /// checking them ([`Controller::set_gains`]'s errors).
    fn gains_change(
        &self,
        i: usize,
        stiffness: Option<&DMatrix<f64>>,
        damping: Option<&DMatrix<f64>>,
    ) -> Result<bool, ControlError> {
        let Some(l) = self.levels.get(i) else {
            return Err(ControlError::BadInput("no such level"));
        };
        for g in [stiffness, damping].into_iter().flatten() {
            let bad = g.shape() != (l.m, l.m)
                || g.iter().any(|x| !x.is_finite())
                || (0..l.m).any(|a| g[(a, a)] <= 0.0)
                || (0..l.m).any(|a| (0..a).any(|b| g[(a, b)] != g[(b, a)]));
            if bad {
                return Err(ControlError::BadInput(
                    "gain has the wrong size, a non-finite value, is asymmetric or not positive",
                ));
            }
        }
        // The same gains again (a transition that moves only the goal hands
        // them on every cycle): nothing is commanded, nothing refilled.
        Ok(
            stiffness.is_some_and(|k| *k != l.stiffness)
                || damping.is_some_and(|d| *d != l.damping),
        )
    }

    /// Puts checked gains in force (the spring saturation's radius follows).
    fn apply_gains(
        &mut self,
        i: usize,
        stiffness: Option<&DMatrix<f64>>,
        damping: Option<&DMatrix<f64>>,
    ) {
        let l = &mut self.levels[i];
        if let Some(k) = stiffness {
            l.stiffness.copy_from(k);
        }
        if let Some(d) = damping {
            l.damping.copy_from(d);
        }
        self.safety.set_spring_radius(i, &l.stiffness, &l.damping);
    }

    /// Sets the velocity ẋ_{i,d} of level `i`'s equilibrium (m_i values, the
    /// task's velocity: m/s, world-frame angular velocity in rad/s, joint
    /// rad/s) without allocating. The damping then acts on ẋ_i − ẋ_{i,d}, so
    /// a moving goal is tracked without lag; all zeros restore the paper's
    /// D_i ẋ_i exactly.
    pub fn set_goal_velocity(&mut self, i: usize, velocity: &[f64]) -> Result<(), ControlError> {
        let Some(l) = self.levels.get_mut(i) else {
            return Err(ControlError::BadInput("no such level"));
        };
        if velocity.len() != l.m || velocity.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::BadInput(
                "goal velocity has the wrong length or a non-finite value",
            ));
        }
        l.goal_velocity.as_mut_slice().copy_from_slice(velocity);
        l.goal_moving = velocity.iter().any(|&x| x != 0.0);
        Ok(())
    }

    /// Makes level `i` track (docs/tracking.md): `Some(ẍ_{i,d})` (m_i values,
    /// the derivative of [`Controller::set_goal_velocity`]'s ẋ_{i,d}: m/s²,
    /// world-frame angular acceleration in rad/s², joint rad/s²) gives the
    /// level the feed-forward J̄_iᵀ (Λ_i v̇_{i,d} + μ_ii v_{i,d}) from the next
    /// cycle on, its desired local velocity formed level by level from every
    /// level's ẋ_{j,d} above it; `None` ends it (the goal is then pulled along
    /// as before). Only in the paper's form ([`Form::Extended`]); while no
    /// tracking level's goal moves, nothing is added (the regulation law bit
    /// for bit). Allocation-free.
    pub fn set_goal_acceleration(
        &mut self,
        i: usize,
        acceleration: Option<&[f64]>,
    ) -> Result<(), ControlError> {
        let Some(l) = self.levels.get_mut(i) else {
            return Err(ControlError::BadInput("no such level"));
        };
        match acceleration {
            None => {
                l.track.on = false;
                l.track.xdd.fill(0.0);
            }
            Some(a) => {
                if a.len() != l.m || a.iter().any(|x| !x.is_finite()) {
                    return Err(ControlError::BadInput(
                        "goal acceleration has the wrong length or a non-finite value",
                    ));
                }
                l.track.xdd.as_mut_slice().copy_from_slice(a);
                l.track.on = true;
            }
        }
        Ok(())
    }

    /// Level `i`'s current goal x_{i,d}, velocity ẋ_{i,d}, K_i and D_i.
    pub fn level_target(&self, i: usize) -> Option<LevelTarget<'_>> {
        self.levels.get(i).map(|l| LevelTarget {
            goal: l.goal.as_slice(),
            goal_velocity: l.goal_velocity.as_slice(),
            stiffness: &l.stiffness,
            damping: &l.damping,
        })
    }
}
