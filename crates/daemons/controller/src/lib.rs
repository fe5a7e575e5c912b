//! The hcc controller daemon: the hierarchical compliance controller of
//! Dietrich, Ott & Albu-Schäffer, "Multi-Objective Compliance Control of
//! Redundant Manipulators: Hierarchy, Control, and Stability" (IROS 2013), as
//! a 1 kHz process that answers every joint state with a torque command over
//! iceoryx2 (the contract of `hcc-msgs`).
//!
//! The cycle itself — stream checks, setpoints, the law τ = Σ τ_i + τ_μ + g
//! (paper Eq. (19)), the torque filter, saturation, the safe command — is the
//! library `hcc-cycle` ([`hcc_cycle::ControlCycle`]), the same code `hcc
//! simulate` and `hcc replay` run. This crate is its I/O shell:
//!
//! * [`control_loop`]: the allocation-free loop around the cycle — wait,
//!   receive the newest state and the setpoints, step the cycle, send the
//!   command, publish telemetry, time every stage ([`ControlLoop`]).
//! * [`warm_up`]: the cache warm-up of the hybrid wait ([`warm_up::WarmUp`]).
//! * [`status`]: the counters and flags the loop shares with the logging
//!   thread ([`LoopStatus`]).
//! * The real-time machinery (thread set-up, absolute and hybrid sleeps, the
//!   precise event wait, the stop signal, logging) is the runtime crate `hcc-rt`.
//! * [`daemon`]: the `hcc-controller` command line, start-up, the logging
//!   thread and shutdown.
//!
//! The binary installs `hcc_rtalloc::RtAllocator` as its global allocator:
//! iceoryx2 0.10 makes one small allocation per loan, which the real-time
//! thread takes from a pre-faulted pool instead of the system allocator.

pub mod control_loop;
pub mod daemon;
pub mod status;
pub mod warm_up;

pub use control_loop::{ControlLoop, LoopSettings, LoopTimings, Outcome, Ports};
pub use status::LoopStatus;
