//! One task of a `[[level]]` (or of a `[[level.task]]` table) from the keys that
//! select what it measures: frame, axes, joints or weights.

use hcc_model::{FrameId, Model};
use hcc_spec::TaskSpec;
use nalgebra::DMatrix;

use crate::context::Ctx;
use crate::error::ConfigError;
use crate::schema::{AxisName, TaskKind};

/// The keys that select what one task measures: those of a single-task `[[level]]`
/// or of one `[[level.task]]` table.
pub(crate) struct TaskKeys<'a> {
    pub(crate) kind: TaskKind,
    pub(crate) frame: Option<&'a String>,
    pub(crate) axes: Option<&'a Vec<AxisName>>,
    pub(crate) joints: Option<&'a Vec<String>>,
    pub(crate) weights: Option<&'a Vec<Vec<f64>>>,
}

fn frame_of(
    cx: &Ctx,
    model: &Model,
    path: &str,
    name: Option<&String>,
) -> Result<FrameId, ConfigError> {
    let name = name.cloned().unwrap_or_else(|| model.tip_link.clone());
    match model.frame_id(&name) {
        Some(id) => Ok(id),
        None => Err(cx.err(
            path,
            format!("unknown link '{name}' (not on the chain of the robot model)"),
        )),
    }
}

/// One task from its keys; `p` is the dotted path of the table holding them.
pub(crate) fn resolve_task(
    cx: &Ctx,
    model: &Model,
    p: &str,
    t: &TaskKeys,
) -> Result<TaskSpec, ConfigError> {
    let f = |field: &str| format!("{p}.{field}");
    let unused = |field: &str, present: bool| -> Result<(), ConfigError> {
        if present {
            Err(cx.err(
                &f(field),
                format!("is not used by a task of kind {:?}", t.kind),
            ))
        } else {
            Ok(())
        }
    };
    if matches!(t.kind, TaskKind::Joint | TaskKind::JointCombination) {
        unused("frame", t.frame.is_some())?;
        unused("axes", t.axes.is_some())?;
    }
    if t.kind != TaskKind::Joint {
        unused("joints", t.joints.is_some())?;
    }
    if t.kind != TaskKind::JointCombination {
        unused("weights", t.weights.is_some())?;
    }
    Ok(match t.kind {
        TaskKind::Position => position_task(cx, model, p, t)?,
        TaskKind::Pose => {
            unused("axes", t.axes.is_some())?;
            TaskSpec::Pose {
                frame: frame_of(cx, model, &f("frame"), t.frame)?,
            }
        }
        TaskKind::Orientation => {
            let frame = frame_of(cx, model, &f("frame"), t.frame)?;
            match t.axes {
                None => TaskSpec::Orientation { frame },
                Some(a) if a.len() == 1 => TaskSpec::PlanarOrientation {
                    frame,
                    axis: a[0].index(),
                },
                Some(_) => {
                    return Err(cx.err(
                        &f("axes"),
                        "an orientation task takes either no axes (3-D) or exactly one (planar)",
                    ));
                }
            }
        }
        TaskKind::JointCombination => joint_combination_task(cx, model, p, t)?,
        TaskKind::Joint => match t.joints {
            None => TaskSpec::Posture,
            Some(names) => TaskSpec::Joints {
                indices: joint_indices(cx, model, p, names)?,
            },
        },
    })
}

/// A position task: the frame and the axes it measures (all three by default), each
/// at most once.
fn position_task(cx: &Ctx, model: &Model, p: &str, t: &TaskKeys) -> Result<TaskSpec, ConfigError> {
    let f = |field: &str| format!("{p}.{field}");
    let frame = frame_of(cx, model, &f("frame"), t.frame)?;
    let axes: Vec<usize> = match t.axes {
        None => vec![0, 1, 2],
        Some(a) => a.iter().map(|a| a.index()).collect(),
    };
    if axes.is_empty() {
        return Err(cx.err(&f("axes"), "must list at least one axis"));
    }
    for (k, a) in axes.iter().enumerate() {
        if axes[..k].contains(a) {
            return Err(cx.err(&f("axes"), "lists an axis twice"));
        }
    }
    Ok(TaskSpec::Position { frame, axes })
}

/// A joint-combination task: its rows of weights, one weight per joint.
fn joint_combination_task(
    cx: &Ctx,
    model: &Model,
    p: &str,
    t: &TaskKeys,
) -> Result<TaskSpec, ConfigError> {
    let f = |field: &str| format!("{p}.{field}");
    let n = model.nq();
    let rows = t
        .weights
        .ok_or_else(|| cx.err(&f("weights"), "is required for a joint_combination task"))?;
    if rows.is_empty() {
        return Err(cx.err(&f("weights"), "must have at least one row"));
    }
    for (k, row) in rows.iter().enumerate() {
        let rp = format!("{p}.weights[{k}]");
        if row.len() != n {
            return Err(cx.err(
                &rp,
                format!("has {} elements, expected {n} (one per joint)", row.len()),
            ));
        }
        cx.finite(&rp, row)?;
    }
    Ok(TaskSpec::JointCombination {
        weights: DMatrix::from_fn(rows.len(), n, |a, b| rows[a][b]),
    })
}

fn joint_indices(
    cx: &Ctx,
    model: &Model,
    p: &str,
    names: &[String],
) -> Result<Vec<usize>, ConfigError> {
    let mut idx = Vec::with_capacity(names.len());
    for (k, name) in names.iter().enumerate() {
        let jp = format!("{p}.joints[{k}]");
        match model.joints.iter().position(|j| &j.name == name) {
            Some(j) if !idx.contains(&j) => idx.push(j),
            Some(_) => return Err(cx.err(&jp, format!("joint '{name}' is listed twice"))),
            None => {
                return Err(cx.err(
                    &jp,
                    format!("unknown joint '{name}' (not a movable joint of the chain)"),
                ));
            }
        }
    }
    if idx.is_empty() {
        return Err(cx.err(&format!("{p}.joints"), "must list at least one joint"));
    }
    Ok(idx)
}
