//! `hcc run --view`: the `hcc view` child starts beside the daemons, serves
//! on its port while the run goes on, and is stopped with them on every way
//! the run ends — a finished run, and Ctrl-C — leaving no process, no
//! listening port and no shared memory behind.

use hcc_system_tests::*;
use std::net::TcpStream;
use std::process::Command;
use std::time::{Duration, Instant};

/// Starts `hcc run --view --view-port 0 --duration DURATION`; returns the
/// run, its stderr file and the port the view printed.
fn start(
    dir: &TempDir,
    namespace: &str,
    prefix: &str,
    duration: &str,
) -> (ChildGuard, std::path::PathBuf, u16) {
    let err_path = dir.path().join("run.stderr");
    let mut run = ChildGuard::spawn(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .env(FILE_PREFIX_ENV, prefix)
            .args([
                "run",
                "config/paper-sim1.toml",
                "--duration",
                duration,
                "--no-plots",
            ])
            .args(["--namespace", namespace, "--view", "--view-port", "0"])
            .arg("--out")
            .arg(dir.path().join("run"))
            .stdout(std::fs::File::create(dir.path().join("run.stdout")).unwrap())
            .stderr(std::fs::File::create(&err_path).unwrap()),
    );
    let start = Instant::now();
    loop {
        let err = std::fs::read_to_string(&err_path).unwrap_or_default();
        if let Some(rest) = err.split("hcc view: ws://127.0.0.1:").nth(1) {
            let port = rest.split_whitespace().next().unwrap().parse().unwrap();
            return (run, err_path, port);
        }
        assert!(
            run.child.try_wait().unwrap().is_none(),
            "hcc run ended early:\n{err}"
        );
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no view address:\n{err}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn listening(port: u16) -> bool {
    TcpStream::connect(("127.0.0.1", port)).is_ok()
}

fn views_of(namespace: &str) -> Vec<(u32, String)> {
    processes_with(namespace)
        .into_iter()
        .filter(|(_, cmd)| cmd.contains(" view "))
        .collect()
}

/// After the run: nothing listens on the view's port, no process of the
/// namespace is left, and no shared memory.
fn assert_view_gone(port: u16, namespace: &str, prefix: &str) {
    assert!(!listening(port), "the view still listens after the run");
    assert!(views_of(namespace).is_empty(), "{:?}", views_of(namespace));
    assert_clean(namespace, prefix);
}

#[test]
fn the_view_stops_with_a_finished_run() {
    let dir = TempDir::new("run_view_finished");
    let namespace = unique_namespace("run_view_fin");
    let prefix = unique_file_prefix();
    let (mut run, err_path, port) = start(&dir, &namespace, &prefix, "2");
    assert!(listening(port), "nothing listens on the view's port");
    assert_eq!(
        views_of(&namespace).len(),
        1,
        "{:?}",
        processes_with(&namespace)
    );
    let status = run
        .wait_timeout(Duration::from_secs(120))
        .expect("the run did not end");
    let err = std::fs::read_to_string(&err_path).unwrap_or_default();
    assert!(status.success(), "{err}");
    assert_view_gone(port, &namespace, &prefix);
}

#[test]
fn the_view_stops_with_an_interrupted_run() {
    let dir = TempDir::new("run_view_interrupt");
    let namespace = unique_namespace("run_view_int");
    let prefix = unique_file_prefix();
    let (mut run, err_path, port) = start(&dir, &namespace, &prefix, "60");
    assert!(listening(port));
    let status = Command::new("kill")
        .args(["-INT", &run.pid().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let status = run
        .wait_timeout(Duration::from_secs(30))
        .expect("hcc run did not stop within 30 s of SIGINT");
    let err = std::fs::read_to_string(&err_path).unwrap_or_default();
    assert!(!status.success() && err.contains("interrupted"), "{err}");
    assert_view_gone(port, &namespace, &prefix);
}
