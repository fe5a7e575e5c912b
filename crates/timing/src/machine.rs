//! Facts about the machine that a timing report must carry, read from
//! `/proc` and `/sys` (Linux; elsewhere they are reported as unknown).
//!
//! The traps of a small virtual machine that these facts expose:
//! - **steal time**: the host runs something else on our virtual CPU; the
//!   guest sees a multi-millisecond stall it cannot prevent
//!   ([`CpuTimes::steal_fraction_since`]);
//! - **real-time throttling**: `sched_rt_runtime_us` < `sched_rt_period_us`
//!   stops a `SCHED_FIFO` thread that would use the whole period
//!   ([`RtThrottling`]);
//! - **deep idle states**: waking an idle CPU takes tens of µs unless a
//!   `/dev/cpu_dma_latency` request holds it in a shallow state
//!   ([`CpuDmaLatency`], what cyclictest does).

use std::fs::File;
use std::io::Write;

use serde::{Deserialize, Serialize};

/// The machine, as the timing report states it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MachineInfo {
    /// Kernel release (`/proc/sys/kernel/osrelease`).
    pub kernel: String,
    /// CPU model (`model name` of `/proc/cpuinfo`).
    pub cpu_model: String,
    /// Online CPUs.
    pub cpus: usize,
    /// Clock source (`/sys/devices/system/clocksource/clocksource0/current_clocksource`).
    pub clocksource: String,
    /// Real-time throttling.
    pub rt_throttling: RtThrottling,
    /// Whether the process runs as a hypervisor guest (`hypervisor` CPU flag).
    pub virtual_machine: bool,
}

impl MachineInfo {
    /// Reads what is available; unknown fields stay empty.
    pub fn read() -> MachineInfo {
        let cpuinfo = read_trimmed("/proc/cpuinfo");
        let field = |name: &str| {
            cpuinfo
                .lines()
                .find(|l| l.starts_with(name))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
                .unwrap_or_default()
        };
        MachineInfo {
            kernel: read_trimmed("/proc/sys/kernel/osrelease"),
            cpu_model: field("model name"),
            cpus: std::thread::available_parallelism().map_or(0, |n| n.get()),
            clocksource: read_trimmed(
                "/sys/devices/system/clocksource/clocksource0/current_clocksource",
            ),
            rt_throttling: RtThrottling::read(),
            virtual_machine: field("flags").split_whitespace().any(|f| f == "hypervisor"),
        }
    }
}

/// `kernel.sched_rt_runtime_us` / `kernel.sched_rt_period_us`: real-time
/// threads together may run `runtime` µs of every `period` µs (−1: no limit).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RtThrottling {
    pub runtime_us: Option<i64>,
    pub period_us: Option<i64>,
}

impl RtThrottling {
    /// Reads the two sysctls.
    pub fn read() -> RtThrottling {
        let num = |p: &str| read_trimmed(p).parse::<i64>().ok();
        RtThrottling {
            runtime_us: num("/proc/sys/kernel/sched_rt_runtime_us"),
            period_us: num("/proc/sys/kernel/sched_rt_period_us"),
        }
    }

    /// Longest stop a thread that never yields can see per period, µs (0: none).
    pub fn gap_us(&self) -> i64 {
        match (self.runtime_us, self.period_us) {
            (Some(r), Some(p)) if r >= 0 && r < p => p - r,
            _ => 0,
        }
    }
}

/// CPU time counters of one CPU (or all) from `/proc/stat`, in clock ticks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CpuTimes {
    /// Sum of every state.
    pub total: u64,
    /// Idle and I/O wait.
    pub idle: u64,
    /// Time the hypervisor ran something else on this virtual CPU.
    pub steal: u64,
}

impl CpuTimes {
    /// Counters of `cpu` (`None`: the `cpu` line of all CPUs together).
    pub fn read(cpu: Option<usize>) -> Option<CpuTimes> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let name = match cpu {
            Some(c) => format!("cpu{c}"),
            None => "cpu".to_string(),
        };
        let line = stat
            .lines()
            .find(|l| l.split_whitespace().next() == Some(name.as_str()))?;
        CpuTimes::parse(line)
    }

    /// Parses one `cpuN user nice system idle iowait irq softirq steal …` line.
    pub fn parse(line: &str) -> Option<CpuTimes> {
        let v: Vec<u64> = line
            .split_whitespace()
            .skip(1)
            .map(|x| x.parse().ok())
            .collect::<Option<Vec<u64>>>()?;
        if v.len() < 4 {
            return None;
        }
        // guest and guest_nice (fields 9, 10) are already counted in user / nice.
        let total: u64 = v.iter().take(8).sum();
        Some(CpuTimes {
            total,
            idle: v[3] + v.get(4).copied().unwrap_or(0),
            steal: v.get(7).copied().unwrap_or(0),
        })
    }

    /// Fraction of the time since `earlier` that was stolen (0 when no time passed).
    pub fn steal_fraction_since(&self, earlier: &CpuTimes) -> f64 {
        let dt = self.total.saturating_sub(earlier.total);
        if dt == 0 {
            return 0.0;
        }
        self.steal.saturating_sub(earlier.steal) as f64 / dt as f64
    }

    /// Fraction of the time since `earlier` that was busy (not idle, not stolen).
    pub fn busy_fraction_since(&self, earlier: &CpuTimes) -> f64 {
        let dt = self.total.saturating_sub(earlier.total);
        if dt == 0 {
            return 0.0;
        }
        let idle = self.idle.saturating_sub(earlier.idle);
        let steal = self.steal.saturating_sub(earlier.steal);
        dt.saturating_sub(idle + steal) as f64 / dt as f64
    }
}

/// A held `/dev/cpu_dma_latency` request (PM QoS): while the file is open,
/// the CPUs stay in idle states whose exit latency is at most the requested
/// value. Released on drop.
#[derive(Debug)]
pub struct CpuDmaLatency {
    _file: File,
    /// The requested latency, µs.
    pub us: i32,
}

impl CpuDmaLatency {
    /// Requests `us` µs (0: stay in the shallowest idle state).
    pub fn request(us: i32) -> std::io::Result<CpuDmaLatency> {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/cpu_dma_latency")?;
        file.write_all(&us.to_ne_bytes())?;
        Ok(CpuDmaLatency { _file: file, us })
    }
}

fn read_trimmed(path: &str) -> String {
    std::fs::read_to_string(path)
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_proc_stat_lines() {
        let t = CpuTimes::parse("cpu0 100 0 50 800 10 5 5 30 0 0").unwrap();
        assert_eq!(t.total, 1000);
        assert_eq!(t.idle, 810);
        assert_eq!(t.steal, 30);
        let later = CpuTimes::parse("cpu0 200 0 100 1600 20 10 10 60 0 0").unwrap();
        assert!((later.steal_fraction_since(&t) - 0.03).abs() < 1e-12);
        assert!((later.busy_fraction_since(&t) - 0.16).abs() < 1e-12);
        assert_eq!(t.steal_fraction_since(&t), 0.0);
        assert!(CpuTimes::parse("cpu0 1 2").is_none());
        assert!(CpuTimes::parse("cpu0 a b c d").is_none());
    }

    #[test]
    fn throttling_gap() {
        let t = RtThrottling {
            runtime_us: Some(950_000),
            period_us: Some(1_000_000),
        };
        assert_eq!(t.gap_us(), 50_000);
        let off = RtThrottling {
            runtime_us: Some(-1),
            period_us: Some(1_000_000),
        };
        assert_eq!(off.gap_us(), 0);
        assert_eq!(RtThrottling::default().gap_us(), 0);
    }

    #[test]
    fn reads_this_machine_without_failing() {
        let m = MachineInfo::read();
        assert!(m.cpus >= 1);
        if cfg!(target_os = "linux") {
            assert!(!m.kernel.is_empty());
            assert!(CpuTimes::read(None).is_some_and(|t| t.total > 0));
            assert!(CpuTimes::read(Some(0)).is_some());
        }
    }
}
