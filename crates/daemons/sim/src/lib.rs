//! The hcc plant-simulator daemon `hcc-sim`: the simulated robot of `hcc-plant`
//! (RK4 integration of the rigid-body dynamics, paper Eq. (1), with the torque
//! held over each control period) acting as a robot driver on the hcc-msgs
//! services, so that the controller daemon can be run and tested against it
//! exactly as against a real robot.
//!
//! * [`hcc_plant::SimDriver`]: the plant behind the driver side of the
//!   contract (`hcc_msgs::driver`: command freshness, hold, fallback,
//!   status), allocation-free per period — the driver `hcc simulate` runs
//!   in process as well.
//! * [`daemon`]: the process — real-time (absolute 1 kHz clock) or lockstep
//!   pacing on the runtime of `hcc-rt`, start-up, logging (`tracing`, from a
//!   logging thread that reads the loop's atomics) and shutdown.

pub mod daemon;

pub use hcc_plant::{Applied, DriverCounters, SimDriver};
