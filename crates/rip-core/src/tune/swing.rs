//! The swing-up's settings, searched by Monte Carlo for the rig `riprs tune` tunes.
//!
//! Under ±10 % model error (and a dead zone and arm friction the file may not know) the
//! swing-up fails mostly at its catch and in the seconds after it: a catch region too wide for
//! the perturbed plant, an estimator handed over too soon, an arm still turning as the pendulum
//! arrives. The settings that govern those (`swing_up.catch_margin` of the predicted catch,
//! `rise_damping`) have no value that suits every rig: the last-rise brake
//! that lifts the `paper` preset from 85 to 96 % sinks `qube_servo2` (docs/swing-up.md), so
//! they are chosen per rig, on the rig's own statistics.
//!
//! **The study.** Each candidate is judged by [`swing_monte_carlo`] on the controllers the
//! tuning chose, [`SEARCH_RUNS`] draws per controller, the same draws for every candidate
//! (common random numbers: the comparison is not drowned in the draws' own spread). A
//! candidate's score is its number of successes summed over the three controllers, ties to the
//! one whose worst controller does best.
//!
//! **The search.** From the file's settings with the predicted catch on
//! (`catch_prediction = 1` s where it is off, `reference_return_rate = 0.5` rad/s where it is
//! 0: the catch of an arm off centre needs both), every combination of the values of
//! [`CANDIDATES`] is judged on [`SEARCH_RUNS`] draws, each run ending [`HELD_AFTER_CATCH`]
//! after the longest swing-up (what is compared is the success, not the step after it; the
//! handover's length, tried too, changed no success on either preset); the [`FINALISTS`] best
//! are judged again on [`FINAL_RUNS`] more, and the best of all their draws is kept. Where
//! no finalist's every controller has a Wilson 95 % upper bound of at least
//! [`FOUND_LOWER_BOUND`] (a controller holding 90 of 100 has one of 94.5 %), no candidate can
//! be confirmed and the best is kept without that second look.
//!
//! **The arrival.** The energy law aims a margin `δ G` above upright (`energy_margin`,
//! default 0.05), so that the pendulum reaches upright in finite time; it arrives still
//! moving, and one that is not caught goes over the top and round again with that energy.
//! With the catch settings kept, [`SLOW_ARRIVAL_MARGIN`] is tried in place of `δ` on the
//! finalists' same draws and kept when it holds as many catches (one fewer per controller
//! at most) and more runs pass over the top at most twice. On `qube_servo2`, whose pendulum
//! rises in one swing, it is kept: 99.5 % of 1000 runs pass over the top at most twice,
//! against 92.2 % at 0.05, every catch still held. On `paper` it is not: there the slower
//! arrival lost about 2 % of the catches (96.2 % against 98.2 %) for 99.7 % of runs within
//! two passes.
//!
//! **The method** is the file's: a file that asks for the planned swing-up
//! (`method = "trajectory"`) keeps it, its catch settings searched no further (a plan takes
//! seconds to design per candidate), and the record stores the plan's length and margins.
//!
//! **The verdict** ([`SwingVerdict`]), on [`CONFIRM_RUNS`] fresh draws per controller of the
//! settings kept (taken [`CONFIRM_BLOCK`] at a time, and ended once even a success on every
//! draw left would not reach the bound: the verdict is then decided), each run ending as the
//! search's do, [`HELD_AFTER_CATCH`] after its catch (the verdict is on the hold;
//! `riprs.swing_up_monte_carlo` runs the whole experiment and reports the step's tracking):
//! *found* when every controller's Wilson 95 % lower bound is at
//! least [`FOUND_LOWER_BOUND`]; *not found* otherwise; *impossible* when the energy bound
//! forbids any swing-up of the nominal rig (nothing is searched). `rip-rt run --swing-up`'s
//! pre-flight refuses every controller of a rig whose swing-up was not found
//! (`crate::preflight::swing`): the swing is the same for all three, and a rig is swung up
//! when its search says so, not controller by controller.

use std::sync::atomic::AtomicBool;

pub use crate::preflight::swing::{StoredPlan, StoredStudy, StoredSwingSearch, SwingVerdict};

use crate::spec::study::{
    swing_monte_carlo, swing_monte_carlo_draws, SwingMonteCarlo, SwingStudy, HELD_AFTER_CATCH,
};
use crate::spec::{ControllerKind, Spec, SpecError};
use crate::swingup::{feasibility, SwingUpMethod, SwingUpSettings, Verdict};

use super::settings::{check_cancel, Progress};

/// Draws per controller with which each candidate is judged.
pub const SEARCH_RUNS: u64 = 100;

/// Candidates judged again, on [`FINAL_RUNS`] more draws.
pub const FINALISTS: usize = 3;

/// Further draws per controller for each finalist.
pub const FINAL_RUNS: u64 = 300;

/// Fresh draws per controller on which the settings kept are confirmed.
pub const CONFIRM_RUNS: u64 = 1000;

/// Draws of the confirmation taken between two looks at whether it can still pass (module
/// docs, "The verdict"): the same draws whatever the machine, so the same verdict and record.
pub const CONFIRM_BLOCK: u64 = 100;

/// The smallest Wilson 95 % lower bound of the success rate over [`CONFIRM_RUNS`] with which a
/// controller holds its catches (a swing-up is *found* when every controller does). Set so
/// that what passes holds its catches at about 96.5 % or more: a lower bound of 93 % over
/// 200 further runs asks about that much (a controller at 96 % passed the confirmation at
/// 93 % on 400 runs and fell to 92.3 % on 200 others, generated rig 7).
pub const FOUND_LOWER_BOUND: f64 = 0.95;

/// The seed of the search's draws; the confirmation draws from the next ones.
const SEARCH_SEED: u64 = 2024;

/// One setting the search moves, with the values it tries.
pub struct Candidate {
    /// The `[swing_up]` key.
    pub key: &'static str,
    /// The values tried, in order.
    pub values: &'static [f64],
    /// Sets the value on settings.
    pub set: fn(&mut SwingUpSettings, f64),
}

/// The settings searched and their values (module docs).
pub const CANDIDATES: [Candidate; 2] = [
    Candidate {
        key: "catch_margin",
        values: &[0.2, 0.25, 0.35, 0.45],
        set: |s, v| s.catch_margin = v,
    },
    Candidate {
        key: "rise_damping",
        values: &[0.0, 15.0, 25.0],
        set: |s, v| s.rise_damping = v,
    },
];

/// The swing-up settings a search kept, with their confirmation.
#[derive(Debug, Clone, PartialEq)]
pub struct SwingSearch {
    /// The verdict.
    pub verdict: SwingVerdict,
    /// The settings kept (the file's when nothing was searched).
    pub settings: SwingUpSettings,
    /// Each controller's confirmation on [`CONFIRM_RUNS`] fresh draws (empty when
    /// impossible).
    pub confirmed: Vec<SwingMonteCarlo>,
    /// Candidates judged.
    pub tried: usize,
    /// The plan's length and margins on the nominal model, when the method kept is the plan.
    pub plan: Option<StoredPlan>,
}

impl SwingSearch {
    /// One line per controller: its successes, interval and the other figures of the study.
    pub fn summary(&self) -> String {
        if self.verdict == SwingVerdict::Impossible {
            return "impossible: the energy bound forbids a swing-up of this rig".to_string();
        }
        self.confirmed
            .iter()
            .map(|m| {
                let (lo, hi) = m.success_interval().unwrap_or((f64::NAN, f64::NAN));
                format!(
                    "{}: {} of {} held {:.0} s after the catch ({:.1} %, Wilson 95 % [{:.1}, \
                     {:.1}] %), {} excluded by the energy bound, {} caught on the first \
                     arrival, at most {} passes over the top",
                    m.controller.name(),
                    m.held,
                    m.judged(),
                    crate::spec::study::HELD_AFTER_CATCH,
                    100.0 * m.success_rate(),
                    100.0 * lo,
                    100.0 * hi,
                    m.excluded,
                    m.caught_on_first,
                    m.most_over_tops,
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    }
}

/// The settings the search starts from (module docs).
fn start(settings: &SwingUpSettings) -> SwingUpSettings {
    let mut s = settings.clone();
    if s.catch_prediction <= 0.0 {
        s.catch_prediction = 1.0;
    }
    if s.reference_return_rate <= 0.0 {
        s.reference_return_rate = 0.5;
    }
    s
}

/// Which draws a study takes: how many, from which seed, and where each run ends.
type Draws = (u64, u64, Option<f64>);

/// The study of `spec` with `settings` for every controller: `runs` draws from `seed`.
fn study(
    spec: &Spec,
    settings: &SwingUpSettings,
    ts: f64,
    (runs, seed, horizon): Draws,
    cancel: &AtomicBool,
) -> Result<Vec<SwingMonteCarlo>, SpecError> {
    let mut s = spec.clone();
    s.swing_up = settings.clone();
    let study = SwingStudy {
        runs,
        seed,
        horizon,
        ..SwingStudy::default()
    };
    ControllerKind::ALL
        .iter()
        .map(|&kind| {
            check_cancel(cancel)?;
            swing_monte_carlo(&s, kind, ts, &study, cancel)
        })
        .collect()
}

/// The score of a study (module docs): successes in all, then the worst controller's.
fn score(results: &[SwingMonteCarlo]) -> (u64, u64) {
    let total = results.iter().map(|m| m.held).sum();
    let worst = results.iter().map(|m| m.held).min().unwrap_or(0);
    (total, worst)
}

/// Each controller's study over two sets of draws together.
fn summed(first: &[SwingMonteCarlo], second: &[SwingMonteCarlo]) -> Vec<SwingMonteCarlo> {
    first
        .iter()
        .zip(second)
        .map(|(a, b)| a.combined(b))
        .collect()
}

/// Whether the Wilson 95 % lower bound of `held` successes in `judged` runs reaches `bound`.
fn reaches(held: u64, judged: u64, bound: f64) -> bool {
    crate::stats::wilson(held, judged, crate::stats::Z_95).is_ok_and(|(lo, _)| lo >= bound)
}

/// The confirmation (module docs) of `settings` on `spec`: [`CONFIRM_RUNS`] draws from `seed`
/// per controller, taken [`CONFIRM_BLOCK`] at a time. A controller's confirmation ends after
/// the block from which even a success on every draw left would not reach
/// [`FOUND_LOWER_BOUND`]: the verdict is then *not found* whatever the rest would hold, and
/// the controller's study says how many draws it took.
fn confirm(
    spec: &Spec,
    settings: &SwingUpSettings,
    ts: f64,
    (seed, horizon): (u64, Option<f64>),
    cancel: &AtomicBool,
) -> Result<Vec<SwingMonteCarlo>, SpecError> {
    let mut s = spec.clone();
    s.swing_up = settings.clone();
    let study = SwingStudy {
        runs: CONFIRM_RUNS,
        seed,
        horizon,
        ..SwingStudy::default()
    };
    let mut out = Vec::with_capacity(ControllerKind::ALL.len());
    for kind in ControllerKind::ALL {
        let mut total: Option<SwingMonteCarlo> = None;
        for start in (0..CONFIRM_RUNS).step_by(CONFIRM_BLOCK as usize) {
            check_cancel(cancel)?;
            let end = (start + CONFIRM_BLOCK).min(CONFIRM_RUNS);
            let part = swing_monte_carlo_draws(&s, kind, ts, &study, start..end, cancel)?;
            let sum = total.map_or(part, |t| t.combined(&part));
            let left = CONFIRM_RUNS - end;
            let hopeless = !reaches(sum.held + left, sum.judged() + left, FOUND_LOWER_BOUND);
            total = Some(sum);
            if hopeless {
                break;
            }
        }
        out.extend(total);
    }
    Ok(out)
}

/// Every combination of the values of [`CANDIDATES`] on `base`, in order.
fn grid(base: &SwingUpSettings) -> Vec<SwingUpSettings> {
    let mut out = vec![base.clone()];
    for candidate in &CANDIDATES {
        out = out
            .iter()
            .flat_map(|s| {
                candidate.values.iter().map(move |&v| {
                    let mut next = s.clone();
                    (candidate.set)(&mut next, v);
                    next
                })
            })
            .collect();
    }
    out
}

/// The number of steps [`search`] counts, for a progress count.
pub fn search_steps() -> usize {
    CANDIDATES.iter().map(|c| c.values.len()).product::<usize>() + FINALISTS + 2
}

/// The energy margin `δ` (`swing_up.energy_margin`) tried below the file's once the catch
/// settings are kept (module docs, "The arrival").
pub const SLOW_ARRIVAL_MARGIN: f64 = 0.005;

/// `best` with [`SLOW_ARRIVAL_MARGIN`] in place of its energy margin when, on the same draws
/// as `results` (the finalists' two looks, `draws`), that holds as many catches (one fewer per
/// controller at most) and passes over the top at most twice in more runs (module docs, "The
/// arrival").
fn slower_arrival(
    spec: &Spec,
    best: SwingUpSettings,
    results: &[SwingMonteCarlo],
    ts: f64,
    draws: (Draws, Draws),
    cancel: &AtomicBool,
) -> Result<SwingUpSettings, SpecError> {
    if best.energy_margin <= SLOW_ARRIVAL_MARGIN {
        return Ok(best);
    }
    let mut slower = best.clone();
    slower.energy_margin = SLOW_ARRIVAL_MARGIN;
    if slower.validate().is_err() {
        return Ok(best);
    }
    let tried = summed(
        &study(spec, &slower, ts, draws.0, cancel)?,
        &study(spec, &slower, ts, draws.1, cancel)?,
    );
    let total =
        |r: &[SwingMonteCarlo], f: fn(&SwingMonteCarlo) -> u64| -> u64 { r.iter().map(f).sum() };
    // One catch per controller is the draws' own grain, not a difference between the two.
    let grain = results.len() as u64;
    let holds = total(&tried, |m| m.held) + grain >= total(results, |m| m.held);
    let fewer_over =
        total(&tried, |m| m.at_most_two_over_tops) > total(results, |m| m.at_most_two_over_tops);
    Ok(if holds && fewer_over { slower } else { best })
}

/// Searches the swing-up settings of `spec` (its controllers as tuned) at sample time `ts`
/// (module docs), counting its steps in `progress` and stopping with an error once `cancel`
/// is set.
pub fn search(
    spec: &Spec,
    ts: f64,
    progress: &Progress,
    cancel: &AtomicBool,
) -> Result<SwingSearch, SpecError> {
    let plant = spec.plant()?;
    if feasibility(&plant, &spec.swing_up).verdict == Verdict::Impossible {
        return Ok(SwingSearch {
            verdict: SwingVerdict::Impossible,
            settings: spec.swing_up.clone(),
            confirmed: Vec::new(),
            tried: 0,
            plan: None,
        });
    }
    progress.add(search_steps());
    let start = start(&spec.swing_up);
    let horizon = Some(start.max_time + HELD_AFTER_CATCH);
    let mut best = start.clone();
    let mut tried = 0;
    if start.method == SwingUpMethod::Energy {
        let search = (SEARCH_RUNS, SEARCH_SEED, horizon);
        let mut scored: Vec<((u64, u64), SwingUpSettings, Vec<SwingMonteCarlo>)> = Vec::new();
        for s in grid(&start) {
            progress.step();
            if s.validate().is_err() {
                continue;
            }
            let results = study(spec, &s, ts, search, cancel)?;
            tried += 1;
            scored.push((score(&results), s, results));
        }
        // Best first; the sort is stable, so a tie keeps the grid's order.
        scored.sort_by_key(|s| std::cmp::Reverse(s.0));
        scored.truncate(FINALISTS);
        // Where no finalist's every controller has a Wilson upper bound reaching the bound,
        // none can be confirmed: more draws would not change the verdict, only its cost.
        let promising = scored.iter().any(|(_, _, results)| {
            results.iter().all(|m| {
                m.success_interval()
                    .is_some_and(|(_, hi)| hi >= FOUND_LOWER_BOUND)
            })
        });
        if !promising {
            if let Some((_, s, _)) = scored.first() {
                best = s.clone();
            }
            // The finalists' steps of the progress count, done by not taking them.
            scored.drain(..).for_each(|_| progress.step());
        }
        let more = (FINAL_RUNS, SEARCH_SEED + SEARCH_RUNS, horizon);
        let mut best_score = None;
        let mut best_results = None;
        for (_, s, first) in scored {
            progress.step();
            let second = study(spec, &s, ts, more, cancel)?;
            let both = summed(&first, &second);
            let total = score(&both);
            if best_score.map_or(true, |b| total > b) {
                best_score = Some(total);
                best = s;
                best_results = Some(both);
            }
        }
        progress.step();
        if let Some(results) = best_results {
            best = slower_arrival(spec, best, &results, ts, (search, more), cancel)?;
        }
    }
    let seed = SEARCH_SEED + SEARCH_RUNS + FINAL_RUNS;
    let confirmed = confirm(spec, &best, ts, (seed, horizon), cancel)?;
    progress.step();
    let found = confirmed
        .iter()
        .all(|m| reaches(m.held, m.judged(), FOUND_LOWER_BOUND));
    let mut kept = spec.clone();
    kept.swing_up = best.clone();
    Ok(SwingSearch {
        verdict: if found {
            SwingVerdict::Found
        } else {
            SwingVerdict::NotFound
        },
        settings: best,
        confirmed,
        tried,
        plan: plan_margins(&kept, ts)?,
    })
}

/// The plan of `spec`'s swing-up on its nominal model, as the record stores it (`None` for
/// the energy law, or where no plan was found): its length and what it leaves of the
/// voltage the swing-up may use (after the compensation's share) and of
/// `swing_up.arm_limit`. The plan does not depend on the balance controller.
fn plan_margins(spec: &Spec, ts: f64) -> Result<Option<StoredPlan>, SpecError> {
    if spec.swing_up.method != SwingUpMethod::Trajectory {
        return Ok(None);
    }
    let design = spec.design(ts)?;
    let swing = crate::spec::study::swing_up(spec, &design, ControllerKind::Lqr)?;
    let plan = swing.plan();
    if plan.is_empty() {
        return Ok(None);
    }
    let largest = |f: &dyn Fn(&crate::swingup::PlanPoint) -> f64| {
        plan.iter().map(|p| f(p).abs()).fold(0.0, f64::max)
    };
    Ok(Some(StoredPlan {
        duration_s: plan.len() as f64 * ts,
        voltage_left: swing.settings().max_voltage - largest(&|p| p.u),
        arm_left: spec.swing_up.arm_limit - largest(&|p| p.x[0]),
    }))
}

/// `search` of the tuned `design` (whose `[swing_up]` holds the settings kept), as the tuning
/// record stores it for `rip-rt run --swing-up`'s pre-flight.
pub fn stored(search: &SwingSearch, design: &crate::spec::Design) -> StoredSwingSearch {
    StoredSwingSearch {
        inputs: crate::preflight::design_checksum(design),
        verdict: search.verdict,
        needed: FOUND_LOWER_BOUND,
        method: search.settings.method,
        plan: search.plan,
        confirmed: search
            .confirmed
            .iter()
            .map(|m| {
                let lower_bound = m.success_interval().map_or(0.0, |(lo, _)| lo);
                let s = StoredStudy {
                    runs: m.judged(),
                    excluded: m.excluded,
                    held: m.held,
                    lower_bound,
                };
                (m.controller.name().to_string(), s)
            })
            .collect(),
    }
}
