//! What the robot reported when a motion ended abnormally, with the robot's
//! own error names (libfranka's, e.g. `cartesian_reflex`,
//! `joint_velocity_violation`, `communication_constraints_violation`,
//! `controller_torque_discontinuity`), and the counts of each over a run.

use std::collections::BTreeMap;

use franka::{FrankaError, MoveStatus};

/// The kind of an abnormal end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// The robot aborted the motion (a reflex, a limit, an input error):
    /// recoverable with `automatic_error_recovery`.
    Aborted,
    /// The connection to the robot failed (a network error, a protocol
    /// error): the driver ends.
    Connection,
    /// Anything else franka-rs refused (a realtime requirement, an invalid
    /// operation): the driver ends.
    Other,
}

/// One abnormal end of a motion.
#[derive(Debug, Clone)]
pub struct Fault {
    pub kind: FaultKind,
    /// The robot's error flags at the end (`last_motion_errors`), by name.
    pub errors: Vec<&'static str>,
    /// The terminal status of the motion, when the robot sent one.
    pub move_status: Option<MoveStatus>,
    /// franka-rs's message (libfranka's wording).
    pub message: String,
}

impl Fault {
    /// The fault of a franka-rs error.
    pub fn from_error(e: &FrankaError) -> Fault {
        let (kind, errors, move_status) = match e {
            FrankaError::Control(c) => (
                FaultKind::Aborted,
                c.last_motion_errors.names(),
                c.move_status,
            ),
            FrankaError::Network(_) | FrankaError::Protocol(_) => {
                (FaultKind::Connection, Vec::new(), None)
            }
            _ => (FaultKind::Other, Vec::new(), None),
        };
        Fault {
            kind,
            errors,
            move_status,
            message: e.to_string(),
        }
    }

    /// The error names joined with `+` (`"-"` when the robot named none).
    pub fn names(&self) -> String {
        if self.errors.is_empty() {
            "-".into()
        } else {
            self.errors.join("+")
        }
    }

    /// The log line: the robot's error names first, then its message.
    pub fn line(&self) -> String {
        let status = self
            .move_status
            .map_or(String::new(), |s| format!(", motion status {s:?}"));
        format!(
            "robot error {}{status}: {}",
            self.names(),
            self.message.trim()
        )
    }
}

/// How often each robot error ended a motion in this run.
#[derive(Debug, Clone, Default)]
pub struct FaultCounts {
    by_name: BTreeMap<&'static str, u64>,
    aborted_motions: u64,
}

impl FaultCounts {
    /// Counts `fault` (each of its error names once).
    pub fn add(&mut self, fault: &Fault) {
        if fault.kind == FaultKind::Aborted {
            self.aborted_motions += 1;
        }
        for name in &fault.errors {
            *self.by_name.entry(name).or_default() += 1;
        }
    }

    /// Motions the robot aborted.
    pub fn aborted_motions(&self) -> u64 {
        self.aborted_motions
    }

    /// (error name, count), by name.
    pub fn entries(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        self.by_name.iter().map(|(k, v)| (*k, *v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use franka::{ControlException, Errors};

    fn reflex(names: &[&str]) -> FrankaError {
        let mut errors = Errors::default();
        for n in names {
            errors.0[Errors::index_of(n).unwrap()] = true;
        }
        FrankaError::Control(ControlException {
            message: "libfranka: Move command aborted: motion aborted by reflex!".into(),
            move_status: Some(MoveStatus::ReflexAborted),
            last_motion_errors: errors,
            log: Vec::new(),
        })
    }

    #[test]
    fn a_reflex_is_named_with_the_robot_s_error_names() {
        let f = Fault::from_error(&reflex(&["joint_velocity_violation", "cartesian_reflex"]));
        assert_eq!(f.kind, FaultKind::Aborted);
        assert_eq!(f.names(), "joint_velocity_violation+cartesian_reflex");
        let line = f.line();
        assert!(line.starts_with("robot error joint_velocity_violation+cartesian_reflex"));
        assert!(line.contains("ReflexAborted"), "{line}");
        let mut counts = FaultCounts::default();
        counts.add(&f);
        counts.add(&Fault::from_error(&reflex(&["cartesian_reflex"])));
        assert_eq!(counts.aborted_motions(), 2);
        let entries: Vec<_> = counts.entries().collect();
        assert_eq!(
            entries,
            [("cartesian_reflex", 2), ("joint_velocity_violation", 1)]
        );
    }

    #[test]
    fn a_lost_connection_is_not_recoverable() {
        let f = Fault::from_error(&FrankaError::Network(
            "libfranka: UDP receive: Timeout".into(),
        ));
        assert_eq!(f.kind, FaultKind::Connection);
        assert_eq!(f.names(), "-");
        assert!(f.line().contains("UDP receive: Timeout"));
    }
}
