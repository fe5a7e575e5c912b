//! The machine's floor: a bare periodic thread at the control rate on each
//! core, no IPC, no work — its lateness is what the machine alone costs; the
//! busy threads of `--load`; the steal time of the cores.

use anyhow::{Context, bail};
use hcc_msgs::monotonic_now_ns;
use hcc_rt::{self as rt, RtSettings};
use hcc_timing::machine::CpuTimes;
use hcc_timing::{LatencyHistogram, RtObtained};
use serde_json::{Value, json};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use tracing::warn;

use super::plan::{JitterArgs, LATE_FRACTION, Plan, Wait};
use crate::daemons::interrupted;

/// What one floor thread measured.
pub(super) struct FloorCore {
    pub(super) core: usize,
    pub(super) rt: RtObtained,
    pub(super) lateness: LatencyHistogram,
    pub(super) late_cycles: u64,
}

/// The real-time settings of a measuring thread of `hcc jitter` (a floor
/// thread, the law's reference): pinned to `core`, SCHED_FIFO `fifo` when
/// permitted, its stack prefaulted, memory not locked (the daemons lock
/// theirs).
pub(super) fn measuring_thread(core: usize, fifo: Option<i32>) -> RtSettings {
    RtSettings {
        cpu_core: Some(core),
        sched_priority: fifo,
        lock_memory: false,
        prefault_stack_bytes: 256 * 1024,
    }
}

/// Bare periodic threads, one per core, all with the same deadlines.
pub(super) fn measure_floor(
    cores: &[usize],
    fifo: Option<i32>,
    wait: Wait,
    period_ns: u64,
    duration_s: f64,
) -> anyhow::Result<Vec<FloorCore>> {
    let cycles = (duration_s * 1e9 / period_ns as f64).round().max(1.0) as u64;
    let late_ns = (period_ns as f64 * LATE_FRACTION) as u64;
    let start_ns = monotonic_now_ns() + 50_000_000;
    let handles: Vec<_> = cores
        .iter()
        .map(|&core| {
            std::thread::Builder::new()
                .name(format!("hcc-floor-{core}"))
                .spawn(move || {
                    let settings = measuring_thread(core, fifo);
                    let report = rt::prepare_rt_thread(&settings);
                    let mut lateness = LatencyHistogram::new();
                    let mut late_cycles = 0;
                    rt::sleep_until_ns(start_ns);
                    for k in 1..=cycles {
                        let deadline = start_ns + k * period_ns;
                        wait.sleep_until(deadline);
                        let late = monotonic_now_ns().saturating_sub(deadline);
                        lateness.record(late);
                        late_cycles += u64::from(late > late_ns);
                        if interrupted() {
                            break;
                        }
                    }
                    FloorCore {
                        core,
                        rt: report.obtained(&settings),
                        lateness,
                        late_cycles,
                    }
                })
        })
        .collect::<Result<_, _>>()
        .context("starting the floor threads")?;
    handles
        .into_iter()
        .map(|h| {
            h.join()
                .map_err(|_| anyhow::anyhow!("a floor thread panicked"))
        })
        .collect()
}

/// Busy threads at normal priority, one per core, until dropped.
pub(super) struct Load {
    pub(super) stop: Arc<AtomicBool>,
    pub(super) threads: Vec<std::thread::JoinHandle<()>>,
}

impl Load {
    pub(super) fn start(cores: &[usize]) -> anyhow::Result<Load> {
        let stop = Arc::new(AtomicBool::new(false));
        let mut threads = Vec::new();
        for &core in cores {
            let stop = stop.clone();
            threads.push(
                std::thread::Builder::new()
                    .name(format!("hcc-load-{core}"))
                    .spawn(move || {
                        core_affinity::set_for_current(core_affinity::CoreId { id: core });
                        // Arithmetic and a 4 MiB working set (evicts the caches
                        // the real-time threads share with it).
                        let mut buffer = vec![1u64; 512 * 1024];
                        let mut x = 0x9e37_79b9_7f4a_7c15u64;
                        let mut i = 0usize;
                        while !stop.load(Ordering::Relaxed) {
                            for _ in 0..4096 {
                                x ^= x << 13;
                                x ^= x >> 7;
                                x ^= x << 17;
                                let j = (x as usize) % buffer.len();
                                buffer[j] = buffer[j].wrapping_add(x);
                                i = i.wrapping_add(1);
                            }
                        }
                        std::hint::black_box((&buffer, i));
                    })
                    .context("starting a load thread")?,
            );
        }
        Ok(Load { stop, threads })
    }
}

impl Drop for Load {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// CPU time counters of the measured cores, to report the steal time.
pub(super) fn cpu_times(cores: &[usize]) -> Vec<Option<CpuTimes>> {
    cores.iter().map(|&c| CpuTimes::read(Some(c))).collect()
}

pub(super) fn steal_since(cores: &[usize], before: &[Option<CpuTimes>]) -> Value {
    let after = cpu_times(cores);
    let mut v = serde_json::Map::new();
    for ((core, b), a) in cores.iter().zip(before).zip(&after) {
        let f = match (b, a) {
            (Some(b), Some(a)) => json!(a.steal_fraction_since(b)),
            _ => Value::Null,
        };
        v.insert(format!("core{core}"), f);
    }
    Value::Object(v)
}

/// One half of the floor measurement (`when`: before or after the pair), with
/// its warnings and (unless `quiet`) its result lines.
pub(super) fn floor_phase(
    args: &JitterArgs,
    plan: &Plan,
    duration_s: f64,
    when: &str,
) -> anyhow::Result<(Vec<FloorCore>, Value)> {
    let before = cpu_times(&plan.cores);
    let floor = measure_floor(
        &plan.cores,
        plan.fifo,
        args.wait,
        plan.period_ns,
        duration_s,
    )?;
    let steal = steal_since(&plan.cores, &before);
    if interrupted() {
        bail!("interrupted during the floor measurement");
    }
    for f in &floor {
        for w in &f.rt.warnings {
            warn!("floor core {}: {w}", f.core);
        }
    }
    if !args.quiet {
        for f in &floor {
            eprintln!(
                "hcc jitter: floor core {} ({when}): {}",
                f.core,
                f.lateness.summary().line_us()
            );
        }
    }
    Ok((floor, steal))
}

/// The two halves of the floor as one measurement: per core, the lateness
/// histograms merged and the late cycles summed; the steal fraction the mean
/// of the halves' (equal durations).
pub(super) fn join_floors(
    (mut floor, steal): (Vec<FloorCore>, Value),
    (after, steal_after): (Vec<FloorCore>, Value),
) -> (Vec<FloorCore>, Value) {
    for f in &mut floor {
        if let Some(a) = after.iter().find(|a| a.core == f.core) {
            f.lateness.merge(&a.lateness);
            f.late_cycles += a.late_cycles;
        }
    }
    let mut mean = serde_json::Map::new();
    if let (Some(b), Some(a)) = (steal.as_object(), steal_after.as_object()) {
        for (core, x) in b {
            let m = match (x.as_f64(), a.get(core).and_then(Value::as_f64)) {
                (Some(x), Some(y)) => json!((x + y) / 2.0),
                _ => Value::Null,
            };
            mean.insert(core.clone(), m);
        }
    }
    (floor, Value::Object(mean))
}
