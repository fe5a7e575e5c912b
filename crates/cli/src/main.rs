//! `hcc`: the user-facing command of the hierarchical compliance controller.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod model_cmd;

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
    /// Print the dynamics of a URDF chain (M, C, g, ...) at given states, as JSON.
    Model(model_cmd::ModelArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Model(args) => model_cmd::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hcc: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
