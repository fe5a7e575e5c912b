//! The loading pipeline: the file parsed, every table resolved and checked in
//! turn (against the robot model and by the controller), and the [`Scenario`]
//! assembled.

use std::path::Path;

use hcc_model::Model;
use hcc_spec::{ControllerSpec, Form, SpecError};

use crate::context::Ctx;
use crate::daemons::{resolve_controller_daemon, resolve_sim_daemon};
use crate::error::{ConfigError, from_toml};
use crate::levels::{check_hierarchy, resolve_level};
use crate::robot::{load_model, resolve_initial};
use crate::safety::safety_spec;
use crate::scenario::Scenario;
use crate::schema::{self, ScenarioFile};
use crate::simulation::resolve_simulation;
use crate::trajectories::resolve_tracking;
use crate::{contact, franka, schedule, setpoint_limits, torque_filter};

impl Scenario {
    /// Loads, checks and resolves a scenario file; builds the robot model from its URDF.
    pub fn load(path: impl AsRef<Path>) -> Result<Scenario, ConfigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Io {
            file: path.to_path_buf(),
            error,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Like [`Scenario::load`] for TOML text; `path` names the file in errors and is
    /// the base for the relative URDF path.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Scenario, ConfigError> {
        Self::from_texts(text, path, None, &Default::default())
    }

    /// The scenario a controller publishes on its scenario service
    /// (`hcc_msgs::ipc::read_scenario`): its file's text as the controller
    /// loaded it, the robot from the URDF's text it sent (the file on disk
    /// when the document has none), its paths from the texts it sent.
    /// Errors name the controller's file.
    pub fn from_document(doc: &hcc_msgs::scenario::ScenarioDoc) -> Result<Scenario, ConfigError> {
        let urdf = (!doc.urdf.is_empty()).then_some(doc.urdf.as_str());
        Self::from_texts(&doc.toml, Path::new(&doc.path), urdf, &doc.paths)
    }

    /// Like [`Scenario::from_toml_str`], the robot from `urdf` (the URDF's
    /// text) when given, else from the file `[robot] urdf` names, and each
    /// level's path from `paths` (file as the scenario names it → text)
    /// where it holds the file, else from the file (a recording or a
    /// controller's document carries all the texts).
    pub fn from_texts(
        text: &str,
        path: &Path,
        urdf: Option<&str>,
        paths: &std::collections::BTreeMap<String, String>,
    ) -> Result<Scenario, ConfigError> {
        let file: ScenarioFile = toml::from_str(text).map_err(|e| from_toml(path, text, &e))?;
        let cx = Ctx {
            file: path,
            text,
            stacked: false,
            trajectory: false,
        };
        let (model, urdf_path) = load_model(&cx, &file.robot, urdf)?;
        let n = model.nq();

        // [[level]]
        if file.levels.is_empty() {
            return Err(cx.err("level", "at least one [[level]] is required"));
        }
        let mut levels = Vec::with_capacity(file.levels.len());
        for (i, l) in file.levels.iter().enumerate() {
            levels.push(resolve_level(&cx, &model, i, l)?);
        }
        check_hierarchy(&cx, &levels, n)?;

        // [controller]
        let ratio = file.controller.singularity.singular_ratio;
        if !(ratio > 0.0 && ratio < 1.0) {
            return Err(cx.err(
                "controller.singularity.singular_ratio",
                format!("must be in (0, 1), got {ratio}"),
            ));
        }

        let rate_hz = file.controller.rate_hz;
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return Err(cx.err(
                "controller.rate_hz",
                format!("must be a positive finite number, got {rate_hz}"),
            ));
        }

        let (q0, qd0) = resolve_initial(&cx, &model, &file.initial)?;
        let simulation = resolve_simulation(&cx, &model, &file.simulation, rate_hz)?;
        check_namespace(&cx, &file.ipc.namespace)?;

        let torque_filter = torque_filter::resolve(cx.file, cx.text, &file.torque_filter)?;
        let tracking = resolve_tracking(
            &cx,
            &file.levels,
            &mut levels,
            n,
            file.controller.form,
            paths,
        )?;
        let spec = ControllerSpec {
            levels,
            gravity_compensation: file.robot.gravity_compensation,
            coriolis_cancellation: file.controller.coriolis_cancellation,
            form: file.controller.form,
            singular_ratio: ratio,
            safety: safety_spec(&cx, &file.safety, rate_hz, torque_filter.torque_rate_limit)?,
        };
        check_spec(&cx, &model, &spec)?;

        let controller_daemon =
            resolve_controller_daemon(&cx, &model, &file.controller_daemon, rate_hz)?;
        let sim_daemon = resolve_sim_daemon(&cx, n, &file.sim_daemon)?;
        check_renamed_tables(&cx, &file)?;
        let setpoint_limits =
            setpoint_limits::resolve(cx.file, cx.text, &file.setpoint_limits, &spec.levels, n)?;
        let setpoints = schedule::resolve(cx.file, cx.text, &file.setpoints, &spec.levels, n)?;
        let franka = franka::resolve(cx.file, cx.text, &file.franka)?;
        let contact = contact::resolve(&cx, &model, &q0, &file.contact, rate_hz)?;

        let name = file.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scenario".to_string())
        });
        Ok(Scenario {
            path: path.to_path_buf(),
            text: text.to_string(),
            name,
            urdf_path,
            model,
            spec,
            rate_hz,
            q0,
            qd0,
            simulation,
            ipc: file.ipc,
            controller_daemon,
            sim_daemon,
            setpoint_limits,
            torque_filter,
            setpoints,
            franka,
            contact,
            tracking,
        })
    }
}

/// Tables that were renamed: refused with their new name.
fn check_renamed_tables(cx: &Ctx, file: &schema::ScenarioFile) -> Result<(), ConfigError> {
    for (old, present, new) in [
        ("commanding", file.commanding.is_some(), "setpoint_limits"),
        ("output", file.output.is_some(), "torque_filter"),
    ] {
        if present {
            return Err(cx.err(
                old,
                format!("[{old}] is now called [{new}] (same fields): rename the table"),
            ));
        }
    }
    Ok(())
}

/// `[ipc] namespace`: non-empty, letters, digits, '_' and '-'.
fn check_namespace(cx: &Ctx, ns: &str) -> Result<(), ConfigError> {
    if ns.is_empty()
        || !ns
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Err(cx.err(
            "ipc.namespace",
            format!("{ns:?} must be non-empty and use only letters, digits, '_' and '-'"),
        ));
    }
    Ok(())
}

/// The checks of the hierarchy that need no configuration
/// (`hcc_spec::ControllerSpec::validate`), named by field; those at the
/// initial configuration are the law's (`hcc_cycle::controller_for`).
fn check_spec(cx: &Ctx, model: &Model, spec: &ControllerSpec) -> Result<(), ConfigError> {
    if let Err(e) = spec.validate(model) {
        let field = match &e {
            SpecError::Level { level, .. } => hcc_spec::level_field(level),
            SpecError::Spec(_) if spec.form == Form::KinematicProjector => {
                "controller.form".to_string()
            }
            SpecError::Spec(_) => "level".to_string(),
        };
        return Err(cx.err(&field, e.to_string()));
    }
    Ok(())
}
