//! How a real-time loop waits for its next deadline or event.

use crate::sleep::{HYBRID_LEAD_NS, sleep_until_hybrid_with, sleep_until_ns};

/// How a loop waits: the `wait_strategy` of the scenario TOML
/// (`[controller_daemon]`, lowercase) and the `--wait` option of the daemons.
///
/// * `event`: sleep to the deadline (`clock_nanosleep`, [`sleep_until_ns`])
///   and block on the IPC event; no CPU used while waiting, but the wake-up is
///   as late as the kernel makes it (tens of µs).
/// * `hybrid`: sleep until [`HYBRID_LEAD_NS`] before the deadline, then spin
///   on the clock to it ([`crate::sleep_until_hybrid_ns`]); loops that wait for an
///   answer poll for it a while before they block. Precise to a few µs at the
///   cost of a busy core for part of the period.
///
/// The default is `hybrid` (the controller daemon's default; the simulator
/// daemon's `--wait` defaults to `event`).
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Deserialize,
    serde::Serialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum WaitStrategy {
    /// Sleep to the deadline; block on the IPC event.
    Event,
    /// Sleep until shortly before the deadline, then spin; poll, then block.
    #[default]
    Hybrid,
}

/// A wait strategy's name that is not one (`WaitStrategy::from_str`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownWaitStrategy(pub String);

impl std::fmt::Display for UnknownWaitStrategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "unknown wait strategy {:?} (event or hybrid)", self.0)
    }
}

impl std::error::Error for UnknownWaitStrategy {}

impl std::str::FromStr for WaitStrategy {
    type Err = UnknownWaitStrategy;

    /// `event` or `hybrid` (lowercase, as in the TOML and on the command line).
    fn from_str(name: &str) -> Result<Self, Self::Err> {
        match name {
            "event" => Ok(WaitStrategy::Event),
            "hybrid" => Ok(WaitStrategy::Hybrid),
            _ => Err(UnknownWaitStrategy(name.to_string())),
        }
    }
}

impl WaitStrategy {
    /// The name used in the TOML, on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            WaitStrategy::Event => "event",
            WaitStrategy::Hybrid => "hybrid",
        }
    }

    /// Waits for the `CLOCK_MONOTONIC` time `deadline_ns` this way
    /// ([`sleep_until_ns`] or [`crate::sleep_until_hybrid_ns`] with
    /// [`HYBRID_LEAD_NS`]). Allocation-free.
    pub fn sleep_until(self, deadline_ns: u64) {
        self.sleep_until_with(deadline_ns, || {});
    }

    /// [`WaitStrategy::sleep_until`] that calls `idle` before sleeping and,
    /// for `hybrid`, on every pass of the spin ([`sleep_until_hybrid_with`]).
    pub fn sleep_until_with(self, deadline_ns: u64, mut idle: impl FnMut()) {
        match self {
            WaitStrategy::Event => {
                idle();
                sleep_until_ns(deadline_ns)
            }
            WaitStrategy::Hybrid => sleep_until_hybrid_with(deadline_ns, HYBRID_LEAD_NS, idle),
        }
    }
}

impl std::fmt::Display for WaitStrategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    #[derive(serde::Deserialize)]
    struct Section {
        #[serde(default)]
        wait_strategy: WaitStrategy,
    }

    #[test]
    fn parses_from_toml_in_lowercase() {
        let s: Section = toml::from_str("wait_strategy = \"event\"").unwrap();
        assert_eq!(s.wait_strategy, WaitStrategy::Event);
        let s: Section = toml::from_str("wait_strategy = \"hybrid\"").unwrap();
        assert_eq!(s.wait_strategy, WaitStrategy::Hybrid);
        let s: Section = toml::from_str("").unwrap();
        assert_eq!(s.wait_strategy, WaitStrategy::Hybrid);
        assert!(toml::from_str::<Section>("wait_strategy = \"spin\"").is_err());
        assert!(toml::from_str::<Section>("wait_strategy = \"Event\"").is_err());
        // The names as the scenario's [controller_daemon] holds them.
        assert_eq!("event".parse(), Ok(WaitStrategy::Event));
        assert_eq!("hybrid".parse(), Ok(WaitStrategy::Hybrid));
        let e = "spin".parse::<WaitStrategy>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown wait strategy \"spin\" (event or hybrid)"
        );
    }

    #[test]
    fn parses_from_the_command_line_and_names_itself() {
        #[derive(clap::Parser)]
        struct Cli {
            #[arg(long, value_enum, default_value_t = WaitStrategy::Event)]
            wait: WaitStrategy,
        }
        use clap::Parser;
        assert_eq!(Cli::parse_from(["x"]).wait, WaitStrategy::Event);
        assert_eq!(
            Cli::parse_from(["x", "--wait", "hybrid"]).wait,
            WaitStrategy::Hybrid
        );
        assert!(Cli::try_parse_from(["x", "--wait", "spin"]).is_err());
        for w in WaitStrategy::value_variants() {
            let value = w.to_possible_value().unwrap();
            assert_eq!(value.get_name(), w.name());
            assert_eq!(w.to_string(), w.name());
        }
    }
}
