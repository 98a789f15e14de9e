//! End to end, against the emulator: the rest check and the hanging-down calibration.
//! Each test holds `common::one_at_a_time` (the reason is there).

mod common;

use std::f64::consts::{PI, TAU};

use common::*;
use rip_rt::calibrate::{self, RestFault};
use rip_rt::config::Config;
use rip_rt::controllers::{self, ControllerKind};
use rip_rt::loop_core::LoopCore;
use rip_rt::serial::SerialPort;
use rip_rt::stop::{StopGuard, StopReason};
use rip_rt::timing::{ClockMode, Periodic};

/// What [`rest_check`] saw: the check's outcome, the rest pose's angles after calibration, and
/// the commands the device received.
type RestOutcome = (
    Result<calibrate::Calibration, StopReason>,
    Option<(f64, f64)>,
    Vec<(i32, u8)>,
);

/// Runs the rest check of `cfg_text` against an emulator started with `emulator_args`.
fn rest_check(name: &str, emulator_args: &[&str], cfg_text: &str) -> RestOutcome {
    let emu = Emulator::lockstep(name, emulator_args);
    let cfg = Config::from_toml(cfg_text).unwrap();
    let port = SerialPort::open(&emu.device, 115_200).unwrap();
    let controller = controllers::build(ControllerKind::Lqr, &cfg).unwrap();
    let mut core = LoopCore::new(controller, &cfg).unwrap();
    let guard = StopGuard::new(port.io().raw());
    let mut periodic = Periodic::starting(cfg.period_ns(), ClockMode::Lockstep);
    let result = calibrate::check_rest(port.io(), &mut core, &cfg, &mut periodic, true);
    let angles = result.as_ref().ok().map(|cal| {
        core.calibrate(cal);
        let m = rip_rt::protocol::Measurement {
            arm_counts: cal.arm_zero_counts.round() as i32,
            pendulum_counts: cal.pendulum_hanging_counts.round() as i32,
            ..Default::default()
        };
        core.angles(&m)
    });
    assert!(guard.stop());
    drop(guard);
    (result, angles, emu.commands())
}

#[test]
fn a_hanging_rig_at_rest_is_calibrated_with_the_motor_disabled() {
    let _serial = one_at_a_time();
    // Arm parked at 0.3 rad of the encoder's count; pendulum hanging; 0.3 counts of noise.
    let (result, angles, commands) = rest_check(
        "rest-ok",
        &[
            "--initial-pendulum",
            &PI.to_string(),
            "--initial-arm",
            "0.3",
            "--noise",
            "0.3",
        ],
        "",
    );
    let cal = result.unwrap();
    // The emulator's counts: θ·2048/2π for the arm, (α + π)·2048/2π for the pendulum.
    let arm = 0.3 * 2048.0 / TAU;
    assert!((cal.arm_zero_counts - arm).abs() < 0.6, "{cal}");
    assert!((cal.pendulum_hanging_counts - 2048.0).abs() < 0.3, "{cal}");
    assert!(cal.pendulum_offset.abs() < 1e-3, "{cal}");
    // One window of 1 s after the first measurement, give or take a period or two.
    assert!(cal.after_s < 1.5, "{cal}");
    // After calibration the rest pose reads θ = 0, α = ±π.
    let (theta, alpha) = angles.unwrap();
    assert!(theta.abs() < 2.0 * TAU / 2048.0, "{theta}");
    assert!(PI - alpha.abs() < 2.0 * TAU / 2048.0, "{alpha}");
    // Only stop commands, one per period.
    assert!(commands.len() >= 90, "{}", commands.len());
    assert!(commands.iter().all(|&c| c == (0, 0)), "{commands:?}");
}

#[test]
fn a_swinging_pendulum_is_refused_with_the_motor_never_enabled() {
    let _serial = one_at_a_time();
    let (result, _, commands) = rest_check(
        "rest-swinging",
        &["--initial-pendulum", "2.8", "--no-hold"],
        "[calibration]\nrest_timeout_s = 1.5\n",
    );
    let reason = result.unwrap_err();
    assert_eq!(reason.exit_code(), 12, "{reason}");
    assert!(
        matches!(
            reason,
            StopReason::NotAtRest(RestFault::Moving {
                joint: "pendulum",
                ..
            })
        ),
        "{reason}"
    );
    assert!(!commands.is_empty());
    assert!(commands.iter().all(|&c| c == (0, 0)), "{commands:?}");
}

#[test]
fn a_pendulum_held_away_from_hanging_is_refused() {
    let _serial = one_at_a_time();
    // Held still (until an enabling command, which never comes) 1 rad from upright.
    let (result, _, commands) = rest_check("rest-held", &["--initial-pendulum", "1.0"], "");
    let reason = result.unwrap_err();
    assert_eq!(reason.exit_code(), 12, "{reason}");
    assert!(
        matches!(reason, StopReason::NotAtRest(RestFault::NotHanging { offset, .. }) if (offset - (PI - 1.0)).abs() < 0.01),
        "{reason}"
    );
    assert!(commands.iter().all(|&c| c == (0, 0)), "{commands:?}");
}

/// The swing-up's arm limit (`[swing_up] arm_limit`, default 1.5 rad).
const SWING_ARM_LIMIT: f64 = 1.5;
/// `[safety] arm_limit`, default 3 rad: a stop.
const SAFETY_ARM_LIMIT: f64 = 3.0;
/// The balance region (`[swing_up] balance_angle`, default 0.6 rad).
const BALANCE_ANGLE: f64 = 0.6;

/// A configuration file for the swing-up runs: a half-second rest window keeps them short.
fn config(name: &str, extra: &str) -> std::path::PathBuf {
    swing_config(name, 2.0, extra)
}

/// The commands before the first enabling one: the rest check's stop commands.
fn before_enabling(commands: &[(i32, u8)]) -> usize {
    commands
        .iter()
        .position(|&(_, flags)| flags & 1 != 0)
        .unwrap_or(commands.len())
}

/// From hanging at rest: the rest check, the swing, the catch, then 3 s of the experiment
/// (the arm step 1 s after the catch). Checks the log's phases, the balance after the catch,
/// the arm and voltage limits, and that the device was left stopped.
fn swing_up_and_balance(controller: &str, seed: &str) {
    let _ = swing_up_and_balance_on(controller, &format!("swing-{controller}"), seed, "");
}

/// [`swing_up_and_balance`] with `spec` added to the configuration, which the emulator
/// simulates too (its `[plant]`); the logged pendulum angle of the swing up to and including
/// the first catch, and the time (s) from the swing's start to that catch.
fn swing_up_and_balance_on(
    controller: &str,
    name: &str,
    seed: &str,
    spec: &str,
) -> (Vec<f64>, f64) {
    let cfg = config(name, spec);
    let (emu, log_path, r) = swing_up_lockstep(name, &cfg, controller, seed, "3");
    println!("{controller}: {}", r.stderr);
    assert_eq!(r.status.code(), Some(0), "{}", r.stderr);
    let log = Log::read(&log_path);
    assert_eq!(log.meta("swing_up"), Some("true"));
    assert_eq!(log.meta("stop"), Some("finished"));
    let t = log.col("t");
    let theta = log.col("theta");
    let alpha = log.col("alpha");
    let u = log.col("u");
    let reference = log.col("theta_ref");
    let phase = log.text("phase");
    // The sign check first, then swinging; a catch, and after the last one balance to the
    // end. (A fall swings up again, the default `swing_up.on_fall = "retry"`; on a machine
    // that keeps the loop and the emulator on time there is none, but a starved emulator can
    // make one.)
    let swing = phase.iter().position(|p| p != "sign_check").unwrap();
    assert!(swing >= 55, "{swing} sign-check rows");
    assert_eq!(phase[swing], "swing_up");
    assert!(
        log.meta("sign_check").unwrap().starts_with("passed"),
        "{:?}",
        log.meta("sign_check")
    );
    // The pulse only: ±2 V, then 0 V.
    assert!(u[..swing].iter().all(|v| [0.0, 2.0, -2.0].contains(v)));
    let catches: Vec<usize> = (1..phase.len())
        .filter(|&k| phase[k] == "balance" && phase[k - 1] == "swing_up")
        .collect();
    let (Some(&first), Some(&k)) = (catches.first(), catches.last()) else {
        panic!("{controller}: no catch: {}", r.stderr)
    };
    if catches.len() > 1 {
        println!("{controller}: {} catches (falls retried)", catches.len());
    }
    assert!(phase[swing..first].iter().all(|p| p == "swing_up"));
    assert!(
        phase[k..].iter().all(|p| p == "balance"),
        "{controller}: fell after the last catch at t = {}",
        t[k]
    );
    assert_eq!(
        log.meta("catches"),
        Some(catches.len().to_string().as_str())
    );
    let catch_s: f64 = log.meta("catch_s").unwrap().parse().unwrap();
    assert_eq!(catch_s, t[first]);
    assert!(log.meta("probe").unwrap().contains("swing-up"));
    // Started hanging: the calibration makes the first measurement α = ±π.
    assert!(std::f64::consts::PI - alpha[0].abs() < 0.01, "{}", alpha[0]);
    // After the catch the pendulum stays in the balance region (measured; the phase column
    // says the supervisor saw no fall).
    let max_alpha = alpha[k..].iter().fold(0.0f64, |m, a| m.max(a.abs()));
    assert!(
        max_alpha <= BALANCE_ANGLE,
        "{controller}: |α| up to {max_alpha}"
    );
    // The experiment ran from the last catch: 3 s of it, the step 1 s after the catch; the
    // reference is 0 whenever the pendulum swings.
    assert!(t.last().unwrap() - t[k] >= 2.9, "log ends early");
    for (j, (ti, r)) in t.iter().zip(&reference).enumerate() {
        // The log's times are rounded: at the step's own period either value is right.
        let since_step = ti - t[k] - 1.0;
        if j >= k && since_step.abs() > 1e-3 {
            let expected = if since_step > 0.0 { 1.0 } else { 0.0 };
            assert_eq!(*r, expected, "reference at t = {ti}");
        }
        // (The step that falls still had the experiment's reference.)
        if phase[j] == "swing_up" && phase[j - 1] != "balance" {
            assert_eq!(*r, 0.0, "reference at t = {ti}");
        }
    }
    // The arm followed the step: over the last 0.5 s (2 s after it) it is near 1 rad.
    for (ti, th) in t.iter().zip(&theta) {
        if t.last().unwrap() - ti < 0.5 {
            assert!(
                (th - 1.0).abs() < 0.35,
                "{controller}: arm at {th} rad at t = {ti}"
            );
        }
    }
    // The swing from rest kept the arm inside the swing-up's limit (the law's own doing), and
    // nothing reached safety.arm_limit; the voltage stayed inside ±12 V.
    let max_abs = |x: &[f64]| x.iter().fold(0.0f64, |m, a| m.max(a.abs()));
    let swing_theta = max_abs(&theta[..first]);
    assert!(
        swing_theta < SWING_ARM_LIMIT,
        "{controller}: |θ| up to {swing_theta} before the catch"
    );
    assert!(max_abs(&theta) < SAFETY_ARM_LIMIT);
    assert!(u.iter().all(|v| v.abs() <= 12.0));
    let swing_alpha = (alpha[swing..=first].to_vec(), t[first] - t[swing]);
    let commands = emu.commands();
    // The rest check's 0.5 s of stop commands came before the first enabling command (the
    // sign check's pulse).
    let first = before_enabling(&commands);
    assert!(first >= 50, "{first} commands before enabling");
    assert!(commands[..first].iter().all(|&c| c == (0, 0)));
    assert_eq!(
        commands.last(),
        Some(&(0, 0)),
        "last command must be 0 V, disabled"
    );
    swing_alpha
}

/// The arrivals within `catch_angle` (the default 0.3 rad) of upright in a logged swing.
fn arrivals((swing_alpha, _): &(Vec<f64>, f64)) -> usize {
    let near: Vec<bool> = swing_alpha.iter().map(|a| a.abs() <= 0.3).collect();
    near.windows(2).filter(|w| w[1] && !w[0]).count()
}

#[test]
fn lqr_swings_up_catches_and_balances() {
    let _serial = one_at_a_time();
    swing_up_and_balance("lqr", "11");
}

#[test]
fn lqg_swings_up_catches_and_balances() {
    let _serial = one_at_a_time();
    swing_up_and_balance("lqg", "12");
}

#[test]
fn mpc_swings_up_catches_and_balances() {
    let _serial = one_at_a_time();
    swing_up_and_balance("mpc", "13");
}

#[test]
fn the_qube_servo2_preset_swings_up_with_the_defaults() {
    let _serial = one_at_a_time();
    let _ = swing_up_and_balance_on(
        "lqg",
        "swing-qube",
        "14",
        "[plant]\npreset = \"qube_servo2\"\n",
    );
}

/// Generated rig 15 (`rip_core::rig::Rig::random`, its `[plant]` and `[sensor]`): of the
/// first 16 the one the defaults swing up on every controller and noise seed in simulation.
#[test]
fn a_generated_rig_swings_up_with_the_defaults() {
    let _serial = one_at_a_time();
    let rig = rip_core::rig::Rig::random(15).to_toml();
    let _ = swing_up_and_balance_on("lqr", "swing-rig15", "15", &rig);
}

/// Generated rig 6, which the defaults swing up in 4 of 5 simulated LQR runs, with the arm
/// reference returning to the centre and the predicted catch (5 of 5 for every controller).
#[test]
fn a_generated_rig_swings_up_with_the_predicted_catch() {
    let _serial = one_at_a_time();
    let rig = rip_core::rig::Rig::random(6).to_toml();
    let spec = format!(
        "{rig}\n[swing_up]\nreference_return_rate = 0.5\ncatch_prediction = 1.0\n\
         catch_margin = 0.25\n"
    );
    let _ = swing_up_and_balance_on("lqg", "swing-rig6", "16", &spec);
}

/// The planned swing-up (`swing_up.method = "trajectory"`) on `qube_servo2`, where the energy
/// law catches on the first arrival in 28 % of perturbed simulations, and on generated rig 6,
/// where it goes over the top up to 6 times in simulation: caught on the first arrival near
/// upright.
#[test]
fn a_planned_swing_up_catches_on_the_first_arrival_end_to_end() {
    let _serial = one_at_a_time();
    let planned = "[swing_up]\nmethod = \"trajectory\"\n";
    let rig6 = rip_core::rig::Rig::random(6).to_toml();
    // The catch comes within the plan and its tail (the energy law takes 2.4 s in the median
    // on qube_servo2): the plan was followed.
    let cases = [
        (
            "qube_servo2",
            "mpc",
            "[plant]\npreset = \"qube_servo2\"\n",
            1.0,
        ),
        ("rig 6", "lqr", rig6.as_str(), 1.5),
    ];
    for (i, (name, controller, rig, plan_s)) in cases.into_iter().enumerate() {
        let spec = format!("{rig}\n{planned}");
        let log_name = format!("swing-planned-{i}");
        let swing = swing_up_and_balance_on(controller, &log_name, &(17 + i).to_string(), &spec);
        assert_eq!(arrivals(&swing), 1, "{name}");
        assert!(
            swing.1 <= plan_s,
            "{name}: caught {} s after the start",
            swing.1
        );
    }
}

#[test]
fn sigint_during_the_swing_leaves_zero_volts_as_the_last_command() {
    let _serial = one_at_a_time();
    // In lockstep, so that a loaded machine's late replies (the real-time watchdog) cannot
    // end the run before the signal; the signal itself is what is under test. The catch
    // region is made unreachable and the swing-up time the longest allowed, so the run is
    // swinging whenever the signal arrives.
    let emu = Emulator::lockstep("swing-sigint", &["--start", "down", "--noise", "0.3"]);
    let cfg = config(
        "swing-sigint",
        "[swing_up]\ncatch_rate = 1e-6\nmax_time = 120.0\n",
    );
    let log_path = scratch("swing-sigint.csv");
    let child = spawn_run(
        &emu.device,
        "mpc",
        &with_lockstep(&[
            "--swing-up",
            "--config",
            cfg.to_str().unwrap(),
            "--log",
            log_path.to_str().unwrap(),
        ]),
    );
    // Wait for the swing's enabling commands (the sign check's pulse is ±2 V only, and the
    // rest after it 0 V), then signal.
    let start = std::time::Instant::now();
    let mut child = child;
    while !emu
        .commands_so_far()
        .iter()
        .any(|&(mv, f)| f & 1 != 0 && ![0, 2000, -2000].contains(&mv))
    {
        if child.try_wait().unwrap().is_some() {
            let r = wait_with_timeout(child, std::time::Duration::from_secs(1));
            panic!(
                "the run ended before the swing: {:?}\n{}",
                r.status, r.stderr
            );
        }
        assert!(start.elapsed().as_secs() < 40, "the swing never started");
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let r = wait_with_timeout(child, std::time::Duration::from_secs(10));
    assert_eq!(r.status.code(), Some(130), "{}", r.stderr);
    let commands = emu.commands();
    assert!(
        commands.iter().any(|&(mv, f)| f == 1 && mv != 0),
        "{}",
        r.stderr
    );
    assert_eq!(commands.last(), Some(&(0, 0)));
    let log = Log::read(&log_path);
    assert_eq!(log.meta("stop"), Some("signal"));
    assert_eq!(log.meta("catch_s"), Some("none"));
    let phase = log.text("phase");
    let swing = phase.iter().position(|p| p != "sign_check").unwrap();
    assert!(phase[swing..].iter().all(|p| p == "swing_up"), "{phase:?}");
    // The swing itself drove the motor before the stop.
    let u = log.col("u");
    assert!(u[swing..].iter().any(|v| *v != 0.0));
}

#[test]
fn a_rig_that_is_not_at_rest_is_refused_before_any_enabling_command() {
    let _serial = one_at_a_time();
    // Released 0.34 rad from hanging: it swings for far longer than the check waits.
    let emu = Emulator::lockstep(
        "swing-not-at-rest",
        &["--initial-pendulum", "2.8", "--no-hold"],
    );
    let cfg = config("swing-not-at-rest", "");
    let log_path = scratch("swing-not-at-rest.csv");
    let r = run_lockstep(
        &emu.device,
        "lqr",
        &[
            "--swing-up",
            "--config",
            cfg.to_str().unwrap(),
            "--log",
            log_path.to_str().unwrap(),
        ],
    );
    assert_eq!(r.status.code(), Some(12), "{}", r.stderr);
    assert!(r.stderr.contains("not at rest"), "{}", r.stderr);
    assert!(r.stderr.contains("the pendulum is moving"), "{}", r.stderr);
    let commands = emu.commands();
    assert!(!commands.is_empty());
    assert!(
        commands.iter().all(|&c| c == (0, 0)),
        "an enabling command was sent: {commands:?}"
    );
    let log = Log::read(&log_path);
    assert_eq!(log.meta("stop"), Some("not_at_rest"));
    assert!(log.rows.is_empty());
}

#[test]
fn a_swing_up_out_of_time_stops_with_exit_13_its_arm_inside_a_tight_limit() {
    let _serial = one_at_a_time();
    // 1 s is too short to pump a hanging pendulum up; 0.8 rad of arm holds the law in hard.
    const LIMIT: f64 = 0.8;
    let emu = Emulator::lockstep("swing-timeout", &["--start", "down", "--noise", "0.3"]);
    let cfg = config(
        "swing-timeout",
        &format!("[swing_up]\nmax_time = 1.0\narm_limit = {LIMIT}\ncatch_arm_angle = 0.5\n"),
    );
    let log_path = scratch("swing-timeout.csv");
    let r = run_lockstep(
        &emu.device,
        "lqg",
        &[
            "--swing-up",
            "--config",
            cfg.to_str().unwrap(),
            "--log",
            log_path.to_str().unwrap(),
        ],
    );
    assert_eq!(r.status.code(), Some(13), "{}", r.stderr);
    assert!(r.stderr.contains("swing_up.max_time"), "{}", r.stderr);
    let log = Log::read(&log_path);
    assert_eq!(log.meta("stop"), Some("swing_up_failed"));
    let theta = log.col("theta");
    let max_theta = theta.iter().fold(0.0f64, |m, a| m.max(a.abs()));
    // The law used its room (so the limit, not a timid swing, kept the arm in) and kept
    // inside it.
    assert!(max_theta > 0.5 * LIMIT, "|θ| only up to {max_theta}");
    assert!(max_theta <= LIMIT, "|θ| up to {max_theta}");
    // The supervisor counts its 1 s in samples (held periods included): at most 100 rows
    // after the sign check's.
    let rows = log
        .text("phase")
        .iter()
        .filter(|p| *p == "swing_up")
        .count();
    assert!((50..=100).contains(&rows), "{rows} rows");
    let commands = emu.commands();
    assert_eq!(commands.last(), Some(&(0, 0)));
}

#[test]
fn an_emulator_started_from_the_files_initial_state_rests_there() {
    let _serial = one_at_a_time();
    let file = scratch("initial-state.toml");
    std::fs::write(
        &file,
        format!("[plant]\ninitial_state = [0.3, 0.0, {PI}, 0.0]\nfall_limit = 4.0\n"),
    )
    .unwrap();
    let (result, _, _) = rest_check("rest-from-file", &["--config", file.to_str().unwrap()], "");
    let cal = result.unwrap();
    assert!(
        (cal.arm_zero_counts - 0.3 * 2048.0 / TAU).abs() < 0.6,
        "{cal}"
    );
    assert!((cal.pendulum_hanging_counts - 2048.0).abs() < 0.6, "{cal}");
}

/// A stand-in supervisor for the probe: in the swing-up (until it sees the pendulum near
/// upright and still, as the probe's settling samples show it) each step takes `swing_sleep`.
struct SlowSwing {
    phase: rip_core::Phase,
    last: f64,
    swing_sleep: std::time::Duration,
}

impl rip_core::Controller for SlowSwing {
    fn n_outputs(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn step(&mut self, y: &[f64], _r: &[f64], u: &mut [f64]) -> rip_core::StepStatus {
        if self.phase == rip_core::Phase::SwingUp {
            std::thread::sleep(self.swing_sleep);
            if y[1].abs() < 0.3 && y[1] == self.last {
                self.phase = rip_core::Phase::Balance;
            }
        }
        self.last = y[1];
        u[0] = 0.0;
        rip_core::StepStatus::Nominal
    }
    fn phase(&self) -> rip_core::Phase {
        self.phase
    }
    fn reset(&mut self) {
        self.phase = rip_core::Phase::SwingUp;
    }
}

#[test]
fn the_probe_times_swing_up_steps_and_refuses_slow_ones() {
    let cfg = Config::default();
    let probe = |sleep_ms: u64| {
        let c = SlowSwing {
            phase: rip_core::Phase::SwingUp,
            last: f64::NAN,
            swing_sleep: std::time::Duration::from_millis(sleep_ms),
        };
        let mut core = LoopCore::new(Box::new(c), &cfg).unwrap();
        assert!(core.supervises_swing_up());
        let result = rip_rt::runner::probe(&mut core, &cfg);
        // Reset afterwards: swinging again.
        assert_eq!(core.phase(), rip_core::Phase::SwingUp);
        result
    };
    // Fast swing-up steps: ten of them timed, then the balance steps after the catch.
    let p = probe(0).unwrap();
    assert_eq!(p.swing_steps, rip_rt::runner::PROBE_SWING_STEPS);
    assert_eq!(p.steps, p.swing_steps + rip_rt::runner::PROBE_STEPS);
    // Swing-up steps of 8 ms do not fit the 5 ms a period leaves after the reply timeout,
    // however fast the balance steps are.
    let e = probe(8).unwrap_err();
    assert_eq!(e.exit_code(), 11, "{e}");
}

#[test]
fn a_swing_up_a_stop_could_not_brake_names_the_largest_arm_limit_and_that_one_runs() {
    // A 1.8 rad safety limit: a stop from the edge of a 1.45 rad swing has no room.
    let text = |arm_limit: &str| {
        format!(
            "[plant]\npreset = \"paper\"\n[safety]\narm_limit = 1.8\n\
             [swing_up]\narm_limit = {arm_limit}\n"
        )
    };
    let swing = |name: &str, arm_limit: &str| {
        let file = scratch(name);
        std::fs::write(&file, text(arm_limit)).unwrap();
        let r = run(
            std::path::Path::new("/nonexistent"),
            "lqr",
            &["--swing-up", "--config", file.to_str().unwrap()],
        );
        (r.status.code(), r.stderr)
    };
    let (code, err) = swing("swing-stop-wide.toml", "1.45");
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("swing_up.arm_limit: 1.45 rad"), "{err}");
    let at = err.find("at most ").expect(&err) + "at most ".len();
    let largest = err[at..].split(" rad").next().unwrap().to_string();
    let value: f64 = largest.parse().expect(&err);
    assert!(value > 0.7 && value < 1.45, "{err}");
    assert!(!err.contains("where swing_up."), "{err}");
    // The value named passes the check: the run goes on to the port, which does not exist.
    let (code, err) = swing("swing-stop-largest.toml", &largest);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--port /nonexistent"), "{err}");
    assert!(!err.contains("swing_up.arm_limit"), "{err}");
    // One step above it does not.
    let (code, err) = swing("swing-stop-above.toml", &format!("{:.2}", value + 0.01));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(&format!("at most {largest} rad passes")),
        "{err}"
    );
}

#[test]
fn a_swing_up_arm_limit_outside_the_safety_limit_is_refused_naming_it() {
    let file = scratch("swing-arm-limit.toml");
    // Valid for rip-core (at most π), but not inside rip-rt's safety.arm_limit (3 rad).
    std::fs::write(
        &file,
        "[swing_up]\narm_limit = 3.1\ncatch_arm_angle = 1.0\n",
    )
    .unwrap();
    let r = run(
        std::path::Path::new("/nonexistent"),
        "lqr",
        &["--swing-up", "--config", file.to_str().unwrap()],
    );
    assert_eq!(r.status.code(), Some(2), "{}", r.stderr);
    assert!(r.stderr.contains("swing_up.arm_limit"), "{}", r.stderr);
    // One validation for the file: a run without --swing-up, like `rip-rt config` and
    // `riprs config`, refuses the swing-up it sets, naming the file and the key (it used to
    // accept the file, which the swing-up run then refused).
    let r = run(
        std::path::Path::new("/nonexistent"),
        "lqr",
        &["--config", file.to_str().unwrap()],
    );
    assert_eq!(r.status.code(), Some(2), "{}", r.stderr);
    let named = format!("{}: swing_up.arm_limit", file.display());
    assert!(r.stderr.contains(&named), "{}", r.stderr);
}

#[test]
fn a_swing_up_region_or_voltage_beyond_the_safety_limits_is_refused_naming_both_keys() {
    for (name, text, key, safety) in [
        (
            "swing-balance-angle",
            "[swing_up]\nbalance_angle = 1.2\n",
            "swing_up.balance_angle",
            "safety.pendulum_limit",
        ),
        // A file that lowers only the voltage limit is refused through it (the key it wrote),
        // naming the default swing-up voltage it must hold.
        (
            "swing-max-voltage",
            "[safety]\nvoltage_limit = 10.0\n",
            "safety.voltage_limit",
            "swing_up.max_voltage",
        ),
    ] {
        let file = scratch(&format!("{name}.toml"));
        std::fs::write(&file, text).unwrap();
        let r = run(
            std::path::Path::new("/nonexistent"),
            "lqr",
            &["--swing-up", "--config", file.to_str().unwrap()],
        );
        assert_eq!(r.status.code(), Some(2), "{name}: {}", r.stderr);
        assert!(r.stderr.contains(key), "{name}: {}", r.stderr);
        assert!(r.stderr.contains(safety), "{name}: {}", r.stderr);
        // The message names the file, as every other configuration error does.
        let named = format!("{}: {key}", file.display());
        assert!(r.stderr.contains(&named), "{name}: {}", r.stderr);
        // `rip-rt config` refuses what the file sets of `[swing_up]`, with the same message
        // (the second file leaves the swing-up at its defaults: only a swing-up run needs
        // them inside a lowered voltage limit).
        let checked = std::process::Command::new(BIN)
            .arg("config")
            .arg(&file)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&checked.stderr);
        if text.contains("[swing_up]") {
            assert_eq!(checked.status.code(), Some(2), "{name}: {stderr}");
            assert!(stderr.contains(&named), "{name}: {stderr}");
        } else {
            assert!(checked.status.success(), "{name}: {stderr}");
        }
    }
}

#[test]
fn a_pendulum_resting_a_tenth_of_a_radian_off_hanging_is_refused_by_default() {
    let _serial = one_at_a_time();
    // 0.1 rad (about 6°) from hanging: still, but held or leaning. Calibrating it as hanging
    // would shift the upright by 0.1 rad, which the balance controllers do not survive.
    let (result, _, commands) = rest_check("rest-off01", &["--initial-pendulum", "3.04"], "");
    let reason = result.unwrap_err();
    assert_eq!(reason.exit_code(), 12, "{reason}");
    let text = reason.to_string();
    assert!(text.contains("calibration.max_pendulum_offset"), "{text}");
    assert!(!text.contains("pendulum_sign"), "{text}");
    assert!(commands.iter().all(|&(_, flags)| flags & 1 == 0));
}

#[test]
fn a_wrong_pendulum_counts_per_rev_is_stopped_by_the_witness() {
    let _serial = one_at_a_time();
    // The pendulum encoder counts 2140 a turn where the rig's configuration says 2048: the
    // calibration at hanging is right, but the swing under gravity reads nonlinearly wrong
    // (half a turn from hanging reads 0.14 rad past upright). Before the witness each catch
    // dropped the pendulum again and the run cycled through falls until swing_up.max_time
    // (exit 13); the pendulum's gravity is the reference that tells the scale is wrong.
    // (Its zero offset puts hanging at a whole turn of counts, where the rig's reads it.)
    let emu_cfg = scratch("swing-cycle-emulator.toml");
    std::fs::write(
        &emu_cfg,
        "[sensor]\nencoder_counts = [2048, 2140]\nencoder_offsets = [0.0, -0.27012]\n",
    )
    .unwrap();
    let emu = Emulator::lockstep(
        "swing-cycle",
        &["--start", "down", "--config", emu_cfg.to_str().unwrap()],
    );
    let cfg = config(
        "swing-cycle",
        "[swing_up]\nmax_time = 10.0\n[safety]\narm_limit = 4.0\n",
    );
    let log_path = scratch("swing-cycle.csv");
    let r = run_lockstep(
        &emu.device,
        "lqr",
        &[
            "--swing-up",
            "--duration",
            "5",
            "--config",
            cfg.to_str().unwrap(),
            "--log",
            log_path.to_str().unwrap(),
        ],
    );
    assert_eq!(r.status.code(), Some(15), "{}", r.stderr);
    assert!(
        r.stderr.contains("sensor.encoder_counts[1]"),
        "{}",
        r.stderr
    );
    let log = Log::read(&log_path);
    assert_eq!(log.meta("stop"), Some("witness"));
    assert_eq!(emu.commands().last(), Some(&(0, 0)));
}

#[test]
fn a_reversed_motor_or_arm_encoder_is_refused_before_the_swing_with_exit_14() {
    let _serial = one_at_a_time();
    for (fault, expected) in [
        ("--reverse-motor", "swap the motor leads"),
        ("--reverse-arm-encoder", "device.arm_sign = -1"),
    ] {
        let name = format!("swing-sign{fault}");
        let emu = Emulator::lockstep(&name, &["--start", "down", "--noise", "0.3", fault]);
        let cfg = config(&name, "");
        let log_path = scratch(&format!("{name}.csv"));
        let r = run_lockstep(
            &emu.device,
            "lqr",
            &[
                "--swing-up",
                "--config",
                cfg.to_str().unwrap(),
                "--log",
                log_path.to_str().unwrap(),
            ],
        );
        assert_eq!(r.status.code(), Some(14), "{fault}: {}", r.stderr);
        assert!(r.stderr.contains(expected), "{fault}: {}", r.stderr);
        assert!(!r.stderr.contains("swinging up"), "{fault}: {}", r.stderr);
        let log = Log::read(&log_path);
        assert_eq!(log.meta("stop"), Some("sign_check"), "{fault}");
        assert_eq!(log.meta("sign_check"), Some("not passed"), "{fault}");
        let phase = log.text("phase");
        assert!(!phase.is_empty(), "{fault}: no sign-check rows");
        assert!(
            phase.iter().all(|p| p == "sign_check"),
            "{fault}: swing-up rows after a failed check"
        );
        // The pulse, +2 V then −2 V, and otherwise nothing but 0 V; the last command 0 V,
        // disabled.
        let commands = emu.commands();
        assert!(commands.iter().all(|c| [0, 2000, -2000].contains(&c.0)));
        let pulse = commands.iter().filter(|c| c.1 != 0 && c.0 != 0).count();
        assert!(
            (28..=32).contains(&pulse),
            "{fault}: {pulse} pulse commands"
        );
        assert_eq!(commands.last(), Some(&(0, 0)), "{fault}");
    }
}

/// 0.05 V cannot make up the pendulum's friction over its last swing (rip-core's energy
/// balance): the pre-flight's swing_up check refuses the run (exit 16), naming the voltage it
/// would need, before the port is opened, so before any enabling command. `--force` overrides
/// it as it does every pre-flight refusal: the run goes on to the rest check and the sign
/// check's pulse, and then swings in vain until `swing_up.max_time`.
#[test]
fn a_rig_that_cannot_be_swung_up_is_refused_by_the_preflight_unless_forced() {
    let _serial = one_at_a_time();
    let cfg = config(
        "swing-impossible",
        "[swing_up]\nmax_voltage = 0.05\nmax_time = 1.0\n",
    );
    let args = ["--swing-up", "--config", cfg.to_str().unwrap()];
    let refused = |r: &RunResult| {
        assert_eq!(r.status.code(), Some(16), "{}", r.stderr);
        assert!(
            r.stderr
                .contains("swing_up [refuse]: swing_up.max_voltage: no swing-up is possible")
                && r.stderr.contains("it would need about")
                && r.stderr.contains("--force"),
            "{}",
            r.stderr
        );
    };
    let r = run(std::path::Path::new("/nonexistent"), "lqr", &args);
    refused(&r);
    assert!(!r.stderr.contains("/nonexistent"), "{}", r.stderr);

    let emu = hanging_rig("swing-impossible", &cfg, &[], true);
    refused(&run_lockstep(&emu.device, "lqr", &args));
    // The emulator writes its record once it runs; a refusal can come before that.
    let start = std::time::Instant::now();
    while !emu.record.exists() {
        assert!(start.elapsed().as_secs() < 30, "no record {:?}", emu.record);
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    assert_eq!(before_enabling(&emu.commands()), emu.commands().len());

    let mut forced = args.to_vec();
    forced.push("--force");
    let r = run_lockstep(&emu.device, "lqr", &forced);
    assert_ne!(r.status.code(), Some(16), "{}", r.stderr);
    assert!(
        r.stderr
            .contains("warning: --force: swing_up [refuse]: swing_up.max_voltage"),
        "{}",
        r.stderr
    );
    let commands = emu.commands();
    assert!(
        before_enabling(&commands) < commands.len(),
        "the motor was never enabled: {}",
        r.stderr
    );
}

/// The feasibility verdict `riprs tune` stored beside the rig file is the one the run uses
/// while its checksum matches the file's model and swing-up bounds: a stored "impossible" for
/// a rig the energy balance allows is obeyed (so the verdict was read, not computed), and the
/// same record made stale by an edit of the file is ignored and the verdict computed again.
#[test]
fn the_run_reads_the_stored_swing_up_verdict_while_its_checksum_matches() {
    use rip_core::preflight::tune_record_path;
    use rip_core::swingup::StoredFeasibility;
    let file = scratch("swing-stored.toml");
    std::fs::write(&file, "[swing_up]\nmax_voltage = 11.0\n").unwrap();
    let cfg = Config::load(&file).unwrap();
    let plant = cfg.spec.plant().unwrap();
    let computed = StoredFeasibility::compute(&plant, &cfg.spec.swing_up);
    assert_eq!(computed.verdict, "not_excluded");
    let stored = StoredFeasibility {
        verdict: "impossible".into(),
        voltage_needed: Some(99.0),
        time_estimate: f64::INFINITY,
        ..computed
    };
    let record = tune_record_path(&file);
    let record_text = format!(
        "inputs = \"fnv1a64:0000000000000000\"\nruns = \"none\"\n[prediction]\n{}",
        stored.to_section()
    );
    std::fs::write(&record, &record_text).unwrap();
    let nowhere = std::path::Path::new("/nonexistent");
    let args = ["--swing-up", "--config", file.to_str().unwrap()];
    let r = run(nowhere, "lqr", &args);
    assert_eq!(r.status.code(), Some(16), "{}", r.stderr);
    assert!(r.stderr.contains("swing_up [refuse]"), "{}", r.stderr);
    assert!(r.stderr.contains("about 99.0 V"), "{}", r.stderr);
    assert!(r.stderr.contains("stored by riprs tune"), "{}", r.stderr);
    assert!(!r.stderr.contains("/nonexistent"), "{}", r.stderr);
    // The file's voltage edited after tuning: the record is stale, the verdict computed
    // again (not excluded), and the run goes on to the port.
    std::fs::write(&file, "[swing_up]\nmax_voltage = 11.5\n").unwrap();
    let r = run(nowhere, "lqr", &args);
    assert_ne!(r.status.code(), Some(0), "{}", r.stderr);
    assert!(r.stderr.contains("is stale"), "{}", r.stderr);
    assert!(
        r.stderr.contains("a swing-up is not excluded"),
        "{}",
        r.stderr
    );
    assert!(r.stderr.contains("/nonexistent"), "{}", r.stderr);
}
