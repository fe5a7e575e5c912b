//! Away from every limit and singularity the safety layer leaves the paper's
//! law alone: with the default `[safety]` every torque command is bit for bit
//! the one of `[safety] enabled = false` — on the paper's simulations, on a
//! Panda whose posture is pulled far in the null space of a held pose
//! (`config/panda-posture-far-from-limits.toml`), and while a goal moves.

use std::path::PathBuf;

use hcc_config::Scenario;

fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

/// The scenario `name` with `extra` TOML appended, with the default
/// `[safety]` and with the layer off.
fn pair(name: &str, extra: &str) -> (Scenario, Scenario) {
    let path = config(name);
    let text = std::fs::read_to_string(&path).unwrap() + extra;
    let on = Scenario::from_toml_str(&text, &path).unwrap();
    let mut off = on.clone();
    off.spec.safety.enabled = false;
    assert!(on.spec.safety.enabled, "the layer is on by default");
    (on, off)
}

/// Every command's torque, as bits, and the largest joint speed / limit.
fn torques(scenario: &Scenario) -> (Vec<Vec<u64>>, f64) {
    let limits: Vec<f64> = scenario
        .model
        .joints
        .iter()
        .map(|j| j.velocity_limit)
        .collect();
    let (mut out, mut speed) = (Vec::new(), 0.0_f64);
    hcc_in_process::simulate_observed(scenario, &mut |v| {
        out.push(
            v.cycle
                .command()
                .tau()
                .iter()
                .map(|t| t.to_bits())
                .collect(),
        );
        for (qd, l) in v.state.qd().iter().zip(&limits) {
            speed = speed.max(qd.abs() / l);
        }
        Ok(())
    })
    .unwrap();
    (out, speed)
}

fn assert_untouched(name: &str, extra: &str) -> f64 {
    let (on, off) = pair(name, extra);
    let ((a, speed), (b, _)) = (torques(&on), torques(&off));
    assert_eq!(a.len(), b.len());
    if let Some(k) = (0..a.len()).find(|&k| a[k] != b[k]) {
        panic!("{name}: the safety layer changed the torque of cycle {k}");
    }
    println!(
        "{name}{}: {} cycles bit-identical; largest |q̇|/limit {speed:.2}",
        if extra.is_empty() {
            ""
        } else {
            " (with a setpoint)"
        },
        a.len()
    );
    speed
}

#[test]
fn the_paper_simulations_are_untouched() {
    assert_untouched("paper-sim1.toml", "");
    assert_untouched("paper-sim2.toml", "");
}

#[test]
fn a_panda_far_from_its_limits_is_untouched() {
    let speed = assert_untouched("panda-posture-far-from-limits.toml", "");
    assert!(
        speed < 0.6,
        "the scenario must stay below the velocity band: {speed}"
    );
}

#[test]
fn a_moving_goal_far_from_the_limits_is_untouched() {
    // The TCP moves 5 cm along y over a second from t = 0.5 s.
    let extra = "\n[[setpoint]]\nt = 0.5\nlevel = 1\ngoal = [0.48404681539304417, 0.05, 0.41262977546230273, -3.140127636212154, -0.09998930383585482, -0.014675140733355529]\nduration = 1.0\n";
    let speed = assert_untouched("panda-posture-far-from-limits.toml", extra);
    assert!(speed < 0.6, "{speed}");
}
