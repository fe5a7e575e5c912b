//! The law's terms of one cycle into a telemetry sample.

use hcc_control::StepOutput;
use hcc_msgs::{MAX_LEVELS, MAX_TASK_DIM, Telemetry};

/// Writes what the law computed in its last step (`out`) into `t`: per level
/// τ_i (Eqs. (20), (21)), the task error x̃_i, the storage S_i (Eqs. (26),
/// (28)), the conditioning and the singular flag; τ_μ (Eq. (22)) and its
/// power P_μ = τ_μᵀ q̇ (Sec. IV-C); the gravity torque the command carries
/// (`gravity`: g(q), or the load's alone where the driver adds the arm's); the
/// storage H, each level's potential in it, its energy tank and valve.
/// Allocation-free.
pub(crate) fn write_law_terms(t: &mut Telemetry, out: &StepOutput, gravity: Option<&[f64]>) {
    let n = out.tau.len();
    let mut singular = 0u32;
    for i in 0..out.storage.len().min(MAX_LEVELS) {
        if out.singular[i] {
            singular |= 1 << i;
        }
        t.tau_level[i][..n].copy_from_slice(out.tau_level[i].as_slice());
        let m = out.task_error[i].len().min(MAX_TASK_DIM);
        t.task_error[i][..m].copy_from_slice(&out.task_error[i].as_slice()[..m]);
        t.storage[i] = out.storage[i];
        // σ_min/σ_max of the level's Gram factor (square root of the
        // smallest eigenvalue ratio of the inverted Gram matrices).
        t.min_singular_value[i] = out.conditioning[i].max(0.0).sqrt();
        t.potential[i] = out.safety.level_potential[i];
        t.tank[i] = out.tank[i];
        t.tank_valve[i] = out.tank_valve[i];
    }
    t.h = out.safety.h;
    t.singular_levels = singular;
    t.tau_mu[..n].copy_from_slice(out.tau_mu.as_slice());
    if let Some(g) = gravity {
        t.tau_gravity[..n].copy_from_slice(g);
    }
    t.p_mu = out.p_mu;
}
