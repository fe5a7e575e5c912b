//! The algorithms. Each is a free function over an immutable [`Model`] and a
//! preallocated [`Data`]; none allocates.
//!
//! The joint-space dynamics are those of the paper's eq. (1),
//! `M(q) q̈ + C(q, q̇) q̇ + g(q) = τ + τ_ext`, with `C` satisfying `Ṁ = C + Cᵀ`.
//!
//! Spatial-vector algebra after Featherstone, "Rigid Body Dynamics Algorithms"
//! (Springer 2008, "RBDA"), with every spatial quantity expressed in **world
//! coordinates at the world origin** (RBDA Ch. 2, spatial vectors in a single fixed
//! frame, the ground-frame variant of the recursions):
//! - a motion vector is `(v, ω)` (linear first): `ω` the angular velocity and
//!   `v` the velocity of the body-fixed point that momentarily coincides with
//!   the world origin;
//! - a force vector is `(f, n)`: force and moment about the world origin;
//! - the motion subspace of joint i is `S_i = (p_i × z_i, z_i)` (revolute,
//!   `z_i` world axis through `p_i`) or `(z_i, 0)` (prismatic); its time
//!   derivative is `Ṡ_i = v_i × S_i`;
//! - body velocities are plain sums `v_i = v_{i−1} + S_i q̇_i`, composite
//!   inertias plain sums of world inertias.
//!
//! With `n` bodies on a serial chain the recursions reduce to the loops below
//! (each body's parent is the previous one).
//!
//! Bad input (state vectors or outputs of the wrong size, an unknown frame)
//! never panics: results are filled with NaN (functions without a `Result`) or
//! an error is returned ([`forward_dynamics`]). [`Model::check_state`] checks
//! sizes up front.

use crate::linalg::{cholesky_in_place, cholesky_solve_in_place};
use crate::{Data, FrameId, JointKind, Model, ModelError, SpatialInertia};
use nalgebra::{
    ArrayStorage, DMatrix, DVector, Isometry3, Matrix3, Point3, Rotation3, Translation3,
    UnitQuaternion, Vector3, Vector6,
};

/// Per-body scratch buffers used by the recursive algorithms (sized in `Data::new`).
/// All spatial quantities are world-frame (see the module documentation).
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    /// Motion subspace `S_i` of each joint.
    s: Vec<Vector6<f64>>,
    /// Its time derivative `Ṡ_i = v_i × S_i`.
    sdot: Vec<Vector6<f64>>,
    /// Velocity-product (bias) acceleration `Σ_{j≤i} Ṡ_j q̇_j` of each body (no gravity).
    abias: Vec<Vector6<f64>>,
    /// Accelerations of the RNEA pass.
    a: Vec<Vector6<f64>>,
    /// Forces of the RNEA pass.
    f: Vec<Vector6<f64>>,
    /// Spatial inertia of each body.
    inertia: Vec<BodyInertia>,
    /// Composite inertia `Σ_{k≥i} I_k`.
    ic: Vec<BodyInertia>,
    /// `Ic_i S_i`, `Bc_iᵀ S_i`, `Ic_i Ṡ_i + Bc_i S_i` per body (Coriolis matrix, `Bc_i = Σ_{k≥i} B_k`).
    ics: Vec<Vector6<f64>>,
    bcts: Vec<Vector6<f64>>,
    w: Vec<Vector6<f64>>,
    /// (sin q_i, cos q_i) of the revolute joints.
    sin_cos: Vec<(f64, f64)>,
    /// `S_k`, `Ic_k S_k` and `Bc_kᵀ S_k` component by component (18 runs of n: element
    /// c of the vector of body k at `c n + k`), for the Coriolis fill down the columns.
    by_component: Vec<f64>,
}

impl Data {
    /// Allocates every buffer the algorithms need for `model`.
    pub fn new(model: &Model) -> Data {
        let n = model.nq();
        let v6 = vec![Vector6::zeros(); n];
        let i6 = vec![BodyInertia::default(); n];
        Data {
            o_m_i: vec![Isometry3::identity(); n],
            v: v6.clone(),
            m: DMatrix::zeros(n, n),
            c: DMatrix::zeros(n, n),
            g: DVector::zeros(n),
            nle: DVector::zeros(n),
            tau: DVector::zeros(n),
            qdd: DVector::zeros(n),
            m_chol: DMatrix::zeros(n, n),
            scratch: Scratch {
                s: v6.clone(),
                sdot: v6.clone(),
                abias: v6.clone(),
                a: v6.clone(),
                f: v6.clone(),
                inertia: i6.clone(),
                ic: i6,
                ics: v6.clone(),
                bcts: v6.clone(),
                w: v6,
                sin_cos: vec![(0.0, 1.0); n],
                by_component: vec![0.0; 18 * n],
            },
        }
    }

    /// Number of bodies this workspace was sized for.
    pub fn nq(&self) -> usize {
        self.o_m_i.len()
    }
}

impl Model {
    /// Checks that `q` (and `qd`, `tau` where given) have length [`Model::nq`].
    pub fn check_state(
        &self,
        q: &DVector<f64>,
        qd: Option<&DVector<f64>>,
        tau: Option<&DVector<f64>>,
    ) -> Result<(), ModelError> {
        let n = self.nq();
        let check = |what: &'static str, got: usize| {
            if got == n {
                Ok(())
            } else {
                Err(ModelError::Dimension {
                    what,
                    expected: n,
                    got,
                })
            }
        };
        check("q", q.len())?;
        if let Some(qd) = qd {
            check("qd", qd.len())?;
        }
        if let Some(tau) = tau {
            check("tau", tau.len())?;
        }
        Ok(())
    }

    /// Kinetic plus potential energy ½ q̇ᵀ M q̇ − Σ mᵢ gᵀ cᵢ for (`q`, `qd`), with M in
    /// `data.m` from [`crba`] (or [`compute_all_terms`]) at the same `q`.
    /// Needs [`forward_kinematics`] at `q`. Potential zero at the world origin.
    pub fn energy(&self, data: &Data, qd: &DVector<f64>) -> f64 {
        let n = self.nq();
        if qd.len() != n || data.nq() != n {
            return f64::NAN;
        }
        let mut kinetic = 0.0;
        for i in 0..n {
            for j in 0..n {
                kinetic += 0.5 * qd[i] * data.m[(i, j)] * qd[j];
            }
        }
        let mut potential = 0.0;
        for (joint, o_m) in self.joints.iter().zip(&data.o_m_i) {
            let c = o_m * Point3::from(joint.inertia.com);
            potential -= joint.inertia.mass * self.gravity.dot(&c.coords);
        }
        kinetic + potential
    }
}

// 3×3 products written out on the column-major arrays: the same as nalgebra's
// in release builds, and much faster in unoptimised (test) builds.

fn mat3(a: [[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_array_storage(ArrayStorage(a))
}

/// `a b`.
fn mul33(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let (a, b) = (&a.data.0, &b.data.0);
    let mut out = [[0.0; 3]; 3];
    for (col, oc) in out.iter_mut().enumerate() {
        for (row, x) in oc.iter_mut().enumerate() {
            *x = a[0][row] * b[col][0] + a[1][row] * b[col][1] + a[2][row] * b[col][2];
        }
    }
    mat3(out)
}

/// `a bᵀ`.
fn mul33t(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let (a, b) = (&a.data.0, &b.data.0);
    let mut out = [[0.0; 3]; 3];
    for (col, oc) in out.iter_mut().enumerate() {
        for (row, x) in oc.iter_mut().enumerate() {
            *x = a[0][row] * b[0][col] + a[1][row] * b[1][col] + a[2][row] * b[2][col];
        }
    }
    mat3(out)
}

/// `a v`.
fn mul3v(a: &Matrix3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let a = &a.data.0;
    let v = &v.data.0[0];
    Vector3::new(
        a[0][0] * v[0] + a[1][0] * v[1] + a[2][0] * v[2],
        a[0][1] * v[0] + a[1][1] * v[1] + a[2][1] * v[2],
        a[0][2] * v[0] + a[1][2] * v[1] + a[2][2] * v[2],
    )
}

/// `aᵀ v`.
fn mul3tv(a: &Matrix3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let a = &a.data.0;
    let v = &v.data.0[0];
    Vector3::new(
        a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
        a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
        a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
    )
}

/// Rotation by the angle θ with (`s`, `c`) = (sin θ, cos θ) about the unit `axis`
/// (Rodrigues' formula, `R = cos θ 1 + sin θ [a]× + (1 − cos θ) a aᵀ`).
fn axis_angle(axis: &Vector3<f64>, (s, c): (f64, f64)) -> Matrix3<f64> {
    let a = &axis.data.0[0];
    let t = 1.0 - c;
    mat3([
        [
            c + t * a[0] * a[0],
            t * a[1] * a[0] + s * a[2],
            t * a[2] * a[0] - s * a[1],
        ],
        [
            t * a[0] * a[1] - s * a[2],
            c + t * a[1] * a[1],
            t * a[2] * a[1] + s * a[0],
        ],
        [
            t * a[0] * a[2] + s * a[1],
            t * a[1] * a[2] - s * a[0],
            c + t * a[2] * a[2],
        ],
    ])
}

fn lin(v: &Vector6<f64>) -> Vector3<f64> {
    let v = &v.data.0[0];
    Vector3::new(v[0], v[1], v[2])
}

fn ang(v: &Vector6<f64>) -> Vector3<f64> {
    let v = &v.data.0[0];
    Vector3::new(v[3], v[4], v[5])
}

/// `aᵀ b` of 6-vectors.
fn dot6(a: &Vector6<f64>, b: &Vector6<f64>) -> f64 {
    let (a, b) = (&a.data.0[0], &b.data.0[0]);
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]
}

fn join(l: Vector3<f64>, a: Vector3<f64>) -> Vector6<f64> {
    Vector6::new(l.x, l.y, l.z, a.x, a.y, a.z)
}

/// Spatial motion cross product `a × b` (RBDA Ch. 2, linear-first order).
fn motion_cross(a: &Vector6<f64>, b: &Vector6<f64>) -> Vector6<f64> {
    let (va, wa) = (lin(a), ang(a));
    let (vb, wb) = (lin(b), ang(b));
    join(wa.cross(&vb) + va.cross(&wb), wa.cross(&wb))
}

/// Spatial force cross product `v ×* f` (RBDA Ch. 2, linear-first order).
fn force_cross(v: &Vector6<f64>, f: &Vector6<f64>) -> Vector6<f64> {
    let (vv, w) = (lin(v), ang(v));
    let (fl, n) = (lin(f), ang(f));
    join(w.cross(&fl), w.cross(&n) + vv.cross(&fl))
}

/// World-frame spatial inertia in compact form (RBDA Ch. 2, taken at the world
/// origin, linear-first order): the 6×6 matrix `[[m 1, −h×], [h×, I_O]]` with
/// mass `m`, first moment `h = m c` and rotational inertia `I_O = I_c − m c× c×`
/// about the world origin. Composite inertias are plain sums.
#[derive(Clone, Copy, Debug, Default)]
struct BodyInertia {
    m: f64,
    h: Vector3<f64>,
    i_o: Matrix3<f64>,
}

impl BodyInertia {
    /// The inertia of a body with world rotation `r` and origin `p`.
    fn from_body(si: &SpatialInertia, r: &Matrix3<f64>, p: &Vector3<f64>) -> BodyInertia {
        let c = p + mul3v(r, &si.com);
        let iw = mul33t(&mul33(r, &si.inertia), r);
        // I_O = I_w + m (|c|² 1 − c cᵀ)
        let m = si.mass;
        let c2 = c.norm_squared();
        let mut i_o = iw.data.0;
        for (col, column) in i_o.iter_mut().enumerate() {
            for (row, x) in column.iter_mut().enumerate() {
                let delta = if row == col { c2 } else { 0.0 };
                *x += m * (delta - c[row] * c[col]);
            }
        }
        BodyInertia {
            m,
            h: c * m,
            i_o: mat3(i_o),
        }
    }

    /// `I (v, ω) = (m v − h × ω, h × v + I_O ω)`.
    fn mul(&self, x: &Vector6<f64>) -> Vector6<f64> {
        let (v, w) = (lin(x), ang(x));
        join(
            v * self.m - self.h.cross(&w),
            self.h.cross(&v) + mul3v(&self.i_o, &w),
        )
    }

    fn add(&mut self, other: &BodyInertia) {
        self.m += other.m;
        self.h += other.h;
        self.i_o += other.i_o;
    }
}

/// The Coriolis operator `B(v) = ½ (v×* I − I v× + (I v)×̄)` of Echeandia & Wensing,
/// "Numerical Methods to Compute the Coriolis Matrix and Christoffel Symbols for
/// Rigid-Body Systems" (arXiv 2010.01033, eq. 13), where `(h)×̄` is the operator
/// `m ↦ m ×* h`; it satisfies `B + Bᵀ = İ` and `B v = v ×* (I v)`.
///
/// Written out with `I = [[m 1, −h×], [h×, I_O]]` and `I v = (f, n)`, the left
/// block column vanishes:
/// `B = [[0, −f×], [0, ½ (2 (v·h) 1 − v hᵀ − h vᵀ + ω× I_O − I_O ω× − n×)]]`.
/// Returns `f` and the lower-right block.
fn coriolis_blocks(v: &Vector6<f64>, inertia: &BodyInertia) -> (Vector3<f64>, Matrix3<f64>) {
    let (vl, w) = (lin(v), ang(v));
    let iv = inertia.mul(v);
    let (f, n) = (lin(&iv), ang(&iv));
    let h = inertia.h;
    let wx = w.cross_matrix();
    let wi = mul33(&wx, &inertia.i_o).data.0;
    let iw = mul33(&inertia.i_o, &wx).data.0;
    let nx = n.cross_matrix().data.0;
    let vh = vl.dot(&h);
    let mut br = [[0.0; 3]; 3];
    for (col, column) in br.iter_mut().enumerate() {
        for (row, x) in column.iter_mut().enumerate() {
            let diag = if row == col { 2.0 * vh } else { 0.0 };
            *x = 0.5
                * (diag - vl[row] * h[col] - h[row] * vl[col] + wi[col][row]
                    - iw[col][row]
                    - nx[col][row]);
        }
    }
    (f, mat3(br))
}

fn dims_ok(model: &Model, data: &Data, vecs: &[&DVector<f64>]) -> bool {
    let n = model.nq();
    data.nq() == n && data.m.nrows() == n && vecs.iter().all(|v| v.len() == n)
}

/// Forward pass: placements, motion subspaces and world inertias; with `qd`
/// also velocities, `Ṡ` and bias accelerations (zero without `qd`).
fn kinematics(model: &Model, data: &mut Data, q: &DVector<f64>, qd: Option<&DVector<f64>>) {
    let sc = &mut data.scratch;
    // The sines and cosines of the joint angles first: independent calls, which the
    // CPU overlaps here (inside the recursion each would wait on the one before).
    for ((sc_i, joint), &qi) in sc.sin_cos.iter_mut().zip(&model.joints).zip(q.iter()) {
        if joint.kind == JointKind::Revolute {
            *sc_i = qi.sin_cos();
        }
    }
    let mut r_parent = Matrix3::identity();
    let mut p_parent = Vector3::zeros();
    let mut v_parent = Vector6::zeros();
    let mut a_parent = Vector6::zeros();
    for (i, joint) in model.joints.iter().enumerate() {
        // Joint frame before the motion, then the joint motion about/along the axis.
        let r_pre = mul33(&r_parent, &joint.placement_rotation);
        let mut p = p_parent + mul3v(&r_parent, &joint.placement.translation.vector);
        let z = mul3v(&r_pre, &joint.axis);
        let (r, s) = match joint.kind {
            JointKind::Revolute => (
                mul33(&r_pre, &axis_angle(&joint.axis, sc.sin_cos[i])),
                join(p.cross(&z), z),
            ),
            JointKind::Prismatic => {
                p += z * q[i];
                (r_pre, join(z, Vector3::zeros()))
            }
        };
        sc.s[i] = s;
        sc.inertia[i] = BodyInertia::from_body(&joint.inertia, &r, &p);
        match qd {
            Some(qd) => {
                let v = v_parent + s * qd[i];
                let sdot = motion_cross(&v, &s);
                let a = a_parent + sdot * qd[i];
                data.v[i] = v;
                sc.sdot[i] = sdot;
                sc.abias[i] = a;
                v_parent = v;
                a_parent = a;
            }
            None => {
                data.v[i] = Vector6::zeros();
                sc.sdot[i] = Vector6::zeros();
                sc.abias[i] = Vector6::zeros();
            }
        }
        data.o_m_i[i] = Isometry3::from_parts(
            Translation3::from(p),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
        );
        r_parent = r;
        p_parent = p;
    }
}

/// Recursive Newton–Euler (RBDA Table 5.1, world-frame form) after [`kinematics`]:
/// `out = M q̈ + C q̇ + g` with the velocities of the last kinematics pass,
/// q̈ = 0 when `qdd` is `None`, and gravity when `with_gravity`.
fn rnea_pass(
    model: &Model,
    sc: &mut Scratch,
    v: &[Vector6<f64>],
    qdd: Option<&DVector<f64>>,
    with_gravity: bool,
    out: &mut DVector<f64>,
) {
    let n = model.nq();
    // Gravity enters as a fictitious base acceleration −g (RBDA Ch. 5).
    let mut a = if with_gravity {
        join(-model.gravity, Vector3::zeros())
    } else {
        Vector6::zeros()
    };
    for i in 0..n {
        // a_i = a_{i−1} + Ṡ_i q̇_i + S_i q̈_i; the Ṡ q̇ terms are summed in `abias`.
        let prev_bias = if i > 0 {
            sc.abias[i - 1]
        } else {
            Vector6::zeros()
        };
        a += sc.abias[i] - prev_bias;
        if let Some(qdd) = qdd {
            a += sc.s[i] * qdd[i];
        }
        sc.a[i] = a;
        let h = sc.inertia[i].mul(&v[i]);
        sc.f[i] = sc.inertia[i].mul(&a) + force_cross(&v[i], &h);
    }
    for i in (0..n).rev() {
        out[i] = dot6(&sc.s[i], &sc.f[i]);
        if i > 0 {
            let fi = sc.f[i];
            sc.f[i - 1] += fi;
        }
    }
}

/// Composite inertias and M (CRBA, RBDA Table 6.2, world-frame form) after [`kinematics`].
fn crba_pass(model: &Model, data: &mut Data) {
    let n = model.nq();
    let sc = &mut data.scratch;
    for i in (0..n).rev() {
        sc.ic[i] = sc.inertia[i];
        if i + 1 < n {
            let next = sc.ic[i + 1];
            sc.ic[i].add(&next);
        }
        let f = sc.ic[i].mul(&sc.s[i]);
        sc.ics[i] = f;
        for j in 0..=i {
            let mij = dot6(&sc.s[j], &f);
            data.m[(i, j)] = mij;
            data.m[(j, i)] = mij;
        }
    }
}

/// Coriolis matrix after [`kinematics`] with velocities and [`crba_pass`]:
/// `C = Σ_i J_iᵀ (I_i J̇_i + B_i J_i)` (Echeandia & Wensing, arXiv 2010.01033,
/// eq. 14–16), where `J_i` holds the world motion subspaces `S_j` (j ≤ i) of the
/// ancestors of body i. On a chain the sum over bodies becomes composite sums:
/// `C[k, j] = (Ic_k S_k)ᵀ Ṡ_j + (Bc_kᵀ S_k)ᵀ S_j` for k ≥ j and
/// `C[k, j] = S_kᵀ (Ic_j Ṡ_j + Bc_j S_j)` for k < j. O(n²).
fn coriolis_pass(model: &Model, data: &mut Data) {
    let n = model.nq();
    let sc = &mut data.scratch;
    // Composite B_c = Σ_{k≥i} B_k = [[0, −f_c×], [0, br_c]] (see `coriolis_blocks`).
    let mut f_c = Vector3::zeros();
    let mut br_c = Matrix3::zeros();
    for i in (0..n).rev() {
        let (f, br) = coriolis_blocks(&data.v[i], &sc.inertia[i]);
        f_c += f;
        br_c += br;
        let (sl, sa) = (lin(&sc.s[i]), ang(&sc.s[i]));
        // B_cᵀ S_i and I_c Ṡ_i + B_c S_i.
        sc.bcts[i] = join(Vector3::zeros(), f_c.cross(&sl) + mul3tv(&br_c, &sa));
        sc.w[i] = sc.ic[i].mul(&sc.sdot[i]) + join(-f_c.cross(&sa), mul3v(&br_c, &sa));
    }
    assert_eq!(data.c.shape(), (n, n));
    if n < COMPONENT_FILL_MIN {
        // Column j of C (contiguous) from the per-joint vectors, sliced to n once.
        let (s, sdot, ics, bcts, w) = (
            &sc.s[..n],
            &sc.sdot[..n],
            &sc.ics[..n],
            &sc.bcts[..n],
            &sc.w[..n],
        );
        for (j, col) in data.c.as_mut_slice().chunks_exact_mut(n).enumerate() {
            let (col, sj, sdj, wj) = (&mut col[..n], &s[j], &sdot[j], &w[j]);
            for (k, ck) in col.iter_mut().enumerate() {
                *ck = if k >= j {
                    dot6(&ics[k], sdj) + dot6(&bcts[k], sj)
                } else {
                    dot6(&s[k], wj)
                };
            }
        }
        return;
    }
    assert_eq!(sc.by_component.len(), 18 * n);
    for (c, run) in sc.by_component.chunks_exact_mut(n).enumerate() {
        let (v, c) = match c / 6 {
            0 => (&sc.s, c),
            1 => (&sc.ics, c - 6),
            _ => (&sc.bcts, c - 12),
        };
        for (x, vk) in run.iter_mut().zip(v) {
            *x = vk[c];
        }
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (just checked).
        unsafe { coriolis_fill_avx2(data.c.as_mut_slice(), sc, n) };
        return;
    }
    coriolis_fill(data.c.as_mut_slice(), sc, n);
}

/// The smallest n for which C is filled down its columns by [`coriolis_fill`] (below,
/// the columns are too short to gain from it, and the dot products run directly on the
/// per-joint vectors).
const COMPONENT_FILL_MIN: usize = 8;

/// [`coriolis_fill`] compiled for AVX2 (four rows per instruction; no fused
/// multiply-adds, so the same roundings).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn coriolis_fill_avx2(c: &mut [f64], sc: &Scratch, n: usize) {
    coriolis_fill(c, sc, n);
}

/// C (n × n, column-major `c`) from the per-joint vectors of [`coriolis_pass`], column
/// j down its rows k from the component runs of `S_k`, `Ic_k S_k` and `Bc_kᵀ S_k`, so
/// that consecutive rows are formed side by side in vector registers. Every element
/// is the sum of products of [`dot6`] (`(Ic_k S_k)ᵀ Ṡ_j + (Bc_kᵀ S_k)ᵀ S_j` for k ≥ j,
/// `S_kᵀ w_j` for k < j) in the same order, so C is bitwise that of the dot products.
#[inline(always)]
fn coriolis_fill(c: &mut [f64], sc: &Scratch, n: usize) {
    let by = &sc.by_component[..18 * n];
    let run = |c: usize| &by[c * n..(c + 1) * n];
    let s: [&[f64]; 6] = std::array::from_fn(run);
    let ics: [&[f64]; 6] = std::array::from_fn(|c| run(6 + c));
    let bcts: [&[f64]; 6] = std::array::from_fn(|c| run(12 + c));
    for (j, col) in c[..n * n].chunks_exact_mut(n).enumerate() {
        let (sj, sdj, wj) = (
            &sc.s[j].data.0[0],
            &sc.sdot[j].data.0[0],
            &sc.w[j].data.0[0],
        );
        let (upper, lower) = col.split_at_mut(j);
        // k < j: S_kᵀ w_j.
        for (k, ck) in upper.iter_mut().enumerate() {
            *ck = s[0][k] * wj[0]
                + s[1][k] * wj[1]
                + s[2][k] * wj[2]
                + s[3][k] * wj[3]
                + s[4][k] * wj[4]
                + s[5][k] * wj[5];
        }
        // k ≥ j: (Ic_k S_k)ᵀ Ṡ_j + (Bc_kᵀ S_k)ᵀ S_j.
        for (k, ck) in (j..n).zip(lower.iter_mut()) {
            let a = ics[0][k] * sdj[0]
                + ics[1][k] * sdj[1]
                + ics[2][k] * sdj[2]
                + ics[3][k] * sdj[3]
                + ics[4][k] * sdj[4]
                + ics[5][k] * sdj[5];
            let b = bcts[0][k] * sj[0]
                + bcts[1][k] * sj[1]
                + bcts[2][k] * sj[2]
                + bcts[3][k] * sj[3]
                + bcts[4][k] * sj[4]
                + bcts[5][k] * sj[5];
            *ck = a + b;
        }
    }
}

/// Gravity torques from the composite inertias: `g_k = S_kᵀ Ic_k (−g, 0)`
/// (RNEA with q̇ = q̈ = 0). Needs [`crba_pass`].
fn gravity_from_composite(model: &Model, data: &mut Data) {
    let a0 = join(-model.gravity, Vector3::zeros());
    let sc = &data.scratch;
    for k in 0..model.nq() {
        data.g[k] = dot6(&sc.s[k], &sc.ic[k].mul(&a0));
    }
}

/// Forward kinematics: world placement of every body for configuration `q`
/// (into `data.o_m_i`; velocities set to zero).
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &DVector<f64>) {
    if !dims_ok(model, data, &[q]) {
        fill_nan_kinematics(data);
        return;
    }
    kinematics(model, data, q, None);
}

/// Forward kinematics with velocities: placements and body velocities for (`q`, `qd`).
/// `data.v[i]` is the world-frame spatial velocity `(v, ω)` of body i, `v` being the
/// velocity of the body point at the world origin (see the module documentation).
pub fn forward_kinematics_vel(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    if !dims_ok(model, data, &[q, qd]) {
        fill_nan_kinematics(data);
        return;
    }
    kinematics(model, data, q, Some(qd));
}

fn fill_nan_kinematics(data: &mut Data) {
    let nan_iso = Isometry3::from_parts(
        Translation3::new(f64::NAN, f64::NAN, f64::NAN),
        UnitQuaternion::identity(),
    );
    data.o_m_i.iter_mut().for_each(|m| *m = nan_iso);
    let nan6 = Vector6::repeat(f64::NAN);
    data.v.iter_mut().for_each(|v| *v = nan6);
    let sc = &mut data.scratch;
    for buf in [&mut sc.s, &mut sc.sdot, &mut sc.abias] {
        buf.iter_mut().for_each(|v| *v = nan6);
    }
}

/// Body index and world placement of a frame; `None` for an unknown frame.
fn frame_info(
    model: &Model,
    data: &Data,
    frame: FrameId,
) -> Option<(Option<usize>, Isometry3<f64>)> {
    let f = model.frames.get(frame)?;
    match f.body {
        None => Some((None, f.placement)),
        Some(b) => {
            let o_m = data.o_m_i.get(b)?;
            Some((Some(b), o_m * f.placement))
        }
    }
}

/// World placement of a frame. Requires [`forward_kinematics`] first.
/// An unknown frame id gives a NaN translation.
pub fn frame_placement(model: &Model, data: &Data, frame: FrameId) -> Isometry3<f64> {
    match frame_info(model, data, frame) {
        Some((_, o_m)) => o_m,
        None => nan_placement(),
    }
}

/// 6×n frame Jacobian (rows linear then angular, world axes, reference point at the frame
/// origin) into `out`. Requires [`forward_kinematics`] first.
///
/// Column j ≤ body of the frame: `(S_j,lin + S_j,ang × p, S_j,ang)`, i.e. `z_j × (p − p_j)`
/// over `z_j` for a revolute joint (Pinocchio's LOCAL_WORLD_ALIGNED convention;
/// the task Jacobians `J_i` of the paper's eq. (2)).
/// `out` of the wrong size or an unknown frame: `out` is filled with NaN.
pub fn frame_jacobian(model: &Model, data: &Data, frame: FrameId, out: &mut DMatrix<f64>) {
    let info = frame_info(model, data, frame);
    jacobian_at(model, data, info.as_ref(), out);
}

/// Time derivative J̇ of [`frame_jacobian`] (same convention) into `out`.
/// Requires [`forward_kinematics_vel`] first.
///
/// Column j: `(Ṡ_j,lin + Ṡ_j,ang × p + S_j,ang × ṗ, Ṡ_j,ang)` with `Ṡ_j = v_j × S_j`
/// and `ṗ` the velocity of the frame origin; for a revolute joint this is
/// `[(ω_j × z_j) × (p − p_j) + z_j × (ṗ − ṗ_j); ω_j × z_j]`.
/// `out` of the wrong size or an unknown frame: `out` is filled with NaN.
pub fn frame_jacobian_time_variation(
    model: &Model,
    data: &Data,
    frame: FrameId,
    out: &mut DMatrix<f64>,
) {
    let info = frame_info(model, data, frame);
    jacobian_time_variation_at(model, data, info.as_ref(), out);
}

/// [`frame_jacobian`] into `j` and, when given, [`frame_jacobian_time_variation`] into
/// `jdot` for one frame, its world placement formed once for both; returns that
/// placement ([`frame_placement`], a NaN translation for an unknown frame), so that a
/// caller that also needs it does not form it again. Requires
/// [`forward_kinematics_vel`] first (or [`forward_kinematics`] without `jdot`).
pub fn frame_jacobians(
    model: &Model,
    data: &Data,
    frame: FrameId,
    j: &mut DMatrix<f64>,
    jdot: Option<&mut DMatrix<f64>>,
) -> Isometry3<f64> {
    let info = frame_info(model, data, frame);
    jacobian_at(model, data, info.as_ref(), j);
    if let Some(jdot) = jdot {
        jacobian_time_variation_at(model, data, info.as_ref(), jdot);
    }
    match info {
        Some((_, o_m)) => o_m,
        None => nan_placement(),
    }
}

/// The placement of [`frame_placement`] for an unknown frame.
fn nan_placement() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(f64::NAN, f64::NAN, f64::NAN),
        UnitQuaternion::identity(),
    )
}

/// The body of [`frame_jacobian`] for a frame's body and placement from [`frame_info`].
fn jacobian_at(
    model: &Model,
    data: &Data,
    info: Option<&(Option<usize>, Isometry3<f64>)>,
    out: &mut DMatrix<f64>,
) {
    let n = model.nq();
    let (body, o_m) = match info {
        Some(x) if out.nrows() == 6 && out.ncols() == n && data.nq() == n => x,
        _ => {
            out.fill(f64::NAN);
            return;
        }
    };
    // Column-major 6 × n: column j is out[6 j..6 j + 6].
    let out = out.as_mut_slice();
    out.fill(0.0);
    let p = o_m.translation.vector;
    if let Some(b) = *body {
        for (s, col) in data.scratch.s[..=b].iter().zip(out.chunks_exact_mut(6)) {
            let w = ang(s);
            let v = lin(s) + w.cross(&p);
            col[..3].copy_from_slice(v.as_slice());
            col[3..].copy_from_slice(w.as_slice());
        }
    }
}

/// The body of [`frame_jacobian_time_variation`] for a frame's body and placement from
/// [`frame_info`].
fn jacobian_time_variation_at(
    model: &Model,
    data: &Data,
    info: Option<&(Option<usize>, Isometry3<f64>)>,
    out: &mut DMatrix<f64>,
) {
    let n = model.nq();
    let (body, o_m) = match info {
        Some(x) if out.nrows() == 6 && out.ncols() == n && data.nq() == n => x,
        _ => {
            out.fill(f64::NAN);
            return;
        }
    };
    let out = out.as_mut_slice();
    out.fill(0.0);
    let p = o_m.translation.vector;
    if let Some(b) = *body {
        let vb = &data.v[b];
        let pdot = lin(vb) + ang(vb).cross(&p);
        let (s, sdot) = (&data.scratch.s[..=b], &data.scratch.sdot[..=b]);
        for ((s, sd), col) in s.iter().zip(sdot).zip(out.chunks_exact_mut(6)) {
            let wd = ang(sd);
            let v = lin(sd) + wd.cross(&p) + ang(s).cross(&pdot);
            col[..3].copy_from_slice(v.as_slice());
            col[3..].copy_from_slice(wd.as_slice());
        }
    }
}

/// J̇ q̇: classical (not spatial) acceleration of the frame origin for q̈ = 0, linear then
/// angular, world axes. Requires [`forward_kinematics_vel`] first.
///
/// With the spatial bias acceleration `a = Σ Ṡ_j q̇_j` of the body (RBDA Ch. 2),
/// the classical acceleration of the point p is `(a_lin + a_ang × p + ω × ṗ, a_ang)`.
/// Unknown frame: NaN.
pub fn frame_classical_acceleration(model: &Model, data: &Data, frame: FrameId) -> Vector6<f64> {
    match frame_info(model, data, frame) {
        None => Vector6::repeat(f64::NAN),
        Some((None, _)) => Vector6::zeros(),
        Some((Some(b), o_m)) => {
            let p = o_m.translation.vector;
            let vb = &data.v[b];
            let w = ang(vb);
            let pdot = lin(vb) + w.cross(&p);
            let a = &data.scratch.abias[b];
            join(lin(a) + ang(a).cross(&p) + w.cross(&pdot), ang(a))
        }
    }
}

/// Composite rigid-body algorithm (RBDA Table 6.2): joint-space inertia M into `data.m`.
/// Also runs [`forward_kinematics`] (velocities zero).
pub fn crba(model: &Model, data: &mut Data, q: &DVector<f64>) {
    if !dims_ok(model, data, &[q]) {
        data.m.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, None);
    crba_pass(model, data);
}

/// Coriolis matrix C(q, q̇) with Ṁ = C + Cᵀ into `data.c`: the Christoffel-symbol
/// factorisation `C_kj = Σ_i Γ_kji q̇_i` (as Pinocchio's computeCoriolisMatrix), by the
/// O(n²) algorithm of Echeandia & Wensing (arXiv 2010.01033). Also computes M, the
/// placements and velocities.
pub fn coriolis_matrix(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    if !dims_ok(model, data, &[q, qd]) {
        data.c.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, Some(qd));
    crba_pass(model, data);
    coriolis_pass(model, data);
}

/// Gravity torques g(q) into `data.g` (RNEA with q̇ = q̈ = 0). Also runs
/// [`forward_kinematics`].
pub fn gravity(model: &Model, data: &mut Data, q: &DVector<f64>) {
    if !dims_ok(model, data, &[q]) {
        data.g.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, None);
    let Data { scratch, v, g, .. } = data;
    rnea_pass(model, scratch, v, None, true, g);
}

/// Nonlinear effects C q̇ + g into `data.nle` (RNEA with q̈ = 0). Also runs
/// [`forward_kinematics_vel`].
pub fn nle(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    if !dims_ok(model, data, &[q, qd]) {
        data.nle.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, Some(qd));
    let Data {
        scratch, v, nle, ..
    } = data;
    rnea_pass(model, scratch, v, None, true, nle);
}

/// Recursive Newton–Euler inverse dynamics (RBDA Table 5.1): τ = M q̈ + C q̇ + g into
/// `data.tau`. Also runs [`forward_kinematics_vel`].
pub fn rnea(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    qdd: &DVector<f64>,
) {
    if !dims_ok(model, data, &[q, qd, qdd]) {
        data.tau.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, Some(qd));
    let Data {
        scratch, v, tau, ..
    } = data;
    rnea_pass(model, scratch, v, Some(qdd), true, tau);
}

/// Forward dynamics q̈ = M⁻¹(τ − C q̇ − g) into `data.qdd` (the paper's eq. (1) with τ_ext = 0,
/// RBDA Ch. 6: M by CRBA,
/// C q̇ + g by RNEA, then an in-place Cholesky solve). Also leaves M in `data.m`,
/// C q̇ + g in `data.nle`, the Cholesky factor in `data.m_chol`, placements and
/// velocities. Errors on wrong vector lengths or an M that is not positive definite.
pub fn forward_dynamics(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<(), ModelError> {
    model.check_state(q, Some(qd), Some(tau))?;
    if data.nq() != model.nq() {
        return Err(ModelError::Dimension {
            what: "data (workspace built for another model)",
            expected: model.nq(),
            got: data.nq(),
        });
    }
    kinematics(model, data, q, Some(qd));
    crba_pass(model, data);
    {
        let Data {
            scratch, v, nle, ..
        } = data;
        rnea_pass(model, scratch, v, None, true, nle);
    }
    data.m_chol.copy_from(&data.m);
    cholesky_in_place(&mut data.m_chol)?;
    data.qdd.copy_from(tau);
    data.qdd -= &data.nle;
    cholesky_solve_in_place(&data.m_chol, &mut data.qdd)?;
    Ok(())
}

/// Everything a controller needs in one pass: placements and velocities, M, C, g and
/// C q̇ + g for (`q`, `qd`) (into `data.m`, `data.c`, `data.g`, `data.nle`). Afterwards
/// the frame functions ([`frame_placement`], [`frame_jacobian`],
/// [`frame_jacobian_time_variation`], [`frame_classical_acceleration`]) can be used.
pub fn compute_all_terms(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    if !dims_ok(model, data, &[q, qd]) {
        fill_nan_kinematics(data);
        for m in [&mut data.m, &mut data.c] {
            m.fill(f64::NAN);
        }
        data.g.fill(f64::NAN);
        data.nle.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, Some(qd));
    crba_pass(model, data);
    coriolis_pass(model, data);
    gravity_from_composite(model, data);
    let n = model.nq();
    for k in 0..n {
        let mut s = data.g[k];
        for j in 0..n {
            s += data.c[(k, j)] * qd[j];
        }
        data.nle[k] = s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fmt::Write as _;

    /// An n-joint chain (axes alternating z / y / x, offsets and centres of mass off
    /// the axes), long enough for the Coriolis fill by components.
    fn chain(n: usize) -> Model {
        let mut s =
            String::from("<?xml version=\"1.0\"?>\n<robot name=\"c\">\n<link name=\"l0\"/>\n");
        for k in 0..n {
            let axis = ["0 0 1", "0 1 0", "1 0 0"][k % 3];
            let m = 1.0 + 0.1 * k as f64;
            writeln!(
                s,
                "<link name=\"l{}\"><inertial><origin xyz=\"0.01 -0.02 0.05\" rpy=\"0.1 0.2 0.3\"/>\
                 <mass value=\"{m}\"/><inertia ixx=\"0.02\" ixy=\"0.001\" ixz=\"0\" iyy=\"0.025\" \
                 iyz=\"0.002\" izz=\"0.015\"/></inertial></link>\
                 <joint name=\"j{k}\" type=\"revolute\"><parent link=\"l{k}\"/><child link=\"l{}\"/>\
                 <origin xyz=\"0.02 0 0.1\" rpy=\"0 0.1 0\"/><axis xyz=\"{axis}\"/>\
                 <limit lower=\"-3\" upper=\"3\" effort=\"10\" velocity=\"2\"/></joint>",
                k + 1,
                k + 1
            )
            .unwrap();
        }
        s.push_str("</robot>\n");
        Model::from_urdf_str(&s, None, &format!("l{n}"), None).unwrap()
    }

    #[test]
    fn coriolis_fill_by_components_is_bitwise_the_dot_products() {
        for n in [8, 10, 13] {
            let model = chain(n);
            let mut data = Data::new(&model);
            let q = DVector::from_fn(n, |i, _| 0.3 * (i as f64 + 1.0).sin());
            let qd = DVector::from_fn(n, |i, _| 0.5 * (0.7 * i as f64).cos());
            compute_all_terms(&model, &mut data, &q, &qd);
            let sc = &data.scratch;
            let reference = DMatrix::from_fn(n, n, |k, j| {
                if k >= j {
                    dot6(&sc.ics[k], &sc.sdot[j]) + dot6(&sc.bcts[k], &sc.s[j])
                } else {
                    dot6(&sc.s[k], &sc.w[j])
                }
            });
            assert_eq!(data.c, reference, "n = {n}");
            // The portable build as well (the CPUs without AVX2).
            let mut c = DMatrix::zeros(n, n);
            coriolis_fill(c.as_mut_slice(), sc, n);
            assert_eq!(c, reference, "portable, n = {n}");
        }
    }
}
