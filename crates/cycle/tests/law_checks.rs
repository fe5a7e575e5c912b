//! What the law refuses at the initial configuration (`hcc_cycle::controller_for`):
//! the scenario loads (its shape and units are right), and building its
//! controller names the file, the field and its line, as the scenario
//! reader's own errors do.

use std::path::PathBuf;

use hcc_config::Scenario;

fn sim1() -> (PathBuf, String) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/paper-sim1.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    (path, text)
}

/// The 1-based line of the first line of `text` that starts with `start`.
fn line_of(text: &str, start: &str) -> usize {
    text.lines().position(|l| l.starts_with(start)).unwrap() + 1
}

#[test]
fn the_shipped_scenario_builds_its_controller() {
    let (path, text) = sim1();
    let s = Scenario::from_toml_str(&text, &path).unwrap();
    assert!(hcc_cycle::controller_for(&s).is_ok());
}

#[test]
fn a_level_singular_at_q0_is_refused_naming_the_level_and_its_line() {
    let (path, text) = sim1();
    // The arm stretched out: the TCP's x-y Jacobian loses a rank.
    let q0 = text
        .lines()
        .find(|l| l.starts_with("q0 = "))
        .unwrap()
        .to_string();
    let bad = text.replace(&q0, "q0 = [0.0, 0.0, 0.0, 0.0]");
    let s = Scenario::from_toml_str(&bad, &path).expect("the shape is right");
    let e = hcc_cycle::controller_for(&s).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("paper-sim1.toml"), "{msg}");
    assert!(msg.contains("level[0]"), "{msg}");
    assert!(
        msg.contains("singular at the initial configuration"),
        "{msg}"
    );
    assert_eq!(e.line(), Some(line_of(&bad, "[[level]]")), "{msg}");
}

#[test]
fn damping_the_control_rate_cannot_carry_is_refused_naming_the_level() {
    let (path, text) = sim1();
    let bad = text.replace("damping = 15.0", "damping = 1.0e5");
    let s = Scenario::from_toml_str(&bad, &path).expect("the shape is right");
    let e = hcc_cycle::controller_for(&s).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("level[2]"), "{msg}");
    assert!(msg.contains("rejected by the controller"), "{msg}");
    // The third [[level]] table.
    let third = bad
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with("[[level]]"))
        .nth(2)
        .unwrap()
        .0
        + 1;
    assert_eq!(e.line(), Some(third), "{msg}");
}
