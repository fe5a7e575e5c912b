//! The dense linear algebra of hcc — one home for every routine the robot
//! model, the control law and the message checks need, all in place on
//! caller-provided storage and allocation-free (a 1 kHz loop calls them):
//!
//! * [`cholesky`]: A = L Lᵀ, solves with it, the SPD inverse, and the
//!   positive-definiteness test of the setpoint checks (Golub & Van Loan,
//!   "Matrix Computations", Alg. 4.2.1);
//! * [`spd`]: the inverse of the law's Gram matrices, exact or damped
//!   ((A + δI)⁻¹ near a singularity), with their conditioning;
//! * [`products`]: `gemm`, `gemv` and their transposed, symmetric and
//!   leading-block variants, transposes and copies;
//! * [`eigen`]: the symmetric eigenproblem by cyclic Jacobi;
//! * [`basis`]: null-space bases (Householder QR) and their alignment to the
//!   previous cycle's (orthogonal Procrustes, polar factor);
//! * [`blocks`]: block copies and column views;
//! * [`symmetric`]: a matrix plus a transpose (Ṁ = C + Cᵀ), exactly symmetric.
//!
//! The hand-written products are kept where the benchmark `cargo bench -p
//! hcc-linalg --bench kernels` shows them faster than nalgebra's own in-place
//! routines at the sizes of a robot controller; elsewhere nalgebra's are used
//! (see [`products`]). Bad input never panics where a `Result` is returned
//! ([`LinalgError`]); the kernels without one assume sizes the caller checked
//! at construction.

pub mod basis;
pub mod blocks;
pub mod cholesky;
pub mod eigen;
pub mod products;
pub mod spd;
pub mod symmetric;

pub use cholesky::{
    LinalgError, cholesky_factor, cholesky_in_place, cholesky_in_place_slice,
    cholesky_solve_in_place, cholesky_solve_matrix_in_place, cholesky_solve_slice,
};
