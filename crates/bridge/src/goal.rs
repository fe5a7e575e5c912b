//! The goal topic of each level: which ROS message type it takes, and how a
//! received message becomes the level's goal in its task coordinates (the
//! coordinates of the scenario TOML and of [`hcc_msgs::Setpoint`]).
//!
//! | level's tasks (scenario)               | goal type                          | goal coordinates |
//! |----------------------------------------|------------------------------------|------------------|
//! | `pose` (or position on x, y, z + orientation) | `geometry_msgs/msg/PoseStamped` | x, y, z, roll, pitch, yaw |
//! | `position` (the selected axes)         | `geometry_msgs/msg/PointStamped`   | the selected axes of the point |
//! | `orientation`                          | `geometry_msgs/msg/QuaternionStamped` | roll, pitch, yaw |
//! | joints, posture, joint combinations, planar orientation, other stacks | `std_msgs/msg/Float64MultiArray` | the m values as they are |
//!
//! Orientations: R_d = Rz(yaw) Ry(pitch) Rx(roll), as the controller reads
//! them (`hcc_control::TaskSpec::Orientation`); the quaternion must be of
//! unit norm within [`QUATERNION_NORM_TOLERANCE`] (it is normalised). The
//! frame id must be empty or the robot model's root link: the controller's
//! Cartesian goals are in that frame, and the bridge does not transform.

use hcc_config::Scenario;
use hcc_config::{LevelSpec, TaskSpec};
use nalgebra::{Quaternion, UnitQuaternion};

use crate::names::RosType;
use crate::ros::{self, GoalMsg};

/// Largest accepted deviation of a goal quaternion's norm from 1.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// What a level's goal topic takes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LevelKind {
    /// A 6-D pose: x, y, z, roll, pitch, yaw.
    Pose,
    /// A position on the listed axes (0 = x, 1 = y, 2 = z).
    Position { axes: Vec<usize> },
    /// An orientation: roll, pitch, yaw.
    Orientation,
    /// Anything else: `dim` values.
    Vector { dim: usize },
}

impl LevelKind {
    /// The kind of `level` of a robot with `n` joints.
    pub fn of(level: &LevelSpec, n: usize) -> LevelKind {
        match level.tasks.as_slice() {
            [TaskSpec::Pose { .. }] => LevelKind::Pose,
            [TaskSpec::Position { axes, .. }] => LevelKind::Position { axes: axes.clone() },
            [TaskSpec::Orientation { .. }] => LevelKind::Orientation,
            [
                TaskSpec::Position { axes, frame: a },
                TaskSpec::Orientation { frame: b },
            ] if axes.as_slice() == [0, 1, 2] && a == b => LevelKind::Pose,
            _ => LevelKind::Vector { dim: level.dim(n) },
        }
    }

    /// The message type of the goal topic.
    pub fn ros_type(&self) -> &'static RosType {
        match self {
            LevelKind::Pose => &ros::POSE_STAMPED,
            LevelKind::Position { .. } => &ros::POINT_STAMPED,
            LevelKind::Orientation => &ros::QUATERNION_STAMPED,
            LevelKind::Vector { .. } => &ros::FLOAT64_MULTI_ARRAY,
        }
    }
}

/// One level's goal topic.
#[derive(Debug, Clone)]
pub struct GoalLevel {
    /// Index of the level (0-based).
    pub index: usize,
    /// The ROS name of the level (the topic is `/<ns>/<name>/goal`).
    pub ros_name: String,
    /// What the topic takes.
    pub kind: LevelKind,
}

/// Why a goal message was refused by the bridge.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GoalError {
    /// The message type is not the level's.
    #[error("a {got} goal does not fit a {want} level")]
    Type {
        got: &'static str,
        want: &'static str,
    },
    /// The frame is not the root link.
    #[error("frame_id {got:?} is not the controller's frame {root:?} (or empty)")]
    Frame { got: String, root: String },
    /// The quaternion is not of unit norm.
    #[error("the quaternion's norm is {0}, not 1")]
    Quaternion(f64),
    /// A value is NaN or infinite.
    #[error("a goal value is NaN or infinite")]
    NonFinite,
    /// The array length is not the level's dimension.
    #[error("{got} values for a level of dimension {want}")]
    Length { got: usize, want: usize },
}

/// Roll, pitch, yaw of a quaternion (x, y, z, w), after the norm check.
fn rpy(q: [f64; 4]) -> Result<[f64; 3], GoalError> {
    let quat = Quaternion::new(q[3], q[0], q[1], q[2]);
    let norm = quat.norm();
    if !norm.is_finite() {
        return Err(GoalError::NonFinite);
    }
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(GoalError::Quaternion(norm));
    }
    let (roll, pitch, yaw) = UnitQuaternion::from_quaternion(quat).euler_angles();
    Ok([roll, pitch, yaw])
}

fn check_frame(frame: &str, root: &str) -> Result<(), GoalError> {
    if frame.is_empty() || frame == root {
        Ok(())
    } else {
        Err(GoalError::Frame {
            got: frame.into(),
            root: root.into(),
        })
    }
}

impl GoalLevel {
    /// The goal topics of a scenario's levels, named by `ros_names`.
    pub fn of_scenario(scenario: &Scenario, ros_names: &[String]) -> Vec<GoalLevel> {
        let n = scenario.model.nq();
        scenario
            .levels()
            .iter()
            .zip(ros_names)
            .enumerate()
            .map(|(index, (level, name))| GoalLevel {
                index,
                ros_name: name.clone(),
                kind: LevelKind::of(level, n),
            })
            .collect()
    }

    /// The level's goal (task coordinates) from a received message; `root`
    /// is the model's root link.
    pub fn goal(&self, msg: &GoalMsg, root: &str) -> Result<Vec<f64>, GoalError> {
        let goal = match (&self.kind, msg) {
            (
                LevelKind::Pose,
                GoalMsg::Pose {
                    frame,
                    position,
                    orientation,
                },
            ) => {
                check_frame(frame, root)?;
                let [r, p, y] = rpy(*orientation)?;
                vec![position[0], position[1], position[2], r, p, y]
            }
            (LevelKind::Position { axes }, GoalMsg::Point { frame, point }) => {
                check_frame(frame, root)?;
                axes.iter().map(|&a| point[a]).collect()
            }
            (LevelKind::Orientation, GoalMsg::Quaternion { frame, quaternion }) => {
                check_frame(frame, root)?;
                rpy(*quaternion)?.to_vec()
            }
            (LevelKind::Vector { dim }, GoalMsg::Array(data)) => {
                if data.len() != *dim {
                    return Err(GoalError::Length {
                        got: data.len(),
                        want: *dim,
                    });
                }
                data.clone()
            }
            (kind, msg) => {
                return Err(GoalError::Type {
                    got: type_of(msg),
                    want: kind.ros_type().name,
                });
            }
        };
        if goal.iter().all(|v| v.is_finite()) {
            Ok(goal)
        } else {
            Err(GoalError::NonFinite)
        }
    }
}

fn type_of(msg: &GoalMsg) -> &'static str {
    match msg {
        GoalMsg::Pose { .. } => ros::POSE_STAMPED.name,
        GoalMsg::Point { .. } => ros::POINT_STAMPED.name,
        GoalMsg::Quaternion { .. } => ros::QUATERNION_STAMPED.name,
        GoalMsg::Array(_) => ros::FLOAT64_MULTI_ARRAY.name,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    fn level(tasks: Vec<TaskSpec>) -> LevelSpec {
        LevelSpec {
            name: "l".into(),
            tasks,
            stiffness: DMatrix::zeros(0, 0),
            damping: DMatrix::zeros(0, 0),
            goal: DVector::zeros(0),
        }
    }

    fn goal_level(kind: LevelKind) -> GoalLevel {
        GoalLevel {
            index: 0,
            ros_name: "l".into(),
            kind,
        }
    }

    #[test]
    fn kinds_of_levels() {
        let f: usize = 3;
        assert_eq!(
            LevelKind::of(&level(vec![TaskSpec::Pose { frame: f }]), 7),
            LevelKind::Pose
        );
        let stacked = level(vec![
            TaskSpec::Position {
                frame: f,
                axes: vec![0, 1, 2],
            },
            TaskSpec::Orientation { frame: f },
        ]);
        assert_eq!(LevelKind::of(&stacked, 7), LevelKind::Pose);
        let pos = level(vec![TaskSpec::Position {
            frame: f,
            axes: vec![0, 2],
        }]);
        assert_eq!(
            LevelKind::of(&pos, 7),
            LevelKind::Position { axes: vec![0, 2] }
        );
        assert_eq!(
            LevelKind::of(&level(vec![TaskSpec::Orientation { frame: f }]), 7),
            LevelKind::Orientation
        );
        assert_eq!(
            LevelKind::of(&level(vec![TaskSpec::Posture]), 7),
            LevelKind::Vector { dim: 7 }
        );
        assert_eq!(
            LevelKind::Pose.ros_type().name,
            "geometry_msgs/msg/PoseStamped"
        );
    }

    #[test]
    fn pose_goals_become_xyz_rpy() {
        let (r, p, y) = (0.3, -0.4, 2.0);
        let q = UnitQuaternion::from_euler_angles(r, p, y);
        let msg = GoalMsg::Pose {
            frame: "base".into(),
            position: [0.5, 0.1, 0.4],
            orientation: [q.i, q.j, q.k, q.w],
        };
        let g = goal_level(LevelKind::Pose).goal(&msg, "base").unwrap();
        let want = [0.5, 0.1, 0.4, r, p, y];
        for (a, b) in g.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{g:?}");
        }
        // Another frame is refused; a non-unit quaternion too.
        assert!(matches!(
            goal_level(LevelKind::Pose).goal(&msg, "world"),
            Err(GoalError::Frame { .. })
        ));
        let bad = GoalMsg::Pose {
            frame: "".into(),
            position: [0.5, 0.1, 0.4],
            orientation: [0.0, 0.0, 0.0, 0.5],
        };
        assert_eq!(
            goal_level(LevelKind::Pose).goal(&bad, "base"),
            Err(GoalError::Quaternion(0.5))
        );
    }

    #[test]
    fn points_take_the_selected_axes_and_arrays_their_length() {
        let msg = GoalMsg::Point {
            frame: "".into(),
            point: [1.0, 2.0, 3.0],
        };
        let l = goal_level(LevelKind::Position { axes: vec![0, 2] });
        assert_eq!(l.goal(&msg, "base").unwrap(), [1.0, 3.0]);
        let v = goal_level(LevelKind::Vector { dim: 2 });
        assert_eq!(
            v.goal(&GoalMsg::Array(vec![1.0, 2.0]), "b").unwrap(),
            [1.0, 2.0]
        );
        assert_eq!(
            v.goal(&GoalMsg::Array(vec![1.0]), "b"),
            Err(GoalError::Length { got: 1, want: 2 })
        );
        assert_eq!(
            v.goal(&GoalMsg::Array(vec![1.0, f64::NAN]), "b"),
            Err(GoalError::NonFinite)
        );
        assert!(matches!(v.goal(&msg, "b"), Err(GoalError::Type { .. })));
        let o = goal_level(LevelKind::Orientation);
        let nan = GoalMsg::Quaternion {
            frame: "".into(),
            quaternion: [f64::NAN, 0.0, 0.0, 1.0],
        };
        assert_eq!(o.goal(&nan, "b"), Err(GoalError::NonFinite));
    }
}
