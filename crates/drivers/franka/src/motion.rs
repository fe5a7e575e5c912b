//! The torque motion as the driver's cycle sees it: read the robot's next
//! state, write one torque, finish the motion. [`franka::ActiveTorqueControl`]
//! is the real one; tests put a fake in its place (the cycle is generic over
//! [`TorqueMotion`], so the same code runs against both).

use franka::{ActiveTorqueControl, FrankaResult, RobotState, Torques};

use crate::guard::JOINTS;

/// One running torque-control motion of a Franka.
pub trait TorqueMotion {
    /// Waits for the robot's next state (1 kHz, the robot's clock).
    fn read_once(&mut self) -> FrankaResult<RobotState>;
    /// Sends the torque answering the last state read (`tau_J_d`, N·m,
    /// without gravity: the robot adds it).
    fn write_once(&mut self, tau: &[f64; JOINTS]) -> FrankaResult<()>;
    /// Ends the motion cleanly with `tau` (libfranka's `motion_finished`):
    /// the robot leaves torque control, holds the arm with its brakes'
    /// controller, and the connection stays open.
    fn finish(&mut self, tau: &[f64; JOINTS]) -> FrankaResult<()>;
}

impl TorqueMotion for ActiveTorqueControl<'_> {
    fn read_once(&mut self) -> FrankaResult<RobotState> {
        ActiveTorqueControl::read_once(self).map(|(state, _period)| state)
    }

    fn write_once(&mut self, tau: &[f64; JOINTS]) -> FrankaResult<()> {
        ActiveTorqueControl::write_once(self, &Torques::new(*tau))
    }

    fn finish(&mut self, tau: &[f64; JOINTS]) -> FrankaResult<()> {
        ActiveTorqueControl::write_once(self, &franka::motion_finished(Torques::new(*tau)))
    }
}
