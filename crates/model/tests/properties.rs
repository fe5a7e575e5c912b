//! Physics properties of the algorithms on random states of the Panda and of
//! the planar 4-DOF arm (seeded RNG, 200 states per robot and property):
//! M symmetric positive definite, Ṁ = C + Cᵀ (so Ṁ − 2C is skew-symmetric),
//! C equal to the Christoffel-symbol matrix of M, g = ∂V/∂q, Jacobians and
//! their time derivatives equal to finite differences, forward dynamics
//! inverting RNEA. Derivatives are central finite differences; the tolerances
//! are relative (‖a − b‖ ≤ tol · max(1, ‖b‖)) and sized for their O(h²) error.

mod common;

use common::*;
use hcc_model::*;
use nalgebra::{DMatrix, DVector, Isometry3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

const STATES: usize = 200;
const H: f64 = 1e-5;

fn robots() -> Vec<(&'static str, Model)> {
    vec![("panda", panda()), ("planar4", planar())]
}

/// Random q within the joint limits (±π where unlimited), q̇ in ±2 rad/s.
fn random_state(model: &Model, rng: &mut StdRng) -> (DVector<f64>, DVector<f64>) {
    let n = model.nq();
    let q = DVector::from_iterator(
        n,
        model.joints.iter().map(|j| {
            let lo = j.lower.max(-std::f64::consts::PI);
            let hi = j.upper.min(std::f64::consts::PI);
            rng.random_range(lo..hi)
        }),
    );
    let qd = DVector::from_iterator(n, (0..n).map(|_| rng.random_range(-2.0..2.0)));
    (q, qd)
}

fn mass_matrix(model: &Model, data: &mut Data, q: &DVector<f64>) -> DMatrix<f64> {
    crba(model, data, q);
    data.m.clone()
}

fn placement(model: &Model, data: &mut Data, q: &DVector<f64>, frame: FrameId) -> Isometry3<f64> {
    forward_kinematics(model, data, q);
    frame_placement(model, data, frame)
}

fn jacobian(model: &Model, data: &mut Data, q: &DVector<f64>, frame: FrameId) -> DMatrix<f64> {
    let mut j = DMatrix::zeros(6, model.nq());
    forward_kinematics(model, data, q);
    frame_jacobian(model, data, frame, &mut j);
    j
}

#[test]
fn mass_matrix_symmetric_positive_definite() {
    let mut rng = StdRng::seed_from_u64(1);
    for (name, model) in robots() {
        let mut data = Data::new(&model);
        for _ in 0..STATES {
            let (q, _) = random_state(&model, &mut rng);
            let m = mass_matrix(&model, &mut data, &q);
            assert!(
                (&m - m.transpose()).norm() <= 1e-14 * m.norm(),
                "{name}: M not symmetric"
            );
            let eig = m.clone().symmetric_eigenvalues();
            assert!(eig.min() > 0.0, "{name}: M not positive definite: {eig}");
            let mut l = m.clone();
            linalg::cholesky_in_place(&mut l).unwrap();
        }
    }
}

#[test]
fn mdot_equals_c_plus_ct_and_christoffel() {
    let mut rng = StdRng::seed_from_u64(2);
    let mut worst_skew = 0.0_f64;
    let mut worst_christoffel = 0.0_f64;
    for (name, model) in robots() {
        let n = model.nq();
        let mut data = Data::new(&model);
        for _ in 0..STATES {
            let (q, qd) = random_state(&model, &mut rng);
            // Ṁ along q̇ by central difference.
            let mdot = (mass_matrix(&model, &mut data, &(&q + H * &qd))
                - mass_matrix(&model, &mut data, &(&q - H * &qd)))
                / (2.0 * H);
            // ∂M/∂q_i.
            let dm: Vec<DMatrix<f64>> = (0..n)
                .map(|i| {
                    let mut e = DVector::zeros(n);
                    e[i] = H;
                    (mass_matrix(&model, &mut data, &(&q + &e))
                        - mass_matrix(&model, &mut data, &(&q - &e)))
                        / (2.0 * H)
                })
                .collect();
            coriolis_matrix(&model, &mut data, &q, &qd);
            let c = data.c.clone();
            let skew = &mdot - 2.0 * &c;
            let e1 = (&skew + skew.transpose()).norm() / mdot.norm().max(1.0);
            assert!(e1 < 1e-8, "{name}: Mdot - 2C not skew-symmetric ({e1:e})");
            worst_skew = worst_skew.max(e1);
            // Christoffel symbols of the first kind: C_kj = Σ_i Γ_kji q̇_i,
            // Γ_kji = ½ (∂M_kj/∂q_i + ∂M_ki/∂q_j − ∂M_ji/∂q_k).
            let christoffel = DMatrix::from_fn(n, n, |k, j| {
                (0..n)
                    .map(|i| 0.5 * (dm[i][(k, j)] + dm[j][(k, i)] - dm[k][(j, i)]) * qd[i])
                    .sum::<f64>()
            });
            let e2 = rel(&c, &christoffel);
            assert!(
                e2 < 1e-8,
                "{name}: C is not the Christoffel matrix ({e2:e})"
            );
            worst_christoffel = worst_christoffel.max(e2);
        }
    }
    println!(
        "worst |Mdot-2C + (Mdot-2C)^T| rel {worst_skew:e}, C vs Christoffel rel {worst_christoffel:e}"
    );
}

#[test]
fn gravity_is_gradient_of_potential_energy() {
    let mut rng = StdRng::seed_from_u64(3);
    for (name, model) in robots() {
        let n = model.nq();
        let mut data = Data::new(&model);
        let zero = DVector::zeros(n);
        let mut potential = |q: &DVector<f64>| {
            crba(&model, &mut data, q);
            model.energy(&data, &zero)
        };
        for _ in 0..STATES {
            let (q, _) = random_state(&model, &mut rng);
            let grad = DVector::from_fn(n, |i, _| {
                let mut e = DVector::zeros(n);
                e[i] = H;
                (potential(&(&q + &e)) - potential(&(&q - &e))) / (2.0 * H)
            });
            let mut data = Data::new(&model);
            gravity(&model, &mut data, &q);
            let err = relv(&data.g, &grad);
            assert!(err < 1e-8, "{name}: g differs from dV/dq ({err:e})");
        }
    }
}

#[test]
fn jacobians_match_finite_differences() {
    let mut rng = StdRng::seed_from_u64(4);
    let mut worst = [0.0_f64; 3];
    for (name, model) in robots() {
        let n = model.nq();
        let mut data = Data::new(&model);
        for s in 0..STATES {
            let (q, qd) = random_state(&model, &mut rng);
            // Alternate between the tip and another frame of the model.
            let frame = if s % 2 == 0 {
                model.tip_frame()
            } else {
                s % model.frames.len()
            };
            let j = jacobian(&model, &mut data, &q, frame);
            let fd = DMatrix::from_fn(6, n, |r, c| {
                let mut e = DVector::zeros(n);
                e[c] = H;
                let plus = placement(&model, &mut data, &(&q + &e), frame);
                let minus = placement(&model, &mut data, &(&q - &e), frame);
                if r < 3 {
                    (plus.translation.vector[r] - minus.translation.vector[r]) / (2.0 * H)
                } else {
                    // World-axes rotation vector of R₊ R₋ᵀ.
                    (plus.rotation * minus.rotation.inverse()).scaled_axis()[r - 3] / (2.0 * H)
                }
            });
            let e = rel(&j, &fd);
            assert!(e < 1e-8, "{name}: J differs from d(FK)/dq ({e:e})");
            worst[0] = worst[0].max(e);

            // J̇ by central difference of J along q̇.
            let jdot_fd = (jacobian(&model, &mut data, &(&q + H * &qd), frame)
                - jacobian(&model, &mut data, &(&q - H * &qd), frame))
                / (2.0 * H);
            forward_kinematics_vel(&model, &mut data, &q, &qd);
            let mut jdot = DMatrix::zeros(6, n);
            frame_jacobian_time_variation(&model, &data, frame, &mut jdot);
            let e = rel(&jdot, &jdot_fd);
            assert!(e < 1e-8, "{name}: Jdot differs from dJ/dt ({e:e})");
            worst[1] = worst[1].max(e);

            // J̇ q̇ from the matrix equals the classical acceleration.
            let a = frame_classical_acceleration(&model, &data, frame);
            let a = DVector::from_column_slice(a.as_slice());
            let e = relv(&(&jdot * &qd), &a);
            assert!(
                e < 1e-12,
                "{name}: Jdot qd differs from classical acceleration ({e:e})"
            );
            worst[2] = worst[2].max(e);
        }
    }
    println!(
        "worst rel: J {:e}, Jdot {:e}, Jdot*qd {:e}",
        worst[0], worst[1], worst[2]
    );
}

#[test]
fn forward_dynamics_inverts_rnea() {
    let mut rng = StdRng::seed_from_u64(5);
    let mut worst = 0.0_f64;
    for (name, model) in robots() {
        let n = model.nq();
        let mut data = Data::new(&model);
        for _ in 0..STATES {
            let (q, qd) = random_state(&model, &mut rng);
            let tau = DVector::from_fn(n, |_, _| rng.random_range(-50.0..50.0));
            forward_dynamics(&model, &mut data, &q, &qd, &tau).unwrap();
            let qdd = data.qdd.clone();
            rnea(&model, &mut data, &q, &qd, &qdd);
            let e = relv(&data.tau, &tau);
            assert!(e < 1e-9, "{name}: rnea(fd(tau)) != tau ({e:e})");
            worst = worst.max(e);
            // RNEA = M q̈ + C q̇ + g with the separately computed terms.
            let tau_rnea = data.tau.clone();
            compute_all_terms(&model, &mut data, &q, &qd);
            let sum = &data.m * &qdd + &data.c * &qd + &data.g;
            let e = relv(&sum, &tau_rnea);
            assert!(e < 1e-9, "{name}: M qdd + C qd + g != rnea ({e:e})");
            let mut d2 = Data::new(&model);
            nle(&model, &mut d2, &q, &qd);
            assert!(relv(&d2.nle, &data.nle) < 1e-12, "{name}: nle differs");
        }
    }
    println!("worst rel |rnea(fd(tau)) - tau|: {worst:e}");
}
