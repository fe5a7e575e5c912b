//! The hierarchy's description the law consumes, from `hcc-spec` (which the
//! scenario reader fills without depending on the law): re-exported here, so
//! that the law's users name it as part of the law.

pub use hcc_spec::{ControllerSpec, Form, LevelSpec, SpecError, TaskSpec, TaskUnit};
