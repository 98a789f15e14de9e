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
use rip_rt::timing::{now_ns, Periodic};

/// What [`rest_check`] saw: the check's outcome, the rest pose's angles after calibration, and
/// the commands the device received.
type RestOutcome = (
    Result<calibrate::Calibration, StopReason>,
    Option<(f64, f64)>,
    Vec<(i32, u8)>,
);

/// Runs the rest check of `cfg_text` against an emulator started with `emulator_args`.
fn rest_check(name: &str, emulator_args: &[&str], cfg_text: &str) -> RestOutcome {
    let emu = Emulator::start(name, emulator_args);
    let cfg = Config::from_toml(cfg_text).unwrap();
    let port = SerialPort::open(&emu.device, 115_200).unwrap();
    let controller = controllers::build(ControllerKind::Lqr, &cfg).unwrap();
    let mut core = LoopCore::new(controller, &cfg).unwrap();
    let guard = StopGuard::new(port.io().raw());
    let mut periodic = Periodic::new(cfg.period_ns(), now_ns() + cfg.period_ns());
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
