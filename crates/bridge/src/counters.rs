//! The bridge's own counters, shared by its threads (relaxed atomics: each
//! is a total, read for telemetry and the final summary).

use std::sync::atomic::{AtomicU64, Ordering};

macro_rules! bridge_counters {
    ($( $(#[doc = $doc:literal])* $field:ident ),+ $(,)?) => {
        /// Totals since the bridge started.
        #[derive(Debug, Default)]
        pub struct Counters {
            $( $(#[doc = $doc])* pub $field: AtomicU64, )+
        }

        impl Counters {
            /// Number of counters.
            pub const COUNT: usize = [$(stringify!($field)),+].len();

            /// (name, value) of every counter, the names prefixed `bridge_`
            /// as they appear in the telemetry message.
            pub fn snapshot(&self) -> [(&'static str, u64); Self::COUNT] {
                [$((concat!("bridge_", stringify!($field)), self.$field.load(Ordering::Relaxed))),+]
            }
        }
    };
}

bridge_counters! {
    /// Samples read from iceoryx2 (joint states, torque commands, telemetry).
    received,
    /// Samples lost in the iceoryx2 queues before the bridge read them
    /// (sequence gaps; the publishers never wait for the bridge).
    ipc_lost,
    /// Samples left out by the decimation to `--rate`.
    decimated,
    /// Samples dropped because the Zenoh side was behind (its queue full).
    dropped_behind,
    /// Samples published on Zenoh.
    published,
    /// Zenoh publications that failed.
    publish_errors,
    /// Goal messages received from Zenoh.
    goals_received,
    /// Goals refused: the bridge is read-only.
    goals_refused_read_only,
    /// Goals refused: over the setpoint rate cap.
    goals_refused_rate,
    /// Goals refused: unreadable, wrong frame, type, length or values.
    goals_refused_bad,
    /// Goals sent to the controller as setpoints.
    goals_forwarded,
    /// Forwarded goals the controller accepted.
    goals_accepted,
    /// Forwarded goals the controller rejected.
    goals_rejected,
}

/// Adds one to `c`.
pub fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

/// Adds `n` to `c`.
pub fn add(c: &AtomicU64, n: u64) {
    c.fetch_add(n, Ordering::Relaxed);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snapshot_names_and_values() {
        let c = Counters::default();
        bump(&c.goals_refused_rate);
        add(&c.published, 5);
        let s = c.snapshot();
        assert_eq!(s.len(), Counters::COUNT);
        assert!(s.contains(&("bridge_goals_refused_rate", 1)));
        assert!(s.contains(&("bridge_published", 5)));
        assert!(s.iter().all(|(n, _)| n.starts_with("bridge_")));
    }
}
