use super::*;

thread_local! {
    /// How often this thread computed a plant's RK4 stability limit.
    pub(super) static LIMIT_EVALUATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

#[test]
fn the_rk4_limit_is_computed_once_per_plant_not_per_step() {
    let before = LIMIT_EVALUATIONS.with(|n| n.get());
    let plant = Plant::new(FurutaParams::paper()).unwrap();
    let copy = plant;
    assert_eq!(LIMIT_EVALUATIONS.with(|n| n.get()), before + 1);
    let mut x = State::new(0.0, 0.0, 0.1, 0.0);
    for _ in 0..100 {
        x = copy.step_checked(&x, 1.0, 0.0, 0.01, 10).unwrap();
    }
    copy.integrate(&x, &[0.5; 10], 0.01, 10).unwrap();
    assert!(copy.step_checked(&x, 0.0, 0.0, 1.0, 1).is_err());
    assert_eq!(LIMIT_EVALUATIONS.with(|n| n.get()), before + 1);
    // The stored limit is the one of the eigenvalues: ρ(A_c) at upright and hanging.
    let rho = [
        State::zeros(),
        State::new(0.0, 0.0, std::f64::consts::PI, 0.0),
    ]
    .iter()
    .map(|x| {
        let (a, _) = plant.linearize(x, 0.0);
        let a = Mat::from_fn(4, 4, |i, j| a[(i, j)]);
        a.complex_eigenvalues()
            .iter()
            .map(|l| l.norm())
            .fold(0.0, f64::max)
    })
    .fold(0.0, f64::max);
    assert!((plant.max_rk4_substep() - RK4_STABILITY_LIMIT / rho).abs() < 1e-12 / rho);
}

#[test]
fn a_substep_beyond_rk4_stability_is_refused_and_the_limit_is_real() {
    for plant in [Plant::paper(), Plant::qube_servo2()] {
        let h_max = plant.max_rk4_substep();
        let x = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
        let err = plant.step_checked(&x, 0.0, 0.0, 1e10, 1).unwrap_err();
        assert!(matches!(err, RipError::InvalidParameter { ref name, .. } if name == "dt"));
        assert!(plant.step_checked(&x, 0.0, 0.0, 0.01, 10).is_ok());
        // Inside the bound the integration of the hanging pendulum stays near rest, and on
        // the upright linearisation's fastest mode (real, λ = −ρ) RK4's amplification
        // R(z) = 1 + z + z²/2 + z³/6 + z⁴/24 crosses 1 at the bound.
        let mut z = x + State::new(0.0, 1e-3, 0.0, 1e-3);
        for _ in 0..2000 {
            plant.rk4_step(&mut z, 0.0, 0.0, 0.9 * h_max);
        }
        assert!((z - x).norm() < 1e-2);
        let amplification = |z: f64| 1.0 + z + z * z / 2.0 + z.powi(3) / 6.0 + z.powi(4) / 24.0;
        let rho = RK4_STABILITY_LIMIT / h_max;
        assert!(amplification(-0.99 * rho * h_max).abs() < 1.0);
        assert!(amplification(-1.01 * 2.785 / rho * rho).abs() > 1.0);
    }
}

#[test]
fn linearization_matches_central_differences() {
    for kc in [0.0, 2.384e-3] {
        linearization_matches_central_differences_with_cable(kc);
    }
}

fn linearization_matches_central_differences_with_cable(kc: f64) {
    let plant = Plant::new(FurutaParams {
        kc,
        ..FurutaParams::qube_servo2()
    })
    .unwrap();
    let points = [
        (State::zeros(), 0.0),
        (State::new(0.3, 0.0, std::f64::consts::PI, 0.0), 0.0),
        (State::new(0.4, -1.3, 0.7, 2.1), 3.5),
        (State::new(-2.0, 4.0, -2.4, -5.0), -7.0),
    ];
    for (x, u) in points {
        let (a, b) = plant.linearize(&x, u);
        for j in 0..5 {
            let h = 1e-6;
            let (mut xp, mut xm, mut up, mut um) = (x, x, u, u);
            if j < 4 {
                xp[j] += h;
                xm[j] -= h;
            } else {
                up += h;
                um -= h;
            }
            let fd = (plant.derivative(&xp, up, 0.0) - plant.derivative(&xm, um, 0.0)) / (2.0 * h);
            for i in 0..4 {
                let an = if j < 4 { a[(i, j)] } else { b[i] };
                let tol = 1e-6 * (1.0 + an.abs());
                assert!((an - fd[i]).abs() < tol, "({i},{j}) {an} vs {}", fd[i]);
            }
        }
    }
}

#[test]
fn invalid_parameters_name_the_field() {
    let mut p = FurutaParams::qube_servo2();
    p.mp = -1.0;
    let err = Plant::new(p).unwrap_err();
    assert!(err.to_string().contains("mp"), "{err}");
    let mut p = FurutaParams::qube_servo2();
    p.dr = f64::NAN;
    assert!(Plant::new(p).unwrap_err().to_string().contains("Dr"));
    let mut p = FurutaParams::qube_servo2();
    p.km = 0.0;
    assert!(Plant::new(p).is_ok());
}

#[test]
fn energy_is_conserved_without_friction() {
    let p = FurutaParams {
        km: 0.0,
        dr: 0.0,
        dp: 0.0,
        ..FurutaParams::qube_servo2()
    };
    let plant = Plant::new(p).unwrap();
    let mut x = State::new(0.0, 3.0, 0.5, -4.0);
    let e0 = plant.energy(&x);
    for _ in 0..2000 {
        plant.advance(&mut x, 0.0, 0.0, 1e-3, 1);
    }
    // RK4 is not symplectic; its O(h⁵) local drift over 2 s at h = 1 ms is ~2·10⁻⁹ relative.
    assert!((plant.energy(&x) - e0).abs() < 1e-8 * e0.abs());
}

/// Only the arm's torques change its angular momentum: without them it is conserved through
/// a pendulum swinging over the top, and with the motor driving, `Ḣ` is the motor torque
/// less the arm's damping (integrated by the trapezoid rule along the trajectory).
#[test]
fn arm_momentum_changes_by_the_arms_torques_alone() {
    let free = Plant::new(FurutaParams {
        km: 0.0,
        dr: 0.0,
        dp: 0.0,
        cr: 0.0,
        cp: 0.0,
        ..FurutaParams::qube_servo2()
    })
    .unwrap();
    let mut x = State::new(0.0, 3.0, 0.5, -14.0);
    let h0 = free.arm_momentum(&x);
    let mut swing: f64 = 0.0;
    for _ in 0..2000 {
        free.advance(&mut x, 0.0, 0.0, 1e-3, 1);
        swing = swing.max((x[1] - 3.0).abs());
    }
    assert!(
        swing > 1.0,
        "the arm's rate alone must not be conserved: {swing}"
    );
    let drift = (free.arm_momentum(&x) - h0).abs();
    // RK4's truncation over 2 s at 1 ms with the pendulum over the top: ~4·10⁻⁹ relative;
    // a wrong coupling term changes H by the order of the arm's swing in rate.
    assert!(drift < 1e-7 * h0.abs(), "{drift} of {h0}");

    let p = FurutaParams {
        dp: 0.0,
        cr: 0.0,
        cp: 0.0,
        ..FurutaParams::qube_servo2()
    };
    let driven = Plant::new(p).unwrap();
    let torque = |x: &State| driven.motor_torque(x, 5.0) - p.dr * x[1];
    let mut x = State::new(0.0, 1.0, 2.5, 3.0);
    let h0 = driven.arm_momentum(&x);
    let mut integral = 0.0;
    let h = 1e-4;
    for _ in 0..5000 {
        let before = torque(&x);
        driven.advance(&mut x, 5.0, 0.0, h, 1);
        integral += 0.5 * h * (before + torque(&x));
    }
    let change = driven.arm_momentum(&x) - h0;
    assert!(
        (change - integral).abs() < 1e-6 * integral.abs(),
        "{change} against {integral}"
    );
    assert!(
        (driven.arm_inertia(x[2]) * x[1] - driven.arm_momentum(&x)).abs() > 1e-6,
        "the pendulum's rate must count"
    );
}

fn rough_params() -> FurutaParams {
    FurutaParams {
        cr: 3e-3,
        cp: 2e-5,
        vd: 0.4,
        ..FurutaParams::qube_servo2()
    }
}

#[test]
fn stiction_raises_the_arm_friction_to_the_breakaway_torque_at_low_speed() {
    let p = rough_params();
    let smooth = Plant::new(FurutaParams {
        cr: 0.0,
        cp: 0.0,
        vd: 0.0,
        ..p
    })
    .unwrap();
    let coulomb = Plant::new(FurutaParams {
        cp: 0.0,
        vd: 0.0,
        ..p
    })
    .unwrap();
    let sticky = coulomb.with_arm_breakaway(3.0 * p.cr).unwrap();
    assert_eq!(sticky.arm_breakaway(), 3.0 * p.cr);
    // The friction torque on the arm, from the difference of the arm's equation with and
    // without it: M ẍ differs only in the first force, f1.
    let friction = |plant: &Plant, rate: f64| {
        let x = State::new(0.0, rate, 0.0, 0.0);
        let ([m11, m12, _], _) = smooth.mass_and_forces(&x, 0.0, 0.0);
        let (d0, d1) = (
            smooth.derivative(&x, 2.0, 0.0),
            plant.derivative(&x, 2.0, 0.0),
        );
        // Only f1 changes: M [Δθ̈; Δα̈] = [Δf1; 0].
        m11 * (d0[1] - d1[1]) + m12 * (d0[3] - d1[3])
    };
    for rate in [0.02, 0.05, 0.1, 0.3, 1.0] {
        let sgn = (rate / COULOMB_VELOCITY_SCALE).tanh();
        let want = (p.cr + 2.0 * p.cr * (-(rate / STRIBECK_VELOCITY).powi(2)).exp()) * sgn;
        assert!((friction(&sticky, rate) - want).abs() < 1e-12, "{rate}");
        assert!(
            (friction(&coulomb, rate) - p.cr * sgn).abs() < 1e-12,
            "{rate}"
        );
    }
    // Well above v_s the breakaway has decayed to the Coulomb level.
    assert!((friction(&sticky, 1.0) - friction(&coulomb, 1.0)).abs() < 1e-12);
    // The stiffer friction at rest shortens the RK4 substep limit.
    assert!(sticky.max_rk4_substep() < coulomb.max_rk4_substep());
    assert!(coulomb.with_arm_breakaway(0.5 * p.cr).is_err());
    assert!(coulomb.with_arm_breakaway(f64::NAN).is_err());
    assert_eq!(coulomb.with_arm_breakaway(0.0).unwrap(), coulomb);
}

#[test]
fn the_dead_zone_removes_the_threshold_voltage() {
    assert_eq!(dead_zone(0.3, 0.4), 0.0);
    assert_eq!(dead_zone(-0.4, 0.4), 0.0);
    assert!((dead_zone(1.5, 0.4) - 1.1).abs() < 1e-15);
    assert!((dead_zone(-1.5, 0.4) + 1.1).abs() < 1e-15);
    for u in [-3.0, -1e-9, 0.0, 2.5] {
        assert_eq!(dead_zone(u, 0.0), u);
    }
    // On the plant: a voltage inside the dead zone is no voltage, one beyond it is reduced.
    let rough = Plant::new(rough_params()).unwrap();
    let smooth = Plant::new(FurutaParams {
        vd: 0.0,
        ..rough_params()
    })
    .unwrap();
    let x = State::new(0.0, 0.7, 0.4, -0.3);
    assert_eq!(
        rough.derivative(&x, 0.35, 0.0),
        smooth.derivative(&x, 0.0, 0.0)
    );
    let d = rough.derivative(&x, 2.0, 0.0) - smooth.derivative(&x, 1.6, 0.0);
    assert!(d.norm() < 1e-12, "{d}");
}

#[test]
fn coulomb_friction_opposes_motion_and_dissipates_energy() {
    // No viscous friction nor back-EMF: Coulomb friction alone must bring the swinging
    // pendulum and the spinning arm to rest, monotonically losing energy.
    let p = FurutaParams {
        km: 0.0,
        dr: 0.0,
        dp: 0.0,
        cp: 2e-4,
        ..rough_params()
    };
    let plant = Plant::new(p).unwrap();
    let mut x = State::new(0.0, 2.0, std::f64::consts::PI - 0.5, 0.0);
    let mut e = plant.energy(&x);
    for _ in 0..20_000 {
        plant.advance(&mut x, 0.0, 0.0, 1e-3, 1);
        let e_next = plant.energy(&x);
        assert!(e_next <= e + 1e-12, "energy rose from {e} to {e_next}");
        e = e_next;
    }
    assert!(x[1].abs() < 0.05 && x[3].abs() < 0.05, "{x}");
    // The torque has the size cr away from rest, against the motion.
    let smooth = Plant::new(FurutaParams {
        cr: 0.0,
        cp: 0.0,
        ..p
    })
    .unwrap();
    let x = State::new(0.0, 1.0, 0.0, 0.0);
    let (a, b) = (
        plant.derivative(&x, 0.0, 0.0),
        smooth.derivative(&x, 0.0, 0.0),
    );
    let with_torque = smooth.derivative(&x, 0.0, -p.cr * (1.0f64 / COULOMB_VELOCITY_SCALE).tanh());
    assert!((a - with_torque).norm() < 1e-9 * a.norm());
    assert!(a[1] < b[1]);
}

#[test]
fn stiff_coulomb_friction_shortens_the_stable_substep_and_the_bound_holds() {
    let rough = Plant::new(FurutaParams {
        cr: 0.05,
        ..rough_params()
    })
    .unwrap();
    let smooth = Plant::qube_servo2();
    let h = rough.max_rk4_substep();
    assert!(h < 0.5 * smooth.max_rk4_substep());
    // Inside the bound a slowly moving arm creeps to rest; far beyond it RK4 blows up.
    for (factor, stable) in [(0.9, true), (1.5, false)] {
        let mut x = State::new(0.0, 0.01, std::f64::consts::PI, 0.0);
        for _ in 0..500 {
            rough.rk4_step(&mut x, 0.0, 0.0, factor * h);
        }
        assert_eq!(x[1].abs() < 0.01, stable, "{factor}: {x}");
    }
}

#[test]
fn upright_linearization_has_the_paper_structure_and_signs() {
    let (a, b) = Plant::paper().linearize_upright();
    let (ap, bp) = crate::paper::continuous_model();
    for i in 0..4 {
        assert!((b[(i, 0)] - bp[(i, 0)]).abs() < 1e-3 * (1.0 + bp[(i, 0)].abs()));
        for j in 0..4 {
            let tol = 5e-3 * (1.0 + ap[(i, j)].abs());
            assert!((a[(i, j)] - ap[(i, j)]).abs() < tol, "A[{i}][{j}]");
        }
    }
}

/// The QUBE-Servo 3 cable stiffness an identification measured (N·m/rad).
const QUBE3_CABLE: f64 = 2.384e-3;

#[test]
fn the_cable_holds_the_arm_where_its_spring_balances_the_motor() {
    // Statics, independent of the equations' form: at rest the motor's torque kt V / Rm
    // (no back-EMF) balances the cable's kc θ, so θ = kt V / (Rm kc).
    let p = FurutaParams {
        kc: QUBE3_CABLE,
        ..FurutaParams::qube_servo2()
    };
    let plant = Plant::new(p).unwrap();
    let v = 0.5;
    let mut x = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    for _ in 0..6000 {
        plant.advance(&mut x, v, 0.0, 0.01, 10);
    }
    let expected = p.kt * v / (p.rm * p.kc);
    assert!(
        (x[0] - expected).abs() < 1e-3,
        "{} against {expected}",
        x[0]
    );
    assert_eq!(cable_torque(x[0], p.kc), -p.kc * x[0]);
    // Without a cable nothing holds it: the arm runs away.
    let mut free = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    for _ in 0..200 {
        Plant::qube_servo2().advance(&mut free, v, 0.0, 0.01, 10);
    }
    assert!(free[0] > 2.0 * expected, "{}", free[0]);
}

#[test]
fn the_cable_adds_the_arm_spring_column_to_the_upright_linearisation() {
    let p = FurutaParams {
        kc: QUBE3_CABLE,
        ..FurutaParams::paper()
    };
    let (a, b) = Plant::new(p).unwrap().linearize_upright();
    let (a0, b0) = Plant::paper().linearize_upright();
    // M⁻¹ column of the arm's force: (Jα, m₁₂) / det M (module docs).
    let (j0, ja) = (
        p.jr + p.mr * p.lr * p.lr / 4.0 + p.mp * p.lr * p.lr,
        p.jp + p.mp * p.lp * p.lp / 4.0,
    );
    let m12 = p.mp * p.lr * p.lp / 2.0;
    let det = j0 * ja - m12 * m12;
    let expected = [0.0, -p.kc * ja / det, 0.0, -p.kc * m12 / det];
    for i in 0..4 {
        assert!((a[(i, 0)] - expected[i]).abs() < 1e-12 * (1.0 + expected[i].abs()));
        assert_eq!(b[(i, 0)], b0[(i, 0)]);
        for j in 1..4 {
            assert_eq!(a[(i, j)], a0[(i, j)], "A[{i}][{j}]");
        }
    }
    // Without a cable the arm column is an exact zero, as in the paper's structure.
    assert!((0..4).all(|i| a0[(i, 0)] == 0.0 && a0[(i, 0)].is_sign_positive()));
}
