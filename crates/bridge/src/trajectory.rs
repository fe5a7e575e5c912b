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
//! the level's frame — with a transform per point. When every point carries
//! its `velocities` and `accelerations` (a time-parameterised MoveIt or
//! planner trajectory: a joint level's m values; a Cartesian level's first
//! twist, linear then angular, in the trajectory's frame), the points go as
//! samples with those derivatives (`hcc_msgs::PATH_DERIVATIVES`), so the
//! path keeps the planner's timing law between sparse points; otherwise
//! the controller interpolates its own from the knots. `effort` is not
//! used. `time_from_start` is the knot's time from when
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

/// A trajectory as read: its frame, joint names and points.
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryMsg {
    pub frame: String,
    pub joint_names: Vec<String>,
    pub points: Vec<Point>,
}

/// One point: its time (s), values (positions; or the first transform's
/// x y z, qx qy qz qw) and rates as sent (velocities, accelerations; or the
/// first twist of each: linear x y z, angular x y z; empty when not sent).
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub t: f64,
    pub values: Vec<f64>,
    pub velocities: Vec<f64>,
    pub accelerations: Vec<f64>,
}

/// Per knot: its velocity and its acceleration.
pub type Rates = (Vec<Vec<f64>>, Vec<Vec<f64>>);

/// A level's path from a trajectory: knot times, columns and, when every
/// point carries them, the knots' velocities and accelerations in the
/// level's goal-velocity coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Knots {
    pub times: Vec<f64>,
    pub points: Vec<Vec<f64>>,
    pub rates: Option<Rates>,
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
            let (mut values, mut velocities, mut accelerations, mut effort) =
                (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            r.seq_f64("points.positions", &mut values)?;
            r.seq_f64("points.velocities", &mut velocities)?;
            r.seq_f64("points.accelerations", &mut accelerations)?;
            r.seq_f64("points.effort", &mut effort)?;
            points.push(Point {
                t: duration(&mut r)?,
                values,
                velocities,
                accelerations,
            });
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
            let mut rates = [Vec::new(), Vec::new()];
            for (field, first_twist) in ["points.velocities", "points.accelerations"]
                .into_iter()
                .zip(&mut rates)
            {
                let twists = r.seq_len(field)?;
                for k in 0..6 * twists {
                    let v = r.f64(field)?;
                    if k < 6 {
                        first_twist.push(v);
                    }
                }
            }
            let [velocities, accelerations] = rates;
            points.push(Point {
                t: duration(&mut r)?,
                values: first,
                velocities,
                accelerations,
            });
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
) -> Result<Knots, PathError> {
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
    // One point's rates in the level's goal-velocity coordinates, if sent.
    let rates = |v: &[f64]| -> Option<Vec<f64>> {
        match kind {
            LevelKind::Vector { dim } => (v.len() == *dim).then(|| v.to_vec()),
            _ if v.len() < 6 => None,
            LevelKind::Position { axes } => Some(axes.iter().map(|&a| v[a]).collect()),
            LevelKind::Orientation => Some(v[3..6].to_vec()),
            LevelKind::Pose => Some(v[..6].to_vec()),
        }
    };
    let n = msg.points.len() + 1;
    let (mut times, mut points) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut velocities, mut accelerations) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut all_rates = true;
    if msg.points[0].t > 0.0 {
        times.push(0.0);
        points.push(goal_columns(kind, equilibrium));
        let zeros = vec![0.0; equilibrium.len()];
        velocities.push(zeros.clone());
        accelerations.push(zeros);
    }
    for (k, p) in msg.points.iter().enumerate() {
        times.push(p.t);
        points.push(columns(k, &p.values)?);
        match (rates(&p.velocities), rates(&p.accelerations)) {
            (Some(v), Some(a)) => {
                velocities.push(v);
                accelerations.push(a);
            }
            _ => all_rates = false,
        }
    }
    Ok(Knots {
        times,
        points,
        rates: all_rates.then_some((velocities, accelerations)),
    })
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
        let tv: Vec<_> = msg.points.iter().map(|p| (p.t, p.values.clone())).collect();
        assert_eq!(tv, vec![(0.5, vec![0.1, 0.2]), (1.5, vec![0.3, 0.4])]);
        let kind = LevelKind::Vector { dim: 2 };
        let names = ["j1".to_string(), "j2".to_string()];
        let k = knots(&msg, &kind, &names, "base", &[0.0, 0.1]).unwrap();
        assert_eq!(k.times, [0.0, 0.5, 1.5]);
        assert_eq!(k.points, [vec![0.0, 0.1], vec![0.1, 0.2], vec![0.3, 0.4]]);
        assert_eq!(k.rates, None, "no velocities sent: knots");
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
        let k = knots(&msg, &LevelKind::Pose, &[], "base", &[0.0; 6]).unwrap();
        assert_eq!(k.times, [0.0]);
        assert_eq!(k.points, [vec![0.5, 0.1, 0.3, 1.0, 0.0, 0.0, 0.0]]);
        let k = knots(
            &msg,
            &LevelKind::Position { axes: vec![0, 2] },
            &[],
            "base",
            &[0.0; 2],
        )
        .unwrap();
        assert_eq!(k.points, [vec![0.5, 0.3]]);
        assert!(matches!(
            knots(&msg, &LevelKind::Pose, &[], "world", &[0.0; 6]),
            Err(PathError::Frame { .. })
        ));
    }

    #[test]
    fn points_with_their_rates_become_samples() {
        // A joint trajectory whose points carry velocities and accelerations
        // (a time-parameterised plan), the first later than 0.
        let mut w = CdrWriter::new();
        w.start();
        header(&mut w, "");
        w.seq_string::<&str>(&[]);
        w.seq_len(2);
        for (k, (p, v, a)) in [
            ([0.1, 0.2], [0.3, 0.0], [1.0, 0.0]),
            ([0.2, 0.2], [0.0; 2], [0.0; 2]),
        ]
        .iter()
        .enumerate()
        {
            w.seq_f64(p).seq_f64(v).seq_f64(a).seq_f64(&[]);
            w.i32(k as i32 + 1).u32(0);
        }
        let msg = read_trajectory(&JOINT_TRAJECTORY, w.bytes()).unwrap();
        let kind = LevelKind::Vector { dim: 2 };
        let k = knots(&msg, &kind, &[], "base", &[0.1, 0.2]).unwrap();
        assert_eq!(k.times, [0.0, 1.0, 2.0]);
        let (v, a) = k.rates.unwrap();
        assert_eq!(v, [vec![0.0, 0.0], vec![0.3, 0.0], vec![0.0, 0.0]]);
        assert_eq!(a, [vec![0.0, 0.0], vec![1.0, 0.0], vec![0.0, 0.0]]);

        // A pose trajectory with twists: linear then angular.
        let mut w = CdrWriter::new();
        w.start();
        header(&mut w, "base");
        w.seq_string(&["tcp"]);
        w.seq_len(1);
        w.seq_len(1);
        for x in [0.5, 0.1, 0.3, 0.0, 0.0, 0.0, 1.0] {
            w.f64(x);
        }
        for twist in [
            [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
            [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        ] {
            w.seq_len(1);
            for x in twist {
                w.f64(x);
            }
        }
        w.i32(0).u32(0);
        let msg = read_trajectory(&MULTI_DOF_JOINT_TRAJECTORY, w.bytes()).unwrap();
        let k = knots(&msg, &LevelKind::Pose, &[], "base", &[0.0; 6]).unwrap();
        let (v, a) = k.rates.unwrap();
        assert_eq!(v, [vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]]);
        assert_eq!(a, [vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]]);
        let k = knots(&msg, &LevelKind::Orientation, &[], "base", &[0.0; 3]).unwrap();
        assert_eq!(k.rates.unwrap().0, [vec![0.4, 0.5, 0.6]]);
        let k = knots(
            &msg,
            &LevelKind::Position { axes: vec![1] },
            &[],
            "base",
            &[0.0],
        )
        .unwrap();
        assert_eq!(k.rates.unwrap().1, [vec![2.0]]);
    }
}
