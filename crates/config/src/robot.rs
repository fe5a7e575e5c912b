//! `[robot]`: the robot model from its URDF; `[initial]`: its initial state.

use std::path::{Path, PathBuf};

use hcc_model::Model;
use nalgebra::{DVector, Vector3};

use crate::context::Ctx;
use crate::error::{self, ConfigError};
use crate::schema::{InitialSection, LoadSection, RobotSection};

/// `[robot]`: the model from the URDF (path relative to the scenario file),
/// or from its text `urdf` when given (the path is then only named).
pub(crate) fn load_model(
    cx: &Ctx,
    robot: &RobotSection,
    urdf: Option<&str>,
) -> Result<(Model, PathBuf), ConfigError> {
    let gravity = match &robot.gravity {
        Some(g) => {
            let v = cx.vector("robot.gravity", g, 3, "x, y, z")?;
            Some(Vector3::new(v[0], v[1], v[2]))
        }
        None => None,
    };
    let base = cx.file.parent().unwrap_or(Path::new("."));
    let urdf_path = base.join(&robot.urdf);
    let (root, tip) = (robot.root_link.as_deref(), robot.tip_link.as_str());
    let model = match urdf {
        Some(text) => Model::from_urdf_str(text, root, tip, gravity),
        None => Model::from_urdf_file(&urdf_path, root, tip, gravity),
    }
    .map_err(|error| {
        let field = match &error {
            hcc_model::ModelError::UnknownLink { what, .. } if what == "root" => "robot.root_link",
            hcc_model::ModelError::UnknownLink { what, .. } if what == "tip" => "robot.tip_link",
            hcc_model::ModelError::TipNotBelowRoot { .. } => "robot.tip_link",
            _ => "robot.urdf",
        };
        ConfigError::Model {
            file: cx.file.to_path_buf(),
            line: error::locate_path(cx.text, field),
            error,
        }
    })?;
    let mut model = model;
    if let Some(limit) = robot.payload_kg {
        if !(limit.is_finite() && limit >= 0.0) {
            return Err(cx.err(
                "robot.payload_kg",
                format!("{limit} must be a mass ≥ 0 (kg)"),
            ));
        }
        model.payload_limit = limit;
    }
    if let Some(section) = &robot.load {
        let load = tip_load(cx, "robot.load", section, model.payload_limit)?;
        hcc_model::set_load(&mut model, &load);
    }
    Ok((model, urdf_path))
}

/// The load `section` (at `path`, e.g. `robot.load`) as a
/// [`hcc_model::Load`]: its values' count and finiteness, then its physics
/// and mass against `payload_limit` ([`hcc_model::Load::check`]), each
/// refusal naming its field.
pub(crate) fn tip_load(
    cx: &Ctx,
    path: &str,
    section: &LoadSection,
    payload_limit: f64,
) -> Result<hcc_model::Load, ConfigError> {
    let field = |f: &str| format!("{path}.{f}");
    let com = match &section.com {
        Some(c) => cx.vector(&field("com"), c, 3, "x, y, z in the tip frame")?,
        None => DVector::zeros(3),
    };
    let inertia = match &section.inertia {
        Some(i) => {
            let v = cx.vector(&field("inertia"), i, 6, "ixx, ixy, ixz, iyy, iyz, izz")?;
            nalgebra::Matrix3::new(v[0], v[1], v[2], v[1], v[3], v[4], v[2], v[4], v[5])
        }
        None => nalgebra::Matrix3::zeros(),
    };
    let load = hcc_model::Load {
        mass: section.mass,
        com: Vector3::new(com[0], com[1], com[2]),
        inertia,
    };
    load.check(payload_limit).map_err(|e| {
        let f = match e {
            hcc_model::LoadError::Inertia(_) | hcc_model::LoadError::NotSymmetric => "inertia",
            _ => "mass",
        };
        cx.err(&field(f), e.to_string())
    })?;
    Ok(load)
}

/// `[initial]`: q0 (within the joint limits) and q̇0.
pub(crate) fn resolve_initial(
    cx: &Ctx,
    model: &Model,
    initial: &InitialSection,
) -> Result<(DVector<f64>, DVector<f64>), ConfigError> {
    let n = model.nq();
    let q0 = cx.vector("initial.q0", &initial.q0, n, "one per joint")?;
    let qd0 = match &initial.qd0 {
        Some(v) => cx.vector("initial.qd0", v, n, "one per joint")?,
        None => DVector::zeros(n),
    };
    for (k, j) in model.joints.iter().enumerate() {
        if q0[k] < j.lower - 1e-9 || q0[k] > j.upper + 1e-9 {
            return Err(cx.err(
                &format!("initial.q0[{k}]"),
                format!(
                    "{} is outside the limits [{}, {}] of joint '{}'",
                    q0[k], j.lower, j.upper, j.name
                ),
            ));
        }
    }
    Ok((q0, qd0))
}
