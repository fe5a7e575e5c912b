//! The command tank E_c: what a client's goal transition may put into the
//! arm, booked like every other element of the storage H (issue "passive by
//! construction"; docs/limits-and-singularities.md, "Energy tanks").
//!
//! A goal setpoint is an input: when it is taken, E_c is granted the energy a
//! step to its target would store at the arm's present state,
//! S = β_i κ max(0, V_i(x; x_{i,d}^target) − V_i(x; x_{i,d})) (β_i the level's
//! fade times the law's share, κ the stiffness scale), and the share of it a
//! refill would give each level's tank: (1 + (r − 1) · `TANK_TRANSIENT_SHARE`) S
//! — a transition puts in no more than the step it smooths and the refill
//! after it would. While a transition runs:
//!
//! * the moving goals' and the tracking feed-forward's work
//!   T (−Σ_i β_i ẋ_{i,d}ᵀ F_i + q̇ᵀ τ_ff) (`command_input.rs`) is paid from E_c (a goal that moves
//!   towards the arm gives its spring's energy back to it); what E_c cannot
//!   pay is drawn from the tanks' spare ([`Controller::tank_spare`]) at the
//!   next sample, and what that cannot is counted as unpaid;
//! * the levels' tanks are topped up from E_c (to `tank_initial` plus half
//!   the storage, as a command's refill), and their content above `tank_max`
//!   does not decay: what they hold was granted for the transition;
//! * a goal step is taken only while E_c and the spare hold the last
//!   period's work ([`Controller::ramp_goal`]); otherwise the caller holds
//!   the goal's clock.
//!
//! E_c is counted in H (at the cycle's sample, like the levels' tanks), so
//! that H rises only by the grant when a setpoint is taken; once no
//! transition runs, what is left of E_c is dropped (dissipated).

use super::Controller;
use super::level::Level;
use crate::ControlError;
use crate::energy_tank::TANK_TRANSIENT_SHARE;
use nalgebra::DVector;

/// E_c and what it books (module docs).
#[derive(Clone, Debug, Default)]
pub(super) struct CommandTank {
    /// E_c (J).
    pub(super) energy: f64,
    /// E_c at this cycle's sample: after the grant and the levels' top-ups,
    /// before the cycle books the goals' work of the coming period.
    pub(super) at_sample: f64,
    /// Granted since the last sample; put into E_c at the next (J).
    pub(super) pending: f64,
    /// A transition runs ([`Controller::set_commands_active`]).
    pub(super) active: bool,
    /// The goals' work neither E_c nor the spare could pay (J, total).
    pub(super) unpaid: f64,
    /// The work booked in the last cycle (J).
    pub(super) last_work: f64,
    /// The paths' share of this cycle's goal power (W; `Controller::follow_goal`).
    pub(super) followed_power: f64,
}

impl Controller {
    /// A goal setpoint for level `i` with the target `target` (the values
    /// [`Controller::set_goal`] takes) was taken: grants the command tank the
    /// energy the step to it would store at the last cycle's state (module
    /// docs), put into it at the next cycle's sample; returns it (J). 0 with
    /// the energy tanks off. Allocation-free.
    pub fn grant_goal_step(&mut self, i: usize, target: &[f64]) -> Result<f64, ControlError> {
        let Some(l) = self.levels.get_mut(i) else {
            return Err(ControlError::BadInput("no such level"));
        };
        if target.len() != l.goal.len() || target.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::BadInput(
                "goal has the wrong length or a non-finite value",
            ));
        }
        if !self.tanks_on() {
            return Ok(0.0);
        }
        let l = &mut self.levels[i];
        let tasks = &self.spec.levels[i].tasks;
        l.goal_target.as_mut_slice().copy_from_slice(target);
        l.pot_target.set_goal(tasks, target, self.n);
        let v_target = crate::task::potential(
            &self.model,
            &self.data,
            tasks,
            &mut self.frames,
            &self.q,
            &l.stiffness,
            &l.goal_target,
            None,
            &mut l.pot_target,
            &mut l.err_target,
            &mut l.grad_target,
        );
        let v_now = l.pot.spring_energy(&l.stiffness);
        let fade = if i == 0 { 1.0 } else { self.out.fade[i] };
        let share = fade * self.law_share * self.stiffness_scale;
        // The step's energy, and the share of it a refill gives each level's
        // tank (the storage it makes: `TANK_TRANSIENT_SHARE`).
        let tanks = TANK_TRANSIENT_SHARE * (self.levels.len() - 1) as f64;
        let grant = (1.0 + tanks) * share * (v_target - v_now).max(0.0);
        if !grant.is_finite() {
            return Ok(0.0);
        }
        self.command.pending += grant;
        Ok(grant)
    }

    /// One step of a goal transition (hcc-cycle's setpoints): the goal as
    /// [`Controller::set_goal`] checks it and `rate`, the transition's ẋ_{i,d}
    /// (m_i values) its work is booked with, but nothing is refilled — its
    /// work is paid from the command tank (module docs). `Ok(false)`, and
    /// nothing changed, while the command tank (its pending grant included)
    /// and the tanks' spare together hold less than the last period's work:
    /// the transition must wait. With the energy tanks off,
    /// [`Controller::set_goal`]. Allocation-free.
    pub fn ramp_goal(
        &mut self,
        i: usize,
        goal: &[f64],
        rate: &[f64],
    ) -> Result<bool, ControlError> {
        if !self.tanks_on() {
            return self.set_goal(i, goal).map(|()| true);
        }
        let l = moving_goal_level(&mut self.levels, i, goal, rate)?;
        l.goal_rate.fill(0.0);
        if l.goal.as_slice() == goal {
            return Ok(true);
        }
        // A grant not yet at its sample counts: it is there when the step is
        // paid (the sample after the period it starts). The step is taken
        // when they hold what the last period's work was.
        let funds = self.command.energy + self.command.pending + self.tank_spare();
        if funds <= 0.0 || funds < self.command.last_work {
            return Ok(false);
        }
        let l = &mut self.levels[i];
        l.goal.as_mut_slice().copy_from_slice(goal);
        l.goal_rate.as_mut_slice().copy_from_slice(rate);
        l.pot.set_goal(&self.spec.levels[i].tasks, goal, self.n);
        self.safety.release_conflict(i);
        Ok(true)
    }

    /// A path's sample for level `i` (hcc-cycle's paths, every cycle it
    /// drives the level): the goal as [`Controller::set_goal`] checks it and
    /// `rate`, the path's ẋ_{i,d} (m_i values), which its work is booked
    /// with. Not a command: the tanks are not refilled (the path's message
    /// was a command when it was taken: [`Controller::command_taken`]); the
    /// work of the coming period, −β_i (rᵀ ∂V_i/∂x_iᵀ + u_iᵀ (F_i − σ_i ∂V_i/∂x_iᵀ)),
    /// is an input, reported in `command_input.goal_power` — and while a
    /// transition runs, granted to the command tank as it is paid, so that a
    /// path never holds a transition nor is held. The passivity budget is
    /// refilled as by a goal change (the damping must not brake a commanded
    /// motion). With the energy tanks off, [`Controller::set_goal`].
    /// Allocation-free.
    pub fn follow_goal(
        &mut self,
        i: usize,
        goal: &[f64],
        rate: &[f64],
    ) -> Result<(), ControlError> {
        if !self.tanks_on() {
            return self.set_goal(i, goal);
        }
        let l = moving_goal_level(&mut self.levels, i, goal, rate)?;
        l.goal_rate.as_mut_slice().copy_from_slice(rate);
        l.followed = true;
        if l.goal.as_slice() != goal {
            l.goal.as_mut_slice().copy_from_slice(goal);
            l.pot.set_goal(&self.spec.levels[i].tasks, goal, self.n);
            self.safety.release_conflict(i);
            self.safety.refill_passivity_budget();
        }
        Ok(())
    }

    /// Whether a transition runs (hcc-cycle's setpoints, every cycle). When
    /// none runs any more, what is left of the command tank is dropped.
    pub fn set_commands_active(&mut self, active: bool) {
        if !active {
            self.command.energy = 0.0;
            self.command.last_work = 0.0;
            for l in &mut self.levels {
                l.goal_rate.fill(0.0);
            }
        }
        self.command.active = active;
    }

    /// The command tank E_c at the last sample (J) and the goals' work it
    /// and the spare could not pay since the start (J).
    pub fn command_tank(&self) -> (f64, f64) {
        (self.command.at_sample, self.command.unpaid)
    }

    /// At the cycle's sample (before the levels' tanks plan it): the grant
    /// goes in, a debt of the last period's work is settled from the spare
    /// (what it cannot pay is counted as unpaid), and while a transition runs
    /// the levels' tanks are topped up from E_c to `tank_initial` plus half
    /// the storage.
    pub(super) fn command_tank_sample(&mut self, qd: &DVector<f64>) {
        let pending = self.command.pending;
        self.command.energy += pending;
        self.out.command_input.granted = pending;
        self.command.pending = 0.0;
        if self.command.energy < 0.0 {
            let drawn = self.draw_tank_spare(-self.command.energy);
            self.command.energy += drawn;
            if self.command.energy < 0.0 {
                self.command.unpaid -= self.command.energy;
                self.command.energy = 0.0;
            }
        }
        if self.command.active && self.command.energy > 0.0 {
            let target = self.refill_level(qd);
            for l in self.levels.iter_mut().skip(1) {
                let take = (target - l.tank.energy).max(0.0).min(self.command.energy);
                l.tank.energy += take;
                self.command.energy -= take;
            }
        }
        self.command.at_sample = self.command.energy;
        self.out.command_input.tank = self.command.at_sample;
    }

    /// Whether the levels' tanks keep what is above `tank_max` (a transition
    /// runs: its grant is for the transition).
    pub(super) fn commands_hold_tanks(&self) -> bool {
        self.command.active
    }

    /// After the level torques: the goals' and the feed-forward's work over
    /// the coming period is paid from E_c; what E_c does not hold is a debt
    /// the next sample settles from the spare ([`Controller::command_tank_sample`]),
    /// so that every payment shows in H at the sample after the period it
    /// pays for, whoever pays it.
    pub(super) fn book_command_work(&mut self) {
        let input = self.out.command_input;
        let followed = self.spec.safety.control_period_s * self.command.followed_power;
        // A path's rate is its sample's: booked once (`follow_goal`).
        for l in self.levels.iter_mut().filter(|l| l.followed) {
            l.followed = false;
            l.goal_rate.fill(0.0);
        }
        if !self.tanks_on() || !self.command.active {
            self.out.command_input.paid = false;
            return;
        }
        self.out.command_input.paid = true;
        let work =
            self.spec.safety.control_period_s * (input.goal_power + input.feed_forward_power);
        if work.is_finite() {
            self.command.energy -= work;
            self.command.last_work = work - followed;
            // The paths' share is an input: granted as it is paid.
            if followed.is_finite() {
                self.command.pending += followed;
            }
        }
    }

    /// The command tank empty (a reset).
    pub(super) fn reset_command_tank(&mut self) {
        self.command = CommandTank::default();
    }
}

/// Level `i` of `levels` for a goal that moves at `rate`
/// ([`Controller::ramp_goal`], [`Controller::follow_goal`]): both of the
/// level's dimension and finite.
fn moving_goal_level<'a>(
    levels: &'a mut [Level],
    i: usize,
    goal: &[f64],
    rate: &[f64],
) -> Result<&'a mut Level, ControlError> {
    let Some(l) = levels.get_mut(i) else {
        return Err(ControlError::BadInput("no such level"));
    };
    let bad = |v: &[f64]| v.len() != l.goal.len() || v.iter().any(|x| !x.is_finite());
    if bad(goal) || bad(rate) {
        return Err(ControlError::BadInput(
            "goal or its rate has the wrong length or a non-finite value",
        ));
    }
    Ok(l)
}
