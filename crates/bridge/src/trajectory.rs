//! The path topic of each level (`/<ns>/<level>/path`, docs/tracking.md):
//! a ROS 2 trajectory becomes the level's path knots (`hcc_msgs::PathKnots`,
//! sent through the bridge's client).
//!
//! | level's tasks                        | path type                                    | knot columns |
//! |--------------------------------------|----------------------------------------------|--------------|
//! | joints, posture, other vector levels | `trajectory_msgs/msg/JointTrajectory`        | `positions` (m values) |
//! | position, orientation, pose          | `trajectory_msgs/msg/MultiDOFJointTrajectory` | the first transform of each point: its translation (a position's axes), its rotation as w x y z |
//!
//! Why these: `JointTrajectory` is what MoveIt and ros2_control's
//! `joint_trajectory_controller` already send (`FollowJointTrajectory`), and
//! `MultiDOFJointTrajectory` is the standard message (`common_interfaces`,
//! no extra package) that MoveIt uses for multi-DOF joints: one "joint" —
//! the level's frame — with a transform per point. `velocities`,
//! `accelerations` and `effort` are not used: the controller interpolates
//! its own from the knots. `time_from_start` is the knot's time from when
//! the controller accepts the path; a trajectory whose first point comes
//! later than 0 (as a `joint_trajectory_controller` trajectory usually
//! does) starts from the level's equilibrium at 0. Joint names, when given,
//! must be the level's joints in its order; the frame id empty or the root
//! link.

use hcc_config::{LevelSpec, Scenario, TaskSpec};
use nalgebra::UnitQuaternion;

use crate::cdr::{CdrError, CdrReader};
use crate::goal::LevelKind;
use crate::names::RosType;

/// `trajectory_msgs/msg/JointTrajectory`.
pub const JOINT_TRAJECTORY: RosType = RosType {
    name: "trajectory_msgs/msg/JointTrajectory",
    hash: "RIHS01_179b33eba59d676f6d967ac71fe35e7ca2f64b2f3928f4a018cec115e213796e",
};
/// `trajectory_msgs/msg/MultiDOFJointTrajectory`.
pub const MULTI_DOF_JOINT_TRAJECTORY: RosType = RosType {
    name: "trajectory_msgs/msg/MultiDOFJointTrajectory",
    hash: "RIHS01_3a18fd095292a65cfde8833c72985a30af981f3ec44494655c6267262b443a4a",
};

/// A trajectory as read: its frame, joint names and, per point, its time (s)
/// and values (positions; or the first transform's x y z, qx qy qz qw).
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryMsg {
    pub frame: String,
    pub joint_names: Vec<String>,
    pub points: Vec<(f64, Vec<f64>)>,
}

/// The path type of a level of `kind`.
pub fn ros_type(kind: &LevelKind) -> &'static RosType {
    match kind {
        LevelKind::Vector { .. } => &JOINT_TRAJECTORY,
        _ => &MULTI_DOF_JOINT_TRAJECTORY,
    }
}

fn duration(r: &mut CdrReader) -> Result<f64, CdrError> {
    let sec = r.i32("time_from_start.sec")?;
    let nanosec = r.u32("time_from_start.nanosec")?;
    Ok(f64::from(sec) + f64::from(nanosec) * 1e-9)
}

fn strings(r: &mut CdrReader, field: &'static str) -> Result<Vec<String>, CdrError> {
    let n = r.seq_len(field)?;
    (0..n).map(|_| r.string(field).map(str::to_owned)).collect()
}

/// Reads a trajectory of type `ty` (one of the two path types).
pub fn read_trajectory(ty: &RosType, payload: &[u8]) -> Result<TrajectoryMsg, CdrError> {
    let mut r = CdrReader::new(payload)?;
    r.i32("header.stamp.sec")?;
    r.u32("header.stamp.nanosec")?;
    let frame = r.string("header.frame_id")?.to_owned();
    let joint_names = strings(&mut r, "joint_names")?;
    let n = r.seq_len("points")?;
    let mut points = Vec::with_capacity(n.min(4096));
    for _ in 0..n {
        if *ty == JOINT_TRAJECTORY {
            let mut positions = Vec::new();
            r.seq_f64("points.positions", &mut positions)?;
            let mut skip = Vec::new();
            for field in ["points.velocities", "points.accelerations", "points.effort"] {
                r.seq_f64(field, &mut skip)?;
            }
            points.push((duration(&mut r)?, positions));
        } else {
            let transforms = r.seq_len("points.transforms")?;
            let mut first = Vec::new();
            for k in 0..transforms {
                let mut v = Vec::with_capacity(7);
                for _ in 0..7 {
                    v.push(r.f64("points.transforms")?);
                }
                if k == 0 {
                    first = v;
                }
            }
            for field in ["points.velocities", "points.accelerations"] {
                let twists = r.seq_len(field)?;
                for _ in 0..6 * twists {
                    r.f64(field)?;
                }
            }
            points.push((duration(&mut r)?, first));
        }
    }
    Ok(TrajectoryMsg {
        frame,
        joint_names,
        points,
    })
}

/// A trajectory the level cannot take.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("frame_id {got:?} is not the controller's frame {root:?} (or empty)")]
    Frame { got: String, root: String },
    #[error("joint_names {got:?} are not the level's joints {want:?}")]
    Joints { got: Vec<String>, want: Vec<String> },
    #[error("point {0} has {1} values, the level takes {2}")]
    Length(usize, usize, usize),
    #[error("point {0} has no transform")]
    NoTransform(usize),
    #[error("the trajectory has no points")]
    Empty,
}

/// The level's joint names (a joint level's), for the check of `joint_names`.
pub fn joint_names(level: &LevelSpec, scenario: &Scenario) -> Vec<String> {
    let model = &scenario.model;
    let name = |j: usize| model.joints[j].name.clone();
    match level.tasks.as_slice() {
        [TaskSpec::Joints { indices }] => indices.iter().map(|&j| name(j)).collect(),
        [TaskSpec::Posture] => (0..model.nq()).map(name).collect(),
        _ => Vec::new(),
    }
}

/// The knots (t, columns) of `msg` for a level of `kind` (`joints`: its
/// joint names, empty for none) — starting with `equilibrium` (the level's
/// equilibrium in its goal format) at t = 0 when the first point comes later.
pub fn knots(
    msg: &TrajectoryMsg,
    kind: &LevelKind,
    joints: &[String],
    root: &str,
    equilibrium: &[f64],
) -> Result<(Vec<f64>, Vec<Vec<f64>>), PathError> {
    if !(msg.frame.is_empty() || msg.frame == root) {
        return Err(PathError::Frame {
            got: msg.frame.clone(),
            root: root.into(),
        });
    }
    if matches!(kind, LevelKind::Vector { .. })
        && !msg.joint_names.is_empty()
        && !joints.is_empty()
        && msg.joint_names != joints
    {
        return Err(PathError::Joints {
            got: msg.joint_names.clone(),
            want: joints.to_vec(),
        });
    }
    if msg.points.is_empty() {
        return Err(PathError::Empty);
    }
    // One point's columns from the message's values (positions, or x y z
    // qx qy qz qw).
    let columns = |k: usize, v: &[f64]| -> Result<Vec<f64>, PathError> {
        let quat = |v: &[f64]| vec![v[6], v[3], v[4], v[5]];
        match kind {
            LevelKind::Vector { dim } if v.len() == *dim => Ok(v.to_vec()),
            LevelKind::Vector { dim } => Err(PathError::Length(k, v.len(), *dim)),
            _ if v.len() < 7 => Err(PathError::NoTransform(k)),
            LevelKind::Position { axes } => Ok(axes.iter().map(|&a| v[a]).collect()),
            LevelKind::Orientation => Ok(quat(v)),
            LevelKind::Pose => Ok([&v[..3], &quat(v)[..]].concat()),
        }
    };
    let mut times = Vec::with_capacity(msg.points.len() + 1);
    let mut points = Vec::with_capacity(msg.points.len() + 1);
    if msg.points[0].0 > 0.0 {
        times.push(0.0);
        points.push(goal_columns(kind, equilibrium));
    }
    for (k, (t, v)) in msg.points.iter().enumerate() {
        times.push(*t);
        points.push(columns(k, v)?);
    }
    Ok((times, points))
}

/// A goal (the level's goal format: roll, pitch, yaw for orientations) in
/// the path's columns (w x y z).
fn goal_columns(kind: &LevelKind, goal: &[f64]) -> Vec<f64> {
    let wxyz = |rpy: &[f64]| {
        let q = UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]);
        vec![q.w, q.i, q.j, q.k]
    };
    match kind {
        LevelKind::Orientation => wxyz(&goal[..3]),
        LevelKind::Pose => [&goal[..3], &wxyz(&goal[3..6])[..]].concat(),
        _ => goal.to_vec(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdr::CdrWriter;

    fn header(w: &mut CdrWriter, frame: &str) {
        w.i32(1).u32(2).string(frame);
    }

    #[test]
    fn joint_and_multi_dof_trajectories_become_knots() {
        let mut w = CdrWriter::new();
        w.start();
        header(&mut w, "");
        w.seq_string(&["j1", "j2"]);
        w.seq_len(2);
        for (k, p) in [[0.1, 0.2], [0.3, 0.4]].iter().enumerate() {
            w.seq_f64(p).seq_f64(&[]).seq_f64(&[]).seq_f64(&[]);
            w.i32(k as i32).u32(500_000_000);
        }
        let msg = read_trajectory(&JOINT_TRAJECTORY, w.bytes()).unwrap();
        assert_eq!(msg.joint_names, ["j1", "j2"]);
        assert_eq!(
            msg.points,
            vec![(0.5, vec![0.1, 0.2]), (1.5, vec![0.3, 0.4])]
        );
        let kind = LevelKind::Vector { dim: 2 };
        let names = ["j1".to_string(), "j2".to_string()];
        let (t, p) = knots(&msg, &kind, &names, "base", &[0.0, 0.1]).unwrap();
        assert_eq!(t, [0.0, 0.5, 1.5]);
        assert_eq!(p, [vec![0.0, 0.1], vec![0.1, 0.2], vec![0.3, 0.4]]);
        let other = ["a".to_string(), "b".to_string()];
        assert!(matches!(
            knots(&msg, &kind, &other, "base", &[0.0; 2]),
            Err(PathError::Joints { .. })
        ));

        let mut w = CdrWriter::new();
        w.start();
        header(&mut w, "base");
        w.seq_string(&["tcp"]);
        w.seq_len(1);
        w.seq_len(1);
        for v in [0.5, 0.1, 0.3, 0.0, 0.0, 0.0, 1.0] {
            w.f64(v);
        }
        w.seq_len(0).seq_len(0);
        w.i32(0).u32(0);
        let msg = read_trajectory(&MULTI_DOF_JOINT_TRAJECTORY, w.bytes()).unwrap();
        let (t, p) = knots(&msg, &LevelKind::Pose, &[], "base", &[0.0; 6]).unwrap();
        assert_eq!(t, [0.0]);
        assert_eq!(p, [vec![0.5, 0.1, 0.3, 1.0, 0.0, 0.0, 0.0]]);
        let (_, p) = knots(
            &msg,
            &LevelKind::Position { axes: vec![0, 2] },
            &[],
            "base",
            &[0.0; 2],
        )
        .unwrap();
        assert_eq!(p, [vec![0.5, 0.3]]);
        assert!(matches!(
            knots(&msg, &LevelKind::Pose, &[], "world", &[0.0; 6]),
            Err(PathError::Frame { .. })
        ));
    }
}
