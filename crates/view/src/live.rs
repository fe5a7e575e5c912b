//! The live server: one thread drains the namespace's streams from iceoryx2
//! through a tap (`hcc_msgs::ipc::Tap`: the largest queues the services
//! allow, 128 samples = 128 ms at 1 kHz, drained every millisecond, at once
//! again after a drain that found half a queue) and hands every sample to
//! the [`Viewer`]; the Foxglove
//! SDK's own runtime sends to the clients. Samples lost because the queue
//! overflowed are counted as gaps; a restarted controller or driver (its
//! sequence numbers start again) is counted and followed.

use anyhow::Context as _;
use hcc_config::ToolScenarioError;
use hcc_msgs::ServiceNames;
use hcc_msgs::ipc::{self, TAP_BURST, TapNode, TapStreams, Tapped};
use hcc_record::mcap_log::{
    self, JointStateMsg, LoadMsg, PathMsg, SetpointMsg, TelemetryMsg, TorqueCommandMsg,
};
use std::time::{Duration, Instant};

use crate::viewer::stats_line;
use crate::{Args, Server};

/// Sleep between drains.
const POLL: Duration = Duration::from_millis(1);
/// Interval of the progress line on stderr.
const PROGRESS: Duration = Duration::from_secs(10);

/// Monotonic stamps onto Unix time (the offset measured at the start).
struct Clock {
    offset_ns: i128,
}

impl Clock {
    fn new() -> Clock {
        let (unix, mono) = mcap_log::clock_pair();
        Clock {
            offset_ns: unix as i128 - mono as i128,
        }
    }

    fn unix(&self, stamp_ns: u64) -> u64 {
        (stamp_ns as i128 + self.offset_ns).clamp(0, u64::MAX as i128) as u64
    }

    fn now(&self) -> u64 {
        self.unix(hcc_msgs::monotonic_now_ns())
    }
}

/// Hands one sample to the viewer.
fn show(server: &mut Server, clock: &Clock, m: Tapped<'_>) {
    let v = &mut server.viewer;
    match m {
        Tapped::Setpoint(s) => v.setpoint(clock.unix(s.header.stamp_ns), &SetpointMsg::from(s)),
        Tapped::Path(p) => v.path(clock.unix(p.header.stamp_ns), &PathMsg::from(p)),
        Tapped::Load(l) => v.load(clock.unix(l.header.stamp_ns), &LoadMsg::from(l)),
        Tapped::State(s) => {
            let h = s.header;
            v.joint_state(h.seq, h.stamp_ns, clock.unix(h.stamp_ns), || {
                JointStateMsg::from(s)
            });
        }
        Tapped::Command(c) => {
            let h = c.header;
            v.torque_command(h.seq, c.state_seq, clock.unix(h.stamp_ns), || {
                TorqueCommandMsg::from(c)
            });
        }
        Tapped::Telemetry(t) => {
            let h = t.header;
            v.telemetry(h.seq, t.state_seq, clock.unix(h.stamp_ns), || {
                TelemetryMsg::from(t)
            });
        }
    }
}

pub fn run(args: &Args, namespace: &str) -> anyhow::Result<()> {
    let names = ServiceNames::new(namespace).context("--namespace")?;
    let file_prefix = args.file_prefix.clone().or_else(ipc::file_prefix_from_env);
    ipc::config(file_prefix.as_deref()).context("--file-prefix")?;
    let scenario = match hcc_config::scenario_for_tool(
        "hcc-view-scenario",
        args.config.as_deref(),
        &names,
        file_prefix.as_deref(),
        std::time::Duration::from_secs(5),
    ) {
        Ok((s, differs)) => {
            if let Some(d) = differs {
                eprintln!("hcc view: warning: --config: {d}");
            }
            Some(s)
        }
        Err(ToolScenarioError::Config(e)) => return Err(e).context("--config"),
        // No controller's scenario: the view serves without the robot.
        Err(e) => {
            if !args.quiet {
                eprintln!("hcc view: {e}: no transform tree, stick figure or joint limits");
            }
            None
        }
    };
    let mut tap = TapNode::open(
        &format!("hcc-view-{}", std::process::id()),
        file_prefix.as_deref(),
        &names,
        TapStreams::All,
    )?;
    let mut server = crate::start(args, scenario.as_ref(), &format!("namespace {namespace}"))?;
    let clock = Clock::new();
    let mut next_progress = Instant::now() + PROGRESS;
    let mut receive_errors = 0u64;
    while !hcc_rt::stop_requested() {
        let most = match tap.tap().drain(&mut |m| show(&mut server, &clock, m)) {
            Ok(k) => k,
            Err(e) => {
                // The server outlives a broken peer: counted and said, once a power of two.
                receive_errors += 1;
                if receive_errors.is_power_of_two() {
                    tracing::warn!("receive failed ({receive_errors} times so far): {e}");
                }
                0
            }
        };
        if server.description_wanted() {
            server.viewer.robot_description(clock.now());
        }
        let clients = server.clients();
        server.viewer.tick(clients, clock.now());
        if !args.quiet && Instant::now() >= next_progress {
            eprintln!("hcc view: {}", stats_line(server.viewer.counts()));
            next_progress += PROGRESS;
        }
        if most < TAP_BURST {
            std::thread::sleep(POLL);
        }
    }
    println!("hcc view: stopped; {}", stats_line(server.viewer.counts()));
    server.handle.stop().wait_blocking();
    drop(tap);
    Ok(())
}
