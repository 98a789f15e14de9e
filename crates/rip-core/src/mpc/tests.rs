use nalgebra::DVector;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

use super::*;
use crate::controller::Controller;

fn randn(rng: &mut StdRng, r: usize, c: usize) -> Mat {
    Mat::from_fn(r, c, |_, _| rng.sample::<f64, _>(StandardNormal))
}

/// A random plant with spectral radius about 1.05 (mildly unstable, like the pendulum).
fn random_plant(rng: &mut StdRng, n: usize, nu: usize, ny: usize) -> (Mat, Mat, Mat) {
    let a = randn(rng, n, n);
    let rho = crate::linalg::spectral_radius(&a);
    (a * (1.05 / rho), randn(rng, n, nu), randn(rng, ny, n))
}

/// The KKT point of `min ½zᵀHz + fᵀz, A z ≤ b` by enumerating every working set of size
/// at most `dim z`: the one whose equality solution is feasible with nonnegative multipliers.
fn enumerate_kkt(h: &Mat, f: &DVector<f64>, a: &Mat, b: &DVector<f64>) -> DVector<f64> {
    let n = h.nrows();
    let ncon = a.nrows();
    let mut best: Option<(f64, DVector<f64>)> = None;
    let mut subset = Vec::new();
    fn rec(
        start: usize,
        subset: &mut Vec<usize>,
        n: usize,
        ncon: usize,
        visit: &mut dyn FnMut(&[usize]),
    ) {
        visit(subset);
        if subset.len() == n {
            return;
        }
        for i in start..ncon {
            subset.push(i);
            rec(i + 1, subset, n, ncon, visit);
            subset.pop();
        }
    }
    let mut visit = |w: &[usize]| {
        let k = w.len();
        let mut kkt = Mat::zeros(n + k, n + k);
        let mut rhs = DVector::zeros(n + k);
        kkt.view_mut((0, 0), (n, n)).copy_from(h);
        rhs.rows_mut(0, n).copy_from(&(-f));
        for (r, &i) in w.iter().enumerate() {
            for c in 0..n {
                kkt[(n + r, c)] = a[(i, c)];
                kkt[(c, n + r)] = a[(i, c)];
            }
            rhs[n + r] = b[i];
        }
        let Some(sol) = kkt.lu().solve(&rhs) else {
            return;
        };
        if sol.iter().any(|v| !v.is_finite()) {
            return;
        }
        let z = sol.rows(0, n).into_owned();
        let tol = 1e-8 * (1.0 + b.amax());
        let feasible = (a * &z - b).iter().all(|&v| v <= tol);
        let dual = sol.rows(n, k).iter().all(|&l| l >= -1e-8);
        if feasible && dual {
            let cost = 0.5 * z.dot(&(h * &z)) + f.dot(&z);
            if best.as_ref().map_or(true, |(c, _)| cost < *c) {
                best = Some((cost, z));
            }
        }
    };
    rec(0, &mut subset, n, ncon, &mut visit);
    best.expect("a strictly convex feasible QP has a KKT point")
        .1
}

fn small_settings(solver: QpSolver) -> MpcSettings {
    MpcSettings::builder()
        .prediction_horizon(6)
        .control_horizon(2)
        .output_weights(vec![2.0, 1.0])
        .input_rate_weights(vec![0.3])
        .input_weights(vec![0.05])
        .input_scales(vec![2.0])
        .output_scales(vec![1.0, 0.5])
        .input_bounds(vec![(-1.0, 0.8)])
        .output_bounds(vec![(f64::NEG_INFINITY, f64::INFINITY), (-0.4, 0.5)])
        .ecr_weight(10.0)
        .output_disturbance(Some(OutputDisturbance::integrated_white_noise(2, 0.1)))
        .solver(solver)
        .build()
        .unwrap()
}

#[test]
fn both_backends_match_enumerated_kkt_point() {
    let mut rng = StdRng::seed_from_u64(7);
    let (mut input_active, mut slack_positive) = (0, 0);
    for _ in 0..40 {
        let (a, b, c) = random_plant(&mut rng, 3, 1, 2);
        let mut cl = Mpc::new(&a, &b, &c, 0.1, small_settings(QpSolver::Clarabel)).unwrap();
        let mut asb = Mpc::new(&a, &b, &c, 0.1, small_settings(QpSolver::ActiveSet)).unwrap();
        for _ in 0..3 {
            let x: Vec<f64> = (0..4)
                .map(|_| rng.sample::<f64, _>(StandardNormal))
                .collect();
            let u_prev = [rng.gen_range(-1.5..1.5)];
            let r = [rng.gen_range(-2.0..2.0), rng.gen_range(-1.0..1.0)];
            let (h, f, ac, bc) = cl.qp_matrices(&x, &u_prev, &r).unwrap();
            let z_ref = enumerate_kkt(&h, &f, &ac, &bc);
            let u_ref = u_prev[0] + z_ref[0];
            let s1 = cl.solve(&x, &u_prev, &r).unwrap().clone();
            let s2 = asb.solve(&x, &u_prev, &r).unwrap().clone();
            assert_eq!(s1.status, QpStatus::Solved);
            assert_eq!(s2.status, QpStatus::Solved);
            assert!(
                (s1.u[0] - u_ref).abs() < 1e-6,
                "clarabel {} vs {}",
                s1.u[0],
                u_ref
            );
            assert!(
                (s2.u[0] - u_ref).abs() < 1e-8,
                "active set {} vs {}",
                s2.u[0],
                u_ref
            );
            assert!((s2.slack - z_ref[2].max(0.0)).abs() < 1e-8);
            if (u_ref - 0.8).abs() < 1e-9 || (u_ref + 1.0).abs() < 1e-9 {
                input_active += 1;
            }
            if z_ref[2] > 1e-6 {
                slack_positive += 1;
            }
        }
    }
    assert!(
        input_active > 5,
        "only {input_active} instances with the input bound active"
    );
    assert!(
        slack_positive > 5,
        "only {slack_positive} instances with a positive slack"
    );
}

#[test]
fn paper_backends_agree_along_a_closed_loop_on_the_linear_model() {
    // The active-set controller drives the loop; Clarabel solves the same QP at every step.
    let mut cl = paper::controller(QpSolver::Clarabel).unwrap();
    let mut asb = paper::controller(QpSolver::ActiveSet).unwrap();
    let plant = crate::paper::discrete_model();
    let mut x = DVector::from_row_slice(&[0.0, 0.0, 0.3, 0.0]);
    let mut u = [0.0];
    let (mut max_du, mut saturated, mut soft_active) = (0.0f64, 0, 0);
    for k in 0..300 {
        let y = &plant.c * &x;
        let r = [if k < 100 { 0.0 } else { 1.0 }, 0.0];
        let u_prev = asb.last_input().to_vec();
        asb.step(y.as_slice(), &r, &mut u);
        let xhat = asb.state_estimate().unwrap().to_vec();
        let s = cl.solve(&xhat, &u_prev, &r).unwrap().clone();
        assert!(s.status.is_usable());
        // Where they differ, the active-set point is feasible and no worse (IPM accuracy).
        let (h, f, a, b) = asb.qp_matrices(&xhat, &u_prev, &r).unwrap();
        let z_of = |sol: &MpcSolution| {
            let mut z = DVector::zeros(4);
            z.rows_mut(0, 3).copy_from(&sol.du);
            z[0] = sol.u[0] - u_prev[0];
            z[3] = sol.slack;
            z
        };
        let (z_cl, z_as) = (z_of(&s), z_of(asb.last_solution()));
        let cost = |z: &DVector<f64>| 0.5 * z.dot(&(&h * z)) + f.dot(z);
        assert!((&a * &z_as - &b).max() <= 1e-9 * (1.0 + b.amax()));
        let (c_as, c_cl) = (cost(&z_as), cost(&z_cl));
        assert!(
            c_as <= c_cl + 1e-10 * c_cl.abs().max(1.0),
            "k={k}: {c_as} > {c_cl}"
        );
        assert_eq!(asb.last_solution().status, QpStatus::Solved);
        max_du = max_du.max((s.u[0] - u[0]).abs());
        saturated += usize::from(u[0].abs() > 12.0 - 1e-9);
        soft_active += usize::from(asb.last_solution().slack > 1e-6);
        assert!(u[0].abs() <= 12.0);
        x = &plant.a * &x + &plant.b * u[0];
    }
    assert!(saturated > 0, "the scenario should saturate the input");
    assert!(soft_active > 0, "the scenario should use the slack");
    assert!(max_du < 1e-6, "backends differ by {max_du} V");
    assert!(
        x[2].abs() < 0.05 && (x[0] - 1.0).abs() < 0.1,
        "did not settle: {x}"
    );
}

#[test]
fn paper_kalman_gains_equal_eq_11() {
    let mpc = paper::controller(QpSolver::ActiveSet).unwrap();
    let reference = crate::paper::kalman_design().unwrap();
    let k = mpc.kalman_design();
    assert!((&k.l - &reference.l).amax() < 1e-12);
    assert!((&k.m - &reference.m).amax() < 1e-12);
    let aug = crate::paper::augmented_model();
    assert!((&mpc.model().a - &aug.a).amax() == 0.0);
    assert!((&mpc.model().c - &aug.c).amax() == 0.0);
}

#[test]
fn bad_settings_name_the_argument() {
    let (a, b, c) = random_plant(&mut StdRng::seed_from_u64(1), 3, 1, 2);
    let cases: Vec<(MpcSettings, &str)> = vec![
        (
            MpcSettings {
                prediction_horizon: 3,
                control_horizon: 4,
                ..Default::default()
            },
            "control_horizon",
        ),
        (
            MpcSettings {
                prediction_step: 0,
                ..Default::default()
            },
            "prediction_step",
        ),
        (
            // P = 10 grid steps of 1001 periods: a horizon beyond MAX_PREDICTION_HORIZON.
            MpcSettings {
                prediction_step: MAX_PREDICTION_HORIZON / 10 + 1,
                ..Default::default()
            },
            "prediction_step",
        ),
        (
            MpcSettings {
                output_weights: vec![1.0, -1.0],
                ..Default::default()
            },
            "output_weights",
        ),
        (
            MpcSettings {
                input_bounds: vec![(1.0, -1.0)],
                ..Default::default()
            },
            "input_bounds",
        ),
        (
            MpcSettings {
                output_bounds: vec![(0.0, f64::NAN), (0.0, 1.0)],
                ..Default::default()
            },
            "output_bounds",
        ),
        (
            MpcSettings {
                input_scales: vec![0.0],
                ..Default::default()
            },
            "input_scales",
        ),
        (
            MpcSettings {
                ecr_weight: -1.0,
                ..Default::default()
            },
            "ecr_weight",
        ),
        (
            MpcSettings {
                ecr_weight: 1e308,
                ..Default::default()
            },
            "ecr_weight",
        ),
        (
            MpcSettings {
                output_weights: vec![1.0],
                ..Default::default()
            },
            "output_weights",
        ),
        (
            MpcSettings {
                output_disturbance: Some(OutputDisturbance::integrated_white_noise(3, 1.0)),
                ..Default::default()
            },
            "C_od",
        ),
        (
            MpcSettings {
                input_rate_weights: vec![0.0],
                output_weights: vec![0.0, 0.0],
                ..Default::default()
            },
            "input_rate_weights",
        ),
        (
            MpcSettings {
                prediction_horizon: 1_000_000_000,
                ..Default::default()
            },
            "prediction_horizon",
        ),
        (
            // Within the horizon bound, but m = P makes the condensed matrices P² in size.
            MpcSettings {
                prediction_horizon: MAX_PREDICTION_HORIZON,
                control_horizon: MAX_PREDICTION_HORIZON,
                ..Default::default()
            },
            "prediction_horizon",
        ),
    ];
    for (settings, name) in cases {
        let err = Mpc::new(&a, &b, &c, 0.1, settings).unwrap_err();
        // The key is data: a message that merely mentions the key among others is not enough.
        match &err {
            RipError::InvalidParameter { name: key, .. } => {
                assert_eq!(
                    key.split('[').next(),
                    Some(name),
                    "{err} should be blamed on {name}"
                )
            }
            other => assert!(other.to_string().contains(name), "{err} should name {name}"),
        }
    }
}

#[test]
fn fallback_is_finite_and_within_bounds() {
    let mut settings = paper::settings(QpSolver::Clarabel);
    settings.max_iterations = 1;
    let plant = crate::paper::discrete_model();
    let mut mpc = Mpc::new(&plant.a, &plant.b, &plant.c, 0.01, settings).unwrap();
    let mut u = [f64::NAN];
    let status = mpc.step(&[0.5, 0.4], &[1.0, 0.0], &mut u);
    assert_eq!(status, StepStatus::Fallback);
    assert_eq!(mpc.last_solution().status, QpStatus::MaxIterations);
    assert!(u[0].is_finite() && u[0].abs() <= 12.0);

    let mut good = paper::controller(QpSolver::ActiveSet).unwrap();
    good.step(&[0.0, 0.1], &[0.0, 0.0], &mut u);
    let planned_next = u[0] + good.last_solution().du[1];
    let status = good.step(&[f64::NAN, 0.0], &[0.0, 0.0], &mut u);
    assert_eq!(status, StepStatus::Fallback);
    assert_eq!(good.last_solution().status, QpStatus::InvalidInput);
    assert!((u[0] - planned_next.clamp(-12.0, 12.0)).abs() < 1e-12);
    assert!(good.state_estimate().unwrap().iter().all(|v| v.is_finite()));
}

#[test]
fn clones_are_independent_and_send() {
    fn assert_send<T: Send + Clone>() {}
    assert_send::<Mpc>();
    let mut a = paper::controller(QpSolver::Clarabel).unwrap();
    let mut u = [0.0];
    a.step(&[0.0, 0.2], &[0.0, 0.0], &mut u);
    let mut b = a.clone();
    let (mut ua, mut ub) = ([0.0], [0.0]);
    a.step(&[0.01, 0.15], &[0.0, 0.0], &mut ua);
    b.step(&[0.01, 0.15], &[0.0, 0.0], &mut ub);
    assert!((ua[0] - ub[0]).abs() < 1e-12);
}

#[test]
fn preview_of_one_row_equals_constant_reference() {
    let mut mpc = paper::controller(QpSolver::ActiveSet).unwrap();
    let x = [0.1, 0.0, 0.05, 0.0, 0.0];
    let u1 = mpc.solve(&x, &[0.0], &[1.0, 0.0]).unwrap().u[0];
    let mut preview = vec![0.0; 2 * 50];
    for i in 0..50 {
        preview[2 * i] = 1.0;
    }
    let u2 = mpc.solve(&x, &[0.0], &preview).unwrap().u[0];
    let u3 = mpc.solve(&x, &[0.0], &preview[..20]).unwrap().u[0];
    assert!((u1 - u2).abs() < 1e-10 && (u1 - u3).abs() < 1e-10);
    assert!(mpc.solve(&x, &[0.0], &[1.0; 3]).is_err());
    assert!(mpc.solve(&x, &[0.0], &vec![1.0; 102]).is_err());
}

#[test]
fn hold_is_the_time_update_without_innovation_and_shifts_the_plan() {
    for solver in [QpSolver::ActiveSet, QpSolver::Clarabel] {
        let mut mpc = paper::controller(solver).unwrap();
        let mut twin = paper::controller(solver).unwrap();
        let (a, b, c) = (
            mpc.model().a.clone(),
            mpc.model().b.clone(),
            mpc.model().c.clone(),
        );
        let (l, m) = (mpc.kalman_design().l.clone(), mpc.kalman_design().m.clone());
        let r = [0.5, 0.0];
        let mut u = [0.0];
        for k in 0..5 {
            mpc.step(&[0.01 * k as f64, 0.05], &r, &mut u);
        }
        let prior = mpc.estimator().prior().clone();

        // The plant keeps a command other than the last move (rounded, limited by the loop).
        let held = u[0] - 0.25;
        mpc.hold(&[held]);
        assert_eq!(mpc.estimator().posterior(), &prior);
        assert_eq!(mpc.state_estimate().unwrap(), prior.as_slice());
        assert!(mpc.estimator().innovation().iter().all(|&e| e == 0.0));
        let want = &a * &prior + &b * held;
        assert!((mpc.estimator().prior() - &want).amax() < 1e-12);
        assert_eq!(mpc.last_input(), &[held]);

        // The next sample: eqs. (4)-(6) from the held period's prediction, and a move from u_h.
        let y = [0.02, 0.04];
        mpc.step(&y, &r, &mut u);
        let e = DVector::from_row_slice(&y) - &c * &want;
        let post = &want + &m * &e;
        assert!((mpc.estimator().posterior() - &post).amax() < 1e-12);
        let expected = twin.solve(post.as_slice(), &[held], &r).unwrap().u[0];
        // An interior-point solve stops within its tolerances of an active bound, so two
        // solves from estimates equal to 1e-12 agree only to that tolerance.
        let tol = match solver {
            QpSolver::ActiveSet => 1e-9,
            QpSolver::Clarabel => 1e-6,
        };
        assert!(
            (u[0] - expected).abs() < tol,
            "{solver:?}: {} vs {expected}",
            u[0]
        );
        let next_prior = &a * &want + &b * u[0] + &l * &e;
        assert!((mpc.estimator().prior() - &next_prior).amax() < 1e-12);

        // A hold advances the plan like a sample: after one hold and one failed step, the
        // fallback is the move planned for two samples ahead.
        let mut mpc = paper::controller(solver).unwrap();
        for k in 0..5 {
            mpc.step(&[0.01 * k as f64, 0.05], &r, &mut u);
        }
        let sol = mpc.last_solution().clone();
        let two_ahead = (sol.u[0] + sol.du[1] + sol.du[2]).clamp(-12.0, 12.0);
        mpc.hold(&u);
        assert_eq!(mpc.step(&[f64::NAN, 0.0], &r, &mut u), StepStatus::Fallback);
        assert!((u[0] - two_ahead).abs() < 1e-12, "{} vs {two_ahead}", u[0]);
    }
}

#[test]
fn an_overflowing_measurement_is_discarded_and_the_controller_recovers() {
    for solver in [QpSolver::ActiveSet, QpSolver::Clarabel] {
        let mut mpc = paper::controller(solver).unwrap();
        let mut skipped = paper::controller(solver).unwrap();
        let mut u = [0.0];
        let mut v = [0.0];
        for k in 0..3 {
            let y = [0.001 * k as f64, 0.02];
            mpc.step(&y, &[0.0, 0.0], &mut u);
            skipped.step(&y, &[0.0, 0.0], &mut v);
        }
        let prior = mpc.estimator().prior().clone();
        let status = mpc.step(&[1e308, -1e308], &[0.0, 0.0], &mut u);
        assert_eq!(status, StepStatus::Fallback);
        assert_eq!(mpc.last_solution().status, QpStatus::InvalidInput);
        assert_eq!(mpc.estimator().posterior(), &prior);
        assert!(u[0].is_finite() && u[0].abs() <= 12.0);
        // Exactly as if the sample had been NaN.
        skipped.step(&[f64::NAN, f64::NAN], &[0.0, 0.0], &mut v);
        assert_eq!(u, v);
        assert_eq!(mpc.estimator().prior(), skipped.estimator().prior());
        for k in 0..5 {
            let y = [0.0, 0.01 * k as f64];
            let status = mpc.step(&y, &[0.0, 0.0], &mut u);
            skipped.step(&y, &[0.0, 0.0], &mut v);
            assert_eq!(status, StepStatus::Nominal, "{solver:?} sample {k}");
            assert_eq!(mpc.last_solution().status, QpStatus::Solved);
            assert_eq!(u, v);
        }
        // Also when the reference of that sample is unusable too (no QP to solve).
        let prior = mpc.estimator().prior().clone();
        mpc.step(&[-1e308, 1e308], &[f64::NAN, 0.0], &mut u);
        assert_eq!(mpc.estimator().posterior(), &prior);
        mpc.step(&[0.0, 0.0], &[0.0, 0.0], &mut u);
        assert_eq!(mpc.last_solution().status, QpStatus::Solved, "{solver:?}");
        // The same holds for a direct solve from an absurd state: no solver call, a fallback.
        let sol = mpc.solve(&[1e307, 0.0, -1e307, 0.0, 0.0], &[0.0], &[0.0, 0.0]);
        assert_eq!(sol.unwrap().status, QpStatus::InvalidInput);
    }
}

/// The condensed problem on a grid of `s` periods against the model run one period at a
/// time: the predicted outputs every `s` periods with each move held for `s` periods, and the
/// QP's cost differences against the cost summed along that simulated trajectory.
#[test]
fn prediction_grid_matches_the_model_run_period_by_period() {
    let mut rng = StdRng::seed_from_u64(11);
    let s = 3;
    let settings = MpcSettings {
        prediction_step: s,
        ..small_settings(QpSolver::ActiveSet)
    };
    let (p, m) = (settings.prediction_horizon, settings.control_horizon);
    let (wy, wu, wdu, su, sy) = ([2.0, 1.0], 0.05, 0.3, 2.0, [1.0, 0.5]);
    let rho = settings.ecr_weight;
    for _ in 0..10 {
        let (a, b, c) = random_plant(&mut rng, 3, 1, 2);
        let mpc = Mpc::new(&a, &b, &c, 0.1, settings.clone()).unwrap();
        let model = mpc.model();
        let nx = model.a.nrows();
        let x0 = DVector::from_fn(nx, |_, _| rng.sample::<f64, _>(StandardNormal));
        let u_prev = [rng.gen_range(-1.0..1.0)];
        let r = [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)];
        let (h, f, _, _) = mpc.qp_matrices(x0.as_slice(), &u_prev, &r).unwrap();
        // Outputs (engineering units) every s periods and the inputs of each grid step.
        let simulate = |du: &[f64]| {
            let (mut x, mut u) = (x0.clone(), u_prev[0]);
            let (mut ys, mut us) = (Vec::new(), Vec::new());
            for k in 0..p * s {
                if k % s == 0 {
                    if k / s < m {
                        u += du[k / s];
                    }
                    us.push(u);
                }
                x = &model.a * &x + &model.b * u;
                if (k + 1) % s == 0 {
                    let y = &model.c * &x;
                    ys.push([y[0] * sy[0], y[1] * sy[1]]);
                }
            }
            (ys, us)
        };
        let cost = |du: &[f64], eps: f64| {
            let (ys, us) = simulate(du);
            let mut j = rho * eps * eps;
            for y in &ys {
                for o in 0..2 {
                    j += (wy[o] * (r[o] - y[o]) / sy[o]).powi(2);
                }
            }
            j += du.iter().map(|d| (wdu * d / su).powi(2)).sum::<f64>();
            j + us.iter().map(|u| (wu * u / su).powi(2)).sum::<f64>()
        };
        let qp_cost = |du: &[f64], eps: f64| {
            let mut z = DVector::from_column_slice(du).push(0.0);
            z[m] = eps;
            0.5 * z.dot(&(&h * &z)) + f.dot(&z)
        };
        let du: Vec<f64> = (0..m).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let (ys, _) = simulate(&du);
        let pred = mpc.predict_outputs(x0.as_slice(), &u_prev, &du).unwrap();
        for (i, y) in ys.iter().enumerate() {
            for o in 0..2 {
                let tol = 1e-9 * (1.0 + y[o].abs());
                assert!(
                    (pred[(i, o)] - y[o]).abs() < tol,
                    "step {i}: {pred} vs {ys:?}"
                );
            }
        }
        let zero = vec![0.0; m];
        let (eps, eps0) = (rng.gen_range(0.0..0.5), 0.0);
        let want = cost(&du, eps) - cost(&zero, eps0);
        let got = qp_cost(&du, eps) - qp_cost(&zero, eps0);
        assert!(
            (got - want).abs() < 1e-8 * (1.0 + want.abs()),
            "cost difference {got} vs {want}"
        );
    }
}
