//! Gains the control rate cannot carry (hcc_control::rate): a bare FR3 with a
//! posture damping of 2 N·m·s/rad (joint 7's inertia ≈ 1e-4 kg·m², D·T/I ≈ 20
//! at 1 kHz) is refused at load with a message that names the level, the
//! damping and the largest value the rate carries; with that value the same
//! scenario converges, every joint below its velocity limit.

use std::path::{Path, PathBuf};

use hcc_config::Scenario;
use hcc_in_process::run_observed;

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data")
        .join(name)
}

/// The scenario text with the posture damping `d` and the URDF by its
/// absolute path, written to its own temporary directory.
fn with_posture_damping(d: f64, dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(data("fr3-position-posture.toml")).unwrap();
    let urdf = data("../../config/robots/fr3/fr3.urdf")
        .canonicalize()
        .unwrap();
    let text = text
        .replace(
            "urdf = \"../../config/robots/fr3/fr3.urdf\"",
            &format!("urdf = {:?}", urdf.to_string_lossy()),
        )
        .replace(
            "damping = 2.0  # Nms/rad",
            &format!("damping = {d:?}  # Nms/rad"),
        );
    let path = dir.join("fr3-position-posture.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_damping_the_rate_cannot_carry_is_refused_and_the_one_it_names_converges() {
    // The file's shape is right; the law refuses the gain at q0.
    let refused = Scenario::load(data("fr3-position-posture.toml")).expect("the file loads");
    let Err(err) = hcc_cycle::controller_for(&refused) else {
        panic!("a posture damping of 2 on a bare FR3 is refused");
    };
    let err = err.to_string();
    println!("{err}");
    assert!(err.contains("level 2 (posture)"), "{err}");
    assert!(err.contains("damping"), "{err}");
    // "… (its largest entry 2.0000 to at most X)": the largest carried.
    let carried: f64 = err
        .rsplit("to at most ")
        .next()
        .and_then(|s| s.trim_end_matches(')').split(')').next())
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or_else(|| panic!("no carried value in: {err}"));
    assert!(carried > 0.0 && carried < 0.2, "{carried}");

    let dir = std::env::temp_dir().join(format!("hcc-gain-rate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = with_posture_damping(carried, &dir);
    let scenario = Scenario::load(&path);
    std::fs::remove_dir_all(&dir).ok();
    let scenario = scenario.expect("the file loads");
    assert!(
        hcc_cycle::controller_for(&scenario).is_ok(),
        "the damping the refusal names is carried"
    );
    let limits: Vec<f64> = scenario
        .model
        .joints
        .iter()
        .map(|j| j.velocity_limit)
        .collect();
    let (mut speed, mut error, mut finite) = (0.0_f64, f64::NAN, true);
    run_observed(&scenario, &mut |v| {
        let out = v.cycle.controller().output();
        finite &= out.tau.iter().all(|x| x.is_finite());
        for (qd, l) in v.state.qd().iter().zip(&limits) {
            speed = speed.max(qd.abs() / l);
        }
        error = out.task_error[0].norm();
        Ok(())
    })
    .expect("closed loop");
    println!(
        "posture damping {carried}: TCP error after 3 s {error:.2e} m, largest |q̇|/limit {speed:.3}"
    );
    assert!(finite);
    assert!(error < 1e-4, "TCP error {error} m");
    assert!(speed < 0.95, "a joint at {speed} × its velocity limit");
}
