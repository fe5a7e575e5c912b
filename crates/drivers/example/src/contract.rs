//! The driver side of the hcc-msgs contract, without any transport: which
//! received command may be applied, what to do when none may (hold, then
//! fallback, then stop), and what the published state says about it.
//!
//! Per control period the driver
//! 1. samples the joints and publishes a [`JointState`] filled by
//!    [`DriverLogic::fill_state`] (seq +1, stamp, status, gravity flag,
//!    counters);
//! 2. passes every received [`TorqueCommand`] to [`DriverLogic::offer`], which
//!    checks its sequence number, [`TorqueCommand::validate`], the gravity
//!    agreement ([`check_gravity_agreement`]) and the echo of the state it
//!    answers ([`command_freshness`]: `Current`, or `Late` up to the
//!    configured tolerance; `Future` never);
//! 3. calls [`DriverLogic::decide`] with the newest applicable command, which
//!    yields the torque to write:
//!    - an applicable command in mode Normal, Singular or SafeHold: its τ;
//!    - mode Stop: nothing; the driver stops (status Stopping, then Stopped,
//!      and never resumes);
//!    - no applicable command (a miss): `missed_commands` +1, status
//!      FallbackActive, `fallback_cycles` +1; the last applied τ is held for
//!      `hold_cycles` periods, after that τ = g(q) − D q̇ (g only when the
//!      robot does not compensate gravity itself) — never an extrapolated
//!      controller torque; after `fallback_timeout_cycles` periods in a row in
//!      fallback the driver stops.
//!
//! Everything here is allocation-free and meant for the control loop.

use hcc_msgs::{
    CommandFreshness, CommandMode, DriverStatus, JointState, MAX_JOINTS, MsgError,
    STATE_FLAG_DRIVER_GRAVITY_COMPENSATION, SeqEvent, SequenceChecker, TorqueCommand,
    check_gravity_agreement, command_freshness,
};

/// Settings of the contract logic.
#[derive(Debug, Clone, PartialEq)]
pub struct DriverSettings {
    /// Number of joints n.
    pub n: usize,
    /// Commands answering a state up to this many periods older than the
    /// latest published one are still applied (0: only the current state).
    pub late_tolerance: u64,
    /// Periods the last applied τ is held after a miss before the fallback torque.
    pub hold_cycles: u64,
    /// Periods in a row in fallback after which the driver stops.
    pub fallback_timeout_cycles: u64,
    /// Joint damping D of the fallback torque −D q̇ (first n entries used).
    pub fallback_damping: [f64; MAX_JOINTS],
    /// Whether the robot adds gravity compensation itself.
    pub compensates_gravity: bool,
}

/// Why a received command was not applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rejection {
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
    Rejected(Rejection),
}

/// What the driver does this period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Write the command's τ.
    Apply,
    /// A miss: write the last applied τ again (within `hold_cycles`).
    Hold,
    /// A miss: write the fallback torque g(q) − D q̇.
    Fallback,
    /// Do not write; engage the safe stop (first time: `first` is true).
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
pub struct RejectionCounts {
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
    have_last_tau: bool,
    applied: u64,
    rejections: RejectionCounts,
}

impl DriverLogic {
    /// A driver that has published nothing yet (status Ok).
    pub fn new(settings: DriverSettings) -> DriverLogic {
        DriverLogic {
            settings,
            status: DriverStatus::Ok,
            stop_reason: None,
            next_state_seq: 0,
            commands: SequenceChecker::new(),
            missed_commands: 0,
            fallback_cycles: 0,
            misses_in_a_row: 0,
            last_tau: [0.0; MAX_JOINTS],
            have_last_tau: false,
            applied: 0,
            rejections: RejectionCounts::default(),
        }
    }

    /// Current status.
    pub fn status(&self) -> DriverStatus {
        self.status
    }

    /// Why the driver stopped, once it does.
    pub fn stop_reason(&self) -> Option<StopReason> {
        self.stop_reason
    }

    /// Periods without an applicable command so far.
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

    /// Rejected commands by reason.
    pub fn rejections(&self) -> RejectionCounts {
        self.rejections
    }

    /// Fills the header and driver fields of the next state and the joint
    /// values; returns its sequence number. On error (wrong lengths,
    /// non-finite sensor values) nothing is published and the caller stops.
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
        msg.status = self.status.code();
        msg.flags = if self.settings.compensates_gravity {
            STATE_FLAG_DRIVER_GRAVITY_COMPENSATION
        } else {
            0
        };
        msg.missed_commands = self.missed_commands;
        msg.fallback_cycles = self.fallback_cycles;
        Ok(seq)
    }

    /// Classifies a received command against the latest published state.
    pub fn offer(&mut self, command: &TorqueCommand, latest: &JointState) -> Offer {
        let freshness = command_freshness(command.state_seq, latest.header.seq);
        match self.commands.observe(command.header.seq) {
            SeqEvent::First | SeqEvent::Next | SeqEvent::Gap { .. } => {}
            SeqEvent::Backwards { .. } if freshness == CommandFreshness::Current => {
                // A restarted controller answering our latest state: resynchronise.
                self.commands.reset();
                self.commands.observe(command.header.seq);
            }
            SeqEvent::Duplicate | SeqEvent::Backwards { .. } => {
                self.rejections.old += 1;
                return Offer::Rejected(Rejection::Old);
            }
        }
        if let Err(e) = command.validate(self.settings.n) {
            self.rejections.invalid += 1;
            return Offer::Rejected(Rejection::Invalid(e));
        }
        if let Err(e) = check_gravity_agreement(latest, command) {
            self.rejections.gravity_conflict += 1;
            return Offer::Rejected(Rejection::GravityConflict(e));
        }
        match freshness {
            CommandFreshness::Current => Offer::Applicable { current: true },
            CommandFreshness::Late { cycles } if cycles <= self.settings.late_tolerance => {
                Offer::Applicable { current: false }
            }
            CommandFreshness::Late { cycles } => {
                self.rejections.too_late += 1;
                Offer::Rejected(Rejection::TooLate { cycles })
            }
            CommandFreshness::Future => {
                self.rejections.future += 1;
                Offer::Rejected(Rejection::Future)
            }
        }
    }

    /// Decides this period's torque. `command`: the newest command
    /// [`DriverLogic::offer`] found applicable this period (if any); `qd` and
    /// `gravity` (g(q), ignored when the robot compensates gravity) have length
    /// n; `tau` receives the torque to write for Apply, Hold and Fallback.
    pub fn decide(
        &mut self,
        command: Option<&TorqueCommand>,
        qd: &[f64],
        gravity: &[f64],
        tau: &mut [f64],
    ) -> Action {
        let n = self.settings.n;
        if matches!(self.status, DriverStatus::Stopping | DriverStatus::Stopped) {
            tau.fill(0.0);
            self.status = DriverStatus::Stopped;
            return Action::Stop { first: false };
        }
        if let Some(c) = command {
            if c.mode() == Ok(CommandMode::Stop) {
                tau.fill(0.0);
                return self.begin_stop(StopReason::Commanded);
            }
            tau[..n].copy_from_slice(c.tau());
            self.last_tau[..n].copy_from_slice(c.tau());
            self.have_last_tau = true;
            self.misses_in_a_row = 0;
            self.applied += 1;
            self.status = DriverStatus::Ok;
            return Action::Apply;
        }
        self.missed_commands += 1;
        self.misses_in_a_row += 1;
        if self.misses_in_a_row > self.settings.fallback_timeout_cycles {
            tau.fill(0.0);
            return self.begin_stop(StopReason::FallbackTimeout);
        }
        self.status = DriverStatus::FallbackActive;
        self.fallback_cycles += 1;
        if self.have_last_tau && self.misses_in_a_row <= self.settings.hold_cycles {
            tau[..n].copy_from_slice(&self.last_tau[..n]);
            return Action::Hold;
        }
        for k in 0..n {
            let g = if self.settings.compensates_gravity {
                0.0
            } else {
                gravity[k]
            };
            tau[k] = g - self.settings.fallback_damping[k] * qd[k];
        }
        Action::Fallback
    }

    /// The driver stops on its own (signal, end of the run, hardware fault).
    pub fn request_stop(&mut self) -> Action {
        if matches!(self.status, DriverStatus::Stopping | DriverStatus::Stopped) {
            return Action::Stop { first: false };
        }
        self.begin_stop(StopReason::Requested)
    }

    /// The safe stop has completed: the next state says Stopped.
    pub fn stop_completed(&mut self) {
        if self.status == DriverStatus::Stopping {
            self.status = DriverStatus::Stopped;
        }
    }

    fn begin_stop(&mut self, reason: StopReason) -> Action {
        self.status = DriverStatus::Stopping;
        self.stop_reason = Some(reason);
        Action::Stop { first: true }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hcc_msgs::COMMAND_FLAG_GRAVITY_INCLUDED;

    const N: usize = 2;

    fn settings(compensates_gravity: bool) -> DriverSettings {
        let mut d = [0.0; MAX_JOINTS];
        d[..N].copy_from_slice(&[2.0, 3.0]);
        DriverSettings {
            n: N,
            late_tolerance: 0,
            hold_cycles: 2,
            fallback_timeout_cycles: 5,
            fallback_damping: d,
            compensates_gravity,
        }
    }

    fn publish(logic: &mut DriverLogic) -> JointState {
        let mut s = JointState::zeroed();
        logic
            .fill_state(&mut s, &[0.1, 0.2], &[1.0, -1.0], &[0.0, 0.0], 1000)
            .unwrap();
        s
    }

    fn command(seq: u64, state: &JointState, tau: [f64; N], mode: CommandMode) -> TorqueCommand {
        let mut c = TorqueCommand::zeroed();
        c.set_n_joints(N).unwrap();
        c.header.seq = seq;
        c.answer(state);
        c.mode = mode.code();
        c.flags = if state.driver_compensates_gravity() {
            0
        } else {
            COMMAND_FLAG_GRAVITY_INCLUDED
        };
        c.set_tau(&tau).unwrap();
        c
    }

    #[test]
    fn states_carry_seq_status_flag_and_counters() {
        let mut logic = DriverLogic::new(settings(true));
        let s0 = publish(&mut logic);
        let s1 = publish(&mut logic);
        assert_eq!((s0.header.seq, s1.header.seq), (0, 1));
        assert!(s1.driver_compensates_gravity());
        assert_eq!(s1.status(), Ok(DriverStatus::Ok));
        assert!(s1.validate(N).is_ok());
        let mut logic = DriverLogic::new(settings(false));
        assert!(!publish(&mut logic).driver_compensates_gravity());
        // A non-finite sensor value is refused.
        let mut s = JointState::zeroed();
        assert!(
            logic
                .fill_state(&mut s, &[f64::NAN, 0.0], &[0.0; 2], &[0.0; 2], 0)
                .is_err()
        );
    }

    #[test]
    fn current_command_is_applied_and_echo_is_checked() {
        let mut logic = DriverLogic::new(settings(false));
        let s0 = publish(&mut logic);
        let c = command(0, &s0, [1.0, 2.0], CommandMode::Normal);
        assert_eq!(logic.offer(&c, &s0), Offer::Applicable { current: true });
        let mut tau = [0.0; N];
        assert_eq!(
            logic.decide(Some(&c), &[0.0; N], &[0.0; N], &mut tau),
            Action::Apply
        );
        assert_eq!(tau, [1.0, 2.0]);
        // The same command again is old.
        assert_eq!(logic.offer(&c, &s0), Offer::Rejected(Rejection::Old));
        // A command answering an older state is late (tolerance 0).
        let s1 = publish(&mut logic);
        let late = command(1, &s0, [0.0; N], CommandMode::Normal);
        assert_eq!(
            logic.offer(&late, &s1),
            Offer::Rejected(Rejection::TooLate { cycles: 1 })
        );
        // A command answering a state never published is refused.
        let mut future = command(2, &s1, [0.0; N], CommandMode::Normal);
        future.state_seq = 99;
        assert_eq!(
            logic.offer(&future, &s1),
            Offer::Rejected(Rejection::Future)
        );
        let r = logic.rejections();
        assert_eq!((r.old, r.too_late, r.future), (1, 1, 1));
    }

    #[test]
    fn late_commands_within_the_tolerance_are_applied() {
        let mut s = settings(false);
        s.late_tolerance = 1;
        let mut logic = DriverLogic::new(s);
        let s0 = publish(&mut logic);
        let s1 = publish(&mut logic);
        let c = command(0, &s0, [1.0, 1.0], CommandMode::Normal);
        assert_eq!(logic.offer(&c, &s1), Offer::Applicable { current: false });
    }

    #[test]
    fn invalid_and_gravity_conflicting_commands_are_refused() {
        let mut logic = DriverLogic::new(settings(true));
        let s0 = publish(&mut logic);
        // The driver compensates gravity, but the command includes it.
        let mut c = command(0, &s0, [1.0, 2.0], CommandMode::Normal);
        c.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
        assert!(matches!(
            logic.offer(&c, &s0),
            Offer::Rejected(Rejection::GravityConflict(_))
        ));
        let mut c = command(1, &s0, [1.0, 2.0], CommandMode::Normal);
        c.tau[1] = f64::INFINITY;
        assert!(matches!(
            logic.offer(&c, &s0),
            Offer::Rejected(Rejection::Invalid(_))
        ));
        let mut c = command(2, &s0, [1.0, 2.0], CommandMode::Normal);
        c.mode = 77;
        assert!(matches!(
            logic.offer(&c, &s0),
            Offer::Rejected(Rejection::Invalid(_))
        ));
        let mut c = command(3, &s0, [1.0, 2.0], CommandMode::Normal);
        c.header.n_joints = 3;
        assert!(matches!(
            logic.offer(&c, &s0),
            Offer::Rejected(Rejection::Invalid(_))
        ));
    }

    #[test]
    fn misses_hold_then_fall_back_then_stop() {
        let mut logic = DriverLogic::new(settings(false));
        let s0 = publish(&mut logic);
        let c = command(0, &s0, [5.0, 6.0], CommandMode::Normal);
        let mut tau = [0.0; N];
        let qd = [1.0, -1.0];
        let g = [10.0, 20.0];
        logic.decide(Some(&c), &qd, &g, &mut tau);
        // hold_cycles = 2: the last τ twice.
        for _ in 0..2 {
            assert_eq!(logic.decide(None, &qd, &g, &mut tau), Action::Hold);
            assert_eq!(tau, [5.0, 6.0]);
            assert_eq!(logic.status(), DriverStatus::FallbackActive);
        }
        // Then g − D q̇ (the robot does not compensate gravity).
        assert_eq!(logic.decide(None, &qd, &g, &mut tau), Action::Fallback);
        assert_eq!(tau, [10.0 - 2.0, 20.0 + 3.0]);
        assert_eq!(logic.missed_commands(), 3);
        assert_eq!(logic.fallback_cycles(), 3);
        let s = publish(&mut logic);
        assert_eq!(s.status(), Ok(DriverStatus::FallbackActive));
        assert_eq!((s.missed_commands, s.fallback_cycles), (3, 3));
        // An applicable command ends the fallback.
        let c = command(1, &s, [1.0, 1.0], CommandMode::Singular);
        assert_eq!(logic.offer(&c, &s), Offer::Applicable { current: true });
        assert_eq!(logic.decide(Some(&c), &qd, &g, &mut tau), Action::Apply);
        assert_eq!(logic.status(), DriverStatus::Ok);
        // Timeout (5 periods in a row) stops the driver.
        for _ in 0..5 {
            assert_ne!(
                logic.decide(None, &qd, &g, &mut tau),
                Action::Stop { first: true }
            );
        }
        assert_eq!(
            logic.decide(None, &qd, &g, &mut tau),
            Action::Stop { first: true }
        );
        assert_eq!(logic.stop_reason(), Some(StopReason::FallbackTimeout));
    }

    #[test]
    fn fallback_without_gravity_when_the_robot_compensates_it() {
        let mut s = settings(true);
        s.hold_cycles = 0;
        let mut logic = DriverLogic::new(s);
        let mut tau = [0.0; N];
        assert_eq!(
            logic.decide(None, &[1.0, 1.0], &[10.0, 20.0], &mut tau),
            Action::Fallback
        );
        assert_eq!(tau, [-2.0, -3.0]);
    }

    #[test]
    fn stop_command_stops_for_good() {
        let mut logic = DriverLogic::new(settings(false));
        let s0 = publish(&mut logic);
        let stop = command(0, &s0, [9.0, 9.0], CommandMode::Stop);
        assert_eq!(logic.offer(&stop, &s0), Offer::Applicable { current: true });
        let mut tau = [1.0; N];
        assert_eq!(
            logic.decide(Some(&stop), &[0.0; N], &[0.0; N], &mut tau),
            Action::Stop { first: true }
        );
        assert_eq!(tau, [0.0; N]);
        assert_eq!(logic.stop_reason(), Some(StopReason::Commanded));
        let s1 = publish(&mut logic);
        assert_eq!(s1.status(), Ok(DriverStatus::Stopping));
        logic.stop_completed();
        let s2 = publish(&mut logic);
        assert_eq!(s2.status(), Ok(DriverStatus::Stopped));
        // A later normal command is not applied: no resume within the session.
        let c = command(1, &s2, [1.0, 1.0], CommandMode::Normal);
        logic.offer(&c, &s2);
        assert_eq!(
            logic.decide(Some(&c), &[0.0; N], &[0.0; N], &mut tau),
            Action::Stop { first: false }
        );
        assert_eq!(tau, [0.0; N]);
        assert_eq!(logic.applied(), 0);
    }

    #[test]
    fn restarted_controller_is_resynchronised() {
        let mut logic = DriverLogic::new(settings(false));
        let s0 = publish(&mut logic);
        let c = command(500, &s0, [1.0, 1.0], CommandMode::Normal);
        assert_eq!(logic.offer(&c, &s0), Offer::Applicable { current: true });
        let s1 = publish(&mut logic);
        // The controller restarted: its seq starts again at 0, answering s1.
        let c = command(0, &s1, [1.0, 1.0], CommandMode::Normal);
        assert_eq!(logic.offer(&c, &s1), Offer::Applicable { current: true });
        let c = command(1, &s1, [1.0, 1.0], CommandMode::Normal);
        assert_eq!(logic.offer(&c, &s1), Offer::Applicable { current: true });
    }
}
