//! The scenario of a tool that watches, commands or records a running
//! controller: the file it is given (`--config`), checked against what the
//! controller runs, or else the scenario the controller publishes on its
//! scenario service (`hcc_msgs::ipc::read_scenario`).

use std::path::Path;
use std::time::Duration;

use hcc_msgs::ServiceNames;
use hcc_msgs::ipc::{ScenarioReadError, read_scenario_as};

use crate::{ConfigError, Scenario};

/// How long a tool given `--config` waits for the controller's document to
/// compare it with (a controller that publishes none is not waited for).
pub const COMPARE_WAIT: Duration = Duration::from_millis(500);

/// Why a tool has no scenario.
#[derive(Debug, thiserror::Error)]
pub enum ToolScenarioError {
    /// The `--config` file is refused.
    #[error(transparent)]
    Config(ConfigError),
    /// No scenario could be read from the controller.
    #[error(transparent)]
    Read(#[from] ScenarioReadError),
    /// The controller's document does not build a scenario here.
    #[error("the controller's scenario: {0}")]
    Published(ConfigError),
}

/// The scenario of the tool `tool` (its node's name) on the namespace of
/// `names`: `config` when given — with how it differs from what the
/// controller runs ([`Scenario::differs_from`]; `None` when it is the same
/// or no controller answered within [`COMPARE_WAIT`]) — else the one the
/// controller publishes, waiting up to `wait` for a starting controller.
pub fn scenario_for_tool(
    tool: &str,
    config: Option<&Path>,
    names: &ServiceNames,
    file_prefix: Option<&str>,
    wait: Duration,
) -> Result<(Scenario, Option<String>), ToolScenarioError> {
    let node = format!("{tool}-{}", std::process::id());
    match config {
        Some(path) => {
            let scenario = Scenario::load(path).map_err(ToolScenarioError::Config)?;
            let differs = read_scenario_as(&node, names, file_prefix, COMPARE_WAIT)
                .ok()
                .and_then(|doc| scenario.differs_from(&doc));
            Ok((scenario, differs))
        }
        None => {
            let doc = read_scenario_as(&node, names, file_prefix, wait)?;
            let scenario = Scenario::from_document(&doc).map_err(ToolScenarioError::Published)?;
            Ok((scenario, None))
        }
    }
}
