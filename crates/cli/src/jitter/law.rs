//! The law's same-run reference: the scenario's control law stepped back to
//! back on the controller's core, next to each half of the floor.

use anyhow::{Context, bail};
use hcc_config::Scenario;
use hcc_msgs::monotonic_now_ns;
use hcc_rt as rt;
use hcc_timing::LatencyHistogram;

use super::floor::measuring_thread;
use super::plan::{JitterArgs, Plan};
use crate::daemons::interrupted;

/// Untimed steps before the law's back-to-back reference is timed.
pub(super) const LAW_WARM_UP_STEPS: usize = 200;

/// Timed steps of the law's back-to-back reference, per floor half.
pub(super) const LAW_STEPS: usize = 2_000;

/// The scenario's control law stepped back to back on the controller's core:
/// what one step costs on this machine at this moment with its caches warm
/// (the step benchmark's "back to back", measured in the same run as the
/// pair). The law's time in the loop is read against it: their ratio is
/// what the idle between two states and the machine's neighbours add.
pub(super) struct LawReference {
    pub(super) core: usize,
    pub(super) steps: LatencyHistogram,
}

/// Steps the scenario's law [`LAW_WARM_UP_STEPS`] + [`LAW_STEPS`] times back
/// to back in a thread pinned to `core` (SCHED_FIFO `fifo` when permitted),
/// along a small joint trajectory around the scenario's q0, timing each of the
/// last [`LAW_STEPS`] (a step that fails is not timed).
pub(super) fn measure_law(
    scenario: &Scenario,
    core: usize,
    fifo: Option<i32>,
) -> anyhow::Result<LawReference> {
    let mut controller = hcc_cycle::controller_for(scenario)?;
    let q0: Vec<f64> = scenario.q0.iter().copied().collect();
    let steps = std::thread::scope(|scope| {
        std::thread::Builder::new()
            .name(format!("hcc-law-{core}"))
            .spawn_scoped(scope, move || {
                let _ = rt::prepare_rt_thread(&measuring_thread(core, fifo));
                let mut steps = LatencyHistogram::new();
                let mut q = q0.clone();
                let mut qd = vec![0.0; q0.len()];
                for k in 0..LAW_WARM_UP_STEPS + LAW_STEPS {
                    let t = k as f64 * 1e-3;
                    for (j, (qj, qdj)) in q.iter_mut().zip(qd.iter_mut()).enumerate() {
                        let phase = t + j as f64;
                        *qj = q0[j] + 0.05 * phase.sin();
                        *qdj = 0.05 * phase.cos();
                    }
                    let start = monotonic_now_ns();
                    let ok = controller.step(&q, &qd).is_ok();
                    let took = monotonic_now_ns().saturating_sub(start);
                    if ok && k >= LAW_WARM_UP_STEPS {
                        steps.record(took);
                    }
                }
                steps
            })
            .map(|h| h.join())
    })
    .context("starting the law's reference thread")?
    .map_err(|_| anyhow::anyhow!("the law's reference thread panicked"))?;
    Ok(LawReference { core, steps })
}

/// The law's back-to-back reference on the controller's core, next to one
/// half of the floor (`when`), with its result line unless `quiet`.
pub(super) fn law_phase(
    args: &JitterArgs,
    scenario: &Scenario,
    plan: &Plan,
    when: &str,
) -> anyhow::Result<LawReference> {
    let law = measure_law(scenario, args.controller_core, plan.fifo)?;
    if interrupted() {
        bail!("interrupted during the law's reference");
    }
    if !args.quiet {
        eprintln!(
            "hcc jitter: control law back to back, core {} ({when}): {}",
            law.core,
            law.steps.summary().line_us()
        );
    }
    Ok(law)
}
