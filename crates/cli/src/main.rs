//! `hcc`: the user-facing command of the hierarchical compliance controller.
//!
//! Results, summaries and progress lines are the command's output (stdout,
//! progress on stderr); diagnostics are logged with `tracing` to stderr, at
//! the level `RUST_LOG` selects (default `info`, e.g. `RUST_LOG=debug` for the
//! daemons' command lines).

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod daemons;
mod follow_cmd;
mod jitter;
mod load_cmd;
mod model_cmd;
mod monitor_cmd;
mod plot_cmd;
mod record_cmd;
mod replay_cmd;
mod run_cmd;
mod run_schedule;
mod setpoint_cmd;
mod simulate_cmd;
mod view_child;

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
    Jitter(jitter::JitterArgs),
    /// Print the dynamics of a URDF chain (M, C, g, ...) at given states, as JSON.
    Model(model_cmd::ModelArgs),
    /// Derive trajectory.csv, metrics.json and the plots from a recording (FILE.mcap), or
    /// redraw the plots of a results directory from its trajectory.csv and metrics.json.
    Plot(plot_cmd::PlotArgs),
    /// Record a running namespace (joint states, commands, telemetry, setpoints) into an
    /// MCAP file, as a pure subscriber.
    Record(record_cmd::RecordArgs),
    /// Write a recording's derived table (the columns of trajectory.csv) as CSV.
    Export(plot_cmd::ExportArgs),
    /// Feed a recording's joint states and setpoints through the controller again and
    /// check that every torque command is bit-identical.
    Replay(replay_cmd::ReplayArgs),
    /// Set a level's goal on a running controller (exit 0 once it accepted it).
    Goal(setpoint_cmd::GoalArgs),
    /// Set a level's stiffness and/or damping on a running controller.
    Gains(setpoint_cmd::GainsArgs),
    /// Tell a running controller the load the robot's hand holds from now on
    /// (mass, centre of mass and inertia at the tip frame).
    Load(load_cmd::LoadArgs),
    /// Send a path file to a running controller's level while it runs, and
    /// follow its progress (the format of a scenario's `trajectory`).
    Follow(follow_cmd::FollowArgs),
    /// Watch a running controller's telemetry (a table, or JSON lines).
    Monitor(monitor_cmd::MonitorArgs),
    /// Serve a running namespace (or a recording, FILE.mcap) live to Foxglove over
    /// WebSocket: the recording's channels, the chain's transforms, the URDF.
    View(hcc_view::Args),
    /// Publish a running namespace on Zenoh for ROS 2 nodes (rmw_zenoh wire format):
    /// joint states, torque commands, telemetry; remote goals with --allow-setpoints.
    Bridge(hcc_bridge::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    hcc_rt::init_logging("hcc");
    let result = match cli.command {
        Command::Run(args) => run_cmd::run(args),
        Command::Simulate(args) => simulate_cmd::run(args),
        Command::Jitter(args) => jitter::run(args),
        Command::Model(args) => model_cmd::run(args),
        Command::Plot(args) => plot_cmd::run(args),
        Command::Record(args) => record_cmd::run(args),
        Command::Export(args) => plot_cmd::export(args),
        Command::Replay(args) => replay_cmd::run(args),
        Command::Goal(args) => setpoint_cmd::goal(args),
        Command::Gains(args) => setpoint_cmd::gains(args),
        Command::Follow(args) => follow_cmd::follow(args),
        Command::Load(args) => load_cmd::load(args),
        Command::Monitor(args) => monitor_cmd::monitor(args),
        Command::View(args) => hcc_view::run(args),
        Command::Bridge(args) => hcc_bridge::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hcc: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
