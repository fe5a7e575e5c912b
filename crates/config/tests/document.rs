//! The scenario a controller publishes (`Scenario::document`) builds the same
//! scenario again from its texts alone (`Scenario::from_document`), and a
//! file that is not what the controller runs is told apart
//! (`Scenario::differs_from`).

use std::path::PathBuf;

use hcc_config::Scenario;

fn load(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    Scenario::load(&path).unwrap()
}

#[test]
fn the_document_builds_the_same_scenario_and_names_its_levels_and_joints() {
    let s = load("panda-pose-posture.toml");
    let doc = s.document("robot1");
    assert_eq!(doc.namespace, "robot1");
    assert_eq!(doc.rate_hz, 1000.0);
    let levels: Vec<(&str, usize)> = doc
        .levels
        .iter()
        .map(|l| (l.name.as_str(), l.dim))
        .collect();
    assert_eq!(
        levels,
        [("TCP position", 3), ("TCP orientation", 3), ("posture", 7)]
    );
    assert_eq!(doc.levels[0].tasks, ["position"]);
    // The resolved values: goal, K and D (row-major), the law's options.
    let l = &s.spec.levels[0];
    assert_eq!(doc.levels[0].goal, l.goal.as_slice());
    assert_eq!(doc.levels[0].stiffness.len(), 9);
    assert_eq!(doc.levels[0].stiffness[4], l.stiffness[(1, 1)]);
    assert_eq!(doc.levels[2].damping.len(), 49);
    assert_eq!(doc.form, "extended");
    assert!(doc.coriolis_cancellation);
    assert_eq!(doc.joints.len(), 7);
    assert_eq!(doc.joints[0].name, "panda_joint1");
    assert!(doc.joints[3].upper.unwrap() < 0.0, "joint 4's upper limit");
    assert!(!doc.urdf.is_empty());

    let again = Scenario::from_document(&doc).unwrap();
    assert_eq!(again.spec, s.spec);
    assert_eq!(again.q0, s.q0);
    assert_eq!(again.rate_hz, s.rate_hz);
    assert_eq!(again.model.nq(), s.model.nq());
    assert_eq!(again.text(), s.text());
    assert!(again.differs_from(&doc).is_none());
}

#[test]
fn a_file_that_is_not_what_the_controller_runs_is_told_apart() {
    let panda = load("panda-pose-posture.toml");
    let sim1 = load("paper-sim1.toml");
    let d = sim1
        .differs_from(&panda.document("robot1"))
        .expect("different scenarios");
    assert!(d.contains("levels") && d.contains("joints"), "{d}");
    assert!(d.contains("robot1"), "{d}");
}
