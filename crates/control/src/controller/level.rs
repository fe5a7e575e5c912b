//! The per-level state: a level's task (J_i, J̇_i, x̃_i, F_i), its decomposition
//! (Z_i, J̄_i of eq. 5, Λ_i of eq. 18, v_i = J̄_i q̇ of eq. 3) and, for a level
//! between the first and the lowest, the blocks of the projector of eq. (8).

use super::tracking::TrackLevel;
use crate::energy_tank::EnergyTank;
use crate::rate::RateWork;
use crate::spec::{ControllerSpec, LevelSpec};
use crate::task::PotentialWork;
use hcc_linalg::spd::{Conditioning, SpdWork};
use nalgebra::{DMatrix, DVector};

/// Per-level workspace.
#[derive(Clone, Debug)]
pub(super) struct Level {
    pub(super) m: usize,
    /// Dimension of v_i: m_i, or n − Σ_{j<r} m_j for the lowest null-space level.
    pub(super) d: usize,
    pub(super) stiffness: DMatrix<f64>,
    pub(super) damping: DMatrix<f64>,
    pub(super) goal: DVector<f64>,
    /// R_d of the quaternion tasks and the buffers of the potential.
    pub(super) pot: PotentialWork,
    /// Velocity ẋ_{i,d} of a moving equilibrium (zero unless set; see
    /// [`Controller::set_goal_velocity`]); the damping acts on ẋ_i − ẋ_{i,d}.
    pub(super) goal_velocity: DVector<f64>,
    pub(super) goal_moving: bool,
    /// The rate of x_{i,d} a transition moves it at ([`Controller::ramp_goal`];
    /// its work on V_i is booked with it, also where the damper is not told
    /// ẋ_{i,d}); zero otherwise.
    pub(super) goal_rate: DVector<f64>,
    /// A path's sample set the goal for the coming period
    /// ([`Controller::follow_goal`]): `goal_rate` is the path's, its work an
    /// input of this cycle.
    pub(super) followed: bool,
    /// The potential's buffers at a goal not (yet) in force: the energy a
    /// step to a transition's target would store (`command_tank.rs`).
    pub(super) pot_target: PotentialWork,
    pub(super) goal_target: DVector<f64>,
    pub(super) err_target: DVector<f64>,
    pub(super) grad_target: DVector<f64>,
    /// The tracking form's buffers and desired local velocities (`tracking.rs`).
    pub(super) track: TrackLevel,
    // task
    pub(super) j: DMatrix<f64>,
    pub(super) jdot: DMatrix<f64>,
    pub(super) err: DVector<f64>,
    pub(super) grad: DVector<f64>,
    pub(super) xdot: DVector<f64>,
    pub(super) f: DVector<f64>,
    pub(super) potential: f64,
    /// (∂V_i/∂x_i) J_i q̇: the rate of V_i the arm's motion makes (not the goal's).
    pub(super) spring_rate: f64,
    /// The level's energy tank and its spring point's shift (crate::energy_tank;
    /// unused for level 1), whether it acted this cycle, w_i and κ_i.
    pub(super) tank: EnergyTank,
    pub(super) tank_planned: bool,
    /// E_i at this cycle's sample: after the refill, before the cycle books
    /// the coming period (what H counts with the state's ½q̇ᵀMq̇ and V_i).
    pub(super) tank_at_sample: f64,
    pub(super) w_up: DVector<f64>,
    pub(super) kappa: DVector<f64>,
    // decomposition
    pub(super) z: DMatrix<f64>,
    pub(super) zdot: DMatrix<f64>,
    pub(super) zm: DMatrix<f64>,
    pub(super) zmdot: DMatrix<f64>,
    pub(super) lambda: DMatrix<f64>,
    pub(super) lambda_inv: DMatrix<f64>,
    pub(super) lambda_dot: DMatrix<f64>,
    pub(super) jbar: DMatrix<f64>,
    /// The block column of J̄⁻¹ belonging to level 1 (eq. 13), n × m_1 (empty for the
    /// others: theirs is Z_iᵀ).
    pub(super) jbar_inv: DMatrix<f64>,
    pub(super) v: DVector<f64>,
    pub(super) y_d: DVector<f64>,
    pub(super) y_d2: DVector<f64>,
    pub(super) y_d3: DVector<f64>,
    pub(super) spd: SpdWork,
    /// The gains' check against the control rate (crate::rate).
    pub(super) rate: RateWork,
    /// Eq. (11) with (8) for 2 ≤ i < r (k = Σ_{j<i} m_j; empty otherwise):
    /// Z_i = J_i M⁻¹ N_i = Y_i − T Y_aug with Y = J M⁻¹, G = J_aug M⁻¹ J_augᵀ (k × k),
    /// H = J_i M⁻¹ J_augᵀ (m × k), T = H G⁻¹, and the derivatives of G, H, T, Y.
    pub(super) proj: Projection,
}

/// The blocks of eq. (8) for one level above the lowest.
#[derive(Clone, Debug)]
pub(super) struct Projection {
    pub(super) k: usize,
    pub(super) g: DMatrix<f64>,
    pub(super) g_inv: DMatrix<f64>,
    pub(super) gdot: DMatrix<f64>,
    pub(super) h: DMatrix<f64>,
    pub(super) hdot: DMatrix<f64>,
    pub(super) t: DMatrix<f64>,
    pub(super) tdot: DMatrix<f64>,
    /// Y_aug, formed for the classical form only.
    pub(super) y_aug: DMatrix<f64>,
    /// Vectors for the classical form N_i x = x − J_augᵀ G⁻¹ Y_aug x (eq. 8).
    pub(super) y_k: DVector<f64>,
    pub(super) y_top: DVector<f64>,
    pub(super) spd: SpdWork,
    pub(super) g_cond: Conditioning,
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
    /// The buffers of every level of `spec` (task dimensions `dims`, `n` joints)
    /// and K, the rows of the levels whose Jacobians are stacked: all above the
    /// lowest (level 1 alone for r = 1).
    pub(super) fn hierarchy(
        spec: &ControllerSpec,
        dims: &[usize],
        n: usize,
    ) -> (Vec<Level>, usize) {
        let r = spec.levels.len();
        let top = if r == 1 { 1 } else { r - 1 };
        let ktop: usize = dims[..top].iter().sum();
        let mut levels = Vec::with_capacity(r);
        let mut k = 0;
        for (i, l) in spec.levels.iter().enumerate() {
            levels.push(Level::new(l, i, r, dims[i], n, k, ktop));
            k += dims[i];
        }
        (levels, ktop)
    }

    /// Buffers of level `i` (0-based) of `r` for `n` joints: m = m_i, `k` = Σ_{j<i} m_j,
    /// `ktop` the rows of the levels above the lowest (its tank empty: the
    /// controller fills it in its first cycle).
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
            goal_rate: DVector::zeros(m),
            followed: false,
            pot_target: PotentialWork::new(&spec.tasks, &spec.goal, n),
            goal_target: DVector::zeros(m),
            err_target: DVector::zeros(m),
            grad_target: DVector::zeros(m),
            track: TrackLevel::new(m, d),
            j: DMatrix::zeros(m, n),
            jdot: DMatrix::zeros(m, n),
            err: DVector::zeros(m),
            grad: DVector::zeros(m),
            xdot: DVector::zeros(m),
            spring_rate: 0.0,
            tank: EnergyTank::new(m, 0.0),
            tank_planned: false,
            tank_at_sample: 0.0,
            w_up: DVector::zeros(m),
            kappa: DVector::zeros(m),
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
