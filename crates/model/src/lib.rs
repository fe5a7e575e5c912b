//! Rigid-body kinematics and dynamics of a serial robot, in Pinocchio's shape:
//! an immutable [`Model`] built once from a URDF, a [`Data`] workspace that
//! preallocates every buffer, and free functions `algo(&model, &mut data, ...)`
//! that leave their result in `data` (or in a caller-provided output) and
//! never allocate after `Data::new`.
//!
//! Conventions (the same as Pinocchio's, so `../tests/data/panda_dynamics.json`
//! can be compared directly):
//! - `q`, `qd`, `tau` are in the order of the movable joints along the chain
//!   from the root link to the tip link; revolute/continuous joints in rad,
//!   prismatic in m.
//! - Frame Jacobians are 6×n, rows (vx, vy, vz, wx, wy, wz), world axes,
//!   reference point at the frame origin ("LOCAL_WORLD_ALIGNED").
//! - `C` is the Christoffel-symbol Coriolis matrix, `Ṁ = C + Cᵀ`.

pub mod algorithms;
pub mod error;
pub mod load;
pub mod urdf;

/// The dense linear algebra (Cholesky and the rest), from its one home `hcc-linalg`.
pub use hcc_linalg as linalg;

pub use algorithms::*;
pub use error::ModelError;
pub use load::{Load, LoadError, load_gravity, set_load};

use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Vector3, Vector6};

/// Index of a frame (a URDF link of the chain or of a locked subtree) in [`Model::frames`].
pub type FrameId = usize;

/// Kind of a movable joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// Revolute or continuous: rotation about `axis`.
    Revolute,
    /// Prismatic: translation along `axis`.
    Prismatic,
}

/// One movable joint of the chain and the rigid body it carries.
#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    /// Placement of the joint frame in the frame of the previous body (or of the root link).
    pub placement: Isometry3<f64>,
    /// The rotation of `placement` as a matrix, formed once when the model is built
    /// (the kinematics reads it every cycle; keep it in step when changing `placement`).
    pub placement_rotation: Matrix3<f64>,
    /// Unit axis in the joint frame.
    pub axis: Vector3<f64>,
    /// Inertia of everything rigidly attached after this joint and before the next movable
    /// joint of the chain (fixed children and locked subtrees lumped in), in the joint frame.
    pub inertia: SpatialInertia,
    /// Lower / upper position limit (−inf/+inf for continuous joints).
    pub lower: f64,
    pub upper: f64,
    /// Velocity limit (inf when the URDF gives none).
    pub velocity_limit: f64,
    /// Effort limit (inf when the URDF gives none).
    pub effort_limit: f64,
}

/// Mass, centre of mass and rotational inertia about the centre of mass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialInertia {
    pub mass: f64,
    /// Centre of mass in the body frame.
    pub com: Vector3<f64>,
    /// Rotational inertia about the centre of mass, body axes.
    pub inertia: Matrix3<f64>,
}

/// A named frame rigidly attached to a body of the chain (index `body`, `None` = the root link).
#[derive(Clone, Debug)]
pub struct Frame {
    pub name: String,
    pub body: Option<usize>,
    /// Placement of the frame in the body's joint frame.
    pub placement: Isometry3<f64>,
}

/// The immutable robot model: a serial chain from a root link to a tip link.
#[derive(Clone, Debug)]
pub struct Model {
    pub name: String,
    pub root_link: String,
    pub tip_link: String,
    /// Movable joints of the chain, root to tip; `joints.len()` is the number of DOF `n`.
    pub joints: Vec<Joint>,
    /// Every link of the chain (and of locked subtrees) as a frame.
    pub frames: Vec<Frame>,
    /// Gravity in world coordinates (default (0, 0, −9.81)).
    pub gravity: Vector3<f64>,
    /// Names of movable joints not on the chain that were locked at 0.
    pub locked_joints: Vec<String>,
    /// The load the tip frame carries ([`set_load`]; none from the URDF).
    pub load: Load,
    /// The heaviest load the tip may carry, kg (a URDF does not say:
    /// infinite unless the configuration gives it).
    pub payload_limit: f64,
    /// The inertia of the body that carries the tip frame, without the load
    /// (what [`set_load`] adds the load to).
    pub unloaded_tip_body: SpatialInertia,
}

/// Preallocated workspace for every algorithm of this crate. Create it once
/// with [`Data::new`]; the algorithms then never allocate.
#[derive(Clone, Debug)]
pub struct Data {
    /// World placement of each body (joint frame after the joint motion).
    pub o_m_i: Vec<Isometry3<f64>>,
    /// Spatial velocity of each body (algorithm-internal convention: world axes,
    /// `(v, ω)` with `v` the velocity of the body point at the world origin; see
    /// [`algorithms`]).
    pub v: Vec<Vector6<f64>>,
    /// Joint-space inertia matrix M (n×n), from [`crba`].
    pub m: DMatrix<f64>,
    /// Coriolis matrix C (n×n) with Ṁ = C + Cᵀ, from [`coriolis_matrix`].
    pub c: DMatrix<f64>,
    /// Gravity torques g (n), from [`gravity`].
    pub g: DVector<f64>,
    /// Nonlinear effects C q̇ + g (n), from [`nle`].
    pub nle: DVector<f64>,
    /// Joint torques from [`rnea`].
    pub tau: DVector<f64>,
    /// Joint accelerations from [`forward_dynamics`].
    pub qdd: DVector<f64>,
    /// Cholesky factor of M, from [`forward_dynamics`].
    pub m_chol: DMatrix<f64>,
    // Algorithm scratch space (spatial quantities per body, etc.) is added by the
    // implementation; every field is sized in `Data::new`.
    pub(crate) scratch: algorithms::Scratch,
}

impl Model {
    /// Number of degrees of freedom (movable joints on the chain).
    pub fn nq(&self) -> usize {
        self.joints.len()
    }

    /// Frame index of a link name.
    pub fn frame_id(&self, name: &str) -> Option<FrameId> {
        self.frames.iter().position(|f| f.name == name)
    }

    /// Frame index of the tip link.
    pub fn tip_frame(&self) -> FrameId {
        self.frame_id(&self.tip_link).expect("tip link is a frame")
    }

    /// Effort limits as a vector (inf where the URDF gives none).
    pub fn effort_limits(&self) -> DVector<f64> {
        DVector::from_iterator(self.nq(), self.joints.iter().map(|j| j.effort_limit))
    }
}
