//! Monte Carlo batches that keep per-run metrics instead of trajectories.
//!
//! A [`simulate`](crate::simulate) record costs about 0.4 MB per 10 s run; a study of 10⁵–10⁶
//! runs cannot hold them. [`simulate_metrics`] runs the same closed loop
//! ([`crate::sim`]) but folds each sample into a fixed-size accumulator as it is produced, so a
//! run allocates only its controller's clone and a batch grows by one [`RunMetrics`]
//! (`size_of::<RunMetrics>()` bytes) per run.
//!
//! Runs are identified by an index `i`: the plant variant and the noise seed of run `i` depend
//! on `i` alone (never on the order runs are scheduled in, the thread count or how a study is cut
//! into chunks), so running indices `0..n` at once or as `0..k`, `k..n` gives identical metrics.
//! [`MonteCarlo`] draws the usual variants (independent uniform factors on chosen parameters);
//! any other scheme is a closure `Fn(u64) -> Result<(Plant, u64)>`.
//!
//! Per run, with samples `k = 0 … N−1` (the run cut at a fall):
//!
//! ```text
//! rmse          = metrics::table1_rmse                        (the paper's Tab. 1 indices)
//! peak_voltage  = max_k |u_k|                                 (applied, after saturation)
//! peak_arm      = max_k |θ_k|                                 (true arm angle at the samples)
//! settle_time   = t_j, the earliest sample with |θ_k − θ_ref,k| ≤ band for all k ≥ j
//!                 (NaN if the run fell or its last sample is outside the band)
//! fall_time     = time of the fall to the RK4 substep (NaN if it stayed up)
//! time_to_upright = the swing-up's catch time (NaN without a catch)
//! swing_up_ok   = sim::swing_up_succeeded: caught, then balanced to the end
//! ```

use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use crate::controller::Controller;
use crate::error::{Result, RipError};
use crate::metrics::Table1;
use crate::plant::{FurutaParams, Plant};
use crate::sim::{prepare, run_loop, swing_up_succeeded, Recorder, SimConfig};
use crate::spec::Param;

/// Largest number of runs one call may take (the result alone would be tens of MB beyond it;
/// split a larger study into calls over consecutive index ranges).
pub const MAX_RUNS: u64 = 10_000_000;

/// The metrics of one run (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunMetrics {
    /// Index of the run.
    pub run: u64,
    /// Noise seed the run used.
    pub seed: u64,
    /// The paper's Tab. 1 indices `[arm (rad), pendulum (rad), voltage (V)]`.
    pub rmse: [f64; 3],
    /// Whether the pendulum fell before the end.
    pub fell: bool,
    /// Whether the integration diverged (the state overflowed) before the end: a numerical
    /// failure, not a fall ([`SimResult::diverged`](crate::SimResult::diverged)).
    pub diverged: bool,
    /// Time of the fall (s); `NaN` if it stayed up.
    pub fall_time: f64,
    /// Largest applied `|u|` (V).
    pub peak_voltage: f64,
    /// Largest true `|θ|` at the samples (rad).
    pub peak_arm: f64,
    /// Time (s) from which the arm stays within the settling band to the end; `NaN` if never.
    pub settle_time: f64,
    /// Time to upright (s): the catch time of a swing-up supervisor
    /// ([`SimResult::time_to_upright`](crate::SimResult::time_to_upright)); `NaN` without a
    /// catch.
    pub time_to_upright: f64,
    /// Whether the swing-up succeeded ([`swing_up_succeeded`]): caught, then balanced to the
    /// end; `false` for a balance controller, which never swings up.
    pub swing_up_succeeded: bool,
    /// Control samples taken.
    pub samples: u32,
    /// Steps in which the controller used its fallback.
    pub fallbacks: u32,
}

/// What [`simulate_metrics`] measures beyond the configuration of the runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MetricsOptions {
    /// Half-width (rad) of the band around the arm reference that counts as settled.
    pub settle_band: f64,
}

impl Default for MetricsOptions {
    fn default() -> Self {
        // 2 % of the paper's 1 rad arm step.
        Self { settle_band: 0.02 }
    }
}

impl MetricsOptions {
    /// Checks every field; the error names the bad one.
    pub fn validate(&self) -> Result<()> {
        if !(self.settle_band.is_finite() && self.settle_band > 0.0) {
            return Err(RipError::invalid(
                "settle_band",
                format!("must be positive and finite, got {}", self.settle_band),
            ));
        }
        Ok(())
    }
}

/// The usual Monte Carlo variants: run `i` multiplies each chosen parameter of `base` by an
/// independent factor drawn uniformly from `[1 − perturbation, 1 + perturbation]` and uses noise
/// seed `seed + i` (wrapping).
///
/// The factors of run `i` come from a generator seeded with a mix of `seed` and `i`, so they
/// are the same whichever other runs are computed alongside it.
#[derive(Debug, Clone, PartialEq)]
pub struct MonteCarlo {
    /// The nominal parameters.
    pub base: FurutaParams,
    /// Relative half-width of the uniform factors, in `[0, 1)`.
    pub perturbation: f64,
    /// The parameters that vary, each drawn in this order.
    pub parameters: Vec<Param>,
    /// Noise seed of run 0; also seeds the parameter draws.
    pub seed: u64,
}

/// SplitMix64's finaliser: decorrelates nearby integers (run indices) into seeds.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl MonteCarlo {
    /// Checks the settings; the error names the bad one.
    pub fn validate(&self) -> Result<()> {
        self.base.validate()?;
        if !(self.perturbation.is_finite() && (0.0..1.0).contains(&self.perturbation)) {
            return Err(RipError::invalid(
                "perturbation",
                format!("must be in [0, 1), got {}", self.perturbation),
            ));
        }
        Ok(())
    }

    /// The parameters spelled `names` ([`Param::name`], as in files and in Python); the error
    /// names `parameters` and lists the choices.
    pub fn parameters_named<S: AsRef<str>>(names: &[S]) -> Result<Vec<Param>> {
        names
            .iter()
            .map(|name| {
                let name = name.as_ref();
                Param::from_name(name).ok_or_else(|| {
                    let choices: Vec<&str> = Param::ALL.iter().map(|p| p.name()).collect();
                    RipError::invalid(
                        "parameters",
                        format!(
                            "unknown parameter {name:?}; choose from {}",
                            choices.join(", ")
                        ),
                    )
                })
            })
            .collect()
    }

    /// The plant and noise seed of run `i`.
    pub fn run(&self, i: u64) -> Result<(Plant, u64)> {
        let mut params = self.base;
        if self.perturbation > 0.0 && !self.parameters.is_empty() {
            let stream = mix(self.seed ^ 0x5045_5254_5552_4221);
            let mut rng = StdRng::seed_from_u64(mix(stream.wrapping_add(i)));
            let p = self.perturbation;
            for &param in &self.parameters {
                *param.field(&mut params) *= rng.gen_range(1.0 - p..=1.0 + p);
            }
        }
        let plant = Plant::new(params)?;
        Ok((plant, self.seed.wrapping_add(i)))
    }
}

/// Run indices `first_run .. first_run + runs`; the error names `first_run` when the end
/// does not fit in a `u64`.
pub fn run_range(first_run: u64, runs: u64) -> Result<Range<u64>> {
    let end = first_run.checked_add(runs).ok_or_else(|| {
        RipError::invalid(
            "first_run",
            format!("first_run + runs overflows ({first_run} + {runs})"),
        )
    })?;
    Ok(first_run..end)
}

/// Folds the samples of one run into its metrics.
struct Accumulator {
    table1: Table1,
    band: f64,
    peak: f64,
    peak_arm: f64,
    samples: usize,
    /// Index of the first sample after the last one outside the band.
    settled_from: usize,
    settled_at: f64,
}

impl Recorder for Accumulator {
    #[inline]
    fn sample(
        &mut self,
        t: f64,
        x: &[f64; 4],
        y: &[f64; 2],
        u: f64,
        r: &[f64; 2],
        _estimate: Option<&[f64]>,
        _elapsed: f64,
    ) {
        self.table1.push(y, u, r);
        self.peak = self.peak.max(u.abs());
        self.peak_arm = self.peak_arm.max(x[0].abs());
        let inside = (x[0] - r[0]).abs() <= self.band;
        if !inside {
            self.settled_from = self.samples + 1;
        } else if self.settled_from == self.samples {
            self.settled_at = t;
        }
        self.samples += 1;
    }
}

/// Run `index` of a study on the calling thread: its own controller from `controller()`, its
/// plant and seed from `variant(index)`, metrics only. [`simulate_metrics`] runs these in
/// parallel. Allocates only what `variant` and `controller` do (and, for the Clarabel MPC, its
/// solver per step); nothing per sample.
pub fn run_metrics(
    index: u64,
    variant: &(dyn Fn(u64) -> Result<(Plant, u64)> + Sync),
    controller: &(dyn Fn() -> Box<dyn Controller> + Sync),
    config: &SimConfig,
    options: &MetricsOptions,
    cancel: &AtomicBool,
) -> Result<RunMetrics> {
    if cancel.load(Ordering::Relaxed) {
        return Err(RipError::Cancelled);
    }
    let (plant, seed) = variant(index)?;
    let mut ctrl = controller();
    let cfg = SimConfig {
        seed,
        ..config.clone()
    };
    let n = prepare(ctrl.as_ref(), &cfg)?;
    let mut acc = Accumulator {
        table1: Table1::default(),
        band: options.settle_band,
        peak: 0.0,
        peak_arm: 0.0,
        samples: 0,
        settled_from: 0,
        settled_at: f64::NAN,
    };
    let end = run_loop(&plant, ctrl.as_mut(), &cfg, n, &mut acc, cancel)?;
    let settled = !end.fell && !end.diverged && acc.settled_from < acc.samples;
    Ok(RunMetrics {
        run: index,
        seed,
        rmse: acc.table1.finish(),
        fell: end.fell,
        diverged: end.diverged,
        fall_time: end.fall_time.unwrap_or(f64::NAN),
        peak_voltage: acc.peak,
        peak_arm: acc.peak_arm,
        settle_time: if settled { acc.settled_at } else { f64::NAN },
        time_to_upright: end.catch_time.unwrap_or(f64::NAN),
        swing_up_succeeded: swing_up_succeeded(
            end.catch_time,
            end.fell,
            end.diverged,
            end.stop_cause,
        ),
        samples: acc.samples as u32,
        fallbacks: end.fallbacks as u32,
    })
}

/// Runs `runs` (a range of run indices) in parallel on all cores and returns their metrics in
/// index order (module docs); no trajectory is kept.
///
/// - `variant(i)` gives run `i`'s plant and noise seed (e.g. [`MonteCarlo::run`]); it must
///   depend on `i` only, which makes every run reproducible on its own.
/// - `controller()` gives a fresh controller for one run (typically a clone of a template);
///   it is [`reset`](Controller::reset) before the run.
/// - `config` is used with each run's seed in place of its own.
/// - `done` is incremented after each finished run (for progress reports from another thread).
/// - Setting `cancel` (from another thread) stops the batch with [`RipError::Cancelled`]: no run
///   starts after it and running ones stop within one control sample.
///
/// Memory: the returned `Vec` (one [`RunMetrics`] per run) plus, per worker thread, one
/// controller clone and one plant; nothing grows with the length of a run.
pub fn simulate_metrics(
    runs: Range<u64>,
    config: &SimConfig,
    options: &MetricsOptions,
    variant: &(dyn Fn(u64) -> Result<(Plant, u64)> + Sync),
    controller: &(dyn Fn() -> Box<dyn Controller> + Sync),
    done: &AtomicU64,
    cancel: &AtomicBool,
) -> Result<Vec<RunMetrics>> {
    config.validate()?;
    options.validate()?;
    let count = runs.end.saturating_sub(runs.start);
    if count == 0 || count > MAX_RUNS {
        return Err(RipError::invalid(
            "runs",
            format!("need 1 to {MAX_RUNS} runs per call, got {count}"),
        ));
    }
    // Settings that would fail every run fail once, before any work is spread out.
    prepare(controller().as_ref(), config)?;
    runs.into_par_iter()
        .map(|i| {
            let m = run_metrics(i, variant, controller, config, options, cancel);
            done.fetch_add(1, Ordering::Relaxed);
            m
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::table1_rmse;
    use crate::regulators::Lqg;
    use crate::sim::{simulate, Reference, SensorModel};

    fn config() -> SimConfig {
        SimConfig {
            duration: 3.0,
            x0: [0.0, 0.0, 0.05, 0.0],
            reference: Reference::Step {
                time: 0.5,
                value: [1.0, 0.0],
            },
            sensor: SensorModel {
                counts_per_rev: Some([2048.0, 2048.0]),
                noise_std: [1e-3, 1e-3],
                offsets: [0.0; 2],
            },
            ..Default::default()
        }
    }

    fn study() -> MonteCarlo {
        MonteCarlo {
            base: FurutaParams::paper(),
            perturbation: 0.1,
            parameters: Param::ALL.to_vec(),
            seed: 7,
        }
    }

    fn metrics(runs: Range<u64>, cancel: &AtomicBool) -> Result<Vec<RunMetrics>> {
        let mc = study();
        let lqg = Lqg::paper().unwrap();
        simulate_metrics(
            runs,
            &config(),
            &MetricsOptions::default(),
            &|i| mc.run(i),
            &|| Box::new(lqg.clone()),
            &AtomicU64::new(0),
            cancel,
        )
    }

    #[test]
    fn metrics_match_the_full_record_of_each_run() {
        let never = AtomicBool::new(false);
        let all = metrics(0..6, &never).unwrap();
        let mc = study();
        for m in &all {
            let (plant, seed) = mc.run(m.run).unwrap();
            let cfg = SimConfig { seed, ..config() };
            let res = simulate(&plant, &mut Lqg::paper().unwrap(), &cfg).unwrap();
            assert_eq!(m.rmse, table1_rmse(&res));
            assert_eq!(m.fell, res.fell);
            assert_eq!(m.samples as usize, res.len());
            let peak = res.u.iter().fold(0.0f64, |a, u| a.max(u.abs()));
            assert_eq!(m.peak_voltage, peak);
            // Settling by brute force: the earliest sample after which every arm error is in
            // the band.
            let inside: Vec<bool> = (0..res.len())
                .map(|k| (res.x[k][0] - res.r[k][0]).abs() <= 0.02)
                .collect();
            let from = (0..=res.len())
                .rev()
                .take_while(|&j| j == res.len() || inside[j])
                .last()
                .unwrap();
            if res.fell || from == res.len() {
                assert!(m.settle_time.is_nan());
            } else {
                assert_eq!(m.settle_time, res.t[from]);
                assert!(m.settle_time > 0.5);
            }
        }
        assert!(all.iter().any(|m| m.settle_time.is_finite()));
    }

    #[test]
    fn swing_up_metrics_match_the_full_record() {
        use crate::spec::study::{hanging_config, supervised};
        use crate::spec::{ControllerKind, Spec};
        let spec = Spec::default();
        let design = spec.design(crate::paper::TS).unwrap();
        let config = SimConfig {
            duration: 6.0,
            ..hanging_config(&spec, crate::paper::TS, 0)
        };
        let mc = study();
        let make = || -> Box<dyn Controller> {
            Box::new(supervised(&spec, &design, ControllerKind::Lqr).unwrap())
        };
        let never = AtomicBool::new(false);
        let all = simulate_metrics(
            0..4,
            &config,
            &MetricsOptions::default(),
            &|i| mc.run(i),
            &make,
            &AtomicU64::new(0),
            &never,
        )
        .unwrap();
        for m in &all {
            let (plant, seed) = mc.run(m.run).unwrap();
            let res = simulate(
                &plant,
                make().as_mut(),
                &SimConfig {
                    seed,
                    ..config.clone()
                },
            )
            .unwrap();
            assert_eq!(
                m.time_to_upright.to_bits(),
                res.catch_time.unwrap_or(f64::NAN).to_bits()
            );
            assert_eq!(
                m.swing_up_succeeded,
                res.catch_time.is_some() && !res.fell && res.stop_cause.is_none()
            );
            let peak = res.x.iter().fold(0.0f64, |a, x| a.max(x[0].abs()));
            assert_eq!(m.peak_arm, peak);
            // The step comes reference.step_time after the catch, never before.
            if let Some(tc) = res.catch_time {
                for (t, r) in res.t.iter().zip(&res.r) {
                    let stepped = *t >= tc + spec.reference.step_time - 1e-9;
                    assert_eq!(r[0], if stepped { 1.0 } else { 0.0 }, "t {t}, catch {tc}");
                }
            }
        }
        assert!(all.iter().any(|m| m.swing_up_succeeded));
    }

    #[test]
    fn a_run_depends_on_its_index_only() {
        let never = AtomicBool::new(false);
        let whole = metrics(0..8, &never).unwrap();
        let mut parts = metrics(0..3, &never).unwrap();
        parts.extend(metrics(3..8, &never).unwrap());
        // NaN (no fall, not settled) is not equal to itself; the bits are.
        assert_eq!(format!("{whole:?}"), format!("{parts:?}"));
        assert_ne!(whole[0].rmse, whole[1].rmse);
        assert_eq!(whole[5].seed, 7 + 5);
    }

    #[test]
    fn a_set_cancel_flag_stops_the_batch() {
        let cancel = AtomicBool::new(true);
        assert_eq!(metrics(0..4, &cancel), Err(RipError::Cancelled));
    }

    #[test]
    fn parameters_are_named_as_in_files_and_run_ranges_do_not_wrap() {
        let named = MonteCarlo::parameters_named(&["mp", "Lr", "km"]).unwrap();
        assert_eq!(named, [Param::Mp, Param::Lr, Param::Km]);
        let err = MonteCarlo::parameters_named(&["mp", "mass"]).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("parameters") && text.contains("\"mass\""),
            "{text}"
        );
        assert!(text.contains("Lr") && text.contains("km"), "{text}");
        assert_eq!(run_range(5, 3), Ok(5..8));
        let err = run_range(u64::MAX - 1, 2).unwrap_err();
        assert!(err.to_string().contains("first_run"), "{err}");
        // A perturbed parameter is the named field, scaled within the band; the others stay.
        let mc = MonteCarlo {
            parameters: named,
            ..study()
        };
        let (plant, _) = mc.run(4).unwrap();
        let (base, got) = (FurutaParams::paper(), plant.params());
        for (b, v) in [(base.mp, got.mp), (base.lr, got.lr), (base.km, got.km)] {
            assert!(v != b && (v / b - 1.0).abs() <= 0.1, "{b} -> {v}");
        }
        assert_eq!((got.mr, got.jp, got.rm), (base.mr, base.jp, base.rm));
    }

    #[test]
    fn bad_settings_name_themselves() {
        let never = AtomicBool::new(false);
        let err = metrics(5..5, &never).unwrap_err();
        assert!(err.to_string().contains("runs"), "{err}");
        let bad = MonteCarlo {
            perturbation: 1.0,
            ..study()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("perturbation"));
    }
}
