//! The run recorder of the hierarchical compliance controller (Dietrich, Ott &
//! Albu-Schäffer, IROS 2013): one trajectory row per controller cycle, built
//! from the sampled state and what the law computed, with the derived
//! columns of the report (see [`hcc_report::columns`]) computed from the
//! model. `hcc simulate` (in process) and `hcc run` (over IPC) record through
//! the same [`Recorder`], so their tables agree column for column.
//!
//! A row, in the order of [`column_names`]:
//! - the required columns (t, q, q̇, τ, task errors x̃_i, S_i of eqs. 26/28, P_μ),
//! - `tau_L<i>_<k>` and `tau_mu_<k>`: the torque τ_i of each level (eqs. 20, 21)
//!   and τ_μ (eq. 22),
//! - `acc<i>_<j>` for i ≠ j: ‖J_i M⁻¹ τ_j‖, the task-space acceleration that the
//!   control torque of level j alone produces on level i (Fig. 5). With a strict
//!   hierarchy it vanishes for j > i (J_i M⁻¹ N_j = 0); for j < i it is the
//!   admissible influence of a higher level on a lower one. `acc<i>_mu` is the
//!   same for τ_μ. J_i is the law's analytic task Jacobian of the cycle
//!   ([`LawTerms::task_jacobian`]),
//! - `accv<i>_<j>` and `accv<i>_mu` (when the law provides J̄): the same in the
//!   paper's local null-space coordinates, ‖J̄_i M⁻¹ τ_j‖ = ‖v̇_i‖ caused by τ_j
//!   (eqs. 3, 15, 24, 25). The block-diagonal Λ (eq. 16) makes it vanish for
//!   every j ≠ i, so these columns measure the decoupling of Sec. III;
//!   `accv<i>_mu` = ‖Λ_i⁻¹ Σ_{j≠i} μ_ij v_j‖ is the coupling that τ_μ cancels,
//! - `S<i>_kin` = S_i − V_i (the kinetic part ½ v_iᵀ Λ_i v_i) and `S<i>_pot` =
//!   V_i(x̃_i) (the potential of eq. 28),
//! - `E_kin`, `E_pot`: the mechanical energy of the plant ([`EnergyModel`]),
//! - `H`, `V_<i>`: the storage of the arm and the controller as the
//!   controller counts it, and each level's potential in it (from the
//!   telemetry, [`CycleOutput::h`]; NaN where the output has none),
//! - `tank_<i>`, `valve_<i>`: the energy in level i's energy tank and its
//!   valve (from the telemetry, [`CycleOutput::tank`]; NaN where the output
//!   has none),
//! - `tau_ext_<k>`, `contact`: the estimate of the external joint torque and
//!   the contact flag, from the telemetry (NaN where the output has none);
//! - `f_ext_<k>`: the estimate of the external wrench at the first position or
//!   pose level's frame, its task rows, from the control cycle
//!   ([`WithWrench`]; NaN where the output has none; no columns without such
//!   a level);
//! - `xd<i>_<k>`: level i's desired value x_{i,d} — its goal, or its path's
//!   value at the cycle (docs/tracking.md) — from the telemetry
//!   ([`CycleOutput::desired`]; NaN where the output has none); with
//!   `e<i>_<k>` = x_i − x_{i,d} the tracking error.
//!
//! A live namespace is captured into a recording by [`capture`] (a tap of
//! its streams on a thread of its own, written as they come); a recording is
//! read back by [`mcap_log`], and replayed by `hcc-replay`.
//!
//! The recorder is streaming: [`Recorder::record`] takes one cycle and pushes
//! one row into a [`RowSink`]; the in-memory [`hcc_report::Trajectory`] is one
//! such sink, the streaming [`hcc_report::RunWriter`] (the results of a run
//! written as its rows come) and [`hcc_report::CsvWriter`] are others.
//!
//! ```no_run
//! # use hcc_record::*;
//! # fn f(scenario: &hcc_config::Scenario, energy: Box<dyn EnergyModel>,
//! #      out: &dyn CycleOutput, law: &dyn LawTerms) -> Result<(), RecordError> {
//! let mut recorder = Recorder::new(scenario, true, energy)?;
//! let mut table = recorder.trajectory(1001)?;
//! let q = scenario.q0.as_slice();
//! let qd = scenario.qd0.as_slice();
//! recorder.record(&Cycle { t: 0.0, q, qd, output: out, law: Some(law) }, &mut table)?;
//! # Ok(()) }
//! ```

mod adapters;
pub mod capture;
mod layout;
pub mod mcap_log;
mod recorder;

pub use adapters::WithWrench;
pub use layout::{column_names, describe, wrench_rows};
pub use recorder::{Cycle, CycleOutput, EnergyModel, LawTerms, Recorder, RowSink};

/// Errors of the recorder; each names the time of the cycle concerned.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{0}")]
    Invalid(String),
    #[error("{0}")]
    Sink(#[from] hcc_report::ReportError),
}
