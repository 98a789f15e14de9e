//! One stage of the Levenberg–Marquardt fit (module docs of [`super`], "Method").

use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::problem::{assemble, Problem, Segment};
use super::NP;
use crate::error::{Result, RipError};
use crate::plant::{FurutaParams, Plant};

/// Forward-difference step on `log p`.
const H: f64 = 1e-6;

/// The bounds of `log p` and the parameters held at their start values.
pub(super) struct Bounds {
    /// Lower bounds of the optimisation values.
    pub(super) lower: [f64; NP],
    /// Upper bounds of the optimisation values.
    pub(super) upper: [f64; NP],
    /// Held at the start value (a lab file's measurement).
    pub(super) held: [bool; NP],
}

impl Bounds {
    /// Whether `log p` of parameter `k` sits on its lower or upper bound.
    pub(super) fn on_bound(&self, logp: &[f64; NP], k: usize) -> bool {
        (logp[k] - self.lower[k].ln()).abs() < 1e-9 || self.on_upper(logp, k)
    }

    /// Whether `log p` of parameter `k` sits on its upper bound.
    pub(super) fn on_upper(&self, logp: &[f64; NP], k: usize) -> bool {
        (logp[k] - self.upper[k].ln()).abs() < 1e-9
    }
}

/// What a stage reached.
pub(super) struct Stage {
    /// Iterations run.
    pub(super) iterations: usize,
    /// Whether the tolerance was met (or no damping lowered the cost).
    pub(super) converged: bool,
    /// The cost at the end.
    pub(super) cost: f64,
}

/// What a stage works with.
pub(super) struct Context<'a, 'b> {
    /// The logs and their simulation.
    pub(super) problem: &'a Problem<'b>,
    /// Bounds and held parameters.
    pub(super) bounds: &'a Bounds,
    /// The parameter set of a `log p`.
    pub(super) params_of: &'a (dyn Fn(&[f64; NP]) -> FurutaParams + Sync),
    /// Iteration limit.
    pub(super) max_iterations: usize,
    /// Relative cost decrease below which the stage has converged.
    pub(super) tolerance: f64,
    /// The logs' names, for the error of a fit that left the simulable region.
    pub(super) names: &'a str,
    /// Set to stop the work.
    pub(super) cancel: &'a AtomicBool,
}

impl Context<'_, '_> {
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    fn plant(&self, logp: &[f64; NP]) -> Option<(Plant, usize)> {
        self.problem.plant(&(self.params_of)(logp))
    }
}

/// Simulates every segment from its initial state at `logp`; the cost `Σ r²`.
fn start_residuals(
    cx: &Context<'_, '_>,
    segments: &mut [Segment],
    logp: &[f64; NP],
) -> Result<f64> {
    let base = cx
        .plant(logp)
        .ok_or_else(|| RipError::invalid("start", "does not give a plant that can be simulated"))?;
    let ok = segments
        .par_iter_mut()
        .map(|s| !cx.cancelled() && cx.problem.simulate(&base, s.log, s.k0, &s.x0, &mut s.r))
        .collect::<Vec<_>>();
    if cx.cancelled() {
        return Err(RipError::Cancelled);
    }
    if ok.iter().any(|v| !v) {
        return Err(RipError::invalid(
            "start",
            "the simulation from the start parameters diverges on these logs",
        ));
    }
    Ok(segments
        .iter()
        .map(|s| s.r.iter().map(|v| v * v).sum::<f64>())
        .sum())
}

/// Forward-difference Jacobian of every segment's residuals in its `jac` (parameters, then
/// its own initial state).
fn jacobians(cx: &Context<'_, '_>, segments: &mut [Segment], logp: &[f64; NP]) -> Result<()> {
    let plants: Vec<Option<(Plant, usize)>> = (0..NP)
        .map(|k| {
            let mut lp = *logp;
            lp[k] += H;
            cx.plant(&lp)
        })
        .collect();
    let base = cx.plant(logp).expect("accepted parameters simulate");
    let ok: Vec<bool> = segments
        .par_iter_mut()
        .map(|s| {
            let rows = 2 * s.n;
            let (r, jac, trial) = (&s.r, &mut s.jac, &mut s.trial);
            for (k, plant) in plants.iter().enumerate() {
                let Some(plant) = plant else { return false };
                if cx.cancelled() || !cx.problem.simulate(plant, s.log, s.k0, &s.x0, trial) {
                    return false;
                }
                for i in 0..rows {
                    jac[k * rows + i] = (trial[i] - r[i]) / H;
                }
            }
            for c in 0..4 {
                let hx = 1e-6 * (1.0 + s.x0[c].abs());
                let mut x0 = s.x0;
                x0[c] += hx;
                if cx.cancelled() || !cx.problem.simulate(&base, s.log, s.k0, &x0, trial) {
                    return false;
                }
                for i in 0..rows {
                    jac[(NP + c) * rows + i] = (trial[i] - r[i]) / hx;
                }
            }
            true
        })
        .collect();
    if cx.cancelled() {
        return Err(RipError::Cancelled);
    }
    if ok.iter().any(|v| !v) {
        return Err(RipError::invalid(
            "logs",
            format!(
                "{}: the fit left the region where the model can be simulated on these logs \
                 (the simulation diverges next to the parameters it reached): the start set is \
                 too far from the rig; weigh and measure it (a lab file with mp, Lp, mr, Lr, \
                 Rm) and check that the logs are of open-loop excitation runs",
                cx.names
            ),
        ));
    }
    Ok(())
}

/// The damped step for `lambda`, projected onto the bounds: `(log p, full step)`, or `None`
/// when the damped normal equations are not positive definite.
fn damped_step(
    cx: &Context<'_, '_>,
    normal: &DMatrix<f64>,
    grad: &DVector<f64>,
    logp: &[f64; NP],
    lambda: f64,
) -> Option<([f64; NP], DVector<f64>)> {
    let n = normal.nrows();
    let mut lhs = normal.clone();
    for k in 0..n {
        lhs[(k, k)] += lambda * normal[(k, k)].max(1e-12);
    }
    let mut rhs = -grad;
    for k in (0..NP).filter(|&k| cx.bounds.held[k]) {
        lhs.row_mut(k).fill(0.0);
        lhs.column_mut(k).fill(0.0);
        lhs[(k, k)] = 1.0;
        rhs[k] = 0.0;
    }
    let step = lhs.cholesky()?.solve(&rhs);
    let b = cx.bounds;
    let trial =
        std::array::from_fn(|k| (logp[k] + step[k]).clamp(b.lower[k].ln(), b.upper[k].ln()));
    Some((trial, step))
}

/// The cost of a trial step (parameters and initial states), its residuals in each segment's
/// `trial`; `None` when a segment cannot be simulated.
fn trial_cost(
    cx: &Context<'_, '_>,
    segments: &mut [Segment],
    plant: &(Plant, usize),
    step: &DVector<f64>,
) -> Result<Option<f64>> {
    let cost: Option<f64> = segments
        .par_iter_mut()
        .enumerate()
        .map(|(si, s)| {
            if cx.cancelled() {
                return None;
            }
            let mut x0 = s.x0;
            for c in 0..4 {
                x0[c] += step[NP + 4 * si + c];
            }
            cx.problem
                .simulate(plant, s.log, s.k0, &x0, &mut s.trial)
                .then(|| s.trial.iter().map(|v| v * v).sum::<f64>())
        })
        .sum();
    if cx.cancelled() {
        return Err(RipError::Cancelled);
    }
    Ok(cost)
}

/// Levenberg–Marquardt on `log p` and the segments' initial states from `logp`, updated in
/// place, as are the segments' states and residuals.
pub(super) fn stage(
    cx: &Context<'_, '_>,
    segments: &mut [Segment],
    logp: &mut [f64; NP],
) -> Result<Stage> {
    let mut cost = start_residuals(cx, segments, logp)?;
    let n_unknowns = NP + 4 * segments.len();
    let mut normal = DMatrix::<f64>::zeros(n_unknowns, n_unknowns);
    let mut grad = DVector::<f64>::zeros(n_unknowns);
    let mut lambda = 1e-2;
    let mut out = Stage {
        iterations: 0,
        converged: false,
        cost,
    };
    while out.iterations < cx.max_iterations {
        out.iterations += 1;
        jacobians(cx, segments, logp)?;
        assemble(segments, &mut normal, &mut grad);
        let mut improved = false;
        for _ in 0..12 {
            let Some((trial_logp, step)) = damped_step(cx, &normal, &grad, logp, lambda) else {
                lambda *= 10.0;
                continue;
            };
            let Some(trial_plant) = cx.plant(&trial_logp) else {
                lambda *= 4.0;
                continue;
            };
            // A point whose neighbours cannot be simulated (a stiff friction law, an arm
            // inertia at its limit) would end the fit at the next Jacobian: step shorter.
            if (0..NP).any(|k| {
                let mut lp = trial_logp;
                lp[k] += H;
                cx.plant(&lp).is_none()
            }) {
                lambda *= 4.0;
                continue;
            }
            match trial_cost(cx, segments, &trial_plant, &step)? {
                Some(c) if c < cost => {
                    let small = cost - c <= cx.tolerance * cost;
                    for (si, s) in segments.iter_mut().enumerate() {
                        for c in 0..4 {
                            s.x0[c] += step[NP + 4 * si + c];
                        }
                        std::mem::swap(&mut s.r, &mut s.trial);
                    }
                    *logp = trial_logp;
                    cost = c;
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = true;
                    out.converged = small;
                    break;
                }
                _ => lambda *= 4.0,
            }
        }
        if !improved {
            // No damping lowers the cost: a (local) minimum to working precision.
            out.converged = true;
            break;
        }
        if out.converged {
            break;
        }
    }
    out.cost = cost;
    Ok(out)
}
