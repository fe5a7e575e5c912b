//! One FCI cycle of the driver, and the idle cycle between motions.
//!
//! The robot is the clock: it sends a state every millisecond and expects the
//! torque answering it before the next one. Per cycle ([`FrankaCycle::step`]):
//!
//! 1. read the robot's state ([`TorqueMotion::read_once`]);
//! 2. publish it as a [`JointState`]: q, q̇, the measured joint torques
//!    `tau_J`, the robot's `message_id` as the sequence number (franka-rs
//!    keeps the id as `RobotState::time` in ms, which is how libfranka
//!    derives `time` from it), the driver's status and counters, and
//!    `STATE_FLAG_DRIVER_GRAVITY_COMPENSATION`: the robot adds g(q) itself;
//! 3. wait for the command answering it until the command window closes
//!    (`[franka] command_window_us` after the state was read), offering every
//!    command received to the contract logic ([`DriverLogic::offer`]);
//! 4. decide the torque ([`DriverLogic::decide`]: apply, hold, fall back to
//!    −D q̇, or stop), pass it through the [`TorqueGuard`] and write it in the
//!    same FCI cycle ([`TorqueMotion::write_once`]).
//!
//! A stop (a Stop command, the fallback timeout, a signal) ramps the torque
//! to zero within the rate limit, status `Stopping`, then ends the motion
//! with `motion_finished` ([`TorqueMotion::finish`]): the connection stays
//! open. Nothing here allocates, locks (beyond franka-rs's uncontended
//! mutexes), logs or formats; the system calls are franka-rs's socket calls
//! and iceoryx2's.

use franka::RobotState;
use hcc_msgs::driver::{
    Action, CommandRejectionCounts, DriverLogic, DriverSettings, Gravity, Offer, StopMode,
    StopReason,
};
use hcc_msgs::ipc::{self, DriverPorts, PreLoan};
use hcc_msgs::{
    CommandFreshness, DriverStatus, JointState, MAX_JOINTS, MsgError, TorqueCommand,
    command_freshness, monotonic_now_ns,
};
use hcc_timing::LatencyHistogram;

use crate::guard::{GuardCounts, JOINTS, TorqueGuard};
use crate::motion::TorqueMotion;

/// The driver's policy, from the scenario's `[franka]` table.
#[derive(Debug, Clone, PartialEq)]
pub struct FrankaSettings {
    /// The wait for a state's answer, from the state's read, ns.
    pub window_ns: u64,
    /// Cycles the last torque is held after a miss.
    pub hold_cycles: u64,
    /// Misses in a row after which the driver stops.
    pub fallback_timeout_cycles: u64,
    /// Damping of the fallback torque −D q̇, N·m·s/rad.
    pub fallback_damping: [f64; JOINTS],
    /// The guard's torque limits, N·m.
    pub torque_limits: [f64; JOINTS],
    /// The guard's torque-rate limit, N·m/s.
    pub torque_rate_limit: f64,
}

impl FrankaSettings {
    /// The settings of `[franka]`.
    pub fn from_config(f: &hcc_config::franka::Franka) -> FrankaSettings {
        FrankaSettings {
            window_ns: (f.command_window_us * 1e3).round() as u64,
            hold_cycles: u64::from(f.hold_cycles),
            // One FCI cycle is 1 ms.
            fallback_timeout_cycles: f.fallback_timeout_ms.ceil().max(1.0) as u64,
            fallback_damping: f.fallback_damping,
            torque_limits: f.torque_limits,
            torque_rate_limit: f.torque_rate_limit,
        }
    }

    /// The contract logic's settings: the robot adds gravity, a stop is the
    /// robot's own (ramp, then `motion_finished`), the fallback brakes until
    /// the first command (the controller may come up later) and times out
    /// after misses.
    pub fn driver_settings(&self) -> DriverSettings {
        let mut fallback_damping = [0.0; MAX_JOINTS];
        fallback_damping[..JOINTS].copy_from_slice(&self.fallback_damping);
        DriverSettings {
            n: JOINTS,
            // The answer must come within the cycle of its state.
            late_tolerance: 0,
            check_sequence: true,
            hold_cycles: self.hold_cycles,
            fallback_timeout_cycles: Some(self.fallback_timeout_cycles),
            wait_for_first_command: true,
            fallback_damping,
            gravity: Gravity::RobotAdds,
            stop_mode: StopMode::SafeStop,
        }
    }
}

/// How one cycle ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// A torque was written; the motion goes on.
    Running,
    /// The motion ended cleanly (`motion_finished` sent) after a stop.
    Finished(StopReason),
}

/// Counts of the cycles, by what was written.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CycleCounts {
    /// Torque motions started.
    pub motions: u64,
    /// FCI cycles run in motions.
    pub cycles: u64,
    /// Cycles that applied a command.
    pub applied: u64,
    /// Cycles that held the last torque after a miss.
    pub held: u64,
    /// Cycles in the fallback after misses.
    pub fallback: u64,
    /// Cycles in the fallback before the first command of a motion.
    pub waiting: u64,
    /// Cycles ramping a stop down.
    pub stopping: u64,
    /// Robot states never read (gaps of `message_id`: franka-rs drops all
    /// but the newest queued state when the driver was late).
    pub states_skipped: u64,
    /// States whose values were not finite (not published; the driver stops).
    pub bad_states: u64,
    /// Idle states published between motions.
    pub idle_states: u64,
    /// System allocations in cycles after the warm-up (expected 0).
    pub loop_system_allocs: u64,
    /// The lowest `control_command_success_rate` the robot reported in a
    /// motion, per mille (1000: every command of its last 100 cycles
    /// arrived; the robot aborts below its own threshold).
    pub min_success_permille: u64,
}

/// The cycles' latency histograms, ns.
pub struct CycleTimings {
    /// FCI state read → its `JointState` published.
    pub state_publish: LatencyHistogram,
    /// The answering command received → its torque written.
    pub command_write: LatencyHistogram,
    /// FCI state read → the torque answering it written (the whole path,
    /// controller included).
    pub state_torque: LatencyHistogram,
    /// `JointState` published → its command received: the controller's part.
    pub controller: LatencyHistogram,
    /// The whole path less the controller's part: what the driver adds.
    pub driver_added: LatencyHistogram,
}

impl CycleTimings {
    fn new() -> CycleTimings {
        CycleTimings {
            state_publish: LatencyHistogram::new(),
            command_write: LatencyHistogram::new(),
            state_torque: LatencyHistogram::new(),
            controller: LatencyHistogram::new(),
            driver_added: LatencyHistogram::new(),
        }
    }

    /// (name, histogram) of each, for the `--stats` report.
    pub fn named(&self) -> [(&'static str, &LatencyHistogram); 5] {
        [
            ("state_to_joint_state", &self.state_publish),
            ("command_to_torque", &self.command_write),
            ("state_to_torque", &self.state_torque),
            ("controller_state_to_command", &self.controller),
            ("driver_added", &self.driver_added),
        ]
    }
}

/// Cycles after the start of a motion whose allocations are not counted
/// (the first loans and lazily built state).
const WARM_UP_CYCLES: u64 = 100;

/// The driver's loop state: the contract logic, the guard, the ports and
/// the figures. Every method called per cycle is allocation-free.
pub struct FrankaCycle<'a> {
    settings: FrankaSettings,
    logic: DriverLogic,
    guard: TorqueGuard,
    ports: &'a DriverPorts,
    loan: PreLoan<JointState>,
    state: JointState,
    tau: [f64; JOINTS],
    /// The last `message_id` read (0: none yet).
    last_id: u64,
    /// Cycles of the current motion.
    motion_cycles: u64,
    /// A stop is ramping down.
    stopping: bool,
    counts: CycleCounts,
    rejections: CommandRejectionCounts,
    timings: CycleTimings,
    /// Misses before this motion (the logic counts one motion).
    missed_before: u64,
    fallback_before: u64,
    upkeep: hcc_rt::ConnectionUpkeep,
}

/// When the answer to the current state arrived.
struct Answer {
    command: Option<TorqueCommand>,
    /// Receipt of the first command answering the current state, ns.
    received_ns: Option<u64>,
}

impl<'a> FrankaCycle<'a> {
    /// The loop state on `ports`, ready for a motion.
    pub fn new(settings: FrankaSettings, ports: &'a DriverPorts) -> FrankaCycle<'a> {
        FrankaCycle {
            logic: DriverLogic::new(settings.driver_settings()),
            guard: TorqueGuard::new(settings.torque_limits, settings.torque_rate_limit),
            settings,
            ports,
            loan: PreLoan::new(),
            state: JointState::zeroed(),
            tau: [0.0; JOINTS],
            last_id: 0,
            motion_cycles: 0,
            stopping: false,
            counts: CycleCounts {
                min_success_permille: 1000,
                ..CycleCounts::default()
            },
            rejections: CommandRejectionCounts::default(),
            timings: CycleTimings::new(),
            missed_before: 0,
            fallback_before: 0,
            upkeep: hcc_rt::ConnectionUpkeep::new(),
        }
    }

    /// Starts a new motion: fresh contract logic (waiting for a command,
    /// counters carried on), the guard ramps from zero torque.
    pub fn begin_motion(&mut self) {
        self.missed_before += self.logic.missed_commands();
        self.fallback_before += self.logic.fallback_cycles();
        self.add_rejections();
        self.logic = DriverLogic::new(self.settings.driver_settings());
        self.guard.restart();
        self.stopping = false;
        self.motion_cycles = 0;
        // Gaps before the motion (a recovery, its start) are not states skipped.
        self.last_id = 0;
        self.counts.motions += 1;
    }

    /// The motion ended abnormally (the robot aborted it): status Stopped.
    pub fn abort_motion(&mut self) {
        self.logic.request_stop();
        self.logic.stop_completed();
        self.stopping = false;
    }

    /// The contract logic of the current motion.
    pub fn logic(&self) -> &DriverLogic {
        &self.logic
    }

    /// Commands missed over all motions.
    pub fn missed_commands(&self) -> u64 {
        self.missed_before + self.logic.missed_commands()
    }

    /// Fallback cycles over all motions.
    pub fn fallback_cycles(&self) -> u64 {
        self.fallback_before + self.logic.fallback_cycles()
    }

    /// Rejected commands over all motions.
    pub fn rejections(&self) -> CommandRejectionCounts {
        let r = self.logic.rejections();
        let s = self.rejections;
        CommandRejectionCounts {
            old: s.old + r.old,
            invalid: s.invalid + r.invalid,
            gravity_conflict: s.gravity_conflict + r.gravity_conflict,
            future: s.future + r.future,
            too_late: s.too_late + r.too_late,
        }
    }

    fn add_rejections(&mut self) {
        self.rejections = self.rejections();
    }

    /// The counts.
    pub fn counts(&self) -> CycleCounts {
        self.counts
    }

    /// The guard's counts.
    pub fn guard_counts(&self) -> GuardCounts {
        self.guard.counts()
    }

    /// The latency histograms.
    pub fn timings(&self) -> &CycleTimings {
        &self.timings
    }

    /// The connection upkeep's counts (its allocations are not the loop's).
    pub fn upkeep(&self) -> hcc_rt::UpkeepCounts {
        self.upkeep.counts()
    }

    /// One FCI cycle of a motion (see the module docs). `stop`: the driver
    /// itself stops (a signal). An error is the motion's end by the robot
    /// (a reflex, a lost connection): nothing was written this cycle.
    pub fn step<M: TorqueMotion>(
        &mut self,
        motion: &mut M,
        stop: bool,
    ) -> franka::FrankaResult<Step> {
        let allocs = hcc_rtalloc::thread_stats().system_allocs;
        let robot = motion.read_once()?;
        let read_ns = monotonic_now_ns();
        let published = self.publish(&robot, read_ns);
        let published_ns = monotonic_now_ns();
        if published.is_err() {
            // Non-finite sensor values: nothing to publish, stop.
            self.counts.bad_states += 1;
            if !self.stopping {
                self.logic.request_stop();
                self.stopping = true;
            }
        }
        self.counts.cycles += 1;
        self.motion_cycles += 1;
        let warm = self.motion_cycles > WARM_UP_CYCLES;
        if warm {
            let permille = (robot.control_command_success_rate * 1000.0).round() as u64;
            self.counts.min_success_permille = self.counts.min_success_permille.min(permille);
        }
        let step = if self.stopping {
            self.ramp(motion)?
        } else {
            let answer = self.receive(read_ns + self.settings.window_ns);
            let step = self.act(motion, &robot, answer.command.as_ref(), stop)?;
            self.record(read_ns, published_ns, &answer);
            step
        };
        if warm {
            self.counts.loop_system_allocs += hcc_rtalloc::thread_stats()
                .system_allocs
                .saturating_sub(allocs);
        }
        // Off the path: peers that came or went, the next state's loan.
        self.upkeep.run(&self.ports.connections());
        self.loan.refill(&self.ports.states);
        Ok(step)
    }

    /// Publishes the robot's state; `Err` when its values are not finite.
    fn publish(&mut self, robot: &RobotState, stamp_ns: u64) -> Result<(), MsgError> {
        let id = robot.time.as_millis();
        if self.last_id != 0 && id > self.last_id + 1 {
            self.counts.states_skipped += id - self.last_id - 1;
        }
        self.last_id = id;
        self.logic
            .fill_state(&mut self.state, &robot.q, &robot.dq, &robot.tau_J, stamp_ns)?;
        self.state.header.seq = id;
        let _ = self.loan.send(&self.ports.states, self.state);
        let _ = self.ports.state_ready.notify();
        Ok(())
    }

    /// Waits until `deadline_ns` for the command answering the state just
    /// published; returns the newest applicable one.
    fn receive(&mut self, deadline_ns: u64) -> Answer {
        let latest = self.state.header.seq;
        let mut answer = Answer {
            command: None,
            received_ns: None,
        };
        loop {
            while let Ok(Some(c)) = self.ports.commands.receive() {
                if let Offer::Applicable { current } = self.logic.offer(&c, latest) {
                    answer.command = Some(*c);
                    if current && answer.received_ns.is_none() {
                        answer.received_ns = Some(monotonic_now_ns());
                    }
                }
            }
            if answer.received_ns.is_some() || monotonic_now_ns() >= deadline_ns {
                let _ = self.ports.command_ready.try_wait(|_| {});
                return answer;
            }
            if ipc::wait_for_event_until(&self.ports.command_ready, deadline_ns) {
                let _ = self.ports.command_ready.try_wait(|_| {});
            }
        }
    }

    /// Decides, guards and writes this cycle's torque.
    fn act<M: TorqueMotion>(
        &mut self,
        motion: &mut M,
        robot: &RobotState,
        command: Option<&TorqueCommand>,
        stop: bool,
    ) -> franka::FrankaResult<Step> {
        let action = if stop {
            self.logic.request_stop()
        } else {
            // The robot adds gravity: the fallback torque never needs g(q).
            let no_gravity = |g: &mut [f64]| g.fill(0.0);
            self.logic
                .decide(command, &robot.dq, no_gravity, &mut self.tau)
        };
        match action {
            Action::Stop { .. } => {
                self.stopping = true;
                return self.ramp(motion);
            }
            Action::Apply => self.counts.applied += 1,
            Action::Hold => self.counts.held += 1,
            Action::Fallback => self.counts.fallback += 1,
            Action::Waiting => self.counts.waiting += 1,
        }
        self.guard.apply(&mut self.tau);
        motion.write_once(&self.tau)?;
        Ok(Step::Running)
    }

    /// One cycle of a stop: the torque towards zero within the rate limit,
    /// then `motion_finished` with zero torque.
    fn ramp<M: TorqueMotion>(&mut self, motion: &mut M) -> franka::FrankaResult<Step> {
        self.counts.stopping += 1;
        if self.guard.ramp_down(&mut self.tau) {
            motion.finish(&self.tau)?;
            self.logic.stop_completed();
            self.stopping = false;
            return Ok(Step::Finished(
                self.logic.stop_reason().unwrap_or(StopReason::Requested),
            ));
        }
        motion.write_once(&self.tau)?;
        Ok(Step::Running)
    }

    /// Records the cycle's latencies (the torque was just written).
    fn record(&mut self, read_ns: u64, published_ns: u64, answer: &Answer) {
        let written_ns = monotonic_now_ns();
        let t = &mut self.timings;
        t.state_publish.record(published_ns.saturating_sub(read_ns));
        t.state_torque.record(written_ns.saturating_sub(read_ns));
        if let Some(received) = answer.received_ns {
            let controller = received.saturating_sub(published_ns);
            t.command_write.record(written_ns.saturating_sub(received));
            t.controller.record(controller);
            t.driver_added.record(
                written_ns
                    .saturating_sub(read_ns)
                    .saturating_sub(controller),
            );
        }
    }

    /// Between motions: publishes the robot's current state (status
    /// Stopped) and takes the commands answering it. True when a valid
    /// command answered it: a controller is there to take a new motion.
    pub fn idle_step(&mut self, robot: &RobotState) -> bool {
        self.counts.idle_states += 1;
        if self.publish(robot, monotonic_now_ns()).is_err() {
            self.counts.bad_states += 1;
            return false;
        }
        let latest = self.state.header.seq;
        let mut answered = false;
        while let Ok(Some(c)) = self.ports.commands.receive() {
            // Checked without the logic's sequence check: the idle logic is
            // stopped and keeps no command.
            let fresh = matches!(
                command_freshness(c.state_seq, latest),
                CommandFreshness::Current | CommandFreshness::Late { cycles: 0..=2 }
            );
            answered |= fresh && c.validate(JOINTS).is_ok() && !c.gravity_included();
        }
        let _ = self.ports.command_ready.try_wait(|_| {});
        answered
    }

    /// Whether the current motion's logic is in fallback after misses.
    pub fn in_fallback(&self) -> bool {
        self.logic.in_fallback()
    }

    /// The status the states of the current motion carry.
    pub fn status(&self) -> DriverStatus {
        self.logic.status()
    }
}
