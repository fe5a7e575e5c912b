//! The law of a scenario: [`controller_for`] builds the
//! `hcc_control::Controller` of a loaded scenario and names, as the scenario
//! reader's own errors do, the file, the field and its line of what the law
//! refuses at the initial configuration (Sec. II: a Jacobian or an augmented
//! Jacobian singular at q0, an algorithmic singularity, a lowest level that
//! does not fill the remaining null space, gains the control rate cannot
//! carry). The scenario reader checks what needs no configuration
//! (`hcc_spec::ControllerSpec::validate`); these checks are the law's.

use hcc_config::{ConfigError, Scenario};
use hcc_control::{ControlError, Controller};

/// The controller of `scenario` (its model, hierarchy and q0). An error of
/// the law names the level it refuses (`level[k]`, 0-based as in the file)
/// or the initial configuration (`initial.q0`), with the line.
pub fn controller_for(scenario: &Scenario) -> Result<Controller, ConfigError> {
    Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).map_err(|e| {
        let field = match &e {
            ControlError::Level { level, .. } => hcc_spec::level_field(level),
            _ => "initial.q0".to_string(),
        };
        scenario.error_at(&field, format!("rejected by the controller: {e}"))
    })
}
