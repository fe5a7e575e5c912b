//! The controller: workspace, construction checks and the per-cycle law.

use crate::ControlError;
use crate::fade::fade_factor;
use crate::rate::{GainRate, RateWork};
use crate::spec::{ControllerSpec, Form, LevelSpec};
use crate::task::{FrameWork, PotentialWork};
use hcc_linalg::basis::{AlignWork, null_space_basis, orthonormalize_polar, procrustes_align};
use hcc_linalg::products::{
    copy, gemm, gemm_leading, gemm_nt, gemm_nt_leading, gemm_sym, gemm_tn, gemv, gemv_slices,
    gemv_t, gemv_t_slices, transpose_cols_into, transpose_into,
};
use hcc_linalg::spd::{Conditioning, SpdWork, damped_spd_inverse};
use hcc_model::{Data, Model};
use nalgebra::{DMatrix, DVector};

/// Smallest eigenvalue that counts as "not vanished" for a Gram matrix.
const GRAM_FLOOR: f64 = 1e-12;

/// Smallest singular value of the previous basis projected onto the new null space
/// (the cosine of the largest principal angle between them) for which the basis is
/// continued; below it the state jumped and a fresh basis is taken.
const MIN_OVERLAP: f64 = 0.5;

/// What one control cycle produced (all preallocated; valid after [`Controller::step`]).
#[derive(Clone, Debug)]
pub struct StepOutput {
    /// τ = Σ τ_i + τ_μ + g (eq. 19); g only with gravity compensation.
    pub tau: DVector<f64>,
    /// τ_i of each level (eqs. 20, 21).
    pub tau_level: Vec<DVector<f64>>,
    /// τ_μ (eq. 22); zero when the cancellation is off.
    pub tau_mu: DVector<f64>,
    /// g(q) (also when it is not added to τ).
    pub gravity: DVector<f64>,
    /// x_i − x_{i,d} per level (orientation: 2·R_d·ε ≈ the rotation vector, world axes).
    pub task_error: Vec<DVector<f64>>,
    /// v_i = J̄_i q̇ (eq. 3); the lowest level has n − Σ_{j<r} m_j entries.
    pub v: Vec<DVector<f64>>,
    /// V_i(x̃_i), the potential of each level.
    pub potential: Vec<f64>,
    /// S_i = ½ v_iᵀ Λ_i v_i + V_i (eqs. 26, 28).
    pub storage: Vec<f64>,
    /// P_μ = τ_μᵀ q̇ (zero in theory).
    pub p_mu: f64,
    /// Per level: an inversion of this level was damped (kinematic or algorithmic singularity).
    pub singular: Vec<bool>,
    /// Any level singular.
    pub any_singular: bool,
    /// Per level: the smallest eigenvalue ratio of the Gram matrices inverted for it.
    pub conditioning: Vec<f64>,
    /// Per level: the factor its torque was scaled by as the Gram matrix of the levels
    /// above it becomes singular (always 1 for level 1, and away from singularities;
    /// see the crate docs, "Singularities").
    pub fade: Vec<f64>,
    /// The factor τ_μ was scaled by (it fades with the conditioning of every level).
    pub fade_mu: f64,
    /// C(q, q̇) q̇, added to τ by [`Form::KinematicProjector`] only (zero otherwise).
    pub coriolis: DVector<f64>,
    /// Safety layer (crate::safety): its torque (added to τ only when it acts), what
    /// acted, counters, the fade's energy tank and the total energy E.
    pub safety: crate::safety::SafetyOutput,
}

impl StepOutput {
    fn new(n: usize, dims: &[usize], v_dims: &[usize]) -> StepOutput {
        let r = dims.len();
        StepOutput {
            tau: DVector::zeros(n),
            tau_level: (0..r).map(|_| DVector::zeros(n)).collect(),
            tau_mu: DVector::zeros(n),
            gravity: DVector::zeros(n),
            task_error: dims.iter().map(|&m| DVector::zeros(m)).collect(),
            v: v_dims.iter().map(|&d| DVector::zeros(d)).collect(),
            potential: vec![0.0; r],
            storage: vec![0.0; r],
            p_mu: 0.0,
            singular: vec![false; r],
            any_singular: false,
            conditioning: vec![1.0; r],
            fade: vec![1.0; r],
            fade_mu: 1.0,
            coriolis: DVector::zeros(n),
            safety: crate::safety::SafetyOutput::new(n, r),
        }
    }
}

/// A level's current spring–damper target ([`Controller::level_target`]).
#[derive(Clone, Copy, Debug)]
pub struct LevelTarget<'a> {
    /// x_{i,d} (roll, pitch, yaw for an orientation task).
    pub goal: &'a [f64],
    /// ẋ_{i,d} (zero for a fixed goal).
    pub goal_velocity: &'a [f64],
    /// K_i.
    pub stiffness: &'a DMatrix<f64>,
    /// D_i.
    pub damping: &'a DMatrix<f64>,
}

/// Per-level workspace.
#[derive(Clone, Debug)]
struct Level {
    m: usize,
    /// Dimension of v_i: m_i, or n − Σ_{j<r} m_j for the lowest null-space level.
    d: usize,
    stiffness: DMatrix<f64>,
    damping: DMatrix<f64>,
    goal: DVector<f64>,
    /// R_d of the quaternion tasks and the buffers of the potential.
    pot: PotentialWork,
    /// Velocity ẋ_{i,d} of a moving equilibrium (zero unless set; see
    /// [`Controller::set_goal_velocity`]); the damping acts on ẋ_i − ẋ_{i,d}.
    goal_velocity: DVector<f64>,
    goal_moving: bool,
    // task
    j: DMatrix<f64>,
    jdot: DMatrix<f64>,
    err: DVector<f64>,
    grad: DVector<f64>,
    xdot: DVector<f64>,
    f: DVector<f64>,
    potential: f64,
    /// (∂V_i/∂x_i) J_i q̇: the rate of V_i the arm's motion makes (not the goal's).
    spring_rate: f64,
    // decomposition
    z: DMatrix<f64>,
    zdot: DMatrix<f64>,
    zm: DMatrix<f64>,
    zmdot: DMatrix<f64>,
    lambda: DMatrix<f64>,
    lambda_inv: DMatrix<f64>,
    lambda_dot: DMatrix<f64>,
    jbar: DMatrix<f64>,
    /// The block column of J̄⁻¹ belonging to level 1 (eq. 13), n × m_1 (empty for the
    /// others: theirs is Z_iᵀ).
    jbar_inv: DMatrix<f64>,
    v: DVector<f64>,
    y_d: DVector<f64>,
    y_d2: DVector<f64>,
    y_d3: DVector<f64>,
    spd: SpdWork,
    /// The gains' check against the control rate (crate::rate).
    rate: RateWork,
    /// Eq. (11) with (8) for 2 ≤ i < r (k = Σ_{j<i} m_j; empty otherwise):
    /// Z_i = J_i M⁻¹ N_i = Y_i − T Y_aug with Y = J M⁻¹, G = J_aug M⁻¹ J_augᵀ (k × k),
    /// H = J_i M⁻¹ J_augᵀ (m × k), T = H G⁻¹, and the derivatives of G, H, T, Y.
    proj: Projection,
}

/// The blocks of eq. (8) for one level above the lowest.
#[derive(Clone, Debug)]
struct Projection {
    k: usize,
    g: DMatrix<f64>,
    g_inv: DMatrix<f64>,
    gdot: DMatrix<f64>,
    h: DMatrix<f64>,
    hdot: DMatrix<f64>,
    t: DMatrix<f64>,
    tdot: DMatrix<f64>,
    /// Y_aug, formed for the classical form only.
    y_aug: DMatrix<f64>,
    /// Vectors for the classical form N_i x = x − J_augᵀ G⁻¹ Y_aug x (eq. 8).
    y_k: DVector<f64>,
    y_top: DVector<f64>,
    spd: SpdWork,
    g_cond: Conditioning,
}

impl Projection {
    fn new(k: usize, m: usize, n: usize, top: usize) -> Projection {
        Projection {
            k,
            g: DMatrix::zeros(k, k),
            g_inv: DMatrix::zeros(k, k),
            gdot: DMatrix::zeros(k, k),
            h: DMatrix::zeros(m, k),
            hdot: DMatrix::zeros(m, k),
            t: DMatrix::zeros(m, k),
            tdot: DMatrix::zeros(m, k),
            y_aug: DMatrix::zeros(k, n),
            y_k: DVector::zeros(k),
            y_top: DVector::zeros(top),
            spd: SpdWork::new(k),
            g_cond: Conditioning {
                ratio: 1.0,
                damping: 0.0,
            },
        }
    }
}

impl Level {
    /// Buffers of level `i` (0-based) of `r` for `n` joints: m = m_i, `k` = Σ_{j<i} m_j,
    /// `ktop` the rows of the levels above the lowest.
    fn new(
        spec: &LevelSpec,
        i: usize,
        r: usize,
        m: usize,
        n: usize,
        k: usize,
        ktop: usize,
    ) -> Level {
        let d = if i > 0 && i == r - 1 { n - k } else { m };
        let middle = i > 0 && i < r - 1;
        let proj = if middle {
            Projection::new(k, m, n, ktop)
        } else {
            Projection::new(0, 0, 0, 0)
        };
        Level {
            m,
            d,
            stiffness: spec.stiffness.clone(),
            damping: spec.damping.clone(),
            goal: spec.goal.clone(),
            pot: PotentialWork::new(&spec.tasks, &spec.goal, n),
            goal_velocity: DVector::zeros(m),
            goal_moving: false,
            j: DMatrix::zeros(m, n),
            jdot: DMatrix::zeros(m, n),
            err: DVector::zeros(m),
            grad: DVector::zeros(m),
            xdot: DVector::zeros(m),
            spring_rate: 0.0,
            f: DVector::zeros(m),
            potential: 0.0,
            z: DMatrix::zeros(d, n),
            zdot: DMatrix::zeros(d, n),
            zm: DMatrix::zeros(if middle { d } else { 0 }, n),
            zmdot: DMatrix::zeros(if middle { d } else { 0 }, n),
            lambda: DMatrix::zeros(d, d),
            lambda_inv: DMatrix::zeros(d, d),
            lambda_dot: DMatrix::zeros(d, d),
            jbar: DMatrix::zeros(d, n),
            jbar_inv: DMatrix::zeros(if i == 0 { n } else { 0 }, if i == 0 { d } else { 0 }),
            v: DVector::zeros(d),
            y_d: DVector::zeros(d),
            y_d2: DVector::zeros(d),
            y_d3: DVector::zeros(d),
            spd: SpdWork::new(d),
            rate: RateWork::new(m, n),
            proj,
        }
    }
}

/// Null space of the augmented Jacobian of the levels above the lowest one
/// (eqs. 6–9), for Z_r = V_{r−1}ᵀ.
#[derive(Clone, Debug)]
struct NullSpace {
    qr_work: DMatrix<f64>,
    qr_q: DMatrix<f64>,
    /// V_{i−1}: orthonormal basis (n × (n − k)), and Vᵀ.
    v: DMatrix<f64>,
    vt: DMatrix<f64>,
    v_prev: DMatrix<f64>,
    has_prev: bool,
    vdot: DMatrix<f64>,
    vdot_t: DMatrix<f64>,
    gram: DMatrix<f64>,
    gram_inv: DMatrix<f64>,
    t1: DMatrix<f64>,
    t2: DMatrix<f64>,
    /// M V and Ṁ V (n × (n − k)).
    mv: DMatrix<f64>,
    mdv: DMatrix<f64>,
    /// VᵀMV, S = (VᵀMV)⁻¹ and X = d/dt (VᵀMV) = V̇ᵀMV + VᵀṀV + VᵀMV̇, so Ṡ = −S X S.
    vtmv: DMatrix<f64>,
    s: DMatrix<f64>,
    x: DMatrix<f64>,
    tmp_dd: DMatrix<f64>,
    /// J̄_rᵀ = M V S (n × (n − K)).
    jbar_t: DMatrix<f64>,
    /// Vᵀ x and S Vᵀ x for the classical projector form.
    y_nd: DVector<f64>,
    y_nd2: DVector<f64>,
    /// J x and (J Jᵀ)⁻¹ J x for the kinematic projector form.
    y_k: DVector<f64>,
    y_k2: DVector<f64>,
    spd_k: SpdWork,
    spd_d: SpdWork,
    align: AlignWork,
    gram_cond: Conditioning,
    s_cond: Conditioning,
}

impl NullSpace {
    /// Buffers for an `nb`-joint robot (0 without a null-space level), `kb` rows above
    /// the lowest level and an `nd`-dimensional null space.
    fn new(nb: usize, kb: usize, nd: usize) -> NullSpace {
        NullSpace {
            qr_work: DMatrix::zeros(nb, kb),
            qr_q: DMatrix::zeros(nb, nb),
            v: DMatrix::zeros(nb, nd),
            vt: DMatrix::zeros(nd, nb),
            v_prev: DMatrix::zeros(nb, nd),
            has_prev: false,
            vdot: DMatrix::zeros(nb, nd),
            vdot_t: DMatrix::zeros(nd, nb),
            gram: DMatrix::zeros(kb, kb),
            gram_inv: DMatrix::zeros(kb, kb),
            t1: DMatrix::zeros(kb, nd),
            t2: DMatrix::zeros(kb, nd),
            mv: DMatrix::zeros(nb, nd),
            mdv: DMatrix::zeros(nb, nd),
            vtmv: DMatrix::zeros(nd, nd),
            s: DMatrix::zeros(nd, nd),
            x: DMatrix::zeros(nd, nd),
            tmp_dd: DMatrix::zeros(nd, nd),
            jbar_t: DMatrix::zeros(nb, nd),
            y_nd: DVector::zeros(nd),
            y_nd2: DVector::zeros(nd),
            y_k: DVector::zeros(kb),
            y_k2: DVector::zeros(kb),
            spd_k: SpdWork::new(kb),
            spd_d: SpdWork::new(nd),
            align: AlignWork::new(nb, nd),
            gram_cond: Conditioning::default(),
            s_cond: Conditioning::default(),
        }
    }
}

/// The per-level columns of the τ_μ chains (eq. 22), n × r each: u_i = q̇ − (J̄⁻¹)_i v_i,
/// M⁻¹ C u_i, M u_i and Ṁ u_i.
#[derive(Clone, Debug)]
struct MuWork {
    u: DMatrix<f64>,
    minv_cu: DMatrix<f64>,
    mu: DMatrix<f64>,
    mdot_u: DMatrix<f64>,
}

impl MuWork {
    fn new(n: usize, r: usize) -> MuWork {
        MuWork {
            u: DMatrix::zeros(n, r),
            minv_cu: DMatrix::zeros(n, r),
            mu: DMatrix::zeros(n, r),
            mdot_u: DMatrix::zeros(n, r),
        }
    }
}

/// The hierarchical compliance controller of Dietrich, Ott & Albu-Schäffer (IROS 2013).
///
/// Built once by [`Controller::new`] (which allocates everything), then driven by
/// [`Controller::step`], one call from the measured state to the torque command, which
/// never allocates.
#[derive(Clone, Debug)]
pub struct Controller {
    model: Model,
    data: Data,
    spec: ControllerSpec,
    n: usize,
    levels: Vec<Level>,
    /// The null space of the lowest level (empty with a single level).
    basis: NullSpace,
    /// J and J̇ of the levels above the lowest stacked (level 1 alone for r = 1),
    /// K = Σ m_i rows; J_aug of level i is its first k_i rows (eq. 6).
    jtop: DMatrix<f64>,
    jtop_dot: DMatrix<f64>,
    /// Jᵀ of the levels above the lowest (n × K).
    jtop_t: DMatrix<f64>,
    /// (J M⁻¹)ᵀ = M⁻¹ Jᵀ and its derivative M⁻¹ (J̇ᵀ − Ṁ M⁻¹ Jᵀ) (n × K; the rows of
    /// Y = J M⁻¹ and Ẏ a level needs are transposed straight out of their columns), the
    /// Gram matrix W = J M⁻¹ Jᵀ (K × K) and the columns of Ẇ the middle levels read
    /// (K × max k_i, k_i = Σ_{j<i} m_j: Ġ and Ḣ of eq. 8 lie in them).
    yt: DMatrix<f64>,
    yt_dot: DMatrix<f64>,
    w: DMatrix<f64>,
    w_dot: DMatrix<f64>,
    q: DVector<f64>,
    qd: DVector<f64>,
    /// Cholesky factor of M (M⁻¹ is applied by solves, never formed).
    chol: DMatrix<f64>,
    mdot: DMatrix<f64>,
    /// Frame Jacobians of the current cycle (shared by the tasks on one frame).
    frames: FrameWork,
    /// Ẏ and Ẇ are needed (a level between the first and the lowest exists).
    middle: bool,
    tmp_n: DVector<f64>,
    tmp_n2: DVector<f64>,
    /// Level 1's damped inversion of J_1 M⁻¹ J_1ᵀ (the Gram matrix G of level 2).
    first_cond: Conditioning,
    /// Columns per level of the τ_μ chains (eq. 22).
    mu: MuWork,
    /// Safety layer workspace and memory (crate::safety).
    safety: crate::safety::Safety,
    /// The acceleration the law's torque gives (the velocity barrier's input).
    barrier_qdd: DVector<f64>,
    /// The torque the robot applies now (the previous command, after the torque
    /// filter), when the cycle reports it ([`Controller::set_applied_torque`]).
    applied_tau: DVector<f64>,
    have_applied: bool,
    /// The acceleration `applied_tau` gives on the model (for the barrier).
    applied_qdd: DVector<f64>,
    /// κ, the factor on every level's spring ([`Controller::set_stiffness_scale`]).
    stiffness_scale: f64,
    out: StepOutput,
}

impl Controller {
    /// Checks the hierarchy against the model and the initial configuration `q0`, and
    /// allocates every buffer. Errors name the level and the reason.
    pub fn new(
        model: &Model,
        spec: ControllerSpec,
        q0: &DVector<f64>,
    ) -> Result<Controller, ControlError> {
        spec.validate(model)?;
        let n = model.nq();
        let r = spec.levels.len();
        if q0.len() != n || q0.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::Spec(format!(
                "initial configuration must be {n} finite values, got {}",
                q0.len()
            )));
        }
        let dims = spec.task_dims(n);

        // The levels whose Jacobians are stacked in `jtop`: all above the lowest.
        let top = if r == 1 { 1 } else { r - 1 };
        let ktop: usize = dims[..top].iter().sum();
        let mut levels = Vec::with_capacity(r);
        let mut k = 0;
        for (i, l) in spec.levels.iter().enumerate() {
            levels.push(Level::new(l, i, r, dims[i], n, k, ktop));
            k += dims[i];
        }
        // The lowest level's null space: k = K rows above it, n − K columns.
        let basis = if r > 1 {
            NullSpace::new(n, ktop, n - ktop)
        } else {
            NullSpace::new(0, 0, 0)
        };
        let middle = r > 2;
        let kd = if middle { ktop } else { 0 };
        let kmid = levels.iter().map(|l| l.proj.k).max().unwrap_or(0);
        let v_dims: Vec<usize> = levels.iter().map(|l| l.d).collect();
        let out = StepOutput::new(n, &dims, &v_dims);
        // Safety layer (crate::safety): limits from the model, workspace.
        let safety = crate::safety::Safety::new(model, &spec, &dims, ktop)?;
        let mut c = Controller {
            data: Data::new(model),
            model: model.clone(),
            spec,
            n,
            levels,
            basis,
            jtop: DMatrix::zeros(ktop, n),
            jtop_dot: DMatrix::zeros(ktop, n),
            jtop_t: DMatrix::zeros(n, ktop),
            yt: DMatrix::zeros(n, ktop),
            yt_dot: DMatrix::zeros(n, kd),
            w: DMatrix::zeros(ktop, ktop),
            w_dot: DMatrix::zeros(kd, kmid),
            middle,
            q: DVector::zeros(n),
            qd: DVector::zeros(n),
            chol: DMatrix::zeros(n, n),
            mdot: DMatrix::zeros(n, n),
            frames: FrameWork::new(n),
            tmp_n: DVector::zeros(n),
            tmp_n2: DVector::zeros(n),
            first_cond: Conditioning::default(),
            mu: MuWork::new(n, r),
            safety,
            barrier_qdd: DVector::zeros(n),
            applied_tau: DVector::zeros(n),
            have_applied: false,
            applied_qdd: DVector::zeros(n),
            stiffness_scale: 1.0,
            out,
        };
        c.check_initial(q0)?;
        // Safety layer: the spring saturation's task speeds from the Jacobians at q0.
        let jacobians: Vec<&DMatrix<f64>> = c.levels.iter().map(|l| &l.j).collect();
        c.safety.set_task_speeds(&jacobians);
        for i in 0..r {
            let l = &c.levels[i];
            c.safety.set_spring_radius(i, &l.stiffness, &l.damping);
        }
        c.reset();
        // Safety layer: the checks' cycle counts for nothing.
        c.out.safety = crate::safety::SafetyOutput::new(n, r);
        Ok(c)
    }

    /// Rank checks at the initial configuration (Sec. II: full row rank of every J_i and
    /// of the augmented Jacobians; the lowest level must fill the remaining null space).
    fn check_initial(&mut self, q0: &DVector<f64>) -> Result<(), ControlError> {
        let zero = DVector::zeros(self.n);
        self.compute(q0, &zero)
            .map_err(|e| ControlError::Spec(format!("at the initial configuration: {e}")))?;
        let r = self.levels.len();
        let eps = self.spec.singular_ratio;
        for i in 0..r {
            let name = format!("{} ({})", i + 1, self.spec.levels[i].name);
            let lv = &self.levels[i];
            // J_i J_iᵀ full rank (not required of the lowest level, which may be larger than
            // the remaining null space).
            if i < r - 1 || r == 1 {
                let mut g = DMatrix::zeros(lv.m, lv.m);
                gemm_nt(&mut g, 1.0, &lv.j, &lv.j, 0.0);
                let mut inv = g.clone();
                let c = damped_spd_inverse(&g, &mut inv, &mut SpdWork::new(lv.m), eps, GRAM_FLOOR);
                if c.damping > 0.0 || c.ratio < eps {
                    return Err(ControlError::Level {
                        level: name,
                        why: format!(
                            "its Jacobian is singular at the initial configuration (eigenvalue ratio of J Jᵀ {:.3e})",
                            c.ratio
                        ),
                    });
                }
            }
            // The gains the control rate carries (crate::rate).
            if let Err(e) = self.check_gain_rate(i, None, None) {
                return Err(ControlError::Level {
                    level: name,
                    why: e.to_string(),
                });
            }
            let lv = &self.levels[i];
            if i > 0 {
                let gc = if i == r - 1 {
                    self.basis.gram_cond
                } else {
                    lv.proj.g_cond
                };
                if gc.ratio < eps {
                    return Err(ControlError::Level {
                        level: name,
                        why: format!(
                            "the Jacobians of the levels above it are not independent at the initial configuration (augmented Jacobian eigenvalue ratio {:.3e})",
                            gc.ratio
                        ),
                    });
                }
                if self.out.singular[i] {
                    let why = if i == r - 1 {
                        "it cannot fill the remaining null space: J_r V_{r-1} is rank deficient at the initial configuration"
                    } else {
                        "algorithmic singularity at the initial configuration: its task conflicts with the levels above (Z_i M Z_iᵀ singular)"
                    };
                    return Err(ControlError::Level {
                        level: name,
                        why: why.into(),
                    });
                }
            }
            if i == r - 1 && r > 1 {
                // The lowest level must span the remaining null space: J_r V_{r-1} of full column rank.
                let ns = &self.basis;
                let d = ns.v.ncols();
                let mut jv = DMatrix::zeros(lv.m, d);
                gemm(&mut jv, 1.0, &lv.j, &ns.v, 0.0);
                let mut g = DMatrix::zeros(d, d);
                gemm_tn(&mut g, 1.0, &jv, &jv, 0.0);
                let mut inv = g.clone();
                let c = damped_spd_inverse(&g, &mut inv, &mut SpdWork::new(d), eps, GRAM_FLOOR);
                if c.ratio < eps || lv.m < d {
                    return Err(ControlError::Level {
                        level: name,
                        why: format!(
                            "the lowest level cannot fill the remaining {d}-dimensional null space (its task has {} dimensions; ratio {:.3e})",
                            lv.m, c.ratio
                        ),
                    });
                }
            }
        }
        Ok(())
    }

    /// Forgets the null-space basis of the previous cycle (call when the state jumps,
    /// e.g. a new robot connection). The next cycle picks a fresh basis.
    pub fn reset(&mut self) {
        self.basis.has_prev = false;
        // Safety layer: forget the fade memory and empty its energy tank.
        self.safety.reset();
    }

    /// Number of joints.
    pub fn nq(&self) -> usize {
        self.n
    }

    /// Number of levels r.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Task dimension m_i of level `i` (0-based).
    pub fn task_dim(&self, i: usize) -> usize {
        self.levels[i].m
    }

    /// The (stacked) task Jacobian J_i of level `i` (0-based) of the last cycle.
    pub fn task_jacobian(&self, i: usize) -> &DMatrix<f64> {
        &self.levels[i].j
    }

    /// The model the controller was built with.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The spec the controller was built with.
    pub fn spec(&self) -> &ControllerSpec {
        &self.spec
    }

    /// The model's terms at the state of the last cycle: M(q), C(q, q̇) (with
    /// Ṁ = C + Cᵀ) and g(q) in `m`, `c`, `g` (what the momentum observer of
    /// [`crate::contact`] reads). Valid after a successful [`Controller::step`].
    pub fn model_terms(&self) -> &Data {
        &self.data
    }

    /// Result of the last cycle.
    pub fn output(&self) -> &StepOutput {
        &self.out
    }

    /// Switches τ_μ (eq. 22) on or off (the ablation).
    pub fn set_coriolis_cancellation(&mut self, on: bool) {
        self.spec.coriolis_cancellation = on;
    }

    /// Chooses eq. (21) or the classical projector form (eqs. 8, 9).
    pub fn set_form(&mut self, form: Form) {
        self.spec.form = form;
    }

    /// The torque the robot applies until the next command (the previous
    /// command as sent, gravity included when the controller adds it), or
    /// `None` before the first. With a torque rate limit downstream the applied
    /// torque lags the law's, and the velocity barrier (crate::safety) brakes for
    /// the faster of the two accelerations. Entries beyond n are ignored; a
    /// shorter slice or a non-finite entry is ignored. Allocation-free.
    pub fn set_applied_torque(&mut self, tau: Option<&[f64]>) {
        let n = self.applied_tau.len();
        self.have_applied = match tau {
            Some(t) if t.len() >= n && t[..n].iter().all(|x| x.is_finite()) => {
                self.applied_tau.as_mut_slice().copy_from_slice(&t[..n]);
                true
            }
            _ => false,
        };
    }

    /// Whether the control rate carries the gains of level `i` (crate::rate):
    /// the stiffness `k` and damping `d` given, the level's own where `None`, at
    /// the configuration of the last cycle (the initial one before the first).
    /// For a gains setpoint before it is taken. Allocation-free.
    pub fn check_gain_rate(
        &mut self,
        i: usize,
        k: Option<&DMatrix<f64>>,
        d: Option<&DMatrix<f64>>,
    ) -> Result<(), GainRate> {
        let period = self.spec.safety.control_period_s;
        let Some(l) = self.levels.get_mut(i) else {
            return Ok(());
        };
        if !l.rate.set_mobility(&self.chol, &l.j) {
            return Ok(());
        }
        let k = k.unwrap_or(&l.stiffness);
        let d = d.unwrap_or(&l.damping);
        crate::rate::check_level(&mut l.rate, i, k, d, period)
    }

    /// Scales every level's spring by κ in (0, 1]: V_i becomes κ V_i and its
    /// gradient κ ∂V_i/∂x_i (after the spring saturation), as if every K_i
    /// were κ K_i; the damping D_i is unchanged. With κ = 1 the law is the
    /// paper's, bit for bit. A contact reaction's softening (hcc-cycle) ramps κ
    /// smoothly; a time-varying κ adds the power κ̇ Σ V_i to the storage
    /// Σ S_i (Sec. IV), which is ≤ 0 while κ falls and at most (1 − κ_min)
    /// Σ V_i over a whole rise. A value outside (0, 1] or not finite is
    /// ignored (κ kept). Allocation-free.
    pub fn set_stiffness_scale(&mut self, kappa: f64) {
        if kappa > 0.0 && kappa <= 1.0 {
            self.stiffness_scale = kappa;
        }
    }

    /// κ ([`Controller::set_stiffness_scale`]).
    pub fn stiffness_scale(&self) -> f64 {
        self.stiffness_scale
    }

    /// Sets the virtual equilibrium x_{i,d} of level `i` without allocating.
    pub fn set_goal(&mut self, i: usize, goal: &[f64]) -> Result<(), ControlError> {
        let Some(l) = self.levels.get_mut(i) else {
            return Err(ControlError::BadInput("no such level"));
        };
        if goal.len() != l.goal.len() || goal.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::BadInput(
                "goal has the wrong length or a non-finite value",
            ));
        }
        if l.goal.as_slice() != goal {
            l.goal.as_mut_slice().copy_from_slice(goal);
            l.pot.set_goal(&self.spec.levels[i].tasks, goal, self.n);
            self.safety.release_conflict(i);
            self.safety.refill_passivity_budget();
        }
        Ok(())
    }

    /// Sets the stiffness K_i and/or the damping D_i of level `i` (m_i × m_i)
    /// of the spring–damper F_i (eqs. 20, 21) without allocating; `None`
    /// keeps one. They must be symmetric positive definite for the stability
    /// of Sec. IV: a wrong size, a non-finite or asymmetric matrix, or a
    /// diagonal entry ≤ 0 is an error and changes nothing; full positive
    /// definiteness is the caller's check (`hcc_msgs::Setpoint::validate`).
    pub fn set_gains(
        &mut self,
        i: usize,
        stiffness: Option<&DMatrix<f64>>,
        damping: Option<&DMatrix<f64>>,
    ) -> Result<(), ControlError> {
        let Some(l) = self.levels.get_mut(i) else {
            return Err(ControlError::BadInput("no such level"));
        };
        for g in [stiffness, damping].into_iter().flatten() {
            let bad = g.shape() != (l.m, l.m)
                || g.iter().any(|x| !x.is_finite())
                || (0..l.m).any(|a| g[(a, a)] <= 0.0)
                || (0..l.m).any(|a| (0..a).any(|b| g[(a, b)] != g[(b, a)]));
            if bad {
                return Err(ControlError::BadInput(
                    "gain has the wrong size, a non-finite value, is asymmetric or not positive",
                ));
            }
        }
        if let Some(k) = stiffness {
            l.stiffness.copy_from(k);
        }
        if let Some(d) = damping {
            l.damping.copy_from(d);
        }
        self.safety.set_spring_radius(i, &l.stiffness, &l.damping);
        self.safety.refill_passivity_budget();
        Ok(())
    }

    /// Sets the velocity ẋ_{i,d} of level `i`'s equilibrium (m_i values, the
    /// task's velocity: m/s, world-frame angular velocity in rad/s, joint
    /// rad/s) without allocating. The damping then acts on ẋ_i − ẋ_{i,d}, so
    /// a moving goal is tracked without lag; all zeros restore the paper's
    /// D_i ẋ_i exactly.
    pub fn set_goal_velocity(&mut self, i: usize, velocity: &[f64]) -> Result<(), ControlError> {
        let Some(l) = self.levels.get_mut(i) else {
            return Err(ControlError::BadInput("no such level"));
        };
        if velocity.len() != l.m || velocity.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::BadInput(
                "goal velocity has the wrong length or a non-finite value",
            ));
        }
        l.goal_velocity.as_mut_slice().copy_from_slice(velocity);
        l.goal_moving = velocity.iter().any(|&x| x != 0.0);
        Ok(())
    }

    /// Level `i`'s current goal x_{i,d}, velocity ẋ_{i,d}, K_i and D_i.
    pub fn level_target(&self, i: usize) -> Option<LevelTarget<'_>> {
        self.levels.get(i).map(|l| LevelTarget {
            goal: l.goal.as_slice(),
            goal_velocity: l.goal_velocity.as_slice(),
            stiffness: &l.stiffness,
            damping: &l.damping,
        })
    }

    /// One control cycle: from the measured (q, q̇) to the torque command in
    /// [`StepOutput::tau`]. Allocation-free. On non-finite input it returns an error and
    /// leaves the previous output untouched; a numerical failure (which the damping
    /// should prevent) returns an error with τ set to g (or 0 without gravity compensation).
    pub fn step(&mut self, q: &[f64], qd: &[f64]) -> Result<&StepOutput, ControlError> {
        if q.len() != self.n || qd.len() != self.n {
            return Err(ControlError::BadInput(
                "state has the wrong number of joints",
            ));
        }
        if q.iter().chain(qd.iter()).any(|x| !x.is_finite()) {
            return Err(ControlError::BadInput("state has a non-finite value"));
        }
        self.q.as_mut_slice().copy_from_slice(q);
        self.qd.as_mut_slice().copy_from_slice(qd);
        let (q, qd) = (std::mem::take(&mut self.q), std::mem::take(&mut self.qd));
        let res = self.compute(&q, &qd);
        self.q = q;
        self.qd = qd;
        match res {
            Ok(()) => Ok(&self.out),
            Err(e) => {
                let gc = self.spec.gravity_compensation
                    && self.out.gravity.iter().all(|x| x.is_finite());
                for i in 0..self.n {
                    self.out.tau[i] = if gc { self.out.gravity[i] } else { 0.0 };
                }
                Err(e)
            }
        }
    }

    /// One evaluation of the law at (q, q̇) into [`Controller::output`].
    fn compute(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), ControlError> {
        let r = self.levels.len();
        let eps = self.spec.singular_ratio;
        hcc_model::compute_all_terms(&self.model, &mut self.data, q, qd);
        // M = L Lᵀ (M⁻¹ is only ever applied, by solves) and Ṁ = C + Cᵀ (Sec. II).
        copy(&mut self.chol, &self.data.m);
        hcc_model::linalg::cholesky_factor(&mut self.chol)
            .map_err(|_| ControlError::Numerical("M is not positive definite"))?;
        sym_sum_transpose(&mut self.mdot, &self.data.c);
        copy(&mut self.out.gravity, &self.data.g);

        // Safety layer: the speed each joint reaches before the rate-limited
        // applied torque can stop it (crate::safety; |q̇| without a rate limit).
        self.applied_acceleration(qd);
        let applied_qdd = self.have_applied.then_some(&self.applied_qdd);
        self.safety.set_reach(qd, applied_qdd, &self.chol);

        // Task quantities x̃_i, J_i, J̇_i, ∂V_i/∂x_i, F_i = ∂V/∂x + D ẋ (eqs. 20, 21).
        self.frames.invalidate();
        self.out.safety.spring_saturated = false;
        // Safety layer: the velocity governor's gain from the joint speeds
        // (crate::safety; 0, and the springs untouched, below the velocity band).
        let governor = self.safety.governor_gain(qd);
        self.out.safety.velocity_governor = governor;
        let speed = if governor > 0.0 { qd.norm() } else { 0.0 };
        for i in 0..r {
            self.evaluate_task(i, q, qd, governor, speed);
        }

        // The levels above the lowest, stacked: Y = J M⁻¹ (by solves, M⁻¹ is never
        // formed), W = J M⁻¹ Jᵀ, whose diagonal blocks are J_i M⁻¹ J_iᵀ and whose
        // leading blocks are J_aug M⁻¹ J_augᵀ (eq. 8), and their derivatives with
        // d/dt M⁻¹ = −M⁻¹ Ṁ M⁻¹.
        self.stack_top()?;
        self.first_level();
        for i in 1..r {
            self.null_space_level(i)?;
        }
        self.out.any_singular = self.out.singular.iter().any(|&s| s);
        // Safety layer: a fade-in is paid from the energy tank (crate::safety).
        self.passive_fade();
        // τ_μ involves every level's Λ_i and J̄̇_i: it fades with any of them.
        self.out.fade_mu = self
            .out
            .conditioning
            .iter()
            .map(|&c| fade_factor(c, eps))
            .product();

        self.out.safety.spring_saturated_cycles += u64::from(self.out.safety.spring_saturated);
        self.level_torques(qd);
        self.coriolis_cancellation(qd)?;
        // Safety layer: null-space damping of faded levels, the passivity
        // damping, joint position and velocity limits (crate::safety); zero and
        // not added where nothing acts.
        self.safety_torque(q, qd);
        // τ = Σ τ_i + τ_μ + g (eq. 19) (+ τ_safety where it acts).
        copy(&mut self.out.tau, &self.out.tau_mu);
        for t in &self.out.tau_level {
            self.out.tau += t;
        }
        if self.out.safety.active {
            self.out.tau += &self.out.safety.tau;
        }
        if self.spec.form == Form::KinematicProjector {
            // The comparison law adds C q̇ instead of τ_μ.
            gemv(&mut self.out.coriolis, 1.0, &self.data.c, qd, 0.0);
            self.out.tau += &self.out.coriolis;
        }
        // Safety layer: the velocity barrier, on the acceleration this τ gives.
        self.velocity_barrier(qd);
        if self.spec.gravity_compensation {
            self.out.tau += &self.data.g;
        }
        if self.out.tau.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::Numerical("non-finite torque"));
        }
        Ok(())
    }

    /// The passive fade of the safety layer (crate::safety): the fade factors of
    /// this cycle may only remove energy; a fade-in is paid from the energy tank.
    fn passive_fade(&mut self) {
        // Σ β_i ẋ_iᵀ D_i ẋ_i = Σ β_i ẋ_iᵀ (F_i − ∂V_i/∂x_i) (β of the last cycle).
        let mut p1 = 0.0;
        for (i, l) in self.levels.iter().enumerate() {
            let beta = self.safety.last_fade(i);
            p1 += beta * (l.xdot.dot(&l.f) - l.xdot.dot(&l.grad));
            self.out.potential[i] = l.potential;
        }
        let (fade, pot) = (&mut self.out.fade, &self.out.potential);
        let cond = &self.out.conditioning;
        self.safety
            .passive_fade(fade, pot, p1, cond, &mut self.out.safety);
    }

    /// The acceleration the applied torque ([`Controller::set_applied_torque`])
    /// gives on the model, M⁻¹ (τ_applied − g − C q̇) (g only where the
    /// controller adds it: the robot adds it itself otherwise), into
    /// `applied_qdd`; `have_applied` false when there is none or the solve fails.
    fn applied_acceleration(&mut self, qd: &DVector<f64>) {
        if !self.have_applied {
            return;
        }
        let a = &mut self.applied_qdd;
        gemv(a, -1.0, &self.data.c, qd, 0.0);
        *a += &self.applied_tau;
        if self.spec.gravity_compensation {
            *a -= &self.data.g;
        }
        self.have_applied = hcc_model::linalg::cholesky_solve_in_place(&self.chol, a).is_ok();
    }

    /// The velocity barrier of the safety layer (crate::safety): the
    /// acceleration q̈ = M⁻¹ (τ − C q̇) that τ (gravity not yet added: it
    /// cancels g) gives on the model, and the barrier's torque added to τ
    /// where a joint in the velocity band is driven too fast (or, with a torque
    /// rate limit downstream, driven faster than it could still be stopped).
    /// Nothing is computed while every joint is below the band and no rate
    /// limit follows.
    fn velocity_barrier(&mut self, qd: &DVector<f64>) {
        if !self.safety.barrier_needs_acceleration(qd) {
            if self.out.safety.barrier_active {
                self.out.safety.barrier_tau.fill(0.0);
                self.out.safety.barrier_active = false;
            }
            return;
        }
        gemv(&mut self.barrier_qdd, 1.0, &self.data.c, qd, 0.0);
        self.barrier_qdd.neg_mut();
        // The applied torque's acceleration: M⁻¹ (τ_applied − g − C q̇) (g only
        // where the controller adds it; the robot adds it itself otherwise).
        self.barrier_qdd += &self.out.tau;
        if hcc_model::linalg::cholesky_solve_in_place(&self.chol, &mut self.barrier_qdd).is_err() {
            return;
        }
        let applied_qdd = self.have_applied.then_some(&self.applied_qdd);
        if self.safety.velocity_barrier(
            qd,
            &self.barrier_qdd,
            applied_qdd,
            &self.chol,
            &mut self.out.safety,
        ) {
            self.out.tau += &self.out.safety.barrier_tau;
        }
    }

    /// The power the hierarchy's torques (τ_i of every level, τ_μ) put into the
    /// storage E = ½ q̇ᵀ M q̇ + Σ β_i V_i through the arm's motion:
    /// q̇ᵀ (Σ τ_i + τ_μ) + Σ β_i (∂V_i/∂x_i) J_i q̇ (the dampers' dissipation
    /// included, a moving goal's work on the springs not). In free motion it is
    /// ≤ 0 once the levels above each level have converged (Sec. IV); before that
    /// the projections of eqs. (20), (21) can feed energy in.
    fn hierarchy_power(&self, qd: &DVector<f64>) -> f64 {
        let mut p = self.out.tau_mu.dot(qd);
        for (i, l) in self.levels.iter().enumerate() {
            p += self.out.tau_level[i].dot(qd) + self.out.fade[i] * l.spring_rate;
        }
        if self.spec.form == Form::KinematicProjector {
            // The comparison law's C q̇: q̇ᵀ C q̇ = ½ q̇ᵀ Ṁ q̇.
            let n = self.n;
            let mut s = 0.0;
            for a in 0..n {
                for b in 0..n {
                    s += qd[a] * self.mdot[(a, b)] * qd[b];
                }
            }
            p += 0.5 * s;
        }
        p
    }

    /// The torque of the safety layer (crate::safety) into `out.safety`.
    fn safety_torque(&mut self, q: &DVector<f64>, qd: &DVector<f64>) {
        let hierarchy_power = self.hierarchy_power(qd);
        let goal_moving = self.levels.iter().any(|l| l.goal_moving);
        let terms = crate::safety::CycleTerms {
            hierarchy_power,
            goal_moving,
            q,
            qd,
            m: &self.data.m,
            chol: &self.chol,
            jtop: &self.jtop,
            w: &self.w,
            fade: &self.out.fade,
            conditioning: &self.out.conditioning,
            potential: &self.out.potential,
            singular_ratio: self.spec.singular_ratio,
        };
        self.safety.torque(&terms, &mut self.out.safety);
    }

    /// The levels above the lowest, stacked (see the comment in [`Controller::compute`]).
    fn stack_top(&mut self) -> Result<(), ControlError> {
        let n = self.n;
        let mut row = 0;
        let top = self.jtop.nrows();
        for l in &self.levels {
            if row == top {
                break;
            }
            copy_block(&mut self.jtop, row, 0, &l.j, 0, 0, l.m, n);
            copy_block(&mut self.jtop_dot, row, 0, &l.jdot, 0, 0, l.m, n);
            row += l.m;
        }
        transpose_into(&mut self.jtop_t, &self.jtop);
        copy(&mut self.yt, &self.jtop_t);
        hcc_model::linalg::cholesky_solve_slice(self.chol.as_slice(), n, self.yt.as_mut_slice())
            .map_err(|_| ControlError::Numerical("M⁻¹ Jᵀ"))?;
        gemm(&mut self.w, 1.0, &self.jtop, &self.yt, 0.0);
        if self.middle {
            transpose_into(&mut self.yt_dot, &self.jtop_dot);
            gemm(&mut self.yt_dot, -1.0, &self.mdot, &self.yt, 1.0);
            hcc_model::linalg::cholesky_solve_slice(
                self.chol.as_slice(),
                n,
                self.yt_dot.as_mut_slice(),
            )
            .map_err(|_| ControlError::Numerical("d/dt M⁻¹ Jᵀ"))?;
            gemm_leading(&mut self.w_dot, 1.0, &self.jtop_dot, &self.yt, 0.0);
            gemm_leading(&mut self.w_dot, 1.0, &self.jtop, &self.yt_dot, 1.0);
        }
        Ok(())
    }

    /// Level 1: Λ_1 = (J_1 M⁻¹ J_1ᵀ)⁻¹ (eq. 18), J̄_1 = J_1.
    fn first_level(&mut self) {
        let eps = self.spec.singular_ratio;
        let l = &mut self.levels[0];
        copy_block(&mut l.lambda_inv, 0, 0, &self.w, 0, 0, l.m, l.m);
        let c = damped_spd_inverse(&l.lambda_inv, &mut l.lambda, &mut l.spd, eps, GRAM_FLOOR);
        self.first_cond = c;
        self.out.conditioning[0] = c.ratio;
        self.out.singular[0] = c.damping > 0.0;
        copy(&mut l.jbar, &l.j);
        // (J̄⁻¹)_1 = J_1^{M+} = M⁻¹ J_1ᵀ Λ_1 (eq. 13); M⁻¹ J_1ᵀ is the first m_1
        // columns of M⁻¹ Jᵀ.
        gemm_leading(&mut l.jbar_inv, 1.0, &self.yt, &l.lambda, 0.0);
    }

    /// Null-space level i ≥ 2 (eqs. 5–13, 16–18).
    fn null_space_level(&mut self, i: usize) -> Result<(), ControlError> {
        let (r, eps) = (self.levels.len(), self.spec.singular_ratio);
        let lowest = i == r - 1;
        if lowest {
            self.null_space()?;
        }
        let (above, rest) = self.levels.split_at_mut(i);
        let l = &mut rest[0];
        let (c, gc) = if lowest {
            // Z_r = V_{r−1}ᵀ and Λ_r = Vᵀ M V (eq. 18) with its inverse S and derivative
            // X from the null space; J̄_r = S (M V)ᵀ (eq. 5).
            let ns = &mut self.basis;
            // Vᵀ and V̇ᵀ of this cycle, handed over (the buffers swap; the null space
            // forms both afresh every cycle).
            std::mem::swap(&mut l.z, &mut ns.vt);
            std::mem::swap(&mut l.zdot, &mut ns.vdot_t);
            copy(&mut l.lambda, &ns.vtmv);
            copy(&mut l.lambda_inv, &ns.s);
            copy(&mut l.lambda_dot, &ns.x);
            gemm_nt(&mut ns.jbar_t, 1.0, &ns.mv, &ns.s, 0.0);
            transpose_into(&mut l.jbar, &ns.jbar_t);
            (ns.s_cond, ns.gram_cond)
        } else {
            // Z_i = J_i M⁻¹ N_i (eq. 11) with N_i = I − J_augᵀ (J_aug^{M+})ᵀ (eq. 8):
            // Z_i = Y_i − T Y_aug, T = H G⁻¹, and Ż_i = Ẏ_i − Ṫ Y_aug − T Ẏ_aug with
            // Ṫ = (Ḣ − T Ġ) G⁻¹ — the same Z_i as eq. (12), without a null-space basis.
            let p = &mut l.proj;
            let (k, m) = (p.k, l.m);
            copy_block(&mut p.gdot, 0, 0, &self.w_dot, 0, 0, k, k);
            copy_block(&mut p.h, 0, 0, &self.w, k, 0, m, k);
            copy_block(&mut p.hdot, 0, 0, &self.w_dot, k, 0, m, k);
            // Y_i and Ẏ_i: rows k..k + m of Y and Ẏ; Y_aug and Ẏ_aug (rows 0..k) are
            // read in place as the leading columns of Yᵀ = M⁻¹ Jᵀ and its derivative.
            transpose_cols_into(&mut l.z, &self.yt, k);
            transpose_cols_into(&mut l.zdot, &self.yt_dot, k);
            if i == 1 {
                // G = J_1 M⁻¹ J_1ᵀ = Λ_1⁻¹: its damped inverse is level 1's Λ_1.
                copy(&mut p.g_inv, &above[0].lambda);
                p.g_cond = self.first_cond;
            } else {
                copy_block(&mut p.g, 0, 0, &self.w, 0, 0, k, k);
                p.g_cond = damped_spd_inverse(&p.g, &mut p.g_inv, &mut p.spd, eps, GRAM_FLOOR);
            }
            gemm(&mut p.t, 1.0, &p.h, &p.g_inv, 0.0);
            gemm(&mut p.hdot, -1.0, &p.t, &p.gdot, 1.0);
            gemm(&mut p.tdot, 1.0, &p.hdot, &p.g_inv, 0.0);
            gemm_nt_leading(&mut l.z, -1.0, &p.t, &self.yt, 1.0);
            gemm_nt_leading(&mut l.zdot, -1.0, &p.tdot, &self.yt, 1.0);
            gemm_nt_leading(&mut l.zdot, -1.0, &p.t, &self.yt_dot, 1.0);
            // Λ_i = Z M Zᵀ (eq. 18) and Λ̇_i = Ż M Zᵀ + Z M Żᵀ + Z Ṁ Zᵀ.
            gemm(&mut l.zm, 1.0, &l.z, &self.data.m, 0.0);
            gemm(&mut l.zmdot, 1.0, &l.z, &self.mdot, 0.0);
            gemm_nt(&mut l.lambda, 1.0, &l.zm, &l.z, 0.0);
            // Z M Żᵀ = (Ż M Zᵀ)ᵀ, its elements the same sums of the same products.
            gemm_nt(&mut l.lambda_dot, 1.0, &l.zdot, &l.zm, 0.0);
            add_own_transpose(&mut l.lambda_dot);
            gemm_nt(&mut l.lambda_dot, 1.0, &l.zmdot, &l.z, 1.0);
            let c = damped_spd_inverse(&l.lambda, &mut l.lambda_inv, &mut l.spd, eps, GRAM_FLOOR);
            // J̄_i = (Z M Zᵀ)⁻¹ Z M (eq. 5).
            gemm(&mut l.jbar, 1.0, &l.lambda_inv, &l.zm, 0.0);
            (c, p.g_cond)
        };
        self.out.conditioning[i] = c.ratio.min(gc.ratio);
        self.out.singular[i] = c.damping > 0.0 || gc.damping > 0.0;
        // The projection of level i inverts the Gram matrix of the levels above
        // it: its torque fades as that one becomes singular (crate docs).
        self.out.fade[i] = fade_factor(gc.ratio, eps);
        // (J̄⁻¹)_i = Z_iᵀ (eq. 13): read as Z_iᵀ where it is applied, never formed.
        Ok(())
    }

    /// Torques of the levels (eqs. 20, 21) and the local velocities v_i (eq. 3).
    fn level_torques(&mut self, qd: &DVector<f64>) {
        let r = self.levels.len();
        for i in 0..r {
            let l = &mut self.levels[i];
            gemv(&mut l.v, 1.0, &l.jbar, qd, 0.0);
            let tau_i = &mut self.out.tau_level[i];
            if i == 0 {
                gemv_t(tau_i, -1.0, &l.j, &l.f, 0.0);
            } else {
                gemv_t(&mut self.tmp_n, 1.0, &l.j, &l.f, 0.0);
                match self.spec.form {
                    Form::Extended => {
                        gemv(&mut l.y_d, 1.0, &l.z, &self.tmp_n, 0.0);
                        gemv_t(tau_i, -1.0, &l.jbar, &l.y_d, 0.0);
                    }
                    Form::ClassicalProjector if i == r - 1 => {
                        // N_r J_rᵀ F_r with N_r = M V S Vᵀ (eq. 9).
                        let ns = &mut self.basis;
                        gemv_t(&mut ns.y_nd, 1.0, &ns.v, &self.tmp_n, 0.0);
                        gemv(&mut ns.y_nd2, 1.0, &ns.s, &ns.y_nd, 0.0);
                        gemv(&mut self.tmp_n2, 1.0, &ns.v, &ns.y_nd2, 0.0);
                        gemv(tau_i, -1.0, &self.data.m, &self.tmp_n2, 0.0);
                    }
                    Form::ClassicalProjector => {
                        // N_i J_iᵀ F_i with N_i = I − J_augᵀ G⁻¹ J_aug M⁻¹ (eq. 8).
                        let p = &mut l.proj;
                        transpose_cols_into(&mut p.y_aug, &self.yt, 0);
                        gemv(&mut p.y_k, 1.0, &p.y_aug, &self.tmp_n, 0.0);
                        p.y_top.fill(0.0);
                        let (yk, gi) = (&p.y_k, &p.g_inv);
                        for a in 0..p.k {
                            let mut s = 0.0;
                            for b in 0..p.k {
                                s += gi[(a, b)] * yk[b];
                            }
                            p.y_top[a] = s;
                        }
                        copy(tau_i, &self.tmp_n);
                        gemv_t(tau_i, 1.0, &self.jtop, &p.y_top, -1.0);
                    }
                    Form::KinematicProjector => {
                        // (I − J_1ᵀ (J_1ᵀ)⁺) τ_2 with (J_1ᵀ)⁺ = (J_1 J_1ᵀ)⁻¹ J_1 (r = 2:
                        // `jtop` = J_1, the Gram matrix and its damped inverse are the
                        // null space's), τ_2 = −J_2ᵀ F_2.
                        let ns = &mut self.basis;
                        gemv(&mut ns.y_k, 1.0, &self.jtop, &self.tmp_n, 0.0);
                        gemv(&mut ns.y_k2, 1.0, &ns.gram_inv, &ns.y_k, 0.0);
                        copy(tau_i, &self.tmp_n);
                        gemv_t(tau_i, 1.0, &self.jtop, &ns.y_k2, -1.0);
                    }
                }
            }
            if self.out.fade[i] < 1.0 {
                *tau_i *= self.out.fade[i];
            }
            copy(&mut self.out.v[i], &l.v);
            copy(&mut self.out.task_error[i], &l.err);
            self.out.potential[i] = l.potential;
            // S_i = ½ v_iᵀ Λ_i v_i + V_i (eqs. 26, 28).
            gemv(&mut l.y_d2, 1.0, &l.lambda, &l.v, 0.0);
            self.out.storage[i] = 0.5 * l.v.dot(&l.y_d2) + l.potential;
        }
    }

    /// τ_μ = Σ_i J̄_iᵀ Σ_{j≠i} μ_ij v_j (eq. 22) with μ = Λ (J̄ M⁻¹ C − J̄̇) J̄⁻¹ (eq. 17):
    /// Σ_{j≠i} (J̄⁻¹)_j v_j = q̇ − (J̄⁻¹)_i v_i = u, so each level needs one
    /// matrix-vector chain, J̄̇_i u = Λ_i⁻¹ (Ż_i M u + Z_i Ṁ u − Λ̇_i J̄_i u) included
    /// (J̄̇_1 = J̇_1): J̄̇_i itself is never formed.
    fn coriolis_cancellation(&mut self, qd: &DVector<f64>) -> Result<(), ControlError> {
        let r = self.levels.len();
        self.out.tau_mu.fill(0.0);
        if self.spec.coriolis_cancellation && self.spec.form != Form::KinematicProjector {
            // The levels' u as the columns of U, then C U, M⁻¹ C U (one solve for all
            // levels, whose substitutions overlap), M U and Ṁ U.
            let (mu, n) = (&mut self.mu, self.n);
            let us = mu.u.as_mut_slice().chunks_exact_mut(n);
            for (i, (l, u)) in self.levels.iter().zip(us).enumerate() {
                u.copy_from_slice(qd.as_slice());
                if i == 0 {
                    gemv_slices(u, -1.0, &l.jbar_inv, l.v.as_slice(), 1.0);
                } else {
                    // (J̄⁻¹)_i = Z_iᵀ (eq. 13).
                    gemv_t_slices(u, -1.0, &l.z, l.v.as_slice(), 1.0);
                }
            }
            gemm(&mut mu.minv_cu, 1.0, &self.data.c, &mu.u, 0.0);
            hcc_model::linalg::cholesky_solve_slice(
                self.chol.as_slice(),
                self.n,
                mu.minv_cu.as_mut_slice(),
            )
            .map_err(|_| ControlError::Numerical("M⁻¹ C"))?;
            if r > 1 {
                gemm(&mut mu.mu, 1.0, &self.data.m, &mu.u, 0.0);
                gemm(&mut mu.mdot_u, 1.0, &self.mdot, &mu.u, 0.0);
            }
            for i in 0..r {
                let l = &mut self.levels[i];
                let u = col(&mu.u, i, n);
                let y_d = l.y_d.as_mut_slice();
                gemv_slices(y_d, 1.0, &l.jbar, col(&mu.minv_cu, i, n), 0.0);
                if i == 0 {
                    gemv_slices(y_d, -1.0, &l.jdot, u, 1.0);
                } else {
                    let y_d3 = l.y_d3.as_mut_slice();
                    gemv_slices(y_d3, 1.0, &l.zdot, col(&mu.mu, i, n), 0.0);
                    gemv_slices(y_d3, 1.0, &l.z, col(&mu.mdot_u, i, n), 1.0);
                    gemv_slices(l.y_d2.as_mut_slice(), 1.0, &l.jbar, u, 0.0);
                    gemv(&mut l.y_d3, -1.0, &l.lambda_dot, &l.y_d2, 1.0);
                    gemv(&mut l.y_d, -1.0, &l.lambda_inv, &l.y_d3, 1.0);
                }
                gemv(&mut l.y_d2, 1.0, &l.lambda, &l.y_d, 0.0);
                gemv_t(&mut self.out.tau_mu, 1.0, &l.jbar, &l.y_d2, 1.0);
            }
        }
        if self.out.fade_mu < 1.0 {
            self.out.tau_mu *= self.out.fade_mu;
        }
        self.out.p_mu = self.out.tau_mu.dot(qd);
        Ok(())
    }

    /// Null space of the augmented Jacobian above the lowest level (eqs. 6–9): the
    /// basis V_{r−1}, its derivative V̇ = −J⁺ J̇ V (parallel transport), M V, Ṁ V,
    /// Vᵀ M V, its inverse S and X = d/dt (VᵀMV). The basis is kept continuous in
    /// time (Z_r = V_{r−1}ᵀ depends on it).
    fn null_space(&mut self) -> Result<(), ControlError> {
        let eps = self.spec.singular_ratio;
        let ns = &mut self.basis;
        let (jaug, jaug_t, jaug_dot) = (&self.jtop, &self.jtop_t, &self.jtop_dot);
        // J⁺ = Jᵀ (J Jᵀ)⁻¹ (damped near singularities).
        gemm_nt(&mut ns.gram, 1.0, jaug, jaug, 0.0);
        ns.gram_cond =
            damped_spd_inverse(&ns.gram, &mut ns.gram_inv, &mut ns.spd_k, eps, GRAM_FLOOR);
        // The basis V: the previous cycle's basis projected onto the null space,
        // W = (I − J⁺ J) V_prev, and orthonormalised by its polar factor — the
        // orthonormal basis of null(J) closest to V_prev (the Procrustes-aligned one).
        // Unlike a fresh factorisation this stays continuous when J_aug loses rank
        // (the null space grows, W keeps following V_prev). Without a usable previous
        // basis (first cycle, after `reset`, or a jump of the state): Householder QR,
        // aligned to the previous basis when there is one.
        let mut continued = false;
        if ns.has_prev {
            gemm(&mut ns.t1, 1.0, jaug, &ns.v_prev, 0.0);
            gemm(&mut ns.t2, 1.0, &ns.gram_inv, &ns.t1, 0.0);
            copy(&mut ns.v, &ns.v_prev);
            gemm(&mut ns.v, -1.0, jaug_t, &ns.t2, 1.0);
            continued = orthonormalize_polar(&mut ns.v, &mut ns.align, MIN_OVERLAP) > MIN_OVERLAP;
        }
        if !continued {
            null_space_basis(jaug, &mut ns.qr_work, &mut ns.qr_q, &mut ns.v);
            if ns.has_prev {
                procrustes_align(&mut ns.v, &ns.v_prev, &mut ns.align);
            }
        }
        copy(&mut ns.v_prev, &ns.v);
        ns.has_prev = true;
        // V̇ = −J⁺ J̇ V (parallel transport).
        gemm(&mut ns.t1, 1.0, jaug_dot, &ns.v, 0.0);
        gemm(&mut ns.t2, 1.0, &ns.gram_inv, &ns.t1, 0.0);
        gemm(&mut ns.vdot, -1.0, jaug_t, &ns.t2, 0.0);
        // S = (VᵀMV)⁻¹ (always positive definite) and X = V̇ᵀMV + VᵀṀV + VᵀMV̇; the
        // products with Vᵀ and V̇ᵀ (= Z_r and Ż_r) by the column kernel, the symmetric
        // ones with the upper triangle mirrored.
        transpose_into(&mut ns.vt, &ns.v);
        transpose_into(&mut ns.vdot_t, &ns.vdot);
        gemm(&mut ns.mv, 1.0, &self.data.m, &ns.v, 0.0);
        gemm_sym(&mut ns.vtmv, &ns.vt, &ns.mv);
        ns.s_cond = damped_spd_inverse(&ns.vtmv, &mut ns.s, &mut ns.spd_d, eps, GRAM_FLOOR);
        gemm(&mut ns.mdv, 1.0, &self.mdot, &ns.v, 0.0);
        gemm_sym(&mut ns.x, &ns.vt, &ns.mdv);
        gemm(&mut ns.tmp_dd, 1.0, &ns.vdot_t, &ns.mv, 0.0);
        ns.x += &ns.tmp_dd;
        transpose_add(&mut ns.x, &ns.tmp_dd);
        Ok(())
    }

    /// x̃_i, J_i, J̇_i, the potential V_i and its gradient, ẋ_i and F_i; the
    /// spring part scaled by the velocity governor (gain `governor`, `speed` = ‖q̇‖;
    /// crate::safety) where it drives the motion near a velocity limit.
    fn evaluate_task(
        &mut self,
        i: usize,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        governor: f64,
        speed: f64,
    ) {
        let l = &mut self.levels[i];
        let tasks = &self.spec.levels[i].tasks;
        let (model, data) = (&self.model, &self.data);
        crate::task::jacobian(
            model,
            data,
            tasks,
            &mut self.frames,
            &mut l.j,
            Some(&mut l.jdot),
        );
        l.potential = crate::task::potential(
            model,
            data,
            tasks,
            &mut self.frames,
            q,
            &l.stiffness,
            &l.goal,
            &mut l.pot,
            &mut l.err,
            &mut l.grad,
        );
        // Safety layer: the spring saturation (crate::safety): beyond r_0 the
        // gradient of the saturated potential, which replaces V_i.
        let (v_sat, scale) = self.safety.saturate_spring(i, l.potential, &mut l.grad);
        l.potential = v_sat;
        if scale < 1.0 {
            self.out.safety.spring_saturated = true;
        }
        // A contact reaction's softening: κ V_i, a potential still.
        let kappa = self.stiffness_scale;
        if kappa != 1.0 {
            l.potential *= kappa;
            l.grad *= kappa;
        }
        gemv(&mut l.xdot, 1.0, &l.j, qd, 0.0);
        l.spring_rate = l.grad.dot(&l.xdot);
        if l.goal_moving {
            // A moving equilibrium: damp the velocity relative to it.
            l.xdot -= &l.goal_velocity;
        }
        // F_i = (∂V_i/∂x_i)ᵀ + D_i (ẋ_i − ẋ_{i,d}), ẋ_{i,d} = 0 for a fixed goal.
        copy(&mut l.f, &l.grad);
        let mut sigma = 1.0;
        if governor > 0.0 {
            // Velocity governor: σ_i from the spring's power and the cosine between
            // q̇ and −J_iᵀ ∂V_i/∂x_i (crate::safety).
            gemv_t(&mut self.tmp_n, 1.0, &l.j, &l.grad, 0.0);
            let power = self.tmp_n.dot(qd);
            sigma = crate::safety::spring_scale(governor, power, self.tmp_n.norm(), speed);
            if sigma < 1.0 {
                l.f *= sigma;
            }
        }
        self.out.safety.spring_scale[i] = sigma;
        gemv(&mut l.f, 1.0, &l.damping, &l.xdot, 1.0);
    }

    /// Diagnostics (not for the control loop: allocates). The stacked J̄ (eq. 4), J̄̇,
    /// J̄⁻¹ (eq. 13), Λ (eq. 16, block-diagonal by construction of eq. 18) and
    /// μ = Λ (J̄ M⁻¹ C − J̄̇) J̄⁻¹ (eq. 17) of the last cycle, plus M, M⁻¹, C and the
    /// level sizes d_i. Meaningful when the lowest level is a null-space level
    /// (Σ d_i = n).
    pub fn diagnostics(&self) -> Diagnostics {
        let n = self.n;
        let total: usize = self.levels.iter().map(|l| l.d).sum();
        let mut jbar = DMatrix::zeros(total, n);
        let mut jbar_dot = DMatrix::zeros(total, n);
        let mut jbar_inv = DMatrix::zeros(n, total);
        let mut lambda = DMatrix::zeros(total, total);
        let mut row = 0;
        for l in &self.levels {
            jbar.view_mut((row, 0), (l.d, n)).copy_from(&l.jbar);
            // J̄̇_1 = J̇_1, J̄̇_i = Λ_i⁻¹ (Ż M + Z Ṁ − Λ̇_i J̄_i) (not formed by the step).
            let jd = if row == 0 {
                l.jdot.clone()
            } else {
                &l.lambda_inv
                    * (&l.zdot * &self.data.m + &l.z * &self.mdot - &l.lambda_dot * &l.jbar)
            };
            jbar_dot.view_mut((row, 0), (l.d, n)).copy_from(&jd);
            // (J̄⁻¹)_1 = J_1^{M+}, (J̄⁻¹)_i = Z_iᵀ (eq. 13).
            let ji = if row == 0 {
                l.jbar_inv.clone()
            } else {
                l.z.transpose()
            };
            jbar_inv.view_mut((0, row), (n, l.d)).copy_from(&ji);
            lambda.view_mut((row, row), (l.d, l.d)).copy_from(&l.lambda);
            row += l.d;
        }
        let mut minv = DMatrix::identity(n, n);
        // The factor is valid after any cycle that got past M (else M⁻¹ is NaN).
        if hcc_model::linalg::cholesky_solve_matrix_in_place(&self.chol, &mut minv).is_err() {
            minv.fill(f64::NAN);
        }
        let mu = if total == n {
            &lambda * (&jbar * &minv * &self.data.c - &jbar_dot) * &jbar_inv
        } else {
            DMatrix::zeros(total, total)
        };
        Diagnostics {
            dims: self.levels.iter().map(|l| l.d).collect(),
            jacobians: self.levels.iter().map(|l| l.j.clone()).collect(),
            z: self.levels.iter().map(|l| l.z.clone()).collect(),
            jbar,
            jbar_dot,
            jbar_inv,
            lambda,
            mu,
            m: self.data.m.clone(),
            minv,
            c: self.data.c.clone(),
        }
    }
}

/// Stacked matrices of one cycle, for checks and debugging.
#[derive(Clone, Debug)]
pub struct Diagnostics {
    /// d_i = dim v_i per level.
    pub dims: Vec<usize>,
    /// J_i per level.
    pub jacobians: Vec<DMatrix<f64>>,
    /// Z_i per level (J_1 for level 1).
    pub z: Vec<DMatrix<f64>>,
    pub jbar: DMatrix<f64>,
    pub jbar_dot: DMatrix<f64>,
    pub jbar_inv: DMatrix<f64>,
    pub lambda: DMatrix<f64>,
    pub mu: DMatrix<f64>,
    pub m: DMatrix<f64>,
    pub minv: DMatrix<f64>,
    pub c: DMatrix<f64>,
}

/// `out = cᵀ + c` (square), one pass: (cᵀ + c)_ij = c_ji + c_ij is the same sum, to the
/// bit, as its mirror c_ij + c_ji, so the upper triangle is formed and mirrored.
fn sym_sum_transpose(out: &mut DMatrix<f64>, c: &DMatrix<f64>) {
    let n = c.nrows();
    assert_eq!(c.shape(), (n, n));
    assert_eq!(out.shape(), (n, n));
    let (o, c) = (out.as_mut_slice(), c.as_slice());
    for j in 0..n {
        for i in 0..=j {
            let x = c[i * n + j] + c[j * n + i];
            o[j * n + i] = x;
            o[i * n + j] = x;
        }
    }
}

/// `x = x + xᵀ` (square; exactly symmetric).
fn add_own_transpose(x: &mut DMatrix<f64>) {
    let n = x.nrows();
    assert_eq!(x.ncols(), n);
    let x = x.as_mut_slice();
    for j in 0..n {
        for i in 0..=j {
            let s = x[i * n + j] + x[j * n + i];
            x[j * n + i] = s;
            x[i * n + j] = s;
        }
    }
}

/// Column i of `x` (n rows) as a slice.
fn col(x: &DMatrix<f64>, i: usize, n: usize) -> &[f64] {
    &x.as_slice()[i * n..(i + 1) * n]
}

/// `out += aᵀ`.
fn transpose_add(out: &mut DMatrix<f64>, a: &DMatrix<f64>) {
    let (r, c) = a.shape();
    assert_eq!(out.shape(), (c, r));
    if r == 0 || c == 0 {
        return;
    }
    let a = a.as_slice();
    for (i, col) in out.as_mut_slice().chunks_exact_mut(c).enumerate() {
        for (o, x) in col.iter_mut().zip(a[i..].iter().step_by(r)) {
            *o += *x;
        }
    }
}

/// `dst[dr.., dc..] = src[sr..sr + rows, sc..sc + cols]`, column by column.
#[allow(clippy::too_many_arguments)]
fn copy_block(
    dst: &mut DMatrix<f64>,
    dr: usize,
    dc: usize,
    src: &DMatrix<f64>,
    sr: usize,
    sc: usize,
    rows: usize,
    cols: usize,
) {
    let (dm, sm) = (dst.nrows(), src.nrows());
    assert!(dr + rows <= dm && sr + rows <= sm);
    assert!(dc + cols <= dst.ncols() && sc + cols <= src.ncols());
    let (d, s) = (dst.as_mut_slice(), src.as_slice());
    // Short columns as fixed-size moves (no call of the general copy per column).
    match rows {
        1 => copy_cols::<1>(d, s, (dc * dm + dr, dm), (sc * sm + sr, sm), cols),
        2 => copy_cols::<2>(d, s, (dc * dm + dr, dm), (sc * sm + sr, sm), cols),
        3 => copy_cols::<3>(d, s, (dc * dm + dr, dm), (sc * sm + sr, sm), cols),
        4 => copy_cols::<4>(d, s, (dc * dm + dr, dm), (sc * sm + sr, sm), cols),
        5 => copy_cols::<5>(d, s, (dc * dm + dr, dm), (sc * sm + sr, sm), cols),
        6 => copy_cols::<6>(d, s, (dc * dm + dr, dm), (sc * sm + sr, sm), cols),
        _ => {
            for j in 0..cols {
                let o = (dc + j) * dm + dr;
                let i = (sc + j) * sm + sr;
                d[o..o + rows].copy_from_slice(&s[i..i + rows]);
            }
        }
    }
}

/// `cols` columns of `R` elements from `s` (first at `si`, columns `ss` apart) to `d`
/// (first at `di`, columns `ds` apart).
#[inline(always)]
fn copy_cols<const R: usize>(
    d: &mut [f64],
    s: &[f64],
    (di, ds): (usize, usize),
    (si, ss): (usize, usize),
    cols: usize,
) {
    for j in 0..cols {
        let (o, i) = (di + j * ds, si + j * ss);
        let x: [f64; R] = s[i..i + R].try_into().expect("R elements");
        d[o..o + R].copy_from_slice(&x);
    }
}
