//! The end of a run, judged on the emulator's true state: after `--duration` the pendulum is
//! lowered under control to hanging at rest and the arm brought to rest near the centre, inside
//! `safety.arm_limit`, before the driver is disabled (rather than let fall and braked).

mod common;

use std::time::Duration;

use common::*;

/// Seconds of balancing before the run ends.
const BALANCE_S: f64 = 3.0;
/// Seconds after the end within which the pendulum must hang at rest.
const SETTLE_S: f64 = 5.0;
/// The bar: pendulum within this of hanging (rad) …
const HANGING_RAD: f64 = 0.1;
/// … and the arm slower than this (rad/s), from [`SETTLE_S`] after the end on.
const ARM_RATE: f64 = 0.2;

/// Runs each controller on the rig of `rig_toml` (its `[plant]` and `[sensor]`, also the
/// emulator's) for [`BALANCE_S`] in lockstep, and asserts the gentle end on the true state.
fn ends_gently(name: &str, rig_toml: &str, noise: &[&str]) {
    let cfg = scratch(&format!("gentle-{name}.toml"));
    std::fs::write(&cfg, rig_toml).unwrap();
    let cfg_arg = cfg.to_str().unwrap();
    let limit = rip_rt::config::Config::from_toml(rig_toml)
        .unwrap()
        .safety
        .arm_limit;
    for controller in ["lqr", "lqg", "mpc"] {
        let case = format!("{name} {controller}");
        let mut args = vec!["--config", cfg_arg];
        args.extend_from_slice(noise);
        let mut emu = Emulator::lockstep(&format!("gentle-{name}-{controller}"), &args);
        let duration = BALANCE_S.to_string();
        let r = run_lockstep(
            &emu.device,
            controller,
            &["--config", cfg_arg, "--duration", &duration],
        );
        assert_eq!(r.status.code(), Some(0), "{case}: {}", r.stderr);
        assert!(
            r.stderr.contains("stop: lowered the pendulum to hanging"),
            "{case}: {}",
            r.stderr
        );
        let start = emu
            .truth_so_far()
            .iter()
            .find(|row| row.driver == "drive")
            .map(|row| row.t)
            .expect("a driven row");
        let end = start + BALANCE_S;
        // The record's last row is the state at the emulator's exit, with the driver off: a
        // pendulum hanging at rest there stays so.
        emu.wait_for(
            "the driver off after the run",
            Duration::from_secs(30),
            |rows| rows.last().is_some_and(|row| row.driver != "drive"),
        );
        let rows = emu.finish();
        assert_ne!(rows.last().unwrap().driver, "drive", "{case}");
        let max_theta = max_excursion(&rows);
        let unsettled = rows
            .iter()
            .filter(|row| {
                let phi = rip_core::swingup::wrap_angle(row.alpha - std::f64::consts::PI);
                phi.abs() > HANGING_RAD || row.theta_dot.abs() > ARM_RATE
            })
            .map(|row| row.t)
            .fold(f64::NEG_INFINITY, f64::max);
        println!(
            "{case}: true max |theta| {max_theta:.3} rad, hanging at rest {:.2} s after the end",
            unsettled - end
        );
        assert!(max_theta < limit, "{case}: arm at {max_theta} rad");
        assert!(
            unsettled <= end + SETTLE_S,
            "{case}: still moving {:.2} s after the end\n{}",
            unsettled - end,
            r.stderr
        );
    }
}

#[test]
fn the_paper_preset_ends_with_the_pendulum_lowered() {
    ends_gently("paper", "", &["--noise", "0.3"]);
}

#[test]
fn the_qube_servo2_preset_ends_with_the_pendulum_lowered() {
    ends_gently(
        "qube",
        "[plant]\npreset = \"qube_servo2\"\n",
        &["--noise", "0.3"],
    );
}

/// Generated rigs 1–8 (`rip_core::rig::Rig::random`), their own encoders and noise.
#[test]
fn generated_rigs_end_with_the_pendulum_lowered() {
    for seed in 1..=8 {
        let rig = rip_core::rig::Rig::random(seed).to_toml();
        ends_gently(&format!("rig{seed}"), &rig, &[]);
    }
}

/// A first Ctrl-C (and SIGTERM) ends a balancing run as its duration does: the line says so at
/// once, and the pendulum is lowered; the exit code is the signal's.
#[test]
fn a_first_signal_lowers_the_pendulum_too() {
    for (signal, name) in [(libc::SIGINT, "Ctrl-C"), (libc::SIGTERM, "SIGTERM")] {
        let case = format!("gentle-signal-{signal}");
        let mut emu = Emulator::lockstep(&case, &["--noise", "0.3"]);
        let child = spawn_run(&emu.device, "lqr", &[LOCKSTEP]);
        let rows = emu.wait_for("a second of balancing", Duration::from_secs(30), |rows| {
            let start = rows.iter().find(|r| r.driver == "drive").map(|r| r.t);
            start.is_some_and(|s| rows.last().is_some_and(|r| r.t > s + 1.0))
        });
        unsafe { libc::kill(child.id() as i32, signal) };
        let sent_at = rows.last().unwrap().t;
        let r = wait_with_timeout(child, Duration::from_secs(60));
        assert_eq!(r.status.code(), Some(128 + signal), "{case}: {}", r.stderr);
        assert!(
            r.stderr.contains(&format!(
                "rip-rt: {name}: stopping: lowering the pendulum and bringing the arm to rest"
            )),
            "{case}: {}",
            r.stderr
        );
        assert!(
            r.stderr.contains("stop: lowered the pendulum"),
            "{}",
            r.stderr
        );
        emu.wait_for("the driver off", Duration::from_secs(30), |rows| {
            rows.last().is_some_and(|row| row.driver != "drive")
        });
        let rows = emu.finish();
        let last = rows.last().unwrap();
        let phi = rip_core::swingup::wrap_angle(last.alpha - std::f64::consts::PI);
        assert!(
            phi.abs() < HANGING_RAD && last.theta_dot.abs() < ARM_RATE,
            "{last:?}"
        );
        assert!(max_excursion(&rows) < 3.0, "{case}");
        let driven_until = rows
            .iter()
            .filter(|r| r.driver == "drive")
            .map(|r| r.t)
            .fold(0.0, f64::max);
        assert!(
            driven_until - sent_at < SETTLE_S + 1.0,
            "{case}: {driven_until} {sent_at}"
        );
    }
}
