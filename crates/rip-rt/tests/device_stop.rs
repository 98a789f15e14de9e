//! The device's own stop (`rip_control::stop`, run by `rip-device` in onboard mode), judged on
//! the emulator's true state: `rip-rt run --onboard` checks the wiring with the pendulum
//! hanging, the operator raises it (`emulate --raise-at`), the device balances it, and the
//! host dies (SIGKILL: no stop frame) while it balances and during the reference step. The
//! device, its wiring verified, brakes the arm to rest and holds it inside
//! `safety.arm_limit`, then disables the driver. In host mode the same: `rip-rt run
//! --swing-up` arms the device's stop for its command watchdog once its sign check has
//! passed, and dies during the swing or after the catch.

mod common;

use std::time::Duration;

use common::*;
use rip_core::rig::Rig;

/// Seconds after the first enabling command (the sign check's pulse) at which the operator
/// raises the pendulum: after the pulse and its watch (0.6 s), the pendulum's swing from it
/// left to the onboard start's limits.
const RAISE_AT: f64 = 1.5;

/// When the host dies, in seconds after the onboard start: while balancing, and during the
/// reference step (at `reference.step_time`, 1 s).
const KILLS: [(&str, f64); 2] = [("balancing", 0.6), ("during the step", 1.3)];

/// Arm speed (rad/s) below which the arm counts as at rest at the end.
const REST_RATE: f64 = 0.05;

/// The rigs: both presets, and at the full scale two generated rigs.
fn rigs() -> Vec<(String, String)> {
    let mut out = vec![
        (
            "paper".to_string(),
            "[plant]\npreset = \"paper\"\n".to_string(),
        ),
        (
            "qube_servo2".to_string(),
            "[plant]\npreset = \"qube_servo2\"\n".to_string(),
        ),
    ];
    for seed in rip_test_scale::cases(1..=2u64, |_| false) {
        out.push((format!("generated rig {seed}"), Rig::random(seed).to_toml()));
    }
    out
}

/// One case: the host killed `offset` s into the onboard run, the pendulum started hanging
/// (the wiring checked, then raised by the operator) or, when not `hanging`, upright (the
/// wiring unchecked); the true state from the onboard start to the end, the time of the
/// kill, the rig's `safety.arm_limit` and the run's stderr.
fn host_killed(
    name: &str,
    rig_toml: &str,
    offset: f64,
    hanging: bool,
) -> (Vec<Truth>, f64, f64, String) {
    let file = name.replace([' ', ','], "-");
    let cfg = scratch(&format!("device-stop-{file}.toml"));
    // Time for the operator to raise the pendulum after the sign check.
    let rig_toml = format!("{rig_toml}\n[safety]\nwait_upright_s = 30.0\n");
    let rig_toml = rig_toml.as_str();
    std::fs::write(&cfg, rig_toml).unwrap();
    let cfg_arg = cfg.to_str().unwrap();
    let limit = rip_rt::config::Config::from_toml(rig_toml)
        .unwrap()
        .safety
        .arm_limit;
    let raise = RAISE_AT.to_string();
    let mut emulate = vec!["--config", cfg_arg];
    if hanging {
        emulate.extend(["--start", "down", "--raise-at", &raise]);
    }
    let emu = Emulator::lockstep(&format!("device-stop-{file}"), &emulate);
    let child = spawn_run(
        &emu.device,
        "lqr",
        &["--onboard", "--lockstep", "--config", cfg_arg],
    );
    // The onboard start: the first driven row (after the operator raised the pendulum).
    let start = |rows: &[Truth]| {
        let first = rows.iter().find(|r| r.driver == "drive")?.t;
        if !hanging {
            return Some(first);
        }
        rows.iter()
            .find(|r| r.t > first + RAISE_AT && r.driver == "drive")
            .map(|r| r.t)
    };
    let what = format!("{name}: the host {offset} s into the onboard run");
    let (rows, killed_at, stderr) = kill_after(&emu, child, &what, start, offset, start);
    (rows, killed_at, limit, stderr)
}

/// SIGKILLs the run `child` of `emu` `offset` s after the time `at` finds in the true state
/// (no stop frame can be sent), and waits for the plant's rest: the true state from the time
/// `from` finds, the kill's time and the run's stderr.
fn kill_after(
    emu: &Emulator,
    mut child: std::process::Child,
    what: &str,
    at: impl Fn(&[Truth]) -> Option<f64>,
    offset: f64,
    from: impl Fn(&[Truth]) -> Option<f64>,
) -> (Vec<Truth>, f64, String) {
    let rows = emu.suspend_run_when(
        &mut child,
        what,
        Duration::from_secs(60),
        |rows| at(rows).is_some_and(|s| rows.last().unwrap().t > s + offset - 0.1),
        |rows| at(rows).is_some_and(|s| rows.last().unwrap().t >= s + offset),
    );
    let started = from(&rows).unwrap();
    let killed_at = rows.last().unwrap().t;
    unsafe { libc::kill(child.id() as i32, libc::SIGKILL) };
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    let rows = emu.wait_for_rest(REST_RATE, 1.0, Duration::from_secs(60));
    let rows = rows.into_iter().filter(|r| r.t >= started).collect();
    (rows, killed_at, stderr)
}

/// Judges a run whose host was killed at `killed_at` on the true state `rows`: inside `limit`
/// throughout, the device's own braking law driving after the command watchdog's 50 ms (the
/// host's last command lasts until then), at rest with the driver off at the end; a failure
/// goes to `wrong`. Returns the figures' line.
fn judge(
    case: &str,
    rows: &[Truth],
    killed_at: f64,
    limit: f64,
    wrong: &mut Vec<String>,
) -> String {
    let max_theta = max_excursion(rows);
    let after: Vec<Truth> = rows.iter().filter(|r| r.t >= killed_at).cloned().collect();
    let last = rows.last().unwrap();
    let braked = rows
        .iter()
        .any(|r| r.t > killed_at + 0.06 && r.driver == "drive");
    let stopped_driving = rows
        .iter()
        .rev()
        .find(|r| r.driver == "drive")
        .map_or(killed_at, |r| r.t);
    if max_theta.is_nan() || max_theta >= limit {
        wrong.push(format!("{case}: the arm reached {max_theta:.3} rad"));
    }
    if !braked {
        wrong.push(format!("{case}: the device did not brake the arm itself"));
    }
    if last.theta_dot.abs() > REST_RATE || last.driver == "drive" {
        wrong.push(format!("{case}: not at rest with the driver off: {last:?}"));
    }
    format!(
        "{case}: true max |theta| {max_theta:.3} rad, {:.3} rad after the kill (limit {limit}), \
         device's stop drove until {:.2} s after the kill, end: theta {:.3} rad, rate {:.4} \
         rad/s, driver {}",
        max_excursion(&after),
        stopped_driving - killed_at,
        last.theta,
        last.theta_dot,
        last.driver
    )
}

#[test]
fn a_device_whose_host_dies_brakes_and_holds_the_arm_inside_the_limit() {
    let _one = one_at_a_time();
    let mut wrong = Vec::new();
    for (name, toml) in rigs() {
        for (when, offset) in KILLS {
            let case = format!("{name}, host killed {when}");
            let (rows, killed_at, limit, stderr) = host_killed(&case, &toml, offset, true);
            assert!(
                stderr.contains("sign check passed"),
                "{case}: no sign check:\n{stderr}"
            );
            println!("{}", judge(&case, &rows, killed_at, limit, &mut wrong));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn a_device_stepping_at_1_khz_runs_its_stop_as_at_100_hz() {
    let _one = one_at_a_time();
    // The stop's sequence every 10 ms (rip_control::stop::STOP_PERIOD_S), its command held in
    // between: its rest windows, blind rule and dead band as measured.
    let toml = "[plant]\npreset = \"paper\"\n[loop]\nperiod_ms = 1.0\n";
    let (rows, killed_at, limit, stderr) = host_killed("paper at 1 kHz", toml, 0.6, true);
    assert!(stderr.contains("sign check passed"), "{stderr}");
    let max_theta = max_excursion(&rows);
    let last = rows.last().unwrap();
    let braked = rows
        .iter()
        .any(|r| r.t > killed_at + 0.06 && r.driver == "drive");
    println!("paper at 1 kHz: true max |theta| {max_theta:.3} rad, end {last:?}");
    assert!(braked, "the device did not brake the arm itself");
    assert!(max_theta < limit, "{max_theta}");
    assert!(
        last.theta_dot.abs() < REST_RATE && last.driver != "drive",
        "{last:?}"
    );
}

#[test]
fn an_unverified_device_shorts_the_windings_rather_than_drive() {
    let _one = one_at_a_time();
    // Upright from the start: no sign check, so the device's stop is the short (the stop of
    // every onboard run before the device had its own).
    for (name, toml) in rigs().into_iter().take(2) {
        for (when, offset) in KILLS {
            let case = format!("{name}, unverified, host killed {when}");
            let (rows, killed_at, _, stderr) = host_killed(&case, &toml, offset, false);
            assert!(
                stderr.contains("the wiring's sign is unchecked"),
                "{case}: {stderr}"
            );
            let last_drive = rows.iter().rev().find(|r| r.driver == "drive").unwrap().t;
            let last = rows.last().unwrap();
            println!(
                "{case}: true max |theta| {:.3} rad, end: theta {:.3} rad, driver {}",
                max_excursion(&rows),
                last.theta,
                last.driver
            );
            // Stopped within the 50 ms host timeout and a period, then shorted, never driven
            // again.
            assert!(
                last_drive < killed_at + 0.1,
                "{case}: driven until {last_drive}, killed at {killed_at}"
            );
            assert_eq!(last.driver, "brake", "{case}");
        }
    }
}

#[test]
fn a_host_that_is_alive_lets_the_devices_own_stop_finish() {
    let _one = one_at_a_time();
    // A pendulum limit the reference step's swing passes: the device stops on it with the host
    // there, and the host waits for the device's stop before its own stop frames.
    let toml =
        "[plant]\npreset = \"paper\"\n[safety]\nwait_upright_s = 30.0\npendulum_limit = 0.1\n";
    let cfg = scratch("device-stop-host-alive.toml");
    std::fs::write(&cfg, toml).unwrap();
    let cfg_arg = cfg.to_str().unwrap();
    let raise = RAISE_AT.to_string();
    let emu = Emulator::lockstep(
        "device-stop-host-alive",
        &["--config", cfg_arg, "--start", "down", "--raise-at", &raise],
    );
    let r = run_lockstep(
        &emu.device,
        "lqr",
        &["--onboard", "--config", cfg_arg, "--duration", "6"],
    );
    assert_eq!(r.status.code(), Some(5), "{}", r.stderr);
    assert!(
        r.stderr.contains("the device is stopping the arm itself"),
        "{}",
        r.stderr
    );
    let rows = emu.wait_for_rest(REST_RATE, 1.0, Duration::from_secs(60));
    let pulse = rows.iter().find(|r| r.driver == "drive").unwrap().t;
    let started = rows
        .iter()
        .find(|r| r.t > pulse + RAISE_AT && r.driver == "drive")
        .unwrap()
        .t;
    let tripped = rows
        .iter()
        .find(|r| r.t > started && r.alpha.abs() > 0.1)
        .expect("the pendulum past its limit")
        .t;
    let last_drive = rows.iter().rev().find(|r| r.driver == "drive").unwrap().t;
    let last = rows.last().unwrap();
    println!(
        "host alive: the device's stop drove {:.2} s after the limit, max |theta| {:.3} rad, \
         end {last:?}",
        last_drive - tripped,
        max_excursion(&rows)
    );
    assert!(
        last_drive > tripped + 0.5,
        "the device's stop was cut short"
    );
    assert!(max_excursion(&rows) < 3.0);
    assert!(
        last.theta_dot.abs() < REST_RATE && last.driver != "drive",
        "{last:?}"
    );
}

/// When the host dies in host mode: during the swing, and while balancing after the catch.
const HOST_MODE_KILLS: [(&str, f64); 2] = [("during the swing", 0.5), ("balancing", 1.0)];

/// The rigs of host mode: both presets, and at the full scale the two generated rigs the
/// swing-up's end-to-end tests swing up (rig 6 with the predicted catch).
fn swing_rigs() -> Vec<(String, String)> {
    let mut out = rigs().into_iter().take(2).collect::<Vec<_>>();
    let generated = [
        (15, ""),
        (
            6,
            "[swing_up]\nreference_return_rate = 0.5\ncatch_prediction = 1.0\ncatch_margin = 0.25\n",
        ),
    ];
    for (seed, extra) in rip_test_scale::cases(generated, |_| false) {
        let rig = Rig::random(seed).to_toml();
        out.push((format!("generated rig {seed}"), format!("{rig}\n{extra}")));
    }
    out
}

/// Host mode, `rip-rt run --swing-up`: the sign check verifies the wiring, the host arms the
/// device's stop for its command watchdog, and is killed (SIGKILL) `offset` s after the swing's
/// start or after the catch (`when`); the true state from the swing's start, the kill's time,
/// the limit and the run's stderr.
fn host_mode_killed(
    name: &str,
    rig_toml: &str,
    when: &str,
    offset: f64,
) -> (Vec<Truth>, f64, f64, String) {
    let file = name.replace([' ', ','], "-");
    let cfg = swing_config(&format!("device-stop-host-{file}"), 4.0, rig_toml);
    let limit = rip_rt::config::Config::load(&cfg).unwrap().safety.arm_limit;
    let emu = hanging_rig(&format!("device-stop-host-{file}"), &cfg, &[], true);
    let child = spawn_run(
        &emu.device,
        "lqr",
        &["--swing-up", "--config", cfg.to_str().unwrap(), LOCKSTEP],
    );
    let from = |rows: &[Truth]| {
        if when == "balancing" {
            first_upright(rows)
        } else {
            swing_start(rows)
        }
    };
    let what = format!("{name}: the host {offset} s {when}");
    let (rows, killed_at, stderr) = kill_after(&emu, child, &what, from, offset, swing_start);
    (rows, killed_at, limit, stderr)
}

#[test]
fn a_host_mode_device_whose_host_dies_brakes_and_holds_the_arm_inside_the_limit() {
    let _one = one_at_a_time();
    let mut wrong = Vec::new();
    for (name, toml) in swing_rigs() {
        for (when, offset) in HOST_MODE_KILLS {
            let case = format!("{name}, host mode, host killed {when}");
            let (rows, killed_at, limit, stderr) = host_mode_killed(&case, &toml, when, offset);
            assert!(
                stderr.contains("the device stops the arm itself (braking"),
                "{case}: the device's stop was not armed:\n{stderr}"
            );
            println!("{}", judge(&case, &rows, killed_at, limit, &mut wrong));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
