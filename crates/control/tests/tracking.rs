//! The tracking form (docs/tracking.md), checked independently of the law's
//! own intermediate values: along a trajectory of every level of the paper's
//! planar 4-DOF arm, each level's closed loop satisfies the error dynamics
//! (T.4) Λ_i ṽ̇_i + μ_ii ṽ_i + Z_i J_iᵀ F_i = 0, with Z_i, J̄_i, Λ_i, μ_ii,
//! v_{i,d} and v̇_{i,d} formed here from the model alone (dense inverses,
//! eq. 11 for every level below the first, derivatives along the motion by
//! central differences), q̈ from the model's forward dynamics under the
//! command; and with no moving goal the law is the regulation law bit for bit.

mod common;
use common::*;
use hcc_control::Controller;
use hcc_model::{Data, Model};
use nalgebra::{DMatrix, DVector};
use std::f64::consts::PI;

/// A level's desired x_d(t), ẋ_d(t), ẍ_d(t): base + amplitude · sin(ω t) per row.
struct Wave {
    base: Vec<f64>,
    amp: Vec<f64>,
    omega: Vec<f64>,
}

impl Wave {
    fn at(&self, t: f64) -> [DVector<f64>; 3] {
        let m = self.base.len();
        let x = DVector::from_fn(m, |a, _| {
            self.base[a] + self.amp[a] * (self.omega[a] * t).sin()
        });
        let xd = DVector::from_fn(m, |a, _| {
            self.amp[a] * self.omega[a] * (self.omega[a] * t).cos()
        });
        let xdd = DVector::from_fn(m, |a, _| {
            -self.amp[a] * self.omega[a].powi(2) * (self.omega[a] * t).sin()
        });
        [x, xd, xdd]
    }
}

/// The planar arm's three task maps and their Jacobians, from the model.
struct Planar {
    model: Model,
    data: Data,
    tcp: hcc_model::FrameId,
}

impl Planar {
    fn new() -> Planar {
        let model = planar();
        let tcp = model.frame_id("tcp").expect("tcp");
        Planar {
            data: Data::new(&model),
            model,
            tcp,
        }
    }

    /// x_i(q) and J_i(q) of level `i` (0: TCP x, y; 1: q1+…+q4; 2: q1).
    fn task(&mut self, i: usize, q: &DVector<f64>) -> (DVector<f64>, DMatrix<f64>) {
        match i {
            0 => {
                hcc_model::forward_kinematics(&self.model, &mut self.data, q);
                let p = hcc_model::frame_placement(&self.model, &self.data, self.tcp);
                let mut j6 = DMatrix::zeros(6, 4);
                hcc_model::frame_jacobian(&self.model, &self.data, self.tcp, &mut j6);
                (
                    DVector::from_vec(vec![p.translation.x, p.translation.y]),
                    j6.rows(0, 2).into_owned(),
                )
            }
            1 => (
                DVector::from_element(1, q.sum()),
                DMatrix::from_element(1, 4, 1.0),
            ),
            _ => (
                DVector::from_element(1, q[0]),
                DMatrix::from_row_slice(1, 4, &[1.0, 0.0, 0.0, 0.0]),
            ),
        }
    }

    /// M(q), C(q, q̇), g(q).
    fn dynamics(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> [DMatrix<f64>; 2] {
        hcc_model::compute_all_terms(&self.model, &mut self.data, q, qd);
        [self.data.m.clone(), self.data.c.clone()]
    }

    /// Z_i (eq. 11: Z_1 = (M⁻¹ J_1ᵀ Λ_1)ᵀ's role is played by J̄⁻¹; here
    /// Z_i = J_i M⁻¹ N_i for i ≥ 2 with the dense projector of eq. 8), J̄_i and
    /// Λ_i of level i at q; level 1: Z_1 = Λ_1 J_1 M⁻¹ (so that Z_1ᵀ = (J̄⁻¹)_1).
    fn decomposition(&mut self, i: usize, q: &DVector<f64>) -> [DMatrix<f64>; 3] {
        let qd0 = DVector::zeros(4);
        let [m, _] = self.dynamics(q, &qd0);
        let minv = m.clone().try_inverse().expect("M⁻¹");
        let (_, ji) = self.task(i, q);
        if i == 0 {
            let lambda = (&ji * &minv * ji.transpose()).try_inverse().expect("Λ_1");
            let z = &lambda * &ji * &minv;
            return [z, ji, lambda];
        }
        let rows: Vec<DMatrix<f64>> = (0..i).map(|j| self.task(j, q).1).collect();
        let k: usize = rows.iter().map(|r| r.nrows()).sum();
        let mut jaug = DMatrix::zeros(k, 4);
        let mut row = 0;
        for r in &rows {
            jaug.rows_mut(row, r.nrows()).copy_from(r);
            row += r.nrows();
        }
        let g = (&jaug * &minv * jaug.transpose())
            .try_inverse()
            .expect("G⁻¹");
        let n_i = DMatrix::identity(4, 4) - jaug.transpose() * g * &jaug * &minv;
        let z = &ji * &minv * n_i;
        let lambda = &z * &m * z.transpose();
        let jbar = lambda.clone().try_inverse().expect("Λ⁻¹") * &z * &m;
        [z, jbar, lambda]
    }

    /// v_{i,d}(q, t) of every level (T.1) from the waves' ẋ_{i,d}(t).
    fn desired_velocities(
        &mut self,
        q: &DVector<f64>,
        t: f64,
        waves: &[Wave],
    ) -> Vec<DVector<f64>> {
        let mut qd_d = DVector::zeros(4);
        let mut out = Vec::new();
        for (i, w) in waves.iter().enumerate() {
            let [z, _, _] = self.decomposition(i, q);
            let (_, ji) = self.task(i, q);
            let [_, xd, _] = w.at(t);
            let a = &ji * z.transpose();
            let vd = a.try_inverse().expect("A_i⁻¹") * (xd - &ji * &qd_d);
            qd_d += z.transpose() * &vd;
            out.push(vd);
        }
        out
    }
}

/// Per level the largest |Λ_i ṽ̇_i + μ_ii ṽ_i + Z_i J_iᵀ F_i| at (q, q̇, q̈, t).
fn residuals(
    p: &mut Planar,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    qdd: &DVector<f64>,
    t: f64,
    waves: &[Wave],
    gains: &[(DMatrix<f64>, DMatrix<f64>)],
) -> Vec<f64> {
    let h = 1e-6;
    let qp = q + qd * h;
    let qm = q - qd * h;
    let [_, c] = p.dynamics(q, qd);
    let [m, _] = p.dynamics(q, qd);
    let minv = m.try_inverse().expect("M⁻¹");
    let vd = p.desired_velocities(q, t, waves);
    let vd_p = p.desired_velocities(&qp, t + h, waves);
    let vd_m = p.desired_velocities(&qm, t - h, waves);
    let mut out = Vec::new();
    for (i, w) in waves.iter().enumerate() {
        let [z, jbar, lambda] = p.decomposition(i, q);
        let [_, jbar_p, _] = p.decomposition(i, &qp);
        let [_, jbar_m, _] = p.decomposition(i, &qm);
        let jbar_dot = (jbar_p - jbar_m) / (2.0 * h);
        let v = &jbar * qd;
        let v_dot = &jbar * qdd + &jbar_dot * qd;
        let vd_dot = (&vd_p[i] - &vd_m[i]) / (2.0 * h);
        let mu_ii = &lambda * (&jbar * &minv * &c - &jbar_dot) * z.transpose();
        let (x, ji) = p.task(i, q);
        let [x_d, xd_d, _] = w.at(t);
        let (k, d) = &gains[i];
        let f = k * (x - x_d) + d * (&ji * qd - xd_d);
        let zj = if i == 0 {
            DMatrix::identity(ji.nrows(), ji.nrows())
        } else {
            &z * ji.transpose()
        };
        let res = &lambda * (v_dot - vd_dot) + mu_ii * (v - &vd[i]) + zj * f;
        out.push(res.amax());
    }
    out
}

fn diag(v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_column_slice(v))
}

/// The planar hierarchy with the paper's Table II gains (sim 1), the law alone
/// (no safety layer: the check is of eqs. T.1–T.4).
fn planar_controller(q0: &DVector<f64>) -> Controller {
    let model = planar();
    let mut spec = planar_spec(&model, "sim1");
    spec.safety.enabled = false;
    Controller::new(&model, spec, q0).expect("controller")
}

#[test]
fn every_level_follows_the_error_dynamics_of_the_tracking_law() {
    let r = reference();
    let q0 = DVector::from_vec(vec_of(&r["initial_configuration"]["q0"]));
    let mut p = Planar::new();
    let bases: Vec<DVector<f64>> = (0..3).map(|i| p.task(i, &q0).0).collect();
    let waves = [
        Wave {
            base: bases[0].as_slice().to_vec(),
            amp: vec![0.05, 0.03],
            omega: vec![2.0 * PI * 0.5, 2.0 * PI * 1.0],
        },
        Wave {
            base: bases[1].as_slice().to_vec(),
            amp: vec![0.15],
            omega: vec![2.0 * PI * 0.3],
        },
        Wave {
            base: bases[2].as_slice().to_vec(),
            amp: vec![0.1],
            omega: vec![2.0 * PI * 0.4],
        },
    ];
    let gains = [
        (diag(&[1000.0, 1000.0]), diag(&[40.0, 40.0])),
        (diag(&[800.0]), diag(&[5.0])),
        (diag(&[2400.0]), diag(&[15.0])),
    ];
    let mut c = planar_controller(&q0);
    let (mut q, mut qd) = (q0.clone(), DVector::zeros(4));
    let dt = 1e-3;
    let mut worst = [0.0f64; 3];
    let mut scale = [0.0f64; 3];
    let mut last_err = [0.0f64; 3];
    let steps = 3000;
    for s in 0..steps {
        let t = s as f64 * dt;
        for (i, w) in waves.iter().enumerate() {
            let [x, xd, xdd] = w.at(t);
            c.set_goal(i, x.as_slice()).expect("goal");
            c.set_goal_velocity(i, xd.as_slice()).expect("velocity");
            c.set_goal_acceleration(i, Some(xdd.as_slice()))
                .expect("acceleration");
        }
        let tau = c
            .step(q.as_slice(), qd.as_slice())
            .expect("step")
            .tau
            .clone();
        let qdd = hcc_model_qdd(&mut p, &q, &qd, &tau);
        if s % 10 == 0 {
            let res = residuals(&mut p, &q, &qd, &qdd, t, &waves, &gains);
            for i in 0..3 {
                worst[i] = worst[i].max(res[i]);
                // The size of the terms the residual balances: Z_i J_iᵀ F_i.
                let [z, _, _] = p.decomposition(i, &q);
                let (x, ji) = p.task(i, &q);
                let f = &gains[i].0 * (x - waves[i].at(t)[0].clone());
                let zf = if i == 0 { f } else { &z * ji.transpose() * f };
                scale[i] = scale[i].max(zf.amax());
            }
        }
        // RK4 over the period with the command held.
        let f = |p: &mut Planar, q: &DVector<f64>, qd: &DVector<f64>| hcc_model_qdd(p, q, qd, &tau);
        let k1v = qd.clone();
        let k1a = f(&mut p, &q, &qd);
        let k2v = &qd + &k1a * (dt / 2.0);
        let k2a = f(&mut p, &(&q + &k1v * (dt / 2.0)), &k2v);
        let k3v = &qd + &k2a * (dt / 2.0);
        let k3a = f(&mut p, &(&q + &k2v * (dt / 2.0)), &k3v);
        let k4v = &qd + &k3a * dt;
        let k4a = f(&mut p, &(&q + &k3v * dt), &k4v);
        q += (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (dt / 6.0);
        qd += (k1a + k2a * 2.0 + k3a * 2.0 + k4a) * (dt / 6.0);
        if s == steps - 1 {
            let t_end = (s + 1) as f64 * dt;
            for (i, w) in waves.iter().enumerate() {
                last_err[i] = (p.task(i, &q).0 - w.at(t_end)[0].clone()).amax();
            }
        }
    }
    println!(
        "tracking error dynamics (T.4), largest residual per level: {:.2e} {:.2e} {:.2e} \
         (terms up to {:.2e} {:.2e} {:.2e}); tracking error after 3 s: {:.2e} m, {:.2e} rad, {:.2e} rad",
        worst[0],
        worst[1],
        worst[2],
        scale[0],
        scale[1],
        scale[2],
        last_err[0],
        last_err[1],
        last_err[2]
    );
    for (i, w) in worst.iter().enumerate() {
        assert!(*w < 1e-6, "level {} residual {w:.3e}", i + 1);
    }
    // Started at rest on the path's first point (the desired velocity is
    // not zero there): the errors have decayed by 3 s.
    assert!(last_err[0] < 1e-4 && last_err[1] < 1e-3 && last_err[2] < 1e-3);
}

/// q̈ = M⁻¹ (τ − C q̇ − g) from the model.
fn hcc_model_qdd(
    p: &mut Planar,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    tau: &DVector<f64>,
) -> DVector<f64> {
    hcc_model::compute_all_terms(&p.model, &mut p.data, q, qd);
    let rhs = tau - &p.data.c * qd - &p.data.g;
    p.data.m.clone().lu().solve(&rhs).expect("M solve")
}

#[test]
fn with_no_moving_goal_the_tracking_form_is_the_regulation_law_bit_for_bit() {
    let r = reference();
    let q0 = DVector::from_vec(vec_of(&r["initial_configuration"]["q0"]));
    let mut a = planar_controller(&q0);
    let mut b = planar_controller(&q0);
    for i in 0..3 {
        let m = b.task_dim(i);
        b.set_goal_acceleration(i, Some(&vec![0.0; m])).expect("on");
    }
    let qd = [0.3, -0.2, 0.1, 0.4];
    for _ in 0..3 {
        let ta = a.step(q0.as_slice(), &qd).expect("step").tau.clone();
        let out = b.step(q0.as_slice(), &qd).expect("step");
        assert_eq!(ta, out.tau);
        assert!(out.tau_feed_forward.iter().all(|&x| x == 0.0));
    }
    // A wrong length or a non-finite value is refused; `None` ends tracking.
    assert!(b.set_goal_acceleration(0, Some(&[0.0])).is_err());
    assert!(b.set_goal_acceleration(0, Some(&[f64::NAN, 0.0])).is_err());
    assert!(b.set_goal_acceleration(9, None).is_err());
    b.set_goal_acceleration(0, None).expect("off");
}
