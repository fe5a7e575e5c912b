//! Building a [`crate::Model`] from a URDF file or string (urdf-rs).
//!
//! The model is the serial chain from the root link to the tip link. Every
//! link reachable from the root becomes a [`Frame`]; links attached rigidly
//! (fixed joints) and whole subtrees hanging off the chain through movable
//! joints that are not on the chain (locked at q = 0, e.g. gripper fingers)
//! are lumped into the chain body they hang from: their inertia is added to it
//! and their frames move with it. Links above the root (when a root other
//! than the URDF's root is chosen) are ignored.
//!
//! Body frames are the URDF child-link frames of the movable chain joints, so
//! inertias and frame placements keep the URDF's link conventions. Limits:
//! continuous joints, and revolute/prismatic joints whose URDF gives neither
//! a lower nor an upper limit (both 0), get ±inf position limits; a missing
//! (0) effort or velocity limit becomes +inf.
//!
//! Validation (each failure a [`ModelError`] naming the file and element):
//! unique link and joint names, joints referring to existing links, one parent
//! per link, no cycles, a single root when none is given, tip strictly below
//! root, at least one movable joint on the chain, only revolute, continuous,
//! prismatic and fixed joints on the chain, finite non-zero axes and finite
//! origins, lower ≤ upper, and for every link of the model a finite
//! non-negative mass and a rotational inertia that is positive semidefinite
//! with principal moments obeying the triangle inequality (relative tolerance
//! 1e-9).

use crate::{Frame, Joint, JointKind, Model, ModelError, SpatialInertia};
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::path::Path;

/// Name used as "file" in errors of [`Model::from_urdf_str`].
pub const STRING_SOURCE: &str = "<urdf string>";

/// Default gravity, m/s² in world coordinates.
pub const DEFAULT_GRAVITY: Vector3<f64> = Vector3::new(0.0, 0.0, -9.81);

impl Model {
    /// Loads the chain from `root` (default: the URDF's root link) to `tip` from a URDF file.
    /// `gravity` defaults to (0, 0, −9.81) m/s².
    pub fn from_urdf_file(
        path: impl AsRef<Path>,
        root: Option<&str>,
        tip: &str,
        gravity: Option<Vector3<f64>>,
    ) -> Result<Model, ModelError> {
        let path = path.as_ref();
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ModelError::Io {
            file: file.clone(),
            source,
        })?;
        build(&text, &file, root, tip, gravity)
    }

    /// Same as [`Model::from_urdf_file`] for URDF text in memory; errors name
    /// the source as `<urdf string>`.
    pub fn from_urdf_str(
        urdf: &str,
        root: Option<&str>,
        tip: &str,
        gravity: Option<Vector3<f64>>,
    ) -> Result<Model, ModelError> {
        build(urdf, STRING_SOURCE, root, tip, gravity)
    }

    /// Total mass of the modelled chain bodies (excluding links rigidly attached to the root).
    pub fn total_mass(&self) -> f64 {
        self.joints.iter().map(|j| j.inertia.mass).sum()
    }
}

fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p.xyz.0[0], p.xyz.0[1], p.xyz.0[2]),
        UnitQuaternion::from_euler_angles(p.rpy.0[0], p.rpy.0[1], p.rpy.0[2]),
    )
}

fn pose_finite(p: &urdf_rs::Pose) -> bool {
    p.xyz.0.iter().chain(p.rpy.0.iter()).all(|v| v.is_finite())
}

/// Accumulates rigid bodies as (mass, first moment, inertia about the body origin).
#[derive(Clone, Copy)]
struct Accum {
    mass: f64,
    h: Vector3<f64>,
    i_o: Matrix3<f64>,
}

impl Accum {
    fn zero() -> Accum {
        Accum {
            mass: 0.0,
            h: Vector3::zeros(),
            i_o: Matrix3::zeros(),
        }
    }

    /// Adds mass `m` at `c` with inertia `ic` about its centre of mass (body axes),
    /// using the parallel-axis theorem.
    fn add(&mut self, m: f64, c: Vector3<f64>, ic: Matrix3<f64>) {
        self.mass += m;
        self.h += m * c;
        self.i_o += ic + m * (c.norm_squared() * Matrix3::identity() - c * c.transpose());
    }

    fn finish(self) -> SpatialInertia {
        let com = if self.mass > 0.0 {
            self.h / self.mass
        } else {
            Vector3::zeros()
        };
        let inertia = self.i_o
            - self.mass * (com.norm_squared() * Matrix3::identity() - com * com.transpose());
        SpatialInertia {
            mass: self.mass,
            com,
            inertia: 0.5 * (inertia + inertia.transpose()),
        }
    }
}

/// Checks mass ≥ 0, finite values, and that the rotational inertia is a
/// physically possible one: positive semidefinite with principal moments that
/// satisfy the triangle inequality (each ≤ the sum of the other two).
fn check_inertial(link: &urdf_rs::Link, file: &str) -> Result<(), ModelError> {
    let err = |reason: String| ModelError::InvalidInertial {
        file: file.to_string(),
        link: link.name.clone(),
        reason,
    };
    let inl = &link.inertial;
    let m = inl.mass.value;
    let i = &inl.inertia;
    let vals = [i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz];
    if !m.is_finite() || !vals.iter().all(|v| v.is_finite()) || !pose_finite(&inl.origin) {
        return Err(err("non-finite mass, inertia or origin".into()));
    }
    if m < 0.0 {
        return Err(err(format!("negative mass {m}")));
    }
    let ic = Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    crate::load::check_rotational_inertia(&ic).map_err(|e| err(e.to_string()))
}

/// A link waiting in the depth-first walk: its chain body, its placement in
/// the body frame, and the locked (off-chain movable) joint above it, if any.
struct Pending {
    link: usize,
    body: Option<usize>,
    placement: Isometry3<f64>,
    locked_by: Option<usize>,
}

/// The joint tree of a URDF: link indices by name, each link's parent joint and
/// each link's child joints (checked: unique names, known links, one parent per
/// link, no cycle).
struct Tree<'a> {
    robot: &'a urdf_rs::Robot,
    link_index: HashMap<&'a str, usize>,
    parent_joint: Vec<Option<usize>>,
    children: Vec<Vec<usize>>,
}

fn not_tree(file: &str, element: String, reason: &str) -> ModelError {
    ModelError::NotATree {
        file: file.to_string(),
        element,
        reason: reason.to_string(),
    }
}

impl<'a> Tree<'a> {
    fn new(robot: &'a urdf_rs::Robot, file: &str) -> Result<Tree<'a>, ModelError> {
        let mut link_index: HashMap<&str, usize> = HashMap::new();
        for (i, l) in robot.links.iter().enumerate() {
            if link_index.insert(l.name.as_str(), i).is_some() {
                return Err(not_tree(
                    file,
                    format!("link '{}'", l.name),
                    "duplicate link name",
                ));
            }
        }
        if robot.links.is_empty() {
            return Err(not_tree(file, "robot".into(), "no links"));
        }
        let mut joint_names: HashMap<&str, ()> = HashMap::new();
        let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
        let link = |name: &str, what: String| {
            link_index
                .get(name)
                .copied()
                .ok_or_else(|| ModelError::UnknownLink {
                    file: file.to_string(),
                    what,
                    link: name.to_string(),
                })
        };
        for (ji, j) in robot.joints.iter().enumerate() {
            if joint_names.insert(j.name.as_str(), ()).is_some() {
                return Err(not_tree(
                    file,
                    format!("joint '{}'", j.name),
                    "duplicate joint name",
                ));
            }
            let p = link(&j.parent.link, format!("parent of joint '{}'", j.name))?;
            let c = link(&j.child.link, format!("child of joint '{}'", j.name))?;
            if let Some(other) = parent_joint[c] {
                return Err(not_tree(
                    file,
                    format!("link '{}'", j.child.link),
                    &format!(
                        "has two parent joints '{}' and '{}'",
                        robot.joints[other].name, j.name
                    ),
                ));
            }
            parent_joint[c] = Some(ji);
            children[p].push(ji);
        }
        let tree = Tree {
            robot,
            link_index,
            parent_joint,
            children,
        };
        // Cycle check: walking up from any link must end at a parentless link.
        for start in 0..robot.links.len() {
            let mut l = start;
            let mut steps = 0;
            while let Some(j) = tree.parent_joint[l] {
                l = tree.parent_of(j);
                steps += 1;
                if steps > robot.links.len() {
                    return Err(not_tree(
                        file,
                        format!("link '{}'", robot.links[start].name),
                        "lies on a cycle of joints",
                    ));
                }
            }
        }
        Ok(tree)
    }

    /// The parent link of joint `j`.
    fn parent_of(&self, j: usize) -> usize {
        self.link_index[self.robot.joints[j].parent.link.as_str()]
    }

    /// The named root link, or the one parentless link.
    fn root(&self, root: Option<&str>, file: &str) -> Result<usize, ModelError> {
        if let Some(r) = root {
            return self
                .link_index
                .get(r)
                .copied()
                .ok_or_else(|| ModelError::UnknownLink {
                    file: file.to_string(),
                    what: "root".into(),
                    link: r.to_string(),
                });
        }
        let links = &self.robot.links;
        let roots: Vec<usize> = (0..links.len())
            .filter(|&l| self.parent_joint[l].is_none())
            .collect();
        if roots.len() != 1 {
            let names: Vec<&str> = roots.iter().map(|&l| links[l].name.as_str()).collect();
            return Err(not_tree(
                file,
                "robot".into(),
                &format!("expected one root link, found {}: {:?}", roots.len(), names),
            ));
        }
        Ok(roots[0])
    }

    /// Marks the joints on the chain from `root_idx` to the tip (of supported kinds).
    fn chain(&self, root_idx: usize, tip: &str, file: &str) -> Result<Vec<bool>, ModelError> {
        let robot = self.robot;
        let root_name = robot.links[root_idx].name.clone();
        let tip_idx = *self
            .link_index
            .get(tip)
            .ok_or_else(|| ModelError::UnknownLink {
                file: file.to_string(),
                what: "tip".into(),
                link: tip.to_string(),
            })?;
        let not_below = || ModelError::TipNotBelowRoot {
            file: file.to_string(),
            root: root_name.clone(),
            tip: tip.to_string(),
        };
        let mut chain: Vec<usize> = Vec::new();
        let mut l = tip_idx;
        while l != root_idx {
            let j = self.parent_joint[l].ok_or_else(not_below)?;
            chain.push(j);
            l = self.parent_of(j);
        }
        if chain.is_empty() {
            return Err(not_below());
        }
        let mut on_chain = vec![false; robot.joints.len()];
        for &j in chain.iter().rev() {
            on_chain[j] = true;
            let jt = &robot.joints[j];
            use urdf_rs::JointType as T;
            if !matches!(
                jt.joint_type,
                T::Revolute | T::Continuous | T::Prismatic | T::Fixed
            ) {
                return Err(ModelError::UnsupportedJoint {
                    file: file.to_string(),
                    joint: jt.name.clone(),
                    kind: format!("{:?}", jt.joint_type).to_lowercase(),
                });
            }
        }
        Ok(on_chain)
    }
}

/// A movable joint of the chain, placed at `placement` in its parent body.
fn chain_joint(
    j: &urdf_rs::Joint,
    placement: Isometry3<f64>,
    file: &str,
) -> Result<Joint, ModelError> {
    use urdf_rs::JointType as T;
    let kind = if matches!(j.joint_type, T::Prismatic) {
        JointKind::Prismatic
    } else {
        JointKind::Revolute
    };
    let axis = Vector3::new(j.axis.xyz.0[0], j.axis.xyz.0[1], j.axis.xyz.0[2]);
    let norm = axis.norm();
    if !(norm.is_finite() && norm > 1e-12) {
        return Err(ModelError::ZeroAxis {
            file: file.to_string(),
            joint: j.name.clone(),
        });
    }
    let lim = &j.limit;
    let (lower, upper) =
        if matches!(j.joint_type, T::Continuous) || (lim.lower == 0.0 && lim.upper == 0.0) {
            (f64::NEG_INFINITY, f64::INFINITY)
        } else {
            (lim.lower, lim.upper)
        };
    if lower.is_nan() || upper.is_nan() || lower > upper {
        return Err(ModelError::InvalidJoint {
            file: file.to_string(),
            joint: j.name.clone(),
            reason: format!("lower limit {lower} above upper limit {upper}"),
        });
    }
    let positive_or_inf = |v: f64| if v > 0.0 { v } else { f64::INFINITY };
    Ok(Joint {
        name: j.name.clone(),
        kind,
        placement,
        placement_rotation: *placement.rotation.to_rotation_matrix().matrix(),
        axis: axis / norm,
        inertia: SpatialInertia {
            mass: 0.0,
            com: Vector3::zeros(),
            inertia: Matrix3::zeros(),
        },
        lower,
        upper,
        velocity_limit: positive_or_inf(lim.velocity),
        effort_limit: positive_or_inf(lim.effort),
    })
}

/// The inertia of `link` (placed at `t_b_l` in its body) in body axes, added to `acc`.
fn add_link_inertia(acc: &mut Accum, link: &urdf_rs::Link, t_b_l: &Isometry3<f64>) {
    let inl = &link.inertial;
    let t_b_c = t_b_l * pose(&inl.origin);
    let i = &inl.inertia;
    let ic = Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    let r = t_b_c.rotation.to_rotation_matrix();
    let ic_b = r.matrix() * ic * r.matrix().transpose();
    acc.add(inl.mass.value, t_b_c.translation.vector, ic_b);
}

/// What the depth-first walk produces.
struct Walk {
    joints: Vec<Joint>,
    frames: Vec<Frame>,
    locked_joints: Vec<String>,
}

/// Depth-first walk from the root: every link is assigned to a chain body (its
/// inertia lumped into the body's, its frame recorded); movable joints off the chain
/// are locked.
fn walk(tree: &Tree, root_idx: usize, on_chain: &[bool], file: &str) -> Result<Walk, ModelError> {
    let robot = tree.robot;
    let mut joints: Vec<Joint> = Vec::new();
    let mut accum: Vec<Accum> = Vec::new();
    let mut frames: Vec<Frame> = Vec::new();
    let mut locked_joints: Vec<String> = Vec::new();
    let mut stack = vec![Pending {
        link: root_idx,
        body: None,
        placement: Isometry3::identity(),
        locked_by: None,
    }];
    while let Some(Pending {
        link: li,
        body,
        placement: t_b_l,
        locked_by,
    }) = stack.pop()
    {
        if let Some(ji) = locked_by {
            locked_joints.push(robot.joints[ji].name.clone());
        }
        let link = &robot.links[li];
        check_inertial(link, file)?;
        frames.push(Frame {
            name: link.name.clone(),
            body,
            placement: t_b_l,
        });
        if let Some(b) = body {
            add_link_inertia(&mut accum[b], link, &t_b_l);
        }
        // Push children in reverse so that frames come out in document order.
        for &ji in tree.children[li].iter().rev() {
            let j = &robot.joints[ji];
            if !pose_finite(&j.origin) {
                return Err(ModelError::InvalidJoint {
                    file: file.to_string(),
                    joint: j.name.clone(),
                    reason: "non-finite origin".into(),
                });
            }
            let child = tree.link_index[j.child.link.as_str()];
            let origin = pose(&j.origin);
            let movable = !matches!(j.joint_type, urdf_rs::JointType::Fixed);
            if on_chain[ji] && movable {
                joints.push(chain_joint(j, t_b_l * origin, file)?);
                accum.push(Accum::zero());
                stack.push(Pending {
                    link: child,
                    body: Some(joints.len() - 1),
                    placement: Isometry3::identity(),
                    locked_by: None,
                });
            } else {
                stack.push(Pending {
                    link: child,
                    body,
                    placement: t_b_l * origin,
                    locked_by: movable.then_some(ji),
                });
            }
        }
    }
    for (j, a) in joints.iter_mut().zip(accum) {
        j.inertia = a.finish();
    }
    Ok(Walk {
        joints,
        frames,
        locked_joints,
    })
}

fn build(
    text: &str,
    file: &str,
    root: Option<&str>,
    tip: &str,
    gravity: Option<Vector3<f64>>,
) -> Result<Model, ModelError> {
    let gravity = gravity.unwrap_or(DEFAULT_GRAVITY);
    if !gravity.iter().all(|v| v.is_finite()) {
        return Err(ModelError::InvalidGravity([
            gravity.x, gravity.y, gravity.z,
        ]));
    }
    let robot = urdf_rs::read_from_string(text).map_err(|e| ModelError::Parse {
        file: file.to_string(),
        message: e.to_string(),
    })?;
    let tree = Tree::new(&robot, file)?;
    let root_idx = tree.root(root, file)?;
    let root_name = robot.links[root_idx].name.clone();
    let on_chain = tree.chain(root_idx, tip, file)?;
    let w = walk(&tree, root_idx, &on_chain, file)?;
    if w.joints.is_empty() {
        return Err(ModelError::NoMovableJoint {
            file: file.to_string(),
            root: root_name,
            tip: tip.to_string(),
        });
    }
    let mut model = Model {
        name: robot.name.clone(),
        root_link: root_name,
        tip_link: tip.to_string(),
        joints: w.joints,
        frames: w.frames,
        gravity,
        locked_joints: w.locked_joints,
        load: crate::Load::none(),
        payload_limit: f64::INFINITY,
        unloaded_tip_body: SpatialInertia {
            mass: 0.0,
            com: Vector3::zeros(),
            inertia: Matrix3::zeros(),
        },
    };
    if let Some(body) = crate::load::tip_body(&model) {
        model.unloaded_tip_body = model.joints[body].inertia;
    }
    Ok(model)
}
