//! `hcc load`: tells a running controller the load the robot's hand holds
//! from now on (docs/load.md) and waits for its answer.

use crate::setpoint_cmd::{Target, connect, timeout};

/// `hcc load`.
#[derive(clap::Args, Debug)]
pub struct LoadArgs {
    #[command(flatten)]
    pub target: Target,
    /// Mass, kg (0: the hand holds nothing).
    #[arg(long, allow_negative_numbers = true)]
    pub mass: f64,
    /// Centre of mass in the tip frame, m: X Y Z.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true, default_values_t = [0.0, 0.0, 0.0])]
    pub com: Vec<f64>,
    /// Rotational inertia about the centre of mass, tip axes, kg·m², as a
    /// URDF gives it: IXX IXY IXZ IYY IYZ IZZ (default: a point mass).
    #[arg(long, num_args = 6, value_names = ["IXX", "IXY", "IXZ", "IYY", "IYZ", "IZZ"], allow_negative_numbers = true)]
    pub inertia: Option<Vec<f64>>,
    /// How long the controller's model takes to reach it, s (0: the
    /// default, 0.2 s).
    #[arg(long, default_value_t = 0.0)]
    pub ramp: f64,
}

/// `hcc load`: exit 0 once the controller accepted the load.
pub fn load(args: LoadArgs) -> anyhow::Result<()> {
    let mut message = hcc_msgs::LoadSetpoint::zeroed();
    message.mass = args.mass;
    message.com.copy_from_slice(&args.com);
    if let Some(i) = &args.inertia {
        message.inertia.copy_from_slice(i);
    }
    message.ramp_s = args.ramp;
    let mut client = connect(&args.target)?;
    client.set_load(message, timeout(&args.target)?)?;
    println!(
        "load of {} kg at {:?} m (tip frame) accepted; ramped in over {:.3} s",
        args.mass,
        args.com,
        message.ramp()
    );
    Ok(())
}
