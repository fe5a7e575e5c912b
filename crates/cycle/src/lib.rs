//! The control cycle of hcc, without any I/O: one call from a joint state to
//! the torque command that answers it (libfranka's shape), the same code
//! wherever a cycle runs — the controller daemon (`hcc-controller`, around
//! iceoryx2), the in-process closed loop (`hcc simulate`), the replay of a
//! recording (`hcc replay`) and the derivation of its results. A lockstep
//! run over IPC, an in-process run and a replay therefore apply the same
//! torque by construction.
//!
//! ```text
//!  JointState ─▶ stream checks ─▶ setpoints due ─▶ law (eq. 19) ─▶ saturation ─▶ torque filter ─▶ TorqueCommand
//!   (q, q̇,        validation,      SetpointHandler   hcc-control      hcc_control::  rate limit,      + Telemetry
//!    seq)         sequence, peer   transitions       Controller::step saturate      low-pass
//!                   └─ rejected: the safe command τ = g(q_v) (or 0) ───────────────────────▶
//! ```
//!
//! * [`ControlCycle`] ([`control_cycle`]): the cycle — [`ControlCycle::step`]
//!   takes a state, the setpoints that arrived with it and the wake-up time,
//!   and leaves the [`hcc_msgs::TorqueCommand`] and the
//!   [`hcc_msgs::Telemetry`] sample in its buffers.
//! * [`stream`]: what a state is worth before the law sees it — validation,
//!   the gravity agreement, the sequence (duplicates, gaps, a restarted peer).
//! * [`setpoints`]: [`SetpointHandler`] — checks a client's setpoint against
//!   the law and the `[setpoint_limits]`, queues it until its state, moves
//!   the level's equilibrium and gains through a transition.
//! * `paths`: the levels' desired paths (a scenario level's `trajectory`),
//!   sampled every used state and handed to the law with the tracking
//!   feed-forward's ẍ_{i,d} (docs/tracking.md).
//! * [`torque_filter`]: [`TorqueFilter`] — the `[torque_filter]` rate limit
//!   and low-pass on the saturated torque, against the previous command.
//! * `output_tank`: the energy tank of the stages after the law — what the
//!   saturation, the torque filter and the velocity limit change in the law's
//!   power is booked, and held back when the tank is empty
//!   ([`ControlCycle::storage`] includes it).
//! * [`schedule`]: a scenario's `[[setpoint]]` entries, delivered to a cycle
//!   as a client would send them.
//! * `contact`: the generalized-momentum observer of the external joint
//!   torque and the contact detection on every used state
//!   ([`ControlCycle::external_torque`], [`ControlCycle::in_contact`]);
//!   `wrench`: from it, the external wrench at the first position or pose
//!   level's frame ([`ControlCycle::external_wrench`]).
//! * [`counters`]: every counter of the cycle, defined once.
//! * [`settings`]: [`CycleSettings`] from a scenario, and [`CycleError`].
//!
//! Everything is allocated when a [`ControlCycle`] is built; a cycle
//! allocates nothing, takes no lock, does no logging or formatting (the
//! controller daemon's tests count its allocations). Events go to counters.

mod contact;
pub mod control_cycle;
pub mod counters;
pub mod feasibility;
mod law;
mod load_ramp;
mod output_tank;
pub mod path_check;
mod path_gate;
mod paths;
mod reaction;
pub mod schedule;
pub mod setpoints;
pub mod settings;
pub mod stream;
mod telemetry;
pub mod torque_filter;
mod velocity_limit;
mod wrench;

pub use control_cycle::{Answer, ControlCycle};
pub use counters::{CoreCounters, CycleCounters};
pub use law::controller_for;
pub use path_gate::{CHECK_IDLE_SLEEP, GATE_CAPACITY, PathCheckWorker};
pub use schedule::Schedule;
pub use setpoints::SetpointHandler;
pub use settings::{CycleError, CycleSettings};
pub use stream::{GAP_SLACK, RESYNC_RUN, max_plausible_gap};
pub use torque_filter::TorqueFilter;
