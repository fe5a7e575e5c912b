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
//! * [`sim_loop`]: the allocation-free loop around the driver — real-time
//!   (absolute 1 kHz clock) or lockstep pacing on the runtime of `hcc-rt`,
//!   publish the state, wait for its answer, integrate ([`SimLoop`]).
//! * [`status`]: the counters and flags the loop shares with the logging
//!   thread ([`LoopStatus`]).
//! * [`daemon`]: the `hcc-sim` command line, start-up, the logging thread
//!   and shutdown.

pub mod daemon;
pub mod recorder_wait;
pub mod sim_loop;
pub mod status;

pub use hcc_plant::{Applied, DriverCounters, SimDriver};
pub use sim_loop::{Ports, SimLoop};
pub use status::LoopStatus;
