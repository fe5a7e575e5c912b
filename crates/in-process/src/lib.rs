//! hcc in one process: the simulated robot's driver ([`hcc_plant::SimDriver`],
//! the plant behind the driver side of the message contract) and the control
//! cycle ([`hcc_cycle::ControlCycle`]) exchange the same messages the daemons
//! exchange over iceoryx2 — a [`hcc_msgs::JointState`] per period k (stamped
//! t_k = k T), the [`hcc_msgs::TorqueCommand`] that answers it, held over
//! [t_k, t_{k+1}] — but by function call. The scenario's `[[setpoint]]`
//! entries reach the cycle with the state of their cycle, as a client's do.
//!
//! Because both ends are the daemons' own code, an in-process run (`hcc
//! simulate`) and a lockstep run over IPC (`hcc run --lockstep`) apply the
//! same torque by construction: the torque filter, the saturation, a driver
//! that adds gravity itself (`[robot] gravity_compensation = false`) and the
//! safe command included.
//!
//! One trajectory row per cycle, from t = 0 to t = duration (both included),
//! is recorded by the recorder of hcc-record ([`hcc_record::Recorder`]; its
//! documentation lists the columns) from the cycle's telemetry and the law's
//! terms — what the derivation of a recording reads too.

mod closed_loop;
mod energy;

pub use closed_loop::{CycleView, Run, run_observed, simulate, simulate_observed};
pub use energy::{PlantEnergyModel, recorder};
pub use hcc_plant::SimError;
pub use hcc_record::{column_names, describe};
