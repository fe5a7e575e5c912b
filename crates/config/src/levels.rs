//! `[[level]]`: the levels of the hierarchy in priority order, each stacking
//! its tasks with their gains and goal, and the dimension rules of the hierarchy.

use hcc_model::{FrameId, Model};
use hcc_spec::{LevelSpec, TaskSpec};
use nalgebra::{DMatrix, DVector};

use crate::context::Ctx;
use crate::error::ConfigError;
use crate::schema::{GainValue, LevelSection, LevelTasks, TaskKind, TaskTable};
use crate::tasks::{TaskKeys, resolve_task};

/// A level's gain (`what` = "stiffness" or "damping") over its stacked coordinates:
/// the level's own value, or block-diagonal from the value of every task table.
fn level_gain(
    cx: &Ctx,
    p: &str,
    what: &str,
    level: Option<&GainValue>,
    tasks: &[(Option<&GainValue>, usize)],
) -> Result<DMatrix<f64>, ConfigError> {
    let m: usize = tasks.iter().map(|t| t.1).sum();
    if let Some(g) = level {
        if let Some(k) = tasks.iter().position(|t| t.0.is_some()) {
            return Err(cx.err(
                &format!("{p}.task[{k}].{what}"),
                format!("is also given for the whole level: give the {what} once"),
            ));
        }
        return cx.gain(&format!("{p}.{what}"), g, m);
    }
    let mut out = DMatrix::zeros(m, m);
    let mut o = 0;
    for (k, (g, d)) in tasks.iter().enumerate() {
        let path = if tasks.len() == 1 && !cx.stacked {
            format!("{p}.{what}")
        } else {
            format!("{p}.task[{k}].{what}")
        };
        let g =
            g.ok_or_else(|| cx.err(&path, format!("is required (or a {what} for the level)")))?;
        out.view_mut((o, o), (*d, *d))
            .copy_from(&cx.gain(&path, g, *d)?);
        o += d;
    }
    Ok(out)
}

/// A level's goal: the level's own value or the tasks' goals stacked.
fn level_goal(
    cx: &Ctx,
    p: &str,
    level: Option<&Vec<f64>>,
    tasks: &[(Option<&Vec<f64>>, usize)],
) -> Result<DVector<f64>, ConfigError> {
    let m: usize = tasks.iter().map(|t| t.1).sum();
    if cx.trajectory {
        // The path's first row is the goal (crate::trajectories).
        let given = if level.is_some() {
            Some(format!("{p}.goal"))
        } else {
            let k = tasks.iter().position(|t| t.0.is_some());
            k.map(|k| match tasks.len() == 1 && !cx.stacked {
                true => format!("{p}.goal"),
                false => format!("{p}.task[{k}].goal"),
            })
        };
        if let Some(field) = given {
            return Err(cx.err(
                &field,
                "is given with a trajectory: give the level one of them",
            ));
        }
        return Ok(DVector::zeros(m));
    }
    if let Some(g) = level {
        if let Some(k) = tasks.iter().position(|t| t.0.is_some()) {
            return Err(cx.err(
                &format!("{p}.task[{k}].goal"),
                "is also given for the whole level: give the goal once",
            ));
        }
        return cx.vector(&format!("{p}.goal"), g, m, "the task dimension");
    }
    let mut out = DVector::zeros(m);
    let mut o = 0;
    for (k, (g, d)) in tasks.iter().enumerate() {
        let path = if tasks.len() == 1 && !cx.stacked {
            format!("{p}.goal")
        } else {
            format!("{p}.task[{k}].goal")
        };
        let g = g.ok_or_else(|| cx.err(&path, "is required (or a goal for the level)"))?;
        out.rows_mut(o, *d)
            .copy_from(&cx.vector(&path, g, *d, "the task dimension")?);
        o += d;
    }
    Ok(out)
}

pub(crate) fn resolve_level(
    cx: &Ctx,
    model: &Model,
    i: usize,
    l: &LevelSection,
) -> Result<LevelSpec, ConfigError> {
    let p = format!("level[{i}]");
    let cx = &Ctx {
        trajectory: l.trajectory.is_some(),
        ..*cx
    };
    let Stacked {
        tasks,
        stiffness,
        damping,
        goal,
    } = match &l.task {
        LevelTasks::Kind(kind) => single_task(cx, model, &p, l, *kind)?,
        LevelTasks::Stack(tables) => stacked_tasks(cx, model, &p, l, tables)?,
    };
    let name = l
        .name
        .clone()
        .unwrap_or_else(|| default_name(model, &tasks));
    Ok(LevelSpec {
        name,
        tasks,
        stiffness,
        damping,
        goal,
    })
}

/// A level's tasks with its gains and goal over their stacked coordinates.
struct Stacked {
    tasks: Vec<TaskSpec>,
    stiffness: DMatrix<f64>,
    damping: DMatrix<f64>,
    goal: DVector<f64>,
}

/// A level of one task (`task = "<kind>"`), whose keys stand on the level itself.
fn single_task(
    cx: &Ctx,
    model: &Model,
    p: &str,
    l: &LevelSection,
    kind: TaskKind,
) -> Result<Stacked, ConfigError> {
    let n = model.nq();
    let keys = TaskKeys {
        kind,
        frame: l.frame.as_ref(),
        axes: l.axes.as_ref(),
        joints: l.joints.as_ref(),
        weights: l.weights.as_ref(),
    };
    let task = resolve_task(cx, model, p, &keys)?;
    let m = task.dim(n);
    let stiffness = level_gain(cx, p, "stiffness", None, &[(l.stiffness.as_ref(), m)])?;
    let damping = level_gain(cx, p, "damping", None, &[(l.damping.as_ref(), m)])?;
    let goal = level_goal(cx, p, None, &[(l.goal.as_ref(), m)])?;
    Ok(Stacked {
        tasks: vec![task],
        stiffness,
        damping,
        goal,
    })
}

/// A level that stacks `[[level.task]]` tables, with per-task gains and goals or
/// one gain and goal for the whole level.
fn stacked_tasks(
    cx: &Ctx,
    model: &Model,
    p: &str,
    l: &LevelSection,
    tables: &[TaskTable],
) -> Result<Stacked, ConfigError> {
    let n = model.nq();
    for (field, present) in [
        ("frame", l.frame.is_some()),
        ("axes", l.axes.is_some()),
        ("joints", l.joints.is_some()),
        ("weights", l.weights.is_some()),
    ] {
        if present {
            return Err(cx.err(
                &format!("{p}.{field}"),
                "belongs in a [[level.task]] table when the level stacks tasks",
            ));
        }
    }
    if tables.is_empty() {
        return Err(cx.err(&format!("{p}.task"), "must hold at least one task"));
    }
    let mut tasks = Vec::with_capacity(tables.len());
    for (k, t) in tables.iter().enumerate() {
        let keys = TaskKeys {
            kind: t.kind,
            frame: t.frame.as_ref(),
            axes: t.axes.as_ref(),
            joints: t.joints.as_ref(),
            weights: t.weights.as_ref(),
        };
        tasks.push(resolve_task(cx, model, &format!("{p}.task[{k}]"), &keys)?);
    }
    let dims: Vec<usize> = tasks.iter().map(|t| t.dim(n)).collect();
    let cxs = Ctx {
        stacked: true,
        ..*cx
    };
    let gains = |f: fn(&TaskTable) -> Option<&GainValue>| -> Vec<(Option<&GainValue>, usize)> {
        tables.iter().zip(&dims).map(|(t, &d)| (f(t), d)).collect()
    };
    let stiffness = level_gain(
        &cxs,
        p,
        "stiffness",
        l.stiffness.as_ref(),
        &gains(|t| t.stiffness.as_ref()),
    )?;
    let damping = level_gain(
        &cxs,
        p,
        "damping",
        l.damping.as_ref(),
        &gains(|t| t.damping.as_ref()),
    )?;
    let goals: Vec<_> = tables
        .iter()
        .zip(&dims)
        .map(|(t, &d)| (t.goal.as_ref(), d))
        .collect();
    let goal = level_goal(&cxs, p, l.goal.as_ref(), &goals)?;
    Ok(Stacked {
        tasks,
        stiffness,
        damping,
        goal,
    })
}

fn default_name(model: &Model, tasks: &[TaskSpec]) -> String {
    const AX: [&str; 3] = ["x", "y", "z"];
    let frame = |f: &FrameId| model.frames[*f].name.clone();
    let names: Vec<String> = tasks
        .iter()
        .map(|t| match t {
            TaskSpec::Position { frame: f, axes } => {
                let a: String = axes.iter().map(|&k| AX[k]).collect();
                format!("{} position {a}", frame(f))
            }
            TaskSpec::Orientation { frame: f } => format!("{} orientation", frame(f)),
            TaskSpec::Pose { frame: f } => format!("{} pose", frame(f)),
            TaskSpec::PlanarOrientation { frame: f, axis } => {
                format!("{} rotation about {}", frame(f), AX[*axis])
            }
            TaskSpec::Posture => "joint posture".to_string(),
            TaskSpec::JointCombination { .. } => "joint combination".to_string(),
            TaskSpec::Joints { indices } => {
                let names: Vec<&str> = indices
                    .iter()
                    .map(|&j| model.joints[j].name.as_str())
                    .collect();
                format!("joint {}", names.join(", "))
            }
        })
        .collect();
    names.join(" + ")
}

/// Dimension rules of the hierarchy (Sec. II): every level but the last must leave a
/// null space, Σ_{i<r} m_i < n; the last level may be of any dimension.
pub(crate) fn check_hierarchy(cx: &Ctx, levels: &[LevelSpec], n: usize) -> Result<(), ConfigError> {
    let mut sum = 0;
    let r = levels.len();
    for (i, l) in levels.iter().enumerate() {
        let m = l.dim(n);
        if m > n {
            return Err(cx.err(
                &format!("level[{i}]"),
                format!("task dimension {m} exceeds the {n} joints of the robot"),
            ));
        }
        sum += m;
        if i + 1 < r && sum >= n {
            return Err(cx.err(
                &format!("level[{}]", i + 1),
                format!(
                    "no null space left: levels 1..{} already use {sum} of {n} degrees of freedom; only the last level may exhaust them",
                    i + 1
                ),
            ));
        }
    }
    Ok(())
}
