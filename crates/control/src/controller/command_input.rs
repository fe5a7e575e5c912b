//! What the commands put into the storage H in a cycle
//! ([`StepOutput::command_input`](super::StepOutput::command_input)): a moving
//! goal works on its level's spring and damper, the tracking feed-forward on
//! the arm, and a refill puts energy into the tanks. With a fixed goal and no
//! feed-forward, nothing.
//!
//! Level i's storage β_i V_i(x_i − x_{i,d}) and its damper D_i (ẋ_i − ẋ_{i,d})
//! change with x_{i,d}: along the motion the storage H changes by
//! −ẋ_{i,d}ᵀ F_i on top of what the law dissipates (level 1: dH/dt = −ẋ_{1,d}ᵀ
//! F_1 − ẽᵀ D_1 ẽ, ẽ = ẋ_1 − ẋ_{1,d}); the goal's power is positive while the
//! goal leads the arm. In full, with r_i the rate a transition moves the goal
//! at (`Controller::ramp_goal`; its work is booked with it also where the
//! damper is not told it, `relative_damping = false`) and u_i the velocity the
//! damper acts relative to: −β_i (r_iᵀ ∂V_i/∂x_iᵀ + u_iᵀ (F_i − σ_i ∂V_i/∂x_iᵀ)).
//! The spring's share is V_i's whole gradient (H counts V_i), also where the
//! velocity governor scales the spring in F_i by σ_i (without it, goal 152 of
//! the 500-goal sweep rose by 3.9e-3 J per cycle beyond what was booked).
//! Under the tracking feed-forward the levels above are meant to drag level
//! i ≥ 2 by w_d = J_i q̇_d^{(i−1)}; its tank pays only the drag beyond it, so
//! β_i w_dᵀ F_i is an input as well (without it, a path followed with the
//! feed-forward raised H by 1.1 mJ per cycle through the posture's spring).

use super::Controller;
use nalgebra::DVector;

impl Controller {
    /// The moving goals' and the feed-forward's power into H over the coming
    /// period (F_i as applied, after the tanks). Allocation-free.
    pub(super) fn command_power(&mut self, qd: &DVector<f64>) {
        let (mut goal, mut followed) = (0.0, 0.0);
        for (i, l) in self.levels.iter().enumerate() {
            if i > 0 && self.track.active && l.track.on {
                // Tracking: the levels above are meant to drag level i by
                // w_d = J_i q̇_d^{(i−1)}; its tank pays only the drag beyond
                // that (tanks.rs), so this share of w_iᵀ F_i is the
                // commands' input.
                let drag = self.out.fade[i] * self.law_share * l.track.w_d.dot(&l.f);
                goal += drag;
                if self.levels[..i].iter().any(|a| a.followed) {
                    followed += drag;
                }
            }
            let moving =
                (self.command.active || l.followed) && l.goal_rate.iter().any(|&x| x != 0.0);
            if !l.goal_moving && !moving {
                continue;
            }
            // The spring's share at the goal's rate, the damper's against
            // the velocity it damps relative to (module docs).
            let sigma = self.out.safety.spring_scale[i];
            let rate = if moving {
                &l.goal_rate
            } else {
                &l.goal_velocity
            };
            let spring = rate.dot(&l.grad);
            let damper = l.goal_velocity.dot(&l.f) - sigma * l.goal_velocity.dot(&l.grad);
            let power = -self.out.fade[i] * self.law_share * (spring + damper);
            goal += power;
            if l.followed {
                followed += power;
            }
        }
        self.command.followed_power = followed;
        let input = &mut self.out.command_input;
        input.goal_power = goal;
        input.feed_forward_power = if self.track.active {
            qd.dot(&self.out.tau_feed_forward)
        } else {
            0.0
        };
    }
}
