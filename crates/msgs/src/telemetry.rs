//! The client-facing telemetry: [`Telemetry`] (the law's terms, goals and
//! gains, answers, the storage H and the energy tanks of one controller
//! cycle) with its [`TelemetryCounters`], [`TelemetryTimings`] and
//! [`SetpointAnswer`]s, and the `TELEMETRY_FLAG_*` bits. Same rules as the
//! driver-facing types (`types.rs`): `#[repr(C)]`, `Copy`, no pointers,
//! `ZeroCopySend`, the client schema's version in every type name.

use iceoryx2::prelude::ZeroCopySend;

use crate::error::MsgError;
use crate::{CommandMode, Header, MAX_JOINTS, MAX_LEVELS, MAX_TASK_DIM, SchemaPart};

/// Name of [`Telemetry`] in error messages.
pub const TELEMETRY: &str = "telemetry";

/// [`Telemetry::flags`] bit: no joint state arrived within the controller's
/// stale timeout, the driver is considered lost and this sample answers no
/// state (no command was sent; `state_seq`, `command_seq`, `mode` and the
/// diagnostics are those of the last answer, the counters are current). Set
/// in every sample until states come back. Never set in a command.
pub const TELEMETRY_FLAG_PEER_LOST: u32 = 1 << 16;
/// [`Telemetry::flags`] bit: the controller's contact detection flags a
/// contact — some |[`Telemetry::tau_ext`]_j| rose above its threshold and
/// not every one has fallen below its release level since (hcc-control's
/// `contact` module). Never set in a command.
pub const TELEMETRY_FLAG_CONTACT: u32 = 1 << 17;
/// [`Telemetry::flags`] bit: the contact reaction `hold` is latched — the
/// controller commands gravity and a joint damper, not the law, until a
/// client's accepted setpoint releases it (hcc-cycle's `reaction` module).
/// Never set in a command.
pub const TELEMETRY_FLAG_CONTACT_HOLD: u32 = 1 << 18;

/// Defines a set of `u64` event counters once: the struct (each field
/// `pub NAME: u64`, in the order written, with the attributes given) and, on
/// it, `COUNT`, `NAMES` (the field names), `LABELS` (a short description
/// each, for logs), `ZERO`, `values`, `from_values` and `entries`, all in
/// field order. Adding a counter is one line here; every list of counters
/// (logs, reports, shared atomics) follows.
///
/// ```
/// hcc_msgs::define_counters! {
///     /// Two counters.
///     #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
///     pub struct Pair {
///         /// Things seen.
///         seen: "things seen",
///         /// Things lost.
///         lost: "things lost",
///     }
/// }
/// let p = Pair { seen: 3, lost: 1 };
/// assert_eq!(Pair::NAMES, ["seen", "lost"]);
/// assert_eq!(p.entries(), [("seen", 3), ("lost", 1)]);
/// assert_eq!(Pair::from_values(p.values()), p);
/// ```
#[macro_export]
macro_rules! define_counters {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $( $(#[doc = $doc:literal])* $field:ident : $label:literal ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis struct $name {
            $( $(#[doc = $doc])* pub $field: u64, )+
        }

        impl $name {
            /// Number of counters.
            pub const COUNT: usize = [$(stringify!($field)),+].len();
            /// The counters' names (the field names), in field order.
            pub const NAMES: [&'static str; Self::COUNT] = [$(stringify!($field)),+];
            /// A short description of each counter, in field order.
            pub const LABELS: [&'static str; Self::COUNT] = [$($label),+];
            /// All counters zero.
            pub const ZERO: Self = Self { $($field: 0),+ };

            /// The values, in field order.
            pub const fn values(&self) -> [u64; Self::COUNT] {
                [$(self.$field),+]
            }

            /// The counters from their values in field order.
            pub const fn from_values(values: [u64; Self::COUNT]) -> Self {
                let [$($field),+] = values;
                Self { $($field),+ }
            }

            /// (name, value) of every counter, in field order.
            pub const fn entries(&self) -> [(&'static str, u64); Self::COUNT] {
                [$((stringify!($field), self.$field)),+]
            }
        }
    };
}

define_counters! {
    /// Per-cycle event counters of the controller (totals since start).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
    #[type_name("hcc_msgs::TelemetryCounters@client8")]
    #[repr(C)]
    pub struct TelemetryCounters {
        /// Control cycles run.
        cycles: "cycles",
        /// States rejected by validation (answered with SafeHold).
        invalid_states: "invalid states (answered with SafeHold)",
        /// Cycles in which at least one torque was saturated.
        saturations: "saturated cycles",
        /// Cycles in which a level was flagged singular.
        singular_cycles: "singular cycles",
        /// Wake-ups without a new state within the stale timeout.
        stale_events: "stale timeouts",
        /// Times the peer (driver) was detected dead/gone.
        peer_lost_events: "peer losses",
        /// States missed according to the sequence checker (sum of gaps).
        missed_states: "missed states",
        /// Duplicate or backwards state sequence numbers.
        sequence_errors: "sequence errors",
        /// Commands that could not be sent (loan/send failure).
        send_failures: "send failures",
        /// Cycles whose torque change was limited by the torque-rate limit.
        rate_limited: "rate-limited cycles",
        /// Cycles whose torque went through the output low-pass filter.
        low_passed: "low-pass filtered cycles",
        /// Cycles whose torque the discrete-time velocity limit corrected
        /// (hcc-cycle's `velocity_limit`: the one-period limit, or the brake
        /// certificate behind a torque-rate limit). Client schema 5.
        velocity_limited: "cycles corrected by the velocity limit",
        /// Of those, the cycles in which no brake was certified and the
        /// brake that goes least far past the bound was sent. Client schema 5.
        velocity_limit_fallbacks: "velocity-limit fall-backs",
        /// The largest correction the velocity limit made so far (the largest
        /// |Δτ_k|), mN·m; a maximum, not a total. Client schema 5.
        velocity_limit_max_correction_mnm: "largest velocity-limit correction (mN·m)",
    }
}

/// Timing of one controller cycle, in ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("hcc_msgs::TelemetryTimings@client8")]
#[repr(C)]
pub struct TelemetryTimings {
    /// Wake-up latency: wake time minus the state's `stamp_ns` (can be negative
    /// only with broken clocks).
    pub wakeup_latency_ns: i64,
    /// Time to compute τ (read state → command sent).
    pub compute_ns: u64,
    /// Time since the previous cycle's wake-up.
    pub period_ns: u64,
    /// Worst `compute_ns` seen so far.
    pub max_compute_ns: u64,
}

/// Clients whose last answer [`Telemetry`] carries (the most recent ones;
/// the slot of the client heard from longest ago is reused).
pub const MAX_SETPOINT_CLIENTS: usize = 8;

/// [`SetpointAnswer::knot`] of an answer about no single knot.
pub const NO_KNOT: u32 = u32::MAX;

/// The controller's answer to the last setpoint (or path message) of one
/// client.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("hcc_msgs::SetpointAnswer@client8")]
#[repr(C)]
pub struct SetpointAnswer {
    /// The client's `Setpoint::client_id`.
    pub client_id: u64,
    /// `header.seq` of the client's last setpoint.
    pub seq: u64,
    /// Setpoints answered for this client so far (0: an empty slot).
    pub answered: u64,
    /// [`crate::ANSWER_ACCEPTED`] or a [`crate::SetpointRejection`] code.
    pub code: u32,
    /// The level it addressed (as sent).
    pub level: u32,
    /// The transition duration in force for it, in s (stretched to the
    /// level's speed limit if needed; 0 when rejected).
    pub duration_s: f64,
    /// Setpoints of this client rejected so far (of `answered`).
    pub rejected: u32,
    /// Setpoints of this client applied late so far: they arrived after the
    /// state of their [`crate::Setpoint::apply_at_state_seq`].
    pub late: u32,
    /// The knot a refused [`crate::PathKnots`] message was refused for,
    /// 0-based in the message; [`NO_KNOT`] when the answer is about no
    /// single knot (accepted, a setpoint, or the message as a whole). Client
    /// schema 7.
    pub knot: u32,
    /// Zero (the slot stays a multiple of 8 bytes).
    pub reserved: u32,
}

impl SetpointAnswer {
    /// An empty slot.
    pub const EMPTY: SetpointAnswer = SetpointAnswer {
        client_id: 0,
        seq: 0,
        answered: 0,
        code: 0,
        level: 0,
        duration_s: 0.0,
        rejected: 0,
        late: 0,
        knot: NO_KNOT,
        reserved: 0,
    };

    /// The refused knot, if the answer names one.
    pub fn refused_knot(&self) -> Option<usize> {
        (self.knot != NO_KNOT).then_some(self.knot as usize)
    }
}

impl Default for SetpointAnswer {
    fn default() -> Self {
        Self::EMPTY
    }
}

/// Per-cycle diagnostics of the controller, published at the control rate.
///
/// Paper quantities: τ_i per level (Eqs. (20), (21)), τ_μ (Eq. (22)), g and
/// the total τ (Eq. (19)), task errors x̃_i, storage functions S_i (Eqs. (26),
/// (28)), P_μ = τ_μᵀ q̇ (zero in theory, Sec. IV-C).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("hcc_msgs::Telemetry@client8")]
#[repr(C)]
pub struct Telemetry {
    /// `seq`: controller cycle counter; `stamp_ns`: publication time; `n_joints`: n.
    pub header: Header,
    /// `seq` of the state this cycle consumed.
    pub state_seq: u64,
    /// `seq` of the command this cycle sent.
    pub command_seq: u64,
    /// [`CommandMode`] code of that command.
    pub mode: u32,
    /// Number of hierarchy levels r (≤ [`MAX_LEVELS`]).
    pub n_levels: u32,
    /// Task dimension m_i of each level (≤ [`MAX_TASK_DIM`]).
    pub task_dims: [u32; MAX_LEVELS],
    /// Bit i set: level i (0-based) is singular (σ_min below threshold).
    pub singular_levels: u32,
    /// `COMMAND_FLAG_*` bits of the command sent, and
    /// [`TELEMETRY_FLAG_PEER_LOST`] in samples that report a lost driver.
    pub flags: u32,
    /// Total commanded τ, Eq. (19).
    pub tau: [f64; MAX_JOINTS],
    /// Task torques τ_i per level, Eqs. (20), (21).
    pub tau_level: [[f64; MAX_JOINTS]; MAX_LEVELS],
    /// Coupling compensation τ_μ, Eq. (22).
    pub tau_mu: [f64; MAX_JOINTS],
    /// The gravity torque the command carries: g(q) when the controller adds
    /// gravity; the load's alone where the driver adds the arm's (its model
    /// does not know the load, docs/load.md); zero otherwise.
    pub tau_gravity: [f64; MAX_JOINTS],
    /// Task errors x̃_i per level (first m_i entries valid).
    pub task_error: [[f64; MAX_TASK_DIM]; MAX_LEVELS],
    /// Storage functions S_i per level, Eqs. (26), (28).
    pub storage: [f64; MAX_LEVELS],
    /// Smallest singular value of each level's (projected) Jacobian.
    pub min_singular_value: [f64; MAX_LEVELS],
    /// Power of the coupling compensation P_μ = τ_μᵀ q̇ (≈ 0).
    pub p_mu: f64,
    /// Event counters.
    pub counters: TelemetryCounters,
    /// Cycle timings.
    pub timings: TelemetryTimings,
    /// Active virtual equilibrium x_{i,d}(t) per level (first m_i entries;
    /// roll, pitch, yaw for orientation), moving during a transition.
    pub goal: [[f64; MAX_TASK_DIM]; MAX_LEVELS],
    /// Diagonal of the active stiffness K_i(t) per level.
    pub stiffness_diag: [[f64; MAX_TASK_DIM]; MAX_LEVELS],
    /// Diagonal of the active damping D_i(t) per level.
    pub damping_diag: [[f64; MAX_TASK_DIM]; MAX_LEVELS],
    /// Progress t/T of each level's transition in [0, 1] (1: at rest).
    pub transition_progress: [f64; MAX_LEVELS],
    /// The answer to the last setpoint of each recent client.
    pub setpoint_answers: [SetpointAnswer; MAX_SETPOINT_CLIENTS],
    /// r, the estimate of the external joint torque τ_ext (N·m) by the
    /// generalized-momentum observer (ṙ = K_O (τ_ext − r); De Luca & Mattone,
    /// ICRA 2005), at this state. Client schema 4; appended last, so every
    /// older field keeps its offset.
    pub tau_ext: [f64; MAX_JOINTS],
    /// H = ½ q̇ᵀ M q̇ + V_1 + Σ_{i≥2} β_i V_i + the joint-limit guard's
    /// potential + the controller's energy tanks (J): the storage of the arm
    /// and the controller together at this state. Without external input it
    /// rises only by what the controller injects. Client schema 6; appended.
    pub h: f64,
    /// Per level, its potential as H counts it (J): V_1, β_i V_i for i ≥ 2
    /// (β_i the level's fade). Client schema 6; appended.
    pub potential: [f64; MAX_LEVELS],
    /// Per level, the energy E_i in its energy tank (J; 0 for level 1, which
    /// has none, and with the tanks off). Client schema 6; appended.
    pub tank: [f64; MAX_LEVELS],
    /// Per level, its tank's valve ∈ [0, 1] (the energy-tank paper's β_i, not
    /// the level's fade; 1: the paper's law; 0: the spring point follows what
    /// the levels above do to it). Client schema 6; appended.
    pub tank_valve: [f64; MAX_LEVELS],
    /// The load the controller's model carries at the tip now (docs/load.md):
    /// its mass (kg) — while a load is announced, the ramp's mixture. Client
    /// schema 8; appended.
    pub load_mass: f64,
    /// Its centre of mass in the tip frame (m; zeros without a load).
    /// Client schema 8; appended.
    pub load_com: [f64; 3],
    /// The announced load's ramp ∈ [0, 1] (1: the model carries the load
    /// told last, no ramp running). Client schema 8; appended.
    pub load_progress: f64,
}

impl Telemetry {
    /// All-zero telemetry with the current client schema.
    pub const fn zeroed() -> Self {
        Self {
            header: Header::client(),
            state_seq: 0,
            command_seq: 0,
            mode: CommandMode::Normal as u32,
            n_levels: 0,
            task_dims: [0; MAX_LEVELS],
            singular_levels: 0,
            flags: 0,
            tau: [0.0; MAX_JOINTS],
            tau_level: [[0.0; MAX_JOINTS]; MAX_LEVELS],
            tau_mu: [0.0; MAX_JOINTS],
            tau_gravity: [0.0; MAX_JOINTS],
            task_error: [[0.0; MAX_TASK_DIM]; MAX_LEVELS],
            storage: [0.0; MAX_LEVELS],
            min_singular_value: [0.0; MAX_LEVELS],
            p_mu: 0.0,
            counters: TelemetryCounters::ZERO,
            timings: TelemetryTimings {
                wakeup_latency_ns: 0,
                compute_ns: 0,
                period_ns: 0,
                max_compute_ns: 0,
            },
            goal: [[0.0; MAX_TASK_DIM]; MAX_LEVELS],
            stiffness_diag: [[0.0; MAX_TASK_DIM]; MAX_LEVELS],
            damping_diag: [[0.0; MAX_TASK_DIM]; MAX_LEVELS],
            transition_progress: [0.0; MAX_LEVELS],
            setpoint_answers: [SetpointAnswer::EMPTY; MAX_SETPOINT_CLIENTS],
            tau_ext: [0.0; MAX_JOINTS],
            h: 0.0,
            potential: [0.0; MAX_LEVELS],
            tank: [0.0; MAX_LEVELS],
            tank_valve: [0.0; MAX_LEVELS],
            load_mass: 0.0,
            load_com: [0.0; 3],
            load_progress: 1.0,
        }
    }

    /// Number of valid joints (clamped to the capacity).
    #[inline]
    pub fn n(&self) -> usize {
        self.header.n()
    }

    /// Number of valid levels (clamped to the capacity).
    #[inline]
    pub fn levels(&self) -> usize {
        (self.n_levels as usize).min(MAX_LEVELS)
    }

    /// Sets n (joints), r (levels) and each level's task dimension, zeroing
    /// everything outside the valid ranges.
    pub fn set_shape(&mut self, n: usize, task_dims: &[usize]) -> Result<(), MsgError> {
        if n > MAX_JOINTS {
            return Err(MsgError::TooManyJoints {
                msg: TELEMETRY,
                n,
                capacity: MAX_JOINTS,
            });
        }
        if task_dims.len() > MAX_LEVELS {
            return Err(MsgError::CapacityExceeded {
                msg: TELEMETRY,
                field: "n_levels",
                value: task_dims.len(),
                capacity: MAX_LEVELS,
            });
        }
        if let Some(&m) = task_dims.iter().find(|&&m| m > MAX_TASK_DIM) {
            return Err(MsgError::CapacityExceeded {
                msg: TELEMETRY,
                field: "task_dims",
                value: m,
                capacity: MAX_TASK_DIM,
            });
        }
        let r = task_dims.len();
        self.header.n_joints = n as u32;
        self.n_levels = r as u32;
        self.task_dims = [0; MAX_LEVELS];
        for (dst, &m) in self.task_dims.iter_mut().zip(task_dims) {
            *dst = m as u32;
        }
        for v in [
            &mut self.tau,
            &mut self.tau_mu,
            &mut self.tau_gravity,
            &mut self.tau_ext,
        ] {
            v[n..].fill(0.0);
        }
        for (i, v) in self.tau_level.iter_mut().enumerate() {
            if i < r {
                v[n..].fill(0.0);
            } else {
                v.fill(0.0);
            }
        }
        for rows in [
            &mut self.task_error,
            &mut self.goal,
            &mut self.stiffness_diag,
            &mut self.damping_diag,
        ] {
            for (i, e) in rows.iter_mut().enumerate() {
                let m = if i < r { task_dims[i] } else { 0 };
                e[m..].fill(0.0);
            }
        }
        self.transition_progress[r..].fill(0.0);
        self.storage[r..].fill(0.0);
        self.min_singular_value[r..].fill(0.0);
        Ok(())
    }

    /// Total τ, length n.
    pub fn tau(&self) -> &[f64] {
        &self.tau[..self.n()]
    }

    /// τ_i of level `level` (0-based), length n; empty if out of range.
    pub fn tau_level(&self, level: usize) -> &[f64] {
        if level < self.levels() {
            &self.tau_level[level][..self.n()]
        } else {
            &[]
        }
    }

    /// Task error of level `level` (0-based), length m_i; empty if out of range.
    pub fn task_error(&self, level: usize) -> &[f64] {
        if level < self.levels() {
            let m = (self.task_dims[level] as usize).min(MAX_TASK_DIM);
            &self.task_error[level][..m]
        } else {
            &[]
        }
    }

    /// Active goal of level `level` (0-based), length m_i; empty if out of range.
    pub fn goal(&self, level: usize) -> &[f64] {
        if level < self.levels() {
            let m = (self.task_dims[level] as usize).min(MAX_TASK_DIM);
            &self.goal[level][..m]
        } else {
            &[]
        }
    }

    /// The answer to the last setpoint of `client_id`, if this sample has one.
    pub fn answer_for(&self, client_id: u64) -> Option<&SetpointAnswer> {
        self.setpoint_answers
            .iter()
            .find(|a| a.answered > 0 && a.client_id == client_id)
    }

    /// r, the estimate of the external joint torque, length n.
    pub fn tau_ext(&self) -> &[f64] {
        &self.tau_ext[..self.n()]
    }

    /// Whether this sample flags a contact ([`TELEMETRY_FLAG_CONTACT`]).
    pub fn contact(&self) -> bool {
        self.flags & TELEMETRY_FLAG_CONTACT != 0
    }

    /// Whether the contact reaction `hold` is latched
    /// ([`TELEMETRY_FLAG_CONTACT_HOLD`]).
    pub fn contact_hold(&self) -> bool {
        self.flags & TELEMETRY_FLAG_CONTACT_HOLD != 0
    }

    /// Whether this sample reports a lost driver ([`TELEMETRY_FLAG_PEER_LOST`]).
    pub fn peer_lost(&self) -> bool {
        self.flags & TELEMETRY_FLAG_PEER_LOST != 0
    }

    /// Whether level `level` (0-based) is flagged singular.
    pub fn is_singular(&self, level: usize) -> bool {
        level < 32 && self.singular_levels & (1 << level) != 0
    }

    /// Receiver-side check of the shape fields (schema, n, r, m_i, mode);
    /// values are diagnostics and may legitimately be non-finite.
    pub fn validate(&self, expected_n: usize) -> Result<(), MsgError> {
        self.header
            .check(SchemaPart::Client, TELEMETRY, expected_n)?;
        let r = self.n_levels as usize;
        if r > MAX_LEVELS {
            return Err(MsgError::CapacityExceeded {
                msg: TELEMETRY,
                field: "n_levels",
                value: r,
                capacity: MAX_LEVELS,
            });
        }
        if let Some(&m) = self.task_dims.iter().find(|&&m| m as usize > MAX_TASK_DIM) {
            return Err(MsgError::CapacityExceeded {
                msg: TELEMETRY,
                field: "task_dims",
                value: m as usize,
                capacity: MAX_TASK_DIM,
            });
        }
        CommandMode::from_code(self.mode).map_err(|_| MsgError::UnknownCode {
            msg: TELEMETRY,
            field: "mode",
            value: self.mode,
        })?;
        Ok(())
    }
}

impl Default for Telemetry {
    fn default() -> Self {
        Self::zeroed()
    }
}
