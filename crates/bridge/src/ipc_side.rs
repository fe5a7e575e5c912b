//! The iceoryx2 side: a thread that subscribes to the joint states, torque
//! commands and telemetry of a namespace through a tap (`hcc_msgs::ipc::Tap`,
//! as `hcc record` and `hcc view` do), drains the queues every [`POLL`],
//! counts what the queues lost before it read them (sequence gaps), decimates each stream to the
//! bridge's rate by sequence number ([`Decimator`]) and hands the rest to the Zenoh side
//! through a bounded channel of [`BACKLOG`] samples. A full channel drops
//! the sample and counts it: nothing here ever waits for Zenoh, and the
//! daemons' publishers never wait for this thread (safe overflow).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::time::Duration;

use anyhow::{Context, bail};
use hcc_msgs::ipc::{TAP_BURST, TapNode, TapStreams, Tapped};
use hcc_msgs::{JointState, ServiceNames, Telemetry, TorqueCommand};

use crate::counters::{Counters, add, bump};
use crate::rate::Decimator;

/// Sleep between two drains of the queues (a queue holds 128 ms at 1 kHz).
pub const POLL: Duration = Duration::from_millis(1);
/// Samples that may wait for the Zenoh side (one second at 1 kHz of the
/// three streams).
pub const BACKLOG: usize = 3_000;

/// A decimated sample on its way to Zenoh.
pub enum Sample {
    /// A joint state.
    State(Box<JointState>),
    /// A torque command.
    Command(Box<TorqueCommand>),
    /// A telemetry sample.
    Telemetry(Box<Telemetry>),
    /// The reader failed and stopped.
    Failed(String),
}

/// The reading thread's state: the tap, one decimator per stream, the
/// channel to the Zenoh side.
struct Drain {
    tap: TapNode,
    /// The joint states', torque commands' and telemetry's decimators.
    decimators: [Decimator; 3],
    tx: mpsc::SyncSender<Sample>,
    counters: Arc<Counters>,
    /// The tap's gaps already added to `ipc_lost`.
    lost: u64,
}

impl Drain {
    /// Empties every queue once: counts every sample, and hands those that
    /// pass the decimation on (a full channel drops and counts). Returns the
    /// most samples one queue held.
    fn drain(&mut self) -> Result<usize, String> {
        let (decimators, tx, counters) = (&mut self.decimators, &self.tx, &*self.counters);
        let most = self
            .tap
            .tap()
            .drain(&mut |m| {
                bump(&counters.received);
                let (k, seq, sample) = match m {
                    Tapped::State(s) => (0, s.header.seq, Sample::State(Box::new(*s))),
                    Tapped::Command(c) => (1, c.header.seq, Sample::Command(Box::new(*c))),
                    Tapped::Telemetry(t) => (2, t.header.seq, Sample::Telemetry(Box::new(*t))),
                    // A loop tap reads no client message.
                    Tapped::Setpoint(_) | Tapped::Path(_) | Tapped::Load(_) => return,
                };
                if !decimators[k].pass(seq) {
                    bump(&counters.decimated);
                } else if let Err(mpsc::TrySendError::Full(_)) = tx.try_send(sample) {
                    bump(&counters.dropped_behind);
                }
            })
            .map_err(|e| e.to_string())?;
        // The queues' losses, counted by the tap (a restarted source starts
        // its stream again).
        let lost = self.tap.tap().counts().missed();
        add(&self.counters.ipc_lost, lost - self.lost);
        self.lost = lost;
        Ok(most)
    }
}

/// The running reader.
pub struct IpcReader {
    handle: Option<std::thread::JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    /// The decimated samples.
    pub rx: mpsc::Receiver<Sample>,
}

impl IpcReader {
    /// Subscribes on a new thread (node `node_name`) and returns once the
    /// subscribers exist.
    pub fn start(
        node_name: &str,
        file_prefix: Option<String>,
        names: ServiceNames,
        (source_hz, rate_hz): (f64, f64),
        counters: Arc<Counters>,
    ) -> anyhow::Result<IpcReader> {
        let (tx, rx) = mpsc::sync_channel(BACKLOG);
        let (ready_tx, ready_rx) = mpsc::sync_channel::<Result<(), String>>(1);
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = stop.clone();
        let node_name = node_name.to_string();
        let handle = std::thread::Builder::new()
            .name("hcc-bridge-ipc".into())
            .spawn(move || {
                let tap = match TapNode::open(
                    &node_name,
                    file_prefix.as_deref(),
                    &names,
                    TapStreams::Loop,
                ) {
                    Ok(t) => t,
                    Err(e) => {
                        let _ = ready_tx.send(Err(e.to_string()));
                        return;
                    }
                };
                let _ = ready_tx.send(Ok(()));
                let mut drain = Drain {
                    tap,
                    decimators: std::array::from_fn(|_| Decimator::new(source_hz, rate_hz)),
                    tx,
                    counters,
                    lost: 0,
                };
                while !stop_flag.load(Ordering::Relaxed) {
                    match drain.drain() {
                        Ok(k) if k >= TAP_BURST => {}
                        Ok(_) => std::thread::sleep(POLL),
                        Err(e) => {
                            let _ = drain.tx.send(Sample::Failed(e));
                            break;
                        }
                    }
                }
                drop(drain);
            })
            .context("cannot start the iceoryx2 reader thread")?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(IpcReader {
                handle: Some(handle),
                stop,
                rx,
            }),
            Ok(Err(e)) => {
                let _ = handle.join();
                bail!(e)
            }
            Err(_) => bail!("the iceoryx2 reader thread ended during start-up"),
        }
    }
}

impl Drop for IpcReader {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}
