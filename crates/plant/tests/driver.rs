//! The simulated driver's command handling (no IPC): without a controller the
//! arm is held (gravity plus damping) instead of falling; misses hold the last
//! command for `hold_cycles`, then the fallback brakes, and fresh commands
//! resume normal operation.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_msgs::{CommandMode, DriverStatus, JointState, TorqueCommand};
use hcc_plant::{Applied, SimDriver};

fn scenario() -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/paper-sim1.toml");
    Scenario::load(&path).unwrap()
}

/// The command a controller would send for the driver's current state.
fn answer(controller: &mut Controller, driver: &SimDriver) -> TorqueCommand {
    let mut state = JointState::zeroed();
    driver.write_state(&mut state, 1);
    let out = controller.step(state.q(), state.qd()).unwrap();
    let mut c = TorqueCommand::zeroed();
    c.set_n_joints(state.n()).unwrap();
    c.set_tau(out.tau.as_slice()).unwrap();
    c.answer(&state);
    c.flags = hcc_msgs::COMMAND_FLAG_GRAVITY_INCLUDED;
    c.mode = CommandMode::Normal.code();
    c
}

#[test]
fn without_a_controller_the_arm_is_held_not_dropped() {
    let scenario = scenario();
    let mut driver = SimDriver::new(&scenario).unwrap();
    for _ in 0..500 {
        assert_eq!(driver.advance(None).unwrap(), Applied::WaitingForController);
    }
    let drift = (driver.plant().q() - &scenario.q0).amax();
    assert!(drift < 1e-6, "the arm moved by {drift} rad in 0.5 s");
    assert_eq!(driver.status(), DriverStatus::FallbackActive);
    assert_eq!(driver.counters().missed_commands, 0);
    assert_eq!(driver.counters().fallback_cycles, 500);

    // Compare: no torque at all lets it fall.
    let mut falling = hcc_plant::plant_for(&scenario).unwrap();
    let zero = nalgebra::DVector::zeros(scenario.model.nq());
    for _ in 0..5000 {
        falling.step(&zero, 1e-4).unwrap();
    }
    assert!((falling.q() - &scenario.q0).amax() > 0.1);
}

#[test]
fn misses_hold_then_fall_back_and_fresh_commands_resume() {
    let scenario = scenario();
    let hold = scenario.sim_daemon.hold_cycles;
    let mut driver = SimDriver::new(&scenario).unwrap();
    let mut controller =
        Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
    for _ in 0..10 {
        let c = answer(&mut controller, &driver);
        assert_eq!(driver.advance(Some(&c)).unwrap(), Applied::Command);
    }
    assert_eq!(driver.status(), DriverStatus::Ok);
    // The controller dies: its last command answers an old state.
    let stale = answer(&mut controller, &driver);
    driver.advance(Some(&stale)).unwrap();
    for _ in 0..hold {
        assert_eq!(driver.advance(Some(&stale)).unwrap(), Applied::Held);
        // Detected in the first period without a command: the fallback
        // (holding, then braking) is reported at once.
        assert_eq!(driver.status(), DriverStatus::FallbackActive);
    }
    for _ in 0..20 {
        assert_eq!(driver.advance(Some(&stale)).unwrap(), Applied::Fallback);
    }
    let mut state = JointState::zeroed();
    driver.write_state(&mut state, 1);
    assert_eq!(state.status, DriverStatus::FallbackActive.code());
    assert_eq!(state.missed_commands, u64::from(hold) + 20);
    assert_eq!(state.fallback_cycles, u64::from(hold) + 20);

    // A command answering another state is not applied; a current one is.
    let mut future = answer(&mut controller, &driver);
    future.state_seq += 1;
    assert_eq!(driver.advance(Some(&future)).unwrap(), Applied::Fallback);
    let c = answer(&mut controller, &driver);
    assert_eq!(driver.advance(Some(&c)).unwrap(), Applied::Command);
    assert_eq!(driver.status(), DriverStatus::Ok);

    // Invalid commands are rejected (NaN torque, gravity disagreement).
    let mut nan = answer(&mut controller, &driver);
    nan.tau[1] = f64::NAN;
    assert_ne!(driver.advance(Some(&nan)).unwrap(), Applied::Command);
    let mut no_gravity = answer(&mut controller, &driver);
    no_gravity.flags = 0;
    assert_ne!(driver.advance(Some(&no_gravity)).unwrap(), Applied::Command);
    assert_eq!(driver.counters().rejected_commands, 2);

    // Stop: no more commands are applied.
    let mut stop = answer(&mut controller, &driver);
    stop.mode = CommandMode::Stop.code();
    assert_eq!(driver.advance(Some(&stop)).unwrap(), Applied::Stopped);
    let c = answer(&mut controller, &driver);
    assert_eq!(driver.advance(Some(&c)).unwrap(), Applied::Stopped);
    assert_eq!(driver.status(), DriverStatus::Stopped);
}
