//! Lockstep with a recorder (`--lockstep-recorder`): the simulator publishes
//! state k only once the recorder of `hcc run` has taken state
//! k − [`RECORDER_LEAD`], so that nothing the recorder has not taken is
//! more than its queues hold (`hcc_msgs::ipc::RecorderProgressPublisher`). A recorder that says nothing for the lockstep
//! timeout is no longer waited for (the run goes on; counted and logged).

use hcc_msgs::ServiceNames;
use hcc_msgs::ipc::{IpcError, IpcNode, RECORDER_LEAD, RecorderProgressSubscriber};
use hcc_msgs::monotonic_now_ns;
use hcc_rt as rt;

/// How often the wait looks at the recorder's progress, ns.
const POLL_NS: u64 = 50_000;

/// What the waits for the recorder came to.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct RecorderWaitCounts {
    /// States whose publication waited for the recorder.
    pub waits: u64,
    /// The longest of those waits, ns.
    pub longest_ns: u64,
    /// The recorder fell silent for the timeout and was no longer waited for.
    pub abandoned: bool,
}

/// The simulator's view of the recorder (module docs).
pub struct RecorderWait {
    progress: RecorderProgressSubscriber,
    counts: RecorderWaitCounts,
}

impl RecorderWait {
    /// Subscribes to the recorder's progress in `names` (at start-up).
    pub fn open(node: &IpcNode, names: &ServiceNames) -> Result<RecorderWait, IpcError> {
        Ok(RecorderWait {
            progress: RecorderProgressSubscriber::open(node, names)?,
            counts: RecorderWaitCounts::default(),
        })
    }

    /// What the waits came to so far.
    pub fn counts(&self) -> RecorderWaitCounts {
        self.counts
    }

    /// Before state `k` is published: waits until the recorder has taken
    /// state k − [`RECORDER_LEAD`], a stop is requested, or the recorder
    /// made no progress for `timeout_ns` (then it is abandoned: not waited
    /// for again). Allocation-free.
    pub fn before_publish(&mut self, k: u64, timeout_ns: u64) {
        if self.counts.abandoned {
            return;
        }
        let needed = k.saturating_sub(RECORDER_LEAD);
        let mut taken = self.progress.states_taken();
        if taken >= needed {
            return;
        }
        self.counts.waits += 1;
        let start = monotonic_now_ns();
        let mut last_progress = start;
        while taken < needed {
            if rt::stop_requested() {
                break;
            }
            let now = monotonic_now_ns();
            if now.saturating_sub(last_progress) >= timeout_ns {
                self.counts.abandoned = true;
                break;
            }
            rt::sleep_until_ns(now + POLL_NS);
            let newer = self.progress.states_taken();
            if newer != taken {
                last_progress = monotonic_now_ns();
                taken = newer;
            }
        }
        let waited = monotonic_now_ns().saturating_sub(start);
        self.counts.longest_ns = self.counts.longest_ns.max(waited);
    }
}
