//! The simulator's loop ([`SimLoop`]): the driver, its ports, the newest
//! command, the timing histograms and the counters; paced by an absolute
//! clock (real time) or by the controller's answers (lockstep), module docs
//! of [`crate::daemon`]. Every method called per period is allocation-free.

use std::sync::atomic::Ordering;

use anyhow::Result;
use hcc_config::SimMode;
use hcc_msgs::ipc::{self, PreLoan};
use hcc_msgs::{JointState, STATE_FLAG_DRIVER_POLLS_COMMANDS, TorqueCommand, monotonic_now_ns};
use hcc_plant::{Applied, SimDriver};
use hcc_rt::{self as rt, WaitStrategy};
use hcc_timing::LatencyHistogram;

use crate::recorder_wait::{RecorderWait, RecorderWaitCounts};
use crate::status::LoopStatus;

/// Republish period of the current state while waiting for the first command (lockstep).
const REPUBLISH_NS: u64 = 20_000_000;

/// Real time: part of the period, from the publication of state k, during
/// which the loop waits for the command answering it (then it prepares for
/// the next tick; a command arriving later but before the tick is still
/// applied, and counted as late).
const COMMAND_WINDOW_FRACTION: f64 = 0.8;

/// Hybrid wait: how long the loop polls for the answer before it blocks, ns.
const HYBRID_POLL_NS: u64 = 100_000;

/// The simulator's ports: the driver side of the contract.
pub use hcc_msgs::ipc::DriverPorts as Ports;

/// Counts of the periods by how their torque was chosen.
#[derive(Debug, Default, Clone, Copy)]
struct PeriodCounts {
    periods: u64,
    waiting: u64,
    stopped: u64,
    /// Answers that arrived after the command window but before the tick.
    late: u64,
    /// Missed commands of states that had less than their command window
    /// before the tick: the simulator itself was late (a stall of its core,
    /// then ticks back to back to catch up), so the controller had no chance
    /// to answer in time. Counted in `missed_commands` too.
    short_window_misses: u64,
}

/// The simulator's loop state: the driver, its ports, the newest command,
/// the timing histograms and counters. Every method called per period is
/// allocation-free.
pub struct SimLoop<'a> {
    pub(crate) driver: SimDriver,
    ports: &'a Ports,
    newest: Option<TorqueCommand>,
    state: JointState,
    status: &'a LoopStatus,
    wait: WaitStrategy,
    /// Poll for answers only (`--poll-commands`).
    poll_commands: bool,
    /// Real time: lateness of each tick, ns.
    lateness: LatencyHistogram,
    /// Publication of state k → its answer received here, ns.
    state_to_command: LatencyHistogram,
    /// Answer's stamp − state's stamp (the controller's view), ns.
    answer_stamp: LatencyHistogram,
    /// A state's stamp → its send returned (filling and publishing it; the
    /// driver's part of the state → command latency), ns.
    state_publish: LatencyHistogram,
    /// Publication time of the current state, ns.
    published_ns: u64,
    /// The command window of a state, from its publication, ns
    /// ([`COMMAND_WINDOW_FRACTION`] of the period).
    window_ns: u64,
    /// The answer to the current state was received (and its latency recorded).
    answered: bool,
    /// When the last command was taken from the queue, ns.
    received_ns: u64,
    counts: PeriodCounts,
    overruns: u64,
    /// Connections to peers that appeared or left, made while waiting for
    /// the tick (not by the next state's send).
    upkeep: hcc_rt::ConnectionUpkeep,
    /// The next state's sample, loaned while waiting for the tick.
    state_loan: PreLoan<JointState>,
    /// Lockstep: the recorder the states wait for (`--lockstep-recorder`).
    recorder: Option<RecorderWait>,
}

impl<'a> SimLoop<'a> {
    /// The loop around `driver` on `ports`, reporting to `status`.
    pub fn new(
        driver: SimDriver,
        ports: &'a Ports,
        status: &'a LoopStatus,
        wait: WaitStrategy,
    ) -> Self {
        let period_ns = driver.period_s() * 1e9;
        SimLoop {
            window_ns: (period_ns * COMMAND_WINDOW_FRACTION).round() as u64,
            poll_commands: false,
            driver,
            ports,
            newest: None,
            state: JointState::zeroed(),
            status,
            wait,
            lateness: LatencyHistogram::new(),
            state_to_command: LatencyHistogram::new(),
            answer_stamp: LatencyHistogram::new(),
            state_publish: LatencyHistogram::new(),
            published_ns: 0,
            answered: false,
            received_ns: 0,
            counts: PeriodCounts::default(),
            overruns: 0,
            upkeep: hcc_rt::ConnectionUpkeep::new(),
            state_loan: PreLoan::new(),
            recorder: None,
        }
    }

    /// Lockstep: publishes no state further ahead of `recorder` than its
    /// queues hold (module docs of [`crate::recorder_wait`]).
    pub fn with_recorder(mut self, recorder: Option<RecorderWait>) -> Self {
        self.recorder = recorder;
        self
    }

    /// What the waits for the recorder came to (`None`: none was waited for).
    pub fn recorder_waits(&self) -> Option<RecorderWaitCounts> {
        self.recorder.as_ref().map(RecorderWait::counts)
    }

    /// Waits for answers by polling only and flags the states
    /// `STATE_FLAG_DRIVER_POLLS_COMMANDS` (`--poll-commands`).
    pub fn with_polling(mut self, poll_commands: bool) -> Self {
        self.poll_commands = poll_commands;
        self
    }

    /// The driver.
    pub fn driver(&self) -> &SimDriver {
        &self.driver
    }

    /// Missed commands of states that had less than their command window
    /// before the tick (the simulator's own tick was late; counted in the
    /// driver's `missed_commands` too).
    pub fn short_window_misses(&self) -> u64 {
        self.counts.short_window_misses
    }

    /// Publishes state k (stamped now) and notifies `state_ready`.
    pub fn publish(&mut self) {
        self.published_ns = monotonic_now_ns();
        self.answered = false;
        self.driver.write_state(&mut self.state, self.published_ns);
        if self.poll_commands {
            self.state.flags |= STATE_FLAG_DRIVER_POLLS_COMMANDS;
        }
        let _ = self.state_loan.send(&self.ports.states, self.state);
        self.state_publish
            .record(monotonic_now_ns().saturating_sub(self.published_ns));
        let _ = self.ports.state_ready.notify();
    }

    /// Drains the queue and records the latency of the answer to state k when
    /// it is there for the first time.
    fn take_answer(&mut self) -> bool {
        let got = self.receive_commands();
        if got && !self.answered {
            self.answered = true;
            self.state_to_command
                .record(self.received_ns.saturating_sub(self.published_ns));
        }
        // The notifications are consumed after the receipt time is taken
        // (a polling driver gets none).
        if !self.poll_commands {
            let _ = self.ports.command_ready.try_wait(|_| {});
        }
        got
    }

    /// Real time: waits for the answer to state k until `deadline_ns`.
    pub fn wait_for_answer(&mut self, deadline_ns: u64) {
        if self.poll_commands {
            while monotonic_now_ns() < deadline_ns {
                if self.take_answer() || rt::stop_requested() {
                    return;
                }
                std::hint::spin_loop();
            }
            return;
        }
        if self.wait == WaitStrategy::Hybrid {
            let poll_until = deadline_ns.min(self.published_ns + HYBRID_POLL_NS);
            while monotonic_now_ns() < poll_until {
                if self.take_answer() || rt::stop_requested() {
                    return;
                }
                std::hint::spin_loop();
            }
        }
        loop {
            if self.take_answer() || rt::stop_requested() {
                return;
            }
            let now = monotonic_now_ns();
            if now >= deadline_ns {
                return;
            }
            // Precise to the deadline (Listener::timed_wait is not: see
            // ipc::wait_for_event_until); the event is drained by drain().
            ipc::wait_for_event_until(&self.ports.command_ready, deadline_ns.min(now + 20_000_000));
        }
    }

    /// Takes every queued command into `newest`; true if the newest answers
    /// state k. `received_ns`: when the first of them was taken (before the
    /// queue is drained).
    fn receive_commands(&mut self) -> bool {
        let mut first = true;
        while let Ok(Some(c)) = self.ports.commands.receive() {
            if first {
                self.received_ns = monotonic_now_ns();
                first = false;
            }
            self.newest = Some(*c);
        }
        self.newest
            .is_some_and(|c| c.state_seq == self.driver.k() && c.state_stamp_ns != 0)
    }

    /// [`Self::receive_commands`], then consumes the `command_ready` notifications.
    fn drain(&mut self) -> bool {
        let answered = self.receive_commands();
        let _ = self.ports.command_ready.try_wait(|_| {});
        answered
    }

    fn advance(&mut self) -> Result<()> {
        let answered = self
            .newest
            .filter(|c| c.state_seq == self.driver.k())
            .map(|c| c.header.stamp_ns.saturating_sub(c.state_stamp_ns));
        let applied = self.driver.advance(self.newest.as_ref())?;
        self.counts.periods += 1;
        match applied {
            Applied::WaitingForController => self.counts.waiting += 1,
            Applied::Stopped => self.counts.stopped += 1,
            _ => {}
        }
        if applied == Applied::Command
            && let Some(rtt) = answered
        {
            self.answer_stamp.record(rtt);
        }
        let c = self.driver.counters();
        self.status
            .missed
            .store(c.missed_commands, Ordering::Relaxed);
        self.status
            .fallback_cycles
            .store(c.fallback_cycles, Ordering::Relaxed);
        self.status
            .rejected
            .store(c.rejected_commands, Ordering::Relaxed);
        self.status
            .in_fallback
            .store(self.driver.in_fallback(), Ordering::Relaxed);
        self.status
            .has_command
            .store(self.driver.has_command(), Ordering::Relaxed);
        Ok(())
    }

    /// Real time, at the tick: takes the newest command (an answer that came
    /// after the window counts as late), integrates the period with it (or
    /// holds / falls back) and publishes the next state. False once the
    /// final state has been reached (nothing published then).
    pub fn tick(&mut self) -> Result<bool> {
        let tick_ns = monotonic_now_ns();
        let was_answered = self.answered;
        if self.take_answer() && !was_answered {
            self.counts.late += 1;
        }
        let missed = self.driver.counters().missed_commands;
        self.advance()?;
        if self.driver.counters().missed_commands > missed
            && tick_ns < self.published_ns.saturating_add(self.window_ns)
        {
            self.counts.short_window_misses += 1;
        }
        if self.driver.finished() {
            return Ok(false);
        }
        self.publish();
        Ok(true)
    }

    pub(crate) fn run_realtime(&mut self) -> Result<()> {
        let period_ns = (self.driver.period_s() * 1e9).round() as u64;
        let window_ns = self.window_ns;
        self.publish();
        let mut next = monotonic_now_ns() + period_ns;
        loop {
            self.wait_for_answer((self.published_ns + window_ns).min(next));
            let (ports, upkeep, loan) = (self.ports, &mut self.upkeep, &mut self.state_loan);
            self.wait.sleep_until_with(next, || {
                upkeep.run(&ports.connections());
                // The next state's sample, loaned now rather than on the path.
                loan.refill(&ports.states);
            });
            let now = monotonic_now_ns();
            self.lateness.record(now.saturating_sub(next));
            if rt::stop_requested() {
                break;
            }
            if !self.tick()? {
                break;
            }
            next += period_ns;
            if now > next + 10 * period_ns {
                next = now + period_ns;
                self.overruns += 1;
                self.status.overruns.store(self.overruns, Ordering::Relaxed);
            }
        }
        Ok(())
    }

    pub(crate) fn run_lockstep(&mut self, timeout_ns: u64, max_speed: Option<f64>) -> Result<()> {
        let period_ns = (self.driver.period_s() * 1e9).round() as u64;
        // At most `max_speed` × real time: a state at most every `pace_ns`.
        let pace_ns = max_speed.map_or(0, |x| (period_ns as f64 / x).round() as u64);
        let mut last_publish = 0u64;
        loop {
            if self.driver.finished() {
                break;
            }
            if pace_ns > 0 {
                rt::sleep_until_ns(last_publish.saturating_add(pace_ns));
                last_publish = monotonic_now_ns();
            }
            if let Some(r) = &mut self.recorder {
                r.before_publish(self.driver.k(), timeout_ns);
                if rt::stop_requested() {
                    break;
                }
            }
            self.publish();
            let mut published = monotonic_now_ns();
            let deadline = if !self.driver.has_command() {
                u64::MAX
            } else if self.driver.in_fallback() {
                published + period_ns
            } else {
                published + timeout_ns
            };
            loop {
                if self.drain() || rt::stop_requested() {
                    break;
                }
                let now = monotonic_now_ns();
                if now >= deadline {
                    break;
                }
                if !self.driver.has_command() && now >= published + REPUBLISH_NS {
                    self.publish();
                    published = now;
                }
                let wait = deadline.min(published + REPUBLISH_NS).saturating_sub(now);
                // Precise to the deadline (the event is consumed by drain()).
                ipc::wait_for_event_until(
                    &self.ports.command_ready,
                    now + wait.clamp(1_000, 20_000_000),
                );
            }
            if rt::stop_requested() {
                break;
            }
            self.advance()?;
        }
        Ok(())
    }
}

impl SimLoop<'_> {
    /// Logs the end of the run: counters and the latency summaries.
    pub(crate) fn log_summary(&self, mode: SimMode) {
        let c = self.driver.counters();
        tracing::info!(
            "stopped at t = {:.3} s (k = {}): {} commands applied, {} missed ({} of them after a late tick that left less than the command window), {} fallback cycles, {} rejected, {} overruns",
            self.driver.t(),
            self.driver.k(),
            c.applied_commands,
            c.missed_commands,
            self.counts.short_window_misses,
            c.fallback_cycles,
            c.rejected_commands,
            self.overruns
        );
        let u = self.upkeep.counts();
        tracing::info!(
            "peer connections made or dropped while waiting for the tick: {} (allocations {}, longest {:.1} µs, failures {})",
            u.updates,
            u.allocs,
            u.max_ns as f64 / 1e3,
            u.failures
        );
        if mode == SimMode::Realtime {
            tracing::info!("tick lateness: {}", self.lateness.summary().line_us());
            tracing::info!(
                "state published → command received: {} ({} late)",
                self.state_to_command.summary().line_us(),
                self.counts.late
            );
        }
        tracing::info!(
            "state → command (controller stamp − state stamp): {}",
            self.answer_stamp.summary().line_us()
        );
        if let Some(w) = self.recorder_waits() {
            tracing::info!(
                "states that waited for the recorder: {} (longest {:.1} ms)",
                w.waits,
                w.longest_ns as f64 / 1e6
            );
            if w.abandoned {
                tracing::warn!(
                    "the recorder made no progress for the lockstep timeout and was no longer waited for: the recording may lack samples (counted as gaps)"
                );
            }
        }
    }

    /// The timing report of the run (`--stats`).
    pub(crate) fn timings(
        &self,
        wait: WaitStrategy,
        rt: hcc_timing::RtObtained,
        run_s: f64,
    ) -> hcc_timing::DaemonTimings {
        let c = self.driver.counters();
        let period_ns = self.driver.period_s() * 1e9;
        let mut stats = hcc_timing::DaemonTimings {
            daemon: "hcc-sim".into(),
            wait: wait.name().into(),
            rt,
            run_s,
            ..Default::default()
        };
        for (name, h) in [
            ("tick_lateness", &self.lateness),
            ("state_to_command", &self.state_to_command),
            ("answer_stamp_latency", &self.answer_stamp),
            ("state_publish", &self.state_publish),
        ] {
            stats.figures.insert(name.into(), h.into());
        }
        for (name, value) in [
            ("periods", self.counts.periods),
            ("waiting_for_controller", self.counts.waiting),
            ("stopped_periods", self.counts.stopped),
            ("applied_commands", c.applied_commands),
            ("missed_commands", c.missed_commands),
            ("fallback_cycles", c.fallback_cycles),
            ("rejected_commands", c.rejected_commands),
            ("late_commands", self.counts.late),
            ("short_window_misses", self.counts.short_window_misses),
            (
                "ticks_late",
                self.lateness
                    .count_above((period_ns * COMMAND_WINDOW_FRACTION) as u64),
            ),
            ("overruns", self.overruns),
            (
                "states_in_preloaned_samples",
                self.state_loan.preloaned_sends(),
            ),
            ("state_preloan_failures", self.state_loan.loan_failures()),
        ] {
            stats.counters.insert(name.into(), value);
        }
        stats
    }
}
