//! Grey-box identification of the nonlinear Furuta model from open-loop logs by output-error
//! (simulation-error) minimisation.
//!
//! # Model and parameters
//!
//! The model is [`crate::plant`]'s: rigid bodies, motor, viscous and Coulomb friction and the
//! voltage dead zone. As [`crate::fit`] explains for the linearisation, the equations of motion
//! depend on the rigid-body and motor parameters only through the lumped quantities
//! `J₀, Jα, m₁₂, G, b = kt/rm, c = dr + kt km/rm, dp` (and `cr, cp`, which scale with them),
//! and only up to a common factor; the nonlinear terms add no further combination. So the
//! scale must be fixed by known values. Here the pendulum is weighed and measured: `mp`, `lp`
//! (and `g`) of the start set fix `G = mp g lp/2`, and `mr`, `rm`, `km` are held at the start
//! set too. The nine [`FREE`] parameters then map one to one onto the nine identifiable
//! quantities:
//!
//! ```text
//! lr ↔ m₁₂ = mp lr lp/2      jr ↔ J₀ = jr + mr lr²/4 + mp lr²     jp ↔ Jα = jp + mp lp²/4
//! kt ↔ b = kt/rm             dr ↔ c = dr + kt km/rm               dp, cr, cp, vd  themselves
//! ```
//!
//! `kt` is the motor constant the logs determine (the torque per volt `kt/rm`, with `rm` from
//! the start set); back-EMF and the arm's viscous friction are one coefficient `c`, so `km`
//! stays at the start set's value and `dr` takes the rest. The optimisation works on `J₀` and
//! `Jα` themselves; when the start's `mp`, `lp` leave no room for a positive `jp` the pendulum
//! is taken as a uniform rod of the same `mp lp` (so `mp` and `lp` change, `G` does not), and
//! when its `mr` leaves no room for a positive `jr` the arm is taken as a uniform rod and `mr`
//! changes (the dynamics depend on `J₀` and `Jα` alone). If a start value is
//! inconsistent with the rig in another way (for example `km` larger than the whole of `c`
//! allows), the parameter that takes the difference runs into its lower bound and the result
//! lists it in [`IdentifyResult::at_bounds`].
//!
//! # Criterion
//!
//! The training part of each log (all but its last `holdout` fraction) is cut into segments of
//! about [`IdentifyOptions::segment`] seconds (after a first stage with segments of
//! [`SHORT_SEGMENT`], whose criterion has fewer local minima: a continuation that reaches the
//! right basin from starts that the long segments alone do not). Each segment is simulated from its own initial
//! state `x₀,ₛ` (estimated with the parameters; its angles start at the measured ones and its
//! rates at central differences of them) under the logged, zero-order-held voltage, and the
//! residuals are the simulated minus the measured angles, each output divided by its standard
//! deviation over the logs:
//!
//! ```text
//! min over p, x₀,₁ … x₀,S   Σₛ Σₖ Σⱼ ((ŷⱼ(k; p, x₀,ₛ) − yⱼ(k)) / σⱼ)²
//! ```
//!
//! (multiple shooting without continuity constraints: short segments keep the lightly damped
//! pendulum's simulation error from piling up over a long log, and free initial states keep
//! noisy rate estimates from biasing the parameters).
//!
//! # Method
//!
//! Levenberg–Marquardt on `log p` (positivity), projected onto bounds `[10⁻⁴ p₀, 10³ p₀]`
//! (`10⁻² p₀` below for the rigid-body and motor terms), capped above by physical ceilings
//! (Coulomb friction at most 0.1 N m on the arm, dead zone at most 5 V, ...); the friction and
//! dead-zone terms, which may be zero, start at small positive values. A step to a point whose
//! neighbours cannot be simulated is refused like one that raises the cost. The
//! Jacobian is by forward differences, one simulation per parameter and segment; segments run
//! in parallel (rayon) with per-segment buffers allocated once, and a segment's initial state
//! perturbs only its own simulation, so one Jacobian costs `(9 + 4 + 1)` segment simulations
//! per segment. The damped normal equations are solved densely (the initial states add four
//! unknowns per segment).
//!
//! # Uncertainty and identifiability
//!
//! At the optimum, with `σ̂² = Σ r² / (N − n_p)` and `F` the Schur complement of the initial
//! states in `JᵀJ` (the information about `log p` alone), the standard errors are
//! `se(log pₖ) = σ̂ √(F⁻¹)ₖₖ` and `se(pₖ) = pₖ se(log pₖ)` (residuals of an output-error fit are
//! coloured: `σ̂²` is multiplied by their long-run variance factor
//! `1 + 2 Σ_{l=1}^{20} (1 − l/21) ρ_l`, `ρ_l` their autocorrelation at lag `l`, so that the
//! intervals cover the truth as often as they claim). The condition number and rank of `F`
//! (eigenvalues below `10⁻¹²` of the largest count as zero) measure identifiability, over the
//! parameters not on a bound (those are held there: a friction or dead zone of zero carries no
//! information, and their covariance is zero); a
//! parameter whose relative standard error exceeds [`NOT_IDENTIFIABLE_RSE`], or that dominates
//! a null direction of `F`, is named as not identifiable from the given logs.
//!
//! # Held-out fit
//!
//! The last `holdout` fraction of each log is simulated in windows of the segment length,
//! each from an initial state estimated on it (as MATLAB's `compare` estimates initial
//! conditions; windows, because a pendulum that swings over the top is chaotic and one long
//! simulation would score the chaos rather than the model), and each output's fit
//! is MATLAB's normalised RMSE fit `100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖)` %. An output whose
//! held-out part moves less than [`MIN_HELDOUT_MOTION`] (root-mean-square deviation) is not
//! scored: its fit is NaN, "not measurable", since `‖y − mean(y)‖` is then noise.
//!
//! # Verdict
//!
//! A converged fit is not a trusted one. [`IdentifyResult::problems`] lists every reason not
//! to trust it, each naming the log, the parameter and the measurement or excitation that
//! would fix it; callers must refuse to use a result with problems (`riprs identify` exits
//! non-zero and writes no rig file). The checks:
//!
//! - the held-out fit of every scored output is at least [`MIN_FIT_PERCENT`];
//! - `F` has full rank and a condition number of at most [`MAX_CONDITION`];
//! - every parameter of the upright linearisation ([`LINEAR`]) has a relative standard error
//!   of at most [`MAX_RSE`];
//! - no parameter ends on its upper bound, and none of `lr, jr, jp, kt, dr` on its lower bound
//!   (the friction and dead-zone terms may be zero);
//! - `mr`, `mp`, `lp` changed by at most a factor [`MAX_FIXED_CHANGE`] (a uniform-rod split
//!   beyond that means the fixed values are not the rig's);
//! - the dead zone is at most [`MAX_DEAD_ZONE_FRACTION`] of the logs' 95th percentile of `|u|`.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use rayon::prelude::*;

use crate::error::{Result, RipError};
use crate::linalg::Mat;
use crate::plant::{FurutaParams, Plant, State};

#[cfg(test)]
mod tests;

/// The parameters the fit estimates, as named in [`crate::plant::FurutaParams`]' fields. `mr`, `mp` and
/// `lp` change too when the start's values leave no room for positive `jr`, `jp` (module docs).
pub const FREE: [&str; 9] = ["lr", "jr", "jp", "kt", "dr", "dp", "cr", "cp", "vd"];
const NP: usize = FREE.len();

/// Relative standard error above which a parameter counts as not identifiable.
pub const NOT_IDENTIFIABLE_RSE: f64 = 0.5;

/// Segment length (s) of the first, continuation stage (module docs).
pub const SHORT_SEGMENT: f64 = 0.5;

/// Largest accepted [`IdentifyOptions::max_iterations`].
pub const MAX_ITERATIONS: usize = 500;

/// Largest number of samples over all logs (a few hours at 100 Hz): bounds the work of one call.
pub const MAX_SAMPLES: usize = 2_000_000;

/// Fewest training samples per log: two segments' worth of a hundred samples.
pub const MIN_SAMPLES: usize = 200;

/// Least root-mean-square deviation (rad) of an output over a log's held-out part for its fit
/// to be scored: a held-out part with less motion (a pendulum at rest, a few encoder counts of
/// noise) has no excitation to compare with, and its fit is "not measurable" (NaN), not the
/// ratio of two noise levels. Ten times the envelope's worst noise (2 mrad) and above the
/// coarsest encoder's quantum (2π/512 ≈ 12 mrad).
pub const MIN_HELDOUT_MOTION: f64 = 0.02;

/// Least held-out fit (%) of every scored output for the result to be trusted. Fits of rigs of
/// the envelope identified from a chirp and a PRBS run measure above 90 %; the wrong models of
/// a start far from the rig measure below 45 %.
pub const MIN_FIT_PERCENT: f64 = 70.0;

/// Largest condition number of the information matrix for the result to be trusted: the
/// identified rigs of the envelope measure at most about 1e4.
pub const MAX_CONDITION: f64 = 1e6;

/// Largest relative standard error of a parameter that enters the upright linearisation
/// ([`LINEAR`]) for the result to be trusted.
pub const MAX_RSE: f64 = 0.2;

/// The free parameters that enter the upright linearisation: each must be determined.
pub const LINEAR: [&str; 6] = ["lr", "jr", "jp", "kt", "dr", "dp"];

/// Largest identified dead zone as a fraction of the logs' 95th percentile of `|u|`: a dead zone
/// that swallows most of the excitation is not one the logs can show.
pub const MAX_DEAD_ZONE_FRACTION: f64 = 0.6;

/// Largest factor by which `mr`, `mp` or `lp` may be changed from the fixed values (module
/// docs) before the start set is judged inconsistent with the rig.
pub const MAX_FIXED_CHANGE: f64 = 10.0;

/// One open-loop log sampled every `ts` seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct LogData {
    /// Sample time (s).
    pub ts: f64,
    /// Voltage (V) applied from sample `k` to `k + 1`.
    pub u: Vec<f64>,
    /// Measured `[θ, α]` (rad, α = 0 upright, continuous: not wrapped) at sample `k`.
    pub y: Vec<[f64; 2]>,
}

/// Settings of [`identify`].
#[derive(Debug, Clone, PartialEq)]
pub struct IdentifyOptions {
    /// Fixed parameters (`mp`, `lp`, `mr`, `rm`, `km`, `g`) and the initial guess of [`FREE`].
    pub start: FurutaParams,
    /// Segment length (s) of the multiple-shooting criterion.
    pub segment: f64,
    /// Fraction of each log, at its end, kept out of the fit for validation, in `[0, 0.9]`.
    pub holdout: f64,
    /// Iteration limit of each stage, `1 ..=` [`MAX_ITERATIONS`].
    pub max_iterations: usize,
    /// Least RK4 steps per sample (more are taken when the plant's stability limit needs them).
    pub substeps: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    pub tolerance: f64,
    /// A name for each log (a file name), used in [`IdentifyResult::problems`]; `logs[i]`
    /// where missing.
    pub names: Vec<String>,
    /// Names (of [`FREE`]) held at the start set's values: measured on the rig (a lab file's
    /// `Lr`), so not estimated; their standard error is zero.
    pub fixed: Vec<String>,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            start: FurutaParams::qube_servo2(),
            segment: 2.0,
            holdout: 0.25,
            max_iterations: 60,
            substeps: 4,
            tolerance: 1e-6,
            names: Vec::new(),
            fixed: Vec::new(),
        }
    }
}

/// What [`identify`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentifyResult {
    /// The identified parameters (the start set's fixed ones unchanged).
    pub params: FurutaParams,
    /// Standard error of each of [`FREE`] (same units; `inf` when not identifiable; for `jr`
    /// and `jp` those of the joint-axis inertias `J₀` and `Jα`, which the logs determine).
    pub std_errors: [f64; NP],
    /// Held-out fit (%) per log and output `[θ, α]`; NaN for a log without a held-out part
    /// and for an output that does not move over it (not measurable, [`MIN_HELDOUT_MOTION`]).
    pub fit_percent: Vec<[f64; 2]>,
    /// Root-mean-square deviation (rad) of each output over each log's held-out part.
    pub held_out_motion: Vec<[f64; 2]>,
    /// The same fit over each log's training segments (each from its estimated initial state).
    pub training_fit_percent: Vec<[f64; 2]>,
    /// Names (of [`FREE`]) not identifiable from these logs (module docs).
    pub not_identifiable: Vec<&'static str>,
    /// Names (of [`FREE`]) that ended on a bound.
    pub at_bounds: Vec<&'static str>,
    /// Condition number of the parameters' information matrix `F` (module docs).
    pub condition_number: f64,
    /// Numerical rank of `F` (of [`FREE`]'s count).
    pub rank: usize,
    /// Final cost `Σ r²` and root-mean-square normalised residual.
    pub cost: f64,
    /// `√(cost / N)`.
    pub rms_residual: f64,
    /// Levenberg–Marquardt iterations.
    pub iterations: usize,
    /// Whether the tolerance was met before the iteration limit.
    pub converged: bool,
    /// Segment simulations run (the held-out evaluations included).
    pub simulations: usize,
    /// Training segments.
    pub segments: usize,
    /// Upright linearisation discretised at the logs' sample time: `A_d` (4×4) and `B_d` (4×1).
    pub ad: Mat,
    /// See `ad`.
    pub bd: Mat,
    /// The optimisation values of [`FREE`] at the optimum: the parameters themselves, but the
    /// joint-axis inertias `J₀`, `Jα` in place of `jr`, `jp` (module docs).
    pub values: [f64; NP],
    /// Covariance of `log` of [`FREE`]'s optimisation values (`jr`, `jp`: of `J₀`, `Jα`),
    /// `σ̂² F⁺` (module docs), row-major `9 × 9`; rows and columns of parameters in a null
    /// direction are infinite.
    pub covariance: Vec<f64>,
    /// Why the result cannot be trusted, one sentence each naming the log, the parameter or
    /// the measurement that would fix it; empty when every check passes (module docs,
    /// "Verdict").
    pub problems: Vec<String>,
}

/// The arm's inertia about the motor axis, `J₀ = jr + mr lr²/4 + mp lr²`.
fn arm_inertia(p: &FurutaParams) -> f64 {
    p.jr + p.mr * p.lr * p.lr / 4.0 + p.mp * p.lr * p.lr
}

/// The pendulum's inertia about its joint, `Jα = jp + mp lp²/4`.
fn pendulum_inertia(p: &FurutaParams) -> f64 {
    p.jp + p.mp * p.lp * p.lp / 4.0
}

/// The values the optimisation works on: [`FREE`] with `jr` replaced by `J₀` and `jp` by `Jα`,
/// on which the dynamics depend (their split into centroidal inertia, mass and length does
/// not matter to them).
fn get(p: &FurutaParams, k: usize) -> f64 {
    [
        p.lr,
        arm_inertia(p),
        pendulum_inertia(p),
        p.kt,
        p.dr,
        p.dp,
        p.cr,
        p.cp,
        p.vd,
    ][k]
}

/// The start set with the optimisation's values in place.
///
/// `Jα` is split as `jp = Jα − mp lp²/4` with the start's `mp`, `lp` while that is positive;
/// otherwise the pendulum is taken as a uniform rod with the same `mp lp` (so `G` and `m₁₂`
/// keep their values): `lp = 3 Jα/(mp lp)`, `mp = (mp lp)/lp`, `jp = mp lp²/12`. Then `J₀` is
/// split as `jr = J₀ − mr lr²/4 − mp lr²` with the start's `mr` while that is positive;
/// otherwise the arm is taken as a uniform rod (`mr = 3 (J₀ − mp lr²)/lr²`, `jr = mr lr²/12`).
/// `J₀ ≤ mp lr²` gives an invalid set (no arm can have it), which [`Plant::new`] refuses.
fn with(mut p: FurutaParams, v: &[f64; NP]) -> FurutaParams {
    let [lr, j0, ja, kt, dr, dp, cr, cp, vd] = *v;
    [p.lr, p.kt, p.dr, p.dp, p.cr, p.cp, p.vd] = [lr, kt, dr, dp, cr, cp, vd];
    let jp = ja - p.mp * p.lp * p.lp / 4.0;
    if jp > 0.0 {
        p.jp = jp;
    } else {
        let product = p.mp * p.lp;
        p.lp = 3.0 * ja / product;
        p.mp = product / p.lp;
        p.jp = p.mp * p.lp * p.lp / 12.0;
    }
    let rest = j0 - p.mp * lr * lr;
    let jr = rest - p.mr * lr * lr / 4.0;
    if jr > 0.0 {
        p.jr = jr;
    } else if rest > 0.0 {
        p.mr = 3.0 * rest / (lr * lr);
        p.jr = p.mr * lr * lr / 12.0;
    } else {
        p.jr = -1.0;
    }
    p
}

/// Upper bounds of the optimisation values beyond any bench-top rig (ten times the envelope of
/// shared rigs and more): a fit that reaches one is inconsistent with the rig (the verdict says
/// so), and the stiff friction law of a huge Coulomb term would stall the simulation.
const CEILING: [f64; NP] = [1.0, 1.0, 1.0, 10.0, 0.1, 0.01, 0.1, 0.002, 5.0];

/// Initial values of the free parameters: the start set's, or small positive values for those
/// that may be zero and are.
fn initial(start: &FurutaParams) -> [f64; NP] {
    let floors = [0.0, 0.0, 0.0, 0.0, 1e-4, 1e-5, 1e-3, 1e-5, 0.1];
    std::array::from_fn(|k| get(start, k).max(floors[k]))
}

struct Segment {
    log: usize,
    k0: usize,
    n: usize,
    x0: State,
    r: Vec<f64>,
    trial: Vec<f64>,
    /// Column-major `2n × (NP + 4)`.
    jac: Vec<f64>,
}

struct Problem<'a> {
    logs: &'a [LogData],
    w: [f64; 2],
    substeps: usize,
    sims: AtomicUsize,
}

impl Problem<'_> {
    fn plant(&self, p: &FurutaParams) -> Option<(Plant, usize)> {
        let plant = Plant::new(*p).ok()?;
        let ts = self.logs[0].ts;
        let n = (ts / (0.9 * plant.max_rk4_substep())).ceil();
        (n.is_finite() && n <= 1e4).then(|| (plant, self.substeps.max(n as usize)))
    }

    /// Simulates samples `k0 .. k0 + n` of `log` from `x0`, writing the normalised residuals;
    /// false when the state left the finite numbers.
    fn simulate(
        &self,
        (plant, sub): &(Plant, usize),
        log: usize,
        k0: usize,
        x0: &State,
        out: &mut [f64],
    ) -> bool {
        self.sims.fetch_add(1, Ordering::Relaxed);
        let data = &self.logs[log];
        let n = out.len() / 2;
        let mut x = *x0;
        for i in 0..n {
            let y = data.y[k0 + i];
            out[2 * i] = self.w[0] * (x[0] - y[0]);
            out[2 * i + 1] = self.w[1] * (x[2] - y[1]);
            if i + 1 < n {
                plant.advance(&mut x, data.u[k0 + i], 0.0, data.ts, *sub);
            }
        }
        out.iter().all(|v| v.is_finite())
    }
}

fn check(logs: &[LogData], o: &IdentifyOptions) -> Result<()> {
    o.start.validate()?;
    if logs.is_empty() {
        return Err(RipError::invalid("logs", "at least one log is needed"));
    }
    let ts = logs[0].ts;
    let mut total = 0usize;
    for (i, log) in logs.iter().enumerate() {
        let name = format!("logs[{i}]");
        if !(log.ts.is_finite() && log.ts > 0.0) || (log.ts - ts).abs() > 1e-9 * ts {
            return Err(RipError::invalid(
                name,
                format!(
                    "sample time {} s differs from the first log's {ts} s",
                    log.ts
                ),
            ));
        }
        if log.u.len() != log.y.len() {
            return Err(RipError::invalid(
                name,
                format!("{} voltages but {} measurements", log.u.len(), log.y.len()),
            ));
        }
        if let Some(k) = (0..log.u.len())
            .find(|&k| !(log.u[k].is_finite() && log.y[k].iter().all(|v| v.is_finite())))
        {
            return Err(RipError::invalid(
                name,
                format!("sample {k} is not finite (NaN or infinite voltage or angle)"),
            ));
        }
        let train = ((1.0 - o.holdout) * log.u.len() as f64).floor() as usize;
        if train < MIN_SAMPLES {
            return Err(RipError::invalid(
                name,
                format!(
                    "too short: {} samples, {train} for the fit after the held-out part; at \
                     least {MIN_SAMPLES} are needed",
                    log.u.len()
                ),
            ));
        }
        total += log.u.len();
    }
    if total > MAX_SAMPLES {
        return Err(RipError::invalid(
            "logs",
            format!("{total} samples; at most {MAX_SAMPLES} per call"),
        ));
    }
    if !(o.segment.is_finite() && o.segment >= 20.0 * ts) {
        return Err(RipError::invalid(
            "segment",
            format!(
                "must be at least 20 samples ({} s), got {}",
                20.0 * ts,
                o.segment
            ),
        ));
    }
    if !(o.holdout.is_finite() && (0.0..=0.9).contains(&o.holdout)) {
        return Err(RipError::invalid(
            "holdout",
            format!("must be in [0, 0.9], got {}", o.holdout),
        ));
    }
    if o.max_iterations == 0 || o.max_iterations > MAX_ITERATIONS {
        return Err(RipError::invalid(
            "max_iterations",
            format!("must be in 1..={MAX_ITERATIONS}, got {}", o.max_iterations),
        ));
    }
    if let Some(name) = o.fixed.iter().find(|n| !FREE.contains(&n.as_str())) {
        return Err(RipError::invalid(
            "fixed",
            format!("{name:?} is not one of the estimated parameters {FREE:?}"),
        ));
    }
    crate::plant::check_substeps(o.substeps)?;
    if !(o.tolerance.is_finite() && o.tolerance > 0.0) {
        return Err(RipError::invalid(
            "tolerance",
            "must be positive and finite",
        ));
    }
    Ok(())
}

/// The state at sample `k` estimated from the measured angles (central-difference rates).
fn state_at(log: &LogData, k: usize) -> State {
    let (a, b) = (k.saturating_sub(1), (k + 1).min(log.y.len() - 1));
    let dt = (b - a) as f64 * log.ts;
    let rate = |j: usize| (log.y[b][j] - log.y[a][j]) / dt;
    State::new(log.y[k][0], rate(0), log.y[k][1], rate(1))
}

/// MATLAB's fit `100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖)` of each output, from normalised residuals
/// `r = w (ŷ − y)` and the measurements.
fn fit_percent(r: &[f64], y: &[[f64; 2]], w: [f64; 2]) -> [f64; 2] {
    std::array::from_fn(|j| {
        let n = y.len() as f64;
        let mean = y.iter().map(|v| v[j]).sum::<f64>() / n;
        let dev: f64 = y.iter().map(|v| (v[j] - mean).powi(2)).sum();
        let err: f64 = r
            .iter()
            .skip(j)
            .step_by(2)
            .map(|v| (v / w[j]).powi(2))
            .sum();
        100.0 * (1.0 - (err / dev).sqrt())
    })
}

/// Identifies the free parameters from `logs` (module docs). `cancel` stops the work between
/// segment simulations with [`RipError::Cancelled`].
pub fn identify(
    logs: &[LogData],
    options: &IdentifyOptions,
    cancel: &AtomicBool,
) -> Result<IdentifyResult> {
    check(logs, options)?;
    let ts = logs[0].ts;
    let seg_len = (options.segment / ts).round() as usize;
    // Output scales: each angle's standard deviation over the logs (training parts).
    let mut w = [1.0; 2];
    for (j, wj) in w.iter_mut().enumerate() {
        let (mut n, mut s, mut s2) = (0.0, 0.0, 0.0);
        for log in logs {
            for y in &log.y {
                n += 1.0;
                s += y[j];
                s2 += y[j] * y[j];
            }
        }
        let var = (s2 / n - (s / n).powi(2)).max(0.0);
        if var.sqrt() < 1e-6 {
            return Err(RipError::invalid(
                "logs",
                format!(
                    "the {} angle never moves: no excitation, nothing is identifiable",
                    ["arm", "pendulum"][j]
                ),
            ));
        }
        *wj = 1.0 / var.sqrt();
    }
    let problem = Problem {
        logs,
        w,
        substeps: options.substeps,
        sims: AtomicUsize::new(0),
    };
    let p0 = initial(&options.start);
    let lower: [f64; NP] =
        std::array::from_fn(|k| p0[k] * if (4..NP).contains(&k) { 1e-4 } else { 1e-2 });
    let upper: [f64; NP] = std::array::from_fn(|k| (p0[k] * 1e3).min(CEILING[k]));
    let mut logp: [f64; NP] = p0.map(f64::ln);
    let held: [bool; NP] = std::array::from_fn(|k| options.fixed.iter().any(|n| n == FREE[k]));
    let params_of = |logp: &[f64; NP]| with(options.start, &logp.map(f64::exp));
    let cancelled = || cancel.load(Ordering::Relaxed);

    // Continuation: short segments first (their criterion has fewer local minima, the
    // simulation error has no time to pile up), then the requested length from there.
    let short = ((SHORT_SEGMENT / ts).round() as usize).max(20);
    let stages: Vec<usize> = if short < seg_len {
        vec![short, seg_len]
    } else {
        vec![seg_len]
    };
    let mut segments: Vec<Segment> = Vec::new();
    let mut iterations = 0;
    let mut converged = false;
    let mut cost = f64::INFINITY;
    let mut n_unknowns = NP;
    let mut normal = DMatrix::<f64>::zeros(0, 0);
    let mut grad = DVector::<f64>::zeros(0);
    let h = 1e-6;
    for &seg_len in &stages {
        let previous: Vec<(usize, usize, State)> =
            segments.iter().map(|s| (s.log, s.k0, s.x0)).collect();
        segments.clear();
        for (l, log) in logs.iter().enumerate() {
            let train = ((1.0 - options.holdout) * log.u.len() as f64).floor() as usize;
            let count = (train / seg_len).max(1);
            for s in 0..count {
                let k0 = s * seg_len;
                let n = if s + 1 == count { train - k0 } else { seg_len };
                let x0 = previous
                    .iter()
                    .find(|p| p.0 == l && p.1 == k0)
                    .map_or_else(|| state_at(log, k0), |p| p.2);
                segments.push(Segment {
                    log: l,
                    k0,
                    n,
                    x0,
                    r: vec![0.0; 2 * n],
                    trial: vec![0.0; 2 * n],
                    jac: vec![0.0; 2 * n * (NP + 4)],
                });
            }
        }
        n_unknowns = NP + 4 * segments.len();
        // Residuals at the stage's start.
        let base = problem.plant(&params_of(&logp)).ok_or_else(|| {
            RipError::invalid("start", "does not give a plant that can be simulated")
        })?;
        let ok = segments
            .par_iter_mut()
            .map(|s| !cancelled() && problem.simulate(&base, s.log, s.k0, &s.x0, &mut s.r))
            .collect::<Vec<_>>();
        if cancelled() {
            return Err(RipError::Cancelled);
        }
        if ok.iter().any(|v| !v) {
            return Err(RipError::invalid(
                "start",
                "the simulation from the start parameters diverges on these logs",
            ));
        }
        cost = segments
            .iter()
            .map(|s| s.r.iter().map(|v| v * v).sum::<f64>())
            .sum();
        let mut lambda = 1e-2;
        converged = false;
        normal = DMatrix::<f64>::zeros(n_unknowns, n_unknowns);
        grad = DVector::<f64>::zeros(n_unknowns);
        let mut stage_iterations = 0;
        while stage_iterations < options.max_iterations {
            stage_iterations += 1;
            iterations += 1;
            let plants: Vec<Option<(Plant, usize)>> = (0..NP)
                .map(|k| {
                    let mut lp = logp;
                    lp[k] += h;
                    problem.plant(&params_of(&lp))
                })
                .collect();
            let base = problem
                .plant(&params_of(&logp))
                .expect("accepted parameters simulate");
            let jac_ok: Vec<bool> = segments
                .par_iter_mut()
                .map(|s| {
                    let rows = 2 * s.n;
                    let (r, jac, trial) = (&s.r, &mut s.jac, &mut s.trial);
                    for (k, plant) in plants.iter().enumerate() {
                        if cancelled() {
                            return false;
                        }
                        let Some(plant) = plant else { return false };
                        if !problem.simulate(plant, s.log, s.k0, &s.x0, trial) {
                            return false;
                        }
                        for i in 0..rows {
                            jac[k * rows + i] = (trial[i] - r[i]) / h;
                        }
                    }
                    for c in 0..4 {
                        if cancelled() {
                            return false;
                        }
                        let hx = 1e-6 * (1.0 + s.x0[c].abs());
                        let mut x0 = s.x0;
                        x0[c] += hx;
                        if !problem.simulate(&base, s.log, s.k0, &x0, trial) {
                            return false;
                        }
                        for i in 0..rows {
                            jac[(NP + c) * rows + i] = (trial[i] - r[i]) / hx;
                        }
                    }
                    true
                })
                .collect();
            if cancelled() {
                return Err(RipError::Cancelled);
            }
            if jac_ok.iter().any(|v| !v) {
                return Err(RipError::invalid(
                    "logs",
                    format!(
                        "{}: the fit left the region where the model can be simulated on these \
                         logs (the simulation diverges next to the parameters it reached): the \
                         start set is too far from the rig; weigh and measure it (a lab file \
                         with mp, Lp, mr, Lr, Rm) and check that the logs are of open-loop \
                         excitation runs",
                        log_names(logs, &options.names)
                    ),
                ));
            }
            assemble(&segments, &mut normal, &mut grad);
            let mut improved = false;
            for _ in 0..12 {
                let mut lhs = normal.clone();
                for k in 0..n_unknowns {
                    lhs[(k, k)] += lambda * normal[(k, k)].max(1e-12);
                }
                let mut rhs = -&grad;
                for k in (0..NP).filter(|&k| held[k]) {
                    lhs.row_mut(k).fill(0.0);
                    lhs.column_mut(k).fill(0.0);
                    lhs[(k, k)] = 1.0;
                    rhs[k] = 0.0;
                }
                let Some(step) = lhs.cholesky().map(|c| c.solve(&rhs)) else {
                    lambda *= 10.0;
                    continue;
                };
                let trial_logp: [f64; NP] = std::array::from_fn(|k| {
                    (logp[k] + step[k]).clamp(lower[k].ln(), upper[k].ln())
                });
                let Some(trial_plant) = problem.plant(&params_of(&trial_logp)) else {
                    lambda *= 4.0;
                    continue;
                };
                // A point whose neighbours cannot be simulated (a stiff friction law, an arm
                // inertia at its limit) would end the fit at the next Jacobian: step shorter.
                if (0..NP).any(|k| {
                    let mut lp = trial_logp;
                    lp[k] += h;
                    problem.plant(&params_of(&lp)).is_none()
                }) {
                    lambda *= 4.0;
                    continue;
                }
                let trial_cost: Option<f64> = segments
                    .par_iter_mut()
                    .enumerate()
                    .map(|(si, s)| {
                        if cancelled() {
                            return None;
                        }
                        let mut x0 = s.x0;
                        for c in 0..4 {
                            x0[c] += step[NP + 4 * si + c];
                        }
                        problem
                            .simulate(&trial_plant, s.log, s.k0, &x0, &mut s.trial)
                            .then(|| s.trial.iter().map(|v| v * v).sum::<f64>())
                    })
                    .sum();
                if cancelled() {
                    return Err(RipError::Cancelled);
                }
                match trial_cost {
                    Some(c) if c < cost => {
                        let small = cost - c <= options.tolerance * cost;
                        for (si, s) in segments.iter_mut().enumerate() {
                            for c in 0..4 {
                                s.x0[c] += step[NP + 4 * si + c];
                            }
                            std::mem::swap(&mut s.r, &mut s.trial);
                        }
                        logp = trial_logp;
                        cost = c;
                        lambda = (lambda / 3.0).max(1e-9);
                        improved = true;
                        converged = small;
                        break;
                    }
                    _ => lambda *= 4.0,
                }
            }
            if !improved {
                // No damping lowers the cost: a (local) minimum to working precision.
                converged = true;
                break;
            }
            if converged {
                break;
            }
        }
    }
    let n_seg = segments.len();
    let params = params_of(&logp);
    // Information about log p with the initial states eliminated (Schur complement).
    assemble(&segments, &mut normal, &mut grad);
    let mut info = normal.view((0, 0), (NP, NP)).into_owned();
    for si in 0..n_seg {
        let o = NP + 4 * si;
        let nss = normal.view((o, o), (4, 4)).into_owned();
        let ngs = normal.view((0, o), (NP, 4)).into_owned();
        if let Some(ch) = nss.cholesky() {
            info -= &ngs * ch.solve(&ngs.transpose());
        }
    }
    let n_res: usize = segments.iter().map(|s| 2 * s.n).sum();
    let sigma2 =
        cost / (n_res.saturating_sub(n_unknowns).max(1)) as f64 * coloured_noise_factor(&segments);
    let at_bound: [bool; NP] = std::array::from_fn(|k| {
        let v = logp[k];
        (v - lower[k].ln()).abs() < 1e-9 || (v - upper[k].ln()).abs() < 1e-9
    });
    // Parameters on a bound are held there (a friction or dead zone of zero carries no
    // information): rank, condition and covariance are those of the others.
    let interior: Vec<usize> = (0..NP).filter(|&k| !at_bound[k] && !held[k]).collect();
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
    let mut cov = DMatrix::<f64>::zeros(NP, NP);
    let mut null_weight = [0.0; NP];
    for (i, &l) in eig.eigenvalues.iter().enumerate() {
        let v = eig.eigenvectors.column(i);
        if l > tiny {
            for a in 0..ni {
                for b in 0..ni {
                    cov[(interior[a], interior[b])] += v[a] * v[b] / l;
                }
            }
        } else {
            for a in 0..ni {
                null_weight[interior[a]] += v[a] * v[a];
            }
        }
    }
    let mut std_errors = [0.0; NP];
    let mut not_identifiable = Vec::new();
    let mut at_bounds = Vec::new();
    for k in 0..NP {
        let rse = if null_weight[k] > 0.25 {
            f64::INFINITY
        } else {
            (sigma2 * cov[(k, k)]).max(0.0).sqrt()
        };
        std_errors[k] = rse * logp[k].exp();
        if held[k] {
            continue;
        }
        if at_bound[k] {
            at_bounds.push(FREE[k]);
        } else if rse.is_nan() || rse > NOT_IDENTIFIABLE_RSE {
            not_identifiable.push(FREE[k]);
        }
    }
    let training_fit_percent = logs
        .iter()
        .enumerate()
        .map(|(l, log)| {
            let (r, y): (Vec<f64>, Vec<[f64; 2]>) = segments
                .iter()
                .filter(|s| s.log == l)
                .flat_map(|s| {
                    s.r.chunks(2)
                        .zip(&log.y[s.k0..s.k0 + s.n])
                        .map(|(r, y)| ([r[0], r[1]], *y))
                })
                .fold((Vec::new(), Vec::new()), |(mut r, mut y), (ri, yi)| {
                    r.extend(ri);
                    y.push(yi);
                    (r, y)
                });
            fit_percent(&r, &y, w)
        })
        .collect();
    let final_plant = problem
        .plant(&params)
        .expect("accepted parameters simulate");
    let mut fit = Vec::with_capacity(logs.len());
    let mut held_out_motion = Vec::with_capacity(logs.len());
    for (l, log) in logs.iter().enumerate() {
        let train = ((1.0 - options.holdout) * log.u.len() as f64).floor() as usize;
        let n = log.u.len() - train;
        let motion = rms_deviation(&log.y[train..]);
        held_out_motion.push(motion);
        if n < 20 {
            fit.push([f64::NAN; 2]);
            continue;
        }
        if cancelled() {
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
            r.extend(fit_initial_state(&problem, &final_plant, l, k0, len));
            k0 += len;
        }
        let f = fit_percent(&r, &log.y[train..], w);
        fit.push(std::array::from_fn(|j| {
            if motion[j] >= MIN_HELDOUT_MOTION {
                f[j]
            } else {
                f64::NAN
            }
        }));
    }
    let (ad, bd) = final_plant.0.linearize_discrete(&State::zeros(), 0.0, ts)?;
    let covariance: Vec<f64> = (0..NP * NP)
        .map(|i| {
            let (a, b) = (i / NP, i % NP);
            if null_weight[a] > 0.25 || null_weight[b] > 0.25 {
                f64::INFINITY
            } else {
                sigma2 * cov[(a, b)]
            }
        })
        .collect();
    let rse: [f64; NP] = std::array::from_fn(|k| std_errors[k] / logp[k].exp());
    let problems = verdict(&Verdict {
        logs,
        names: &options.names,
        start: &options.start,
        params: &params,
        fit: &fit,
        rse: &rse,
        at_bounds: &at_bounds,
        at_upper: &std::array::from_fn(|k| (logp[k] - upper[k].ln()).abs() < 1e-9),
        rank,
        condition_number,
    });
    Ok(IdentifyResult {
        params,
        std_errors,
        fit_percent: fit,
        held_out_motion,
        training_fit_percent,
        not_identifiable,
        at_bounds,
        condition_number,
        rank,
        cost,
        rms_residual: (cost / n_res as f64).sqrt(),
        iterations,
        converged,
        simulations: problem.sims.load(Ordering::Relaxed),
        segments: n_seg,
        ad,
        bd,
        values: logp.map(f64::exp),
        covariance,
        problems,
    })
}

/// Lags of the residuals' autocorrelation in [`coloured_noise_factor`] (0.2 s at 100 Hz).
const NOISE_LAGS: usize = 20;

/// The factor by which coloured residuals inflate the variance of a least-squares estimate
/// over white ones: the long-run variance over the variance, `1 + 2 Σ_l (1 − l/(L+1)) ρ_l`
/// with Bartlett weights over `L` = [`NOISE_LAGS`] lags, `ρ_l` the residuals' autocorrelation
/// at lag `l` pooled over segments and outputs (at least 1).
fn coloured_noise_factor(segments: &[Segment]) -> f64 {
    let mut acf = [0.0; NOISE_LAGS + 1];
    for s in segments {
        for j in 0..2 {
            let r: Vec<f64> = s.r.iter().skip(j).step_by(2).copied().collect();
            for (l, a) in acf.iter_mut().enumerate() {
                if l < r.len() {
                    *a += r.iter().zip(&r[l..]).map(|(x, y)| x * y).sum::<f64>();
                }
            }
        }
    }
    if acf[0].is_nan() || acf[0] <= 0.0 {
        return 1.0;
    }
    let lags = NOISE_LAGS as f64 + 1.0;
    let sum: f64 = (1..=NOISE_LAGS)
        .map(|l| (1.0 - l as f64 / lags) * acf[l] / acf[0])
        .sum();
    (1.0 + 2.0 * sum).max(1.0)
}

/// The logs' names, comma-separated (`logs[i]` where a name is missing).
fn log_names(logs: &[LogData], names: &[String]) -> String {
    (0..logs.len())
        .map(|l| {
            names
                .get(l)
                .cloned()
                .unwrap_or_else(|| format!("logs[{l}]"))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Root-mean-square deviation from the mean of each output.
fn rms_deviation(y: &[[f64; 2]]) -> [f64; 2] {
    let n = y.len().max(1) as f64;
    std::array::from_fn(|j| {
        let mean = y.iter().map(|v| v[j]).sum::<f64>() / n;
        (y.iter().map(|v| (v[j] - mean).powi(2)).sum::<f64>() / n).sqrt()
    })
}

/// What [`verdict`] judges.
struct Verdict<'a> {
    logs: &'a [LogData],
    names: &'a [String],
    start: &'a FurutaParams,
    params: &'a FurutaParams,
    fit: &'a [[f64; 2]],
    rse: &'a [f64; NP],
    at_bounds: &'a [&'static str],
    at_upper: &'a [bool; NP],
    rank: usize,
    condition_number: f64,
}

/// The checks of the module docs' "Verdict", each failure a sentence for the user. (The
/// upright eigenvalue is tied to the logs by the pendulum's held-out fit: a model whose
/// pendulum frequency is wrong does not predict a swing.)
fn verdict(v: &Verdict<'_>) -> Vec<String> {
    let mut out = Vec::new();
    let name = |l: usize| {
        v.names
            .get(l)
            .cloned()
            .unwrap_or_else(|| format!("logs[{l}]"))
    };
    for (l, f) in v.fit.iter().enumerate() {
        for (j, output) in ["theta", "alpha"].iter().enumerate() {
            if f[j] < MIN_FIT_PERCENT {
                out.push(format!(
                    "{}: held-out fit of {output} is {:.1} %, below {MIN_FIT_PERCENT} %: the \
                     model does not predict this log; weigh and measure the rig (a lab file: \
                     mp, Lp, mr, Lr, Rm) so that the fit starts near it",
                    name(l),
                    f[j]
                ));
            }
        }
    }
    if v.rank < NP || v.condition_number.is_nan() || v.condition_number > MAX_CONDITION {
        out.push(format!(
            "the information matrix has rank {}/{NP} and condition number {:.3e} (at most \
             {MAX_CONDITION:.0e}): the logs do not determine the parameters; add a chirp and a \
             PRBS run (motor and arm) and a free swing (pendulum)",
            v.rank, v.condition_number
        ));
    }
    for (k, name) in FREE.iter().enumerate() {
        if LINEAR.contains(name) && (v.rse[k].is_nan() || v.rse[k] > MAX_RSE) {
            out.push(format!(
                "{name} has a relative standard error of {:.1} % (at most {} %): the upright \
                 model is not determined; {}",
                100.0 * v.rse[k],
                100.0 * MAX_RSE,
                if *name == "dp" || *name == "jp" {
                    "add a free-swing log (rip-rt excite --signal free-swing)"
                } else {
                    "add a chirp or PRBS run with more amplitude"
                }
            ));
        }
        let structural = ["lr", "jr", "jp", "kt", "dr"].contains(name);
        if v.at_upper[k] || (structural && v.at_bounds.contains(name)) {
            out.push(format!(
                "{name} ended on its bound ({:.4e}): the start set is inconsistent with the rig; \
                 {}",
                get(v.params, k),
                match *name {
                    "dr" => "measure the motor's km (back-EMF) and Rm",
                    "lr" | "jr" => "measure mr and Lr",
                    "jp" => "measure mp and Lp",
                    _ => "measure Rm with a multimeter",
                }
            ));
        }
    }
    for (what, a, b) in [
        ("mr", v.start.mr, v.params.mr),
        ("mp", v.start.mp, v.params.mp),
        ("Lp", v.start.lp, v.params.lp),
    ] {
        if !(b <= a * MAX_FIXED_CHANGE && b >= a / MAX_FIXED_CHANGE) {
            out.push(format!(
                "{what} had to change from {a:.4} to {b:.4} to fit (more than a factor \
                 {MAX_FIXED_CHANGE}): the start set's masses and lengths are not the rig's; \
                 weigh and measure it (lab file: {what})"
            ));
        }
    }
    let mut drive: Vec<f64> = v
        .logs
        .iter()
        .flat_map(|l| l.u.iter().map(|u| u.abs()))
        .collect();
    if !drive.is_empty() {
        let k = ((drive.len() - 1) as f64 * 0.95) as usize;
        let (_, p95, _) = drive.select_nth_unstable_by(k, f64::total_cmp);
        let p95 = *p95;
        if p95 > 0.0 && v.params.vd > MAX_DEAD_ZONE_FRACTION * p95 {
            out.push(format!(
                "the identified dead zone {:.3} V is more than {} % of the logs' voltage (95th \
                 percentile {p95:.3} V): the motor would barely move; repeat the excitation \
                 with a larger amplitude",
                v.params.vd,
                100.0 * MAX_DEAD_ZONE_FRACTION
            ));
        }
    }
    out
}

/// `JᵀJ` and `Jᵀr` of all segments into `normal`, `grad` (global block first, then four
/// initial-state unknowns per segment).
fn assemble(segments: &[Segment], normal: &mut DMatrix<f64>, grad: &mut DVector<f64>) {
    normal.fill(0.0);
    grad.fill(0.0);
    for (si, s) in segments.iter().enumerate() {
        let rows = 2 * s.n;
        let col = |c: usize| &s.jac[c * rows..(c + 1) * rows];
        let index = |c: usize| if c < NP { c } else { NP + 4 * si + (c - NP) };
        for a in 0..NP + 4 {
            let ca = col(a);
            grad[index(a)] += ca.iter().zip(&s.r).map(|(x, y)| x * y).sum::<f64>();
            for b in 0..=a {
                let v: f64 = ca.iter().zip(col(b)).map(|(x, y)| x * y).sum();
                let (ia, ib) = (index(a), index(b));
                normal[(ia, ib)] += v;
                if ia != ib {
                    normal[(ib, ia)] += v;
                }
            }
        }
    }
}

/// Residuals of samples `k0 .. k0 + n` of log `l` simulated in one piece from the initial state
/// that fits them best (a few Gauss–Newton steps on `x₀` from the measured one).
fn fit_initial_state(
    problem: &Problem<'_>,
    plant: &(Plant, usize),
    l: usize,
    k0: usize,
    n: usize,
) -> Vec<f64> {
    let log = &problem.logs[l];
    let mut x0 = state_at(log, k0);
    let mut r = vec![0.0; 2 * n];
    let mut trial = vec![0.0; 2 * n];
    let mut jac = vec![0.0; 2 * n * 4];
    if !problem.simulate(plant, l, k0, &x0, &mut r) {
        return r;
    }
    let mut cost: f64 = r.iter().map(|v| v * v).sum();
    let mut lambda = 1e-3;
    for _ in 0..20 {
        for c in 0..4 {
            let hx = 1e-6 * (1.0 + x0[c].abs());
            let mut x = x0;
            x[c] += hx;
            problem.simulate(plant, l, k0, &x, &mut trial);
            for i in 0..2 * n {
                jac[c * 2 * n + i] = (trial[i] - r[i]) / hx;
            }
        }
        let jm = DMatrix::from_column_slice(2 * n, 4, &jac);
        let jtj = jm.transpose() * &jm;
        let g = jm.transpose() * DVector::from_column_slice(&r);
        let mut improved = false;
        for _ in 0..8 {
            let mut lhs = jtj.clone();
            for k in 0..4 {
                lhs[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let Some(step) = lhs.cholesky().map(|c| c.solve(&(-&g))) else {
                lambda *= 10.0;
                continue;
            };
            let x = x0 + State::from_column_slice(step.as_slice());
            if problem.simulate(plant, l, k0, &x, &mut trial) {
                let c: f64 = trial.iter().map(|v| v * v).sum();
                if c < cost {
                    let small = cost - c < 1e-10 * cost;
                    x0 = x;
                    cost = c;
                    std::mem::swap(&mut r, &mut trial);
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = !small;
                    break;
                }
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    r
}
