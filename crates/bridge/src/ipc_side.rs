//! The iceoryx2 side: a thread that subscribes to the joint states, torque
//! commands and telemetry of a namespace as a pure subscriber (like
//! `hcc record`), drains the queues every [`POLL`], counts what the queues
//! lost before it read them (sequence gaps), decimates each stream to the
//! bridge's rate by sequence number ([`Decimator`]) and hands the rest to the Zenoh side
//! through a bounded channel of [`BACKLOG`] samples. A full channel drops
//! the sample and counts it: nothing here ever waits for Zenoh, and the
//! daemons' publishers never wait for this thread (safe overflow).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::time::Duration;

use anyhow::{Context, bail};
use hcc_msgs::ipc::{self, MAX_SUBSCRIBER_BUFFER, Services};
use hcc_msgs::{
    Header, JointState, SeqEvent, SequenceChecker, ServiceNames, Telemetry, TorqueCommand,
};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::SignalHandlingMode;
use iceoryx2::prelude::ZeroCopySend;
use std::fmt::Debug;

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

/// One stream's bookkeeping: sequence checks and decimation.
struct Stream {
    checker: SequenceChecker,
    decimator: Decimator,
}

impl Stream {
    fn new(source_hz: f64, rate_hz: f64) -> Stream {
        Stream {
            checker: SequenceChecker::default(),
            decimator: Decimator::new(source_hz, rate_hz),
        }
    }

    /// Counts gaps; whether the sample passes the decimation.
    fn admit(&mut self, seq: u64, counters: &Counters) -> bool {
        // A restarted source starts the stream again.
        if let SeqEvent::Gap { missed } = self.checker.observe_restarting(seq) {
            add(&counters.ipc_lost, missed);
        }
        let pass = self.decimator.pass(seq);
        if !pass {
            bump(&counters.decimated);
        }
        pass
    }
}

struct Ports {
    states: ipc::StateSubscriber,
    commands: ipc::CommandSubscriber,
    telemetry: ipc::TelemetrySubscriber,
}

/// The reading thread's state.
struct Drain {
    ports: Ports,
    streams: [Stream; 3],
    tx: mpsc::SyncSender<Sample>,
    counters: Arc<Counters>,
}

impl Drain {
    /// Empties every queue once; returns how many samples were read.
    fn drain(&mut self) -> Result<usize, String> {
        let (p, [s, c, t]) = (&self.ports, &mut self.streams);
        let out = (&self.tx, &*self.counters);
        Ok(drain_port(
            &p.states,
            "joint_state",
            s,
            out,
            |x| &x.header,
            Sample::State,
        )? + drain_port(
            &p.commands,
            "torque_command",
            c,
            out,
            |x| &x.header,
            Sample::Command,
        )? + drain_port(
            &p.telemetry,
            "telemetry",
            t,
            out,
            |x| &x.header,
            Sample::Telemetry,
        )?)
    }
}

/// Empties one queue: counts every sample, checks its sequence, and hands
/// those that pass the decimation on (a full channel drops and counts).
fn drain_port<T: Debug + ZeroCopySend + Copy>(
    port: &Subscriber<ipc::Ipc, T, ()>,
    name: &str,
    stream: &mut Stream,
    (tx, counters): (&mpsc::SyncSender<Sample>, &Counters),
    header: impl Fn(&T) -> &Header,
    wrap: impl Fn(Box<T>) -> Sample,
) -> Result<usize, String> {
    let mut k = 0;
    while let Some(sample) = port.receive().map_err(|e| format!("{name}: {e:?}"))? {
        k += 1;
        bump(&counters.received);
        let h = header(&sample);
        if stream.admit(h.seq, counters)
            && let Err(mpsc::TrySendError::Full(_)) = tx.try_send(wrap(Box::new(*sample)))
        {
            bump(&counters.dropped_behind);
        }
    }
    Ok(k)
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
                let setup = || -> anyhow::Result<_> {
                    let node = ipc::create_node(
                        &node_name,
                        SignalHandlingMode::Disabled,
                        file_prefix.as_deref(),
                    )?;
                    let services = Services::open(&node, &names)?;
                    let ports = Ports {
                        states: services.joint_state_subscriber(MAX_SUBSCRIBER_BUFFER)?,
                        commands: services.torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)?,
                        telemetry: services.telemetry_subscriber(MAX_SUBSCRIBER_BUFFER)?,
                    };
                    Ok((node, services, ports))
                };
                let (node, services, ports) = match setup() {
                    Ok(x) => x,
                    Err(e) => {
                        let _ = ready_tx.send(Err(format!("{e:#}")));
                        return;
                    }
                };
                let _ = ready_tx.send(Ok(()));
                let mut drain = Drain {
                    ports,
                    streams: std::array::from_fn(|_| Stream::new(source_hz, rate_hz)),
                    tx,
                    counters,
                };
                while !stop_flag.load(Ordering::Relaxed) {
                    match drain.drain() {
                        Ok(k) if k >= MAX_SUBSCRIBER_BUFFER / 2 => {}
                        Ok(_) => std::thread::sleep(POLL),
                        Err(e) => {
                            let _ = drain.tx.send(Sample::Failed(e));
                            break;
                        }
                    }
                }
                drop(drain);
                drop(services);
                drop(node);
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
