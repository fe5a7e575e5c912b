//! Task terms of one level: the stacked Jacobian J_i and J̇_i (eq. 2), the task
//! error x̃_i, the potential V_i and its gradient. [`jacobian`] is the one place a
//! task Jacobian is assembled (the controller, the recorders and the checks use it).

use crate::spec::TaskSpec;
use hcc_linalg::products::gemv;
use hcc_model::{Data, FrameId, Model};
use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Scratch of [`jacobian`]: the 6 × n frame Jacobian and its time variation of the
/// last frame evaluated, and the world placement of the last frame formed. Consecutive
/// tasks on one frame (e.g. TCP position and orientation, their Jacobians and their
/// potentials) form them once per cycle; call [`FrameWork::invalidate`] when the state
/// in `Data` changes.
#[derive(Clone, Debug)]
pub struct FrameWork {
    j: DMatrix<f64>,
    jdot: DMatrix<f64>,
    /// The frame the buffers hold, and whether `jdot` is valid for it.
    cached: Option<(FrameId, bool)>,
    /// The last frame placed and its placement ([`hcc_model::frame_placement`]).
    placed: Option<(FrameId, Isometry3<f64>)>,
}

impl FrameWork {
    /// Buffers for a robot with `n` joints.
    pub fn new(n: usize) -> FrameWork {
        FrameWork {
            j: DMatrix::zeros(6, n),
            jdot: DMatrix::zeros(6, n),
            cached: None,
            placed: None,
        }
    }

    /// Forgets the cached frame (the state changed).
    pub fn invalidate(&mut self) {
        self.cached = None;
        self.placed = None;
    }

    /// The world placement of `frame` ([`hcc_model::frame_placement`]), formed once per
    /// state.
    pub fn placement(&mut self, model: &Model, data: &Data, frame: FrameId) -> Isometry3<f64> {
        if let Some((f, o_m)) = self.placed
            && f == frame
        {
            return o_m;
        }
        let o_m = hcc_model::frame_placement(model, data, frame);
        self.placed = Some((frame, o_m));
        o_m
    }

    fn load(&mut self, model: &Model, data: &Data, frame: FrameId, with_jdot: bool) {
        if let Some((f, d)) = self.cached
            && f == frame
            && (d || !with_jdot)
        {
            return;
        }
        let jdot = with_jdot.then_some(&mut self.jdot);
        let o_m = hcc_model::frame_jacobians(model, data, frame, &mut self.j, jdot);
        self.cached = Some((frame, with_jdot));
        self.placed = Some((frame, o_m));
    }
}

/// The stacked task Jacobian J_i of the tasks of a level (rows in task order, world
/// axes at the frame origin for Cartesian rows, angular-velocity rows for orientation)
/// into `j` (m_i × n), and J̇_i into `jdot` when given. Needs the kinematics of the
/// state in `data` (and its velocities for J̇). Allocation-free.
pub fn jacobian(
    model: &Model,
    data: &Data,
    tasks: &[TaskSpec],
    work: &mut FrameWork,
    j: &mut DMatrix<f64>,
    mut jdot: Option<&mut DMatrix<f64>>,
) {
    let n = model.nq();
    let mut o = 0;
    for task in tasks {
        let with_jdot = jdot.is_some();
        // Rows of the frame Jacobian this task takes (Cartesian tasks).
        let rows: (usize, usize, &[usize]) = match task {
            TaskSpec::Position { axes, .. } => (0, axes.len(), axes),
            TaskSpec::Orientation { .. } => (3, 3, &[]),
            TaskSpec::Pose { .. } => (0, 6, &[]),
            TaskSpec::PlanarOrientation { axis, .. } => (3 + axis, 1, &[]),
            _ => (0, 0, &[]),
        };
        if let Some(frame) = task.frame() {
            work.load(model, data, frame, with_jdot);
            let (first, count, select) = rows;
            for a in 0..count {
                let src = if select.is_empty() {
                    first + a
                } else {
                    select[a]
                };
                for b in 0..n {
                    j[(o + a, b)] = work.j[(src, b)];
                    if let Some(jd) = jdot.as_deref_mut() {
                        jd[(o + a, b)] = work.jdot[(src, b)];
                    }
                }
            }
            o += count;
            continue;
        }
        let m = task.dim(n);
        // A task of all the rows (a posture level): one contiguous fill.
        let zero = |x: &mut DMatrix<f64>| {
            if o == 0 && m == x.nrows() {
                x.as_mut_slice().fill(0.0);
            } else {
                x.rows_mut(o, m).fill(0.0);
            }
        };
        zero(j);
        if let Some(jd) = jdot.as_deref_mut() {
            zero(jd);
        }
        match task {
            TaskSpec::Joints { indices } => {
                for (a, &ix) in indices.iter().enumerate() {
                    j[(o + a, ix)] = 1.0;
                }
            }
            TaskSpec::JointCombination { weights } => j.rows_mut(o, m).copy_from(weights),
            _ => {
                for a in 0..m {
                    j[(o + a, a)] = 1.0;
                }
            }
        }
        o += m;
    }
}

/// Per-level buffers of the potential (preallocated by the controller).
#[derive(Clone, Debug)]
pub(crate) struct PotentialWork {
    /// R_d of each task with quaternion rows (identity for the others).
    pub goal_rotation: Vec<Rotation3<f64>>,
    /// (η, ε) of each task with quaternion rows.
    quat: Vec<(f64, Vector3<f64>)>,
    /// The stacked coordinate error e (quaternion rows: 2ε, goal axes) and K e.
    e: DVector<f64>,
    ke: DVector<f64>,
    /// With a shifted spring point ([`potential`]'s `shift`): the error at it,
    /// x̂ − x_d = x̃ − δ (quaternion rows: 2 R̂_d ε̂), the frames' rotations R and
    /// the shifted goal rotations R̂_d = exp(\[δ\]×) R_d.
    shifted_err: DVector<f64>,
    rotation: Vec<Rotation3<f64>>,
    shifted_rotation: Vec<Rotation3<f64>>,
}

impl PotentialWork {
    pub fn new(tasks: &[TaskSpec], goal: &DVector<f64>, n: usize) -> PotentialWork {
        let m = goal.len();
        let mut w = PotentialWork {
            goal_rotation: vec![Rotation3::identity(); tasks.len()],
            quat: vec![(1.0, Vector3::zeros()); tasks.len()],
            e: DVector::zeros(m),
            ke: DVector::zeros(m),
            shifted_err: DVector::zeros(m),
            rotation: vec![Rotation3::identity(); tasks.len()],
            shifted_rotation: vec![Rotation3::identity(); tasks.len()],
        };
        w.set_goal(tasks, goal.as_slice(), n);
        w
    }

    /// ½ eᵀ K e with the stiffness `k` (m × m) at the spring coordinates e of
    /// the last [`potential`] (quaternion rows 2ε; at the shifted spring point
    /// where there is one): V_i as it would be with K = `k`, V being linear
    /// in K. Allocation-free.
    pub fn spring_energy(&self, k: &DMatrix<f64>) -> f64 {
        let e = &self.e;
        let m = e.len().min(k.nrows()).min(k.ncols());
        let mut v = 0.0;
        for a in 0..m {
            for b in 0..m {
                v += e[a] * k[(a, b)] * e[b];
            }
        }
        0.5 * v
    }

    /// R_d from the roll-pitch-yaw part of the goal of every quaternion task.
    pub fn set_goal(&mut self, tasks: &[TaskSpec], goal: &[f64], n: usize) {
        let mut o = 0;
        for (t, task) in tasks.iter().enumerate() {
            if let Some(q) = task.quaternion_rows() {
                let g = &goal[o + q..o + q + 3];
                self.goal_rotation[t] = Rotation3::from_euler_angles(g[0], g[1], g[2]);
            }
            o += task.dim(n);
        }
    }
}

/// The task error x̃_i (`err`; quaternion rows 2 R_d ε ≈ the rotation vector, world
/// axes), V_i (returned) and its gradient conjugate to ẋ_i = J_i q̇ (`grad`; for
/// quaternion rows R_d (ηI + \[ε\]×) (K e)_rows, world axes) of one level at the
/// state in `data` (frame placements through `frames`, shared with the Jacobians). V_i = ½ eᵀ K e over the stacked errors e (e = 2ε for quaternion
/// rows): for a single orientation task V = 2 εᵀ K ε (the spec's potential).
///
/// `shift`: the spring point x̂ = x − δ of an energy tank ([`crate::energy_tank`];
/// δ in the coordinates of ẋ_i, world angular velocity on quaternion rows): V_i
/// and its gradient are then those at x̂ — the goal shifted by δ, R̂_d =
/// exp(\[δ\]×) R_d on quaternion rows — while `err` stays x̃_i = x − x_d. `None`
/// is the unshifted potential, bit for bit.
#[allow(clippy::too_many_arguments)]
pub(crate) fn potential(
    model: &Model,
    data: &Data,
    tasks: &[TaskSpec],
    frames: &mut FrameWork,
    q: &DVector<f64>,
    stiffness: &DMatrix<f64>,
    goal: &DVector<f64>,
    shift: Option<&DVector<f64>>,
    w: &mut PotentialWork,
    err: &mut DVector<f64>,
    grad: &mut DVector<f64>,
) -> f64 {
    let n = model.nq();
    let mut o = 0;
    for (t, task) in tasks.iter().enumerate() {
        let placement: Option<Isometry3<f64>> =
            task.frame().map(|f| frames.placement(model, data, f));
        let m = task.dim(n);
        let (goal, err) = (
            &goal.as_slice()[o..o + m],
            &mut err.as_mut_slice()[o..o + m],
        );
        task_error(task, placement.as_ref(), q, goal, err);
        if let Some(qr) = task.quaternion_rows() {
            let rot = placement.expect("frame task").rotation.to_rotation_matrix();
            w.quat[t] = quaternion_error(&w.goal_rotation[t], &rot, &mut err[qr..qr + 3]);
            w.rotation[t] = rot;
        }
        o += m;
    }
    let Some(delta) = shift else {
        let rotations = Rotations {
            quat: &w.quat,
            goal: &w.goal_rotation,
        };
        return spring(
            tasks, n, stiffness, &rotations, err, &mut w.e, &mut w.ke, grad,
        );
    };
    // The spring point x̂ = x − δ: the error at it, x̃ − δ (an angle wrapped),
    // and on quaternion rows the error against R̂_d = exp([δ]×) R_d.
    w.shifted_err.copy_from(err);
    w.shifted_err -= delta;
    let mut o = 0;
    for (t, task) in tasks.iter().enumerate() {
        if let TaskSpec::PlanarOrientation { .. } = task {
            w.shifted_err[o] = wrap_angle(w.shifted_err[o]);
        }
        if let Some(qr) = task.quaternion_rows() {
            let d = Vector3::new(delta[o + qr], delta[o + qr + 1], delta[o + qr + 2]);
            w.shifted_rotation[t] = Rotation3::new(d) * w.goal_rotation[t];
            let rows = &mut w.shifted_err.as_mut_slice()[o + qr..o + qr + 3];
            w.quat[t] = quaternion_error(&w.shifted_rotation[t], &w.rotation[t], rows);
        }
        o += task.dim(n);
    }
    let rotations = Rotations {
        quat: &w.quat,
        goal: &w.shifted_rotation,
    };
    let (e, ke) = (&mut w.e, &mut w.ke);
    spring(tasks, n, stiffness, &rotations, &w.shifted_err, e, ke, grad)
}

/// The quaternion tasks' (η, ε) and the goal rotations (R_d, or R̂_d at a
/// shifted spring point) they are taken against.
struct Rotations<'a> {
    quat: &'a [(f64, Vector3<f64>)],
    goal: &'a [Rotation3<f64>],
}

/// V = ½ eᵀ K e and its gradient conjugate to ẋ_i at the error `err`, the
/// quaternion rows from `r`; the spring's coordinates e (quaternion rows 2ε)
/// left in `e` ([`PotentialWork::spring_energy`]), `ke` scratch.
#[allow(clippy::too_many_arguments)]
fn spring(
    tasks: &[TaskSpec],
    n: usize,
    stiffness: &DMatrix<f64>,
    r: &Rotations<'_>,
    err: &DVector<f64>,
    e: &mut DVector<f64>,
    ke: &mut DVector<f64>,
    grad: &mut DVector<f64>,
) -> f64 {
    if let [TaskSpec::Orientation { .. }] = tasks {
        // V = 2 εᵀ K ε; its conjugate to ω (world) is R_d · 2 (ηI + [ε]×) K ε.
        let (eta, eps) = r.quat[0];
        let k = Matrix3::from_fn(|a, b| stiffness[(a, b)]);
        let keps = k * eps;
        let f_goal = 2.0 * (eta * keps + eps.cross(&keps));
        let g = r.goal[0] * f_goal;
        for a in 0..3 {
            grad[a] = g[a];
            e[a] = 2.0 * eps[a];
        }
        return 2.0 * eps.dot(&keps);
    }
    if tasks.iter().all(|t| t.quaternion_rows().is_none()) {
        // V = ½ x̃ᵀ K x̃ and ∂V/∂x = K x̃.
        e.copy_from(err);
        gemv(grad, 1.0, stiffness, err, 0.0);
        return 0.5 * err.dot(grad);
    }
    stacked_quaternion_potential(tasks, n, stiffness, r, err, e, ke, grad)
}

/// The error rows x̃ = x − x_d of one task (`goal`, `err`: its rows) at the
/// state (frame `placement`, joint positions `q`); a quaternion task's
/// rotation rows are left to [`quaternion_error`]. Allocation-free.
fn task_error(
    task: &TaskSpec,
    placement: Option<&Isometry3<f64>>,
    q: &DVector<f64>,
    goal: &[f64],
    err: &mut [f64],
) {
    let n = q.len();
    match task {
        TaskSpec::Position { axes, .. } => {
            let p = placement.expect("frame task").translation.vector;
            for (a, &ax) in axes.iter().enumerate() {
                err[a] = p[ax] - goal[a];
            }
        }
        TaskSpec::Pose { .. } => {
            let p = placement.expect("frame task").translation.vector;
            for a in 0..3 {
                err[a] = p[a] - goal[a];
            }
        }
        TaskSpec::PlanarOrientation { axis, .. } => {
            let rot = placement.expect("frame task").rotation.to_rotation_matrix();
            let m = rot.matrix();
            let angle = match axis {
                0 => m[(2, 1)].atan2(m[(1, 1)]),
                1 => m[(0, 2)].atan2(m[(2, 2)]),
                _ => m[(1, 0)].atan2(m[(0, 0)]),
            };
            err[0] = wrap_angle(angle - goal[0]);
        }
        TaskSpec::Joints { indices } => {
            for (a, &ix) in indices.iter().enumerate() {
                err[a] = q[ix] - goal[a];
            }
        }
        TaskSpec::JointCombination { weights } => {
            let m = weights.nrows();
            for a in 0..m {
                let mut s = 0.0;
                for b in 0..n {
                    s += weights[(a, b)] * q[b];
                }
                err[a] = s - goal[a];
            }
        }
        TaskSpec::Posture => {
            for a in 0..n {
                err[a] = q[a] - goal[a];
            }
        }
        TaskSpec::Orientation { .. } => {}
    }
}

/// The rotation rows e = 2 R_d ε (≈ the rotation vector, world axes) of the
/// error R_dᵀ R (shortest way: η ≥ 0) into `rows`; returns (η, ε).
fn quaternion_error(
    goal: &Rotation3<f64>,
    rot: &Rotation3<f64>,
    rows: &mut [f64],
) -> (f64, Vector3<f64>) {
    let quat = UnitQuaternion::from_rotation_matrix(&(goal.inverse() * rot));
    let (mut eta, mut eps) = (quat.w, quat.imag());
    if eta < 0.0 {
        eta = -eta;
        eps = -eps;
    }
    let e: Vector3<f64> = goal * (2.0 * eps);
    rows.copy_from_slice(e.as_slice());
    (eta, eps)
}

/// V = ½ eᵀ K e of a level with quaternion rows (e = 2ε there, x̃ elsewhere) and its
/// gradient: (K e) on the other rows, R_d (ηI + \[ε\]×) (K e) on the quaternion rows
/// (ė = (ηI − \[ε\]×) R_dᵀ ω, so this is the conjugate to the world ω).
#[allow(clippy::too_many_arguments)]
fn stacked_quaternion_potential(
    tasks: &[TaskSpec],
    n: usize,
    stiffness: &DMatrix<f64>,
    r: &Rotations<'_>,
    err: &DVector<f64>,
    e: &mut DVector<f64>,
    ke: &mut DVector<f64>,
    grad: &mut DVector<f64>,
) -> f64 {
    e.copy_from(err);
    let mut o = 0;
    for (t, task) in tasks.iter().enumerate() {
        if let Some(qr) = task.quaternion_rows() {
            let eps = r.quat[t].1;
            for a in 0..3 {
                e[o + qr + a] = 2.0 * eps[a];
            }
        }
        o += task.dim(n);
    }
    gemv(ke, 1.0, stiffness, e, 0.0);
    grad.copy_from(ke);
    let mut o = 0;
    for (t, task) in tasks.iter().enumerate() {
        if let Some(qr) = task.quaternion_rows() {
            let (eta, eps) = r.quat[t];
            let kei = Vector3::new(ke[o + qr], ke[o + qr + 1], ke[o + qr + 2]);
            let g = r.goal[t] * (eta * kei + eps.cross(&kei));
            for a in 0..3 {
                grad[o + qr + a] = g[a];
            }
        }
        o += task.dim(n);
    }
    0.5 * e.dot(ke)
}

fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut x = a % two_pi;
    if x > std::f64::consts::PI {
        x -= two_pi;
    } else if x <= -std::f64::consts::PI {
        x += two_pi;
    }
    x
}
