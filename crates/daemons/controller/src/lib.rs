//! The hcc controller daemon: the hierarchical compliance controller of
//! Dietrich, Ott & Albu-Schäffer, "Multi-Objective Compliance Control of
//! Redundant Manipulators: Hierarchy, Control, and Stability" (IROS 2013), as
//! a 1 kHz process that answers every joint state with a torque command over
//! iceoryx2 (the contract of `hcc-msgs`).
//!
//! * [`cycle`]: one control cycle, allocation-free — wait, validate, compute
//!   τ = Σ τ_i + τ_μ + g (paper Eq. (19)), saturate, publish command and telemetry.
//! * [`rt`]: the real-time runtime `hcc-rt` (thread set-up, absolute sleeps,
//!   the precise event wait, the stop signal), re-exported under its old path.
//! * [`daemon`]: the `hcc-controller` command line, start-up and shutdown.
//!
//! The binary installs `hcc_rtalloc::RtAllocator` as its global allocator:
//! iceoryx2 0.10 makes one small allocation per loan, which the real-time
//! thread takes from a pre-faulted pool instead of the system allocator.

pub mod cycle;
pub mod daemon;
pub use hcc_rt as rt;

pub use cycle::{Cycle, CycleError, CycleSettings, Outcome, Ports, Status};
