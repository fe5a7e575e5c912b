//! The hardware side of a driver: what a real robot's driver implements.
//!
//! [`RobotHardware`] is the only part of this example that talks to a robot.
//! Replace [`StubHardware`] with an implementation over the robot's own
//! interface (fieldbus, vendor SDK, …); the rest of the driver — the message
//! contract, timing, sequence checks, hold/fallback and stop — stays as it is.
//!
//! Every method is called from the 1 kHz loop and must not allocate or block
//! longer than a fraction of the period.

use thiserror::Error;

/// A failure of the robot interface, naming the operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum HardwareError {
    /// Reading the joint sensors failed (communication loss, sensor fault).
    #[error("hardware read failed: {0}")]
    Read(&'static str),
    /// Writing the torque command failed.
    #[error("hardware write failed: {0}")]
    Write(&'static str),
    /// The robot's safe stop could not be engaged.
    #[error("safe stop failed: {0}")]
    Stop(&'static str),
}

/// Access to the joints of one robot, in the contract's joint order (the
/// actuated joints along the URDF chain from root to tip).
pub trait RobotHardware {
    /// Number of actuated joints n.
    fn n_joints(&self) -> usize;

    /// Whether the robot's torque interface adds gravity compensation g(q)
    /// itself (then commands must not contain it; the driver sets
    /// `STATE_FLAG_DRIVER_GRAVITY_COMPENSATION`).
    fn compensates_gravity(&self) -> bool;

    /// Samples the joints at the start of a period: positions q (rad or m),
    /// velocities q̇ and measured torques (zero without torque sensing). Each
    /// slice has length n.
    fn read(&mut self, q: &mut [f64], qd: &mut [f64], tau: &mut [f64])
    -> Result<(), HardwareError>;

    /// Commands joint torques τ (N·m or N, length n) for the coming period.
    fn write_torque(&mut self, tau: &[f64]) -> Result<(), HardwareError>;

    /// Engages the robot's own safe stop (brakes, stop category of the
    /// robot). Called once; afterwards no torque is written.
    fn safe_stop(&mut self) -> Result<(), HardwareError>;
}

/// A stand-in for a robot: the joints stay where they were put, velocities are
/// zero and the "measured" torque is the last written one. It keeps counts of
/// what the driver did, for the log and tests.
#[derive(Debug, Clone)]
pub struct StubHardware {
    q: Vec<f64>,
    last_tau: Vec<f64>,
    compensates_gravity: bool,
    /// Torque writes so far.
    pub writes: u64,
    /// Whether the safe stop was engaged.
    pub stopped: bool,
}

impl StubHardware {
    /// A stub with joints at `q0`.
    pub fn new(q0: &[f64], compensates_gravity: bool) -> StubHardware {
        StubHardware {
            q: q0.to_vec(),
            last_tau: vec![0.0; q0.len()],
            compensates_gravity,
            writes: 0,
            stopped: false,
        }
    }
}

impl RobotHardware for StubHardware {
    fn n_joints(&self) -> usize {
        self.q.len()
    }

    fn compensates_gravity(&self) -> bool {
        self.compensates_gravity
    }

    fn read(
        &mut self,
        q: &mut [f64],
        qd: &mut [f64],
        tau: &mut [f64],
    ) -> Result<(), HardwareError> {
        if q.len() != self.q.len() || qd.len() != self.q.len() || tau.len() != self.q.len() {
            return Err(HardwareError::Read(
                "buffer length differs from the joint count",
            ));
        }
        q.copy_from_slice(&self.q);
        qd.fill(0.0);
        tau.copy_from_slice(&self.last_tau);
        Ok(())
    }

    fn write_torque(&mut self, tau: &[f64]) -> Result<(), HardwareError> {
        if self.stopped {
            return Err(HardwareError::Write("the robot is stopped"));
        }
        if tau.len() != self.last_tau.len() {
            return Err(HardwareError::Write(
                "torque length differs from the joint count",
            ));
        }
        self.last_tau.copy_from_slice(tau);
        self.writes += 1;
        Ok(())
    }

    fn safe_stop(&mut self) -> Result<(), HardwareError> {
        self.stopped = true;
        self.last_tau.fill(0.0);
        Ok(())
    }
}
