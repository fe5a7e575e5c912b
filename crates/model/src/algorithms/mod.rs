//! The algorithms. Each is a free function over an immutable [`Model`] and a
//! preallocated [`Data`]; none allocates.
//!
//! The joint-space dynamics are those of the paper's eq. (1),
//! `M(q) q̈ + C(q, q̇) q̇ + g(q) = τ + τ_ext`, with `C` satisfying `Ṁ = C + Cᵀ`.
//!
//! Spatial-vector algebra after Featherstone, "Rigid Body Dynamics Algorithms"
//! (Springer 2008, "RBDA"), with every spatial quantity expressed in **world
//! coordinates at the world origin** (RBDA Ch. 2, spatial vectors in a single fixed
//! frame, the ground-frame variant of the recursions):
//! - a motion vector is `(v, ω)` (linear first): `ω` the angular velocity and
//!   `v` the velocity of the body-fixed point that momentarily coincides with
//!   the world origin;
//! - a force vector is `(f, n)`: force and moment about the world origin;
//! - the motion subspace of joint i is `S_i = (p_i × z_i, z_i)` (revolute,
//!   `z_i` world axis through `p_i`) or `(z_i, 0)` (prismatic); its time
//!   derivative is `Ṡ_i = v_i × S_i`;
//! - body velocities are plain sums `v_i = v_{i−1} + S_i q̇_i`, composite
//!   inertias plain sums of world inertias.
//!
//! With `n` bodies on a serial chain the recursions reduce to plain loops
//! (each body's parent is the previous one).
//!
//! Bad input (state vectors or outputs of the wrong size, an unknown frame)
//! never panics: results are filled with NaN (functions without a `Result`) or
//! an error is returned ([`forward_dynamics`]). [`Model::check_state`] checks
//! sizes up front.
//!
//! One algorithm per file, as in Pinocchio; each builds on those above it:
//! - `spatial`: the spatial-vector helpers and the world-frame body inertia;
//! - `data`: what they share: the [`Scratch`] buffers of [`Data`] and the size checks;
//! - `kinematics`: forward kinematics and frame placements;
//! - `jacobian`: frame Jacobians, their time variation, the classical acceleration;
//! - `crba`: the joint-space inertia matrix M (CRBA);
//! - `coriolis`: the Coriolis matrix C with Ṁ = C + Cᵀ;
//! - `rnea`: inverse dynamics, gravity and nonlinear effects (RNEA);
//! - `forward_dynamics`: forward dynamics, and every term in one pass;
//! - `energy`: kinetic plus potential energy.
//!
//! [`Model`]: crate::Model
//! [`forward_dynamics`]: fn@forward_dynamics
//! [`Data`]: crate::Data
//! [`Model::check_state`]: crate::Model::check_state

mod coriolis;
mod crba;
mod data;
mod energy;
mod forward_dynamics;
mod jacobian;
mod kinematics;
mod rnea;
mod spatial;

pub use coriolis::coriolis_matrix;
pub use crba::crba;
pub use data::Scratch;
pub use forward_dynamics::{compute_all_terms, forward_dynamics};
pub use jacobian::{
    frame_classical_acceleration, frame_jacobian, frame_jacobian_time_variation, frame_jacobians,
};
pub use kinematics::{forward_kinematics, forward_kinematics_vel, frame_placement};
pub use rnea::{gravity, nle, rnea};
