//! `hcc-driver-example CONFIG [--namespace NS] [--duration S]`: the skeleton
//! of a real-robot driver for the hcc controller (Dietrich, Ott &
//! Albu-Schäffer, IROS 2013: the controller computes τ of eq. (19) from the
//! joint state; the driver samples the joints and applies τ).
//!
//! It takes the place of `hcc-sim`: it publishes a [`JointState`] per control
//! period (1 kHz by default, `[simulation] control_rate_hz` of the scenario)
//! from [`RobotHardware::read`] and applies the controller's
//! [`TorqueCommand`]s through [`RobotHardware::write_torque`], following the
//! hcc-msgs contract exactly (see [`hcc_driver_example::contract`]): sequence and echo checks,
//! gravity agreement, hold then fallback on a missed command, Stop handling.
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
//! absolute times (`clock_nanosleep(TIMER_ABSTIME)`) and waits for the command
//! on the `command_ready` event with a bounded window inside the period.

use anyhow::{Context, anyhow};
use clap::Parser;
use hcc_driver_example::contract::{Action, DriverLogic, DriverSettings, Offer, StopReason};
use hcc_driver_example::hardware::{RobotHardware, StubHardware};
use hcc_msgs::ipc::{self, LATEST_BUFFER, Services};
use hcc_msgs::{JointState, MAX_JOINTS, Namespace, ServiceNames, TorqueCommand};
use iceoryx2::prelude::SignalHandlingMode;
use nalgebra::DVector;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

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
    /// IPC namespace (default: [ipc] namespace of the scenario).
    #[arg(long)]
    namespace: Option<String>,
    /// iceoryx2 file prefix (default: HCC_IPC_FILE_PREFIX, else iceoryx2's default).
    #[arg(long)]
    file_prefix: Option<String>,
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

static STOP_REQUESTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_signal: libc::c_int) {
    STOP_REQUESTED.store(true, Ordering::SeqCst);
}

fn install_signal_handlers() -> anyhow::Result<()> {
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: a zeroed sigaction is valid; the handler only stores to an atomic.
        let rc = unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(signal, &action, std::ptr::null_mut())
        };
        if rc != 0 {
            return Err(anyhow!(
                "cannot install the handler of signal {signal}: {}",
                std::io::Error::last_os_error()
            ));
        }
    }
    Ok(())
}

/// Sleeps until the absolute CLOCK_MONOTONIC time `t_ns` (allocation-free).
fn sleep_until_ns(t_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (t_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (t_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: valid timespec; EINTR just ends the sleep early (the loop re-checks).
    unsafe {
        libc::clock_nanosleep(
            libc::CLOCK_MONOTONIC,
            libc::TIMER_ABSTIME,
            &ts,
            std::ptr::null_mut(),
        );
    }
}

/// What the loop did, printed at the end.
#[derive(Debug, Default)]
struct LoopCounts {
    periods: u64,
    holds: u64,
    fallbacks: u64,
    overruns: u64,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(args) {
        Ok(StopReason::FallbackTimeout) => {
            eprintln!(
                "hcc-driver-example: stopped the robot: no applicable command within the fallback timeout"
            );
            ExitCode::from(3)
        }
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hcc-driver-example: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<StopReason> {
    let scenario = hcc_config::Scenario::load(&args.config)?;
    let model = &scenario.model;
    let n = model.nq();
    let namespace = Namespace::new(args.namespace.as_deref().unwrap_or(&scenario.ipc.namespace))
        .context("namespace")?;
    let file_prefix = args.file_prefix.clone().or_else(ipc::file_prefix_from_env);
    let rate = scenario.simulation.control_rate_hz;
    let period_ns = (1e9 / rate).round() as u64;
    let window_ns = (args.command_window_us * 1000).min(period_ns * 9 / 10);
    let timeout_cycles = (args.fallback_timeout_ms * 1e-3 * rate).ceil().max(1.0) as u64;
    let end_periods = args
        .duration
        .map(|d| (d.max(0.0) * rate).round() as u64)
        .unwrap_or(u64::MAX);

    // The robot: here the stub. The robot compensates gravity itself exactly
    // when the controller is configured not to send g(q).
    let mut hw = StubHardware::new(scenario.q0.as_slice(), !scenario.spec.gravity_compensation);
    if hw.n_joints() != n {
        return Err(anyhow!(
            "the robot has {} joints but the model of {} has {n}",
            hw.n_joints(),
            args.config.display()
        ));
    }
    let mut damping = [0.0; MAX_JOINTS];
    damping[..n].copy_from_slice(scenario.sim_daemon.fallback_damping.as_slice());
    let mut logic = DriverLogic::new(DriverSettings {
        n,
        late_tolerance: args.late_tolerance,
        hold_cycles: u64::from(scenario.sim_daemon.hold_cycles),
        fallback_timeout_cycles: timeout_cycles,
        fallback_damping: damping,
        compensates_gravity: hw.compensates_gravity(),
    });

    // IPC, through the contract's service settings.
    let node = ipc::create_node(
        "hcc-driver-example",
        SignalHandlingMode::Disabled,
        file_prefix.as_deref(),
    )?;
    let services = Services::open(&node, &ServiceNames::for_namespace(namespace.clone()))?;
    let state_pub = services.joint_state_publisher()?;
    let state_ready = services.state_ready_notifier()?;
    let command_sub = services.torque_command_subscriber(LATEST_BUFFER)?;
    let command_ready = services.command_ready_listener()?;
    install_signal_handlers()?;

    // Loop workspace, allocated once.
    let mut q = vec![0.0; n];
    let mut qd = vec![0.0; n];
    let mut tau_measured = vec![0.0; n];
    let mut tau = vec![0.0; n];
    let mut q_model = DVector::zeros(n);
    let mut data = hcc_model::Data::new(model);
    let mut counts = LoopCounts::default();

    if let Err(e) = hcc_rtalloc::lock_memory() {
        eprintln!("hcc-driver-example: warning: {e} (running without locked memory)");
    }
    hcc_rtalloc::prefault();
    hcc_rtalloc::prefault_stack(256 * 1024)?;
    eprintln!(
        "hcc-driver-example: {n} joints at {rate} Hz in namespace {namespace}, robot gravity compensation {}",
        hw.compensates_gravity()
    );

    // Allocator counters after a warm-up (first loans, lazily built state).
    let mut warm: Option<hcc_rtalloc::Stats> = None;
    let rt = hcc_rtalloc::RtSection::enter();
    let mut period_start = hcc_msgs::monotonic_now_ns();
    let reason = loop {
        counts.periods += 1;
        if counts.periods == WARM_UP_PERIODS {
            warm = Some(hcc_rtalloc::stats());
        }
        // (1) Sample the joints and publish the state.
        if let Err(e) = hw.read(&mut q, &mut qd, &mut tau_measured) {
            eprintln!("hcc-driver-example: {e}; stopping");
            logic.request_stop();
            let _ = hw.safe_stop();
        }
        let stamp = hcc_msgs::monotonic_now_ns();
        let mut sample = state_pub
            .loan_uninit()
            .map_err(|e| anyhow!("loan a joint_state sample: {e:?}"))?
            .write_payload(JointState::zeroed());
        logic
            .fill_state(sample.payload_mut(), &q, &qd, &tau_measured, stamp)
            .map_err(|e| anyhow!("joint state from the hardware: {e}"))?;
        let latest: JointState = *sample.payload();
        sample
            .send()
            .map_err(|e| anyhow!("send joint_state: {e:?}"))?;
        let _ = state_ready.notify();

        match logic.status() {
            hcc_msgs::DriverStatus::Stopped => {
                break logic.stop_reason().unwrap_or(StopReason::Requested);
            }
            hcc_msgs::DriverStatus::Stopping => {
                // The stub's safe stop completes at once; a real robot reports
                // when its brakes are engaged.
                logic.stop_completed();
            }
            _ => {
                // (2) Wait (bounded) for the command answering this state.
                let deadline = stamp + window_ns;
                let mut newest: Option<TorqueCommand> = None;
                loop {
                    let mut current = false;
                    while let Some(c) = command_sub
                        .receive()
                        .map_err(|e| anyhow!("receive torque_command: {e:?}"))?
                    {
                        if let Offer::Applicable { current: now } = logic.offer(&c, &latest) {
                            newest = Some(*c);
                            current |= now;
                        }
                    }
                    let now = hcc_msgs::monotonic_now_ns();
                    if current || now >= deadline {
                        break;
                    }
                    // Precise to the deadline (iceoryx2's Listener::timed_wait
                    // rounds up to a scheduler tick, several ms).
                    if hcc_msgs::ipc::wait_for_event_until(&command_ready, deadline) {
                        let _ = command_ready.try_wait(|_| {});
                    }
                }
                // (3) Apply, hold, fall back or stop.
                let action =
                    if STOP_REQUESTED.load(Ordering::SeqCst) || counts.periods >= end_periods {
                        logic.request_stop()
                    } else {
                        if !hw.compensates_gravity() {
                            q_model.as_mut_slice().copy_from_slice(&q);
                            hcc_model::gravity(model, &mut data, &q_model);
                        }
                        logic.decide(newest.as_ref(), &qd, data.g.as_slice(), &mut tau)
                    };
                match action {
                    Action::Apply | Action::Hold | Action::Fallback => {
                        counts.holds += u64::from(action == Action::Hold);
                        counts.fallbacks += u64::from(action == Action::Fallback);
                        if let Err(e) = hw.write_torque(&tau) {
                            eprintln!("hcc-driver-example: {e}; stopping");
                            logic.request_stop();
                            let _ = hw.safe_stop();
                        }
                    }
                    Action::Stop { first: true } => {
                        if let Err(e) = hw.safe_stop() {
                            eprintln!("hcc-driver-example: {e}");
                        }
                    }
                    Action::Stop { first: false } => {}
                }
            }
        }

        // (4) Sleep until the next period (absolute time, no drift).
        period_start += period_ns;
        let now = hcc_msgs::monotonic_now_ns();
        if now > period_start {
            counts.overruns += 1;
            period_start = now; // resynchronise instead of bursting
        } else {
            sleep_until_ns(period_start);
        }
    };
    drop(rt);

    let r = logic.rejections();
    let stats = hcc_rtalloc::stats();
    println!(
        "hcc-driver-example: {} periods, {} commands applied, {} missed ({} held, {} fallback, {} fallback cycles), \
         rejected: {} old, {} invalid, {} gravity conflict, {} future, {} too late; \
         {} overruns; {} torque writes; stop: {:?}; system allocations in the loop after warm-up: {}",
        counts.periods,
        logic.applied(),
        logic.missed_commands(),
        counts.holds,
        counts.fallbacks,
        logic.fallback_cycles(),
        r.old,
        r.invalid,
        r.gravity_conflict,
        r.future,
        r.too_late,
        counts.overruns,
        hw.writes,
        reason,
        warm.map_or("-".to_string(), |w| (stats.rt_system_allocs
            - w.rt_system_allocs)
            .to_string()),
    );
    Ok(reason)
}
