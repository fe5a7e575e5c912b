//! Column names of `trajectory.csv`.
//!
//! Required columns, in this order: `t`, `q1..qn`, `qd1..qdn`, `tau1..taun`
//! (applied joint torque, gravity included), `e<i>_<k>` (task error of level
//! i, component k, both 1-based), `S1..Sr` (level energies, eq. 26/28),
//! `P_mu` (power τ_μᵀq̇ of the Coriolis cancellation, eq. 22).
//!
//! Optional columns written by the simulator after the required ones:
//! - `tau_L<i>_<k>`: torque contribution τ_i of level i at joint k (eqs. 20/21),
//! - `tau_mu_<k>`: the Coriolis cancellation τ_μ at joint k (eq. 22),
//! - `acc<i>_<j>` (i ≠ j): disturbing acceleration ‖J_i M⁻¹ τ_j‖, the task-space
//!   acceleration of level i caused by the control torque of level j alone
//!   (Fig. 5 of the paper); it vanishes for j > i under a strict hierarchy,
//! - `acc<i>_mu`: ‖J_i M⁻¹ τ_μ‖,
//! - `accv<i>_<j>`, `accv<i>_mu`: the same in the local null-space velocities of
//!   the paper, ‖J̄_i M⁻¹ τ_j‖ (zero for j ≠ i by the block-diagonal Λ, eq. 16),
//! - `S<i>_kin`, `S<i>_pot`: kinetic ½v_iᵀΛ_i v_i and potential V_i parts of S_i,
//! - `E_kin`, `E_pot`: mechanical energy of the plant,
//! - `H`: the storage of the arm and the controller together as the controller
//!   counts it, ½q̇ᵀMq̇ + V_1 + Σ_{i≥2} β_i V_i + the joint-limit guard's
//!   potential + its energy tanks (β_i a level's fade); without external input
//!   it rises only by what the controller injects,
//! - `V_<i>`: the potential of level i as H counts it (V_1, β_i V_i),
//! - `tank_<i>`, `valve_<i>`: the energy in level i's energy tank (J; 0 for
//!   level 1) and the tank's valve in [0, 1] (1: the paper's law; 0: the
//!   level's spring point follows what the levels above do to it),
//! - `tau_ext_<k>`: the controller's estimate r of the external joint torque
//!   at joint k (generalized-momentum observer, hcc-control's `contact`),
//! - `contact`: 1 while the contact detection flags a contact, else 0,
//! - `f_ext_<k>`: the controller's estimate F̂ = pinv(J_iᵀ) r of the external
//!   wrench at the frame of the first position or pose level i, task row k
//!   (N along the level's world axes, then N·m for a pose); absent when no
//!   level is a position or a pose.

/// Time column.
pub const TIME: &str = "t";
/// Power of τ_μ.
pub const P_MU: &str = "P_mu";
/// Kinetic energy of the plant.
pub const E_KIN: &str = "E_kin";
/// Potential (gravity) energy of the plant.
pub const E_POT: &str = "E_pot";
/// The storage H of the arm and the controller.
pub const H: &str = "H";

/// The contact flag (1 in contact, 0 not).
pub const CONTACT: &str = "contact";

/// Joint position `q<k>` (1-based).
pub fn position(k: usize) -> String {
    format!("q{k}")
}
/// Joint velocity `qd<k>`.
pub fn velocity(k: usize) -> String {
    format!("qd{k}")
}
/// Applied joint torque `tau<k>`.
pub fn torque(k: usize) -> String {
    format!("tau{k}")
}
/// Task error of level `i`, component `k`: `e<i>_<k>`.
pub fn error(i: usize, k: usize) -> String {
    format!("e{i}_{k}")
}
/// The desired value x_{i,d} of level `i`, component `k` (the goal, or a
/// path's value at the cycle; roll, pitch, yaw for an orientation): `xd<i>_<k>`.
pub fn desired(i: usize, k: usize) -> String {
    format!("xd{i}_{k}")
}
/// Energy S_i of level `i`: `S<i>`.
pub fn energy(i: usize) -> String {
    format!("S{i}")
}
/// Kinetic part of S_i.
pub fn energy_kinetic(i: usize) -> String {
    format!("S{i}_kin")
}
/// Potential part of S_i.
pub fn energy_potential(i: usize) -> String {
    format!("S{i}_pot")
}
/// The potential of level `i` as H counts it: `V_<i>`.
pub fn potential_in_h(i: usize) -> String {
    format!("V_{i}")
}
/// The energy in level `i`'s energy tank: `tank_<i>`.
pub fn tank(i: usize) -> String {
    format!("tank_{i}")
}
/// The valve of level `i`'s energy tank: `valve_<i>`.
pub fn tank_valve(i: usize) -> String {
    format!("valve_{i}")
}
/// Torque of level `i` at joint `k`: `tau_L<i>_<k>`.
pub fn level_torque(i: usize, k: usize) -> String {
    format!("tau_L{i}_{k}")
}
/// The estimate of the external torque at joint `k`: `tau_ext_<k>`.
pub fn external_torque(k: usize) -> String {
    format!("tau_ext_{k}")
}
/// The estimate of the external wrench, task row `k`: `f_ext_<k>`.
pub fn external_wrench(k: usize) -> String {
    format!("f_ext_{k}")
}
/// τ_μ at joint `k`: `tau_mu_<k>`.
pub fn mu_torque(k: usize) -> String {
    format!("tau_mu_{k}")
}
/// Disturbing acceleration of level `i` caused by level `j`: `acc<i>_<j>`.
pub fn disturbing_acceleration(i: usize, j: usize) -> String {
    format!("acc{i}_{j}")
}
/// Acceleration of level `i` caused by τ_μ: `acc<i>_mu`.
pub fn mu_acceleration(i: usize) -> String {
    format!("acc{i}_mu")
}

/// Acceleration of the local null-space velocity v_i caused by level `j`:
/// `accv<i>_<j>` = ‖J̄_i M⁻¹ τ_j‖.
pub fn null_space_acceleration(i: usize, j: usize) -> String {
    format!("accv{i}_{j}")
}
/// ‖J̄_i M⁻¹ τ_μ‖: `accv<i>_mu`.
pub fn null_space_mu_acceleration(i: usize) -> String {
    format!("accv{i}_mu")
}

/// Whether a column name is a disturbing-acceleration column (`acc...`, `accv...`).
pub fn is_disturbing_acceleration(name: &str) -> bool {
    name.starts_with("acc")
}

/// Required columns for `n` joints and levels of dimensions `dims`, in order.
pub fn required(n: usize, dims: &[usize]) -> Vec<String> {
    let mut c = vec![TIME.to_string()];
    c.extend((1..=n).map(position));
    c.extend((1..=n).map(velocity));
    c.extend((1..=n).map(torque));
    for (i, &m) in dims.iter().enumerate() {
        c.extend((1..=m).map(|k| error(i + 1, k)));
    }
    c.extend((1..=dims.len()).map(energy));
    c.push(P_MU.to_string());
    c
}
