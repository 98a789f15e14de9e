//! Uncertainty and identifiability at the optimum, and the fits (module docs of [`super`],
//! "Uncertainty and identifiability" and "Held-out fit").

use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::{DMatrix, SMatrix, SVector, SymmetricEigen};

use super::params::held_sensitivity;
use super::problem::{fit_initial_state, fit_percent, rms_deviation, Problem, Segment};
use super::solve::Bounds;
use super::{Held, FREE, MIN_HELDOUT_MOTION, NOT_IDENTIFIABLE_RSE, NP};
use crate::error::{Result, RipError};
use crate::plant::{FurutaParams, Param, Plant};

/// What the information matrix says about the estimates.
pub(super) struct Uncertainty {
    /// Standard error of each free parameter (of its optimisation value).
    pub(super) std_errors: [f64; NP],
    /// Relative standard errors.
    pub(super) rse: [f64; NP],
    /// Covariance of `log p`, row-major `NP × NP`.
    pub(super) covariance: Vec<f64>,
    /// Names not identifiable.
    pub(super) not_identifiable: Vec<&'static str>,
    /// Names on a bound.
    pub(super) at_bounds: Vec<&'static str>,
    /// Condition number of `F` over the interior parameters.
    pub(super) condition_number: f64,
    /// Numerical rank of `F`.
    pub(super) rank: usize,
}

/// Lags of the residuals' serial correlation in the covariance's middle factor (0.25 s at
/// 100 Hz: a few pendulum-period fractions; quantisation error of a slowly moving angle is
/// correlated over about as long).
const NOISE_LAGS: usize = 25;

/// The information about `log p` with the initial states eliminated, `F = Σₛ J̃ₛᵀ J̃ₛ` with
/// `J̃ₛ = (I − Jₓ (JₓᵀJₓ)⁻¹ Jₓᵀ) Jₚ` (the Schur complement of the initial states in `JᵀJ`),
/// and the middle factor `S` of the sandwich covariance `F⁻¹ S F⁻¹`: the Newey–West
/// (Bartlett-weighted, [`NOISE_LAGS`] lags) long-run covariance of the per-sample scores
/// `gₖ = Σⱼ J̃ₖⱼᵀ rₖⱼ` within each segment. Unlike `σ̂² F⁻¹` it assumes neither equal noise
/// on the two outputs nor white residuals (quantisation makes them neither).
fn information_and_meat(segments: &[Segment]) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut info = DMatrix::<f64>::zeros(NP, NP);
    let mut meat = DMatrix::<f64>::zeros(NP, NP);
    for s in segments {
        let rows = 2 * s.n;
        let jp = DMatrix::from_column_slice(rows, NP, &s.jac[..rows * NP]);
        let jx = DMatrix::from_column_slice(rows, 4, &s.jac[rows * NP..rows * (NP + 4)]);
        let jt = match jx.tr_mul(&jx).cholesky() {
            Some(ch) => &jp - &jx * ch.solve(&jx.tr_mul(&jp)),
            None => jp,
        };
        info += jt.tr_mul(&jt);
        let scores: Vec<SVector<f64, NP>> = (0..s.n)
            .map(|k| {
                SVector::from_fn(|c, _| {
                    (0..2)
                        .map(|j| jt[(2 * k + j, c)] * s.r[2 * k + j])
                        .sum::<f64>()
                })
            })
            .collect();
        for l in 0..=NOISE_LAGS.min(s.n - 1) {
            let w = 1.0 - l as f64 / (NOISE_LAGS as f64 + 1.0);
            let mut m = SMatrix::<f64, NP, NP>::zeros();
            for k in 0..s.n - l {
                m += scores[k] * scores[k + l].transpose();
            }
            let m = if l == 0 { m } else { (m + m.transpose()) * w };
            for a in 0..NP {
                for b in 0..NP {
                    meat[(a, b)] += m[(a, b)];
                }
            }
        }
    }
    (info, meat)
}

/// Standard errors, covariance, rank and condition at `logp` (module docs).
pub(super) fn uncertainty(segments: &[Segment], logp: &[f64; NP], bounds: &Bounds) -> Uncertainty {
    let (info, meat) = information_and_meat(segments);
    let n_res: usize = segments.iter().map(|s| 2 * s.n).sum();
    let n_unknowns = NP + 4 * segments.len();
    // The small-sample correction of the sandwich (as `σ̂²`'s `N − n`).
    let dof = n_res as f64 / n_res.saturating_sub(n_unknowns).max(1) as f64;
    let at_bound: [bool; NP] = std::array::from_fn(|k| bounds.on_bound(logp, k));
    // Parameters on a bound are held there (a friction or dead zone of zero carries no
    // information): rank, condition and covariance are those of the others.
    let interior: Vec<usize> = (0..NP)
        .filter(|&k| !at_bound[k] && !bounds.held[k])
        .collect();
    let ni = interior.len();
    let sub = DMatrix::from_fn(ni, ni, |a, b| info[(interior[a], interior[b])]);
    let eig = SymmetricEigen::new(sub);
    let lmax = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let tiny = 1e-12 * lmax;
    let rank = eig.eigenvalues.iter().filter(|&&l| l > tiny).count() + (NP - ni);
    let lmin = eig
        .eigenvalues
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let condition_number = if ni == 0 {
        1.0
    } else if lmin > tiny {
        (lmax / lmin).sqrt()
    } else {
        f64::INFINITY
    };
    // Pseudo-inverse on the identifiable directions; null directions give infinite errors.
    let mut pinv = DMatrix::<f64>::zeros(NP, NP);
    let mut null_weight = [0.0; NP];
    for (i, &l) in eig.eigenvalues.iter().enumerate() {
        let v = eig.eigenvectors.column(i);
        if l > tiny {
            for a in 0..ni {
                for b in 0..ni {
                    pinv[(interior[a], interior[b])] += v[a] * v[b] / l;
                }
            }
        } else {
            for a in 0..ni {
                null_weight[interior[a]] += v[a] * v[a];
            }
        }
    }
    let cov = &pinv * meat * &pinv * dof;
    let null = |k: usize| null_weight[k] > 0.25;
    let mut std_errors = [0.0; NP];
    let mut rse = [0.0; NP];
    let mut not_identifiable = Vec::new();
    let mut at_bounds = Vec::new();
    for k in 0..NP {
        rse[k] = if null(k) {
            f64::INFINITY
        } else {
            cov[(k, k)].max(0.0).sqrt()
        };
        std_errors[k] = rse[k] * logp[k].exp();
        if bounds.held[k] {
            continue;
        }
        if at_bound[k] {
            at_bounds.push(FREE[k].name());
        } else if rse[k].is_nan() || rse[k] > NOT_IDENTIFIABLE_RSE {
            not_identifiable.push(FREE[k].name());
        }
    }
    let covariance = (0..NP * NP)
        .map(|i| {
            let (a, b) = (i / NP, i % NP);
            if null(a) || null(b) {
                f64::INFINITY
            } else {
                cov[(a, b)]
            }
        })
        .collect();
    Uncertainty {
        std_errors,
        rse,
        covariance,
        not_identifiable,
        at_bounds,
        condition_number,
        rank,
    }
}

/// The standard errors of `u` with the priors of the `held` values added (module docs):
/// `se(pₖ)² = pₖ² (Cov(log p)ₖₖ + Σₕ (priorₕ sₕ,ₖ)²)`, the priors independent. An infinite
/// error (a parameter the logs do not determine) stays infinite.
pub(super) fn with_priors(
    u: &Uncertainty,
    p: &FurutaParams,
    held: &[Held],
    tie_km: bool,
) -> [f64; NP] {
    let sensitivities: Vec<([f64; NP], f64)> = held
        .iter()
        .filter_map(|h| Param::from_name(h.name).map(|param| (param, h.prior_rse)))
        .map(|(param, prior)| (held_sensitivity(p, param, tie_km), prior))
        .collect();
    std::array::from_fn(|k| {
        let rse = u.rse[k];
        if !rse.is_finite() {
            return u.std_errors[k];
        }
        let prior: f64 = sensitivities.iter().map(|(s, r)| (r * s[k]).powi(2)).sum();
        let value = if rse > 0.0 {
            u.std_errors[k] / rse
        } else {
            super::params::get(p, k)
        };
        value * (rse * rse + prior).sqrt()
    })
}

/// The fit over each log's training segments (each from its estimated initial state).
pub(super) fn training_fit(problem: &Problem<'_>, segments: &[Segment]) -> Vec<[f64; 2]> {
    (0..problem.logs.len())
        .map(|l| {
            let log = &problem.logs[l];
            let mut r = Vec::new();
            let mut y = Vec::new();
            for s in segments.iter().filter(|s| s.log == l) {
                r.extend_from_slice(&s.r);
                y.extend_from_slice(&log.y[s.k0..s.k0 + s.n]);
            }
            fit_percent(&r, &y, problem.w)
        })
        .collect()
}

/// A figure per log and output `[θ, α]`.
type PerLog = Vec<[f64; 2]>;

/// Held-out fit (NaN where not measurable) and motion of each log (module docs).
pub(super) fn held_out(
    problem: &Problem<'_>,
    plant: &(Plant, usize),
    holdout: f64,
    seg_len: usize,
    cancel: &AtomicBool,
) -> Result<(PerLog, PerLog)> {
    let mut fit = Vec::with_capacity(problem.logs.len());
    let mut motion = Vec::with_capacity(problem.logs.len());
    for (l, log) in problem.logs.iter().enumerate() {
        let train = ((1.0 - holdout) * log.u.len() as f64).floor() as usize;
        let n = log.u.len() - train;
        let m = rms_deviation(&log.y[train..]);
        motion.push(m);
        if n < 20 {
            fit.push([f64::NAN; 2]);
            continue;
        }
        if cancel.load(Ordering::Relaxed) {
            return Err(RipError::Cancelled);
        }
        // In windows of the segment length, each from its own estimated initial state: a
        // pendulum that swings over the top is chaotic, and one simulation of the whole
        // held-out part would score the chaos, not the model.
        let mut r = Vec::with_capacity(2 * n);
        let mut k0 = train;
        while k0 < log.u.len() {
            let len = if log.u.len() - k0 < 2 * seg_len {
                log.u.len() - k0
            } else {
                seg_len
            };
            r.extend(fit_initial_state(problem, plant, l, k0, len));
            k0 += len;
        }
        let f = fit_percent(&r, &log.y[train..], problem.w);
        fit.push(std::array::from_fn(|j| {
            if m[j] >= MIN_HELDOUT_MOTION {
                f[j]
            } else {
                f64::NAN
            }
        }));
    }
    Ok((fit, motion))
}

/// The entries of the continuous upright `[A B]` that are not structural zeros (rows of the
/// two rates, columns `θ̇, α, α̇, u`: `F` does not depend on `θ`), named for messages.
pub const LINEAR_ENTRIES: [&str; 8] = [
    "A[1][1]", "A[1][2]", "A[1][3]", "B[1]", "A[3][1]", "A[3][2]", "A[3][3]", "B[3]",
];

/// The entries of [`LINEAR_ENTRIES`] and the unstable eigenvalue of `p`'s upright
/// linearisation; `None` for a set that is not a plant.
pub(super) fn linear_values(p: &FurutaParams) -> Option<[f64; 9]> {
    let (a, b) = Plant::new(*p).ok()?.linearize_upright();
    let unstable = crate::linalg::eigenvalues(&a)
        .iter()
        .map(|c| c.re)
        .fold(f64::NEG_INFINITY, f64::max);
    Some([
        a[(1, 1)],
        a[(1, 2)],
        a[(1, 3)],
        b[(1, 0)],
        a[(3, 1)],
        a[(3, 2)],
        a[(3, 3)],
        b[(3, 0)],
        unstable,
    ])
}

/// Relative standard errors of the entries of [`LINEAR_ENTRIES`] and of the unstable
/// eigenvalue, by the delta method: `var(f) = ∇fᵀ Σ ∇f` with `Σ` the covariance of `log p`
/// and `∇f` by central differences in `log p` (infinite when a direction is not identifiable).
pub(super) fn linear_rse(
    params_of: &dyn Fn(&[f64; NP]) -> FurutaParams,
    logp: &[f64; NP],
    covariance: &[f64],
) -> [f64; 9] {
    let h = 1e-4;
    let Some(at) = linear_values(&params_of(logp)) else {
        return [f64::INFINITY; 9];
    };
    let mut grad = [[0.0; NP]; 9];
    for k in 0..NP {
        let (mut up, mut down) = (*logp, *logp);
        up[k] += h;
        down[k] -= h;
        let (Some(fu), Some(fd)) = (
            linear_values(&params_of(&up)),
            linear_values(&params_of(&down)),
        ) else {
            return [f64::INFINITY; 9];
        };
        for e in 0..9 {
            grad[e][k] = (fu[e] - fd[e]) / (2.0 * h);
        }
    }
    std::array::from_fn(|e| {
        let mut var = 0.0;
        for a in 0..NP {
            for b in 0..NP {
                let (ga, gb) = (grad[e][a], grad[e][b]);
                if ga != 0.0 && gb != 0.0 {
                    var += ga * gb * covariance[a * NP + b];
                }
            }
        }
        var.max(0.0).sqrt() / at[e].abs()
    })
}

/// The covariance of the estimated plant parameters themselves ([`FREE`], SI units, row-major
/// `NP × NP`) from that of `log` of the optimisation values, to first order: `G Σ Gᵀ` with `G`
/// the derivative of `(lr, jr, jp, …)` by `log (lr, J₀, Jα, …)` at `p` (`jr = J₀ − mr lr²/4 −
/// mp lr²`, `jp = Jα − mp lp²/4`; `mr`, `mp`, `lp` fixed). Rows and columns that depend on a
/// parameter in a null direction are infinite.
pub(super) fn plant_covariance(p: &FurutaParams, values: &[f64; NP], log_cov: &[f64]) -> Vec<f64> {
    let mut g = [[0.0; NP]; NP];
    for (k, row) in g.iter_mut().enumerate() {
        row[k] = values[k];
    }
    // jr = J₀ − (mr/4 + mp) lr²: d jr / d log lr = −(mr/2 + 2 mp) lr · lr.
    g[1][0] = -(p.mr / 2.0 + 2.0 * p.mp) * p.lr * values[0];
    let mut out = vec![0.0; NP * NP];
    for a in 0..NP {
        for b in 0..NP {
            let mut v = 0.0;
            for i in (0..NP).filter(|&i| g[a][i] != 0.0) {
                for j in (0..NP).filter(|&j| g[b][j] != 0.0) {
                    v += g[a][i] * g[b][j] * log_cov[i * NP + j];
                }
            }
            out[a * NP + b] = v;
        }
    }
    out
}
