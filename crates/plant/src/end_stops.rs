//! Joint end stops and velocity-limit monitoring of the simulated robot, as
//! hardware has them: beyond a URDF position limit the joint meets a stiff,
//! damped contact,
//!
//! τ_stop = min(0, −k p − d q̇) with p = q − upper > 0 (mirrored at the lower limit),
//!
//! that only pushes (never pulls the joint into the stop), and every integration
//! step that ends with a joint beyond a limit or faster than its URDF velocity
//! limit is counted. Where no joint is beyond a limit nothing is added: the
//! dynamics are bit-identical to a plant without end stops. Continuous joints (and
//! joints without a URDF limit) have none.

use hcc_model::Model;
use nalgebra::DVector;

/// Contact stiffness of an end stop, N·m/rad (N/m).
pub const END_STOP_STIFFNESS: f64 = 1e4;
/// Contact damping of an end stop, N·m·s/rad (N·s/m).
pub const END_STOP_DAMPING: f64 = 20.0;

/// The end stops of every joint and the counters of what the plant saw.
#[derive(Clone, Debug)]
pub struct EndStops {
    lower: Vec<f64>,
    upper: Vec<f64>,
    velocity_limit: Vec<f64>,
    stiffness: f64,
    damping: f64,
    enabled: bool,
    in_contact: bool,
    contacts: u64,
    contact_steps: u64,
    velocity_steps: u64,
    max_penetration: f64,
    max_speed_ratio: f64,
}

impl EndStops {
    /// The URDF limits of `model` with the default contact.
    pub fn new(model: &Model) -> EndStops {
        EndStops {
            lower: model.joints.iter().map(|j| j.lower).collect(),
            upper: model.joints.iter().map(|j| j.upper).collect(),
            velocity_limit: model.joints.iter().map(|j| j.velocity_limit).collect(),
            stiffness: END_STOP_STIFFNESS,
            damping: END_STOP_DAMPING,
            enabled: true,
            in_contact: false,
            contacts: 0,
            contact_steps: 0,
            velocity_steps: 0,
            max_penetration: 0.0,
            max_speed_ratio: 0.0,
        }
    }

    /// Adds the contact torque at (`q`, `qd`) to `tau` (nothing where no joint is
    /// beyond a limit).
    pub fn add_torque(&self, q: &DVector<f64>, qd: &DVector<f64>, tau: &mut DVector<f64>) {
        if !self.enabled {
            return;
        }
        for k in 0..q.len() {
            let (up, lo) = (q[k] - self.upper[k], self.lower[k] - q[k]);
            if up > 0.0 {
                tau[k] += (-self.stiffness * up - self.damping * qd[k]).min(0.0);
            } else if lo > 0.0 {
                tau[k] += (self.stiffness * lo - self.damping * qd[k]).max(0.0);
            }
        }
    }

    /// Counts the state at the end of a step.
    pub fn record(&mut self, q: &DVector<f64>, qd: &DVector<f64>) {
        let mut contact = false;
        let mut fast = false;
        for k in 0..q.len() {
            let p = (q[k] - self.upper[k]).max(self.lower[k] - q[k]);
            if p > 0.0 {
                contact = true;
                self.max_penetration = self.max_penetration.max(p);
            }
            let v = self.velocity_limit[k];
            if v.is_finite() {
                let ratio = qd[k].abs() / v;
                self.max_speed_ratio = self.max_speed_ratio.max(ratio);
                fast |= ratio > 1.0;
            }
        }
        self.contacts += u64::from(contact && !self.in_contact);
        self.in_contact = contact;
        self.contact_steps += u64::from(contact);
        self.velocity_steps += u64::from(fast);
    }

    /// Switches the contact off (a robot without end stops; the counters still count).
    pub fn set_enabled(&mut self, on: bool) {
        self.enabled = on;
    }

    /// Contact onsets (a joint reaching a stop after none was in contact).
    pub fn contacts(&self) -> u64 {
        self.contacts
    }
    /// Integration steps that ended with a joint beyond a position limit.
    pub fn contact_steps(&self) -> u64 {
        self.contact_steps
    }
    /// Integration steps that ended with a joint faster than its velocity limit.
    pub fn velocity_violation_steps(&self) -> u64 {
        self.velocity_steps
    }
    /// Deepest penetration beyond a position limit seen (rad or m).
    pub fn max_penetration(&self) -> f64 {
        self.max_penetration
    }
    /// Largest |q̇_k| / velocity limit seen.
    pub fn max_speed_ratio(&self) -> f64 {
        self.max_speed_ratio
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stops() -> EndStops {
        EndStops {
            lower: vec![-1.0, f64::NEG_INFINITY],
            upper: vec![1.0, f64::INFINITY],
            velocity_limit: vec![2.0, f64::INFINITY],
            stiffness: 100.0,
            damping: 10.0,
            enabled: true,
            in_contact: false,
            contacts: 0,
            contact_steps: 0,
            velocity_steps: 0,
            max_penetration: 0.0,
            max_speed_ratio: 0.0,
        }
    }

    #[test]
    fn the_stop_pushes_back_and_never_pulls() {
        let s = stops();
        let mut tau = DVector::from_vec(vec![0.5, 0.5]);
        // Inside the limits: nothing at all.
        s.add_torque(
            &DVector::from_vec(vec![0.9, 5.0]),
            &DVector::from_vec(vec![1.0, 1.0]),
            &mut tau,
        );
        assert_eq!(tau.as_slice(), &[0.5, 0.5]);
        // 0.1 beyond the upper limit, moving in: −100·0.1 − 10·1.
        s.add_torque(
            &DVector::from_vec(vec![1.1, 0.0]),
            &DVector::from_vec(vec![1.0, 0.0]),
            &mut tau,
        );
        assert!((tau[0] - (0.5 - 20.0)).abs() < 1e-12);
        // Leaving fast: the damping would pull, the stop gives 0.
        let mut tau = DVector::zeros(2);
        s.add_torque(
            &DVector::from_vec(vec![1.01, 0.0]),
            &DVector::from_vec(vec![-5.0, 0.0]),
            &mut tau,
        );
        assert_eq!(tau[0], 0.0);
        // Lower limit mirrored.
        s.add_torque(
            &DVector::from_vec(vec![-1.1, 0.0]),
            &DVector::from_vec(vec![0.0, 0.0]),
            &mut tau,
        );
        assert!((tau[0] - 10.0).abs() < 1e-12);
    }

    #[test]
    fn contacts_and_speeding_are_counted() {
        let mut s = stops();
        let z = DVector::zeros(2);
        s.record(&DVector::from_vec(vec![0.0, 0.0]), &z);
        s.record(&DVector::from_vec(vec![1.2, 0.0]), &z);
        s.record(
            &DVector::from_vec(vec![1.1, 0.0]),
            &DVector::from_vec(vec![3.0, 100.0]),
        );
        s.record(&DVector::from_vec(vec![0.0, 0.0]), &z);
        s.record(&DVector::from_vec(vec![-1.5, 0.0]), &z);
        assert_eq!(s.contacts(), 2);
        assert_eq!(s.contact_steps(), 3);
        assert_eq!(s.velocity_violation_steps(), 1);
        assert!((s.max_penetration() - 0.5).abs() < 1e-12);
        assert!((s.max_speed_ratio() - 1.5).abs() < 1e-12);
    }
}
