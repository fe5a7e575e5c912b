//! Every counter of the control cycle, defined once: those telemetry carries
//! ([`TelemetryCounters`], hcc-msgs) and the cycle's own ([`CoreCounters`]),
//! both with `hcc_msgs::define_counters!`. [`CycleCounters`] joins them in
//! one order, so that a daemon's shared atomics, its logs and its `--stats`
//! report follow a new counter without another edit.

use hcc_msgs::TelemetryCounters;

hcc_msgs::define_counters! {
    /// Counters of the cycle that telemetry does not carry (totals since start).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub struct CoreCounters {
        /// States whose control law failed numerically (answered with SafeHold).
        numerical_failures: "numerical failures of the control law (answered with SafeHold)",
        /// Peer restarts detected (a new stream after an outage, or rejected
        /// states that follow each other).
        peer_restarts: "new peer detected; sequence checker reset",
        /// Contacts detected (the contact flag rose; hcc-control's `contact`).
        contact_events: "contacts detected",
        /// Cycles with the contact flag set.
        contact_cycles: "cycles in contact",
        /// Cycles whose command the output stages' energy tank held back
        /// (what the saturation, the torque filter and the velocity limit
        /// would have fed in beyond what it pays: module `output_tank`).
        energy_held: "cycles held back by the output stages' energy tank",
        /// The energy the output stages fed in beyond what their tank held
        /// (mJ, total; H rose by it).
        energy_unpaid_mj: "energy fed in beyond the output stages' tank (mJ)",
        /// Paths sent at run time that reached their last knot and stopped
        /// there at rest (module `paths`).
        paths_stopped: "run-time paths that stopped on their last knot",
        /// Run-time path messages the feasibility check refused
        /// (`infeasible`; module `path_gate`).
        paths_infeasible: "run-time path messages refused as infeasible",
        /// Run-time path messages refused `unchecked`: no verdict within the
        /// timeout, or the check's queue full (module `path_gate`).
        paths_unchecked: "run-time path messages refused unchecked (the check too slow or full)",
        /// Setpoint streams (goal and velocity) that stopped: their velocity
        /// feed-forward faded to zero (module `setpoints`).
        streams_stopped: "setpoint streams that stopped (feed-forward faded)",
        /// Cycles in which a load's ramp held: the energy tanks could not
        /// pay the storage it adds (module `load_ramp`).
        load_ramp_held: "cycles a load's ramp held (the tanks could not pay it)",
        /// Level-cycles in which a gains transition held: the energy tanks
        /// could not pay the stiffening (module `setpoints`).
        gain_ramp_held: "level-cycles a gains transition held (the tanks could not pay it)",
        /// Level-cycles in which a goal transition's step held: neither the
        /// command tank nor the tanks' spare could pay its work (module
        /// `setpoints`).
        goal_ramp_held: "level-cycles a goal transition held (its command tank could not pay it)",
        /// The goals' work neither the command tank nor the tanks' spare
        /// paid (mJ, total; H rose by it).
        command_unpaid_mj: "goals' work beyond the command tank (mJ)",
        /// Cycles in which a contact reaction's return held: the energy
        /// tanks could not pay the springs' return (`soften`'s restore) or
        /// the law's share coming back (`hold`'s release; module `reaction`).
        reaction_restore_held: "cycles a contact reaction's restore or release held (the tanks could not pay it)",
    }
}

/// Every counter of the cycle: telemetry's, then the cycle's own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CycleCounters {
    /// The counters telemetry carries.
    pub telemetry: TelemetryCounters,
    /// The cycle's own counters.
    pub core: CoreCounters,
}

impl CycleCounters {
    /// Number of counters.
    pub const COUNT: usize = TelemetryCounters::COUNT + CoreCounters::COUNT;

    /// Name of counter `i` (telemetry's first).
    const fn name(i: usize) -> &'static str {
        if i < TelemetryCounters::COUNT {
            TelemetryCounters::NAMES[i]
        } else {
            CoreCounters::NAMES[i - TelemetryCounters::COUNT]
        }
    }

    /// Description of counter `i` (telemetry's first).
    const fn label(i: usize) -> &'static str {
        if i < TelemetryCounters::COUNT {
            TelemetryCounters::LABELS[i]
        } else {
            CoreCounters::LABELS[i - TelemetryCounters::COUNT]
        }
    }

    /// The values, telemetry's first, each in field order.
    pub fn values(&self) -> [u64; Self::COUNT] {
        let t = self.telemetry.values();
        let c = self.core.values();
        std::array::from_fn(|i| {
            if i < TelemetryCounters::COUNT {
                t[i]
            } else {
                c[i - TelemetryCounters::COUNT]
            }
        })
    }

    /// The counters from their values in the order of [`CycleCounters::values`].
    pub fn from_values(values: [u64; Self::COUNT]) -> CycleCounters {
        let (t, c) = values.split_at(TelemetryCounters::COUNT);
        CycleCounters {
            telemetry: TelemetryCounters::from_values(std::array::from_fn(|i| t[i])),
            core: CoreCounters::from_values(std::array::from_fn(|i| c[i])),
        }
    }

    /// (name, description, value) of every counter, telemetry's first.
    pub fn entries(&self) -> [(&'static str, &'static str, u64); Self::COUNT] {
        let values = self.values();
        std::array::from_fn(|i| (Self::name(i), Self::label(i), values[i]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_counter_round_trips_through_its_values_in_one_order() {
        let mut values = [0u64; CycleCounters::COUNT];
        for (i, v) in values.iter_mut().enumerate() {
            *v = 10 + i as u64;
        }
        let c = CycleCounters::from_values(values);
        assert_eq!(c.telemetry.cycles, 10);
        assert_eq!(c.telemetry.send_failures, 18);
        assert_eq!(c.telemetry.rate_limited, 19);
        assert_eq!(c.telemetry.low_passed, 20);
        assert_eq!(c.telemetry.velocity_limited, 21);
        assert_eq!(c.telemetry.velocity_limit_max_correction_mnm, 23);
        assert_eq!(c.core.numerical_failures, 24);
        assert_eq!(c.core.peer_restarts, 25);
        assert_eq!(c.values(), values);
        let entries = c.entries();
        assert_eq!(entries[0], ("cycles", "cycles", 10));
        assert_eq!(entries[15].0, "peer_restarts");
        assert!(entries[15].1.contains("new peer detected"));
        let names: Vec<_> = entries.iter().map(|e| e.0).collect();
        let mut unique = names.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "{names:?}");
    }
}
