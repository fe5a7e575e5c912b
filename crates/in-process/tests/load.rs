//! A load announced in the scenario (`[robot.load]`): the plant carries it
//! and the controller's model knows it, so the hierarchy holds its pose as
//! without one — the gravity torque includes the load's, nothing sags.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_in_process::run_observed;

fn pose_posture(load: &str) -> Scenario {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    let text = std::fs::read_to_string(&path).unwrap() + load;
    let mut s = Scenario::from_toml_str(&text, &path).unwrap();
    s.set_duration(3.0).unwrap();
    s
}

/// The largest TCP position error over the last second, m.
fn settled_error(scenario: &Scenario) -> f64 {
    let mut worst: f64 = 0.0;
    run_observed(scenario, &mut |view| {
        if view.t >= 2.0 {
            let e = view.cycle.telemetry().task_error(0);
            worst = worst.max((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt());
        }
        Ok(())
    })
    .unwrap();
    worst
}

#[test]
fn an_announced_load_is_held_as_the_arm_without_one() {
    let bare = settled_error(&pose_posture(""));
    let loaded = settled_error(&pose_posture(
        "\n[robot.load]\nmass = 1.0\ncom = [0.0, 0.0, 0.1]\n",
    ));
    println!(
        "TCP error over the last second: {bare:.2e} m without a load, {loaded:.2e} m with 1 kg announced"
    );
    assert!(loaded < 1e-3, "{loaded:e} m");
}
