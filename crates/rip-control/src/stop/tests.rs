//! Host tests of the stop's rule in `f64` and `f32`, against the physics it models and the
//! behaviour the module docs promise, on the `paper` preset's lumped constants (the swing's
//! tests' model).

use super::*;
use crate::swing::tests::{model, model_to};

const TS: f64 = 0.01;
const U: f64 = 12.0;

fn law() -> BrakingLaw<f64> {
    let m = model();
    let gain = (m.j0 + m.ja) / (2.0 * m.b * TS);
    BrakingLaw {
        voltage: U,
        linear_below: U / gain,
    }
}

fn simulated() -> SimulatedStop<f64> {
    SimulatedStop {
        model: model(),
        dead_zone: 0.3,
        law: law(),
        ts: TS,
        substeps: 10,
        latency_periods: 2,
    }
}

fn to_f32(s: &SimulatedStop<f64>) -> SimulatedStop<f32> {
    SimulatedStop {
        model: model_to(&s.model),
        dead_zone: s.dead_zone as f32,
        law: BrakingLaw {
            voltage: s.law.voltage as f32,
            linear_below: s.law.linear_below as f32,
        },
        ts: s.ts as f32,
        substeps: s.substeps,
        latency_periods: s.latency_periods,
    }
}

/// Full voltage against the motion above `ω_lin`, proportional below it, nothing for a rate
/// that is not finite.
#[test]
fn the_braking_law_opposes_the_motion_and_is_linear_near_rest() {
    let l = law();
    assert_eq!(l.voltage(10.0 * l.linear_below), -U);
    assert_eq!(l.voltage(-10.0 * l.linear_below), U);
    assert!((l.voltage(0.5 * l.linear_below) + 0.5 * U).abs() < 1e-12);
    assert_eq!(l.voltage(f64::NAN), 0.0);
    assert_eq!(l.voltage(f64::INFINITY), 0.0);
}

/// The simulated stop against the analytic distance (2) on a model whose pendulum cannot
/// push (hanging at rest, no coupling): the same share of the voltage, no latency and no dead
/// zone. The law is linear near rest, where (2) brakes at full voltage, and samples the rate
/// a period late: the arm stops past the analytic distance, by less than the travel of the
/// law's linear range and a period at the start speed.
#[test]
fn the_simulated_stop_of_a_lone_arm_matches_the_analytic_distance() {
    let mut m = model();
    m.m12 = 0.0;
    let fraction = SIMULATED_BRAKE_FRACTION;
    let j = m.j0;
    let analytic = StoppingModel {
        a0: fraction * m.b * U / j,
        // The back-EMF and the viscous friction act whole: only the voltage is a share.
        k: m.c_arm / j,
        drive_per_volt: m.b / j,
        latency: 0.0,
        voltage: U,
    };
    let stop = SimulatedStop {
        model: m,
        dead_zone: 0.0,
        law: law(),
        ts: TS,
        substeps: 10,
        latency_periods: 0,
    };
    for w in [2.0, 8.0, 20.0] {
        let d = analytic.braking_distance(w);
        let far = stop.stopping_point([0.0, w, core::f64::consts::PI, 0.0], 0.0);
        let linear = stop.law.linear_below;
        let slack = w * TS + linear * linear / (2.0 * analytic.a0) + linear * 2.0 * TS;
        assert!(far >= d && far <= d + slack, "{w}: {far} vs {d} + {slack}");
        let back = stop.stopping_point([0.0, -w, core::f64::consts::PI, 0.0], 0.0);
        assert!((back + far).abs() < 1e-9, "{back} vs {far}");
    }
    assert_eq!(stop.stopping_point([0.4, 0.0, 0.0, 0.0], 12.0), 0.4);
    assert_eq!(stop.stopping_point([0.4, f64::NAN, 0.0, 0.0], 12.0), 0.4);
}

/// The device runs the rule in `f32`: its simulated stop agrees with the host's `f64` one
/// within a millimetre's worth of arm angle over the states of a swing, a catch and a fall.
#[test]
fn the_simulated_stop_in_f32_agrees_with_f64() {
    let s64 = simulated();
    let s32 = to_f32(&s64);
    for (w, alpha, alpha_rate, applied) in [
        (15.7, 0.05, 1.0, 12.0),
        (8.0, core::f64::consts::PI, 0.0, -3.0),
        (-5.0, 2.5, 8.0, -12.0),
        (3.0, -0.4, 5.0, 0.0),
    ] {
        let x = [0.2, w, alpha, alpha_rate];
        let a = s64.stopping_point(x, applied);
        let b = s32.stopping_point(x.map(|v| v as f32), applied as f32);
        assert!((a - f64::from(b)).abs() < 5e-3, "{x:?}: {a} vs {b}");
    }
}

/// `f32` and `f64` brakes give the same commands on the same readings, the sign flipping
/// alike when the arm speeds up under it.
#[test]
fn the_brake_in_f32_commands_as_in_f64() {
    let l32 = BrakingLaw {
        voltage: U as f32,
        linear_below: law().linear_below as f32,
    };
    let mut b64 = Brake::new(law(), 0.5, BrakeMode::Checked);
    let mut b32 = Brake::new(l32, 0.5f32, BrakeMode::Checked);
    // A rig wired the other way: the arm speeds up under the checked law, then slows.
    let rates = (0..40).map(|k| {
        if k < 8 {
            5.0 + k as f64
        } else {
            12.0 - 0.3 * k as f64
        }
    });
    for rate in rates {
        let (c64, c32) = (b64.command(Some(rate)), b32.command(Some(rate as f32)));
        match (c64, c32) {
            (BrakeCommand::Volts(a), BrakeCommand::Volts(b)) => {
                assert!((a - f64::from(b)).abs() < 1e-4, "{rate}: {a} vs {b}")
            }
            (a, b) => assert_eq!(
                matches!(a, BrakeCommand::Short),
                matches!(b, BrakeCommand::Short)
            ),
        }
        assert_eq!(b64.mode(), b32.mode());
    }
    assert_eq!(b64.mode(), BrakeMode::Reversed);
    assert!(b64.sign_known());
}

/// Rest is less than [`REST_TRAVEL`] over [`REST_S`]; a reading that is not finite never rests.
#[test]
fn the_rest_test_waits_for_rest_s_of_stillness() {
    let mut r = RestTest::<f64>::new(TS);
    let periods = (REST_S / TS).ceil() as usize;
    for k in 0..periods {
        assert!(!r.observe(1.0 + 1e-4 * k as f64), "{k}");
    }
    assert!(r.observe(1.0));
    assert!(!r.observe(1.0 + REST_TRAVEL));
    let mut r = RestTest::<f64>::new(TS);
    for _ in 0..2 * periods {
        assert!(!r.observe(f64::NAN));
    }
}

/// The rates over the device's clock: across its wrap, and 0 for a clock that stood still or
/// jumped back.
#[test]
fn sample_rates_use_the_devices_clock_across_its_wrap() {
    let (w, a) = sample_rates(Some((1.0, 3.1, u32::MAX - 4_999)), 1.1, -3.1, 5_000);
    assert!((w - 10.0).abs() < 1e-9, "{w}");
    let expected = (2.0 * core::f64::consts::PI - 6.2) / 0.01;
    assert!((a - expected).abs() < 1e-6, "{a} vs {expected}");
    assert_eq!(
        sample_rates(Some((1.0, 0.0, 5_000)), 1.1, 0.0, 5_000),
        (0.0, 0.0)
    );
    assert_eq!(
        sample_rates(Some((1.0, 0.0, 5_000)), 1.1, 0.0, 4_000),
        (0.0, 0.0)
    );
    assert_eq!(sample_rates::<f64>(None, 1.1, 0.0, 4_000), (0.0, 0.0));
}

/// The envelope stops where the stopping point leaves the bound, never for a motion inwards,
/// and always for a state it cannot simulate.
#[test]
fn the_envelope_breaches_past_its_bound_only() {
    let m = model();
    let analytic = StoppingModel {
        a0: 0.5 * m.b * U / (m.j0 + m.ja),
        k: 0.5 * m.c_arm / (m.j0 + m.ja),
        drive_per_volt: m.b / (m.j0 - m.m12 * m.m12 / m.ja),
        latency: 2.0 * TS,
        voltage: U,
    };
    let env = ArmEnvelope::new(analytic, Some(simulated()), 2.95);
    let hanging = core::f64::consts::PI;
    assert!(env.check_state(2.0, 1.0, hanging, 0.0, 0.0).is_ok());
    assert!(env.check_state(2.9, -20.0, hanging, 0.0, -12.0).is_ok());
    let b = env.check_state(2.9, 20.0, hanging, 0.0, 12.0).unwrap_err();
    assert!(b.stop_at > 2.95 && b.bound == 2.95, "{b:?}");
    assert!(env.check_state(f64::NAN, 1.0, hanging, 0.0, 0.0).is_err());
}

/// Counts to angles: the pendulum wrapped into (−π, π], a reversed encoder by its sign; the
/// position rule stops at a NaN angle as past the limit.
#[test]
fn counts_become_angles_and_the_position_rule_takes_nan_as_past() {
    let q = core::f64::consts::TAU / 2048.0;
    let [theta, alpha] = angles([512, 1024 + 2048], [-q, q], [0.0, core::f64::consts::PI]);
    assert!(
        (theta + core::f64::consts::FRAC_PI_2).abs() < 1e-12,
        "{theta}"
    );
    assert!(alpha.abs() < 1e-12, "{alpha}");
    let [_, alpha] = angles::<f64>([0, 1024], [q, q], [0.0, 0.0]);
    assert_eq!(alpha, core::f64::consts::PI);
    assert!(!past_limit(3.0, 3.0) && past_limit(-3.01, 3.0));
    assert!(past_limit(f64::NAN, 3.0) && past_limit(f32::INFINITY, 3.0));
}

/// A device faster than the stop's period runs its sequence every ⌈10 ms / T_s⌉ steps; a
/// slower one every step; a period that is not positive and finite, every step.
#[test]
fn a_fast_device_runs_the_stop_every_ten_milliseconds() {
    for (step_s, steps) in [
        (1e-3, 10),
        (3e-3, 4),
        (2.5e-3, 4),
        (1e-2, 1),
        (2e-2, 1),
        (1e-4, 100),
        (1e-6, 1000),
        (0.0, 1),
        (f64::NAN, 1),
        (-1e-3, 1),
    ] {
        assert_eq!(steps_per_stop_period(step_s), steps, "{step_s} s");
    }
}

/// One classical RK4 step of `h` (s) of the model's own equations under `u` (V): the
/// reference the stop's estimates are checked against.
fn rk4(m: &ArmModel, x: [f64; 4], u: f64, h: f64) -> [f64; 4] {
    let d = |x: &[f64; 4]| m.derivative(x, u);
    let add = |x: &[f64; 4], k: &[f64; 4], a: f64| core::array::from_fn(|i| x[i] + a * k[i]);
    let k1 = d(&x);
    let k2 = d(&add(&x, &k1, h / 2.0));
    let k3 = d(&add(&x, &k2, h / 2.0));
    let k4 = d(&add(&x, &k3, h));
    core::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]))
}

/// The paper preset's arm and pendulum driven by a voltage that reverses every 0.15 s, the
/// motor's lead sign `s_m`, read through 2048-count encoders (the arm's with sign `s_e`) every
/// period by a [`CouplingTest`] on the same model with no noise, told the voltage commanded
/// over each period: the RK4 of the model's own equations at a tenth of the period,
/// independent of the test's second differences. The verdicts on `s_e` and on the drive's
/// sign, with their statistics.
fn coupling_verdict<R: Real>(s_e: f64, s_m: f64, arm_frozen: bool) -> [(Option<R>, R); 2] {
    let m = model();
    let q = core::f64::consts::TAU / 2048.0;
    let sigma = q / libm::sqrt(12.0);
    let mut test = CouplingTest::new(model_to::<R>(&m), c(TS), [c(sigma), c(sigma)]);
    let mut x = [0.0, 0.0, core::f64::consts::PI - 0.2, 0.0];
    let h = TS / 10.0;
    let mut commanded = None;
    for k in 0..100 {
        let u = if (k / 15) % 2 == 0 { 6.0 } else { -6.0 };
        let theta = if arm_frozen { 0.0 } else { s_e * x[0] };
        let quant = |v: f64| libm::round(v / q) * q;
        test.observe(
            c(quant(theta)),
            c(wrap_angle(quant(x[2]))),
            commanded.map(c),
        );
        commanded = Some(u);
        for _ in 0..10 {
            x = rk4(&m, x, s_m * u, h);
        }
    }
    [
        (test.sign(), test.statistic()),
        (test.drive_sign(), test.drive_statistic()),
    ]
}

/// The coupling test names the arm encoder's sign from the pendulum's equation, and the
/// drive's sign `s_e s_m` from the arm's, in `f64` and `f32`, for each sign of the encoder and
/// of the motor's lead; an arm reading that never changes gives no verdict on either (it
/// carries no evidence).
#[test]
fn the_coupling_test_tells_a_reversed_arm_encoder_from_the_pendulum() {
    for s_e in [1.0, -1.0] {
        for s_m in [1.0, -1.0] {
            let [(sign, stat), (drive, drive_stat)] = coupling_verdict::<f64>(s_e, s_m, false);
            assert_eq!(sign, Some(s_e), "s_e {s_e} s_m {s_m}: statistic {stat}");
            assert_eq!(
                drive,
                Some(s_e * s_m),
                "s_e {s_e} s_m {s_m}: drive {drive_stat}"
            );
            let [(sign, stat), (drive, drive_stat)] = coupling_verdict::<f32>(s_e, s_m, false);
            assert_eq!(sign, Some(s_e as f32), "f32, s_e {s_e}: statistic {stat}");
            let s_d = (s_e * s_m) as f32;
            assert_eq!(
                drive,
                Some(s_d),
                "f32, s_e {s_e} s_m {s_m}: drive {drive_stat}"
            );
        }
    }
    let [(sign, stat), (drive, drive_stat)] = coupling_verdict::<f64>(1.0, 1.0, true);
    assert_eq!(sign, None, "a frozen arm reading: statistic {stat}");
    assert_eq!(drive, None, "a frozen arm reading: drive {drive_stat}");
}

/// The paper preset's pendulum swinging ±2 rad about hanging with the windings at 0 V, read
/// through a 2048-count arm encoder (sign `s_e`) and a 512-count pendulum encoder: the
/// momentum's block mean against the true `∫H dt / ∫I dt` of the RK4 at a tenth of the
/// period, and the largest error of the per-period `ω_H` from the readings' differences.
fn momentum_errors(s_e: f64) -> (f64, f64) {
    let m = model();
    let (qa, qp) = (
        core::f64::consts::TAU / 2048.0,
        core::f64::consts::TAU / 512.0,
    );
    let quant = |v: f64, q: f64| libm::round(v / q) * q;
    let mut block = MomentumBlock::<f64>::new(TS);
    let mut x = [0.3, 0.4, core::f64::consts::PI - 2.0, 0.0];
    let h = TS / 10.0;
    let (mut true_h, mut true_i) = (0.0, 0.0);
    let (mut worst_block, mut worst_period) = (0.0f64, 0.0f64);
    let mut last: Option<(f64, f64)> = None;
    let mut blocks = 0;
    for k in 0..200 {
        let (theta, alpha) = (quant(s_e * x[0], qa), wrap_angle(quant(x[2], qp)));
        let before = block.mean();
        block.observe(&m, theta, alpha, s_e);
        if k > 0 && block.mean() != before {
            blocks += 1;
            let err = (block.mean().unwrap() - s_e * true_h / true_i).abs();
            worst_block = worst_block.max(err);
            (true_h, true_i) = (0.0, 0.0);
        }
        if let Some((theta0, alpha0)) = last {
            let rate = (theta - theta0) / TS;
            let alpha_rate = wrap_angle(alpha - alpha0) / TS;
            let measured = momentum_rate(&m, rate, alpha, s_e * alpha_rate);
            let truth = s_e * momentum_rate(&m, x[1], x[2], x[3]);
            worst_period = worst_period.max((measured - truth).abs());
        }
        last = Some((theta, alpha));
        for _ in 0..10 {
            let s = x[2].sin();
            let inertia = m.j0 + m.ja * s * s;
            true_h += momentum_rate(&m, x[1], x[2], x[3]) * inertia * h;
            true_i += inertia * h;
            x = rk4(&m, x, 0.0, h);
        }
    }
    assert!(blocks >= 8, "{blocks} blocks");
    (worst_block, worst_period)
}

/// The momentum's mean over a block ([`MomentumBlock`]) from the readings is within a tenth
/// of the law's dead band of the true mean, for either sign of the arm encoder, on encoders
/// whose per-period `ω_H` errs by more than the dead band itself.
#[test]
fn the_momentum_block_sees_through_the_encoders_quantisation() {
    let dead_band = 1.5 * core::f64::consts::TAU / 2048.0 / TS;
    for s_e in [1.0, -1.0] {
        let (block, period) = momentum_errors(s_e);
        assert!(
            block < 0.1 * dead_band,
            "s_e {s_e}: block mean off by {block} rad/s (dead band {dead_band})"
        );
        assert!(
            period > dead_band,
            "s_e {s_e}: per-period ω_H off by only {period} rad/s: the case does not test the block"
        );
    }
}

/// A sign under test is shown right on the arm's response only when the saturated law has
/// halved the speed by more than the dead band (the encoder's quantisation): on a coarse
/// encoder a reading of two counts a period and then one is no evidence. The drive's sign
/// from the arm's equation shows it right when it agrees and flips it once when it does not;
/// a trusted sign is left as it is.
#[test]
fn a_sign_is_shown_right_by_more_than_a_count_or_by_the_drives_sign() {
    let law = law();
    let count = 1.02;
    let dead_band = 1.5 * count;
    let mut brake = Brake::new(law, dead_band, BrakeMode::Checked);
    let saturated = (2.0 * law.linear_below).max(10.0 * dead_band);
    for speed in [saturated, saturated, 0.5 * saturated - 0.5 * dead_band] {
        brake.command(Some(-speed));
    }
    assert!(
        !brake.sign_known(),
        "a halving within the dead band shows nothing"
    );
    let mut brake = Brake::new(law, dead_band, BrakeMode::Checked);
    for speed in [saturated, 0.5 * saturated - 1.5 * dead_band] {
        brake.command(Some(-speed));
    }
    assert!(brake.sign_known(), "halved by more than the dead band");

    let mut agrees = Brake::new(law, dead_band, BrakeMode::Reversed);
    agrees.drive_sign_found(-1.0);
    assert!(agrees.sign_known());
    assert_eq!(agrees.mode(), BrakeMode::Reversed);
    let mut contradicted = Brake::new(law, dead_band, BrakeMode::Checked);
    contradicted.drive_sign_found(-1.0);
    assert_eq!(contradicted.mode(), BrakeMode::Reversed, "flipped once");
    contradicted.drive_sign_found(1.0);
    assert_eq!(
        contradicted.mode(),
        BrakeMode::Short,
        "a second contradiction shorts"
    );
    let mut trusted = Brake::new(law, dead_band, BrakeMode::Active);
    trusted.drive_sign_found(-1.0);
    assert_eq!(trusted.mode(), BrakeMode::Active);
}

/// With the arm encoder stopped ([`BrakeMode::Modelled`]) and the pendulum read each period,
/// the stop brakes the arm's angular momentum carried by the torque alone: on a rig whose
/// pendulum bearing drags five times the model's (the model's own pendulum would part from
/// it), an arm at 8 rad/s under a pendulum swinging 1.2 rad from hanging is braked to a true
/// momentum within twice the dead band before the law gives way to the short, within a
/// second.
#[test]
fn a_modelled_stop_brakes_the_momentum_read_against_the_pendulum() {
    let m = model();
    let rig = ArmModel {
        dp: 5.0 * m.dp.max(1e-5),
        ..m
    };
    let dead_band = 1.5 * core::f64::consts::TAU / 2048.0 / TS;
    let x0 = [0.0, 8.0, core::f64::consts::PI - 1.2, 0.0];
    let mut brake = Brake::modelled(&simulated(), dead_band, Some(x0), 0.0);
    let mut x = rk4(&rig, x0, 0.0, TS);
    let mut last_alpha = None;
    let mut shorted_at = None;
    for k in 0..100 {
        let alpha = wrap_angle(x[2]);
        let alpha_rate = last_alpha.map_or(0.0, |a| wrap_angle(alpha - a) / TS);
        last_alpha = Some(alpha);
        brake.observe_pendulum(alpha, alpha_rate);
        let u = match brake.command(Some(0.0)) {
            BrakeCommand::Volts(v) => v - v.clamp(-0.3, 0.3),
            BrakeCommand::Short => {
                shorted_at = Some((k, momentum_rate(&rig, x[1], x[2], x[3])));
                break;
            }
        };
        for _ in 0..10 {
            x = rk4(&rig, x, u, TS / 10.0);
        }
    }
    let (k, omega) = shorted_at.expect("the law gave way to the short within a second");
    assert!(
        omega.abs() < 2.0 * dead_band,
        "true ω_H {omega} rad/s at the short (period {k}), dead band {dead_band}"
    );
}
