//! The robustness runs: rigs drawn around the file's ([`Perturbation`]) and the fraction of
//! them each tuned controller balances ([`robustness`]).

use std::sync::atomic::AtomicBool;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::plant::{FurutaParams, Plant};
use crate::sim::simulate;
use crate::spec::{ControllerKind, Spec, SpecError};

use super::settings::check_cancel;

/// How the robustness runs perturb the rig.
#[derive(Debug, Clone, PartialEq)]
pub enum Perturbation {
    /// Each physical parameter times an independent uniform factor in `1 ± spread`.
    Relative(f64),
    /// `values · exp(N(0, log_covariance))` on the named parameters (the identification's
    /// `[covariance]`; names as [`crate::spec::Param`] spells them), the rest as they are.
    LogNormal {
        /// The parameters.
        names: Vec<String>,
        /// The covariance of their logarithms (row-major, `n × n`).
        log_covariance: Vec<f64>,
    },
}

/// A rig drawn around `p` by `perturbation` with `rng`.
pub fn perturb(p: &FurutaParams, perturbation: &Perturbation, rng: &mut StdRng) -> FurutaParams {
    let mut v = p.to_array();
    match perturbation {
        Perturbation::Relative(spread) => {
            // g (the last entry of to_array's order is not a rig property) stays.
            let g = p.g;
            for x in v.iter_mut() {
                *x *= 1.0 + spread * (2.0 * rng.gen::<f64>() - 1.0);
            }
            let mut out = FurutaParams::from_array(v);
            out.g = g;
            out
        }
        Perturbation::LogNormal {
            names,
            log_covariance,
        } => {
            let n = names.len();
            let cov = nalgebra::DMatrix::from_row_slice(n, n, log_covariance);
            // Parameters the logs do not determine (inf) or held (0) are left as they are.
            let finite: Vec<usize> = (0..n)
                .filter(|&i| cov[(i, i)].is_finite() && cov[(i, i)] > 0.0)
                .collect();
            let sub = nalgebra::DMatrix::from_fn(finite.len(), finite.len(), |i, j| {
                cov[(finite[i], finite[j])]
            });
            let Some(chol) = sub.cholesky() else {
                return *p;
            };
            let z = nalgebra::DVector::from_fn(finite.len(), |_, _| standard_normal(rng));
            let d = chol.l() * z;
            let mut out = *p;
            for (k, &i) in finite.iter().enumerate() {
                if let Some(param) = crate::spec::Param::from_name(&names[i]) {
                    let f = param.field(&mut out);
                    *f *= d[k].exp();
                }
            }
            out
        }
    }
}

fn standard_normal(rng: &mut StdRng) -> f64 {
    // Box–Muller.
    let u1 = rng.gen::<f64>().max(f64::MIN_POSITIVE);
    let u2 = rng.gen::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// For each controller of `spec` (designed on the file's model), the fraction of `runs`
/// rigs drawn by `perturbation` (seeds from `seed`) on which it balances: no fall over the
/// `[reference]` run. Runs whose drawn parameters are not a valid rig are redrawn.
pub fn robustness(
    spec: &Spec,
    ts: f64,
    perturbation: &Perturbation,
    runs: usize,
    seed: u64,
) -> Result<Vec<(ControllerKind, f64)>, SpecError> {
    robustness_with(spec, ts, perturbation, runs, seed, &AtomicBool::new(false))
}

/// [`robustness`], stopping with an error between two runs once `cancel` is set.
pub fn robustness_with(
    spec: &Spec,
    ts: f64,
    perturbation: &Perturbation,
    runs: usize,
    seed: u64,
    cancel: &AtomicBool,
) -> Result<Vec<(ControllerKind, f64)>, SpecError> {
    let design = spec.design(ts)?;
    let nominal = spec.plant.params();
    let mut rng = StdRng::seed_from_u64(seed);
    let mut plants = Vec::with_capacity(runs);
    while plants.len() < runs {
        check_cancel(cancel)?;
        let p = perturb(&nominal, perturbation, &mut rng);
        if let Ok(mut plant) = Plant::new(p) {
            if let Some(cs) = spec.plant.arm_breakaway {
                plant = plant.with_arm_breakaway(cs.max(p.cr)).unwrap_or(plant);
            }
            plants.push(plant);
        }
    }
    let mut out = Vec::new();
    for kind in ControllerKind::ALL {
        let mut controller = design.controller(kind)?;
        let mut ok = 0usize;
        for (i, plant) in plants.iter().enumerate() {
            check_cancel(cancel)?;
            let cfg = spec.sim_config(ts, seed.wrapping_add(i as u64));
            let run = simulate(plant, controller.as_mut(), &cfg)
                .map_err(|e| SpecError::new("plant", format!("simulation: {e}")))?;
            if !(run.fell || run.diverged) {
                ok += 1;
            }
        }
        out.push((kind, ok as f64 / runs.max(1) as f64));
    }
    Ok(out)
}
