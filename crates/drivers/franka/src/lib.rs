//! # hcc-franka — the hcc driver of Franka FR3 and Panda arms
//!
//! `hcc-franka CONFIG --robot-ip IP` speaks the Franka Control Interface
//! (FCI) to the robot's control box through franka-rs (pure Rust, no
//! libfranka; FR3 = FCI protocol 10, Panda/FER = protocol 5, chosen at
//! connect) and the hcc message contract (`hcc-msgs`) to the controller. It
//! takes the place of `hcc-sim`: one [`hcc_msgs::JointState`] per FCI state,
//! the controller's [`hcc_msgs::TorqueCommand`] answering it written as
//! `tau_J_d` in the same FCI cycle ([`cycle`]).
//!
//! * **Gravity.** The robot adds g(q) to every commanded torque; the driver
//!   says so in every state (`STATE_FLAG_DRIVER_GRAVITY_COMPENSATION`), the
//!   scenario sets `[robot] gravity_compensation = false`, and the contract's
//!   gravity agreement refuses a command that includes g.
//! * **Misses.** hold → fallback (−D q̇) → stop, the contract's
//!   [`hcc_msgs::driver::DriverLogic`]; a stop ramps the torque to zero and
//!   ends the motion with `motion_finished`, never by dropping the
//!   connection.
//! * **The robot's refusals, refused first** ([`guard`]): non-finite torques,
//!   torques above the limits, steps above 1 N·m per cycle.
//! * **Errors and reflexes** ([`faults`]): logged with the robot's own error
//!   names and counted; `--recover` runs `automatic_error_recovery`, waits for
//!   a controller and starts a new motion.
//!
//! ## franka-rs 0.4.0: what the driver works around
//!
//! * `RobotState` has no `message_id`. franka-rs sets `RobotState::time` to
//!   `message_id` milliseconds (as libfranka does), so the driver takes the
//!   id from `time.as_millis()` as the state's sequence number.
//! * Its `ActiveTorqueControl` is a concrete, `!Send` type with no way to
//!   inject I/O. The cycle is written against the small trait
//!   [`motion::TorqueMotion`], implemented for it, so that the loop body is
//!   tested (and its allocations counted) against a fake motion.
//! * It applies no rate limit in `ActiveTorqueControl::write_once` (like
//!   libfranka). The driver's [`guard`] uses franka-rs's own port of
//!   libfranka's `limitRate` ([`franka::limit_rate_torques`]) on every torque.
//! * `Robot::new` raises the calling thread to the highest `SCHED_FIFO`
//!   priority when it may, also with `RealtimeConfig::Ignore` (only the
//!   failure is ignored then), so the driver connects from the thread that
//!   runs the loop.
//! * `Robot::set_collision_behavior` is answered, not applied, by the
//!   franka-sim test server (it has no collision model); on a robot it acts.

pub mod cycle;
pub mod faults;
pub mod guard;
pub mod motion;
