//! What the simulator's IPC tests share.

use hcc_msgs::ipc;

/// Removes iceoryx2's global management files under `prefix` (a test's own
/// file prefix) and asserts that nothing else is left behind in shared memory.
pub fn assert_no_leftover_files(prefix: &str) {
    let files = ipc::leftover_files(prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    let rest: Vec<_> = files.iter().filter(|f| !f.global_mgmt).collect();
    assert!(rest.is_empty(), "shared-memory files left behind: {rest:?}");
}
