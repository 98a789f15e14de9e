//! Host tests of the swing-up in `f64` and `f32`, against the physics and the documented
//! behaviour, on rip-core's `paper` preset parameters (the QUBE-Servo 2's motor and masses,
//! the paper's link lengths, inertias and damping).

use super::*;

extern crate std;
use std::vec::Vec;

/// rip-core's `paper` preset: `(R_m, k_t, k_m, m_r, l_r, J_r, m_p, l_p, J_p, d_r, d_p, g)`.
const PAPER: [f64; 12] = [
    8.4,
    0.042,
    0.042,
    0.095,
    1.491_006_775_583e-1,
    4.956_499_901_120e-4,
    0.024,
    2.788_137_143_023e-1,
    3.289_148_708_531e-4,
    1.894_388_980_126e-3,
    4.512_959_398_114e-4,
    9.81,
];
pub(crate) const TS: f64 = 0.01;
const ARM_LIMIT: f64 = 1.5;
const U: f64 = 12.0;

pub(crate) fn model() -> ArmModel<f64> {
    let [rm, kt, km, mr, lr, jr, mp, lp, jp, dr, dp, g] = PAPER;
    ArmModel {
        j0: jr + mr * lr * lr / 4.0 + mp * lr * lr,
        ja: jp + mp * lp * lp / 4.0,
        m12: mp * lr * lp / 2.0,
        grav: mp * g * lp / 2.0,
        b: kt / rm,
        c_arm: dr + kt * km / rm,
        dp,
    }
}

/// The derived constants of rip-core's defaults (`SwingUpSettings::default()`), the catch
/// region opened or closed by `catch`.
pub(crate) fn params(catch: bool) -> SwingParams<f64> {
    let m = model();
    let stall = m.b * U / (m.j0 + m.ja);
    let brake = 0.5 * stall;
    let top = envelope_speed(brake, ARM_LIMIT);
    let margin = (top * TS).clamp(0.05, 0.5 * ARM_LIMIT);
    let j = m.j0 + m.ja;
    let j_min = (m.j0 - m.m12 * m.m12 / m.ja).max(1e-3 * m.j0);
    SwingParams {
        ts: TS,
        model: m,
        max_voltage: U,
        upright_target: 0.05 * m.grav,
        dissipation: 4.0 * m.dp * (m.grav / m.ja).sqrt(),
        pump: 3.0 * m.grav / m.ja,
        brake,
        energy_gain: 5.0,
        pump_width: 2.0,
        arm_centering: 1.5,
        rise_damping: 0.0,
        barrier_rate: 20.0,
        envelope_limit: ARM_LIMIT - margin,
        rate_cutoff_hz: 20.0,
        estimator_window: 0.3,
        catch_angle: if catch { 0.3 } else { -1.0 },
        catch_lookahead: 0.1,
        catch_mode_fraction: 0.3,
        catch_rate: 7.0,
        catch_arm_rate: 3.0,
        catch_arm_angle: 0.7,
        // The mode's share is not what these tests are about: a pendulum at the catch angle
        // is a tenth of the way to unrecoverable.
        mode: UnstableMode {
            w: [0.0, 0.0, 1.0, 0.0],
            recoverable: 3.0,
        },
        prediction: None,
        balance_angle: 0.6,
        arm_limit: ARM_LIMIT,
        stopping: StoppingModel {
            a0: m.b * U / j,
            k: m.c_arm / j,
            drive_per_volt: m.b / j_min,
            latency: TS,
            voltage: U,
        },
        handover_time: 0.05,
        reference_return_rate: 0.0,
        max_time: 20.0,
        on_fall: OnFall::Retry,
    }
}

pub(crate) fn model_to<R: Real>(m: &ArmModel<f64>) -> ArmModel<R> {
    ArmModel {
        j0: c(m.j0),
        ja: c(m.ja),
        m12: c(m.m12),
        grav: c(m.grav),
        b: c(m.b),
        c_arm: c(m.c_arm),
        dp: c(m.dp),
    }
}

fn stopping_to<R: Real>(s: &StoppingModel<f64>) -> StoppingModel<R> {
    StoppingModel {
        a0: c(s.a0),
        k: c(s.k),
        drive_per_volt: c(s.drive_per_volt),
        latency: c(s.latency),
        voltage: c(s.voltage),
    }
}

fn params_to<R: Real>(p: &SwingParams<f64>) -> SwingParams<R> {
    SwingParams {
        ts: c(p.ts),
        model: model_to(&p.model),
        max_voltage: c(p.max_voltage),
        upright_target: c(p.upright_target),
        dissipation: c(p.dissipation),
        pump: c(p.pump),
        brake: c(p.brake),
        energy_gain: c(p.energy_gain),
        pump_width: c(p.pump_width),
        arm_centering: c(p.arm_centering),
        rise_damping: c(p.rise_damping),
        barrier_rate: c(p.barrier_rate),
        envelope_limit: c(p.envelope_limit),
        rate_cutoff_hz: c(p.rate_cutoff_hz),
        estimator_window: c(p.estimator_window),
        catch_angle: c(p.catch_angle),
        catch_lookahead: c(p.catch_lookahead),
        catch_mode_fraction: c(p.catch_mode_fraction),
        catch_rate: c(p.catch_rate),
        catch_arm_rate: c(p.catch_arm_rate),
        catch_arm_angle: c(p.catch_arm_angle),
        mode: UnstableMode {
            w: p.mode.w.map(c),
            recoverable: c(p.mode.recoverable),
        },
        prediction: p.prediction.map(|q| CatchPrediction {
            k: q.k.map(c),
            steps: q.steps,
            substeps: q.substeps,
            arm_room: c(q.arm_room),
            pendulum_room: c(q.pendulum_room),
            stopping: stopping_to(&q.stopping),
        }),
        balance_angle: c(p.balance_angle),
        arm_limit: c(p.arm_limit),
        stopping: stopping_to(&p.stopping),
        handover_time: c(p.handover_time),
        reference_return_rate: c(p.reference_return_rate),
        max_time: c(p.max_time),
        on_fall: p.on_fall,
    }
}

/// A balance controller that writes a fixed voltage and counts what it is asked.
#[derive(Default)]
pub(crate) struct Probe {
    steps: Vec<([f64; 2], [f64; 2])>,
    observed: usize,
    seeded: usize,
    held: usize,
    resets: usize,
}

impl<R: Real> Balance<R> for Probe {
    type Status = u8;
    fn step(&mut self, angles: [R; 2], reference: [R; 2]) -> (R, u8) {
        self.steps
            .push((angles.map(|v| v.to_f64()), reference.map(|v| v.to_f64())));
        (c(1.5), 7)
    }
    fn observe(&mut self, _: [R; 2], _: R) {
        self.observed += 1;
    }
    fn seed(&mut self, _: [R; 4], _: R) {
        self.seeded += 1;
    }
    fn hold(&mut self, _: R) {
        self.held += 1;
    }
    fn reset(&mut self) {
        self.resets += 1;
    }
}

#[test]
fn wrap_angle_lands_in_the_half_open_interval() {
    use core::f64::consts::PI;
    for (a, w) in [
        (0.0, 0.0),
        (PI, PI),
        (-PI, PI),
        (3.0 * PI, PI),
        (2.0 * PI + 0.1, 0.1),
        (-2.0 * PI - 0.1, -0.1),
        (-7.0, -7.0 + 2.0 * PI),
    ] {
        assert!((wrap_angle(a) - w).abs() < 1e-12, "{a}: {}", wrap_angle(a));
        let w32 = wrap_angle(a as f32);
        assert!(w32 > -PI as f32 && w32 <= PI as f32, "{a}: {w32}");
        assert!((f64::from(w32) - w).abs() < 1e-5, "{a}: {w32}");
    }
}

/// The viscous loss term of (1a): a free damped pendulum that leaves hanging with the target
/// energy `E_t(π) = δ G + D` keeps `E ≈ E_t(α)` all the way up, so it arrives with `δ G`.
#[test]
fn the_target_energy_is_what_a_free_damped_pendulum_keeps_on_its_way_up() {
    let p = params(false);
    let m = p.model;
    assert!(
        p.dissipation > 0.3 * m.grav,
        "D {} G {}",
        p.dissipation,
        m.grav
    );
    let rate0 = (2.0 * (2.0 * m.grav + p.target(core::f64::consts::PI)) / m.ja).sqrt();
    // Arm held still: J_α α̈ = G sin α − d_p α̇.
    let f = |x: [f64; 2]| [x[1], (m.grav * x[0].sin() - m.dp * x[1]) / m.ja];
    let mut x = [core::f64::consts::PI, -rate0];
    let h = 1e-5;
    let mut worst = 0.0f64;
    while x[0] > 0.0 {
        let k1 = f(x);
        let k2 = f([x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1]]);
        let k3 = f([x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1]]);
        let k4 = f([x[0] + h * k3[0], x[1] + h * k3[1]]);
        for i in 0..2 {
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        let s = [0.0, 0.0, x[0], x[1]];
        worst = worst.max((p.energy(&s) - p.target(x[0])).abs());
    }
    // (1a) integrates the loss along the homoclinic orbit; the pendulum above it by δ G + D
    // at hanging moves faster and loses more: under a tenth of D (a factor in D, or the
    // cosine of α rather than α/2, misses by far more).
    assert!(
        worst < 0.1 * p.dissipation,
        "|E − E_t| {worst}, D {}",
        p.dissipation
    );
    let arrival = p.energy(&[0.0, 0.0, x[0], x[1]]);
    assert!(
        (arrival - p.upright_target).abs() < 0.1 * p.dissipation,
        "arrived with {arrival}, δ G {}",
        p.upright_target
    );
}

/// The arm as a double integrator, `θ̈ = a` with the law's `a` held over each period, under a
/// pendulum that swings on its own: the envelope (2)–(3) keeps `|θ| ≤ θ_L`.
fn envelope_run<R: Real>(dt: f64, pump_scale: f64, theta0: f64, rate0: f64) -> f64 {
    let mut p = params(false);
    p.pump *= pump_scale;
    let p: SwingParams<R> = params_to(&p);
    let (mut theta, mut rate) = (theta0, rate0);
    let mut peak = 0.0f64;
    let n = (8.0 / dt) as usize;
    for k in 0..n {
        let t = k as f64 * dt;
        // A pendulum swinging about hanging with a growing amplitude, so that the pumping
        // term pushes back and forth at the pendulum's frequency.
        let amp = (0.3 + 0.3 * t).min(3.0);
        let alpha = wrap_angle(core::f64::consts::PI + amp * (6.0 * t).sin());
        let alpha_dot = amp * 6.0 * (6.0 * t).cos();
        let x: [R; 4] = [c(theta), c(rate), c(alpha), c(alpha_dot)];
        let a = p.acceleration(&x).to_f64();
        theta += rate * dt + 0.5 * a * dt * dt;
        rate += a * dt;
        peak = peak.max(theta.abs());
    }
    peak
}

#[test]
fn the_envelope_keeps_a_double_integrator_arm_inside_its_limit() {
    let p = params(false);
    let limit = p.envelope_limit;
    // Starts inside the envelope: at rest anywhere inside, and moving towards a limit as fast
    // as the envelope allows there.
    let starts = [
        (0.0, 0.0),
        (0.9 * limit, 0.0),
        (-0.9 * limit, 0.0),
        (0.5 * limit, 0.99 * envelope_speed(p.brake, 0.5 * limit)),
        (-0.5 * limit, -0.99 * envelope_speed(p.brake, 0.5 * limit)),
    ];
    for (theta0, rate0) in starts {
        for scale in [1.0, 10.0] {
            // Continuous time (a 0.1 ms hold): the invariance of the envelope itself.
            let peak = envelope_run::<f64>(1e-4, scale, theta0, rate0);
            assert!(
                peak <= limit + 1e-3,
                "{theta0} {rate0} ×{scale}: |θ| {peak} > {limit}"
            );
            // The loop's period: within the arm limit, which the margin is for.
            for (peak, name) in [
                (envelope_run::<f64>(TS, scale, theta0, rate0), "f64"),
                (envelope_run::<f32>(TS, scale, theta0, rate0), "f32"),
            ] {
                assert!(
                    peak <= ARM_LIMIT,
                    "{name} {theta0} {rate0} ×{scale}: |θ| {peak} > {ARM_LIMIT}"
                );
            }
        }
    }
    // Not vacuous: ten times the pumping drives the arm to the envelope's edge.
    let peak = envelope_run::<f64>(1e-4, 10.0, 0.0, 0.0);
    assert!(
        peak > 0.85 * limit,
        "the arm only reached {peak} of {limit}"
    );
}

/// `θ̈(x, u)` of [`ArmModel`] is what the law's voltage (4) is inverted on: the voltage gives
/// the asked acceleration wherever it is within `±U`.
#[test]
fn the_voltage_gives_the_asked_acceleration() {
    let p = params(false);
    let mut checked = 0;
    for i in 0..200 {
        let t = f64::from(i);
        let x = [
            (0.37 * t).sin(),
            3.0 * (0.91 * t).cos(),
            3.1 * (0.53 * t).sin(),
            8.0 * (0.29 * t).cos(),
        ];
        let a = 40.0 * (1.7 * t).sin();
        let u = p.voltage(&x, a);
        assert!(u.abs() <= U);
        if u.abs() < U {
            let got = p.model.accelerations(&x, u)[0];
            assert!(
                (got - a).abs() < 1e-9 * (1.0 + a.abs()),
                "{x:?}: {got} vs {a}"
            );
            checked += 1;
        }
    }
    assert!(checked > 50, "{checked}");
}

/// The plant the recorded swing runs on: the smooth model, RK4 with 4 substeps per period.
fn recorded_swing(seconds: f64) -> (Vec<[f64; 2]>, Vec<f64>) {
    let p = params(false);
    let mut sup = SwingSupervisor::new(p);
    let mut balance = Probe::default();
    let mut x = [0.0, 0.0, core::f64::consts::PI, 0.0];
    let (mut ys, mut us) = (Vec::new(), Vec::new());
    for _ in 0..(seconds / TS) as usize {
        let y = [x[0], x[2]];
        let (u, _) = sup.step(&mut balance, y, [0.0, 0.0]);
        ys.push(y);
        us.push(u);
        p.model.advance(&mut x, u, TS, 4);
    }
    (ys, us)
}

#[test]
fn f32_follows_f64_over_a_recorded_swing() {
    let (ys, us) = recorded_swing(8.0);
    // Not vacuous: the swing reaches upright and uses the voltage.
    let closest = ys
        .iter()
        .map(|y| wrap_angle(y[1]).abs())
        .fold(9.0, f64::min);
    assert!(closest < 0.3, "closest approach {closest}");
    assert!(us.iter().any(|u| u.abs() > 0.5 * U));
    let mut sup = SwingSupervisor::<f32>::new(params_to(&params(false)));
    let mut balance = Probe::default();
    let mut worst = 0.0f64;
    for (y, u) in ys.iter().zip(&us) {
        let (u32, _) = sup.step(&mut balance, [y[0] as f32, y[1] as f32], [0.0, 0.0]);
        worst = worst.max((f64::from(u32) - u).abs());
    }
    // The rates are differences of angles over 10 ms: an f32 angle near π is off by up to
    // 1.2e-7 rad, its rate by 1e-5 rad/s, and the law's slope reaches hundreds of volts per
    // rad/s where the energy error and the smoothed sign saturate: 20 mV, a sixth of a
    // percent of the bound, which the rig's dead zone and noise dwarf.
    assert!(worst < 2e-2, "f32 {worst} V from f64");
}

#[test]
fn the_supervisor_swings_catches_hands_over_and_falls() {
    let p = params(true);
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    // Hanging at exact rest: the law still pushes (s(0) = 1), within the voltage bound, and
    // the balance estimator, far from its linear model, is seeded.
    let (u, s) = sup.step(&mut probe, [0.0, core::f64::consts::PI], [0.0, 0.0]);
    assert!(u > 0.0 && u <= U, "{u}");
    assert_eq!(s, SwingStatus::Nominal);
    assert_eq!((probe.seeded, probe.observed), (1, 0));
    // An unusable measurement: the estimate is kept, the balance controller holds.
    let (_, s) = sup.step(&mut probe, [f64::NAN, 0.0], [0.0, 0.0]);
    assert_eq!(s, SwingStatus::Held);
    assert_eq!(probe.held, 1);
    assert_eq!(sup.phase(), SwingPhase::SwingUp);
    // Upright at rest, arm off centre: caught at the first usable sample there, and the
    // balance controller moves at once, with the arm reference held where it was caught.
    sup.reset(&mut probe);
    let mut probe = Probe::default();
    let (u, s) = sup.step(&mut probe, [0.2, 0.05], [0.0, 0.0]);
    assert_eq!(sup.phase(), SwingPhase::Balance);
    assert_eq!((u, s), (1.5, SwingStatus::Balance(7)));
    assert_eq!(probe.steps[0], ([0.2, 0.05], [0.2, 0.0]));
    for _ in 0..20 {
        sup.step(
            &mut probe,
            [0.2, 2.0 * core::f64::consts::PI + 0.05],
            [0.0, 0.0],
        );
    }
    // The pendulum angle is wrapped for the balance controller; the arm reference stays held
    // while the external one does not change, and is passed through once it does.
    assert!(probe
        .steps
        .iter()
        .all(|(y, r)| (y[1] - 0.05).abs() < 1e-12 && r[0] == 0.2));
    sup.step(&mut probe, [0.2, 0.05], [1.0, 0.0]);
    assert_eq!(probe.steps.last().unwrap().1, [1.0, 0.0]);
    // Seeded for the handover time after the catch (5 periods), then not.
    assert_eq!(probe.seeded, 5);
    // A fall: the pendulum beyond the balance angle. Retry swings up again.
    let (_, s) = sup.step(&mut probe, [0.2, 1.0], [1.0, 0.0]);
    assert_eq!(sup.phase(), SwingPhase::SwingUp);
    assert_eq!(s, SwingStatus::Nominal);
    // With OnFall::Stop the same fall stops at 0 V, for good.
    let mut sup = SwingSupervisor::new(SwingParams {
        on_fall: OnFall::Stop,
        ..p
    });
    sup.step(&mut probe, [0.2, 0.05], [0.0, 0.0]);
    assert_eq!(sup.phase(), SwingPhase::Balance);
    let (u, _) = sup.step(&mut probe, [0.2, 1.0], [0.0, 0.0]);
    assert_eq!(
        (u, sup.phase()),
        (0.0, SwingPhase::Stopped(SwingStop::LeftBalanceRegion))
    );
    let (u, _) = sup.step(&mut probe, [0.2, 0.05], [0.0, 0.0]);
    assert_eq!(u, 0.0);
    // The arm still in range but its stopping point beyond the limit is a fall too.
    let mut sup = SwingSupervisor::new(SwingParams {
        on_fall: OnFall::Stop,
        ..p
    });
    sup.step(&mut probe, [1.3, 0.0], [0.0, 0.0]);
    let mut fell_at = None;
    for k in 1..10 {
        sup.step(&mut probe, [1.3 + 0.05 * f64::from(k), 0.0], [0.0, 0.0]);
        if sup.phase() != SwingPhase::Balance {
            fell_at = Some(1.3 + 0.05 * f64::from(k));
            break;
        }
    }
    let at = fell_at.expect("no fall");
    assert!(at <= ARM_LIMIT, "the fall came only at θ = {at}");
}

#[test]
fn a_swing_up_that_takes_too_long_stops_with_0_v() {
    let p = SwingParams {
        max_time: 0.5,
        ..params(false)
    };
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    let mut stopped_at = None;
    for k in 1..100 {
        let (u, _) = sup.step(&mut probe, [0.0, core::f64::consts::PI], [0.0, 0.0]);
        if let SwingPhase::Stopped(cause) = sup.phase() {
            assert_eq!((u, cause), (0.0, SwingStop::Timeout));
            stopped_at = Some(k);
            break;
        }
    }
    // The 51st sample is past 0.5 s.
    assert_eq!(stopped_at, Some(51));
}

#[test]
fn the_stopping_point_is_the_braked_arm_of_the_model() {
    // Reference: the arm equation `J ω̇ = −(b U + c ω)` integrated finely, after the latency
    // during which `u_a` accelerates it at `b u_a / J_min`.
    let p = params(false);
    let s = p.stopping;
    let m = p.model;
    let j = m.j0 + m.ja;
    for (omega, along) in [(0.5, 0.0), (4.0, 0.0), (4.0, 6.0), (12.0, 12.0)] {
        let (mut x, mut w) = (0.0, omega);
        let h = 1e-6;
        let a_l = s.drive_per_volt * along;
        let mut t = 0.0;
        while t < s.latency {
            x += w * h + 0.5 * a_l * h * h;
            w += a_l * h;
            t += h;
        }
        while w > 0.0 {
            let acc = -(m.b * U + m.c_arm * w) / j;
            x += w * h;
            w += acc * h;
        }
        let d = s.stopping_distance_with(omega, along);
        assert!(
            (d - x).abs() < 1e-4 * (1.0 + x),
            "ω {omega} u_a {along}: {d} vs {x}"
        );
        assert_eq!(s.stopping_point(0.1, -omega, -along), 0.1 - d);
        let d32 = stopping_to::<f32>(&s).stopping_distance_with(omega as f32, along as f32);
        assert!(
            (f64::from(d32) - d).abs() < 1e-5 * (1.0 + d),
            "f32 {d32} vs {d}"
        );
    }
}

/// A plan that holds the arm still at hanging with a constant planned voltage and a gain on
/// the arm angle only: what the supervisor outputs tells which law it follows.
fn still_plan(n: usize) -> Vec<PlanPoint<f64>> {
    (0..n)
        .map(|_| PlanPoint {
            x: [0.0, 0.0, core::f64::consts::PI, 0.0],
            u: 2.0,
            k: [10.0, 0.0, 0.0, 0.0],
        })
        .collect()
}

#[test]
fn a_plan_is_followed_from_hanging_rest_and_left_when_the_arm_strays() {
    let p = params(false);
    let plan = still_plan(50);
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    // On the plan: u_k − K (x − x_k) with the wrapped pendulum error (−π is π).
    let (u, _) = sup.step_planned(&mut probe, &plan, [0.05, -core::f64::consts::PI], [0.0; 2]);
    assert!(sup.planning());
    assert!((u - (2.0 - 10.0 * 0.05)).abs() < 1e-12, "{u}");
    let (u, _) = sup.step_planned(&mut probe, &plan, [0.05, core::f64::consts::PI], [0.0; 2]);
    assert!(sup.planning());
    assert!((u - 1.5).abs() < 1e-9, "{u}");
    // The arm beyond PLAN_ABORT_ANGLE from the plan: the plan is left, and not taken up
    // again when the arm comes back.
    let off = PLAN_ABORT_ANGLE + 0.05;
    let (u, _) = sup.step_planned(&mut probe, &plan, [off, core::f64::consts::PI], [0.0; 2]);
    assert!(!sup.planning());
    assert!((u - (2.0 - 10.0 * off)).abs() > 1e-3, "{u}");
    sup.step_planned(&mut probe, &plan, [0.0, core::f64::consts::PI], [0.0; 2]);
    assert!(!sup.planning());
    assert!(probe.steps.is_empty(), "no catch far from upright");

    // Not at rest when the swing-up starts: no plan.
    let mut sup = SwingSupervisor::new(p);
    sup.step_planned(
        &mut probe,
        &plan,
        [0.0, core::f64::consts::PI - 0.5],
        [0.0; 2],
    );
    assert!(!sup.planning());

    // The plan's end: the energy law (or the catch) takes over.
    let mut sup = SwingSupervisor::new(p);
    let short = still_plan(3);
    for _ in 0..3 {
        sup.step_planned(&mut probe, &short, [0.0, core::f64::consts::PI], [0.0; 2]);
        assert!(sup.planning());
    }
    sup.step_planned(&mut probe, &short, [0.0, core::f64::consts::PI], [0.0; 2]);
    assert!(!sup.planning());
}

#[test]
fn a_planned_swing_is_caught_only_once_the_plan_nears_upright() {
    let p = params(true);
    let hanging = [0.0, 0.0, core::f64::consts::PI, 0.0];
    let near = |alpha: f64| PlanPoint {
        x: [0.0, 0.0, alpha, 0.0],
        u: 0.0,
        k: [0.0; 4],
    };
    // Hanging for the settling samples, then 20 points just outside the catch angle, then 5
    // inside it; the pendulum is measured hanging, then at rest just inside the catch angle.
    let settle = PLAN_SETTLE_SAMPLES as usize;
    let mut plan = std::vec![
        PlanPoint {
            x: hanging,
            u: 0.0,
            k: [0.0; 4]
        };
        settle
    ];
    plan.extend((0..20).map(|_| near(p.catch_angle + 0.1)));
    plan.extend((0..5).map(|_| near(0.5 * p.catch_angle)));
    let measured = [0.0, 0.5 * p.catch_angle];
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    for _ in 0..settle {
        sup.step_planned(&mut probe, &plan, [0.0, core::f64::consts::PI], [0.0; 2]);
    }
    // The plan's pendulum is 0.1 rad from the measured one: followed, not caught, although
    // the rates settle into the catch region within the 20 samples.
    for _ in 0..20 {
        sup.step_planned(&mut probe, &plan, measured, [0.0; 2]);
        assert!(sup.planning());
        assert_eq!(sup.phase(), SwingPhase::SwingUp);
    }
    assert!(p.in_catch_region(&[0.0, 0.0, measured[1], 0.0]));
    sup.step_planned(&mut probe, &plan, measured, [0.0; 2]);
    assert_eq!(sup.phase(), SwingPhase::Balance);
    assert!(!sup.planning());
}

#[test]
fn a_plan_left_with_the_arm_outside_the_envelope_brakes_it_with_the_whole_bound() {
    let p = params(false);
    let a = (-(core::f64::consts::TAU * p.rate_cutoff_hz * p.ts)).exp();
    let pi = core::f64::consts::PI;
    // The plan: hanging, then the arm at 1.2 rad with the rate the estimate reads after a
    // jump there, so that the supervisor is exactly on it.
    let rate = (1.0 - a) * 1.2 / p.ts;
    let plan = [
        PlanPoint {
            x: [0.0, 0.0, pi, 0.0],
            u: 0.0,
            k: [0.0; 4],
        },
        PlanPoint {
            x: [1.2, rate, pi, 0.0],
            u: 3.0,
            k: [0.0; 4],
        },
        PlanPoint {
            x: [1.2, a * rate, pi, 0.0],
            u: 3.0,
            k: [0.0; 4],
        },
    ];
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    sup.step_planned(&mut probe, &plan, [0.0, pi], [0.0; 2]);
    let (u, _) = sup.step_planned(&mut probe, &plan, [1.2, pi], [0.0; 2]);
    assert!(sup.planning() && (u - 3.0).abs() < 1e-9, "{u}");
    // The pendulum 1 rad off the plan: left, with the arm moving out and its stopping point
    // far past the envelope's limit: the whole bound against the motion.
    let (u, _) = sup.step_planned(&mut probe, &plan, [1.2, pi - 1.0], [0.0; 2]);
    assert!(!sup.planning());
    assert_eq!(u, -U);
    // Once the arm turns back, the energy law (within the bound, not the brake's sign).
    for _ in 0..30 {
        sup.step_planned(&mut probe, &plan, [1.0, pi - 1.0], [0.0; 2]);
    }
    let (u, _) = sup.step_planned(&mut probe, &plan, [1.0, pi - 1.0], [0.0; 2]);
    assert!(u.abs() <= U && u != -U, "{u}");
}

#[test]
fn a_plan_started_on_a_moving_pendulum_is_left_within_its_settling_samples() {
    let p = params(false);
    let plan = still_plan(50);
    let pi = core::f64::consts::PI;
    // Through hanging at 5 rad/s: the first sample cannot tell (no rate yet), the second can.
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    sup.step_planned(&mut probe, &plan, [0.0, pi - 0.01], [0.0; 2]);
    assert!(sup.planning());
    sup.step_planned(&mut probe, &plan, [0.0, pi - 0.06], [0.0; 2]);
    assert!(!sup.planning());
    // At rest it is kept past the settling samples.
    let mut sup = SwingSupervisor::new(p);
    for _ in 0..2 * PLAN_SETTLE_SAMPLES {
        sup.step_planned(&mut probe, &plan, [0.0, pi], [0.0; 2]);
        assert!(sup.planning());
    }
}

#[test]
fn a_held_period_advances_the_plan_and_an_unusable_one_applies_its_voltage_alone() {
    let p = params(false);
    let pi = core::f64::consts::PI;
    // Point k asks for k volts, with a gain on the arm.
    let plan: Vec<PlanPoint<f64>> = (0..10)
        .map(|k| PlanPoint {
            x: [0.0, 0.0, pi, 0.0],
            u: k as f64,
            k: [10.0, 0.0, 0.0, 0.0],
        })
        .collect();
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    let (u, _) = sup.step_planned(&mut probe, &plan, [0.0, pi], [0.0; 2]);
    assert_eq!(u, 0.0);
    sup.hold(&mut probe, u);
    sup.hold(&mut probe, u);
    let (u, _) = sup.step_planned(&mut probe, &plan, [0.0, pi], [0.0; 2]);
    assert!((u - 3.0).abs() < 1e-12, "{u}");
    // Without a measurement: point 4's voltage, not corrected by the stale arm estimate.
    let (u, status) = sup.step_planned(&mut probe, &plan, [f64::NAN, pi], [0.0; 2]);
    assert_eq!(status, SwingStatus::Held);
    assert!((u - 4.0).abs() < 1e-12, "{u}");
    assert!(sup.planning());
    let (u, _) = sup.step_planned(&mut probe, &plan, [0.01, pi], [0.0; 2]);
    assert!((u - (5.0 - 10.0 * 0.01)).abs() < 1e-9, "{u}");
    // A reset starts from the plan's beginning again.
    sup.reset(&mut probe);
    let (u, _) = sup.step_planned(&mut probe, &plan, [0.0, pi], [0.0; 2]);
    assert!(sup.planning() && u == 0.0);
}

/// With a return rate, an external step that comes while the arm reference is still on its
/// way back from the catch moves the reference towards it by at most the step, and the rest
/// of the way goes on at the return rate (the reference never moves more than `rate · T_s` a
/// period besides the step, nor past the new value); once back, a later change is passed
/// through as given.
#[test]
fn a_step_during_the_way_back_from_the_catch_is_made_from_where_the_way_back_is() {
    let rate = 0.5;
    let p = SwingParams {
        reference_return_rate: rate,
        ..params(true)
    };
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    let upright = [-0.4, 0.05];
    sup.step(&mut probe, upright, [0.0, 0.0]);
    assert_eq!(sup.phase(), SwingPhase::Balance);
    // The way back starts at the catch's own period.
    assert!((probe.steps[0].1[0] - (-0.4 + rate * TS)).abs() < 1e-12);
    // 0.2 s more of the way back, then the 0 → 1 rad step.
    for _ in 0..20 {
        sup.step(&mut probe, upright, [0.0, 0.0]);
    }
    let before = probe.steps.last().unwrap().1[0];
    assert!(
        (before - (-0.4 + 21.0 * rate * TS)).abs() < 1e-9,
        "{before}"
    );
    sup.step(&mut probe, upright, [1.0, 0.0]);
    let at_step = probe.steps.last().unwrap().1[0];
    // The step as given (1 rad), not 1 rad plus the 0.295 rad left of the way back.
    assert!(
        (at_step - (before + 1.0 + rate * TS)).abs() < 1e-12,
        "{at_step}"
    );
    let mut last = at_step;
    let mut periods = 0;
    while last < 1.0 - 1e-12 {
        sup.step(&mut probe, upright, [1.0, 0.0]);
        let r = probe.steps.last().unwrap().1[0];
        assert!(r - last <= rate * TS + 1e-12 && r >= last, "{last} -> {r}");
        last = r;
        periods += 1;
        assert!(periods < 1000, "never reached the step");
    }
    assert!((last - 1.0).abs() < 1e-12);
    assert_eq!(
        periods,
        ((1.0 - at_step) / (rate * TS) - 1e-9).ceil() as usize
    );
    // Back: the next change is a step as given.
    sup.step(&mut probe, upright, [0.5, 0.0]);
    assert_eq!(probe.steps.last().unwrap().1[0], 0.5);
    // Caught on the side the step goes to: the reference reaches the step at once and does
    // not overshoot it (the step added to where the way back is would be 1.395 rad).
    let mut sup = SwingSupervisor::new(p);
    let mut probe = Probe::default();
    let caught = [0.4, 0.05];
    sup.step(&mut probe, caught, [0.0, 0.0]);
    sup.step(&mut probe, caught, [1.0, 0.0]);
    assert_eq!(probe.steps.last().unwrap().1[0], 1.0);
}
