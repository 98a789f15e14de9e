//! Tests of the loop's logic without I/O.
use super::*;
use crate::protocol::Parser;
use crate::stop::exit_code;

/// A controller whose output is a fixed function of y, to check the plumbing.
struct Affine {
    gain: f64,
}

impl Controller for Affine {
    fn n_outputs(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        u[0] = self.gain * (r[0] - y[0]) + 100.0 * y[1];
        StepStatus::Nominal
    }
    fn reset(&mut self) {}
}

/// Records what the loop tells it about held periods.
struct Recorder {
    held: std::sync::Arc<std::sync::Mutex<Vec<f64>>>,
}

impl Controller for Recorder {
    fn n_outputs(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn step(&mut self, _y: &[f64], _r: &[f64], u: &mut [f64]) -> StepStatus {
        u[0] = 3.21049;
        StepStatus::Nominal
    }
    fn hold(&mut self, u: &[f64]) {
        self.held.lock().unwrap().push(u[0]);
    }
    fn reset(&mut self) {}
}

fn core(gain: f64) -> LoopCore {
    LoopCore::new(Box::new(Affine { gain }), &Config::default()).unwrap()
}

fn measurement(ack: u16, arm: i32, pend: i32) -> Measurement {
    Measurement {
        ack_seq: ack,
        arm_counts: arm,
        pendulum_counts: pend,
        ..Default::default()
    }
}

fn decode_one(bytes: &[u8]) -> Frame {
    let mut p = Parser::new();
    let mut out = None;
    p.feed(bytes, |f| out = Some(f));
    out.expect("one frame")
}

#[test]
fn hold_passes_the_command_the_device_applies() {
    let held = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let rec = Recorder { held: held.clone() };
    let mut c = LoopCore::new(Box::new(rec), &Config::default()).unwrap();
    let mut out = [0u8; MAX_FRAME];
    // Before any command the driver is disabled: 0 V.
    assert_eq!(c.hold(), 0.0);
    c.control(&measurement(1, 0, 1024), 0.0, &mut out).unwrap();
    // The command is rounded to millivolts; the controller hears the rounded value.
    assert_eq!(c.hold(), 3.21);
    c.encode_stop(&mut out);
    assert_eq!(c.hold(), 0.0);
    assert_eq!(*held.lock().unwrap(), vec![0.0, 3.21, 0.0]);
}

#[test]
fn counts_map_to_angles_with_upright_zero() {
    let c = core(1.0);
    // 2048 counts/rev; pendulum zero hanging down: 1024 counts = upright.
    let (theta, alpha) = c.angles(&measurement(0, 512, 1024));
    assert!((theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert!(alpha.abs() < 1e-12);
    let (_, alpha) = c.angles(&measurement(0, 0, 1024 + 2048 * 3 + 10));
    assert!((alpha - 10.0 * std::f64::consts::TAU / 2048.0).abs() < 1e-9);
    let (_, alpha) = c.angles(&measurement(0, 0, 0));
    assert!((alpha - std::f64::consts::PI).abs() < 1e-12);
}

/// A stand-in for the swing-up supervisor: starts swinging, and its phase after each step is
/// the next of `script`.
struct Scripted {
    phase: Phase,
    script: Vec<Phase>,
}

impl Controller for Scripted {
    fn n_outputs(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn step(&mut self, _y: &[f64], _r: &[f64], u: &mut [f64]) -> StepStatus {
        if !self.script.is_empty() {
            self.phase = self.script.remove(0);
        }
        u[0] = 2.0;
        StepStatus::Nominal
    }
    fn phase(&self) -> Phase {
        self.phase
    }
    fn reset(&mut self) {}
}

fn supervised(script: Vec<Phase>) -> LoopCore {
    let c = Scripted {
        phase: Phase::SwingUp,
        script,
    };
    // Scripted measurements no plant makes: the witness would stop them.
    LoopCore::new(Box::new(c), &Config::default())
        .unwrap()
        .without_witness()
}

#[test]
fn a_swing_up_owns_the_pendulum_rule_but_not_the_arm_limit() {
    let mut c = supervised(vec![Phase::SwingUp, Phase::Balance]);
    assert!(c.supervises_swing_up());
    assert!(!core(1.0).supervises_swing_up());
    let mut out = [0u8; MAX_FRAME];
    // Hanging (0 counts, α = π): no fall while swinging; the command goes out.
    let s = c.control(&measurement(1, 0, 0), 0.0, &mut out).unwrap();
    assert_eq!((s.voltage, s.phase), (2.0, Phase::SwingUp));
    // Nor after the catch: 0.7 rad is past safety.pendulum_limit (0.6), and it is the
    // supervisor's balance region that decides.
    let pend = 1024 + (0.7 / std::f64::consts::TAU * 2048.0) as i32;
    let s = c.control(&measurement(2, 0, pend), 0.01, &mut out).unwrap();
    assert_eq!(s.phase, Phase::Balance);
    // The arm limit (3 rad) stays a stop.
    let e = c
        .control(&measurement(3, 1000, 0), 0.02, &mut out)
        .unwrap_err();
    assert!(
        matches!(e, StopReason::AngleLimit { which: "arm", .. }),
        "{e}"
    );
}

#[test]
fn a_supervisor_that_gives_up_stops_the_loop_without_a_command() {
    for (cause, code) in [
        (StopCause::SwingUpTimeout, exit_code::SWING_UP_FAILED),
        (StopCause::LeftBalanceRegion, exit_code::ANGLE_LIMIT),
    ] {
        let mut c = supervised(vec![Phase::SwingUp, Phase::Stopped(cause)]);
        let mut out = [0u8; MAX_FRAME];
        c.control(&measurement(1, 0, 0), 0.0, &mut out).unwrap();
        assert_eq!(c.held_voltage(), 2.0);
        out.fill(0);
        let e = c
            .control(&measurement(2, 0, 0), 0.01, &mut out)
            .unwrap_err();
        assert_eq!(e.exit_code(), code, "{e}");
        assert!(e.to_string().contains("swing_up."), "{e}");
        // Nothing encoded; the loop's stop guard sends the stop frame.
        assert!(out.iter().all(|&b| b == 0));
    }
}

#[test]
fn a_fall_names_the_part_that_left_the_balance_region() {
    let fell = |arm: i32, pend: i32| {
        let mut c = supervised(vec![
            Phase::Balance,
            Phase::Stopped(StopCause::LeftBalanceRegion),
        ]);
        let mut out = [0u8; MAX_FRAME];
        c.control(&measurement(1, 0, 1024), 0.0, &mut out).unwrap();
        c.control(&measurement(2, arm, pend), 0.01, &mut out)
            .unwrap_err()
    };
    // The arm at 1.53 rad (500 counts) is past swing_up.arm_limit (1.5 rad) while the
    // pendulum (0.3 rad) is well inside swing_up.balance_angle (0.6 rad).
    let pend = 1024 + (0.3 / std::f64::consts::TAU * 2048.0) as i32;
    let e = fell(500, pend);
    assert_eq!(e.exit_code(), exit_code::ANGLE_LIMIT);
    let text = e.to_string();
    assert!(
        text.contains("arm") && text.contains("swing_up.arm_limit"),
        "{text}"
    );
    assert!(!text.contains("balance_angle"), "{text}");
    // The pendulum at 0.7 rad with the arm at 0: the pendulum's bound.
    let pend = 1024 + (0.7 / std::f64::consts::TAU * 2048.0) as i32;
    let text = fell(0, pend).to_string();
    assert!(
        text.contains("pendulum") && text.contains("swing_up.balance_angle"),
        "{text}"
    );
    assert!(!text.contains("arm_limit"), "{text}");
}

#[test]
fn a_swing_ups_reference_starts_at_the_catch() {
    let mut c = supervised(vec![]);
    // Before the catch the arm reference is 0 however long the swing takes.
    assert_eq!(c.reference_at(100.0), 0.0);
    c.start_reference_at(4.0);
    // The step (1 rad) comes reference.step_time (1 s) after the catch.
    assert_eq!(c.reference_at(4.99), 0.0);
    assert_eq!(c.reference_at(5.0), 1.0);
    // A balancing run's reference starts with it.
    assert_eq!(core(1.0).reference_at(1.0), 1.0);
}

#[test]
fn calibration_moves_both_zeros() {
    let mut c = core(1.0);
    let cal = Calibration {
        arm_zero_counts: 100.0,
        pendulum_hanging_counts: -7.5,
        pendulum_offset: 0.0,
        spread_counts: [0.0, 0.0],
        max_rates: [0.0, 0.0],
        after_s: 1.0,
    };
    c.calibrate(&cal);
    let count = std::f64::consts::TAU / 2048.0;
    // The rest pose reads θ = 0, α = π (hanging); half a turn on is upright.
    let (theta, alpha) = c.angles(&measurement(0, 100, -7));
    assert!(theta.abs() < 1e-12);
    assert!((alpha.abs() - (std::f64::consts::PI - 0.5 * count)).abs() < 1e-12);
    let (theta, alpha) = c.angles(&measurement(0, 612, -7 + 1024));
    assert!((theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert!((alpha - 0.5 * count).abs() < 1e-12);
}

#[test]
fn control_encodes_clamped_enabling_command() {
    let mut c = core(-100.0);
    let mut out = [0u8; MAX_FRAME];
    // theta = π/2 > step 0, so u = -100·(0 − π/2) = 157 V → clamped to 12 V.
    let s = c
        .control(&measurement(3, 512, 1024), 0.0, &mut out)
        .unwrap();
    assert_eq!(s.voltage, 12.0);
    assert!(s.flags & FLAG_CLAMPED != 0);
    match decode_one(&out[..s.len]).message {
        Message::Command(cmd) => {
            assert_eq!(cmd.voltage_mv, 12000);
            assert!(cmd.enabled());
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn limits_and_faults_stop_without_a_command() {
    let mut c = core(1.0);
    let mut out = [0u8; MAX_FRAME];
    // Pendulum 0.7 rad from upright > 0.6 limit.
    let pend = 1024 + (0.7 / std::f64::consts::TAU * 2048.0) as i32;
    let e = c
        .control(&measurement(0, 0, pend), 0.0, &mut out)
        .unwrap_err();
    assert!(
        matches!(
            e,
            StopReason::AngleLimit {
                which: "pendulum",
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(e.exit_code(), exit_code::ANGLE_LIMIT);
    let e = c
        .control(&measurement(0, 1100, 1024), 0.0, &mut out)
        .unwrap_err();
    assert!(
        matches!(e, StopReason::AngleLimit { which: "arm", .. }),
        "{e}"
    );
    let mut m = measurement(0, 0, 1024);
    m.status = STATUS_FAULT;
    let e = c.control(&m, 0.0, &mut out).unwrap_err();
    assert_eq!(e.exit_code(), exit_code::DEVICE_FAULT);
}

#[test]
fn start_requires_upright() {
    let c = core(1.0);
    assert!(c.check_start(&measurement(0, 0, 1030)).is_ok());
    let e = c.check_start(&measurement(0, 0, 0)).unwrap_err();
    assert_eq!(e.exit_code(), exit_code::NOT_UPRIGHT);
    assert!(e.to_string().contains("refusing"), "{e}");
}

#[test]
fn non_finite_output_is_a_controller_fault() {
    let mut c = core(f64::NAN);
    let mut out = [0u8; MAX_FRAME];
    let e = c
        .control(&measurement(0, 0, 1024), 0.0, &mut out)
        .unwrap_err();
    assert_eq!(e.exit_code(), exit_code::CONTROLLER_FAULT);
}

#[test]
fn a_held_command_goes_stale_whatever_the_watchdog() {
    // A configuration that was never validated: a watchdog of u32::MAX periods.
    let mut cfg = Config::default();
    cfg.loop_.watchdog_periods = u32::MAX;
    let mut c = LoopCore::new(Box::new(Affine { gain: 1.0 }), &cfg).unwrap();
    let mut out = [0u8; MAX_FRAME];
    c.control(&measurement(1, 0, 1024), 0.0, &mut out).unwrap();
    // 100 ms at 10 ms: ten repeats of the enabling command, then no more.
    for k in 1..=10 {
        let n = c.encode_held(&mut out).unwrap();
        match decode_one(&out[..n]).message {
            Message::Command(cmd) => assert!(cmd.enabled(), "repeat {k}"),
            other => panic!("{other:?}"),
        }
    }
    let e = c.encode_held(&mut out).unwrap_err();
    assert_eq!(e.exit_code(), crate::stop::exit_code::WATCHDOG, "{e}");
    // A fresh measurement starts the count again.
    c.control(&measurement(2, 0, 1024), 0.01, &mut out).unwrap();
    assert!(c.encode_held(&mut out).is_ok());
    // The stop command may be repeated for ever.
    c.encode_stop(&mut out);
    for _ in 0..100 {
        c.encode_held(&mut out).unwrap();
    }
}

#[test]
fn an_unvalidated_voltage_limit_is_capped() {
    let mut cfg = Config::default();
    cfg.safety.voltage_limit = 1e9;
    let mut c = LoopCore::new(Box::new(Affine { gain: -1e6 }), &cfg).unwrap();
    let mut out = [0u8; MAX_FRAME];
    let s = c
        .control(&measurement(3, 512, 1024), 0.0, &mut out)
        .unwrap();
    assert_eq!(s.voltage, MAX_VOLTAGE_LIMIT);
}

#[test]
fn drive_checks_the_arm_but_not_the_hanging_pendulum() {
    let mut c = LoopCore::open_loop(&Config::default());
    let mut out = [0u8; MAX_FRAME];
    // Hanging down (0 counts): far outside the pendulum limit, which does not apply.
    let s = c.drive(&measurement(1, 0, 0), 30.0, 0.0, &mut out).unwrap();
    assert_eq!(s.voltage, 12.0);
    assert!(s.flags & FLAG_CLAMPED != 0);
    match decode_one(&out[..s.len]).message {
        Message::Command(cmd) => assert_eq!((cmd.voltage_mv, cmd.enabled()), (12000, true)),
        other => panic!("{other:?}"),
    }
    let e = c
        .drive(&measurement(2, 1100, 0), 1.0, 0.0, &mut out)
        .unwrap_err();
    assert!(
        matches!(e, StopReason::AngleLimit { which: "arm", .. }),
        "{e}"
    );
    let e = c
        .drive(&measurement(3, 0, 0), f64::NAN, 0.0, &mut out)
        .unwrap_err();
    assert_eq!(e.exit_code(), exit_code::CONTROLLER_FAULT);
    let mut m = measurement(4, 0, 0);
    m.status = STATUS_FAULT;
    let e = c.drive(&m, 1.0, 0.0, &mut out).unwrap_err();
    assert_eq!(e.exit_code(), exit_code::DEVICE_FAULT);
}

#[test]
fn receive_ignores_stale_answers() {
    let mut c = core(1.0);
    let mut bytes = Vec::new();
    let mut buf = [0u8; MAX_FRAME];
    for ack in [4u16, 5] {
        let n = encode(
            &Frame {
                seq: 0,
                message: Message::Measurement(measurement(ack, ack as i32, 1024)),
            },
            &mut buf,
        );
        bytes.extend_from_slice(&buf[..n]);
    }
    assert_eq!(c.receive(&bytes, 4).map(|m| m.arm_counts), Some(4));
    assert_eq!(c.receive(&bytes, 9), None);
}
