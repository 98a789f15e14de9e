//! Batches of closed-loop runs: which plant variant and noise seed each run uses
//! ([`batch_runs`]), and running them in parallel, each on its own controller.

use std::sync::atomic::AtomicBool;

use rayon::prelude::*;

use super::{simulate_cancellable, SimConfig, SimResult, NEVER};
use crate::controller::Controller;
use crate::error::{Result, RipError};
use crate::plant::Plant;

/// How a batch combines its plant variants with its noise seeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pairing {
    /// Every `(plant, seed)` combination, plant-major:
    /// `plants[0]×seeds[0], plants[0]×seeds[1], …, plants[1]×seeds[0], …`.
    Product,
    /// Run `i` is `plants[i]` with `seeds[i]` (one fresh plant variant and noise seed per run);
    /// both lists must have the same length.
    OneToOne,
}

/// The `(plant index, seed)` runs of a batch of `n_plants` plant variants and `seeds`, in run
/// order, as [`simulate_runs`] takes them.
///
/// Fails, naming the argument, without plants (`plants`), without seeds (`seeds`), or for
/// [`Pairing::OneToOne`] when the counts differ (`seeds`).
pub fn batch_runs(n_plants: usize, seeds: &[u64], pairing: Pairing) -> Result<Vec<(usize, u64)>> {
    if n_plants == 0 {
        return Err(RipError::invalid("plants", "need at least one plant"));
    }
    if seeds.is_empty() {
        return Err(RipError::invalid("seeds", "need at least one seed"));
    }
    match pairing {
        Pairing::Product => Ok((0..n_plants)
            .flat_map(|p| seeds.iter().map(move |&s| (p, s)))
            .collect()),
        Pairing::OneToOne if n_plants != seeds.len() => Err(RipError::invalid(
            "seeds",
            format!(
                "paired runs need one seed per plant ({n_plants} plants, {} seeds)",
                seeds.len()
            ),
        )),
        Pairing::OneToOne => Ok(seeds.iter().copied().enumerate().collect()),
    }
}

/// Runs every `(plant variant, seed)` pair in parallel on all cores (rayon).
///
/// `controllers` holds one independent controller per run, in the order
/// `plants[0]×seeds[0], plants[0]×seeds[1], …, plants[1]×seeds[0], …` (so
/// `plants.len() · seeds.len()` of them); the results come back in the same order. Each run uses
/// `config` with its own seed.
pub fn simulate_batch(
    plants: &[Plant],
    seeds: &[u64],
    config: &SimConfig,
    controllers: Vec<Box<dyn Controller>>,
) -> Result<Vec<SimResult>> {
    config.validate()?;
    let runs = batch_runs(plants.len(), seeds, Pairing::Product)?;
    if controllers.len() != runs.len() {
        return Err(RipError::invalid(
            "controllers",
            format!(
                "need one per run ({} plants × {} seeds = {}), got {}",
                plants.len(),
                seeds.len(),
                runs.len(),
                controllers.len()
            ),
        ));
    }
    simulate_runs(plants, &runs, config, controllers)
}

/// Runs an explicit list of `(plant index, seed)` pairs in parallel on all cores (rayon), one
/// controller per run, results in the same order. Monte Carlo studies that draw a fresh plant
/// variant *and* a fresh noise seed per run use this instead of [`simulate_batch`]'s product.
pub fn simulate_runs(
    plants: &[Plant],
    runs: &[(usize, u64)],
    config: &SimConfig,
    controllers: Vec<Box<dyn Controller>>,
) -> Result<Vec<SimResult>> {
    simulate_runs_cancellable(plants, runs, config, controllers, &NEVER)
}

/// [`simulate_runs`] that stops with [`RipError::Cancelled`] soon after `cancel` is set: no run
/// starts after it, and running ones stop within one control sample.
pub fn simulate_runs_cancellable(
    plants: &[Plant],
    runs: &[(usize, u64)],
    config: &SimConfig,
    controllers: Vec<Box<dyn Controller>>,
    cancel: &AtomicBool,
) -> Result<Vec<SimResult>> {
    config.validate()?;
    if runs.is_empty() {
        return Err(RipError::invalid("runs", "need at least one run"));
    }
    if let Some(&(bad, _)) = runs.iter().find(|(p, _)| *p >= plants.len()) {
        return Err(RipError::invalid(
            "runs",
            format!("plant index {bad} out of range for {} plants", plants.len()),
        ));
    }
    if controllers.len() != runs.len() {
        return Err(RipError::invalid(
            "controllers",
            format!(
                "need one per run ({}), got {}",
                runs.len(),
                controllers.len()
            ),
        ));
    }
    controllers
        .into_par_iter()
        .zip(runs.par_iter())
        .map(|(mut controller, &(plant, seed))| {
            let cfg = SimConfig {
                seed,
                ..config.clone()
            };
            simulate_cancellable(&plants[plant], controller.as_mut(), &cfg, cancel)
        })
        .collect()
}

/// [`simulate_batch`] for a cloneable controller: each run gets its own clone of `controller`.
pub fn simulate_batch_cloned<C>(
    plants: &[Plant],
    seeds: &[u64],
    config: &SimConfig,
    controller: &C,
) -> Result<Vec<SimResult>>
where
    C: Controller + Clone + 'static,
{
    let controllers = (0..plants.len() * seeds.len())
        .map(|_| Box::new(controller.clone()) as Box<dyn Controller>)
        .collect();
    simulate_batch(plants, seeds, config, controllers)
}
