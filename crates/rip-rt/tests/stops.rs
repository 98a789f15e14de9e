//! Stops judged on the arm's true position: the emulator's `--true-state` record (the
//! simulated plant, not its encoders) before, during and after `rip-rt run` and `rip-rt
//! excite` stop.

mod common;

use std::time::Duration;

use common::*;

#[test]
fn the_true_state_is_recorded_while_running_and_at_exit() {
    let _serial = one_at_a_time();
    let mut emu = Emulator::start("truth", &["--seed", "3"]);
    let log_path = scratch("truth-run.csv");
    let child = spawn_run(
        &emu.device,
        "lqr",
        &["--duration", "2", "--log", log_path.to_str().unwrap()],
    );
    // Readable mid-run: rows keep arriving while the loop balances.
    std::thread::sleep(Duration::from_millis(1500));
    let during = emu.truth_so_far();
    assert!(during.iter().any(|r| r.driver == "drive"), "{during:?}");
    let r = wait_with_timeout(child, Duration::from_secs(30));
    assert_eq!(r.status.code(), Some(0), "{}", r.stderr);
    std::thread::sleep(Duration::from_millis(200));
    let rows = emu.finish();
    assert!(rows.len() > during.len());
    // Before the first command the emulator holds the pendulum at its initial pose.
    assert_eq!((rows[0].theta, rows[0].alpha), (0.0, 0.05));
    // A row every 10 ms of simulated time.
    for w in rows.windows(2).take(100) {
        assert!((w[1].t - w[0].t - 0.01).abs() < 1.5e-3, "{w:?}");
    }
    // The encoders' view (the log) agrees with the plant to the resolution of 2048 counts,
    // within what the arm moves between the sample and the last command.
    let log = Log::read(&log_path);
    let measured = *log.col("theta").last().unwrap();
    let last_drive = rows.iter().rposition(|r| r.driver == "drive").unwrap();
    let truth = rows[last_drive].theta;
    assert!(
        (measured - truth).abs() < 0.03,
        "log {measured}, true {truth}"
    );
    // The run ended with the bridge off and 0 V across the motor, which the last row (written
    // at exit) shows.
    let last = rows.last().unwrap();
    assert_ne!(last.driver, "drive");
    assert_eq!(last.voltage, 0.0);
}
