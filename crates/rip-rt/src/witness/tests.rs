use super::*;
use std::f64::consts::PI;

/// Drives the hanging paper rig open loop with `u(t)` and feeds the witness what an
/// encoder pair wired by `wiring` reads (2048 counts); returns the first fault and when.
fn drive(
    u: impl Fn(f64) -> f64,
    wiring: impl Fn(f64, f64) -> f64,
    seconds: f64,
) -> Option<(f64, WitnessFault)> {
    let cfg = Config::default();
    let plant = cfg.spec.plant().unwrap();
    let mut w = Witness::new(&cfg, WitnessLimits::default()).unwrap();
    let ts = cfg.period_s();
    let q = std::f64::consts::TAU / 2048.0;
    let mut x = State::new(0.0, 0.0, PI, 0.0);
    let mut prev = 0.0;
    for k in 0..(seconds / ts) as usize {
        let t = k as f64 * ts;
        let theta = (wiring(x[0], t) / q).round() * q;
        let alpha = wrap_angle((x[2] / q).round() * q);
        let dt = if k == 0 { 0.0 } else { ts };
        if let Err(f) = w.observe(theta, alpha, (prev, prev), dt, 0.0) {
            return Some((t, f));
        }
        prev = u(t);
        plant.advance(&mut x, prev, 0.0, ts, 10);
    }
    None
}

#[test]
fn a_rig_that_moves_as_commanded_never_trips() {
    // A ±3 V square wave of 0.4 s: the arm turns back and forth, the pendulum swings.
    let square = |t: f64| if (t / 0.2) as i64 % 2 == 0 { 3.0 } else { -3.0 };
    assert_eq!(drive(square, |theta, _| theta, 5.0), None);
    assert_eq!(drive(|_| 0.0, |theta, _| theta, 2.0), None);
}

#[test]
fn a_frozen_arm_encoder_is_named() {
    let (t, f) = drive(|_| 3.0, |_, _| 0.0, 2.0).expect("not stopped");
    assert!(matches!(f, WitnessFault::ArmFrozen { .. }), "{f}");
    assert!(t < 0.3, "{t}");
    assert!(f.to_string().contains("stopped counting"), "{f}");
}

#[test]
fn motion_against_the_voltage_is_named() {
    // The encoder counts backwards from 0.5 s on, while the arm turns under 3 V.
    let reversed = |theta: f64, t: f64| if t < 0.5 { theta } else { -theta };
    let (t, f) = drive(|_| 3.0, reversed, 2.0).expect("not stopped");
    assert!((0.5..0.6).contains(&t), "{t}");
    assert!(
        matches!(
            f,
            WitnessFault::ArmWrongWay { .. } | WitnessFault::ArmDisagrees { .. }
        ),
        "{f}"
    );
    assert!(f.to_string().contains("motor leads"), "{f}");
}

#[test]
fn a_reversed_motor_trips_the_sign_statistic_within_a_few_periods_and_a_scale_does_not() {
    // The encoder counts backwards from 0.5 s on while ±6 V square waves turn the arm:
    // the voltage's share of the motion reads reversed from the first period.
    let square = |t: f64| if (t / 0.1) as i64 % 2 == 0 { 6.0 } else { -6.0 };
    let reversed = |theta: f64, t: f64| if t < 0.5 { theta } else { -theta };
    let (t, f) = drive(square, reversed, 2.0).expect("not stopped");
    assert!((0.5..0.55).contains(&t), "{t}");
    assert!(
        matches!(f, WitnessFault::ArmWrongWay { stat, limit, .. } if stat > limit && limit == SIGN_THRESHOLD),
        "{f}"
    );
    // A quarter of the motion (8192 counts configured on a 2048-count encoder): the
    // voltage still moves the arm its way, so it is not named a reversal.
    if let Some((_, f)) = drive(square, |theta, _| theta / 4.0, 2.0) {
        assert!(!matches!(f, WitnessFault::ArmWrongWay { .. }), "{f}");
    }
}

#[test]
fn a_gap_of_lost_replies_is_no_evidence_of_a_fault() {
    // A ±6 V square wave swings the hanging rig hard; for each gap length every sample
    // in a window is lost (a silent device), then the samples return.
    let cfg = Config::default();
    // A rig a few per cent off the model, as an identified one is: the prediction across
    // a long gap drifts from it.
    let mut rig = cfg.spec.plant.params();
    rig.jp *= 1.03;
    rig.dr *= 1.2;
    let plant = Plant::new(rig).unwrap();
    let ts = cfg.period_s();
    let q = std::f64::consts::TAU / 2048.0;
    let square = |t: f64| {
        if (t / 0.15) as i64 % 2 == 0 {
            6.0
        } else {
            -6.0
        }
    };
    for gap in [2, 3, 5, 10, 20, 31, 45, 60] {
        let mut w = Witness::new(&cfg, WitnessLimits::default()).unwrap();
        let mut x = State::new(0.0, 0.0, PI, 0.0);
        // The voltage applied since the last sample the witness saw, and the command.
        let (mut before, mut command) = (0.0, 0.0);
        let mut last_seen: Option<f64> = None;
        for k in 0..300 {
            let t = k as f64 * ts;
            let lost = (100..100 + gap).contains(&k);
            if !lost {
                let theta = (x[0] / q).round() * q;
                let alpha = wrap_angle((x[2] / q).round() * q);
                let dt = last_seen.map_or(0.0, |s| t - s);
                let r = w.observe(theta, alpha, (before, command), dt, 0.0);
                assert!(r.is_ok(), "gap of {gap} periods: {r:?} at {t:.2} s");
                last_seen = Some(t);
                before = command;
                command = square(t);
            }
            plant.advance(&mut x, command, 0.0, ts, 10);
        }
        let [arm, pendulum, ..] = w.peak();
        assert!(
            arm < 0.5 * ARM_THRESHOLD && pendulum < 0.5 * PENDULUM_THRESHOLD,
            "gap of {gap} periods: peaks {arm:.1} / {pendulum:.1}"
        );
        let sign_peak = w.peak()[3];
        assert!(sign_peak < 0.5 * SIGN_THRESHOLD, "{sign_peak}");
    }
}

#[test]
fn a_gap_in_the_device_clock_restarts_the_observer() {
    let cfg = Config::default();
    let mut w = Witness::new(&cfg, WitnessLimits::default()).unwrap();
    w.observe(0.0, PI, (0.0, 0.0), 0.0, 0.0).unwrap();
    // A second later the arm is elsewhere: no prediction spans the gap.
    w.observe(1.0, PI, (0.0, 0.0), 1.0, 0.0).unwrap();
    w.observe(1.0, PI, (0.0, 0.0), 0.01, 0.0).unwrap();
    assert_eq!(w.statistic(), [0.0, 0.0]);
}
