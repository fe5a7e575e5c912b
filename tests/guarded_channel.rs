//! The guarded torque channel, with real processes: while `hcc-controller`
//! controls `hcc-sim`, a second controller (a second torque publisher) and a
//! second simulator (a second joint-state publisher) are refused by iceoryx2
//! (`max_publishers(1)`) and exit with a clear error; the running pair is
//! unaffected. The shared-memory resources are owner-only, and a process of
//! another user cannot open the namespace at all.

mod monitor;

use std::os::unix::fs::MetadataExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use hcc_msgs::{CommandMode, DriverStatus};
use hcc_system_tests::*;
use monitor::{Daemon, Monitor};

const LONG: Duration = Duration::from_secs(60);

fn config() -> PathBuf {
    repo_root().join("config/paper-sim1.toml")
}

/// Runs `binary CONFIG --namespace NS` to completion (it must fail at start-up).
fn intruder(
    binary: &str,
    ns: &str,
    prefix: &str,
    dir: &Path,
    tag: &str,
    uid: Option<u32>,
) -> Finished {
    let mut cmd = Command::new(bin(binary));
    cmd.env(FILE_PREFIX_ENV, prefix)
        .arg(config())
        .args(["--namespace", ns]);
    if binary == "hcc-sim" {
        cmd.args(["--realtime", "--duration", "1"]);
    }
    if let Some(uid) = uid {
        cmd.uid(uid).gid(uid);
    }
    run_with_timeout(&mut cmd, dir, tag, Duration::from_secs(30))
}

/// Every file and directory of `prefix` in /dev/shm and iceoryx2's directory, with its mode.
fn prefixed_files(prefix: &str) -> Vec<(PathBuf, u32, u32)> {
    let mut out = Vec::new();
    fn walk(dir: &Path, prefix: &str, recurse: bool, out: &mut Vec<(PathBuf, u32, u32)>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            // Another test's process may remove its files while this walks: skip what is gone.
            let Ok(meta) = e.metadata() else {
                continue;
            };
            if e.file_name().to_string_lossy().starts_with(prefix) {
                out.push((e.path(), meta.mode() & 0o7777, meta.uid()));
            }
            if recurse && meta.is_dir() {
                walk(&e.path(), prefix, true, out);
            }
        }
    }
    walk(Path::new("/dev/shm"), prefix, false, &mut out);
    walk(Path::new("/tmp/iceoryx2"), prefix, true, &mut out);
    out
}

fn wait_running(mon: &mut Monitor, from_telemetry: usize, cycles: usize) {
    mon.wait_until("the pair runs", LONG, |m| {
        m.telemetry[from_telemetry.min(m.telemetry.len())..]
            .iter()
            .filter(|t| !t.peer_lost && t.mode == CommandMode::Normal.code())
            .count()
            >= cycles
    });
}

#[test]
fn a_second_torque_publisher_is_refused_and_the_running_controller_is_unaffected() {
    let dir = TempDir::new("guarded");
    let ns = unique_namespace("guarded");
    let prefix = unique_file_prefix();
    {
        let mut mon = Monitor::new(&ns, &prefix);
        let mut ctl = Daemon::controller(&ns, &prefix, dir.path(), "controller");
        let mut sim = Daemon::sim(&ns, &prefix, dir.path(), "sim");
        wait_running(&mut mon, 0, 200);
        let commands_before = mon.commands.len();
        let telemetry_before = mon.telemetry.len();

        // A second controller process: refused by iceoryx2 at its torque publisher.
        let second = intruder(
            "hcc-controller",
            &ns,
            &prefix,
            dir.path(),
            "controller2",
            None,
        );
        println!("second controller: {}", second.stderr.trim_end());
        assert_eq!(second.status.code(), Some(2), "{}", second.log());
        assert!(
            second
                .stderr
                .contains("torque_command already has a publisher")
                && second
                    .stderr
                    .contains("is another controller running in this namespace?"),
            "{}",
            second.log()
        );
        assert!(!second.stderr.contains("panicked"), "{}", second.log());
        // A second simulator: refused at the joint-state publisher.
        let second_sim = intruder("hcc-sim", &ns, &prefix, dir.path(), "sim2", None);
        println!("second simulator: {}", second_sim.stderr.trim_end());
        assert_eq!(second_sim.status.code(), Some(2), "{}", second_sim.log());
        assert!(
            second_sim
                .stderr
                .contains("joint_state already has a publisher"),
            "{}",
            second_sim.log()
        );
        // And in this process too.
        let err = mon.services().torque_command_publisher().unwrap_err();
        assert!(
            err.to_string()
                .contains("torque_command already has a publisher"),
            "{err}"
        );

        // The running pair is unaffected: the commands still come from one
        // publisher (one unbroken sequence), every one a normal answer, and
        // the simulator keeps applying them.
        wait_running(&mut mon, telemetry_before, 300);
        let commands = &mon.commands[commands_before..];
        assert!(commands.len() > 100);
        for w in mon.commands.windows(2) {
            assert_eq!(w[1].header.seq, w[0].header.seq + 1, "one command stream");
        }
        assert!(
            commands
                .iter()
                .all(|c| c.mode == CommandMode::Normal.code())
        );
        let last = mon.last_telemetry().unwrap().counters;
        assert_eq!(
            (
                last.invalid_states,
                last.sequence_errors,
                last.send_failures
            ),
            (0, 0, 0),
            "{last:?}"
        );
        assert!(ctl.running() && sim.running());
        // Still applying commands (a state after a command missed under load
        // reports the fallback: not every one of the last need be Ok).
        assert!(
            mon.states
                .iter()
                .rev()
                .take(100)
                .any(|s| s.status == DriverStatus::Ok.code()),
            "the simulator applies no command any more"
        );
        sim.stop();
        ctl.stop();
    }
    assert_clean(&ns, &prefix);
}

#[test]
fn shared_memory_is_owner_only_and_another_user_cannot_open_the_namespace() {
    let dir = TempDir::new("owner_only");
    let ns = unique_namespace("owner_only");
    let prefix = unique_file_prefix();
    {
        let mut mon = Monitor::new(&ns, &prefix);
        let mut ctl = Daemon::controller(&ns, &prefix, dir.path(), "controller");
        let mut sim = Daemon::sim(&ns, &prefix, dir.path(), "sim");
        wait_running(&mut mon, 0, 200);

        // Every resource of the namespace: owned by this user, no access for
        // group or others on files (directories may be listed, not written).
        let me = unsafe { libc::geteuid() };
        let files = prefixed_files(&prefix);
        assert!(files.len() > 10, "{files:?}");
        let mut shm = 0;
        for (path, mode, uid) in &files {
            assert_eq!(*uid, me, "{} is owned by uid {uid}", path.display());
            if path.to_string_lossy().ends_with(".global_mgmt") {
                // iceoryx2's per-prefix node counter (4 bytes, used to make
                // node ids unique) is world read-writable by design; it holds
                // nothing of the robot's services.
                continue;
            }
            if path.is_dir() {
                assert_eq!(
                    mode & 0o022,
                    0,
                    "{} is writable by others: {mode:o}",
                    path.display()
                );
            } else {
                assert_eq!(
                    mode & 0o077,
                    0,
                    "{} is accessible to others: {mode:o}",
                    path.display()
                );
            }
            shm += usize::from(path.starts_with("/dev/shm"));
        }
        println!(
            "{} resources ({shm} shared-memory segments), all owner-only",
            files.len()
        );

        // A process of another user: refused when it opens the namespace.
        if me == 0 {
            let telemetry_before = mon.telemetry.len();
            for (binary, tag) in [
                ("hcc-controller", "other_user_controller"),
                ("hcc-sim", "other_user_sim"),
            ] {
                let other = intruder(binary, &ns, &prefix, dir.path(), tag, Some(65534));
                println!("{binary} as uid 65534: {}", other.stderr.trim_end());
                assert_eq!(other.status.code(), Some(2), "{}", other.log());
                assert!(other.stderr.contains("permission"), "{}", other.log());
                assert!(!other.stderr.contains("panicked"), "{}", other.log());
            }
            wait_running(&mut mon, telemetry_before, 200);
            let c = mon.last_telemetry().unwrap().counters;
            assert_eq!((c.invalid_states, c.sequence_errors), (0, 0), "{c:?}");
        } else {
            println!(
                "not root: the other-user check needs to start a process as another user; skipped"
            );
        }
        assert!(ctl.running() && sim.running());
        sim.stop();
        ctl.stop();
    }
    assert_clean(&ns, &prefix);
}
