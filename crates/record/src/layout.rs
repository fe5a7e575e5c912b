//! What a recording of a scenario holds besides its rows: the column layout
//! and the report's description of the run.

use hcc_config::{Scenario, TaskUnit};
use hcc_report::{ErrorUnit, LevelDescription, RunDescription, columns};
use std::collections::BTreeMap;

/// The report's unit of task coordinates (`None`: a level that mixes units).
fn unit(u: Option<TaskUnit>) -> ErrorUnit {
    match u {
        Some(TaskUnit::Length) => ErrorUnit::Meter,
        Some(TaskUnit::Angle) => ErrorUnit::Radian,
        None => ErrorUnit::Mixed,
    }
}

/// The report's description of a scenario run.
pub fn describe(scenario: &Scenario) -> RunDescription {
    let s = &scenario.simulation;
    let mut settings = BTreeMap::new();
    let mut put = |k: &str, v: serde_json::Value| {
        settings.insert(k.to_string(), v);
    };
    put("config", scenario.path.display().to_string().into());
    put("urdf", scenario.urdf_path.display().to_string().into());
    put("duration_s", s.duration_s.into());
    put("control_rate_hz", scenario.rate_hz.into());
    put("integrator_dt_s", s.integrator_dt_s.into());
    put("integrator", "RK4".into());
    put(
        "coriolis_cancellation",
        scenario.spec.coriolis_cancellation.into(),
    );
    put(
        "gravity_compensation",
        scenario.spec.gravity_compensation.into(),
    );
    put("form", scenario.spec.form.name().into());
    put(
        "joint_friction",
        s.joint_friction
            .iter()
            .copied()
            .collect::<Vec<f64>>()
            .into(),
    );
    put("external_wrenches", s.wrenches.len().into());
    put(
        "q0",
        scenario.q0.iter().copied().collect::<Vec<f64>>().into(),
    );
    RunDescription {
        scenario: scenario.name.clone(),
        n_joints: scenario.model.nq(),
        levels: scenario
            .levels()
            .iter()
            .map(|l| {
                let n = scenario.model.nq();
                let unit = unit(l.unit(n));
                LevelDescription {
                    name: l.name.clone(),
                    dim: l.dim(n),
                    unit,
                    // Per-row units only for a level that mixes them (a pose).
                    row_units: match unit {
                        ErrorUnit::Mixed => l
                            .units(n)
                            .into_iter()
                            .map(|u| self::unit(Some(u)))
                            .collect(),
                        _ => Vec::new(),
                    },
                }
            })
            .collect(),
        settings,
    }
}

/// Column names recorded by [`crate::Recorder`] for `scenario` (`with_v`: the law
/// provides J̄, so the `accv` columns are recorded).
pub fn column_names(scenario: &Scenario, with_v: bool) -> Vec<String> {
    let n = scenario.model.nq();
    let r = scenario.levels().len();
    let dims: Vec<usize> = scenario.task_dims();
    let mut c = columns::required(n, &dims);
    for i in 1..=r {
        c.extend((1..=n).map(|k| columns::level_torque(i, k)));
    }
    c.extend((1..=n).map(columns::mu_torque));
    for i in 1..=r {
        c.extend(
            (1..=r)
                .filter(|&j| j != i)
                .map(|j| columns::disturbing_acceleration(i, j)),
        );
        c.push(columns::mu_acceleration(i));
    }
    if with_v {
        for i in 1..=r {
            c.extend(
                (1..=r)
                    .filter(|&j| j != i)
                    .map(|j| columns::null_space_acceleration(i, j)),
            );
            c.push(columns::null_space_mu_acceleration(i));
        }
    }
    for i in 1..=r {
        c.push(columns::energy_kinetic(i));
        c.push(columns::energy_potential(i));
    }
    c.push(columns::E_KIN.to_string());
    c.push(columns::E_POT.to_string());
    c.push(columns::H.to_string());
    c.extend((1..=r).map(columns::potential_in_h));
    c.extend((1..=r).map(columns::tank));
    c.extend((1..=r).map(columns::tank_valve));
    c.extend((1..=n).map(columns::external_torque));
    c.push(columns::CONTACT.to_string());
    c.extend((1..=wrench_rows(scenario)).map(columns::external_wrench));
    for (i, &m) in dims.iter().enumerate() {
        c.extend((1..=m).map(|k| columns::desired(i + 1, k)));
    }
    c
}

/// The rows of the external wrench estimate: those of the first position or
/// pose level (`hcc_control::ControllerSpec::wrench_level`), 0 without one.
pub fn wrench_rows(scenario: &Scenario) -> usize {
    let dims = scenario.task_dims();
    scenario.spec.wrench_level().map_or(0, |i| dims[i])
}
