//! Physics checks of the decomposition and the control law on random non-singular
//! states of the planar arm and of the Panda (TCP position / orientation / posture):
//! block-diagonal Λ (eq. 16), the inverse of eq. (13), μ_ij = −μ_jiᵀ and Λ̇ = μ + μᵀ
//! (eq. 17), zero power of τ_μ (eq. 22), the strict hierarchy J_i M⁻¹ τ_j = 0 for j > i,
//! and eq. (21) = the classical projector form (eq. 8).

mod common;
use common::*;
use hcc_control::{Controller, ControllerSpec, Form};
use hcc_model::Model;
use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

const STATES: usize = 200;

fn random_state(model: &Model, rng: &mut StdRng) -> (Vec<f64>, Vec<f64>) {
    let q = model
        .joints
        .iter()
        .map(|j| {
            let (lo, hi) = if j.lower.is_finite() && j.upper.is_finite() {
                (j.lower, j.upper)
            } else {
                (-std::f64::consts::PI, std::f64::consts::PI)
            };
            rng.random_range(lo..hi)
        })
        .collect();
    let qd = (0..model.nq())
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    (q, qd)
}

fn block(m: &DMatrix<f64>, dims: &[usize], i: usize, j: usize) -> DMatrix<f64> {
    let oi: usize = dims[..i].iter().sum();
    let oj: usize = dims[..j].iter().sum();
    m.view((oi, oj), (dims[i], dims[j])).into_owned()
}

struct Worst {
    lambda_offdiag: f64,
    inverse: f64,
    mu_skew: f64,
    p_mu: f64,
    hierarchy: f64,
    classical: f64,
    lambda_dot: f64,
}

fn check_robot(model: &Model, mut spec: ControllerSpec, seed: u64) -> Worst {
    // The algebra of eqs. (3)–(22) on random states, each from a fresh
    // controller: the energy tanks (hcc_control::energy_tank) are off — a
    // random state's hierarchy power can exceed in one period what a new tank
    // holds, and they act on eq. (21) only, not on the classical form compared.
    spec.safety.energy_tanks = false;
    let mut rng = StdRng::seed_from_u64(seed);
    let n = model.nq();
    let mut w = Worst {
        lambda_offdiag: 0.0,
        inverse: 0.0,
        mu_skew: 0.0,
        p_mu: 0.0,
        hierarchy: 0.0,
        classical: 0.0,
        lambda_dot: 0.0,
    };
    let mut tested = 0;
    let mut attempts = 0;
    while tested < STATES {
        attempts += 1;
        assert!(attempts < 20 * STATES, "too few non-singular states");
        let (q, qd) = random_state(model, &mut rng);
        let q0 = DVector::from_vec(q.clone());
        let Ok(mut c) = Controller::new(model, spec.clone(), &q0) else {
            continue; // singular at this state: not a test state
        };
        let out = c.step(&q, &qd).expect("step").clone();
        if out.any_singular || out.conditioning.iter().any(|&r| r < 1e-4) {
            continue;
        }
        tested += 1;
        let d = c.diagnostics();
        let dims = &d.dims;
        let r = dims.len();
        // Λ = J̄⁻ᵀ M J̄⁻¹ block-diagonal (eq. 16).
        let lam = d.jbar_inv.transpose() * &d.m * &d.jbar_inv;
        let scale = lam.norm();
        for i in 0..r {
            for j in 0..r {
                if i != j {
                    let e = block(&lam, dims, i, j).norm() / scale;
                    w.lambda_offdiag = w.lambda_offdiag.max(e);
                    assert!(e <= 1e-9, "Λ block ({i},{j}) = {e:e} relative");
                }
            }
            let e = (block(&lam, dims, i, i) - block(&d.lambda, dims, i, i)).norm() / scale;
            assert!(e <= 1e-9, "Λ_{i} differs from eq. (18): {e:e}");
        }
        // J̄ J̄⁻¹ = I with J̄⁻¹ = (J_1^{M+}, Z_2ᵀ, …, Z_rᵀ) (eq. 13).
        let e = (&d.jbar * &d.jbar_inv - DMatrix::identity(n, n)).norm();
        w.inverse = w.inverse.max(e);
        assert!(e <= 1e-9, "J̄ J̄⁻¹ − I = {e:e}");
        // μ_ij = −μ_jiᵀ (i ≠ j).
        let mu_scale = d.mu.norm().max(1e-12);
        for i in 0..r {
            for j in 0..r {
                if i != j {
                    let e = (block(&d.mu, dims, i, j) + block(&d.mu, dims, j, i).transpose())
                        .norm()
                        / mu_scale;
                    w.mu_skew = w.mu_skew.max(e);
                    assert!(e <= 1e-9, "μ_{i}{j} + μ_{j}{i}ᵀ = {e:e} relative");
                }
            }
        }
        // P_μ = τ_μᵀ q̇ = 0.
        let qdv = DVector::from_vec(qd.clone());
        let e = out.p_mu.abs() / (out.tau_mu.norm() * qdv.norm()).max(1e-12);
        w.p_mu = w.p_mu.max(e);
        assert!(e <= 1e-9, "P_μ relative {e:e}");
        // Strict hierarchy: J_i M⁻¹ τ_j = 0 for j > i.
        for i in 0..r {
            for j in (i + 1)..r {
                let acc = &d.jacobians[i] * &d.minv * &out.tau_level[j];
                let scale = d.jacobians[i].norm() * d.minv.norm() * out.tau_level[j].norm();
                let e = acc.norm() / scale.max(1e-12);
                w.hierarchy = w.hierarchy.max(e);
                assert!(e <= 1e-9, "J_{i} M⁻¹ τ_{j} relative {e:e}");
            }
        }
        // Eq. (21) = classical projector form N_i J_iᵀ F_i (eq. 8).
        let mut spec_c = spec.clone();
        spec_c.form = Form::ClassicalProjector;
        let mut cc = Controller::new(model, spec_c, &q0).expect("classical");
        let oc = cc.step(&q, &qd).expect("step");
        for i in 0..r {
            let e =
                (&oc.tau_level[i] - &out.tau_level[i]).norm() / out.tau_level[i].norm().max(1e-9);
            w.classical = w.classical.max(e);
            assert!(e <= 1e-9, "level {i}: eq. (21) vs eq. (8) relative {e:e}");
        }
        // Λ̇ = μ + μᵀ, Λ̇ by a central difference in time along q(t) = q + t q̇ (the basis
        // carried along by the controller's own continuity).
        if tested <= 40 {
            let h = 1e-6;
            let qm: Vec<f64> = q.iter().zip(&qd).map(|(a, b)| a - h * b).collect();
            let qp: Vec<f64> = q.iter().zip(&qd).map(|(a, b)| a + h * b).collect();
            let mut ct = Controller::new(model, spec.clone(), &q0).expect("controller");
            ct.step(&qm, &qd).expect("step");
            let lm = ct.diagnostics().lambda;
            ct.step(&q, &qd).expect("step");
            let d0 = ct.diagnostics();
            ct.step(&qp, &qd).expect("step");
            let lp = ct.diagnostics().lambda;
            let lambda_dot = (lp - lm) / (2.0 * h);
            let sum = &d0.mu + d0.mu.transpose();
            let e = (&lambda_dot - &sum).norm() / sum.norm().max(1.0);
            w.lambda_dot = w.lambda_dot.max(e);
            assert!(e <= 1e-5, "Λ̇ − (μ + μᵀ) relative {e:e}");
        }
    }
    w
}

fn report(name: &str, w: &Worst) {
    println!(
        "{name}: Λ off-diagonal {:.1e}, J̄J̄⁻¹−I {:.1e}, μ skew {:.1e}, P_μ {:.1e}, hierarchy {:.1e}, eq21 vs eq8 {:.1e}, Λ̇ vs μ+μᵀ {:.1e}",
        w.lambda_offdiag, w.inverse, w.mu_skew, w.p_mu, w.hierarchy, w.classical, w.lambda_dot
    );
}

#[test]
fn planar_arm_properties() {
    let model = planar();
    let w = check_robot(&model, planar_spec(&model, "sim1"), 1);
    report("planar", &w);
}

#[test]
fn panda_properties() {
    let model = panda();
    let w = check_robot(&model, panda_spec(&model), 2);
    report("panda", &w);
}

/// The same checks with a stacked level: the 6-D TCP pose (one level) above the posture.
#[test]
fn panda_pose_posture_properties() {
    let model = panda();
    let w = check_robot(&model, panda_pose_spec(&model, false), 4);
    report("panda pose/posture", &w);
    let w = check_robot(&model, panda_stacked_spec(&model), 5);
    report("panda position+orientation stacked/posture", &w);
}

/// A pose level and the same level written as two stacked tasks (position, orientation)
/// are one law: identical torques.
#[test]
fn pose_task_equals_stacked_position_and_orientation() {
    let model = panda();
    let mut rng = StdRng::seed_from_u64(6);
    let (mut a, mut b) = (None, None);
    let mut tested = 0;
    while tested < 50 {
        let (q, qd) = random_state(&model, &mut rng);
        let q0 = DVector::from_vec(q.clone());
        let (Ok(ca), Ok(cb)) = (
            Controller::new(&model, panda_pose_spec(&model, false), &q0),
            Controller::new(&model, panda_stacked_spec(&model), &q0),
        ) else {
            continue;
        };
        tested += 1;
        let ca = a.insert(ca);
        let cb = b.insert(cb);
        let ta = ca.step(&q, &qd).expect("step").tau.clone();
        let tb = cb.step(&q, &qd).expect("step").tau.clone();
        assert!(close(ta.as_slice(), tb.as_slice(), 1e-12), "{ta} vs {tb}");
    }
}

/// The task force is the gradient of the task potential (the premise of eqs. 26–29):
/// with q̇ = 0, τ_1 = −J_1ᵀ ∂V_1/∂x_1ᵀ, so V_1(q + h u) − V_1(q − h u) ≈ −2h τ_1ᵀ u for
/// any direction u. Checked for the quaternion orientation potential and the position
/// potential of the Panda at random states, far from and near the goal.
#[test]
fn task_forces_are_gradients_of_the_potentials() {
    let model = panda();
    let full = panda_spec(&model);
    let mut rng = StdRng::seed_from_u64(3);
    let mut worst: f64 = 0.0;
    for level in [0, 1] {
        let mut spec = ControllerSpec::new(vec![full.levels[level].clone()]);
        spec.gravity_compensation = false;
        spec.coriolis_cancellation = false;
        let mut tested = 0;
        while tested < 50 {
            let (q, u) = random_state(&model, &mut rng);
            let Ok(mut c) = Controller::new(&model, spec.clone(), &DVector::from_vec(q.clone()))
            else {
                continue;
            };
            tested += 1;
            let zero = vec![0.0; q.len()];
            let tau = c.step(&q, &zero).expect("step").tau_level[0].clone();
            let h = 1e-6;
            let at = |c: &mut Controller, s: f64| {
                let qs: Vec<f64> = q.iter().zip(&u).map(|(a, b)| a + s * b).collect();
                c.step(&qs, &zero).expect("step").potential[0]
            };
            let dv = (at(&mut c, h) - at(&mut c, -h)) / (2.0 * h);
            let predicted = -tau.dot(&DVector::from_vec(u.clone()));
            let e = (dv - predicted).abs() / predicted.abs().max(1.0);
            worst = worst.max(e);
            assert!(
                e <= 1e-6,
                "level {level}: dV/dt {dv} vs −τᵀu {predicted} at q {q:?}"
            );
        }
    }
    println!("potential gradients: worst relative deviation {worst:.1e}");
}

/// The pose task (diagonal and coupled 6×6 stiffness): the force is the gradient of
/// the potential (V(q + h u) − V(q − h u) ≈ −2h τ_1ᵀ u at q̇ = 0), and J̇ is the time
/// derivative of J along q(t) = q + t q̇ (central differences).
#[test]
fn pose_task_gradient_and_jdot_by_finite_differences() {
    let model = panda();
    let mut rng = StdRng::seed_from_u64(7);
    let (mut worst_grad, mut worst_jdot): (f64, f64) = (0.0, 0.0);
    for coupled in [false, true] {
        let full = panda_pose_spec(&model, coupled);
        let mut spec = ControllerSpec::new(vec![full.levels[0].clone()]);
        spec.gravity_compensation = false;
        spec.coriolis_cancellation = false;
        let mut tested = 0;
        while tested < 50 {
            let (q, u) = random_state(&model, &mut rng);
            let Ok(mut c) = Controller::new(&model, spec.clone(), &DVector::from_vec(q.clone()))
            else {
                continue;
            };
            tested += 1;
            let zero = vec![0.0; q.len()];
            let tau = c.step(&q, &zero).expect("step").tau_level[0].clone();
            let h = 1e-6;
            let along = |s: f64| -> Vec<f64> { q.iter().zip(&u).map(|(a, b)| a + s * b).collect() };
            let dv = (c.step(&along(h), &zero).expect("step").potential[0]
                - c.step(&along(-h), &zero).expect("step").potential[0])
                / (2.0 * h);
            let predicted = -tau.dot(&DVector::from_vec(u.clone()));
            let e = (dv - predicted).abs() / predicted.abs().max(1.0);
            worst_grad = worst_grad.max(e);
            assert!(
                e <= 1e-6,
                "coupled {coupled}: dV/dt {dv} vs −τᵀu {predicted}"
            );
            // J̇ at (q, u) against (J(q + h u) − J(q − h u)) / 2h.
            c.step(&q, &u).expect("step");
            let jdot = c.diagnostics().jbar_dot;
            c.step(&along(h), &u).expect("step");
            let jp = c.task_jacobian(0).clone();
            c.step(&along(-h), &u).expect("step");
            let jm = c.task_jacobian(0).clone();
            let fd = (jp - jm) / (2.0 * h);
            let e = (&fd - &jdot).norm() / jdot.norm().max(1.0);
            worst_jdot = worst_jdot.max(e);
            assert!(e <= 1e-6, "coupled {coupled}: J̇ relative {e:e}");
        }
    }
    println!("pose task: gradient {worst_grad:.1e}, J̇ {worst_jdot:.1e} (worst relative)");
}
