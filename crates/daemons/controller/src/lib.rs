//! The hcc controller daemon: the hierarchical compliance controller of
//! Dietrich, Ott & Albu-Schäffer, "Multi-Objective Compliance Control of
//! Redundant Manipulators: Hierarchy, Control, and Stability" (IROS 2013), as
//! a 1 kHz process that answers every joint state with a torque command over
//! iceoryx2 (the contract of `hcc-msgs`).
//!
//! * [`decide`]: the decision for one joint state, without I/O — validate,
//!   check the sequence, compute τ = Σ τ_i + τ_μ + g (paper Eq. (19)), the
//!   safe command, saturate ([`Decider`], [`Answer`]).
//! * [`cycle`]: the allocation-free I/O shell around it — wait, receive the
//!   newest state, decide, send the command, publish telemetry ([`Cycle`]).
//! * [`status`]: the counters (defined once: [`LoopCounters`]) and flags the
//!   loop shares with the logging thread ([`Status`]).
//! * The real-time machinery (thread set-up, absolute and hybrid sleeps, the
//!   precise event wait, the stop signal) is the runtime crate `hcc-rt`.
//! * [`daemon`]: the `hcc-controller` command line, start-up, logging and shutdown.
//!
//! The binary installs `hcc_rtalloc::RtAllocator` as its global allocator:
//! iceoryx2 0.10 makes one small allocation per loan, which the real-time
//! thread takes from a pre-faulted pool instead of the system allocator.

pub mod commander;
pub mod cycle;
pub mod daemon;
pub mod decide;
pub mod output;
pub mod schedule;
pub mod status;

pub use cycle::{Cycle, CycleError, CycleSettings, Outcome, Ports};
pub use decide::{Answer, Decider, RESYNC_RUN, max_plausible_gap};
pub use status::{DaemonCounters, LoopCounters, Status};
