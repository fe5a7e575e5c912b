//! The scenario a controller runs, as it publishes it for the tools that
//! know only its namespace (`hcc/<ns>/scenario`, [`crate::ipc::ScenarioPublisher`]):
//! the scenario file as loaded, the URDF, the levels' names, kinds and
//! dimensions, the joints with their limits and the control rate — one JSON
//! document, versioned by [`SCENARIO_SCHEMA_VERSION`] apart from the message
//! types (it changes when a field changes meaning or goes; new fields are
//! added with defaults).

use serde::{Deserialize, Serialize};

/// Version of the scenario document's layout. A reader refuses another
/// version with [`ScenarioDocError::Version`].
pub const SCENARIO_SCHEMA_VERSION: u32 = 1;

/// Largest document the service carries (bytes): a scenario file and a URDF
/// of a few hundred kB each.
pub const MAX_SCENARIO_DOC_BYTES: usize = 4 << 20;

/// One level of the hierarchy, in priority order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelInfo {
    /// The name of its `[[level]]` (or "level N").
    pub name: String,
    /// Its tasks' kinds, stacked in order (`position`, `orientation`,
    /// `pose`, `planar_orientation`, `joint`, `joint_combination`, `posture`).
    pub tasks: Vec<String>,
    /// Its task dimension m_i.
    pub dim: usize,
    /// x_{i,d} as resolved at load (m, rad; orientation goals as the file
    /// gives them, roll-pitch-yaw).
    pub goal: Vec<f64>,
    /// K_i, m_i × m_i row-major, as resolved at load.
    pub stiffness: Vec<f64>,
    /// D_i, m_i × m_i row-major, as resolved at load.
    pub damping: Vec<f64>,
}

/// One joint of the chain, root to tip, with its URDF limits (rad or m,
/// rad/s or m/s, N·m or N; `None` where the URDF sets none).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointInfo {
    pub name: String,
    pub lower: Option<f64>,
    pub upper: Option<f64>,
    pub velocity: Option<f64>,
    pub effort: Option<f64>,
}

impl JointInfo {
    /// A joint with the limits given (a non-finite one is none).
    pub fn new(name: &str, lower: f64, upper: f64, velocity: f64, effort: f64) -> JointInfo {
        let finite = |x: f64| x.is_finite().then_some(x);
        JointInfo {
            name: name.to_string(),
            lower: finite(lower),
            upper: finite(upper),
            velocity: finite(velocity),
            effort: finite(effort),
        }
    }
}

/// What a controller runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScenarioDoc {
    /// [`SCENARIO_SCHEMA_VERSION`] of the writer.
    pub version: u32,
    /// The scenario's name.
    pub name: String,
    /// The namespace the controller serves.
    pub namespace: String,
    /// The control rate (Hz).
    pub rate_hz: f64,
    /// The law's form (`extended`, `projector`, `kinematic_projector`).
    pub form: String,
    /// Whether τ_μ (eq. 22) is added.
    pub coriolis_cancellation: bool,
    /// Whether the controller adds g(q) (else the driver does).
    pub gravity_compensation: bool,
    /// The scenario file's path as the controller loaded it (informative:
    /// the tools need [`ScenarioDoc::toml`], not the file).
    pub path: String,
    /// The scenario file's text.
    pub toml: String,
    /// The URDF's file name as the scenario names it.
    pub urdf_path: String,
    /// The URDF's text.
    pub urdf: String,
    /// The levels' path files (`trajectory`), as the scenario names them,
    /// with their texts (empty without paths; absent in a document of an
    /// earlier release).
    #[serde(default)]
    pub paths: std::collections::BTreeMap<String, String>,
    /// The levels in priority order.
    pub levels: Vec<LevelInfo>,
    /// The joints, root to tip.
    pub joints: Vec<JointInfo>,
}

/// A scenario document that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioDocError {
    /// Written by a controller of another document version.
    #[error(
        "the controller publishes scenario document version {found}, this tool reads version {expected}: use tools of the controller's release, or pass --config"
    )]
    Version { found: u32, expected: u32 },
    /// Not a scenario document.
    #[error("the scenario document cannot be read: {0}")]
    Decode(String),
}

impl ScenarioDoc {
    /// The document as JSON bytes.
    pub fn to_json(&self) -> Vec<u8> {
        // Plain strings and finite numbers: serialisation cannot fail.
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// Reads a document, refusing another version.
    pub fn from_json(bytes: &[u8]) -> Result<ScenarioDoc, ScenarioDocError> {
        #[derive(Deserialize)]
        struct Version {
            version: u32,
        }
        let decode = |e: serde_json::Error| ScenarioDocError::Decode(e.to_string());
        let v: Version = serde_json::from_slice(bytes).map_err(decode)?;
        if v.version != SCENARIO_SCHEMA_VERSION {
            return Err(ScenarioDocError::Version {
                found: v.version,
                expected: SCENARIO_SCHEMA_VERSION,
            });
        }
        serde_json::from_slice(bytes).map_err(decode)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc() -> ScenarioDoc {
        ScenarioDoc {
            version: SCENARIO_SCHEMA_VERSION,
            name: "sim1".into(),
            namespace: "hcc".into(),
            rate_hz: 1000.0,
            path: "config/paper-sim1.toml".into(),
            toml: "[robot]\n".into(),
            urdf_path: "planar4.urdf".into(),
            urdf: "<robot/>".into(),
            paths: Default::default(),
            form: "extended".into(),
            coriolis_cancellation: true,
            gravity_compensation: true,
            levels: vec![LevelInfo {
                name: "TCP position".into(),
                tasks: vec!["position".into()],
                dim: 2,
                goal: vec![0.9, 0.8],
                stiffness: vec![1000.0, 0.0, 0.0, 1000.0],
                damping: vec![40.0, 0.0, 0.0, 40.0],
            }],
            joints: vec![JointInfo::new("joint1", -2.9, 2.9, f64::INFINITY, 87.0)],
        }
    }

    #[test]
    fn a_document_round_trips_and_another_version_is_refused() {
        let d = doc();
        let back = ScenarioDoc::from_json(&d.to_json()).unwrap();
        assert_eq!(back, d);
        assert_eq!(back.joints[0].velocity, None);
        let mut old = d.clone();
        old.version = SCENARIO_SCHEMA_VERSION + 1;
        let e = ScenarioDoc::from_json(&old.to_json()).unwrap_err();
        assert!(matches!(e, ScenarioDocError::Version { .. }), "{e}");
        assert!(e.to_string().contains("--config"), "{e}");
        assert!(matches!(
            ScenarioDoc::from_json(b"{\"x\": 1}"),
            Err(ScenarioDocError::Decode(_))
        ));
    }
}
