//! `[setpoint_limits]`: defaults from the levels, explicit limits, and errors that
//! name the field.

use hcc_config::Scenario;
use hcc_spec::setpoint_limits::{DEFAULT_MAX_ANGULAR_SPEED, DEFAULT_MAX_LINEAR_SPEED};
use std::path::PathBuf;

fn load(extra: &str) -> Result<Scenario, hcc_config::ConfigError> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/paper-sim1.toml");
    let text = std::fs::read_to_string(&path).unwrap() + extra;
    Scenario::from_toml_str(&text, &path)
}

#[test]
fn defaults_follow_the_levels() {
    let s = load("").unwrap();
    let c = &s.setpoint_limits;
    assert!(c.relative_damping);
    assert_eq!(c.levels.len(), s.levels().len());
    // K_1 = diag(1000, 1000): 4 × its largest eigenvalue.
    assert!((c.levels[0].max_stiffness - 4000.0).abs() < 1e-9);
    assert_eq!(c.levels[0].max_speed, DEFAULT_MAX_LINEAR_SPEED);
    assert_eq!(c.levels[1].max_speed, DEFAULT_MAX_ANGULAR_SPEED);
    assert!(c.levels.iter().all(|l| l.workspace.is_none()));
}

#[test]
fn explicit_limits_are_taken() {
    let s = load(
        "\n[setpoint_limits]\nrelative_damping = false\n\n[[setpoint_limits.level]]\nmax_stiffness = 1500.0\nmax_speed = 0.1\nworkspace_min = [0.0, 0.0]\nworkspace_max = [1.5, 1.5]\n",
    )
    .unwrap();
    let c = &s.setpoint_limits;
    assert!(!c.relative_damping);
    assert_eq!(c.levels[0].max_stiffness, 1500.0);
    assert_eq!(c.levels[0].max_speed, 0.1);
    assert_eq!(
        c.levels[0].workspace,
        Some((vec![0.0, 0.0], vec![1.5, 1.5]))
    );
    // Levels without an entry keep their defaults.
    assert_eq!(c.levels[1].max_speed, DEFAULT_MAX_ANGULAR_SPEED);
}

#[test]
fn bad_limits_name_the_field() {
    for (extra, field) in [
        (
            "\n[[setpoint_limits.level]]\nmax_stiffness = -1.0\n",
            "setpoint_limits.level[0].max_stiffness",
        ),
        (
            "\n[[setpoint_limits.level]]\nmax_speed = 0.0\n",
            "setpoint_limits.level[0].max_speed",
        ),
        (
            "\n[[setpoint_limits.level]]\nworkspace_min = [0.0, 0.0]\n",
            "setpoint_limits.level[0].workspace_min",
        ),
        (
            "\n[[setpoint_limits.level]]\nworkspace_min = [1.0, 0.0]\nworkspace_max = [0.5, 1.0]\n",
            "setpoint_limits.level[0].workspace_min",
        ),
        (
            "\n[[setpoint_limits.level]]\n[[setpoint_limits.level]]\nworkspace_min = [0.0]\nworkspace_max = [1.0]\n",
            "setpoint_limits.level[1].workspace_min",
        ),
        (
            "\n[[setpoint_limits.level]]\n[[setpoint_limits.level]]\n[[setpoint_limits.level]]\n[[setpoint_limits.level]]\n",
            "setpoint_limits.level",
        ),
    ] {
        let e = load(extra).unwrap_err().to_string();
        assert!(e.contains(field), "{extra}: {e}");
    }
    assert!(load("\n[setpoint_limits]\nunknown = 1\n").is_err());
}

#[test]
fn the_torque_filter_is_off_by_default_and_checked() {
    use hcc_spec::torque_filter::RateLimitMode;
    let s = load("").unwrap();
    assert_eq!(s.torque_filter.torque_rate_limit, None);
    assert_eq!(s.torque_filter.low_pass_hz, None);
    let s = load(
        "\n[torque_filter]\ntorque_rate_limit = 1000.0\nrate_limit_mode = \"per_joint\"\nlow_pass_hz = 100.0\n",
    )
    .unwrap();
    assert_eq!(s.torque_filter.torque_rate_limit, Some(1000.0));
    assert_eq!(s.torque_filter.rate_limit_mode, RateLimitMode::PerJoint);
    assert_eq!(s.torque_filter.low_pass_hz, Some(100.0));
    for (extra, field) in [
        (
            "\n[torque_filter]\ntorque_rate_limit = -1.0\n",
            "torque_filter.torque_rate_limit",
        ),
        (
            "\n[torque_filter]\nlow_pass_hz = 0.0\n",
            "torque_filter.low_pass_hz",
        ),
    ] {
        let e = load(extra).unwrap_err().to_string();
        assert!(e.contains(field), "{e}");
    }
    assert!(load("\n[torque_filter]\nrate_limit_mode = \"sometimes\"\n").is_err());
}

#[test]
fn the_former_table_names_are_refused_with_the_new_ones() {
    for (old, new) in [
        (
            "\n[commanding]\nrelative_damping = false\n",
            "[setpoint_limits]",
        ),
        ("\n[output]\nlow_pass_hz = 80.0\n", "[torque_filter]"),
    ] {
        let e = load(old).unwrap_err().to_string();
        assert!(e.contains(new) && e.contains("rename"), "{old}: {e}");
    }
}

#[test]
fn the_path_window_defaults_to_256_knots_and_is_checked() {
    assert_eq!(load("").unwrap().setpoint_limits.path_knots, 256);
    let s = load("\n[setpoint_limits]\npath_knots = 1000\n").unwrap();
    assert_eq!(s.setpoint_limits.path_knots, 1000);
    for bad in ["2", "1000000"] {
        let e = load(&format!("\n[setpoint_limits]\npath_knots = {bad}\n"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("setpoint_limits.path_knots") && e.contains("from 3 to"),
            "{e}"
        );
    }
}

#[test]
fn the_path_check_timeout_defaults_to_100_ms_and_is_checked() {
    let limits = |text: &str| load(text).map(|s| s.setpoint_limits.path_check_timeout_ms);
    assert_eq!(limits("").unwrap(), 100.0);
    assert_eq!(
        limits("\n[setpoint_limits]\npath_check_timeout_ms = 250.0\n").unwrap(),
        250.0
    );
    for bad in ["0.0", "-5.0", "nan"] {
        let e = limits(&format!(
            "\n[setpoint_limits]\npath_check_timeout_ms = {bad}\n"
        ))
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("setpoint_limits.path_check_timeout_ms") && e.contains("positive"),
            "{e}"
        );
    }
}
