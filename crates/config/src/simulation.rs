//! `[simulation]`: the in-process simulation (duration, rates, friction and
//! external wrenches).

use hcc_model::{FrameId, Model};
use nalgebra::{DVector, Vector3};

use crate::context::Ctx;
use crate::error::ConfigError;
use crate::schema::{SimulationSection, WrenchSection};

/// An external wrench of the simulation, resolved to a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Wrench {
    pub start_s: f64,
    pub duration_s: f64,
    pub link: String,
    pub frame_id: FrameId,
    pub force: Vector3<f64>,
    pub torque: Vector3<f64>,
}

/// Resolved `[simulation]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    pub duration_s: f64,
    pub integrator_dt_s: f64,
    /// Plant steps per control period (control period / integrator dt, an integer).
    pub substeps: usize,
    /// Viscous friction per joint.
    pub joint_friction: DVector<f64>,
    pub wrenches: Vec<Wrench>,
    /// What the plant's tip carries from a time on (`[[simulation.load]]`),
    /// by start time.
    pub loads: Vec<TimedLoad>,
}

/// A load the plant's tip takes at `start_s` (replacing the one before).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedLoad {
    pub start_s: f64,
    pub load: hcc_model::Load,
}

pub(crate) fn resolve_simulation(
    cx: &Ctx,
    model: &Model,
    s: &SimulationSection,
    rate_hz: f64,
) -> Result<Simulation, ConfigError> {
    if s.control_rate_hz.is_some() {
        return Err(cx.err(
            "simulation.control_rate_hz",
            "the control rate moved to [controller] rate_hz (the same value, in Hz): \
             move the line there",
        ));
    }
    let substeps = plant_substeps(cx, s, rate_hz)?;
    let n = model.nq();
    let joint_friction = match &s.joint_friction {
        Some(f) => cx.per_joint("simulation.joint_friction", f, n, false)?,
        None => DVector::zeros(n),
    };
    let mut wrenches = Vec::with_capacity(s.wrench.len());
    for (i, w) in s.wrench.iter().enumerate() {
        wrenches.push(resolve_wrench(cx, model, i, w)?);
    }
    let mut loads = Vec::with_capacity(s.load.len());
    for (i, l) in s.load.iter().enumerate() {
        let path = format!("simulation.load[{i}]");
        if !(l.start_s.is_finite() && l.start_s >= 0.0) {
            return Err(cx.err(&format!("{path}.start_s"), "must be a time ≥ 0 (s)"));
        }
        let load = crate::robot::tip_load(cx, &path, &l.load(), model.payload_limit)?;
        loads.push(TimedLoad {
            start_s: l.start_s,
            load,
        });
    }
    loads.sort_by(|a, b| a.start_s.total_cmp(&b.start_s));
    Ok(Simulation {
        duration_s: s.duration_s,
        integrator_dt_s: s.integrator_dt_s,
        substeps: substeps as usize,
        joint_friction,
        wrenches,
        loads,
    })
}

/// The times of `[simulation]`: positive, an integrator step that divides the
/// control period (of `[controller] rate_hz`, checked before), a duration of 1
/// to 1e8 control periods. Returns the plant steps per control period.
fn plant_substeps(cx: &Ctx, s: &SimulationSection, rate_hz: f64) -> Result<f64, ConfigError> {
    let positive = |name: &str, v: f64| -> Result<(), ConfigError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(cx.err(
                &format!("simulation.{name}"),
                format!("must be a positive finite number, got {v}"),
            ))
        }
    };
    positive("duration_s", s.duration_s)?;
    positive("integrator_dt_s", s.integrator_dt_s)?;
    let period = 1.0 / rate_hz;
    let ratio = period / s.integrator_dt_s;
    let substeps = ratio.round();
    if substeps < 1.0 || (ratio - substeps).abs() > 1e-6 * ratio {
        return Err(cx.err(
            "simulation.integrator_dt_s",
            format!(
                "{} s must divide the control period 1/{} Hz = {period} s into a whole number of steps",
                s.integrator_dt_s, rate_hz
            ),
        ));
    }
    if s.duration_s * rate_hz < 1.0 {
        return Err(cx.err(
            "simulation.duration_s",
            "is shorter than one control period",
        ));
    }
    if s.duration_s * rate_hz > 1e8 {
        return Err(cx.err(
            "simulation.duration_s",
            "is too long (more than 1e8 control cycles)",
        ));
    }
    Ok(substeps)
}

/// `[[simulation.wrench]]` number `i`, its link resolved to a frame.
fn resolve_wrench(
    cx: &Ctx,
    model: &Model,
    i: usize,
    w: &WrenchSection,
) -> Result<Wrench, ConfigError> {
    let p = |f: &str| format!("simulation.wrench[{i}].{f}");
    if !(w.start_s.is_finite() && w.start_s >= 0.0) {
        return Err(cx.err(&p("start_s"), "must be a finite non-negative time"));
    }
    if !(w.duration_s.is_finite() && w.duration_s >= 0.0) {
        return Err(cx.err(&p("duration_s"), "must be a finite non-negative duration"));
    }
    let frame_id = model.frame_id(&w.link).ok_or_else(|| {
        cx.err(
            &p("link"),
            format!("unknown link '{}' (not a link of the robot model)", w.link),
        )
    })?;
    let v3 = |name: &str, v: &Option<Vec<f64>>| -> Result<Vector3<f64>, ConfigError> {
        match v {
            None => Ok(Vector3::zeros()),
            Some(v) => {
                let d = cx.vector(&p(name), v, 3, "x, y, z in world axes")?;
                Ok(Vector3::new(d[0], d[1], d[2]))
            }
        }
    };
    Ok(Wrench {
        start_s: w.start_s,
        duration_s: w.duration_s,
        link: w.link.clone(),
        frame_id,
        force: v3("force", &w.force)?,
        torque: v3("torque", &w.torque)?,
    })
}
