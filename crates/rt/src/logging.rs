//! The logging set-up of every hcc process (the daemons, the drivers, the
//! `hcc` command): `tracing` events to stderr, one line each, as
//!
//! ```text
//! <process>: message
//! <process>: warning: message
//! <process>: error: message
//! ```
//!
//! with no timestamp, no colours and no module path, filtered by `RUST_LOG`
//! (default `info`; directives it cannot parse are ignored). Log only from
//! threads that are not real-time: formatting allocates and writing blocks.
//! A real-time loop raises counters and flags instead, and a logging thread
//! reports them.

use std::fmt;

use tracing::{Event, Level, Subscriber};
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields};
use tracing_subscriber::registry::LookupSpan;

/// Installs the process's subscriber: stderr, `RUST_LOG` (default `info`),
/// every line prefixed `process: ` (see the module docs). Call once at
/// start-up; a second call, or a subscriber the embedding program set
/// already, is ignored.
pub fn init_logging(process: &'static str) {
    let filter = tracing_subscriber::EnvFilter::builder()
        .with_default_directive(tracing_subscriber::filter::LevelFilter::INFO.into())
        .from_env_lossy();
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .event_format(Prefixed(process))
        .try_init();
}

/// The line format: `process: [warning: |error: |debug: |trace: ]message`.
struct Prefixed(&'static str);

/// The word a level's lines carry after the prefix (none for `info`).
fn level_word(level: Level) -> &'static str {
    match level {
        Level::ERROR => "error: ",
        Level::WARN => "warning: ",
        Level::INFO => "",
        Level::DEBUG => "debug: ",
        Level::TRACE => "trace: ",
    }
}

impl<S, N> FormatEvent<S, N> for Prefixed
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &FmtContext<'_, S, N>,
        mut writer: Writer<'_>,
        event: &Event<'_>,
    ) -> fmt::Result {
        write!(
            writer,
            "{}: {}",
            self.0,
            level_word(*event.metadata().level())
        )?;
        ctx.field_format().format_fields(writer.by_ref(), event)?;
        writeln!(writer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn info_lines_carry_no_level_word_the_others_do() {
        assert_eq!(level_word(Level::INFO), "");
        assert_eq!(level_word(Level::WARN), "warning: ");
        assert_eq!(level_word(Level::ERROR), "error: ");
    }
}
