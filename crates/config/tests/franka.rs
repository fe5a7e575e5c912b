//! `[franka]`: libfranka's defaults when absent, the values given, and
//! malformed tables refused with the field and the line named.

use hcc_config::franka::{
    DEFAULT_FORCE_THRESHOLDS, DEFAULT_TORQUE_THRESHOLDS, FRANKA_MAX_TORQUE_RATE,
    FRANKA_TORQUE_LIMITS, Franka,
};
use hcc_config::{ConfigError, Scenario};
use std::path::PathBuf;

/// A valid scenario (the paper's simulation #1); `[franka]` is appended by
/// the cases.
const BASE: &str = include_str!("../../../config/paper-sim1.toml");

fn load(franka: &str) -> Result<Scenario, ConfigError> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/test-scenario.toml");
    Scenario::from_toml_str(&format!("{BASE}\n[franka]\n{franka}"), &path)
}

/// The line of `[franka]`'s first field (after the blank line and the header).
fn first_line() -> usize {
    BASE.lines().count() + 3
}

#[test]
fn absent_fields_take_libfranka_s_defaults() {
    let without = Scenario::from_toml_str(
        BASE,
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/test-scenario.toml"),
    )
    .unwrap();
    assert_eq!(without.franka, Franka::default());
    let f = load("").unwrap().franka;
    assert_eq!(f, Franka::default());
    assert_eq!(
        f.collision.upper_torque_thresholds_nominal,
        DEFAULT_TORQUE_THRESHOLDS
    );
    assert_eq!(
        f.collision.lower_force_thresholds_acceleration,
        DEFAULT_FORCE_THRESHOLDS
    );
    assert_eq!(f.torque_limits, FRANKA_TORQUE_LIMITS);
    assert_eq!(f.torque_rate_limit, FRANKA_MAX_TORQUE_RATE);
}

#[test]
fn given_fields_are_taken() {
    let f = load(
        "upper_torque_thresholds_nominal = [30.0, 30.0, 28.0, 28.0, 26.0, 24.0, 22.0]\n\
         lower_force_thresholds_nominal = [5.0, 5.0, 5.0, 5.0, 5.0, 5.0]\n\
         torque_limits = [80.0, 80.0, 80.0, 80.0, 10.0, 10.0, 10.0]\n\
         torque_rate_limit = 500.0\n\
         command_window_us = 600.0\n\
         hold_cycles = 0\n\
         fallback_damping = [1.0, 1.0, 1.0, 1.0, 0.5, 0.5, 0.1]\n\
         fallback_timeout_ms = 50.0\n",
    )
    .unwrap()
    .franka;
    assert_eq!(
        f.collision.upper_torque_thresholds_nominal,
        [30.0, 30.0, 28.0, 28.0, 26.0, 24.0, 22.0]
    );
    // The untouched ones keep their defaults.
    assert_eq!(
        f.collision.upper_torque_thresholds_acceleration,
        DEFAULT_TORQUE_THRESHOLDS
    );
    assert_eq!(f.collision.lower_force_thresholds_nominal, [5.0; 6]);
    assert_eq!(f.torque_limits[4], 10.0);
    assert_eq!(f.torque_rate_limit, 500.0);
    assert_eq!(f.command_window_us, 600.0);
    assert_eq!(f.hold_cycles, 0);
    assert_eq!(f.fallback_damping[6], 0.1);
    assert_eq!(f.fallback_timeout_ms, 50.0);
}

#[test]
fn malformed_franka_tables_name_the_field_and_line() {
    let cases: &[(&str, &str, &str)] = &[
        ("unknown field", "torque_limit = 1.0", "franka.torque_limit"),
        (
            "wrong type",
            "torque_rate_limit = \"fast\"",
            "franka.torque_rate_limit",
        ),
        (
            "too few torque thresholds",
            "upper_torque_thresholds_nominal = [20.0, 20.0]",
            "franka.upper_torque_thresholds_nominal",
        ),
        (
            "force thresholds of seven",
            "lower_force_thresholds_nominal = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]",
            "franka.lower_force_thresholds_nominal",
        ),
        (
            "negative threshold",
            "lower_torque_thresholds_acceleration = [1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.0]",
            "franka.lower_torque_thresholds_acceleration[3]",
        ),
        (
            "infinite threshold",
            "upper_force_thresholds_acceleration = [1.0, 1.0, inf, 1.0, 1.0, 1.0]",
            "franka.upper_force_thresholds_acceleration[2]",
        ),
        (
            "lower above upper",
            "lower_torque_thresholds_nominal = [20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 40.0]",
            "franka.lower_torque_thresholds_nominal[6]",
        ),
        (
            "torque limit above the robot's",
            "torque_limits = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 15.0]",
            "franka.torque_limits[6]",
        ),
        (
            "zero torque limit",
            "torque_limits = [0.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]",
            "franka.torque_limits[0]",
        ),
        (
            "torque rate above the robot's",
            "torque_rate_limit = 1500.0",
            "franka.torque_rate_limit",
        ),
        (
            "zero torque rate",
            "torque_rate_limit = 0.0",
            "franka.torque_rate_limit",
        ),
        (
            "NaN torque rate",
            "torque_rate_limit = nan",
            "franka.torque_rate_limit",
        ),
        (
            "command window beyond the cycle",
            "command_window_us = 1000.0",
            "franka.command_window_us",
        ),
        (
            "negative hold cycles",
            "hold_cycles = -1",
            "franka.hold_cycles",
        ),
        (
            "negative fallback damping",
            "fallback_damping = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, -0.5]",
            "franka.fallback_damping[6]",
        ),
        (
            "zero fallback timeout",
            "fallback_timeout_ms = 0.0",
            "franka.fallback_timeout_ms",
        ),
    ];
    let mut failures = Vec::new();
    for (name, field_line, field) in cases {
        match load(field_line) {
            Ok(_) => failures.push(format!("{name}: loaded without error")),
            Err(e) => {
                let msg = e.to_string();
                // Parse errors name the table's path without the index.
                let named = field.split('[').next().unwrap_or(field);
                if !msg.contains(named) {
                    failures.push(format!("{name}: message does not name {field:?}: {msg}"));
                }
                if e.line() != Some(first_line()) {
                    failures.push(format!(
                        "{name}: line {:?}, expected {}: {msg}",
                        e.line(),
                        first_line()
                    ));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn shipped_franka_scenarios_load_as_the_driver_needs_them() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config");
    for f in ["fr3-pose-posture.toml", "panda-fer-pose-posture.toml"] {
        let s = Scenario::load(dir.join(f)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.model.nq(), 7, "{f}");
        // The robot adds gravity itself.
        assert!(!s.spec.gravity_compensation, "{f}");
        // The torque filter keeps two cycles' change within one step the
        // robot accepts.
        let rate = s
            .torque_filter
            .torque_rate_limit
            .expect("a torque-rate limit");
        assert!(2.0 * rate * 1e-3 <= 1.0, "{f}: {rate}");
        assert_eq!(s.franka.torque_rate_limit, FRANKA_MAX_TORQUE_RATE, "{f}");
        assert_eq!(
            s.controller_daemon.torque_limits.as_slice(),
            FRANKA_TORQUE_LIMITS,
            "{f}"
        );
    }
}
