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
//! the start set); back-EMF and the arm's viscous friction are one coefficient `c`: the free
//! swing's 0 V shorts the windings, so no log separates them. A DC motor has one constant in SI
//! units (torque per ampere = back-EMF per radian per second), so `km = kt` is held unless
//! `km` was measured ([`IdentifyOptions::measured`]), and `dr = c − kt²/rm` takes the rest;
//! with a measured `km`, `dr = c − kt km/rm`. The optimisation works on `J₀` and
//! `Jα` themselves; when the start's `mp`, `lp` leave no room for a positive `jp` the pendulum
//! is taken as a uniform rod of the same `mp lp` (so `mp` and `lp` change, `G` does not), and
//! when its `mr` leaves no room for a positive `jr` the arm is taken as a uniform rod and `mr`
//! changes (the dynamics depend on `J₀` and `Jα` alone). If a start value is
//! inconsistent with the rig in another way (for example `km` larger than the whole of `c`
//! allows), the parameter that takes the difference runs into its lower bound and the result
//! lists it in [`IdentifyResult::at_bounds`].
//!
//! The cable's stiffness `kc` ([`crate::plant`], "The cable") is not estimated: it is held at
//! the start set's value (a start file's `[plant] Kc`, or the preset's 0) and the report names
//! it as held. Its torque `−kc θ` is a spring on the arm, which the excitations (about the
//! arm's zero, hanging) show only through the slow drift of the arm's mean angle, where the
//! arm's Coulomb friction and the dead zone act alike; a stiffness measured on the rig (the
//! arm's rest angle `θ` under a constant voltage `V`, `kc ≈ kt (V − vd) / (rm θ)` with the
//! friction's share taken out by approaching from both sides) belongs in the start file.
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
//! A free swing's coast (a stretch of exactly 0 V of at least [`MIN_COAST`] seconds to the end
//! of the log's training part) is then fitted in longer segments, [`COAST_SEGMENTS`] in turn:
//! a segment's free initial state absorbs the decay before it, so with short segments the
//! damping is seen only within each, and a pendulum with a decay time of a minute decays by a
//! few per cent in two seconds. Over the whole coast the swing's decay is one curve. (Each
//! stage's frequency is close enough that the next, longer one stays within its basin.)
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
//! At the optimum, with `F` the Schur complement of the initial states in `JᵀJ` (the
//! information about `log p` alone), the covariance of `log p` is the sandwich
//!
//! ```text
//! Cov(log p) = N/(N − n) · F⁻¹ S F⁻¹,   S = Σₛ Σ_{|l|≤L} (1 − |l|/(L+1)) Σₖ gₖ gₖ₊ₗᵀ
//! ```
//!
//! with `gₖ` the score of sample `k` (the Jacobian's rows, initial states projected out, times
//! the residuals), `L` = 25 lags within each segment (Newey–West). The residuals of an
//! output-error fit with quantised encoders are neither white nor of equal variance on the two
//! outputs; `σ̂² F⁻¹` (which assumes both) gave 95 % intervals that held the truth in 85 % of
//! re-identifications. `se(log pₖ) = √Cov(log p)ₖₖ` and `se(pₖ) = pₖ se(log pₖ)`.
//!
//! That covariance is the logs' alone, given the held values of the start set. A held value
//! that was not measured ([`HELD`] not in [`IdentifyOptions::measured`]: a preset's) carries a
//! prior relative standard deviation [`PRIOR_RSE`], and what depends on it inherits it: with
//! `sₕ = ∂ log p / ∂ log h` at the same dynamics (`mp`, `lp` set the common factor of the
//! lumped quantities; `rm` splits `b` and `c` into `kt` and `dr`),
//!
//! ```text
//! se(pₖ)² = pₖ² (Cov(log p)ₖₖ + Σₕ (PRIOR_RSE sₕ,ₖ)²)
//! ```
//!
//! so that `dr = c − kt²/rm` with a preset's `rm` is known no better than `rm` allows. The
//! upright linearisation does not move along `sₕ` (the dynamics are the same), so its entries'
//! errors, the verdict's checks and [`IdentifyResult::covariance`] use the logs' part alone.
//!
//! The condition number and rank of `F`
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
//! scored: its fit is NaN, "not measurable", since `‖y − mean(y)‖` is then noise. A log none
//! of whose outputs is scored has had no held-out check: it is listed in
//! [`IdentifyResult::not_done`] (never as passed) with the recording that would score it.
//!
//! # Verdict
//!
//! A converged fit is not a trusted one. [`IdentifyResult::problems`] lists every reason not
//! to trust it, each naming the log, the parameter and the measurement or excitation that
//! would fix it; callers must refuse to use a result with problems (`riprs identify` exits
//! non-zero and writes no rig file). The checks:
//!
//! - the held-out fit of every scored output is at least [`MIN_FIT_PERCENT`] (a log with no
//!   scored output is not checked: [`IdentifyResult::not_done`]);
//! - `F` has full rank and a condition number of at most [`MAX_CONDITION`];
//! - every parameter of the upright linearisation ([`LINEAR`]) has a relative standard error
//!   of at most [`MAX_RSE`];
//! - no parameter ends on its upper bound, and none of `lr, jr, jp, kt, dr` on its lower bound
//!   (the friction and dead-zone terms may be zero);
//! - `mr`, `mp`, `lp` changed by at most a factor [`MAX_FIXED_CHANGE`] (a uniform-rod split
//!   beyond that means the fixed values are not the rig's);
//! - the dead zone is at most [`MAX_DEAD_ZONE_FRACTION`] of the logs' 95th percentile of `|u|`;
//! - every entry of the continuous upright `[A B]` that is not a structural zero
//!   ([`LINEAR_ENTRIES`]) has a relative standard error of at most [`MAX_ENTRY_RSE`], the
//!   pendulum-damping entries `A[1][3]`, `A[3][3]` included, and the unstable eigenvalue one of
//!   at most [`MAX_EIGENVALUE_RSE`], by the delta method `var f = ∇fᵀ Σ ∇f` (`Σ` the
//!   covariance of `log p`, `∇f` by central differences): at two standard errors, within 2 %
//!   and 1 %. A model that passes is known to that precision, not merely fitted; a pendulum
//!   whose free swing does not determine its damping is refused with the free swing that
//!   would (a wider swing, [`MIN_DAMPING_SWING`], naming the peak the logs reached).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use crate::error::{Result, RipError};
use crate::linalg::Mat;
use crate::plant::{FurutaParams, Param, State};

mod check;
pub mod header;
pub mod lab;
mod params;
mod problem;
mod solve;
mod stats;
#[cfg(test)]
mod tests;

use check::{check, log_names, verdict, Verdict};
use params::{initial, with, CEILING};
use problem::{state_at, Problem, Segment};
use solve::{Bounds, Context};
pub use stats::LINEAR_ENTRIES;

/// The parameters the fit estimates, from the one parameter table ([`Param`]; results and
/// options name them as files do, `Lr`). `mr`, `mp` and `Lp` change too when the start's
/// values leave no room for positive `Jr`, `Jp` (module docs).
pub const FREE: [Param; 9] = [
    Param::Lr,
    Param::Jr,
    Param::Jp,
    Param::Kt,
    Param::Dr,
    Param::Dp,
    Param::Cr,
    Param::Cp,
    Param::Vd,
];
const NP: usize = FREE.len();

/// The start set's parameters that the fit holds (module docs): the pendulum's mass and
/// length and the arm's mass, which fix the scale, and the motor's resistance and back-EMF
/// constant (`km = kt` unless measured). Those not measured hold a preset's value, with the
/// prior [`PRIOR_RSE`].
pub const HELD: [Param; 5] = [Param::Mp, Param::Lp, Param::Mr, Param::Rm, Param::Km];

/// Relative standard deviation of a held value that was not measured (a preset's): a preset's
/// value is one rig's, and 30 % stands for a rig of its class. The shared envelope
/// ([`crate::rig`]) spans factors of 3 to 5 in these values, so a rig outside the preset's
/// class is off by more than the prior says: measure the value (the lab file).
pub const PRIOR_RSE: f64 = 0.3;

/// Relative standard error above which a parameter counts as not identifiable.
pub const NOT_IDENTIFIABLE_RSE: f64 = 0.5;

/// Segment length (s) of the first, continuation stage (module docs).
pub const SHORT_SEGMENT: f64 = 0.5;

/// Segment lengths (s) of the last continuation stages over a free swing's coast (module
/// docs): each stage's frequency error leaves the next one's phase drift well inside a cycle.
pub const COAST_SEGMENTS: [f64; 2] = [8.0, 60.0];

/// Least peak swing (rad from hanging) of a free swing's coast that the verdict's advice asks
/// for when the pendulum's damping is not determined. The damping is read from the decay of
/// the swing against the encoders' quantisation and noise, whose error repeats cycle after
/// cycle of a nearly periodic swing: a longer swing adds little, a wider one shrinks the error
/// relative to the swing. On the envelope's most lightly damped rigs a kick of 6 V for 0.3 s
/// (peaks of 0.9–2 rad) brings the entries to about 1 %, the default kick's 0.2–0.7 rad to 2–5 %.
pub const MIN_DAMPING_SWING: f64 = 1.5;

/// Least length (s) of a log's stretch at exactly 0 V, to its training part's end, that counts
/// as a free swing's coast (and is fitted in the longer segments of [`COAST_SEGMENTS`]).
pub const MIN_COAST: f64 = 5.0;

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
/// They are the first six of [`FREE`] (the friction and the dead zone do not enter it).
pub const LINEAR: [Param; 6] = {
    let [lr, jr, jp, kt, dr, dp, ..] = FREE;
    [lr, jr, jp, kt, dr, dp]
};

/// Largest identified dead zone as a fraction of the logs' 95th percentile of `|u|`: a dead zone
/// that swallows most of the excitation is not one the logs can show.
pub const MAX_DEAD_ZONE_FRACTION: f64 = 0.6;

/// Largest relative standard error of an entry of the continuous upright `[A B]`
/// ([`LINEAR_ENTRIES`], by the delta method from the covariance) for the result to be trusted:
/// at two standard errors the entry is then known within 2 %. The pendulum-damping entries
/// `A[1][3]`, `A[3][3]` (set by `dp`) are held to it too; they need a free swing that swings
/// wide ([`MIN_DAMPING_SWING`]).
pub const MAX_ENTRY_RSE: f64 = 0.01;

/// Largest relative standard error of the upright linearisation's unstable eigenvalue for the
/// result to be trusted (within 1 % at two standard errors).
pub const MAX_EIGENVALUE_RSE: f64 = 0.005;

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
    /// Names (of [`HELD`]) measured on the rig (a lab file's): held at the start set's value
    /// without a prior. `km` not measured is held equal to `kt`.
    pub measured: Vec<String>,
    /// The preset the start set is based on: a [`HELD`] value not measured that differs from
    /// its value is taken as measured (a start file's own); `None`: every one not measured is
    /// the preset's.
    pub preset: Option<FurutaParams>,
}

/// A start set's value the fit held without a measurement, and its prior.
#[derive(Debug, Clone, PartialEq)]
pub struct Held {
    /// The parameter's name ([`HELD`]).
    pub name: &'static str,
    /// The value held (the preset's).
    pub value: f64,
    /// Its prior relative standard deviation ([`PRIOR_RSE`]), included in the standard errors
    /// of what depends on it.
    pub prior_rse: f64,
}

impl IdentifyOptions {
    /// Whether `km` is held equal to `kt` (not measured; module docs).
    pub fn km_tied(&self) -> bool {
        !self.is_measured(Param::Km)
    }

    fn is_measured(&self, param: Param) -> bool {
        self.measured.iter().any(|n| n == param.name())
            || self
                .preset
                .is_some_and(|p| p.get(param) != self.start.get(param))
    }

    /// The held values that are a preset's (not measured), each with its prior; `km` tied to
    /// `kt` is not one of them.
    pub fn held_priors(&self) -> Vec<Held> {
        HELD.iter()
            .filter(|&&h| h != Param::Km && !self.is_measured(h))
            .map(|&h| Held {
                name: h.name(),
                value: self.start.get(h),
                prior_rse: PRIOR_RSE,
            })
            .collect()
    }
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
            measured: Vec::new(),
            preset: None,
        }
    }
}

/// What [`identify`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentifyResult {
    /// The identified parameters (the start set's fixed ones unchanged).
    pub params: FurutaParams,
    /// Standard error of each of [`FREE`] (same units; `inf` when not identifiable; for `jr`
    /// and `jp` those of the joint-axis inertias `J₀` and `Jα`, which the logs determine),
    /// the priors of [`held`](Self::held) included (module docs).
    pub std_errors: [f64; NP],
    /// The start set's values held at a preset's, each with its prior (module docs).
    pub held: Vec<Held>,
    /// Whether `km` was held equal to `kt` (not measured).
    pub km_tied: bool,
    /// Checks not done, one sentence each naming the log and the recording that would let it
    /// be done: a log whose held-out part moves too little for any output to be scored
    /// ([`MIN_HELDOUT_MOTION`]). Neither passed nor failed.
    pub not_done: Vec<String>,
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
    /// Segment simulations run (the held-out evaluations and every start included).
    pub simulations: usize,
    /// Starts tried (multi-start, [`identify`]).
    pub starts: usize,
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
    /// the sandwich (module docs), row-major `9 × 9`: the logs' alone, given the held values
    /// (without the priors of [`held`](Self::held)); rows and columns of parameters in a null
    /// direction are infinite.
    pub covariance: Vec<f64>,
    /// Covariance of [`FREE`] as plant parameters (SI units; `jr`, `jp` the centroidal
    /// inertias), row-major `9 × 9`, from `covariance` to first order; infinite rows for
    /// parameters in a null direction. The `[plant_covariance]` a rig's identification file
    /// holds, from which `riprs.envs` and campaigns draw rigs consistent with the logs.
    pub plant_covariance: Vec<f64>,
    /// Relative standard errors of the continuous upright `[A B]`'s entries
    /// ([`LINEAR_ENTRIES`]) and, last, of its unstable eigenvalue (delta method, module docs).
    pub linear_rse: [f64; 9],
    /// Why the result cannot be trusted, one sentence each naming the log, the parameter or
    /// the measurement that would fix it; empty when every check passes (module docs,
    /// "Verdict").
    pub problems: Vec<String>,
}

/// Initial dead zones (V) of the further starts tried when the fit from the start set is not
/// trusted: a fit started at a small dead zone can end in a basin where the dead zone swallows
/// the excitation and the motor constant vanishes.
pub const RESTART_DEAD_ZONES: [f64; 2] = [0.5, 1.0];

/// Identifies the free parameters from `logs` (module docs). When the fit from the start set
/// has problems, it is repeated from the dead zones of [`RESTART_DEAD_ZONES`] (multi-start;
/// not when `vd` is held, nor when the only problems are standard errors, which another start
/// does not mend): the first trusted result is returned, else the first result.
/// `cancel` stops the work between segment simulations with [`RipError::Cancelled`].
pub fn identify(
    logs: &[LogData],
    options: &IdentifyOptions,
    cancel: &AtomicBool,
) -> Result<IdentifyResult> {
    check(logs, options)?;
    let restarts: &[f64] = if options.fixed.iter().any(|n| n == Param::Vd.name()) {
        &[]
    } else {
        &RESTART_DEAD_ZONES
    };
    let mut best: Option<IdentifyResult> = None;
    let mut first_error = None;
    let mut simulations = 0;
    let mut starts = 0;
    for vd in std::iter::once(None).chain(restarts.iter().map(|&v| Some(v))) {
        let mut start = options.start;
        if let Some(vd) = vd {
            start.vd = vd;
        }
        starts += 1;
        match fit(logs, options, &start, cancel) {
            Ok((r, restartable)) => {
                simulations += r.simulations;
                let first = best.is_none();
                if best
                    .as_ref()
                    .map_or(true, |b| !b.problems.is_empty() && r.problems.is_empty())
                {
                    best = Some(r);
                }
                if first && !restartable {
                    break;
                }
            }
            Err(RipError::Cancelled) => return Err(RipError::Cancelled),
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
        if best.as_ref().is_some_and(|b| b.problems.is_empty()) {
            break;
        }
    }
    match best {
        Some(mut b) => {
            b.simulations = simulations;
            b.starts = starts;
            Ok(b)
        }
        None => Err(first_error.expect("a start was tried")),
    }
}

/// Each output's weight: one over its standard deviation over the logs.
fn output_scales(logs: &[LogData]) -> Result<[f64; 2]> {
    let mut w = [1.0; 2];
    for (j, wj) in w.iter_mut().enumerate() {
        let (mut n, mut s, mut s2) = (0.0, 0.0, 0.0);
        for y in logs.iter().flat_map(|l| &l.y) {
            n += 1.0;
            s += y[j];
            s2 += y[j] * y[j];
        }
        let sd = (s2 / n - (s / n).powi(2)).max(0.0).sqrt();
        if sd < 1e-6 {
            return Err(RipError::invalid(
                "logs",
                format!(
                    "the {} angle never moves: no excitation, nothing is identifiable",
                    ["arm", "pendulum"][j]
                ),
            ));
        }
        *wj = 1.0 / sd;
    }
    Ok(w)
}

/// First sample of `log`'s coast: from it to the end of the training part (`train` samples)
/// the voltage is exactly 0 V (a free swing after its kick), for at least [`MIN_COAST`]
/// seconds; `train` when the log has no such coast.
pub(super) fn coast_start(log: &LogData, train: usize) -> usize {
    let c = log.u[..train]
        .iter()
        .rposition(|&u| u != 0.0)
        .map_or(0, |k| k + 1);
    if (train - c) as f64 * log.ts >= MIN_COAST {
        c
    } else {
        train
    }
}

/// The training segments: `seg_len` samples each, but `coast_len` in a log's coast
/// ([`coast_start`]; a coast that starts within `seg_len` of the log's start takes the whole
/// log), each starting from the initial state of `previous` where a segment starts at the same
/// sample, else from the measured state.
fn segments_of(
    logs: &[LogData],
    holdout: f64,
    seg_len: usize,
    coast_len: usize,
    previous: &[Segment],
) -> Vec<Segment> {
    let mut segments = Vec::new();
    for (l, log) in logs.iter().enumerate() {
        let train = ((1.0 - holdout) * log.u.len() as f64).floor() as usize;
        let mut coast = coast_start(log, train);
        if coast < seg_len {
            coast = 0;
        }
        let mut pieces = Vec::new();
        for (from, to, len) in [(0, coast, seg_len), (coast, train, coast_len)] {
            if to <= from {
                continue;
            }
            let count = ((to - from) / len).max(1);
            for s in 0..count {
                let k0 = from + s * len;
                pieces.push((k0, if s + 1 == count { to - k0 } else { len }));
            }
        }
        for (k0, n) in pieces {
            let x0 = previous
                .iter()
                .find(|p| p.log == l && p.k0 == k0)
                .map_or_else(|| state_at(log, k0), |p| p.x0);
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
    segments
}

/// One fit from `start` (checked options): the continuation stages, then the uncertainty,
/// the fits and the verdict; with it, whether another start may mend its problems.
fn fit(
    logs: &[LogData],
    options: &IdentifyOptions,
    start: &FurutaParams,
    cancel: &AtomicBool,
) -> Result<(IdentifyResult, bool)> {
    let ts = logs[0].ts;
    let seg_len = (options.segment / ts).round() as usize;
    let problem = Problem {
        logs,
        w: output_scales(logs)?,
        substeps: options.substeps,
        sims: AtomicUsize::new(0),
    };
    let p0 = initial(start);
    let bounds = Bounds {
        lower: std::array::from_fn(|k| p0[k] * if (4..NP).contains(&k) { 1e-4 } else { 1e-2 }),
        upper: std::array::from_fn(|k| (p0[k] * 1e3).min(CEILING[k])),
        held: std::array::from_fn(|k| options.fixed.iter().any(|n| n == FREE[k].name())),
    };
    let mut logp: [f64; NP] = p0.map(f64::ln);
    let tie_km = options.km_tied();
    let params_of = |logp: &[f64; NP]| with(*start, &logp.map(f64::exp), tie_km);
    let names = log_names(logs, &options.names);
    let cx = Context {
        problem: &problem,
        bounds: &bounds,
        params_of: &params_of,
        max_iterations: options.max_iterations,
        tolerance: options.tolerance,
        names: &names,
        cancel,
    };
    // Continuation: short segments first (their criterion has fewer local minima, the
    // simulation error has no time to pile up), then the requested length from there, then
    // longer segments over the free swings' coasts: a segment's free initial state absorbs
    // the decay before it, so the pendulum's damping is seen only within segments, and a
    // lightly damped pendulum decays too little in a few seconds to determine it.
    let short = ((SHORT_SEGMENT / ts).round() as usize).max(20);
    let mut stages: Vec<(usize, usize)> = Vec::new();
    if short < seg_len {
        stages.push((short, short));
    }
    stages.push((seg_len, seg_len));
    for coast in COAST_SEGMENTS {
        let len = (coast / ts).round() as usize;
        if len > seg_len {
            stages.push((seg_len, len));
        }
    }
    let mut segments: Vec<Segment> = Vec::new();
    let (mut iterations, mut converged, mut cost) = (0, false, f64::INFINITY);
    for &(len, coast) in &stages {
        segments = segments_of(logs, options.holdout, len, coast, &segments);
        let stage = solve::stage(&cx, &mut segments, &mut logp)?;
        iterations += stage.iterations;
        converged = stage.converged;
        cost = stage.cost;
    }
    let params = params_of(&logp);
    let u = stats::uncertainty(&segments, &logp, &bounds);
    let held = options.held_priors();
    let std_errors = stats::with_priors(&u, &params, &held, tie_km);
    let training_fit_percent = stats::training_fit(&problem, &segments);
    let final_plant = problem
        .plant(&params)
        .expect("accepted parameters simulate");
    let (fit, held_out_motion) =
        stats::held_out(&problem, &final_plant, options.holdout, seg_len, cancel)?;
    let (ad, bd) = final_plant.0.linearize_discrete(&State::zeros(), 0.0, ts)?;
    let linear_rse = stats::linear_rse(&params_of, &logp, &u.covariance);
    let not_done = check::not_done(
        logs,
        &options.names,
        &fit,
        &held_out_motion,
        options.holdout,
    );
    let (problems, restartable) = verdict(&Verdict {
        logs,
        names: &options.names,
        start: &options.start,
        params: &params,
        fit: &fit,
        rse: &u.rse,
        at_bounds: &u.at_bounds,
        at_upper: &std::array::from_fn(|k| bounds.on_upper(&logp, k)),
        rank: u.rank,
        condition_number: u.condition_number,
        linear_rse: &linear_rse,
    });
    let n_res: usize = segments.iter().map(|s| 2 * s.n).sum();
    let values = logp.map(f64::exp);
    let plant_covariance = stats::plant_covariance(&params, &values, &u.covariance);
    let result = IdentifyResult {
        params,
        std_errors,
        held,
        km_tied: tie_km,
        not_done,
        fit_percent: fit,
        held_out_motion,
        training_fit_percent,
        not_identifiable: u.not_identifiable,
        at_bounds: u.at_bounds,
        condition_number: u.condition_number,
        rank: u.rank,
        cost,
        rms_residual: (cost / n_res as f64).sqrt(),
        iterations,
        converged,
        simulations: problem.sims.load(Ordering::Relaxed),
        starts: 1,
        segments: segments.len(),
        ad,
        bd,
        values,
        covariance: u.covariance,
        plant_covariance,
        linear_rse,
        problems,
    };
    Ok((result, restartable))
}
