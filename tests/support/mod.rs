//! Helpers shared by the system tests: locating the built binaries, per-test
//! output directories and IPC namespaces, and child processes that are always
//! stopped when a test ends (even when it fails).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// Root of the repository (where `Cargo.toml` of the workspace lives).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Path of a binary of this workspace, built by `cargo build --workspace --bins`
/// into the same profile directory as the test executable.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test-exe> -> target/<profile>/<name>
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target profile directory");
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} not found: build the binaries first (cargo build --workspace --bins)",
        path.display()
    );
    path
}

/// A namespace no other test (in this or a parallel test process) uses.
pub fn unique_namespace(test: &str) -> String {
    static COUNTER: AtomicU32 = AtomicU32::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let clean: String = test
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    format!("t_{clean}_{}_{n}", std::process::id())
}

/// A fresh output directory under the target directory, removed when dropped.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(test: &str) -> TempDir {
        let base = std::env::var_os("CARGO_TARGET_TMPDIR")
            .map(PathBuf::from)
            .unwrap_or_else(std::env::temp_dir);
        let dir = base.join(unique_namespace(test));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create test directory");
        TempDir(dir)
    }
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A child process that is killed (by its own pid) and reaped when dropped.
pub struct ChildGuard {
    pub child: Child,
}

impl ChildGuard {
    pub fn spawn(cmd: &mut Command) -> ChildGuard {
        let child = cmd
            .stdin(Stdio::null())
            .spawn()
            .expect("spawn child process");
        ChildGuard { child }
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Waits up to `timeout` for the child to exit; `None` if it is still running.
    pub fn wait_timeout(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        let start = Instant::now();
        loop {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            if start.elapsed() > timeout {
                return None;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Sends SIGKILL to the child (it cannot clean up: a crash).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

/// Reads a CSV file written by `hcc simulate` / `hcc run` into (header, rows).
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("read {}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .expect("CSV header")
        .split(',')
        .map(|s| s.trim().to_string())
        .collect();
    let rows = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|v| v.trim().parse::<f64>().expect("CSV number"))
                .collect()
        })
        .collect();
    (header, rows)
}

/// Reads a JSON file.
pub fn read_json(path: &Path) -> serde_json::Value {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("parse {}: {e}", path.display()))
}

/// A unique iceoryx2 file prefix for one test (at most 32 characters of
/// `[A-Za-z0-9_]`, ending in '_'), passed to the binaries through
/// `HCC_IPC_FILE_PREFIX` so that tests never see each other's shared memory.
pub fn unique_file_prefix() -> String {
    static COUNTER: AtomicU32 = AtomicU32::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    format!("hcct{}x{n}_", std::process::id())
}

/// Environment variable that carries the iceoryx2 file prefix to the binaries.
pub const FILE_PREFIX_ENV: &str = "HCC_IPC_FILE_PREFIX";

fn collect_prefixed(dir: &Path, prefix: &str, recurse: bool, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if entry.file_name().to_string_lossy().starts_with(prefix) {
            out.push(path.clone());
        }
        if recurse && entry.file_type().map(|t| t.is_dir()).unwrap_or(false) {
            collect_prefixed(&path, prefix, true, out);
        }
    }
}

/// Files that iceoryx2 left under `prefix` (shared memory and its bookkeeping
/// directory), except the per-prefix `global_mgmt` segment it keeps by
/// design; that one is deleted here.
pub fn ipc_leftovers(prefix: &str) -> Vec<PathBuf> {
    let mut found = Vec::new();
    collect_prefixed(Path::new("/dev/shm"), prefix, false, &mut found);
    collect_prefixed(Path::new("/tmp/iceoryx2"), prefix, true, &mut found);
    let (mgmt, rest): (Vec<_>, Vec<_>) = found
        .into_iter()
        .partition(|p| p.to_string_lossy().ends_with("global_mgmt"));
    for p in mgmt {
        let _ = std::fs::remove_file(p);
    }
    rest
}

/// Pids of running processes whose command line contains `needle` (e.g. a
/// test's namespace), other than this test process.
pub fn processes_with(needle: &str) -> Vec<(u32, String)> {
    let me = std::process::id();
    let mut found = Vec::new();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return found;
    };
    for entry in entries.flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        if pid == me {
            continue;
        }
        let Ok(raw) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let cmdline = String::from_utf8_lossy(&raw).replace('\0', " ");
        // Zombies have an empty command line; they are reaped by their parent.
        if cmdline.contains(needle) {
            found.push((pid, cmdline));
        }
    }
    found
}

/// Output of a finished command.
pub struct Finished {
    pub status: std::process::ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

impl Finished {
    /// Both outputs, for assertion messages.
    pub fn log(&self) -> String {
        format!(
            "status {:?}\n--- stdout ---\n{}\n--- stderr ---\n{}",
            self.status, self.stdout, self.stderr
        )
    }
}

/// Runs `cmd` with stdout/stderr redirected to files in `dir` (so that a
/// chatty child never blocks on a full pipe); kills it after `timeout`.
pub fn run_with_timeout(cmd: &mut Command, dir: &Path, tag: &str, timeout: Duration) -> Finished {
    let out_path = dir.join(format!("{tag}.stdout"));
    let err_path = dir.join(format!("{tag}.stderr"));
    let out = std::fs::File::create(&out_path).expect("create stdout file");
    let err = std::fs::File::create(&err_path).expect("create stderr file");
    let mut guard = ChildGuard::spawn(cmd.stdout(out).stderr(err));
    let status = match guard.wait_timeout(timeout) {
        Some(s) => s,
        None => {
            // Let it stop its children first, then make sure it is gone.
            let _ = Command::new("kill")
                .args(["-TERM", &guard.pid().to_string()])
                .status();
            let s = guard.wait_timeout(Duration::from_secs(10));
            guard.kill();
            panic!(
                "{tag} did not finish within {} s (terminated: {s:?}); stderr:\n{}",
                timeout.as_secs(),
                std::fs::read_to_string(&err_path).unwrap_or_default()
            );
        }
    };
    Finished {
        status,
        stdout: std::fs::read_to_string(&out_path).unwrap_or_default(),
        stderr: std::fs::read_to_string(&err_path).unwrap_or_default(),
    }
}

/// After a test: no process of `namespace` may be left, and no iceoryx2 file
/// of `prefix` (waits briefly for exiting processes).
pub fn assert_clean(namespace: &str, prefix: &str) {
    let start = Instant::now();
    loop {
        let procs = processes_with(namespace);
        if procs.is_empty() {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "processes left behind: {procs:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let files = ipc_leftovers(prefix);
    assert!(files.is_empty(), "iceoryx2 files left behind: {files:?}");
}

/// Largest |a − b| over two CSV tables with the same header; panics with the
/// column name if the shapes differ. Returns (max difference, its column, its row).
pub fn max_csv_difference(
    a: &(Vec<String>, Vec<Vec<f64>>),
    b: &(Vec<String>, Vec<Vec<f64>>),
) -> (f64, String, usize) {
    assert_eq!(a.0, b.0, "the CSV headers differ");
    assert_eq!(
        a.1.len(),
        b.1.len(),
        "the CSV tables have {} and {} rows",
        a.1.len(),
        b.1.len()
    );
    let mut worst = (0.0_f64, String::new(), 0);
    for (i, (ra, rb)) in a.1.iter().zip(&b.1).enumerate() {
        for (j, (x, y)) in ra.iter().zip(rb).enumerate() {
            // One NaN against a number counts as an infinite difference.
            let d = match (x.is_nan(), y.is_nan()) {
                (true, true) => 0.0,
                (false, false) => (x - y).abs(),
                _ => f64::INFINITY,
            };
            if d > worst.0 {
                worst = (d, a.0[j].clone(), i);
            }
        }
    }
    worst
}

/// A copy of a scenario of `config/` written into `dir`, with its robot path
/// made absolute and `extra` TOML appended; returns the new file.
pub fn scenario_copy(name: &str, dir: &Path, extra: &str) -> PathBuf {
    let src = repo_root().join("config").join(name);
    let text = std::fs::read_to_string(&src).unwrap_or_else(|e| panic!("{}: {e}", src.display()));
    let mut out = String::new();
    for line in text.lines() {
        let trimmed = line.trim_start();
        if let Some(rest) = trimmed.strip_prefix("urdf") {
            let value = rest.trim_start().trim_start_matches('=').trim();
            let rel = value.trim_matches('"');
            let abs = repo_root().join("config").join(rel);
            out.push_str(&format!("urdf = {:?}\n", abs.display().to_string()));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    out.push_str(extra);
    let path = dir.join(name);
    std::fs::write(&path, out).expect("write scenario copy");
    path
}
