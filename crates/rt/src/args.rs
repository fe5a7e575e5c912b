//! The command-line pieces every real-time process of hcc shares: where it
//! meets its peers ([`IpcArgs`]) and how its loop thread is set up
//! ([`RtArgs`]), both flattened into each process's own clap arguments, and
//! how a usage error ends the process ([`parse_args`]).

use std::ffi::OsString;
use std::process::ExitCode;

/// The IPC namespace and the iceoryx2 file prefix of a process.
// The help texts name the scenario's TOML tables as [table] and placeholders as
// <name>: neither an intra-doc link nor HTML.
#[allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct IpcArgs {
    /// IPC namespace (overrides [ipc].namespace of the scenario).
    #[arg(long)]
    pub namespace: Option<String>,
    /// Prefix of the shared-memory files (default: the HCC_IPC_FILE_PREFIX
    /// environment variable, else iceoryx2's default). All peers must agree.
    #[arg(long)]
    pub file_prefix: Option<String>,
}

impl IpcArgs {
    /// The namespace: `--namespace`, else `scenario_default` (the scenario's
    /// `[ipc] namespace`).
    pub fn namespace_or<'a>(&'a self, scenario_default: &'a str) -> &'a str {
        self.namespace.as_deref().unwrap_or(scenario_default)
    }

    /// The file prefix: `--file-prefix`, else `HCC_IPC_FILE_PREFIX`, else none
    /// (iceoryx2's default).
    pub fn file_prefix(&self) -> Option<String> {
        self.file_prefix
            .clone()
            .or_else(hcc_msgs::ipc::file_prefix_from_env)
    }
}

/// How a process's loop thread is set up for real time ([`prepare_rt_thread`](crate::prepare_rt_thread)):
/// the same three options in the controller daemon, the simulator daemon and
/// every robot driver; each overrides the scenario's value where the process
/// has one.
// The help texts name the scenario's TOML tables as [table]: not an intra-doc link.
#[allow(rustdoc::broken_intra_doc_links)]
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct RtArgs {
    /// CPU core of the loop's thread (overrides the process's [..._daemon].cpu_core).
    #[arg(long)]
    pub cpu_core: Option<usize>,
    /// SCHED_FIFO priority 1..=99 of the loop's thread (overrides the
    /// process's [..._daemon].sched_priority); default: normal scheduling.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub sched_priority: Option<i32>,
    /// Lock memory (mlockall), as the process's [..._daemon].mlock = true.
    #[arg(long)]
    pub mlock: bool,
}

impl RtArgs {
    /// The loop thread's settings: these options over the scenario's
    /// `cpu_core`, `sched_priority` and `mlock` of the process (`None`,
    /// `None`, `false` where it has none), with `prefault_stack_bytes` of
    /// the stack pre-faulted.
    pub fn settings(
        &self,
        cpu_core: Option<usize>,
        sched_priority: Option<i32>,
        mlock: bool,
        prefault_stack_bytes: usize,
    ) -> crate::RtSettings {
        crate::RtSettings {
            cpu_core: self.cpu_core.or(cpu_core),
            sched_priority: self.sched_priority.or(sched_priority),
            lock_memory: self.mlock || mlock,
            prefault_stack_bytes,
        }
    }
}

/// Parses a process's command line (program name first). On `--help` or
/// `--version` the text is printed and `Err(0)` returned; on a usage error the
/// message is printed and `Err(2)` returned — the exit code of the process.
pub fn parse_args<A, I, T>(args: I) -> Result<A, ExitCode>
where
    A: clap::Parser,
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    A::try_parse_from(args).map_err(|e| {
        let _ = e.print();
        if e.use_stderr() {
            ExitCode::from(2)
        } else {
            ExitCode::SUCCESS
        }
    })
}

/// The `main` of a process: parses `args` ([`parse_args`]), calls `run` with
/// them and maps its result to the exit code — 0 after a clean stop, 2 for an
/// error, which `log_error` reports first.
pub fn run_main<A, I, T, E>(
    args: I,
    run: impl FnOnce(A) -> Result<(), E>,
    log_error: impl FnOnce(&E),
) -> ExitCode
where
    A: clap::Parser,
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let args = match parse_args::<A, _, _>(args) {
        Ok(a) => a,
        Err(code) => return code,
    };
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            log_error(&e);
            ExitCode::from(2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Demo {
        #[command(flatten)]
        ipc: IpcArgs,
    }

    #[test]
    fn ipc_options_parse_and_default() {
        let d = parse_args::<Demo, _, _>(["demo", "--namespace", "robot1"]).unwrap();
        assert_eq!(d.ipc.namespace_or("default"), "robot1");
        let d = parse_args::<Demo, _, _>(["demo", "--file-prefix", "p_"]).unwrap();
        assert_eq!(d.ipc.namespace_or("default"), "default");
        assert_eq!(d.ipc.file_prefix().as_deref(), Some("p_"));
        assert_eq!(
            parse_args::<Demo, _, _>(["demo", "--bogus"]).unwrap_err(),
            ExitCode::from(2)
        );
    }

    #[test]
    fn run_main_maps_the_result_to_the_exit_code() {
        let ok = run_main::<Demo, _, _, String>(["demo"], |_| Ok(()), |_| {});
        assert_eq!(ok, ExitCode::SUCCESS);
        let mut logged = String::new();
        let failed = run_main::<Demo, _, _, String>(
            ["demo"],
            |_| Err("no robot".to_string()),
            |e| logged = e.clone(),
        );
        assert_eq!((failed, logged.as_str()), (ExitCode::from(2), "no robot"));
    }
}
