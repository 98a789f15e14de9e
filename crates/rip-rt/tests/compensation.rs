//! End to end, against the emulator: `rip-rt run` compensates the rig's dead zone and arm
//! friction from the experiment file's `[plant]`, where the uncompensated LQG limit-cycles.
//! In lockstep: the subject is the control law on the rig, not the loop's timing (in real
//! time a loaded machine starved the emulator into missed replies and stalls). Each test
//! holds `common::one_at_a_time` (the reason is there).

mod common;

use common::*;

/// The QUBE-like rig with a 0.4 V dead zone and 0.003 N m of arm friction.
const RIG: &str = "[plant]\npreset = 'qube_servo2'\nmr = 0.12\nLr = 0.105\nJr = 0.00011025\n\
                   mp = 0.038\nLp = 0.19\nJp = 0.00011431666666666667\nRm = 6.5\nkt = 0.055\n\
                   km = 0.055\nVd = 0.4\nCr = 0.003\n";

/// Runs LQG for 7 s on the rig with `extra` appended to its file; returns the arm's
/// peak-to-peak and the largest |α| over the last 2.5 s, or the exit code and message of a
/// run that did not finish.
fn lqg_once(name: &str, extra: &str) -> Result<(f64, f64), (Option<i32>, String)> {
    let cfg = scratch(&format!("{name}.toml"));
    std::fs::write(&cfg, format!("{RIG}{extra}")).unwrap();
    let cfg = cfg.to_str().unwrap();
    let emu = Emulator::lockstep(name, &["--config", cfg, "--noise", "0.3", "--seed", "3"]);
    let log_path = scratch(&format!("{name}.csv"));
    let r = run_lockstep(
        &emu.device,
        "lqg",
        &[
            // The uncompensated LQG is predicted to fall: this test is about what the loop
            // does when it runs anyway.
            "--force",
            "--duration",
            "7",
            "--config",
            cfg,
            "--log",
            log_path.to_str().unwrap(),
        ],
    );
    let log = Log::read(&log_path);
    let commands = emu.commands();
    assert_eq!(
        commands.last(),
        Some(&(0, 0)),
        "last command must be 0 V: {}",
        r.stderr
    );
    if r.status.code() != Some(0) {
        return Err((r.status.code(), r.stderr));
    }
    let (t, theta, alpha) = (log.col("t"), log.col("theta"), log.col("alpha"));
    let end = t.last().copied().unwrap_or(0.0);
    let (mut lo, mut hi, mut a) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
    for ((ti, th), al) in t.iter().zip(&theta).zip(&alpha) {
        if *ti >= end - 2.5 {
            lo = lo.min(*th);
            hi = hi.max(*th);
            a = a.max(al.abs());
        }
    }
    Ok((hi - lo, a))
}

#[test]
fn the_dead_zone_and_friction_are_compensated_by_rip_rt_run() {
    let _serial = one_at_a_time();
    let (pp, alpha) = lqg_once("compensated-lqg", "").unwrap();
    println!("compensated LQG: arm peak-to-peak {pp:.3} rad, |alpha| <= {alpha:.3} rad");
    assert!(pp < 0.08 && alpha < 0.03, "{pp} {alpha}");
    // Without it the same LQG cycles until it is stopped as a fault (exit 5): the pendulum
    // passes its angle limit, or the growing arm swing leaves the braking envelope first.
    // At best it cycles at several times the amplitude.
    match lqg_once("uncompensated-lqg", "[compensation]\nenabled = false\n") {
        Ok((pp_off, _)) => assert!(pp_off > 3.0 * pp, "{pp_off} vs {pp}"),
        Err((code, stderr)) => {
            assert_eq!(code, Some(5), "{stderr}");
            assert!(
                stderr.contains("pendulum angle limit") || stderr.contains("arm braking envelope"),
                "{stderr}"
            );
        }
    }
}
