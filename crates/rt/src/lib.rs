//! The runtime of the hcc real-time processes (the controller daemon, the
//! plant-simulator daemon, robot drivers): what each of them needs around its
//! loop, so that the daemons and drivers only say *what* happens per period.
//!
//! * [`thread`]: real-time set-up of the calling thread — core pinning,
//!   `SCHED_FIFO`, `mlockall`, pre-faulting of the stack and the allocator
//!   pool, 1 ns timer slack ([`prepare_rt_thread`]); the cores the process may
//!   use ([`available_cores`]); the start-up clean-up of what crashed peers
//!   left in shared memory ([`cleanup_stale_resources`]).
//! * [`sleep`]: waits to absolute `CLOCK_MONOTONIC` deadlines — the
//!   absolute-time sleep ([`sleep_until_ns`]), the hybrid sleep-then-spin
//!   ([`sleep_until_hybrid_ns`]) and the precise wait for an IPC event
//!   ([`wait_for_event_until`]).
//! * [`stop`]: SIGINT/SIGTERM request a clean stop ([`install_stop_handler`],
//!   [`stop_requested`]).
//! * [`WaitStrategy`]: how a loop waits (`event` or `hybrid`), one type for the
//!   scenario TOML (serde) and the command lines (clap).
//! * [`upkeep`]: iceoryx2 connections to peers that appeared or left, made
//!   while a loop waits instead of inside its next send
//!   ([`ConnectionUpkeep`]).
//! * [`init_logging`]: the one logging set-up of every hcc process —
//!   `tracing` to stderr, filtered by `RUST_LOG`, each line prefixed with the
//!   process's name; for the non-real-time threads.
//!
//! Layering: this crate builds on the message contract `hcc-msgs` (its clock
//! [`hcc_msgs::monotonic_now_ns`] and its iceoryx2 transport); the event wait
//! itself stays in [`hcc_msgs::ipc::wait_for_event_until`], next to the
//! transport whose file descriptor it polls, and is re-exported here so that
//! every wait of a loop is found in one place. Nothing here allocates on the
//! real-time path: the sleeps, the waits and the stop flag are system calls
//! and atomics only.

pub mod args;
pub mod logging;
pub mod sleep;
pub mod stop;
pub mod thread;
pub mod upkeep;
mod wait;

pub use args::{IpcArgs, RtArgs, parse_args, run_main};
pub use sleep::{
    HYBRID_LEAD_NS, sleep_until_hybrid_ns, sleep_until_hybrid_with, sleep_until_ns,
    wait_for_event_until,
};
pub use stop::{install_stop_handler, stop_requested};
pub use thread::{
    RtReport, RtSettings, available_cores, cleanup_stale_resources, fifo_permitted, lower_priority,
    prepare_rt_thread, set_fifo,
};
pub use upkeep::{ConnectionUpkeep, UpkeepCounts};
pub use wait::{UnknownWaitStrategy, WaitStrategy};

pub use logging::init_logging;
