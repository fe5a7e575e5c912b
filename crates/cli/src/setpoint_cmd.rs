//! `hcc goal` and `hcc gains`: setpoints for a running controller through
//! hcc-client, answered by the controller (accepted, or rejected with its
//! reason). Levels are 1-based here (the order of the scenario's
//! `[[level]]`s).

use std::time::Duration;

use anyhow::{Context, bail};
use hcc_client::Client;

/// Where the controller is.
#[derive(clap::Args, Debug, Clone)]
pub struct Target {
    /// Namespace of the controller's services.
    #[arg(long)]
    pub namespace: String,
    /// iceoryx2 file prefix of the controller's peers (default: the
    /// HCC_IPC_FILE_PREFIX environment variable, else iceoryx2's).
    #[arg(long)]
    pub file_prefix: Option<String>,
    /// How long to wait for the controller's answer, s.
    #[arg(long, default_value_t = 2.0)]
    pub timeout: f64,
}

/// `hcc goal`.
// The help texts name the scenario's TOML tables as [table] and placeholders as
// <name>: neither an intra-doc link nor HTML.
#[allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]
#[derive(clap::Args, Debug)]
pub struct GoalArgs {
    #[command(flatten)]
    pub target: Target,
    /// Level: 1-based (the order of the scenario's [[level]]s), or its name
    /// (from the controller's scenario service).
    #[arg(long)]
    pub level: String,
    /// Transition duration, s (0: as fast as the level's speed limit allows).
    #[arg(long, default_value_t = 0.0)]
    pub duration: f64,
    /// The goal in the task's coordinates, as in the TOML.
    #[arg(required = true, allow_negative_numbers = true)]
    pub value: Vec<f64>,
}

/// `hcc gains`.
#[derive(clap::Args, Debug)]
pub struct GainsArgs {
    #[command(flatten)]
    pub target: Target,
    /// Level: 1-based, or its name (from the controller's scenario service).
    #[arg(long)]
    pub level: String,
    /// Task dimension m of the level (default: the level's, from the
    /// controller's scenario service).
    #[arg(long)]
    pub dim: Option<usize>,
    /// Stiffness: m diagonal values or m² row-major.
    #[arg(long, num_args = 1.., allow_negative_numbers = true)]
    pub stiffness: Vec<f64>,
    /// Damping: m diagonal values or m² row-major.
    #[arg(long, num_args = 1.., allow_negative_numbers = true)]
    pub damping: Vec<f64>,
    /// Transition duration, s.
    #[arg(long, default_value_t = 0.0)]
    pub duration: f64,
}

pub(crate) fn connect(t: &Target) -> anyhow::Result<Client> {
    let prefix = t
        .file_prefix
        .clone()
        .or_else(hcc_msgs::ipc::file_prefix_from_env);
    Client::connect(&t.namespace, prefix.as_deref())
        .with_context(|| format!("cannot connect to namespace {:?}", t.namespace))
}

/// The scenario the controller of `t` runs, from its scenario service
/// (`hcc_msgs::ipc::read_scenario`, waiting up to `--timeout`).
pub(crate) fn scenario_of(t: &Target) -> anyhow::Result<hcc_msgs::scenario::ScenarioDoc> {
    let prefix = t
        .file_prefix
        .clone()
        .or_else(hcc_msgs::ipc::file_prefix_from_env);
    let names = hcc_msgs::ServiceNames::new(&t.namespace).context("--namespace")?;
    Ok(hcc_msgs::ipc::read_scenario_as(
        "hcc-tool",
        &names,
        prefix.as_deref(),
        timeout(t)?,
    )?)
}

/// The 0-based level `--level` names: a 1-based number, or a level's name
/// looked up in the controller's scenario (which also gives its dimension).
pub(crate) fn level_index(t: &Target, level: &str) -> anyhow::Result<(usize, Option<usize>)> {
    if let Ok(k) = level.parse::<usize>() {
        if k == 0 {
            bail!("--level is 1-based (the first [[level]] is 1)");
        }
        return Ok((k - 1, None));
    }
    let doc = scenario_of(t).context("--level by name needs the controller's scenario")?;
    match doc.levels.iter().position(|l| l.name == level) {
        Some(i) => Ok((i, Some(doc.levels[i].dim))),
        None => {
            let names: Vec<&str> = doc.levels.iter().map(|l| l.name.as_str()).collect();
            bail!("the controller has no level {level:?} (its levels: {names:?})")
        }
    }
}

pub(crate) fn timeout(t: &Target) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(t.timeout).context("--timeout must be a non-negative number of s")
}

/// `hcc goal`: exit 0 once the controller accepted the goal.
pub fn goal(args: GoalArgs) -> anyhow::Result<()> {
    let (level, _) = level_index(&args.target, &args.level)?;
    let mut client = connect(&args.target)?;
    let seq = client.set_goal(level, &args.value, args.duration)?;
    let answer = client.wait_until_accepted(seq, timeout(&args.target)?)?;
    println!(
        "level {} goal {:?} accepted; transition {:.3} s",
        args.level, args.value, answer.duration_s
    );
    Ok(())
}

/// `hcc gains`: exit 0 once the controller accepted the gains.
pub fn gains(args: GainsArgs) -> anyhow::Result<()> {
    if args.stiffness.is_empty() && args.damping.is_empty() {
        bail!("give --stiffness and/or --damping");
    }
    let (level, known) = level_index(&args.target, &args.level)?;
    let dim = match (args.dim, known) {
        (Some(d), _) => d,
        (None, Some(d)) => d,
        (None, None) => scenario_of(&args.target)
            .context("--dim not given")?
            .levels
            .get(level)
            .map(|l| l.dim)
            .with_context(|| format!("the controller has no level {}", args.level))?,
    };
    let mut client = connect(&args.target)?;
    let seq = client.set_gains(level, dim, &args.stiffness, &args.damping, args.duration)?;
    let answer = client.wait_until_accepted(seq, timeout(&args.target)?)?;
    println!(
        "level {} gains accepted; transition {:.3} s",
        args.level, answer.duration_s
    );
    Ok(())
}
