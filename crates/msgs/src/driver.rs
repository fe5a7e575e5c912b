//! The driver side of the contract, once, without any transport: which
//! received command may be applied, what to do when none may (hold, then
//! fallback, then stop), and what the published state says about it. The
//! simulated robot of the `hcc-sim` daemon and the example real-robot driver
//! both run this logic; their different policies are [`DriverSettings`].
//!
//! Per control period the driver
//! 1. samples the joints and publishes a [`JointState`] whose driver fields
//!    (status, gravity flag, counters) [`DriverLogic::write_status`] fills
//!    ([`DriverLogic::fill_state`] also numbers it and sets the joints);
//! 2. passes received [`TorqueCommand`]s to [`DriverLogic::offer`], which
//!    checks the command's sequence number (if [`DriverSettings::check_sequence`]),
//!    [`TorqueCommand::validate`], the gravity agreement
//!    ([`gravity_agreement`]) and the echo of the state it answers
//!    ([`command_freshness`]: `Current`, or `Late` up to
//!    [`DriverSettings::late_tolerance`]; `Future` never);
//! 3. calls [`DriverLogic::decide`] with the newest applicable command, which
//!    yields the torque to write:
//!    - an applicable command in mode Normal, Singular or SafeHold: its τ
//!      (plus g(q) when the driver adds gravity itself, [`Gravity::DriverAdds`]);
//!    - mode Stop: the driver stops for the session ([`StopMode`]);
//!    - no applicable command (a miss): `missed_commands` +1, status
//!      FallbackActive, `fallback_cycles` +1; the last applied τ is held for
//!      `hold_cycles` periods, after that the fallback τ = g(q) − D q̇ (g only
//!      when the actuators do not add it themselves) — never an extrapolated
//!      controller torque; after `fallback_timeout_cycles` periods in a row
//!      in fallback (if set) the driver stops;
//!    - before the first command, with [`DriverSettings::wait_for_first_command`]:
//!      the fallback torque, counted in `fallback_cycles` but not as a miss
//!      (the controller is not up yet; status FallbackActive from the start).
//!
//! Everything here is allocation-free and meant for the control loop.

use crate::{
    CommandFreshness, CommandMode, DriverStatus, JointState, MAX_JOINTS, MsgError,
    STATE_FLAG_DRIVER_GRAVITY_COMPENSATION, SeqEvent, SequenceChecker, TorqueCommand,
    command_freshness, gravity_agreement,
};

/// Who adds the gravity torque g(q) of the control law (paper Eq. (19)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Gravity {
    /// The controller sends it: commands include g(q), the state flag is
    /// clear, and the fallback torque includes g(q).
    ControllerSends,
    /// The robot's torque interface adds it (many commercial arms): the
    /// state says so ([`STATE_FLAG_DRIVER_GRAVITY_COMPENSATION`]), commands
    /// and the fallback torque do not include it.
    RobotAdds,
    /// The driver adds it in software before writing to actuators that do not
    /// (a simulated plant): the state says the driver compensates gravity,
    /// commands do not include it, and the driver writes τ + g(q); the
    /// fallback torque includes g(q).
    DriverAdds,
}

impl Gravity {
    /// Whether the driver side compensates gravity (the state flag).
    pub fn driver_compensates(self) -> bool {
        self != Gravity::ControllerSends
    }

    /// Whether the written torque must include g(q).
    fn written_includes_gravity(self) -> bool {
        self != Gravity::RobotAdds
    }
}

/// What a stop (a Stop command, the fallback timeout, [`DriverLogic::request_stop`]) does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopMode {
    /// The robot's own safe stop (brakes, stop category): status Stopping
    /// until [`DriverLogic::stop_completed`], then Stopped; no torque is
    /// written ([`Action::Stop`] with τ = 0).
    SafeStop,
    /// A robot without brakes of its own (a simulated plant): status Stopped
    /// at once, and the fallback torque brakes it from then on
    /// ([`Action::Stop`] with τ = the fallback torque, counted in `fallback_cycles`).
    Brake,
}

/// Settings of the contract logic.
#[derive(Debug, Clone, PartialEq)]
pub struct DriverSettings {
    /// Number of joints n.
    pub n: usize,
    /// Commands answering a state up to this many periods older than the
    /// latest published one are still applied (0: only the current state).
    pub late_tolerance: u64,
    /// Reject commands whose sequence number repeats or goes back (a
    /// restarted controller answering the latest state is resynchronised).
    /// Off for a driver that offers the newest received command again each
    /// period.
    pub check_sequence: bool,
    /// Periods the last applied τ is held after a miss before the fallback torque.
    pub hold_cycles: u64,
    /// Periods in a row in fallback after which the driver stops (`None`: never).
    pub fallback_timeout_cycles: Option<u64>,
    /// Before the first applied command, brake with the fallback torque
    /// without counting misses (and without the timeout).
    pub wait_for_first_command: bool,
    /// Joint damping D of the fallback torque −D q̇ (first n entries used).
    pub fallback_damping: [f64; MAX_JOINTS],
    /// Who adds gravity.
    pub gravity: Gravity,
    /// What a stop does.
    pub stop_mode: StopMode,
}

/// Why a received command was not applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CommandRejection {
    /// Its sequence number repeats or goes back (already seen).
    Old,
    /// It fails validation (schema, joint count, unknown mode/flags, non-finite τ).
    Invalid(MsgError),
    /// Its gravity flag disagrees with the driver's gravity handling.
    GravityConflict(MsgError),
    /// It answers a state that was never published.
    Future,
    /// It answers a state older than the tolerance allows.
    TooLate { cycles: u64 },
}

/// What [`DriverLogic::offer`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Offer {
    /// Applicable; `current`: it answers the latest published state.
    Applicable { current: bool },
    /// Not applicable.
    Rejected(CommandRejection),
}

/// What the driver does this period; `tau` of [`DriverLogic::decide`] holds
/// the torque to write unless said otherwise.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Write the command's τ.
    Apply,
    /// A miss: write the last applied τ again (within `hold_cycles`).
    Hold,
    /// A miss: write the fallback torque g(q) − D q̇.
    Fallback,
    /// No command yet ([`DriverSettings::wait_for_first_command`]): write the
    /// fallback torque; not a miss.
    Waiting,
    /// Stopped (`first`: the stop began this period). [`StopMode::SafeStop`]:
    /// write nothing (τ = 0) and engage the robot's safe stop when `first`;
    /// [`StopMode::Brake`]: write the fallback torque.
    Stop { first: bool },
}

/// Why the driver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The controller sent a command in mode Stop.
    Commanded,
    /// No applicable command for `fallback_timeout_cycles` periods.
    FallbackTimeout,
    /// The driver itself was asked to stop (signal, end of run, fault).
    Requested,
}

/// Counters of rejected commands, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CommandRejectionCounts {
    pub old: u64,
    pub invalid: u64,
    pub gravity_conflict: u64,
    pub future: u64,
    pub too_late: u64,
}

/// State of the driver's contract logic.
#[derive(Debug, Clone)]
pub struct DriverLogic {
    settings: DriverSettings,
    status: DriverStatus,
    stop_reason: Option<StopReason>,
    next_state_seq: u64,
    commands: SequenceChecker,
    missed_commands: u64,
    fallback_cycles: u64,
    misses_in_a_row: u64,
    last_tau: [f64; MAX_JOINTS],
    gravity: [f64; MAX_JOINTS],
    have_last_tau: bool,
    applied: u64,
    rejections: CommandRejectionCounts,
}

impl DriverLogic {
    /// A driver that has published nothing yet: status Ok, or FallbackActive
    /// when it waits for the first command.
    pub fn new(settings: DriverSettings) -> DriverLogic {
        DriverLogic {
            status: if settings.wait_for_first_command {
                DriverStatus::FallbackActive
            } else {
                DriverStatus::Ok
            },
            settings,
            stop_reason: None,
            next_state_seq: 0,
            commands: SequenceChecker::new(),
            missed_commands: 0,
            fallback_cycles: 0,
            misses_in_a_row: 0,
            last_tau: [0.0; MAX_JOINTS],
            gravity: [0.0; MAX_JOINTS],
            have_last_tau: false,
            applied: 0,
            rejections: CommandRejectionCounts::default(),
        }
    }

    /// The settings.
    pub fn settings(&self) -> &DriverSettings {
        &self.settings
    }

    /// Current status.
    pub fn status(&self) -> DriverStatus {
        self.status
    }

    /// Why the driver stopped, once it does.
    pub fn stop_reason(&self) -> Option<StopReason> {
        self.stop_reason
    }

    /// Periods without an applicable command so far (after the first command
    /// when waiting for it).
    pub fn missed_commands(&self) -> u64 {
        self.missed_commands
    }

    /// Periods spent in fallback so far.
    pub fn fallback_cycles(&self) -> u64 {
        self.fallback_cycles
    }

    /// Commands applied so far.
    pub fn applied(&self) -> u64 {
        self.applied
    }

    /// Whether a command was ever applied.
    pub fn has_command(&self) -> bool {
        self.have_last_tau
    }

    /// Whether the driver is in the fallback after misses (not while waiting
    /// for the first command, not stopped).
    pub fn in_fallback(&self) -> bool {
        self.have_last_tau && self.status == DriverStatus::FallbackActive
    }

    /// Rejected commands by reason.
    pub fn rejections(&self) -> CommandRejectionCounts {
        self.rejections
    }

    /// The state flags the driver publishes (the gravity flag).
    pub fn state_flags(&self) -> u32 {
        if self.settings.gravity.driver_compensates() {
            STATE_FLAG_DRIVER_GRAVITY_COMPENSATION
        } else {
            0
        }
    }

    /// Writes the driver fields of a state: status, flags, `missed_commands`,
    /// `fallback_cycles`.
    pub fn write_status(&self, msg: &mut JointState) {
        msg.status = self.status.code();
        msg.flags = self.state_flags();
        msg.missed_commands = self.missed_commands;
        msg.fallback_cycles = self.fallback_cycles;
    }

    /// Fills the header and driver fields of the next state and the joint
    /// values; returns its sequence number (0, 1, 2, …). On error (wrong
    /// lengths, non-finite sensor values) nothing is published and the caller stops.
    pub fn fill_state(
        &mut self,
        msg: &mut JointState,
        q: &[f64],
        qd: &[f64],
        tau_measured: &[f64],
        stamp_ns: u64,
    ) -> Result<u64, MsgError> {
        msg.set_joints(q, qd, tau_measured)?;
        let seq = self.next_state_seq;
        self.next_state_seq += 1;
        msg.header.seq = seq;
        msg.header.stamp_ns = stamp_ns;
        self.write_status(msg);
        Ok(seq)
    }

    /// Classifies a received command against the latest published state
    /// (sequence number `latest_seq`).
    pub fn offer(&mut self, command: &TorqueCommand, latest_seq: u64) -> Offer {
        let freshness = command_freshness(command.state_seq, latest_seq);
        if self.settings.check_sequence && self.is_old(command.header.seq, freshness) {
            self.rejections.old += 1;
            return Offer::Rejected(CommandRejection::Old);
        }
        if let Err(e) = command.validate(self.settings.n) {
            self.rejections.invalid += 1;
            return Offer::Rejected(CommandRejection::Invalid(e));
        }
        let compensates = self.settings.gravity.driver_compensates();
        if let Err(e) = gravity_agreement(compensates, command.gravity_included()) {
            self.rejections.gravity_conflict += 1;
            return Offer::Rejected(CommandRejection::GravityConflict(e));
        }
        match freshness {
            CommandFreshness::Current => Offer::Applicable { current: true },
            CommandFreshness::Late { cycles } if cycles <= self.settings.late_tolerance => {
                Offer::Applicable { current: false }
            }
            CommandFreshness::Late { cycles } => {
                self.rejections.too_late += 1;
                Offer::Rejected(CommandRejection::TooLate { cycles })
            }
            CommandFreshness::Future => {
                self.rejections.future += 1;
                Offer::Rejected(CommandRejection::Future)
            }
        }
    }

    /// Whether the command sequence number `seq` was seen already.
    fn is_old(&mut self, seq: u64, freshness: CommandFreshness) -> bool {
        match self.commands.observe(seq) {
            SeqEvent::First | SeqEvent::Next | SeqEvent::Gap { .. } => false,
            SeqEvent::Backwards { .. } if freshness == CommandFreshness::Current => {
                // A restarted controller answering our latest state: resynchronise.
                self.commands.reset();
                self.commands.observe(seq);
                false
            }
            SeqEvent::Duplicate | SeqEvent::Backwards { .. } => true,
        }
    }

    /// Decides this period's torque. `command`: the newest command
    /// [`DriverLogic::offer`] found applicable this period (if any); `qd` has
    /// length n; `gravity` writes g(q) into the slice it is given (length n)
    /// and is called at most once, only when the torque needs it; `tau`
    /// (length n) receives the torque to write (see [`Action`]).
    pub fn decide<G: FnOnce(&mut [f64])>(
        &mut self,
        command: Option<&TorqueCommand>,
        qd: &[f64],
        gravity: G,
        tau: &mut [f64],
    ) -> Action {
        let n = self.settings.n;
        if matches!(self.status, DriverStatus::Stopping | DriverStatus::Stopped) {
            if self.settings.stop_mode == StopMode::SafeStop {
                self.status = DriverStatus::Stopped;
            }
            return self.stopped(false, qd, gravity, tau);
        }
        if let Some(c) = command {
            if c.mode() == Ok(CommandMode::Stop) {
                self.begin_stop(StopReason::Commanded);
                return self.stopped(true, qd, gravity, tau);
            }
            tau[..n].copy_from_slice(c.tau());
            if self.settings.gravity == Gravity::DriverAdds {
                gravity(&mut self.gravity[..n]);
                for (t, g) in tau[..n].iter_mut().zip(&self.gravity[..n]) {
                    *t += g;
                }
            }
            self.last_tau[..n].copy_from_slice(&tau[..n]);
            self.have_last_tau = true;
            self.misses_in_a_row = 0;
            self.applied += 1;
            self.status = DriverStatus::Ok;
            return Action::Apply;
        }
        if self.settings.wait_for_first_command && !self.have_last_tau {
            self.fallback_cycles += 1;
            self.fallback_torque(qd, gravity, tau);
            return Action::Waiting;
        }
        self.missed_commands += 1;
        self.misses_in_a_row += 1;
        if self
            .settings
            .fallback_timeout_cycles
            .is_some_and(|t| self.misses_in_a_row > t)
        {
            self.begin_stop(StopReason::FallbackTimeout);
            return self.stopped(true, qd, gravity, tau);
        }
        self.status = DriverStatus::FallbackActive;
        self.fallback_cycles += 1;
        if self.have_last_tau && self.misses_in_a_row <= self.settings.hold_cycles {
            tau[..n].copy_from_slice(&self.last_tau[..n]);
            return Action::Hold;
        }
        self.fallback_torque(qd, gravity, tau);
        Action::Fallback
    }

    /// The driver stops on its own (signal, end of the run, hardware fault).
    pub fn request_stop(&mut self) -> Action {
        if matches!(self.status, DriverStatus::Stopping | DriverStatus::Stopped) {
            return Action::Stop { first: false };
        }
        self.begin_stop(StopReason::Requested);
        Action::Stop { first: true }
    }

    /// The safe stop has completed: the next state says Stopped.
    pub fn stop_completed(&mut self) {
        if self.status == DriverStatus::Stopping {
            self.status = DriverStatus::Stopped;
        }
    }

    fn begin_stop(&mut self, reason: StopReason) {
        self.status = match self.settings.stop_mode {
            StopMode::SafeStop => DriverStatus::Stopping,
            StopMode::Brake => DriverStatus::Stopped,
        };
        self.stop_reason = Some(reason);
    }

    /// The torque of a stopped period ([`Action::Stop`]).
    fn stopped<G: FnOnce(&mut [f64])>(
        &mut self,
        first: bool,
        qd: &[f64],
        gravity: G,
        tau: &mut [f64],
    ) -> Action {
        match self.settings.stop_mode {
            StopMode::SafeStop => tau.fill(0.0),
            StopMode::Brake => {
                self.fallback_cycles += 1;
                self.fallback_torque(qd, gravity, tau);
            }
        }
        Action::Stop { first }
    }

    /// τ = g(q) − D q̇, without g when the actuators add it themselves.
    fn fallback_torque<G: FnOnce(&mut [f64])>(&mut self, qd: &[f64], gravity: G, tau: &mut [f64]) {
        let n = self.settings.n;
        if self.settings.gravity.written_includes_gravity() {
            gravity(&mut self.gravity[..n]);
        } else {
            self.gravity[..n].fill(0.0);
        }
        for k in 0..n {
            tau[k] = self.gravity[k] - self.settings.fallback_damping[k] * qd[k];
        }
    }
}

#[cfg(test)]
mod tests;
