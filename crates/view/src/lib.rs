//! `hcc view`: a live Foxglove WebSocket server of a running hcc namespace,
//! and the playback of a recording through the same server.
//!
//! The server is a separate process and a pure iceoryx2 subscriber, like the
//! recorder: it never publishes into the namespace and never waits on the
//! control loop (the contract's publishers do not block on subscribers:
//! safe overflow). It serves the recording's channels with their JSON
//! schemas (`/joint_state`, `/torque_command`, `/telemetry`, `/setpoint`;
//! see `hcc_record::mcap_log`), so a Foxglove layout opens a live run and a
//! recording alike, and adds what a 3-D panel and a safety view need: the
//! chain's transform tree with the TCP and goal frame of every Cartesian
//! level (`/tf`), a stick figure of the chain (`/chain`), the joints against
//! their URDF limits (`/joint_limits`), the URDF (`/robot_description`, and
//! as the asset [`assets::URDF_URI`]) and its own counts (`/view`). See
//! [`channels`] for the table.
//!
//! The protocol is the Foxglove SDK's (`foxglove` crate, subprotocol
//! `foxglove.sdk.v1`); each client has its own queue in the SDK, which drops
//! the oldest messages when a client reads too slowly, so a slow client
//! slows nothing but itself. `--rate` limits what is published (joint
//! states on a grid of their stamps, with the command and telemetry of
//! exactly those states; setpoints always); everything received is counted
//! per stream (`/view`: received, published, lost, restarts).

pub mod assets;
pub mod channels;
pub mod frames;
mod live;
mod playback;
pub mod viewer;

use anyhow::{Context as _, bail};
use foxglove::websocket::{Client, ServerListener};
use foxglove::{Context, WebSocketServerHandle};
use hcc_config::Scenario;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::assets::Assets;
use crate::channels::Channels;
use crate::frames::FrameTree;
use crate::viewer::Viewer;

/// Arguments of `hcc view`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// A recording (FILE.mcap) to play back through the server instead of a
    /// live namespace.
    pub file: Option<PathBuf>,
    /// Namespace of the running controller and driver.
    #[arg(long)]
    pub namespace: Option<String>,
    /// The scenario the namespace runs (its URDF and levels give the
    /// transform tree, the stick figure and the joint limits). A playback
    /// takes it from the recording unless given.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Address to listen on (default: this machine only).
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: String,
    /// TCP port (0: any free port; the one chosen is printed).
    #[arg(long, default_value_t = 8765)]
    pub port: u16,
    /// Joint states published per second, with their commands and
    /// telemetry (0: every sample).
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    /// iceoryx2 file prefix of the daemons (default: HCC_IPC_FILE_PREFIX, else iceoryx2's).
    #[arg(long)]
    pub file_prefix: Option<String>,
    /// Playback speed (1: real time).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Playback: exit at the end of the recording instead of serving until Ctrl-C.
    #[arg(long)]
    pub exit_at_end: bool,
    /// No progress lines on stderr.
    #[arg(long)]
    pub quiet: bool,
}

/// The server's event listener: notes when a client subscribes to the URDF
/// topic (the main loop then publishes it; nothing is logged from the
/// server's own tasks).
#[derive(Default)]
struct Listener {
    description_wanted: AtomicBool,
}

impl ServerListener for Listener {
    fn on_subscribe(&self, _client: Client, channel: foxglove::websocket::ChannelView) {
        if channel.topic() == channels::TOPIC_ROBOT_DESCRIPTION {
            self.description_wanted.store(true, Ordering::Relaxed);
        }
    }
}

/// A started server and what feeds it.
struct Server {
    /// The channels' context: they close when it is dropped.
    _ctx: Arc<Context>,
    handle: WebSocketServerHandle,
    listener: Arc<Listener>,
    viewer: Viewer,
}

impl Server {
    /// Whether a client asked for the URDF since the last call.
    fn description_wanted(&self) -> bool {
        self.listener
            .description_wanted
            .swap(false, Ordering::Relaxed)
    }

    fn clients(&self) -> usize {
        self.handle.client_count()
    }
}

/// The scenario's transform tree, URDF text and assets; `None` without a scenario.
fn robot(
    scenario: Option<&Scenario>,
) -> anyhow::Result<(Option<FrameTree>, Option<String>, Option<Assets>)> {
    let Some(s) = scenario else {
        return Ok((None, None, None));
    };
    let urdf = std::fs::read_to_string(&s.urdf_path)
        .with_context(|| format!("cannot read the URDF {}", s.urdf_path.display()))?;
    let tree = FrameTree::new(s, &urdf)?;
    let assets = Assets::new(&s.urdf_path, urdf.clone());
    Ok((Some(tree), Some(urdf), Some(assets)))
}

/// Starts the WebSocket server on `args.bind`:`args.port` for `scenario`
/// and prints its address on stdout (one line, `hcc view: ws://HOST:PORT ...`).
fn start(args: &Args, scenario: Option<&Scenario>, what: &str) -> anyhow::Result<Server> {
    let (tree, urdf, assets) = robot(scenario)?;
    let ctx = Context::new();
    let channels = Channels::new(&ctx)?;
    let listener = Arc::new(Listener::default());
    let mut server = ctx
        .websocket_server()
        .name(format!("hcc view: {what}"))
        .bind(args.bind.clone(), args.port)
        .listener(listener.clone());
    if let Some(assets) = assets {
        server =
            server.fetch_asset_handler_blocking_fn(move |_client, uri: String| assets.fetch(&uri));
    }
    let handle = server
        .start_blocking()
        .with_context(|| format!("cannot serve on {}:{}", args.bind, args.port))?;
    let mut out = std::io::stdout();
    let _ = writeln!(
        out,
        "hcc view: ws://{}:{} ({what}, {})",
        args.bind,
        handle.port(),
        if args.rate > 0.0 {
            format!("{} Hz", args.rate)
        } else {
            "every sample".into()
        }
    );
    let _ = out.flush();
    Ok(Server {
        _ctx: ctx,
        handle,
        listener,
        viewer: Viewer::new(channels, tree, urdf, args.rate),
    })
}

/// Runs `hcc view`: the live server of `--namespace`, or the playback of FILE.
pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.rate.is_finite() && args.rate >= 0.0) {
        bail!(
            "--rate must be a number of samples per second ≥ 0, not {}",
            args.rate
        );
    }
    hcc_rt::install_stop_handler()
        .map_err(|e| anyhow::anyhow!("cannot install the SIGINT/SIGTERM handlers: {e}"))?;
    match (&args.file, &args.namespace) {
        (Some(file), None) => playback::run(&args, file),
        (None, Some(ns)) => live::run(&args, ns),
        (Some(_), Some(_)) => bail!("give either a recording or --namespace, not both"),
        (None, None) => bail!("give --namespace NS (a running system) or a recording FILE.mcap"),
    }
}
