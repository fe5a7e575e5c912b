//! A recording's cycles again, as a library: [`replay`] runs a recording's
//! controller cycles through the control cycle ([`hcc_cycle::ControlCycle`],
//! the code the controller daemon runs) and hands each one on with the
//! recorded and the replayed torque; [`derive`](mod@derive) builds a recorded run's
//! results from it — the rows of `trajectory.csv` in the layout of `hcc
//! simulate`, the metrics and the IPC figures; [`compare`] checks a
//! recording's commands against their replay bit for bit. `hcc replay`, `hcc plot` and
//! `hcc run` parse their arguments and print; the work is here.
//!
//! Opening a recording, replaying its cycles and comparing every command, as
//! `hcc replay` does, then deriving the run's results and metrics, as `hcc
//! plot` does:
//!
//! ```no_run
//! use hcc_replay::derive::{derive, results_writer, scenario_of};
//! use hcc_replay::replay::replay_file;
//!
//! # fn main() -> anyhow::Result<()> {
//! let file = std::path::Path::new("out/run.mcap");
//! // The scenario the recording was made with (the file holds it).
//! let scenario = scenario_of(file, None)?;
//! let (mut compared, mut largest) = (0u64, 0.0f64);
//! let done = replay_file(file, &scenario, &mut |cycle| {
//!     if let (Some(recorded), Some(replayed)) = (cycle.recorded, cycle.replayed_command()) {
//!         for (a, b) in recorded.tau().iter().zip(replayed.tau()) {
//!             largest = largest.max((a - b).abs());
//!         }
//!         compared += 1;
//!     }
//!     Ok(true) // go on
//! })?;
//! println!(
//!     "{compared} cycles compared ({} setpoints taken): largest difference {largest:e} N·m",
//!     done.counts.setpoints_taken
//! );
//! // The run's results (trajectory.csv and metrics.json, no plots) and its metrics.
//! let mut writer = results_writer(&scenario, std::path::Path::new("out/derived"), true)?;
//! let derived = derive(file, &scenario, &mut writer)?;
//! let metrics = writer.finish(&derived.description)?.metrics;
//! print!("{} rows: {}", derived.rows.rows, metrics.summary());
//! # Ok(())
//! # }
//! ```

pub mod compare;
pub mod derive;
pub mod replay;
