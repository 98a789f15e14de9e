//! The swing-up experiment of a [`Spec`], set up once for the tests, the Monte Carlo example
//! and `riprs compare --start down`: the pendulum hangs at rest, the supervisor swings it up
//! and catches it with the spec's balance controller, and `reference.step_time` seconds after
//! the catch the arm reference steps to `reference.arm_step` (the paper's 0 → 1 rad step), as
//! `rip-rt run --swing-up` steps it on the rig.

use super::{ControllerKind, Design, Spec, SpecError, Start};
use crate::controller::Controller;
use crate::error::RipError;
use crate::plant::{FurutaParams, Param};
use crate::sim::SimConfig;
use crate::swingup::{wrap_angle, SwingUp};

/// The simulation of `spec` started hanging at rest: [`Spec::simulation`] with
/// [`Start::Hanging`] (`x0 = [0, 0, π, 0]`, the arm step `reference.step_time` after the catch,
/// `reference.duration + SWING_UP_ALLOWANCE` seconds long).
pub fn hanging_config(spec: &Spec, ts: f64, seed: u64) -> SimConfig {
    spec.simulation(ts, seed, Start::Hanging)
}

/// The supervisor around `design`'s balance controller `kind`, with the swing-up designed on
/// `spec`'s `[plant]` and `[swing_up]` settings, assembled as `rip-rt` and `riprs.SwingUp`
/// assemble it: the law plans within the bounds the compensation leaves, and the
/// compensation (when the design has one) is applied around the whole supervisor, to the
/// swing-up's voltage as to the balance controller's.
pub fn supervised(
    spec: &Spec,
    design: &Design,
    kind: ControllerKind,
) -> Result<Box<dyn Controller>, SpecError> {
    supervised_planned(spec, design, kind, None)
}

/// [`supervised`] with its plan given ([`swing_plan`]) or, with `None`, designed.
pub(crate) fn supervised_planned(
    spec: &Spec,
    design: &Design,
    kind: ControllerKind,
    plan: Option<Plan>,
) -> Result<Box<dyn Controller>, SpecError> {
    Ok(design.compensate(Box::new(swing_up_planned(spec, design, kind, plan)?)))
}

/// The swing-up of [`supervised`] before the compensation is put around it: its plan, its
/// parameters.
pub fn swing_up(
    spec: &Spec,
    design: &Design,
    kind: ControllerKind,
) -> Result<SwingUp<Box<dyn Controller>>, SpecError> {
    swing_up_planned(spec, design, kind, None)
}

/// A planned swing-up's points, shared by the supervisors that run it.
pub(crate) type Plan = std::sync::Arc<[crate::swingup::PlanPoint]>;

/// The swing-up settings of [`supervised`]: `spec`'s, the voltage bound within what `design`'s
/// compensation leaves.
pub(crate) fn supervised_settings(spec: &Spec, design: &Design) -> crate::swingup::SwingUpSettings {
    let mut settings = spec.swing_up.clone();
    if let Some(c) = design.compensation() {
        settings.max_voltage = c.planned_limit(settings.max_voltage);
    }
    settings
}

/// The plan [`supervised`] designs for `spec` under `design` (empty with the energy method or
/// where none is found), designed once for the many supervisors of a study: a plan of
/// several swings takes seconds.
pub(crate) fn swing_plan(spec: &Spec, design: &Design) -> Result<Plan, SpecError> {
    let plant = spec.plant()?;
    let ts = design.ts();
    Ok(crate::swingup::designed_plan(
        &plant,
        &supervised_settings(spec, design),
        ts,
    ))
}

fn swing_up_planned(
    spec: &Spec,
    design: &Design,
    kind: ControllerKind,
    plan: Option<Plan>,
) -> Result<SwingUp<Box<dyn Controller>>, SpecError> {
    let plant = spec.plant()?;
    let balance = design.balance(kind)?;
    SwingUp::planned(balance, &plant, supervised_settings(spec, design), plan).map_err(
        |e| match e {
            RipError::InvalidParameter { name, reason } => SpecError::new(name, reason),
            e => SpecError::new("swing_up", e.to_string()),
        },
    )
}

/// How a swing-up run approached upright, from its true state (not the supervisor's
/// estimate): the figures of the first-arrival requirement.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Arrivals {
    /// Arrivals near upright (the true `|wrap(α)|` entering `catch_angle`) while swinging up,
    /// up to and including the one in which the catch happened.
    pub before_catch: u32,
    /// Whether the catch happened during the first arrival near upright.
    pub caught_on_first: bool,
    /// Passes of the pendulum over the top (the unwrapped α crossing a multiple of 2π) while
    /// the supervisor was swinging up: each one is an arrival that was not caught.
    pub over_tops: u32,
    /// Largest true `|θ|` (rad) over the run.
    pub peak_arm: f64,
    /// Largest true `|θ|` (rad) from the first fall on; 0 without a fall.
    pub peak_arm_after_fall: f64,
}

/// The [`Arrivals`] of `res`, a run of a swing-up supervisor, with `catch_angle` the
/// supervisor's `swing_up.catch_angle`.
pub fn arrivals(res: &crate::SimResult, catch_angle: f64) -> Arrivals {
    use crate::controller::Phase;
    use std::f64::consts::TAU;
    let mut out = Arrivals::default();
    let mut near = false;
    let mut caught = false;
    for k in 0..res.len() {
        let x = res.x[k];
        out.peak_arm = out.peak_arm.max(x[0].abs());
        if res.fall_time.is_some_and(|t| res.t[k] >= t) {
            out.peak_arm_after_fall = out.peak_arm_after_fall.max(x[0].abs());
        }
        let swinging = res.phase[k] == Phase::SwingUp;
        let is_near = wrap_angle(x[2]).abs() <= catch_angle;
        if is_near && !near && !caught && (swinging || res.phase[k] == Phase::Balance) {
            out.before_catch += 1;
        }
        near = is_near;
        if !caught && res.phase[k] == Phase::Balance {
            caught = true;
            out.caught_on_first = out.before_catch == 1;
        }
        if swinging && k + 1 < res.len() {
            let (a, b) = (x[2] / TAU, res.x[k + 1][2] / TAU);
            if a.floor() != b.floor() {
                out.over_tops += 1;
            }
        }
    }
    out
}

/// How long after the catch the pendulum must still be balanced for a swing-up to count as a
/// success (s): the arm's step comes after it and is reported apart ([`SwingRun`]).
pub const HELD_AFTER_CATCH: f64 = 3.0;

/// The largest dead zone (V) drawn for a rig whose file has none: what an unknown drive may
/// hide ([`SwingStudy::draw`]).
pub const DRAWN_DEAD_ZONE: f64 = 0.3;

/// The largest arm Coulomb friction (N·m) drawn for a rig whose file has none
/// ([`SwingStudy::draw`]).
pub const DRAWN_ARM_FRICTION: f64 = 0.002;

/// The swing-up Monte Carlo's draws: `runs` rigs around the file's, drawn from `seed`
/// (docs/swing-up.md, "Statistics").
///
/// Each draw multiplies every physical parameter independently by a factor uniform in
/// `[1 − spread, 1 + spread]`; a dead zone `V_d` and an arm Coulomb friction `C_r` that the
/// file sets to 0 are drawn uniformly from `[0, `[`DRAWN_DEAD_ZONE`]`]` and
/// `[0, `[`DRAWN_ARM_FRICTION`]`]` instead, and stay unknown to the controllers (their
/// compensation is the file's). A draw whose swing-up the energy bound proves impossible
/// ([`crate::swingup::feasibility()`]) is excluded, not counted as a failure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwingStudy {
    /// Runs per controller.
    pub runs: u64,
    /// Seed of the draws and of each run's noise.
    pub seed: u64,
    /// The relative half-width of each parameter's factor.
    pub spread: f64,
    /// Where each run ends (s from the start), when shorter than the whole experiment
    /// ([`swing_study_config`]): a search that only compares successes needs no step after
    /// them, and a swing-up still going at `horizon − HELD_AFTER_CATCH` counts as failed.
    /// With a horizon each run also ends [`HELD_AFTER_CATCH`] after its catch (the success
    /// is judged then), so the step's tracking is not counted.
    pub horizon: Option<f64>,
}

impl Default for SwingStudy {
    fn default() -> Self {
        Self {
            runs: 200,
            seed: 2024,
            spread: 0.1,
            horizon: None,
        }
    }
}

/// Most runs one study may ask for.
pub const MAX_SWING_RUNS: u64 = 100_000;

impl SwingStudy {
    /// Checks the settings; the error names the bad one (`runs`, `spread`).
    pub fn validate(&self) -> Result<(), SpecError> {
        if !(1..=MAX_SWING_RUNS).contains(&self.runs) {
            return Err(SpecError::new(
                "runs",
                format!("must be in 1..={MAX_SWING_RUNS}, got {}", self.runs),
            ));
        }
        if !(self.spread.is_finite() && (0.0..1.0).contains(&self.spread)) {
            return Err(SpecError::new(
                "spread",
                format!("must be in [0, 1), got {}", self.spread),
            ));
        }
        if let Some(h) = self
            .horizon
            .filter(|h| !(h.is_finite() && *h > HELD_AFTER_CATCH))
        {
            return Err(SpecError::new(
                "horizon",
                format!("must be finite and above {HELD_AFTER_CATCH} s, got {h}"),
            ));
        }
        Ok(())
    }

    /// The parameters of draw `i` around `base` (type docs), and its noise seed.
    pub fn draw(&self, base: &FurutaParams, i: u64) -> (FurutaParams, u64) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(
            self.seed
                .wrapping_mul(0x9e37_79b9_7f4a_7c15)
                .wrapping_add(i.wrapping_mul(0xbf58_476d_1ce4_e5b9))
                ^ 0x5357_494e_4755_5021,
        );
        let mut p = *base;
        let s = self.spread;
        for param in Param::ALL {
            let factor = if s > 0.0 {
                rng.gen_range(1.0 - s..=1.0 + s)
            } else {
                1.0
            };
            let drawn = match param {
                Param::Vd if base.vd == 0.0 => rng.gen_range(0.0..=DRAWN_DEAD_ZONE),
                Param::Cr if base.cr == 0.0 => rng.gen_range(0.0..=DRAWN_ARM_FRICTION),
                _ => *param.field(&mut p) * factor,
            };
            *param.field(&mut p) = drawn;
        }
        (p, self.seed.wrapping_add(i))
    }
}

/// One run of a [`SwingStudy`], judged on the simulated plant's true state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SwingRun {
    /// The energy bound proves this draw's swing-up impossible: not simulated, not judged.
    pub excluded: bool,
    /// The time of the catch (s), if there was one.
    pub catch_time: Option<f64>,
    /// Caught, and still balanced [`HELD_AFTER_CATCH`] seconds later: the success.
    pub held: bool,
    /// Held, and the arm's step after it tracked to the end of the run without a fall.
    pub step_tracked: bool,
    /// Caught on the pendulum's first arrival near upright ([`Arrivals::caught_on_first`]).
    pub caught_on_first: bool,
    /// Passes over the top before the catch ([`Arrivals::over_tops`]).
    pub over_tops: u32,
}

impl SwingRun {
    /// Whether the pendulum passed over the top at most twice before the catch: the issue's
    /// bar counts the runs that do.
    pub fn within_two_over_tops(&self) -> bool {
        self.over_tops <= 2
    }
}

/// One controller's [`SwingStudy`]: counts over its runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwingMonteCarlo {
    /// The balance controller.
    pub controller: ControllerKind,
    /// Runs drawn.
    pub runs: u64,
    /// Draws excluded by the energy bound.
    pub excluded: u64,
    /// Runs caught.
    pub caught: u64,
    /// Successes: caught and balanced [`HELD_AFTER_CATCH`] s later.
    pub held: u64,
    /// Successes whose arm step was tracked to the end without a fall.
    pub step_tracked: u64,
    /// Runs caught on the first arrival.
    pub caught_on_first: u64,
    /// Runs with at most two passes over the top before the catch (or its end).
    pub at_most_two_over_tops: u64,
    /// The most passes over the top of any run.
    pub most_over_tops: u32,
}

impl SwingMonteCarlo {
    /// Runs judged: those drawn less those excluded.
    pub fn judged(&self) -> u64 {
        self.runs - self.excluded
    }

    /// The share of judged runs that succeeded (`NaN` with none judged).
    pub fn success_rate(&self) -> f64 {
        self.held as f64 / self.judged() as f64
    }

    /// The Wilson 95 % interval of the success rate ([`crate::stats::wilson`]); `None` with
    /// no run judged.
    pub fn success_interval(&self) -> Option<(f64, f64)> {
        crate::stats::wilson(self.held, self.judged(), crate::stats::Z_95).ok()
    }

    /// This study and `other`, made on other draws of the same controller, as one.
    pub fn combined(&self, other: &Self) -> Self {
        Self {
            controller: self.controller,
            runs: self.runs + other.runs,
            excluded: self.excluded + other.excluded,
            caught: self.caught + other.caught,
            held: self.held + other.held,
            step_tracked: self.step_tracked + other.step_tracked,
            caught_on_first: self.caught_on_first + other.caught_on_first,
            at_most_two_over_tops: self.at_most_two_over_tops + other.at_most_two_over_tops,
            most_over_tops: self.most_over_tops.max(other.most_over_tops),
        }
    }

    /// The figures of `runs`, each a run of the controller `kind`.
    pub(crate) fn of(kind: ControllerKind, runs: &[SwingRun]) -> Self {
        let mut mc = Self {
            controller: kind,
            runs: runs.len() as u64,
            excluded: 0,
            caught: 0,
            held: 0,
            step_tracked: 0,
            caught_on_first: 0,
            at_most_two_over_tops: 0,
            most_over_tops: 0,
        };
        for run in runs {
            mc.add(run);
        }
        mc
    }

    fn add(&mut self, run: &SwingRun) {
        if run.excluded {
            self.excluded += 1;
            return;
        }
        self.caught += u64::from(run.catch_time.is_some());
        self.held += u64::from(run.held);
        self.step_tracked += u64::from(run.step_tracked);
        self.caught_on_first += u64::from(run.caught_on_first);
        self.at_most_two_over_tops += u64::from(run.within_two_over_tops());
        self.most_over_tops = self.most_over_tops.max(run.over_tops);
    }
}

/// The simulation of one study run of `spec`: hanging at rest, the arm's step
/// [`HELD_AFTER_CATCH`] seconds after the catch, long enough for the longest swing-up, the
/// hold and the step's `reference.duration`.
pub fn swing_study_config(spec: &Spec, ts: f64, seed: u64) -> SimConfig {
    let mut s = spec.clone();
    s.reference.step_time = HELD_AFTER_CATCH;
    let mut config = hanging_config(&s, ts, seed);
    config.duration = spec.swing_up.max_time + HELD_AFTER_CATCH + spec.reference.duration;
    config
}

/// Judges the run `res` of a supervisor (type docs of [`SwingRun`]).
pub fn judge_swing_run(res: &crate::SimResult, catch_angle: f64) -> SwingRun {
    let a = arrivals(res, catch_angle);
    let whole = !res.diverged && res.stop_cause.is_none();
    let held = res.catch_time.is_some_and(|catch| {
        let end = res.t.last().copied().unwrap_or(f64::NEG_INFINITY);
        whole
            // Within a rounding of the sample grid: a run ended at the hold's last sample
            // (`SimConfig::end_after_catch`) reaches it.
            && end >= catch + HELD_AFTER_CATCH - 1e-6
            && res
                .fall_time
                .map_or(true, |fall| fall > catch + HELD_AFTER_CATCH)
    });
    SwingRun {
        excluded: false,
        catch_time: res.catch_time,
        held,
        step_tracked: held && !res.fell,
        caught_on_first: a.caught_on_first,
        over_tops: a.over_tops,
    }
}

/// Runs `study` on `spec`'s rig with its balance controller `kind` at sample time `ts`, on two
/// threads, each with one supervisor designed once; `cancel` stops it between runs with an
/// error. The controllers and the swing-up are the file's, designed on its nominal plant;
/// each run's plant is a draw ([`SwingStudy::draw`]).
pub fn swing_monte_carlo(
    spec: &Spec,
    kind: ControllerKind,
    ts: f64,
    study: &SwingStudy,
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<SwingMonteCarlo, SpecError> {
    let runs = swing_runs(spec, kind, ts, study, 0..study.runs, None, cancel)?;
    Ok(SwingMonteCarlo::of(kind, &runs))
}

/// The runs of [`swing_monte_carlo`] on the draws `draws` of `study` alone, draw by draw, in
/// the draws' order: a study taken in parts whose sum is the whole one's
/// ([`SwingMonteCarlo::of`] counts them). `plan` is the swing-up's plan where it is designed
/// already ([`swing_plan`]).
pub(crate) fn swing_runs(
    spec: &Spec,
    kind: ControllerKind,
    ts: f64,
    study: &SwingStudy,
    draws: std::ops::Range<u64>,
    plan: Option<Plan>,
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<Vec<SwingRun>, SpecError> {
    study.validate()?;
    let design = spec.design(ts)?;
    let plan = match plan {
        Some(plan) => plan,
        None => swing_plan(spec, &design)?,
    };
    let base = spec.plant.params();
    let catch_angle = spec.swing_up.catch_angle;
    let one = |sup: &mut Box<dyn Controller>, i: u64| -> Result<SwingRun, SpecError> {
        let (params, seed) = study.draw(&base, i);
        let plant = crate::plant::Plant::new(params)
            .map_err(|e| SpecError::new("plant", format!("draw {i}: {e}")))?;
        let bound = crate::swingup::feasibility(&plant, &spec.swing_up);
        if bound.verdict == crate::swingup::Verdict::Impossible {
            return Ok(SwingRun {
                excluded: true,
                ..SwingRun::default()
            });
        }
        let mut config = swing_study_config(spec, ts, seed);
        if let Some(h) = study.horizon {
            // Only the catch and the hold are judged: nothing after them is simulated.
            config.duration = config.duration.min(h);
            config.end_after_catch = Some(HELD_AFTER_CATCH);
        }
        let res = crate::sim::simulate(&plant, sup, &config)
            .map_err(|e| SpecError::new("plant", format!("draw {i}: {e}")))?;
        Ok(judge_swing_run(&res, catch_angle))
    };
    let half = draws.start + (draws.end - draws.start) / 2;
    let chunk = |range: std::ops::Range<u64>| -> Result<Vec<SwingRun>, SpecError> {
        let mut sup = supervised_planned(spec, &design, kind, Some(plan.clone()))?;
        let mut out = Vec::with_capacity(range.clone().count());
        for i in range {
            if cancel.load(std::sync::atomic::Ordering::Relaxed) {
                return Err(SpecError::new("", "cancelled"));
            }
            out.push(one(&mut sup, i)?);
        }
        Ok(out)
    };
    std::thread::scope(|s| {
        let first = s.spawn(|| chunk(draws.start..half));
        let second = chunk(half..draws.end);
        let first = first
            .join()
            .unwrap_or_else(|_| Err(SpecError::new("", "a Monte Carlo thread panicked")));
        first.and_then(|mut a| {
            a.extend(second?);
            Ok(a)
        })
    })
}
