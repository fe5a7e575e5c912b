//! SIGTERM and SIGINT set the stop flag, and a stop ends the sleeps early.
//! (Its own test binary: the flag is process-wide and stays set.)

use hcc_msgs::monotonic_now_ns;

#[test]
fn a_signal_requests_the_stop_and_ends_the_sleeps() {
    hcc_rt::install_stop_handler().unwrap();
    assert!(!hcc_rt::stop_requested());
    // A sleep interrupted by the signal returns once the stop is requested.
    let sleeper = std::thread::spawn(|| {
        let t0 = monotonic_now_ns();
        hcc_rt::sleep_until_ns(t0 + 20_000_000_000);
        monotonic_now_ns() - t0
    });
    std::thread::sleep(std::time::Duration::from_millis(50));
    // SAFETY: raising a signal whose handler was installed above.
    assert_eq!(unsafe { libc::raise(libc::SIGTERM) }, 0);
    assert!(hcc_rt::stop_requested());
    // The signal went to this thread; wake the sleeper with one of its own
    // (SIGINT, also handled) if it did not see it yet.
    use std::os::unix::thread::JoinHandleExt;
    // SAFETY: the thread is alive until joined below.
    unsafe { libc::pthread_kill(sleeper.as_pthread_t(), libc::SIGINT) };
    let slept = sleeper.join().unwrap();
    assert!(slept < 10_000_000_000, "slept {slept} ns after the stop");
    // The hybrid wait no longer spins once stopped.
    let t0 = monotonic_now_ns();
    hcc_rt::sleep_until_hybrid_ns(t0 + 5_000_000_000, 10_000_000_000);
    assert!(monotonic_now_ns() - t0 < 1_000_000_000);
}
