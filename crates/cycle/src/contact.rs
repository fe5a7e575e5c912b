//! The contact watch of the cycle: the generalized-momentum observer and the
//! contact detection (`hcc_control::contact`) run on every state the law
//! used, with the torque the robot applied since the previous one.
//!
//! **The torque applied.** The previous command as sent (after the
//! saturation and the torque filter; g included when the controller adds it,
//! else the driver adds g itself and g drops out of the balance), held over
//! the period by the driver. It is the torque that acted only if that command
//! answered the previous state, the state follows it directly and the driver
//! reports `Ok` (no fallback of its own); otherwise the observer re-anchors:
//! r is held and the balance restarts at this state (a missed state, a late
//! command, a fallback cost one estimate, never a false torque).
//!
//! **Resets** (r = 0, contact cleared): a new peer, and a fault — a state
//! answered with the safe command (rejected, or a numerical failure of the
//! law).
//!
//! The period of the balance is the nominal control period (deterministic:
//! a lockstep run over IPC and the in-process run estimate the same r).

use hcc_control::{ContactChange, ContactDetector, MomentumObserver, ObserverInput, observe};
use hcc_model::Data;
use hcc_msgs::{DriverStatus, JointState, TorqueCommand};
use hcc_spec::contact::Contact;

use crate::counters::CoreCounters;

/// The observer, the detector and the state the last update saw.
pub(crate) struct ContactWatch {
    observer: MomentumObserver,
    detector: ContactDetector,
    /// Sequence number of the state of the last update (primed or estimated).
    last_seq: Option<u64>,
    /// Whether a contact began at the last update.
    began: bool,
    /// A load is being announced (or was, and the residual it left has not
    /// yet fallen below the release thresholds): no contact begins.
    quiet: bool,
}

impl ContactWatch {
    /// The watch of `[contact]` (sizes checked by the cycle's settings).
    pub(crate) fn new(contact: &Contact) -> ContactWatch {
        ContactWatch {
            observer: MomentumObserver::new(contact.observer_gain.as_slice()),
            detector: ContactDetector::new(contact.threshold.as_slice(), contact.release),
            last_seq: None,
            began: false,
            quiet: false,
        }
    }

    /// Whether a contact began at the last update.
    pub(crate) fn began(&self) -> bool {
        self.began
    }

    /// r, the estimate of τ_ext.
    pub(crate) fn residual(&self) -> &[f64] {
        self.observer.residual()
    }

    /// Whether a contact is flagged.
    pub(crate) fn in_contact(&self) -> bool {
        self.detector.in_contact()
    }

    /// A new peer or a fault: r = 0, contact cleared, the next update primes.
    pub(crate) fn reset(&mut self) {
        self.observer.reset();
        self.detector.reset();
        self.last_seq = None;
        self.began = false;
    }

    /// The update at `state`, whose model terms the law left in `terms`;
    /// `previous` is the last command sent (not yet overwritten by this
    /// state's). Counts contacts and cycles in contact. Allocation-free.
    pub(crate) fn update(
        &mut self,
        state: &JointState,
        terms: &Data,
        previous: &TorqueCommand,
        gravity_in_command: Option<&[f64]>,
        (period_s, announcing): (f64, bool),
        counters: &mut CoreCounters,
    ) {
        let seq = state.header.seq;
        let applied = self.last_seq.is_some_and(|last| {
            previous.state_seq == last
                && seq == last.wrapping_add(1)
                && state.status == DriverStatus::Ok as u32
        });
        if !applied {
            self.observer.reanchor();
        }
        let n = state.n();
        let input = ObserverInput {
            qd: state.qd(),
            tau_applied: &previous.tau[..n],
            gravity_in_command,
            dt: period_s,
        };
        observe(&mut self.observer, terms, &input);
        self.last_seq = Some(seq);
        let r = self.observer.residual();
        self.quiet |= announcing;
        if self.quiet && !announcing && self.detector.below_release(r) {
            self.quiet = false;
        }
        self.began = if self.quiet {
            // An announced load: a contact flagged before may end, none begins.
            if self.detector.in_contact() {
                self.detector.update(r);
            }
            false
        } else {
            self.detector.update(r) == ContactChange::Began
        };
        if self.began {
            counters.contact_events += 1;
        }
        if self.detector.in_contact() {
            counters.contact_cycles += 1;
        }
    }
}
