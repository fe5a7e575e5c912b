//! `hcc-driver-example CONFIG [--namespace NS] [--duration S]`: the skeleton
//! of a real-robot driver for the hcc controller (Dietrich, Ott &
//! Albu-Schäffer, IROS 2013: the controller computes τ of eq. (19) from the
//! joint state; the driver samples the joints and applies τ).
//!
//! It takes the place of `hcc-sim`: it publishes a [`JointState`] per control
//! period (1 kHz by default, `[controller] rate_hz` of the scenario)
//! from [`RobotHardware::read`] and applies the controller's
//! [`TorqueCommand`]s through [`RobotHardware::write_torque`], following the
//! hcc-msgs contract exactly through its driver logic ([`hcc_msgs::driver`],
//! the same the simulated robot runs): sequence and echo checks, gravity
//! agreement, hold then fallback on a missed command, Stop handling.
//! The hardware here is a stub ([`StubHardware`]: joints frozen at the
//! scenario's q0); a real driver replaces it and keeps the rest.
//!
//! Settings from the scenario: the robot model (joint count, g(q) for the
//! fallback), `[robot] gravity_compensation` (false: the robot adds gravity
//! itself and the driver says so in every state), `[sim_daemon] hold_cycles`
//! and `fallback_damping` (the same miss policy as the simulator).
//!
//! The loop is allocation-free after start-up (the one small allocation per
//! iceoryx2 loan is served by the real-time pool of hcc-rtalloc), wakes at
//! absolute times ([`hcc_rt::sleep_until_ns`]) and waits for the command on
//! the `command_ready` event with a bounded window inside the period
//! ([`hcc_rt::wait_for_event_until`]), counted from the state's stamp: a
//! late period is not caught up but re-anchored (an overrun), so every state
//! has its whole window and no miss is the driver's own lateness (`hcc-sim`,
//! which catches late ticks up, counts those apart as `short_window_misses`).
//! It logs nothing: hardware faults are
//! kept and logged (`tracing`, `RUST_LOG`) after the loop has stopped; the
//! summary of the run goes to stdout.

use anyhow::{Context, anyhow};
use clap::Parser;
use hcc_driver_example::hardware::{HardwareError, RobotHardware, StubHardware};
use hcc_msgs::driver::{Action, DriverLogic, DriverSettings, Gravity, Offer, StopMode, StopReason};
use hcc_msgs::ipc::{self, DriverPorts, Services};
use hcc_msgs::{DriverStatus, JointState, MAX_JOINTS, Namespace, ServiceNames, TorqueCommand};
use iceoryx2::prelude::SignalHandlingMode;
use nalgebra::DVector;
use std::path::PathBuf;
use std::process::ExitCode;

#[global_allocator]
static ALLOCATOR: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

#[derive(Parser, Debug)]
#[command(
    name = "hcc-driver-example",
    version,
    about = "Skeleton of a robot driver for the hcc controller (stub hardware)"
)]
struct Args {
    /// Scenario TOML file (robot model, gravity handling, miss policy, rate).
    config: PathBuf,
    /// IPC namespace and file prefix.
    #[command(flatten)]
    ipc: hcc_rt::IpcArgs,
    /// The loop thread's real-time set-up (memory is always locked).
    #[command(flatten)]
    rt: hcc_rt::RtArgs,
    /// Stop after this many seconds (default: run until SIGINT/SIGTERM).
    #[arg(long)]
    duration: Option<f64>,
    /// Apply commands that answer a state up to this many periods old.
    #[arg(long, default_value_t = 0)]
    late_tolerance: u64,
    /// Time after the state is published within which the command must arrive, µs.
    #[arg(long, default_value_t = 800)]
    command_window_us: u64,
    /// Stop after this long in fallback without an applicable command, ms.
    #[arg(long, default_value_t = 100.0)]
    fallback_timeout_ms: f64,
}

/// Periods before the allocator counters are taken as the baseline.
const WARM_UP_PERIODS: u64 = 100;

/// What the loop did, printed at the end.
#[derive(Debug, Default)]
struct LoopCounts {
    periods: u64,
    holds: u64,
    fallbacks: u64,
    overruns: u64,
}

fn main() -> ExitCode {
    hcc_rt::init_logging("hcc-driver-example");
    let args = Args::parse();
    match run(args) {
        Ok(StopReason::FallbackTimeout) => {
            tracing::warn!("stopped the robot: no applicable command within the fallback timeout");
            ExitCode::from(3)
        }
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The driver's loop state: hardware, contract logic, ports and the
/// workspace of one period, allocated once.
struct Driver<'a> {
    hw: StubHardware,
    logic: DriverLogic,
    ports: DriverPorts,
    model: &'a hcc_model::Model,
    data: hcc_model::Data,
    q_model: DVector<f64>,
    q: Vec<f64>,
    qd: Vec<f64>,
    tau_measured: Vec<f64>,
    tau: Vec<f64>,
    counts: LoopCounts,
    /// The first hardware fault, logged after the loop.
    fault: Option<HardwareError>,
}

impl Driver<'_> {
    /// (1) Samples the joints and publishes the state; returns it.
    fn publish(&mut self) -> anyhow::Result<JointState> {
        if let Err(e) = self
            .hw
            .read(&mut self.q, &mut self.qd, &mut self.tau_measured)
        {
            self.fail(e);
        }
        let stamp = hcc_msgs::monotonic_now_ns();
        let mut sample = self
            .ports
            .states
            .loan_uninit()
            .map_err(|e| anyhow!("loan a joint_state sample: {e:?}"))?
            .write_payload(JointState::zeroed());
        self.logic
            .fill_state(
                sample.payload_mut(),
                &self.q,
                &self.qd,
                &self.tau_measured,
                stamp,
            )
            .map_err(|e| anyhow!("joint state from the hardware: {e}"))?;
        let latest: JointState = *sample.payload();
        sample
            .send()
            .map_err(|e| anyhow!("send joint_state: {e:?}"))?;
        let _ = self.ports.state_ready.notify();
        Ok(latest)
    }

    /// (2) Waits (until `deadline`) for the command answering `latest`;
    /// returns the newest applicable one.
    fn receive(
        &mut self,
        latest: &JointState,
        deadline: u64,
    ) -> anyhow::Result<Option<TorqueCommand>> {
        let mut newest: Option<TorqueCommand> = None;
        loop {
            let mut current = false;
            while let Some(c) = self
                .ports
                .commands
                .receive()
                .map_err(|e| anyhow!("receive torque_command: {e:?}"))?
            {
                if let Offer::Applicable { current: now } = self.logic.offer(&c, latest.header.seq)
                {
                    newest = Some(*c);
                    current |= now;
                }
            }
            if current || hcc_msgs::monotonic_now_ns() >= deadline {
                return Ok(newest);
            }
            if hcc_rt::wait_for_event_until(&self.ports.command_ready, deadline) {
                let _ = self.ports.command_ready.try_wait(|_| {});
            }
        }
    }

    /// (3) Applies, holds, falls back or stops (`stop`: the driver's own stop).
    fn act(&mut self, newest: Option<&TorqueCommand>, stop: bool) {
        let action = if stop {
            self.logic.request_stop()
        } else {
            let (model, data, q_model, q) =
                (self.model, &mut self.data, &mut self.q_model, &self.q);
            let gravity = |g: &mut [f64]| {
                q_model.as_mut_slice().copy_from_slice(q);
                hcc_model::gravity(model, data, q_model);
                g.copy_from_slice(data.g.as_slice());
            };
            self.logic.decide(newest, &self.qd, gravity, &mut self.tau)
        };
        match action {
            Action::Apply | Action::Hold | Action::Fallback | Action::Waiting => {
                self.counts.holds += u64::from(action == Action::Hold);
                self.counts.fallbacks += u64::from(action == Action::Fallback);
                if let Err(e) = self.hw.write_torque(&self.tau) {
                    self.fail(e);
                }
            }
            Action::Stop { first: true } => {
                if let Err(e) = self.hw.safe_stop() {
                    self.fault.get_or_insert(e);
                }
            }
            Action::Stop { first: false } => {}
        }
    }

    /// A hardware fault: kept for the log, and the driver stops.
    fn fail(&mut self, e: HardwareError) {
        self.fault.get_or_insert(e);
        self.logic.request_stop();
        let _ = self.hw.safe_stop();
    }
}

/// The contract settings of this driver: the scenario's miss policy, the
/// command line's tolerance and timeout, the robot's gravity handling.
fn settings(args: &Args, scenario: &hcc_config::Scenario, hw: &StubHardware) -> DriverSettings {
    let rate = scenario.rate_hz;
    let mut fallback_damping = [0.0; MAX_JOINTS];
    for (to, d) in fallback_damping
        .iter_mut()
        .zip(&scenario.sim_daemon.fallback_damping)
    {
        *to = *d;
    }
    DriverSettings {
        n: hw.n_joints(),
        late_tolerance: args.late_tolerance,
        check_sequence: true,
        hold_cycles: u64::from(scenario.sim_daemon.hold_cycles),
        fallback_timeout_cycles: Some(
            (args.fallback_timeout_ms * 1e-3 * rate).ceil().max(1.0) as u64
        ),
        wait_for_first_command: false,
        fallback_damping,
        gravity: if hw.compensates_gravity() {
            Gravity::RobotAdds
        } else {
            Gravity::ControllerSends
        },
        stop_mode: StopMode::SafeStop,
    }
}

fn run(args: Args) -> anyhow::Result<StopReason> {
    let scenario = hcc_config::Scenario::load(&args.config)?;
    let model = &scenario.model;
    let n = model.nq();
    let namespace =
        Namespace::new(args.ipc.namespace_or(&scenario.ipc.namespace)).context("namespace")?;
    let file_prefix = args.ipc.file_prefix();
    let rate = scenario.rate_hz;
    let period_ns = (1e9 / rate).round() as u64;
    let window_ns = (args.command_window_us * 1000).min(period_ns * 9 / 10);
    let end_periods = args
        .duration
        .map_or(u64::MAX, |d| (d.max(0.0) * rate).round() as u64);

    // The robot: here the stub. The robot compensates gravity itself exactly
    // when the controller is configured not to send g(q).
    let hw = StubHardware::new(scenario.q0.as_slice(), !scenario.spec.gravity_compensation);
    if hw.n_joints() != n {
        return Err(anyhow!(
            "the robot has {} joints but the model of {} has {n}",
            hw.n_joints(),
            args.config.display()
        ));
    }
    let node = ipc::create_node(
        "hcc-driver-example",
        SignalHandlingMode::Disabled,
        file_prefix.as_deref(),
    )?;
    let services = Services::open(&node, &ServiceNames::for_namespace(namespace.clone()))?;
    let mut d = Driver {
        logic: DriverLogic::new(settings(&args, &scenario, &hw)),
        ports: DriverPorts::open(&services)?,
        hw,
        model,
        data: hcc_model::Data::new(model),
        q_model: DVector::zeros(n),
        q: vec![0.0; n],
        qd: vec![0.0; n],
        tau_measured: vec![0.0; n],
        tau: vec![0.0; n],
        counts: LoopCounts::default(),
        fault: None,
    };
    hcc_rt::install_stop_handler().context("installing the SIGINT/SIGTERM handlers")?;
    let report = hcc_rt::prepare_rt_thread(&args.rt.settings(None, None, true, 256 * 1024));
    for w in &report.warnings {
        tracing::warn!("{w}");
    }
    tracing::info!(
        "{n} joints at {rate} Hz in namespace {namespace}, robot gravity compensation {}",
        d.hw.compensates_gravity()
    );

    // Allocator counters after a warm-up (first loans, lazily built state).
    let mut warm: Option<(hcc_rtalloc::Stats, u64)> = None;
    // Peers that appear or leave (a recorder, a monitor) are connected before
    // the sleep, not by the next state's send.
    let mut upkeep = hcc_rt::ConnectionUpkeep::new();
    let rt = hcc_rtalloc::RtSection::enter();
    let mut period_start = hcc_msgs::monotonic_now_ns();
    let reason = loop {
        d.counts.periods += 1;
        if d.counts.periods == WARM_UP_PERIODS {
            warm = Some((hcc_rtalloc::stats(), upkeep.counts().system_allocs));
        }
        let latest = d.publish()?;
        match d.logic.status() {
            DriverStatus::Stopped => break d.logic.stop_reason().unwrap_or(StopReason::Requested),
            // The stub's safe stop completes at once; a real robot reports
            // when its brakes are engaged.
            DriverStatus::Stopping => d.logic.stop_completed(),
            _ => {
                let newest = d.receive(&latest, latest.header.stamp_ns + window_ns)?;
                let stop = hcc_rt::stop_requested() || d.counts.periods >= end_periods;
                d.act(newest.as_ref(), stop);
            }
        }
        // (4) Sleep until the next period (absolute time, no drift).
        period_start += period_ns;
        let now = hcc_msgs::monotonic_now_ns();
        if now > period_start {
            d.counts.overruns += 1;
            period_start = now; // resynchronise instead of bursting
        } else {
            upkeep.run(&d.ports.connections());
            hcc_rt::sleep_until_ns(period_start);
        }
    };
    drop(rt);
    if let Some(e) = d.fault {
        tracing::error!("{e}; stopped");
    }
    // System allocations of the loop after warm-up, less the upkeep's.
    let alloc = warm.map_or("-".to_string(), |(w, upkeep_before)| {
        let upkeep_allocs = upkeep.counts().system_allocs - upkeep_before;
        (hcc_rtalloc::stats().rt_system_allocs - w.rt_system_allocs - upkeep_allocs).to_string()
    });
    print_summary(&d, reason, &alloc);
    Ok(reason)
}

/// The run's summary on stdout.
fn print_summary(d: &Driver, reason: StopReason, system_allocs: &str) {
    let r = d.logic.rejections();
    println!(
        "{} periods, {} commands applied, {} missed ({} held, {} fallback, {} fallback cycles), \
         rejected: {} old, {} invalid, {} gravity conflict, {} future, {} too late; \
         {} overruns; {} torque writes; stop: {:?}; system allocations in the loop after warm-up: {}",
        d.counts.periods,
        d.logic.applied(),
        d.logic.missed_commands(),
        d.counts.holds,
        d.counts.fallbacks,
        d.logic.fallback_cycles(),
        r.old,
        r.invalid,
        r.gravity_conflict,
        r.future,
        r.too_late,
        d.counts.overruns,
        d.hw.writes,
        reason,
        system_allocs,
    );
}
