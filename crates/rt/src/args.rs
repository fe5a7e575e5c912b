//! The command-line pieces every real-time process of hcc shares: where it
//! meets its peers ([`IpcArgs`], flattened into each process's own clap
//! arguments) and how a usage error ends the process ([`parse_args`]).

use std::ffi::OsString;
use std::process::ExitCode;

/// The IPC namespace and the iceoryx2 file prefix of a process.
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
}
