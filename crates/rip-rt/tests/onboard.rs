//! `rip-rt run --onboard` against the emulator, which runs the firmware's device logic
//! (`rip-device`) and its onboard controller on the simulated plant. Judged on the emulator's
//! true state, not on what the device reports.

mod common;

use std::time::Duration;

use common::*;

fn onboard_run(device: &std::path::Path, extra: &[&str]) -> RunResult {
    // LQR: the tests of the device's stops hold for any controller.
    let mut args = vec!["--onboard"];
    args.extend_from_slice(extra);
    run(device, "lqr", &args)
}

/// The pendulum's RMS angle over the run (after the first 0.5 s) and the arm's mean angle over
/// its last second, from the true state.
fn rms_alpha_and_final_theta(truth: &[Truth]) -> (f64, f64) {
    let during: Vec<&Truth> = truth.iter().filter(|t| t.t > 0.5 && t.t < 8.0).collect();
    assert!(during.len() > 700, "{} rows", during.len());
    let rms = (during.iter().map(|t| t.alpha * t.alpha).sum::<f64>() / during.len() as f64).sqrt();
    let last: Vec<&&Truth> = during.iter().filter(|t| t.t > 7.0).collect();
    let theta = last.iter().map(|t| t.theta).sum::<f64>() / last.len() as f64;
    (rms, theta)
}

#[test]
fn lqr_lqg_and_mpc_balance_onboard_through_the_reference_step_as_on_the_host() {
    let _one = one_at_a_time();
    for controller in ["lqr", "lqg", "mpc"] {
        // The reference: the same rig and noise with the controller on the host (protocol v1).
        let mut emu = Emulator::lockstep(&format!("host-{controller}"), &["--noise", "0.3"]);
        let r = run_lockstep(&emu.device, controller, &["--duration", "8"]);
        assert_eq!(r.status.code(), Some(0), "{controller}: {}", r.stderr);
        let (host_rms, host_theta) = rms_alpha_and_final_theta(&emu.finish());

        let mut emu = Emulator::lockstep(&format!("onboard-{controller}"), &["--noise", "0.3"]);
        let log = scratch(&format!("onboard-{controller}.csv"));
        let r = run(
            &emu.device,
            controller,
            &[
                "--onboard",
                "--lockstep",
                "--duration",
                "8",
                "--log",
                log.to_str().unwrap(),
            ],
        );
        assert_eq!(r.status.code(), Some(0), "{controller}: {}", r.stderr);
        assert!(r.stderr.contains("steps=800"), "{controller}: {}", r.stderr);
        // The device's QP finished within its iteration cap on every step.
        assert!(
            r.stderr.contains("fallbacks=0"),
            "{controller}: {}",
            r.stderr
        );
        let truth = emu.finish();
        // Over the run's 8 s: after it the emulator runs its plant on to rest, the pendulum
        // falling once the device has stopped.
        let worst_alpha = truth
            .iter()
            .filter(|t| t.t > 0.5 && t.t < 8.0)
            .fold(0.0f64, |m, t| m.max(t.alpha.abs()));
        assert!(
            worst_alpha < 0.2,
            "{controller}: pendulum reached {worst_alpha} rad"
        );
        let (rms, theta) = rms_alpha_and_final_theta(&truth);
        // The default reference steps the arm to 1 rad; it settles there, as on the host.
        assert!(
            (theta - 1.0).abs() < 0.05,
            "{controller}: arm at {theta} rad"
        );
        assert!(
            (host_theta - 1.0).abs() < 0.05,
            "{controller} host: arm at {host_theta} rad"
        );
        // The same design on the device: the pendulum's RMS within 5 % of the host loop's.
        assert!(
            (rms / host_rms - 1.0).abs() < 0.05,
            "{controller}: pendulum RMS {rms} onboard, {host_rms} on the host"
        );
        // After the run the motor is no longer driven.
        assert_ne!(truth.last().unwrap().driver, "drive", "{controller}");

        // The log has the usual columns, one row per device step, and its angles are the
        // encoders' view of the true state.
        let log = Log::read(&log);
        assert_eq!(log.meta("onboard"), Some("true"));
        assert_eq!(log.rows.len(), 800);
        let fallback_rows = log
            .col("status")
            .iter()
            .filter(|&&s| (s as u32) & (1 << 9) != 0)
            .count();
        assert_eq!(fallback_rows, 0, "{controller}: rows flagged FALLBACK");
        let t = log.col("t");
        let th = log.col("theta");
        let k = t
            .iter()
            .position(|&x| (x - 7.5).abs() < 1e-6)
            .expect("row at 7.5 s");
        let true_theta = truth
            .iter()
            .min_by(|a, b| (a.t - 7.5).abs().total_cmp(&(b.t - 7.5).abs()))
            .unwrap()
            .theta;
        // 2048 counts per revolution and 0.3 counts of noise: within a few counts.
        assert!(
            (th[k] - true_theta).abs() < 0.02,
            "{controller}: {} vs {true_theta}",
            th[k]
        );
        eprintln!("{controller}: pendulum RMS {rms:.5} onboard, {host_rms:.5} host");
    }
}

#[test]
fn the_device_enforces_the_angle_limits_itself() {
    let _one = one_at_a_time();
    // A miswired motor: the law pushes the wrong way and the pendulum falls.
    let mut emu = Emulator::lockstep("onboard-limit", &["--reverse-motor"]);
    let r = onboard_run(&emu.device, &["--lockstep", "--duration", "8"]);
    // Exit 5, the angle-limit code, from the device's own check.
    assert_eq!(r.status.code(), Some(5), "{}", r.stderr);
    assert!(r.stderr.contains("the device stopped"), "{}", r.stderr);
    let truth = emu.finish();
    let driven: Vec<&Truth> = truth.iter().filter(|t| t.driver == "drive").collect();
    let last_drive = driven.last().expect("never driven");
    // safety.pendulum_limit (0.6 rad by default) or safety.arm_limit (3 rad) was reached while the
    // motor was driven, and the motor was not driven again.
    assert!(
        last_drive.alpha.abs() > 0.5 || last_drive.theta.abs() > 2.9,
        "{last_drive:?}"
    );
    assert!(truth.last().unwrap().t > last_drive.t);
    assert_ne!(truth.last().unwrap().driver, "drive");
}

#[test]
fn a_host_that_dies_leaves_the_device_to_stop_the_motor() {
    let _one = one_at_a_time();
    // In lockstep, so that a loaded machine cannot starve the host into a silence before it
    // dies; the host's death is a hang-up, after which the emulator runs its plant on to rest
    // and the device's own host timeout must stop the motor.
    let emu = Emulator::lockstep("onboard-silent", &[]);
    // No --duration: a lockstep run outpaces the wall clock, and 120 s of it has ended with
    // exit 0 before the kill; without one it runs until the kill.
    let mut child = spawn_run(&emu.device, "lqr", &["--onboard", "--lockstep"]);
    emu.wait_for(
        "the onboard run driving the motor",
        Duration::from_secs(30),
        |rows| rows.iter().filter(|r| r.driver == "drive").count() > 20,
    );
    let pid = child.id() as i32;
    // Suspended first, so that the paced plant stands still where the host left it: the
    // simulated time of the kill is then read off the record, not guessed.
    unsafe { libc::kill(pid, libc::SIGSTOP) };
    let mut last = f64::NAN;
    let frozen = emu.wait_for(
        "the paced plant standing still",
        Duration::from_secs(10),
        |rows| {
            let t = rows.last().map_or(f64::NAN, |r| r.t);
            let still = t == last;
            last = t;
            // Two looks 50 ms apart that agree.
            std::thread::sleep(Duration::from_millis(50));
            still
        },
    );
    let killed_at = frozen.last().unwrap().t;
    // SIGKILL: no stop frame can be sent.
    unsafe { libc::kill(pid, libc::SIGKILL) };
    let _ = child.wait();
    let truth = emu.wait_for(
        "the plant run on after the hang-up",
        Duration::from_secs(30),
        |rows| {
            rows.last()
                .is_some_and(|r| r.t > killed_at + 0.5 && r.driver != "drive")
        },
    );
    let driven: Vec<&Truth> = truth.iter().filter(|t| t.driver == "drive").collect();
    assert!(!driven.is_empty(), "the onboard run never drove the motor");
    let last_drive = driven.last().unwrap().t;
    // Stopped within the 50 ms host timeout plus a period and the record's 10 ms grid.
    assert!(
        last_drive < killed_at + 0.1,
        "driven until {last_drive} s, host killed at {killed_at} s"
    );
    assert_eq!(truth.last().unwrap().driver, "brake");
}

#[test]
fn a_signal_ends_the_onboard_run_with_the_motor_stopped() {
    let _one = one_at_a_time();
    // In lockstep: the subject is the signal's handling, not timing. No --duration: a lockstep
    // run outpaces the wall clock (120 s of it ended before the signal), so it runs until one.
    let mut emu = Emulator::lockstep("onboard-signal", &[]);
    let child = spawn_run(&emu.device, "lqr", &["--onboard", "--lockstep"]);
    emu.wait_for(
        "the onboard run driving the motor",
        Duration::from_secs(30),
        |rows| rows.iter().any(|r| r.driver == "drive"),
    );
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let r = wait_with_timeout(child, Duration::from_secs(5));
    assert_eq!(r.status.code(), Some(130), "{}", r.stderr);
    assert!(r.stderr.contains("stop frames sent"), "{}", r.stderr);
    // The emulator runs its plant on once the run has hung up: the record then ends with
    // the motor as the run's stop frames left it.
    emu.wait_for(
        "the plant run on after the run",
        Duration::from_secs(30),
        |rows| rows.last().is_some_and(|r| r.driver != "drive"),
    );
    let truth = emu.finish();
    assert!(truth.iter().any(|t| t.driver == "drive"));
    assert_ne!(truth.last().unwrap().driver, "drive");
}
