//! Physical parameters from a discrete linear model: given `A_d`, `B_d` sampled at `Ts`, find
//! [`FurutaParams`] whose linearisation about upright, discretised by zero-order hold, reproduces
//! them.
//!
//! # What is identifiable
//!
//! The linearisation (see [`crate::plant`]) is
//!
//! ```text
//! [θ̈; α̈] = M⁻¹ ([−c θ̇ + b u; G α − dp α̇]),   M = [J₀ −m₁₂; −m₁₂ Jα]
//! ```
//!
//! so a linear model determines at most the seven lumped quantities `J₀`, `Jα`, `m₁₂`, `G`,
//! `c = dr + kt km/rm`, `dp`, `b = kt/rm` — and only up to a common factor, because scaling all of
//! them leaves `M⁻¹(…)` unchanged: six independent combinations. (Equivalently, the eight
//! entries `a₁₁ … b₃` of the continuous model obey `a₁₁/a₃₁ = b₁/b₃` and `a₁₃/a₃₃ = a₁₂/a₃₂`.)
//! The twelve physical parameters therefore cannot all be recovered. The fit keeps six of them
//! fixed at the values of a *base* parameter set — `rm`, `kt`, `km` (these fix the scale through
//! `b`), both masses `mr`, `mp`, and `g` — and solves for the six that remain:
//! `Lr`, `Lp`, `Jr`, `Jp`, `Dr`, `Dp` ([`FREE_PARAMETERS`]). Given the fixed ones, these map one
//! to one onto the six identifiable combinations:
//! `lp = 2G/(mp g)`, `lr = m₁₂/(mp lp/2)`, `jp = Jα − mp lp²/4`,
//! `jr = J₀ − mr lr²/4 − mp lr²`, `dr = c − kt km/rm`, `dp`.
//!
//! # Method
//!
//! Levenberg–Marquardt on the logarithms of the free parameters (which keeps them positive),
//! minimising `Σᵢⱼ (wᵢⱼ (F(p) − [A_d B_d])ᵢⱼ)²` with `F(p) = c2d(linearisation(p), Ts)`
//! computed exactly by [`c2d`] and its Jacobian by central differences.
//! The weights `w` default to the inverse magnitude of each entry of `[A_d − I, B_d]` (relative
//! errors, floored at 10⁻³ of the largest entry); [`paper_weights`] weights each entry by half
//! its last printed digit in the paper, which makes "residual ≤ 1" mean "rounds to the printed
//! value".
//!
//! A target that no physical pendulum can produce (for example arm damping smaller than the
//! back-EMF damping of the fixed motor constants) drives a parameter towards zero; the report's
//! residual then says how far the best fit is from the target.

use nalgebra::{DMatrix, DVector};

use crate::error::{Result, RipError};
use crate::linalg::{c2d, check_finite, check_shape, Mat};
use crate::plant::{FurutaParams, Param, Plant};

/// The parameters the fit solves for, in the order of its unknowns; all others are taken from
/// the base set. Their names are [`Param::name`].
pub const FREE_PARAMETERS: [Param; 6] = [
    Param::Lr,
    Param::Lp,
    Param::Jr,
    Param::Jp,
    Param::Dr,
    Param::Dp,
];

/// Largest accepted [`FitOptions::max_iterations`]: the fit converges in tens of iterations
/// when it converges at all, and each iteration costs up to 42 discretisations.
pub const MAX_FIT_ITERATIONS: usize = 1000;

/// Settings of [`fit_params`].
#[derive(Debug, Clone)]
pub struct FitOptions {
    /// Supplies the fixed parameters (`rm`, `kt`, `km`, `mr`, `mp`, `g`) and the initial guess of
    /// the free ones.
    pub base: FurutaParams,
    /// Weight of each entry of `[A_d B_d]` (4×5); `None` for relative weights (module docs).
    pub weights: Option<Mat>,
    /// Iteration limit of Levenberg–Marquardt, `1 ..=` [`MAX_FIT_ITERATIONS`].
    pub max_iterations: usize,
    /// Stop when the relative decrease of the cost and the relative step both fall below this.
    pub tolerance: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            base: FurutaParams::qube_servo2(),
            weights: None,
            max_iterations: 200,
            tolerance: 1e-12,
        }
    }
}

/// The outcome of [`fit_params`].
#[derive(Debug, Clone)]
pub struct FitReport {
    /// The fitted parameters.
    pub params: FurutaParams,
    /// `A_d` of the fitted plant.
    pub ad: Mat,
    /// `B_d` of the fitted plant.
    pub bd: Mat,
    /// Largest weighted residual `max |wᵢⱼ (F(p) − target)ᵢⱼ|`.
    pub max_weighted_residual: f64,
    /// Largest unweighted residual `max |(F(p) − target)ᵢⱼ|`.
    pub max_abs_residual: f64,
    /// Root-mean-square weighted residual.
    pub rms_weighted_residual: f64,
    /// Levenberg–Marquardt iterations used.
    pub iterations: usize,
    /// Whether the tolerance was met before the iteration limit: an accepted step with relative
    /// decrease and relative step below it, a weighted cost `Σ r²` below it, or a stationary
    /// point (no damping decreases the cost and `‖Jᵀr‖ ≤ √tol ‖J‖ ‖r‖`). `false` when the fit
    /// stalled anywhere else or ran out of iterations. It says the optimiser stopped on its
    /// tolerance, not that the target was reproduced: a target no pendulum can produce
    /// converges to the nearest model, and the residuals tell how near that is.
    pub converged: bool,
}

/// Weights that measure each entry of `[A_d B_d]` in units of half the last digit printed in
/// the paper's eq. (3) (row 2 of `A_d` has three decimals, `A_d[1][3]` five, `A_d[3][3]` three,
/// the rest four).
pub fn paper_weights() -> Mat {
    let mut w = Mat::from_element(4, 5, 1.0 / 0.5e-4);
    w[(1, 3)] = 1.0 / 0.5e-5;
    for j in 0..4 {
        w[(2, j)] = 1.0 / 0.5e-3;
    }
    w[(3, 3)] = 1.0 / 0.5e-3;
    w
}

fn with_free(base: &FurutaParams, logp: &DVector<f64>) -> FurutaParams {
    let mut p = *base;
    for (param, v) in FREE_PARAMETERS.iter().zip(logp.iter()) {
        *param.field(&mut p) = v.exp();
    }
    p
}

/// Weighted residual vector (20 entries, row-major over `[A_d B_d]`); `None` when the
/// parameters do not give a finite model.
fn residual(
    base: &FurutaParams,
    logp: &DVector<f64>,
    target: &Mat,
    w: &Mat,
    ts: f64,
) -> Option<(DVector<f64>, Mat, Mat)> {
    let params = with_free(base, logp);
    let plant = Plant::new(params).ok()?;
    let (ac, bc) = plant.linearize_upright();
    let (ad, bd) = c2d(&ac, &bc, ts).ok()?;
    let mut r = DVector::zeros(20);
    for i in 0..4 {
        for j in 0..5 {
            let model = if j < 4 { ad[(i, j)] } else { bd[(i, 0)] };
            r[i * 5 + j] = w[(i, j)] * (model - target[(i, j)]);
        }
    }
    r.iter().all(|v| v.is_finite()).then_some((r, ad, bd))
}

/// Checks the options other than the parameters' own (`base.validate`).
fn check_options(options: &FitOptions) -> Result<()> {
    options.base.validate()?;
    if options.max_iterations == 0 || options.max_iterations > MAX_FIT_ITERATIONS {
        return Err(RipError::invalid(
            "max_iterations",
            format!(
                "must be between 1 and {MAX_FIT_ITERATIONS}, got {}",
                options.max_iterations
            ),
        ));
    }
    if !(options.tolerance.is_finite() && options.tolerance > 0.0) {
        return Err(RipError::invalid(
            "tolerance",
            "must be positive and finite",
        ));
    }
    Ok(())
}

/// The residual weights: the given ones, checked, or by default each entry's
/// `1 / max(|target − [I 0]|, 1e-3 · max |target − [I 0]|)`.
fn fit_weights(weights: Option<&Mat>, target: &Mat) -> Result<Mat> {
    Ok(match weights {
        Some(w) => {
            check_shape("weights", w, 4, 5)?;
            check_finite("weights", w)?;
            if w.iter().any(|&v| v < 0.0) || w.iter().all(|&v| v == 0.0) {
                return Err(RipError::invalid(
                    "weights",
                    "must be non-negative and not all zero",
                ));
            }
            w.clone()
        }
        None => {
            let dev = Mat::from_fn(4, 5, |i, j| {
                (target[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs()
            });
            let floor = 1e-3 * dev.max();
            if floor == 0.0 {
                return Err(RipError::invalid("Ad", "is the identity and Bd is zero"));
            }
            dev.map(|d| 1.0 / d.max(floor))
        }
    })
}

/// Fits the free physical parameters to a discrete linear model (module docs).
///
/// `ad` is 4×4 and `bd` 4×1 in the state order `[θ, θ̇, α, α̇]` with α = 0 upright; `ts` is
/// their sample time.
pub fn fit_params(ad: &Mat, bd: &Mat, ts: f64, options: &FitOptions) -> Result<FitReport> {
    check_shape("Ad", ad, 4, 4)?;
    check_shape("Bd", bd, 4, 1)?;
    check_finite("Ad", ad)?;
    check_finite("Bd", bd)?;
    crate::linalg::check_sample_time("Ts", ts)?;
    check_options(options)?;
    let mut target = Mat::zeros(4, 5);
    target.view_mut((0, 0), (4, 4)).copy_from(ad);
    target.view_mut((0, 4), (4, 1)).copy_from(bd);
    let w = fit_weights(options.weights.as_ref(), &target)?;

    let b = &options.base;
    // Friction may be zero in the base set; the log parameterisation needs a positive start.
    // The logarithm needs a positive start: a frictionless base starts from a small damping.
    let start = FREE_PARAMETERS.map(|p| match p {
        Param::Dr => b.get(p).max(1e-6),
        Param::Dp => b.get(p).max(1e-7),
        _ => b.get(p),
    });
    let mut logp = DVector::from_iterator(FREE_PARAMETERS.len(), start.iter().map(|v| v.ln()));
    let (mut r, mut fit_ad, mut fit_bd) = residual(b, &logp, &target, &w, ts).ok_or_else(|| {
        RipError::invalid(
            "base",
            "gives a non-finite linear model at the initial guess",
        )
    })?;
    let mut cost = r.norm_squared();
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut converged = false;
    let h = 1e-6;
    while iterations < options.max_iterations {
        iterations += 1;
        let mut jac = DMatrix::zeros(20, 6);
        for k in 0..6 {
            let (mut lp, mut lm) = (logp.clone(), logp.clone());
            lp[k] += h;
            lm[k] -= h;
            let (Some((rp, _, _)), Some((rm, _, _))) = (
                residual(b, &lp, &target, &w, ts),
                residual(b, &lm, &target, &w, ts),
            ) else {
                return Err(RipError::invalid(
                    "Ad",
                    "the fit left the region of finite models",
                ));
            };
            jac.set_column(k, &((rp - rm) / (2.0 * h)));
        }
        let jtj = jac.transpose() * &jac;
        let grad = jac.transpose() * &r;
        let mut improved = false;
        for _ in 0..30 {
            let mut lhs = jtj.clone();
            for k in 0..6 {
                lhs[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let Some(step) = lhs.cholesky().map(|c| c.solve(&(-&grad))) else {
                lambda *= 10.0;
                continue;
            };
            let trial = &logp + &step;
            match residual(b, &trial, &target, &w, ts) {
                Some((rt, ad_t, bd_t)) if rt.norm_squared() < cost => {
                    let new_cost = rt.norm_squared();
                    let small_decrease = cost - new_cost <= options.tolerance * cost;
                    let small_step = step.norm() <= options.tolerance.sqrt() * (1.0 + logp.norm());
                    logp = trial;
                    r = rt;
                    fit_ad = ad_t;
                    fit_bd = bd_t;
                    cost = new_cost;
                    lambda = (lambda / 3.0).max(1e-12);
                    improved = true;
                    if small_decrease && small_step {
                        converged = true;
                    }
                    break;
                }
                _ => lambda *= 4.0,
            }
        }
        if cost == 0.0 {
            converged = true;
        }
        if !improved {
            // No damping gives a decrease. That is convergence only at an exact fit (cost below
            // the tolerance) or at a stationary point, where the residual is orthogonal to the
            // Jacobian's range to the tolerance (MINPACK's gradient test,
            // cos∠(r, range J) ≤ √tol); anywhere else the fit has stalled.
            let scale = jac.norm() * r.norm();
            converged = cost <= options.tolerance
                || (scale > 0.0 && grad.norm() <= options.tolerance.sqrt() * scale);
            break;
        }
        if converged {
            break;
        }
    }
    let params = with_free(b, &logp);
    let abs = Mat::from_fn(4, 5, |i, j| {
        let model = if j < 4 {
            fit_ad[(i, j)]
        } else {
            fit_bd[(i, 0)]
        };
        (model - target[(i, j)]).abs()
    });
    Ok(FitReport {
        params,
        ad: fit_ad,
        bd: fit_bd,
        max_weighted_residual: r.amax(),
        max_abs_residual: abs.max(),
        rms_weighted_residual: (cost / 20.0).sqrt(),
        iterations,
        converged,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper;

    #[test]
    fn recovers_the_parameters_of_a_physical_model() {
        let truth = FurutaParams {
            lr: 0.11,
            lp: 0.2,
            jr: 1.2e-4,
            jp: 9e-5,
            dr: 8e-4,
            dp: 2e-4,
            ..FurutaParams::qube_servo2()
        };
        let (ad, bd) = Plant::new(truth)
            .unwrap()
            .linearize_discrete(&Default::default(), 0.0, 0.01)
            .unwrap();
        let report = fit_params(&ad, &bd, 0.01, &FitOptions::default()).unwrap();
        let (got, want) = (report.params.to_array(), truth.to_array());
        for k in 0..12 {
            assert!(
                (got[k] - want[k]).abs() <= 1e-6 * want[k].abs(),
                "{}: {} vs {}",
                crate::plant::Param::FIELDS[k],
                got[k],
                want[k]
            );
        }
    }

    #[test]
    fn paper_preset_is_the_fit_of_the_paper_model() {
        let m = paper::discrete_model();
        let options = FitOptions {
            weights: Some(paper_weights()),
            ..Default::default()
        };
        let report = fit_params(&m.a, &m.b, paper::TS, &options).unwrap();
        assert!(report.max_weighted_residual < 0.1, "{report:?}");
        let (got, want) = (report.params.to_array(), FurutaParams::paper().to_array());
        for k in 0..12 {
            assert!(
                (got[k] - want[k]).abs() <= 1e-6 * want[k].abs(),
                "{}: fitted {:.10e}, preset {:.10e}",
                crate::plant::Param::FIELDS[k],
                got[k],
                want[k]
            );
        }
    }

    #[test]
    fn bad_input_is_rejected_with_the_argument_name() {
        let m = paper::discrete_model();
        let err = fit_params(&m.b, &m.b, 0.01, &FitOptions::default()).unwrap_err();
        assert!(err.to_string().contains("Ad"));
        let err = fit_params(&m.a, &m.b, -1.0, &FitOptions::default()).unwrap_err();
        assert!(err.to_string().contains("Ts"));
        let bad = FitOptions {
            weights: Some(Mat::zeros(4, 5)),
            ..Default::default()
        };
        assert!(fit_params(&m.a, &m.b, 0.01, &bad)
            .unwrap_err()
            .to_string()
            .contains("weights"));
    }
}
