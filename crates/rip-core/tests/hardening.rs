//! Finite but extreme inputs: every routine ends, refuses what it cannot compute with an error
//! naming the cause, and never returns NaN or Inf computed from finite numbers.

use rip_core::fit::{fit_params, FitOptions};
use rip_core::linalg::expm;
use rip_core::mpc::{paper, Mpc, OutputDisturbance, QpSolver};
use rip_core::sim::SensorModel;
use rip_core::{c2d, simulate, FurutaParams, Lqr, Mat, Plant, RipError, SimConfig, State};

fn invalid_name(err: &RipError) -> &str {
    match err {
        RipError::InvalidParameter { name, .. } => name,
        other => panic!("expected InvalidParameter, got {other}"),
    }
}

#[test]
fn c2d_of_huge_entries_ends_with_an_error() {
    // nalgebra's expm derived an infinite number of squarings from these and never returned.
    for scale in [1e41, 1e50, 1e60, 1e300] {
        let a = Mat::from_row_slice(2, 2, &[0.0, scale, -scale, 0.5 * scale]);
        let err = c2d(&a, &Mat::from_element(2, 1, 1.0), 0.01).unwrap_err();
        assert_eq!(invalid_name(&err), "Ts", "{err}");
    }
}

#[test]
fn expm_of_a_huge_stable_matrix_is_scaled_not_refused() {
    // e^{-1e50 I} underflows to zero exactly; scaling and squaring must get there.
    let e = expm(&(Mat::identity(3, 3) * -1e50)).unwrap();
    assert_eq!(e, Mat::zeros(3, 3));
    // Rotation: e^{[[0, w], [-w, 0]]} = [[cos w, sin w], [-sin w, cos w]].
    let w = 40.0_f64;
    let e = expm(&Mat::from_row_slice(2, 2, &[0.0, w, -w, 0.0])).unwrap();
    let want = Mat::from_row_slice(2, 2, &[w.cos(), w.sin(), -w.sin(), w.cos()]);
    assert!((e - want).amax() < 1e-12);
}

#[test]
fn plant_step_bounds_its_work_and_refuses_overflow() {
    let plant = Plant::qube_servo2();
    let x = State::new(0.0, 0.0, 0.1, 0.0);
    let err = plant
        .step_checked(&x, 0.0, 0.0, 0.01, 200_000_000)
        .unwrap_err();
    assert_eq!(invalid_name(&err), "substeps");
    // A substep beyond RK4's stability region is refused before integrating.
    let err = plant.step_checked(&x, 0.0, 0.0, 1e300, 1).unwrap_err();
    assert_eq!(invalid_name(&err), "dt");
    // A legal substep whose result overflows is reported as divergence.
    let err = plant.step_checked(&x, 1e300, 0.0, 0.01, 1).unwrap_err();
    assert!(matches!(err, RipError::Diverged { .. }), "{err}");
    let err = plant
        .integrate(&x, &[1000.0; 1000], 0.01, 1)
        .map(|_| ())
        .unwrap_err();
    assert!(matches!(err, RipError::Diverged { .. }), "{err}");
    let err = plant
        .integrate(&x, &vec![0.0; 1_000_000], 0.01, 100)
        .unwrap_err();
    assert_eq!(invalid_name(&err), "u");
    // A legal call still agrees with `advance`.
    let mut direct = x;
    plant.advance(&mut direct, 1.0, 0.0, 0.01, 4);
    assert_eq!(plant.step_checked(&x, 1.0, 0.0, 0.01, 4).unwrap(), direct);
}

#[test]
fn a_diverging_simulation_is_not_a_fall() {
    let plant = Plant::new(FurutaParams {
        dp: 1e300,
        ..FurutaParams::qube_servo2()
    })
    .unwrap();
    let k = Mat::from_row_slice(1, 4, &[-2.0, -1.5, 30.0, 2.5]);
    let mut ctrl = Lqr::new(&k, 0.01, f64::INFINITY).unwrap();
    let config = SimConfig {
        duration: 1.0,
        x0: [0.0, 0.0, 0.05, 0.0],
        ..Default::default()
    };
    let res = simulate(&plant, &mut ctrl, &config).unwrap();
    assert!(res.diverged, "the integration overflowed");
    assert!(!res.fell, "a numerical failure is not a fall");
    assert!(res.x_final.iter().all(|v| v.is_finite()));
}

#[test]
fn simulator_refuses_noise_whose_square_overflows() {
    let mut ctrl = Lqr::new(&Mat::zeros(1, 4), 0.01, 20.0).unwrap();
    let config = SimConfig {
        sensor: SensorModel {
            counts_per_rev: None,
            noise_std: [1e300, 1e300],
            offsets: [0.0; 2],
        },
        ..Default::default()
    };
    let err = simulate(&Plant::qube_servo2(), &mut ctrl, &config).unwrap_err();
    assert_eq!(invalid_name(&err), "noise_std");
}

#[test]
fn fit_that_never_improves_is_not_converged() {
    let (ad, bd) = Plant::paper()
        .linearize_discrete(&State::zeros(), 0.0, 0.01)
        .unwrap();
    // No step improves the initial guess of a target scaled by 1e300: a stall, not convergence.
    let report = fit_params(&(&ad * 1e300), &bd, 0.01, &FitOptions::default()).unwrap();
    assert!(!report.converged, "{report:?}");
    // A target no pendulum produces converges to the nearest model; "converged" must then mean
    // a stationary point: refitting from the answer does not improve it.
    let target = &ad * 1.5;
    let report = fit_params(&target, &bd, 0.01, &FitOptions::default()).unwrap();
    if report.converged {
        let again = FitOptions {
            base: report.params,
            ..Default::default()
        };
        let refit = fit_params(&target, &bd, 0.01, &again).unwrap();
        assert!(
            refit.rms_weighted_residual >= report.rms_weighted_residual * (1.0 - 1e-6),
            "converged at {} but a restart reached {}",
            report.rms_weighted_residual,
            refit.rms_weighted_residual
        );
    }
    // A reachable target converges, to round-off.
    let report = fit_params(&ad, &bd, 0.01, &FitOptions::default()).unwrap();
    assert!(
        report.converged && report.max_weighted_residual < 1e-6,
        "{report:?}"
    );
}

#[test]
fn fit_iterations_are_bounded() {
    let (ad, bd) = Plant::paper()
        .linearize_discrete(&State::zeros(), 0.0, 0.01)
        .unwrap();
    let options = FitOptions {
        max_iterations: usize::MAX,
        ..Default::default()
    };
    let err = fit_params(&ad, &bd, 0.01, &options).unwrap_err();
    assert_eq!(invalid_name(&err), "max_iterations");
}

fn paper_mpc_with(change: impl FnOnce(&mut rip_core::MpcSettings)) -> rip_core::Result<Mpc> {
    let m = rip_core::paper::discrete_model();
    let mut settings = paper::settings(QpSolver::Clarabel);
    change(&mut settings);
    Mpc::new(&m.a, &m.b, &m.c, rip_core::paper::TS, settings)
}

#[test]
fn mpc_design_errors_name_the_cause() {
    // The unstable pendulum's predictions overflow over 10 000 steps: the horizon, not the
    // weights.
    let err = paper_mpc_with(|s| s.prediction_horizon = 10_000).unwrap_err();
    assert_eq!(invalid_name(&err), "prediction_horizon", "{err}");
    assert!(err.to_string().contains("spectral radius"), "{err}");
    // A long horizon whose Hessian cannot be factored although the rate weight is 1.
    let err = paper_mpc_with(|s| {
        s.prediction_horizon = 2000;
        s.control_horizon = 50;
    })
    .unwrap_err();
    assert_eq!(invalid_name(&err), "prediction_horizon", "{err}");
    assert!(!err.to_string().contains("give positive"), "{err}");
    // Output scales that hide the plant from the estimator.
    let err = paper_mpc_with(|s| s.output_scales = vec![1e300, 1e300]).unwrap_err();
    assert_eq!(invalid_name(&err), "output_scales", "{err}");
    // A disturbance gain whose covariance overflows.
    let err = paper_mpc_with(|s| {
        s.output_disturbance = Some(OutputDisturbance::integrated_white_noise(2, 1e300))
    })
    .unwrap_err();
    assert_eq!(invalid_name(&err), "output_disturbance", "{err}");
    // Zero rate and input weights still get the singular-Hessian message.
    let err = paper_mpc_with(|s| {
        s.input_rate_weights = vec![0.0];
        s.output_weights = vec![0.0, 0.0];
    })
    .unwrap_err();
    assert_eq!(invalid_name(&err), "input_rate_weights", "{err}");
}

/// DAREX examples 3 and 4 (Benner, Laub, Mehrmann 1995; scipy's `test_solve_discrete_are`
/// cases 6 and 7): `R = 0` and a singular `R`, solvable because `R + BᵀXB` is invertible.
/// Published solutions: `X = I` and `X = Q = [[−4, −4], [−4, 7]]/11`.
#[test]
fn dare_with_singular_r_is_solved() {
    let a = Mat::from_row_slice(2, 2, &[2.0, -1.0, 1.0, 0.0]);
    let b = Mat::from_row_slice(2, 1, &[1.0, 0.0]);
    let q = Mat::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 1.0]);
    let sol = rip_core::dare(&a, &b, &q, &Mat::zeros(1, 1), None, None).unwrap();
    assert!((&sol.x - Mat::identity(2, 2)).amax() < 1e-12, "{}", sol.x);
    assert!(sol.closed_loop_eigenvalues.iter().all(|z| z.norm() < 1.0));

    let a = Mat::from_row_slice(2, 2, &[0.0, 1.0, 0.0, -1.0]);
    let b = Mat::from_row_slice(2, 2, &[1.0, 0.0, 2.0, 1.0]);
    let q = Mat::from_row_slice(2, 2, &[-4.0, -4.0, -4.0, 7.0]) * (1.0 / 11.0);
    let r = Mat::from_row_slice(2, 2, &[9.0, 3.0, 3.0, 1.0]);
    let sol = rip_core::dare(&a, &b, &q, &r, None, None).unwrap();
    assert!((&sol.x - &q).amax() < 1e-12, "{}", sol.x);
    assert!(sol.closed_loop_eigenvalues.iter().all(|z| z.norm() < 1.0));

    // Singular R and no stabilizing solution: still refused, naming the pair.
    let a = Mat::from_row_slice(2, 2, &[1.5, 0.0, 0.0, 0.5]);
    let b = Mat::from_row_slice(2, 1, &[0.0, 1.0]);
    let err =
        rip_core::dare(&a, &b, &Mat::identity(2, 2), &Mat::zeros(1, 1), None, None).unwrap_err();
    assert!(matches!(err, RipError::NotStabilizable { .. }), "{err}");
    // An indefinite R is refused by name.
    let err = rip_core::dare(
        &a,
        &b,
        &Mat::identity(2, 2),
        &Mat::from_element(1, 1, -1.0),
        None,
        None,
    )
    .unwrap_err();
    assert!(err.to_string().contains('R'), "{err}");
}

#[test]
fn qp_iteration_limit_is_bounded() {
    let err = paper_mpc_with(|s| s.max_iterations = usize::MAX).unwrap_err();
    assert_eq!(invalid_name(&err), "max_iterations", "{err}");
}
