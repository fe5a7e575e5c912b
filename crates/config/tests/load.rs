//! `[robot.load]` and `[robot] payload_kg`: the load the tip carries from the
//! start, lumped into the model every part of a run uses (the controller's
//! and the plant's), and refused, naming its field and line, when it is not a
//! physical load or heavier than the robot may carry.

use hcc_config::Scenario;
use std::path::PathBuf;

/// The Panda's pose-and-posture scenario with `robot` added to `[robot]` and
/// `extra` at the end.
fn load(robot: &str, extra: &str) -> Result<Scenario, hcc_config::ConfigError> {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    let text = std::fs::read_to_string(&path).unwrap().replacen(
        "[robot]\n",
        &format!("[robot]\n{robot}"),
        1,
    ) + extra;
    Scenario::from_toml_str(&text, &path)
}

#[test]
fn a_load_in_the_scenario_is_carried_by_the_model() {
    let bare = load("", "").unwrap();
    assert_eq!(bare.model.load.mass, 0.0);
    assert_eq!(bare.model.payload_limit, 3.0, "the Panda's rated payload");
    let loaded = load(
        "",
        "\n[robot.load]\nmass = 1.0\ncom = [0.0, 0.0, 0.1]\ninertia = [0.001, 0.0, 0.0, 0.001, 0.0, 0.001]\n",
    )
    .unwrap();
    let m = &loaded.model;
    assert_eq!(m.load.mass, 1.0);
    assert_eq!(m.load.com, nalgebra::Vector3::new(0.0, 0.0, 0.1));
    assert_eq!(m.payload_limit, 3.0);
    let tip = |s: &Scenario| s.model.joints.last().unwrap().inertia.mass;
    assert!((tip(&loaded) - tip(&bare) - 1.0).abs() < 1e-12);
}

#[test]
fn a_load_that_is_not_physical_or_too_heavy_is_refused_at_its_field() {
    let refused = |robot: &str, section: &str| {
        load(robot, &format!("\n[robot.load]\n{section}"))
            .unwrap_err()
            .to_string()
    };
    let e = refused("", "mass = 4.0\n");
    assert!(
        e.contains("robot.load.mass") && e.contains("payload"),
        "{e}"
    );
    let e = refused("", "mass = -1.0\n");
    assert!(
        e.contains("robot.load.mass") && e.contains("negative"),
        "{e}"
    );
    let e = refused("", "mass = 1.0\ninertia = [0.1, 0.0, 0.0, 0.1, 0.0, 0.3]\n");
    assert!(
        e.contains("robot.load.inertia") && e.contains("triangle"),
        "{e}"
    );
    let e = refused("", "mass = 1.0\ncom = [0.0, 0.1]\n");
    assert!(e.contains("robot.load.com") && e.contains("3"), "{e}");
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    let text = std::fs::read_to_string(&path).unwrap().replacen(
        "payload_kg = 3.0",
        "payload_kg = -2.0",
        1,
    );
    let e = Scenario::from_toml_str(&text, &path)
        .map(|_| ())
        .unwrap_err()
        .to_string();
    assert!(e.contains("robot.payload_kg") && e.contains("≥ 0"), "{e}");
    let e = refused("", "mass = 1.0\ncolour = 3\n");
    assert!(e.contains("colour"), "{e}");
}

#[test]
fn loads_the_plant_takes_at_a_time_are_checked_and_sorted() {
    let s = load(
        "",
        "\n[[simulation.load]]\nstart_s = 2.0\nmass = 0.0\n\n[[simulation.load]]\nstart_s = 1.0\nmass = 1.0\ncom = [0.0, 0.0, 0.1]\n",
    )
    .unwrap();
    let loads = &s.simulation.loads;
    assert_eq!(loads.len(), 2);
    assert_eq!((loads[0].start_s, loads[0].load.mass), (1.0, 1.0));
    assert_eq!((loads[1].start_s, loads[1].load.mass), (2.0, 0.0));
    // The controller's model is not told.
    assert_eq!(s.model.load.mass, 0.0);
    let refused = |section: &str| {
        load("", &format!("\n[[simulation.load]]\n{section}"))
            .unwrap_err()
            .to_string()
    };
    let e = refused("start_s = -1.0\nmass = 1.0\n");
    assert!(e.contains("simulation.load[0].start_s"), "{e}");
    let e = refused("start_s = 1.0\nmass = 4.0\n");
    assert!(
        e.contains("simulation.load[0].mass") && e.contains("payload"),
        "{e}"
    );
    let e = refused("start_s = 1.0\nmass = 1.0\ninertia = [0.1, 0.0, 0.0, 0.1, 0.0, -0.3]\n");
    assert!(e.contains("simulation.load[0].inertia"), "{e}");
}
