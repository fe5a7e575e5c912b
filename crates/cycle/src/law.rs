//! The law of a scenario: [`controller_for`] builds the
//! `hcc_control::Controller` of a loaded scenario and names, as the scenario
//! reader's own errors do, the file, the field and its line of what the law
//! refuses at the initial configuration (Sec. II: a Jacobian or an augmented
//! Jacobian singular at q0, an algorithmic singularity, a lowest level that
//! does not fill the remaining null space, gains the control rate cannot
//! carry, a path that does not start at the arm or moves faster than its
//! level's `max_speed`). The scenario reader checks
//! what needs no configuration (`hcc_spec::ControllerSpec::validate`); these
//! checks are the law's.

use hcc_config::{ConfigError, Scenario};
use hcc_control::{ControlError, Controller};
use hcc_spec::TaskUnit;

/// How far a level's path may start from the arm at q0, per coordinate: a
/// path is followed from where the arm is, not jumped to.
pub const MAX_PATH_START_OFFSET_M: f64 = 0.05;
/// The same for angles (rad).
pub const MAX_PATH_START_OFFSET_RAD: f64 = 0.2;

/// The controller of `scenario` (its model, hierarchy and q0). An error of
/// the law names the level it refuses (`level[k]`, 0-based as in the file)
/// or the initial configuration (`initial.q0`), with the line.
pub fn controller_for(scenario: &Scenario) -> Result<Controller, ConfigError> {
    let controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0)
        .map_err(|e| {
            let field = match &e {
                ControlError::Level { level, .. } => hcc_spec::level_field(level),
                _ => "initial.q0".to_string(),
            };
            scenario.error_at(&field, format!("rejected by the controller: {e}"))
        })?;
    check_path_starts(scenario, &controller)?;
    check_path_speeds(scenario)?;
    check_path_feasibility(scenario, &controller)?;
    Ok(controller)
}

/// The hierarchy can follow the scenario's paths from q0: no level singular
/// and no path level left behind along them (crate `feasibility`).
fn check_path_feasibility(scenario: &Scenario, controller: &Controller) -> Result<(), ConfigError> {
    if !scenario.tracking.any() {
        return Ok(());
    }
    let paths: Vec<_> = scenario
        .tracking
        .paths
        .iter()
        .map(|p| p.as_ref().map(|p| &p.trajectory))
        .collect();
    let q0 = scenario.q0.as_slice();
    match crate::feasibility::check_paths(
        controller,
        q0,
        &paths,
        crate::feasibility::ROLLOUT_STEP_S,
    ) {
        Ok(_) => Ok(()),
        Err(e) => {
            // Name the level's path when it has one, else the first path.
            let i = if paths.get(e.level).is_some_and(Option::is_some) {
                e.level
            } else {
                paths.iter().position(Option::is_some).unwrap_or(0)
            };
            let file = scenario.tracking.paths[i]
                .as_ref()
                .map_or("", |p| p.file.as_str());
            Err(scenario.error_at(
                &format!("level[{i}].trajectory"),
                format!("{file}: the paths cannot be followed from initial.q0: {e}"),
            ))
        }
    }
}

/// Every path's speed, √(|ẋ|² + |ω|²) sampled every control period, within
/// its level's `[setpoint_limits] max_speed` (as a path sent at run time).
fn check_path_speeds(scenario: &Scenario) -> Result<(), ConfigError> {
    let dt = scenario.period_s();
    for (i, path) in scenario.tracking.paths.iter().enumerate() {
        let Some(path) = path else { continue };
        let Some(limits) = scenario.setpoint_limits.levels.get(i) else {
            continue;
        };
        let trajectory = &path.trajectory;
        let mut sample = trajectory.sample_buffer();
        let steps = (trajectory.duration() / dt).ceil() as usize;
        let (mut worst, mut at) = (0.0_f64, 0.0);
        for k in 0..=steps {
            let t = k as f64 * dt;
            trajectory.sample(t, &mut sample);
            let speed = sample.velocity.iter().map(|v| v * v).sum::<f64>().sqrt();
            if speed > worst {
                (worst, at) = (speed, t);
            }
        }
        if worst > limits.max_speed * (1.0 + 1e-9) {
            return Err(scenario.error_at(
                &format!("level[{i}].trajectory"),
                format!(
                    "{}: the path moves at {worst:.4} at t = {at:.3} s, faster than the level's setpoint_limits max_speed {}: slow the path down or raise max_speed",
                    path.file, limits.max_speed
                ),
            ));
        }
    }
    Ok(())
}

/// Every path starts within [`MAX_PATH_START_OFFSET_M`] /
/// [`MAX_PATH_START_OFFSET_RAD`] of the arm at q0 (its first row is the
/// level's goal there: the task error of one step at rest).
fn check_path_starts(scenario: &Scenario, controller: &Controller) -> Result<(), ConfigError> {
    if !scenario.tracking.any() {
        return Ok(());
    }
    let n = scenario.model.nq();
    let mut probe = controller.clone();
    let Ok(out) = probe.step(scenario.q0.as_slice(), &vec![0.0; n]) else {
        return Ok(());
    };
    for (i, path) in scenario.tracking.paths.iter().enumerate() {
        let Some(path) = path else { continue };
        let units = scenario.spec.levels[i].units(n);
        for (a, (e, unit)) in out.task_error[i].iter().zip(&units).enumerate() {
            let (limit, what) = match unit {
                TaskUnit::Length => (MAX_PATH_START_OFFSET_M, "m"),
                TaskUnit::Angle => (MAX_PATH_START_OFFSET_RAD, "rad"),
            };
            if e.abs() > limit {
                return Err(scenario.error_at(
                    &format!("level[{i}].trajectory"),
                    format!(
                        "{}: row {}: the path starts {:.4} {what} from the arm at initial.q0 in \
                         coordinate {} (at most {limit} {what}): start the path where the arm is",
                        path.file,
                        path.trajectory.first_line(),
                        e.abs(),
                        a + 1
                    ),
                ));
            }
        }
    }
    Ok(())
}
