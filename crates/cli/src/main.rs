//! `hcc`: the user-facing command of the hierarchical compliance controller.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod daemons;
mod jitter_cmd;
mod model_cmd;
mod plot_cmd;
mod run_cmd;
mod simulate_cmd;

#[derive(Parser)]
#[command(
    name = "hcc",
    version,
    about = "Hierarchical compliance control for redundant robots"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scenario with the daemons over IPC (hcc-sim and hcc-controller as child
    /// processes), record it and write its results (default: config/paper-sim1.toml).
    Run(run_cmd::RunArgs),
    /// Run a scenario in-process (controller at 1 kHz, plant RK4 at 0.1 ms) and write its results.
    Simulate(simulate_cmd::SimulateArgs),
    /// Measure the timing of the daemons on two cores (simulator on one, controller on the
    /// other) against the machine's own floor; table, jitter.json and jitter.png.
    Jitter(jitter_cmd::JitterArgs),
    /// Print the dynamics of a URDF chain (M, C, g, ...) at given states, as JSON.
    Model(model_cmd::ModelArgs),
    /// Redraw the plots of a results directory from its trajectory.csv and metrics.json.
    Plot(plot_cmd::PlotArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => run_cmd::run(args),
        Command::Simulate(args) => simulate_cmd::run(args),
        Command::Jitter(args) => jitter_cmd::run(args),
        Command::Model(args) => model_cmd::run(args),
        Command::Plot(args) => plot_cmd::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hcc: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
