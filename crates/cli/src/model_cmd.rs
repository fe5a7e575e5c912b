//! `hcc model`: the robot model's dynamics at given states, as JSON.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ModelArgs {
    /// URDF file of the robot.
    #[arg(long)]
    pub urdf: PathBuf,
    /// Tip link of the chain.
    #[arg(long)]
    pub tip: String,
    /// Gravity vector X,Y,Z in m/s².
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub gravity: Option<Vec<f64>>,
    /// JSON file {"states":[{"q":[...],"qd":[...],"tau":[...]}]}.
    #[arg(long)]
    pub states: PathBuf,
}

pub fn run(args: ModelArgs) -> anyhow::Result<()> {
    let _ = args;
    anyhow::bail!("not yet implemented")
}
