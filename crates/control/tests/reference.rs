//! τ, τ per level, τ_μ, g and the block-diagonal Λ (eq. 16) against an independent
//! implementation of the paper's planar arm (tests/data/paper_planar4.json), to 1e-9.

mod common;
use common::*;
use hcc_control::Controller;
use nalgebra::DVector;

#[test]
fn planar_torques_match_reference() {
    let model = planar();
    let r = reference();
    let states = r["states"].as_object().expect("states");
    let mut worst: f64 = 0.0;
    for sim in ["sim1", "sim2"] {
        for (name, s) in states {
            let q = vec_of(&s["q"]);
            let qd = vec_of(&s["qd"]);
            let spec = planar_spec(&model, sim);
            let mut c =
                Controller::new(&model, spec, &DVector::from_vec(q.clone())).expect("controller");
            let out = c.step(&q, &qd).expect("step").clone();
            // Λ = diag(Λ_1, Λ_2, Λ_3) (eqs. 16, 18).
            let lambda = c.diagnostics().lambda;
            let want: Vec<f64> = s["Lambda"]
                .as_array()
                .expect("Lambda rows")
                .iter()
                .flat_map(vec_of)
                .collect();
            let got: Vec<f64> = (0..4)
                .flat_map(|i| (0..4).map(move |j| (i, j)))
                .map(|(i, j)| lambda[(i, j)])
                .collect();
            assert!(
                close(&got, &want, 1e-9),
                "{sim} {name} Λ: got {got:?}, want {want:?}"
            );
            let expect = &s[sim];
            let pairs: Vec<(&str, &[f64])> = vec![
                ("tau", out.tau.as_slice()),
                ("tau_level1", out.tau_level[0].as_slice()),
                ("tau_level2", out.tau_level[1].as_slice()),
                ("tau_level3", out.tau_level[2].as_slice()),
                ("tau_mu", out.tau_mu.as_slice()),
                ("g", out.gravity.as_slice()),
            ];
            for (key, got) in pairs {
                let want = vec_of(&expect[key]);
                let d: f64 = got
                    .iter()
                    .zip(&want)
                    .map(|(x, y)| (x - y).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let nb: f64 = want.iter().map(|y| y * y).sum::<f64>().sqrt();
                worst = worst.max(d / nb.max(1.0));
                assert!(
                    close(got, &want, 1e-9),
                    "{sim} {name} {key}: got {got:?}, want {want:?}"
                );
            }
        }
    }
    println!("worst relative deviation from the reference: {worst:.2e}");
}
