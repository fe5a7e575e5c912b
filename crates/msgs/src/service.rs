//! Service names under a validated namespace.
//!
//! Every service of one robot/controller pair lives under
//! `hcc/<namespace>/…`, so two robots (or two concurrently running tests)
//! with different namespaces never share a service. Built once at start-up;
//! these functions allocate.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::NamespaceError;

/// Maximum namespace length in bytes.
pub const MAX_NAMESPACE_LEN: usize = 64;

/// Prefix of all hcc service names.
pub const SERVICE_PREFIX: &str = "hcc";

/// Event id a driver notifies on the state-ready event service after
/// publishing a [`crate::JointState`].
pub const EVENT_STATE_PUBLISHED: usize = 1;
/// Event id the controller notifies on the command-ready event service after
/// publishing a [`crate::TorqueCommand`].
pub const EVENT_COMMAND_PUBLISHED: usize = 2;

/// Checks a namespace: 1 to [`MAX_NAMESPACE_LEN`] characters of
/// `[A-Za-z0-9_-]`, not starting with '-'.
pub fn validate_namespace(namespace: &str) -> Result<(), NamespaceError> {
    if namespace.is_empty() {
        return Err(NamespaceError::Empty {
            max: MAX_NAMESPACE_LEN,
        });
    }
    if let Some((index, ch)) = namespace
        .char_indices()
        .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_' || c == '-'))
    {
        return Err(NamespaceError::InvalidChar {
            namespace: namespace.to_owned(),
            ch,
            index,
        });
    }
    if namespace.len() > MAX_NAMESPACE_LEN {
        return Err(NamespaceError::TooLong {
            namespace: namespace.to_owned(),
            len: namespace.len(),
            max: MAX_NAMESPACE_LEN,
        });
    }
    if namespace.starts_with('-') {
        return Err(NamespaceError::LeadingDash {
            namespace: namespace.to_owned(),
        });
    }
    Ok(())
}

/// A validated namespace.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Namespace(String);

impl Namespace {
    /// Validates and wraps `namespace`.
    pub fn new(namespace: &str) -> Result<Self, NamespaceError> {
        validate_namespace(namespace)?;
        Ok(Self(namespace.to_owned()))
    }

    /// A namespace unique to this process and call: `<prefix>_<pid>_<counter>`
    /// (prefix truncated to fit), for tests that run in parallel.
    pub fn unique(prefix: &str) -> Result<Self, NamespaceError> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let k = COUNTER.fetch_add(1, Ordering::Relaxed);
        let suffix = format!("_{}_{}", std::process::id(), k);
        let keep = MAX_NAMESPACE_LEN.saturating_sub(suffix.len());
        let prefix: String = prefix.chars().take(keep).collect();
        Self::new(&format!("{prefix}{suffix}"))
    }

    /// The namespace text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Display for Namespace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// The names of all services of one namespace.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceNames {
    namespace: Namespace,
    joint_state: String,
    torque_command: String,
    telemetry: String,
    setpoint: String,
    path: String,
    load: String,
    state_ready: String,
    command_ready: String,
    scenario: String,
    recorder_progress: String,
}

impl ServiceNames {
    /// Builds the names for `namespace` (validated).
    pub fn new(namespace: &str) -> Result<Self, NamespaceError> {
        Ok(Self::for_namespace(Namespace::new(namespace)?))
    }

    /// Builds the names for an already validated namespace.
    pub fn for_namespace(namespace: Namespace) -> Self {
        let base = format!("{SERVICE_PREFIX}/{namespace}");
        Self {
            joint_state: format!("{base}/joint_state"),
            torque_command: format!("{base}/torque_command"),
            telemetry: format!("{base}/telemetry"),
            setpoint: format!("{base}/setpoint"),
            path: format!("{base}/path"),
            load: format!("{base}/load"),
            state_ready: format!("{base}/state_ready"),
            command_ready: format!("{base}/command_ready"),
            scenario: format!("{base}/scenario"),
            recorder_progress: format!("{base}/recorder_progress"),
            namespace,
        }
    }

    /// The namespace.
    pub fn namespace(&self) -> &Namespace {
        &self.namespace
    }

    /// Publish-subscribe service of [`crate::JointState`] (driver → controller).
    pub fn joint_state(&self) -> &str {
        &self.joint_state
    }

    /// Publish-subscribe service of [`crate::TorqueCommand`] (controller → driver).
    pub fn torque_command(&self) -> &str {
        &self.torque_command
    }

    /// Publish-subscribe service of [`crate::Telemetry`] (controller → loggers).
    pub fn telemetry(&self) -> &str {
        &self.telemetry
    }

    /// Publish-subscribe service of [`crate::Setpoint`] (clients → controller).
    pub fn setpoint(&self) -> &str {
        &self.setpoint
    }

    /// Publish-subscribe service of [`crate::PathKnots`] (clients → controller).
    pub fn path(&self) -> &str {
        &self.path
    }

    /// Publish-subscribe service of [`crate::LoadSetpoint`] (clients → controller).
    pub fn load(&self) -> &str {
        &self.load
    }

    /// Event service the driver notifies with [`EVENT_STATE_PUBLISHED`].
    pub fn state_ready(&self) -> &str {
        &self.state_ready
    }

    /// Event service the controller notifies with [`EVENT_COMMAND_PUBLISHED`].
    pub fn command_ready(&self) -> &str {
        &self.command_ready
    }

    /// Publish-subscribe service of the controller's [`crate::scenario::ScenarioDoc`]
    /// (a JSON byte slice, the last one kept for tools that connect later).
    pub fn scenario(&self) -> &str {
        &self.scenario
    }

    /// Publish-subscribe service of the recorder's progress in a lockstep
    /// run (`hcc_msgs::ipc::RecorderProgressPublisher`): the simulator does
    /// not run further ahead of the recorder than its queues hold.
    pub fn recorder_progress(&self) -> &str {
        &self.recorder_progress
    }

    /// All names, for listing/cleanup.
    pub fn all(&self) -> [&str; 10] {
        [
            &self.joint_state,
            &self.torque_command,
            &self.telemetry,
            &self.setpoint,
            &self.path,
            &self.load,
            &self.state_ready,
            &self.command_ready,
            &self.scenario,
            &self.recorder_progress,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_namespaced() {
        let s = ServiceNames::new("panda_left").unwrap();
        assert_eq!(s.joint_state(), "hcc/panda_left/joint_state");
        assert_eq!(s.torque_command(), "hcc/panda_left/torque_command");
        assert_eq!(s.telemetry(), "hcc/panda_left/telemetry");
        assert_eq!(s.setpoint(), "hcc/panda_left/setpoint");
        assert_eq!(s.state_ready(), "hcc/panda_left/state_ready");
        assert_eq!(s.command_ready(), "hcc/panda_left/command_ready");
        assert_eq!(s.scenario(), "hcc/panda_left/scenario");
        let other = ServiceNames::new("panda_right").unwrap();
        for (a, b) in s.all().iter().zip(other.all()) {
            assert_ne!(*a, b);
        }
        // Every name is accepted by iceoryx2.
        for name in s.all() {
            iceoryx2::prelude::ServiceName::new(name).unwrap();
        }
    }

    #[test]
    fn invalid_namespaces_are_rejected_with_clear_errors() {
        assert!(matches!(
            validate_namespace(""),
            Err(NamespaceError::Empty { .. })
        ));
        let e = validate_namespace("a/b").unwrap_err();
        assert_eq!(
            e,
            NamespaceError::InvalidChar {
                namespace: "a/b".into(),
                ch: '/',
                index: 1
            }
        );
        assert!(e.to_string().contains("'/'"), "{e}");
        assert!(matches!(
            validate_namespace("robot ä"),
            Err(NamespaceError::InvalidChar { ch: ' ', .. })
        ));
        assert!(matches!(
            validate_namespace("ü"),
            Err(NamespaceError::InvalidChar { ch: 'ü', .. })
        ));
        let long = "x".repeat(MAX_NAMESPACE_LEN + 1);
        assert!(matches!(
            validate_namespace(&long),
            Err(NamespaceError::TooLong { len: 65, .. })
        ));
        assert!(validate_namespace(&long[..MAX_NAMESPACE_LEN]).is_ok());
        assert!(matches!(
            validate_namespace("-x"),
            Err(NamespaceError::LeadingDash { .. })
        ));
        assert!(validate_namespace("Robot-1_a").is_ok());
    }

    #[test]
    fn unique_namespaces_differ_and_are_valid() {
        let a = Namespace::unique("test").unwrap();
        let b = Namespace::unique("test").unwrap();
        assert_ne!(a, b);
        let long = Namespace::unique(&"p".repeat(200)).unwrap();
        assert!(long.as_str().len() <= MAX_NAMESPACE_LEN);
    }
}
