//! The transform tree of the chain, as a 3-D viewer draws it: one transform
//! per URDF link of the model (parent link → child link, the tree of the
//! URDF's joints, values from the model's forward kinematics at the joint
//! state), and per hierarchy level the TCP frame of each Cartesian task (the
//! task frame's world pose) and its goal frame (the TCP pose with the task's
//! coordinates replaced by the active goal x_i,d(t) of the telemetry).
//!
//! Goals, as the controller holds them (see `hcc_control::TaskSpec`):
//! positions in m along world axes, orientations as roll, pitch, yaw with
//! R_d = Rz(yaw) Ry(pitch) Rx(roll), a planar orientation as an angle about a
//! world axis (its goal frame is the TCP turned by −x̃_i about that axis, so
//! that the angle wraps as the controller's error does).

use anyhow::{Context, bail};
use hcc_config::Scenario;
use hcc_control::TaskSpec;
use hcc_model::{Data, FrameId, Model};
use nalgebra::{DVector, Isometry3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};
use std::collections::HashMap;

/// Name of the fixed frame every other frame hangs from.
pub const WORLD: &str = "world";

/// One parent → child transform of the tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Transform {
    pub parent: String,
    pub child: String,
    /// Pose of the child frame in the parent frame.
    pub pose: Isometry3<f64>,
}

/// A link of the model and where it hangs in the URDF's tree.
#[derive(Clone, Debug)]
struct Link {
    frame: FrameId,
    /// The URDF parent link when it is a frame of the model, else the world.
    parent: Option<FrameId>,
}

/// The Cartesian tasks of one level on one frame: its TCP and goal frames.
#[derive(Clone, Debug)]
struct LevelFrame {
    /// 0-based level.
    level: usize,
    frame: FrameId,
    /// (task, row offset of the task in the level's coordinates).
    tasks: Vec<(TaskSpec, usize)>,
    tcp_name: String,
    goal_name: String,
}

/// Computes the transforms of a scenario's chain at joint states.
pub struct FrameTree {
    model: Model,
    data: Data,
    q: DVector<f64>,
    links: Vec<Link>,
    levels: Vec<LevelFrame>,
    out: Vec<Transform>,
    /// The chain as a polyline: root, every joint origin, the tip (world).
    points: Vec<Vector3<f64>>,
}

/// Parent link of every child link in the URDF text.
fn urdf_parents(urdf: &str) -> anyhow::Result<HashMap<String, String>> {
    let robot = urdf_rs::read_from_string(urdf).context("the URDF does not parse")?;
    Ok(robot
        .joints
        .into_iter()
        .map(|j| (j.child.link, j.parent.link))
        .collect())
}

impl FrameTree {
    /// The tree of `scenario`'s model, with the link tree of its URDF text `urdf`.
    pub fn new(scenario: &Scenario, urdf: &str) -> anyhow::Result<FrameTree> {
        let model = scenario.model.clone();
        let parents = urdf_parents(urdf)?;
        let links = (0..model.frames.len())
            .filter(|&f| model.frames[f].name != WORLD)
            .map(|f| Link {
                frame: f,
                parent: parents
                    .get(&model.frames[f].name)
                    .and_then(|p| model.frame_id(p)),
            })
            .collect();
        let n = model.nq();
        let mut levels = Vec::new();
        for (i, spec) in scenario.levels().iter().enumerate() {
            let mut offset = 0;
            let mut groups: Vec<LevelFrame> = Vec::new();
            for task in &spec.tasks {
                if let Some(frame) = task.frame() {
                    let name = &model.frames[frame].name;
                    match groups.iter_mut().find(|g| g.frame == frame) {
                        Some(g) => g.tasks.push((task.clone(), offset)),
                        None => groups.push(LevelFrame {
                            level: i,
                            frame,
                            tasks: vec![(task.clone(), offset)],
                            tcp_name: format!("level{}/{name}", i + 1),
                            goal_name: format!("level{}/{name}/goal", i + 1),
                        }),
                    }
                }
                offset += task.dim(n);
            }
            levels.extend(groups);
        }
        if model.frames.is_empty() {
            bail!("the model has no link frame");
        }
        Ok(FrameTree {
            data: Data::new(&model),
            q: DVector::zeros(n),
            model,
            links,
            levels,
            out: Vec::new(),
            points: Vec::new(),
        })
    }

    /// The model the tree is built from.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The transforms at joint positions `q`, with the goal frames of the
    /// levels whose active goal `goal(i)` (0-based level) and task error
    /// `error(i)` are known. `None` when `q` has the wrong length or a
    /// non-finite entry (nothing is drawn from a bad state).
    pub fn at<'a>(
        &mut self,
        q: &[f64],
        goal: impl Fn(usize) -> Option<(&'a [f64], &'a [f64])>,
    ) -> Option<&[Transform]> {
        if q.len() != self.q.len() || q.iter().any(|x| !x.is_finite()) {
            return None;
        }
        self.q.as_mut_slice().copy_from_slice(q);
        hcc_model::forward_kinematics(&self.model, &mut self.data, &self.q);
        self.out.clear();
        let world = |m: &Model, d: &Data, f: FrameId| hcc_model::frame_placement(m, d, f);
        for link in &self.links {
            let child = world(&self.model, &self.data, link.frame);
            let (parent, pose) = match link.parent {
                Some(p) => (
                    self.model.frames[p].name.clone(),
                    world(&self.model, &self.data, p).inv_mul(&child),
                ),
                None => (WORLD.to_string(), child),
            };
            self.out.push(Transform {
                parent,
                child: self.model.frames[link.frame].name.clone(),
                pose,
            });
        }
        for lf in &self.levels {
            let tcp = world(&self.model, &self.data, lf.frame);
            self.out.push(Transform {
                parent: WORLD.to_string(),
                child: lf.tcp_name.clone(),
                pose: tcp,
            });
            if let Some((goal, error)) = goal(lf.level)
                && let Some(pose) = goal_pose(&tcp, &lf.tasks, goal, error)
            {
                self.out.push(Transform {
                    parent: WORLD.to_string(),
                    child: lf.goal_name.clone(),
                    pose,
                });
            }
        }
        self.points.clear();
        let root = model_root(&self.model);
        self.points
            .push(world(&self.model, &self.data, root).translation.vector);
        self.points
            .extend(self.data.o_m_i.iter().map(|m| m.translation.vector));
        let tip = world(&self.model, &self.data, self.model.tip_frame());
        self.points.push(tip.translation.vector);
        Some(&self.out)
    }

    /// A point given in the tip frame, in the world, at the state of the
    /// last [`FrameTree::at`] (the load's centre of mass).
    pub fn tip_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let tip = hcc_model::frame_placement(&self.model, &self.data, self.model.tip_frame());
        tip.transform_point(&(*p).into()).coords
    }

    /// The chain as a polyline in the world (root link, every joint origin,
    /// the tip link) at the state of the last [`FrameTree::at`]: a stick
    /// figure of the arm for robots whose URDF has no visuals to draw.
    pub fn chain_points(&self) -> &[Vector3<f64>] {
        &self.points
    }

    /// Names of every frame the tree publishes (links, then TCP and goal frames).
    pub fn frame_names(&self) -> Vec<String> {
        let mut names: Vec<String> = self
            .links
            .iter()
            .map(|l| self.model.frames[l.frame].name.clone())
            .collect();
        for lf in &self.levels {
            names.push(lf.tcp_name.clone());
            names.push(lf.goal_name.clone());
        }
        names
    }
}

/// The frame of the root link (the first frame when it is missing).
fn model_root(model: &Model) -> FrameId {
    model.frame_id(&model.root_link).unwrap_or(0)
}

/// The goal pose of a frame: its TCP pose `tcp` with the coordinates of
/// `tasks` replaced by the level's `goal` (rows at each task's offset);
/// `None` when a row is missing or not finite.
fn goal_pose(
    tcp: &Isometry3<f64>,
    tasks: &[(TaskSpec, usize)],
    goal: &[f64],
    error: &[f64],
) -> Option<Isometry3<f64>> {
    let rows = |from: usize, len: usize, v: &[f64]| -> Option<Vec<f64>> {
        let r = v.get(from..from + len)?;
        r.iter().all(|x| x.is_finite()).then(|| r.to_vec())
    };
    let rpy = |r: &[f64]| {
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_euler_angles(r[0], r[1], r[2]))
    };
    let mut p: Vector3<f64> = tcp.translation.vector;
    let mut rot = tcp.rotation;
    for (task, o) in tasks {
        match task {
            TaskSpec::Position { axes, .. } => {
                let g = rows(*o, axes.len(), goal)?;
                for (k, &ax) in axes.iter().enumerate() {
                    p[ax] = g[k];
                }
            }
            TaskSpec::Pose { .. } => {
                let g = rows(*o, 6, goal)?;
                p = Vector3::new(g[0], g[1], g[2]);
                rot = rpy(&g[3..6]);
            }
            TaskSpec::Orientation { .. } => rot = rpy(&rows(*o, 3, goal)?),
            TaskSpec::PlanarOrientation { axis, .. } => {
                let e = rows(*o, 1, error)?;
                let mut a = Vector3::zeros();
                a[*axis] = 1.0;
                rot = UnitQuaternion::from_axis_angle(&Unit::new_normalize(a), -e[0]) * rot;
            }
            _ => {}
        }
    }
    Some(Isometry3::from_parts(Translation3::from(p), rot))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario(name: &str) -> (Scenario, String) {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let s = Scenario::load(root.join("config").join(name)).unwrap();
        let urdf = std::fs::read_to_string(&s.urdf_path).unwrap();
        (s, urdf)
    }

    /// The pose of `frame` in the world, composed along the published tree.
    fn compose(tf: &[Transform], frame: &str) -> Isometry3<f64> {
        let mut pose = Isometry3::identity();
        let mut at = frame.to_string();
        for _ in 0..100 {
            if at == WORLD {
                return pose;
            }
            let t = tf
                .iter()
                .find(|t| t.child == at)
                .unwrap_or_else(|| panic!("{at} not published"));
            pose = t.pose * pose;
            at = t.parent.clone();
        }
        panic!("the tree has a cycle at {frame}");
    }

    fn close(a: &Isometry3<f64>, b: &Isometry3<f64>) -> bool {
        (a.translation.vector - b.translation.vector).norm() < 1e-12
            && a.rotation.angle_to(&b.rotation) < 1e-9
    }

    /// Every link's pose composed along the tree, and every TCP frame, equal
    /// the model's forward kinematics at the same state.
    #[test]
    fn composed_transforms_equal_the_forward_kinematics() {
        for file in ["paper-sim1.toml", "panda-pose-posture.toml"] {
            let (s, urdf) = scenario(file);
            let mut tree = FrameTree::new(&s, &urdf).unwrap();
            let n = s.model.nq();
            let q: Vec<f64> = (0..n).map(|k| 0.3 - 0.17 * k as f64).collect();
            let tf = tree.at(&q, |_| None).unwrap().to_vec();
            let mut data = Data::new(&s.model);
            hcc_model::forward_kinematics(&s.model, &mut data, &DVector::from_column_slice(&q));
            for (f, frame) in s.model.frames.iter().enumerate() {
                if frame.name == WORLD {
                    continue;
                }
                let fk = hcc_model::frame_placement(&s.model, &data, f);
                assert!(
                    close(&compose(&tf, &frame.name), &fk),
                    "{file}: {}",
                    frame.name
                );
            }
            let tip = hcc_model::frame_placement(&s.model, &data, s.model.tip_frame());
            let tcp = format!("level1/{}", s.model.tip_link);
            assert!(close(&compose(&tf, &tcp), &tip), "{file}: {tcp}");
            // Links hang from their URDF parents, not all from the world.
            assert!(tf.iter().filter(|t| t.parent == WORLD).count() < s.model.frames.len());
        }
    }

    /// The goal frame of the paper's planar arm: the position goal on x, y
    /// (z of the TCP kept) and the planar angle turned back by the error.
    #[test]
    fn goal_frames_follow_the_goal_and_the_error() {
        let (s, urdf) = scenario("paper-sim1.toml");
        let mut tree = FrameTree::new(&s, &urdf).unwrap();
        let q = s.q0.as_slice().to_vec();
        let goal1 = [0.9, 0.8];
        let err1 = [0.0, 0.0];
        let goal2 = [-1.57];
        let err2 = [0.25];
        let tf = tree
            .at(&q, |i| match i {
                0 => Some((&goal1[..], &err1[..])),
                1 => Some((&goal2[..], &err2[..])),
                _ => None,
            })
            .unwrap()
            .to_vec();
        let tcp = compose(&tf, "level1/tcp");
        let g1 = compose(&tf, "level1/tcp/goal");
        assert_eq!(g1.translation.x, 0.9);
        assert_eq!(g1.translation.y, 0.8);
        assert_eq!(g1.translation.z, tcp.translation.z);
        let g2 = compose(&tf, "level2/tcp/goal");
        let turn = g2.rotation * tcp.rotation.inverse();
        assert!((turn.angle() - 0.25).abs() < 1e-12);
        assert!(
            (turn.axis().unwrap().z + 1.0).abs() < 1e-12,
            "turned about −z"
        );
        // Level 3 is a joint task: no frame of its own.
        assert!(!tf.iter().any(|t| t.child.starts_with("level3")));
    }

    /// An orientation goal is R_d = Rz(yaw) Ry(pitch) Rx(roll).
    #[test]
    fn pose_goals_are_roll_pitch_yaw() {
        let tcp = Isometry3::identity();
        let tasks = [(TaskSpec::Pose { frame: 0 }, 0)];
        let goal = [0.1, 0.2, 0.3, 0.4, -0.5, 0.6];
        let g = goal_pose(&tcp, &tasks, &goal, &[0.0; 6]).unwrap();
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.6)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), -0.5)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), 0.4);
        assert!(
            g.rotation
                .angle_to(&UnitQuaternion::from_rotation_matrix(&r))
                < 1e-12
        );
        assert_eq!(g.translation.vector, Vector3::new(0.1, 0.2, 0.3));
        assert!(goal_pose(&tcp, &tasks, &goal[..5], &[0.0; 6]).is_none());
        assert!(goal_pose(&tcp, &tasks, &[f64::NAN; 6], &[0.0; 6]).is_none());
    }

    /// The load's centre of mass: the tip pose (composed along the published
    /// tree) applied to the point in the tip frame.
    #[test]
    fn a_point_in_the_tip_frame_is_placed_by_the_tip_pose() {
        let (s, urdf) = scenario("panda-pose-posture.toml");
        let mut tree = FrameTree::new(&s, &urdf).unwrap();
        let q: Vec<f64> = s.q0.iter().map(|x| x + 0.1).collect();
        let tip = compose(tree.at(&q, |_| None).unwrap(), &s.model.tip_link);
        let com = Vector3::new(0.01, -0.02, 0.1);
        let want = tip * nalgebra::Point3::from(com);
        assert!((tree.tip_point(&com) - want.coords).norm() < 1e-12);
        let end = tree.chain_points()[tree.chain_points().len() - 1];
        assert!((tree.tip_point(&Vector3::zeros()) - end).norm() < 1e-15);
    }

    #[test]
    fn a_bad_state_draws_nothing() {
        let (s, urdf) = scenario("paper-sim1.toml");
        let mut tree = FrameTree::new(&s, &urdf).unwrap();
        assert!(tree.at(&[0.0; 3], |_| None).is_none());
        assert!(tree.at(&[0.0, f64::NAN, 0.0, 0.0], |_| None).is_none());
        assert!(tree.at(&[0.0; 4], |_| None).is_some());
    }
}
