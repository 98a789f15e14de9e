//! Per-rig tuning: shared weights for LQR, LQG and MPC that balance the rig in the file.
//!
//! The paper's thesis is one cost for all three controllers, so the tuning keeps them
//! shared: a candidate scales the arm weights `Q[0], Q[1]` by `q_θ`, the pendulum weights
//! `Q[2], Q[3]` by `q_α` and `R` by `ρ`; the MPC's weights enter its cost squared, so its
//! `w^y` scale by `√q_θ, √q_α` and its `w^u, w^Δu` by `√ρ`, and the cost stays the one cost
//! of the file, reweighted alike. A candidate may lower the shared estimator's measurement
//! noise ([`candidates`]) and add integral action (`lqr.integral_weight`, MATLAB's `lqi`) to
//! LQR and LQG; the MPC has its output-disturbance model already. Each candidate then gets
//! the loop transfer recovery (Doyle–Stein) its margins ask for: the smallest parameter
//! `q` of [`RECOVERY`] with which the margins of LQG and the MPC, the two controllers on the
//! shared estimator, meet the bar ([`choose_recovery`]; LQR's margins do not depend on it).
//!
//! A candidate **works** when every controller meets the rig's bar ([`Bar::for_rig`], whose
//! docs give it whole), on the rig's nonlinear model (its dead zone, friction and stiction;
//! `[sensor]`; the `[reference]` step, [`SEEDS`] noise seeds):
//!
//! - with the file's compensation it balances (no fall, no divergence), with the steady state
//!   over the last [`Bar::window`] seconds inside the bar: arm peak-to-peak (raised above
//!   0.05 rad by what the sensor alone costs the rig), pendulum `|α|`, arm offset
//!   `|mean θ − θ_ref|`;
//! - it respects the voltage bound: LQR and LQG never reach their clamp (the MPC plans within
//!   it by construction);
//! - with the compensation 30 % off either way and the arm's stiction on, it does not fall and
//!   its arm stays within [`Bar::off_limit`]: the candidates are scored with the error a
//!   compensation identified on a real rig has in view;
//! - the margins of its linearised loop at the plant input (crate::margins) meet the bar:
//!   LQR's classical ones, LQG's and the MPC's disk margin.
//!
//! [`tune`] tries the file's own weights first and keeps them when they work; otherwise the
//! candidates of [`candidates`] in order (closest to the file's first) and keeps the first
//! that works (a candidate whose recovered LQG or MPC misses the margins cannot work, so it is
//! simulated only once none does). When none does, it tries again those whose recovery was
//! raised, without it (a recovered estimator trusts the sensor more, which a coarse or noisy
//! one may not bear), and keeps the one that misses the bar by least: one that balances
//! within the bar and the voltage bound beats any that does not, and among equals the one
//! nearer the margins wins. Where a controller is still short, the compensation's gains
//! (how much of the identified dead zone and friction it applies) are chosen with the
//! identification's error in view ([`gains`]); the MPC's own weights are then searched where
//! the shared ones leave it short ([`own`]). When a controller is still short (and not all
//! of them fall), all of this is done again over a second grid whose cost holds the pendulum
//! harder against the arm ([`pendulum_led_candidates`]), and its outcome kept when fewer
//! controllers are short with it. A controller that works on the tuning's noise seeds with
//! a compensation to be off is run again on further seeds ([`FALL_CHECK_SEEDS`]) and is short
//! if it falls there. Each controller that still misses the bar is said to, with what it
//! misses ([`Tuned::shortfalls`]), and `rip-rt run`'s pre-flight refuses it through the
//! record ([`record`]).
//! [`robustness`] then draws rigs around the file's (each parameter within ±10 %, or from
//! the identification's covariance) and counts the runs each tuned controller balances.

use std::sync::atomic::AtomicBool;

use crate::preflight::{design_checksum, StoredPrediction, TuneRecord};
use crate::spec::{ControllerKind, Spec, SpecError};

mod assess;
mod bar;
pub mod gains;
pub mod own;
mod robustness;
mod settings;
pub mod swing;
pub use assess::{
    assess, check_falls, steady_state, Assessment, OffCompensation, FALL_CHECK_SEEDS,
};
pub(crate) use assess::{assess_kinds, screen_then_confirm};
pub use bar::{
    frictionless, off_compensation, sensor_floor, Bar, BASE_PEAK_TO_PEAK, GUARD, OFF_COMPENSATION,
    STICTION_RATIO,
};
pub use robustness::{perturb, robustness, robustness_with, Perturbation};
use settings::check_cancel;
pub use settings::{check_spread, check_ts, check_voltage, Progress, Settings, MAX_RUNS};

/// Noise seeds of an assessment's simulations. The search screens each candidate on the
/// first [`SCREEN`] and confirms one that works there on all of them before keeping it: a
/// steady state at the bar on two seeds may be past it on the next.
pub const SEEDS: [u64; 4] = [11, 12, 13, 14];

/// How many of [`SEEDS`] screen a candidate.
pub const SCREEN: usize = 2;

/// How many of the candidates nearest the bar are assessed whole when none works, to keep the
/// one with which most controllers work.
pub const FINALISTS: usize = 6;

/// One candidate's change to the file's weights (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weights {
    /// Factor `q_θ` on the arm weights.
    pub arm: f64,
    /// Factor `q_α` on the pendulum weights.
    pub pendulum: f64,
    /// Factor `ρ` on `R`.
    pub input: f64,
    /// `lqr.integral_weight` (0: none).
    pub integral_weight: f64,
    /// Factor on `kalman.measurement_noise` (the shared estimator's `D_n`).
    pub measurement_noise: f64,
    /// The loop-transfer-recovery parameter `q ≥ 1` (Doyle–Stein, [`RECOVERY`]): the shared
    /// estimator's fictitious noise on the plant input, relative to its output disturbance
    /// and measurement noise, raised by `q`; applied as `kalman.disturbance_gain / q` and
    /// `kalman.measurement_noise / q`.
    pub recovery: f64,
}

impl Weights {
    /// The file's own weights.
    pub const FILE: Weights = Weights {
        arm: 1.0,
        pendulum: 1.0,
        input: 1.0,
        integral_weight: 0.0,
        measurement_noise: 1.0,
        recovery: 1.0,
    };

    /// These weights with the recovery parameter `q` ([`recovery`](Self::recovery)).
    pub fn with_recovery(self, q: f64) -> Self {
        Self {
            recovery: q,
            ..self
        }
    }

    /// `spec` with these weights (module docs); the integral weight replaces the file's only
    /// when it is positive here or the other factors (the recovery aside) change something.
    pub fn apply(&self, spec: &Spec) -> Spec {
        let mut s = spec.clone();
        s.lqr.Q[0] *= self.arm;
        s.lqr.Q[1] *= self.arm;
        s.lqr.Q[2] *= self.pendulum;
        s.lqr.Q[3] *= self.pendulum;
        s.lqr.R *= self.input;
        if self.with_recovery(1.0) != Self::FILE {
            s.lqr.integral_weight = self.integral_weight;
        }
        s.mpc.output_weights[0] *= self.arm.sqrt();
        s.mpc.output_weights[1] *= self.pendulum.sqrt();
        s.mpc.input_rate_weights[0] *= self.input.sqrt();
        s.mpc.input_weights[0] *= self.input.sqrt();
        for v in s.kalman.measurement_noise.iter_mut() {
            *v *= self.measurement_noise / self.recovery;
        }
        s.kalman.disturbance_gain /= self.recovery;
        s
    }
}

/// The loop-transfer-recovery parameters `q` [`tune`] chooses from, smallest first.
///
/// The shared Kalman filter is designed with unit white noise `w_u` on the scaled plant input,
/// the output disturbance `g w_od` and the measurement noise `D_n v`:
/// `Q = B_u S_u S_uᵀ B_uᵀ + g² B_od B_odᵀ`, `R = D_n D_nᵀ`. Doyle and Stein's recovery at the
/// plant input ("Robustness with observers", IEEE TAC 24(4), 1979) adds fictitious input
/// noise, `Q(q) = q² B_u S_u S_uᵀ B_uᵀ + g² B_od B_odᵀ`: as `q → ∞` the filter attributes
/// every unexplained output to the input, and the loop of the controller on the estimate
/// approaches that of the same law on the true state (LQR's `K (zI − A)⁻¹ B` for LQG, the
/// unconstrained MPC's own law for the MPC). The gains depend only on `Q / R`, so `Q(q), R`
/// is `Q(1)` with `g / q` and `D_n / q` — which is how [`Weights::apply`] writes it, in the
/// file's own keys. Larger `q` trusts the sensor more and passes more of its noise to the
/// voltage, so [`tune`] takes the smallest that meets the margins. The largest is 100: with
/// `q = 1000` generated rig 3's recovered LQG missed the steady-state bar even on an
/// 8192-count encoder with 0.1 mrad of noise (0.16 rad arm peak-to-peak on its own sensor).
pub const RECOVERY: [f64; 5] = [1.0, 3.0, 10.0, 30.0, 100.0];

/// The candidates after the file's own weights, closest to them first: the estimator's
/// measurement noise lowered (loop transfer recovery at the plant input: the shared Kalman
/// filter already models unit noise on the scaled input, so a smaller `D_n` makes LQG's loop
/// approach LQR's, whose margins it otherwise loses); `R` raised (a gentler loop that stays
/// inside the voltage bound on the step) or lowered; the arm weighted more; then integral
/// action (`q_i = Q[0]` of the tuned `Q`); then all of these again with the pendulum weighted
/// a quarter ([`PENDULUM`]).
pub fn candidates(spec: &Spec) -> Vec<Weights> {
    grid(spec, &PENDULUM, &ARM, &[])
}

/// The candidates [`tune`] tries when a controller is still short with those of
/// [`candidates`] (after the compensation's gains, the controllers' own keys and the fall
/// check) and not every controller falls: the same grid with the pendulum weighted 4 or 16
/// times the file's, or the arm a quarter of it ([`PENDULUM_LED`], [`ARM_LED`]; those of
/// [`candidates`] left out), weights that [`candidates`] never tries.
///
/// On a coarse pendulum encoder LQR's differenced rate passes a count's step to the voltage
/// through the pendulum's gains: the pendulum then wanders by a few counts unless the cost
/// holds it harder than the arm. Generated rigs 3 and 16 (792 and 836 counts a turn, a count
/// 7.9 and 7.5 mrad) kept LQR's `|α|` at 0.017–0.022 rad with every one of [`candidates`]
/// and meet the whole bar, all three controllers, with one of these.
pub fn pendulum_led_candidates(spec: &Spec) -> Vec<Weights> {
    grid(spec, &PENDULUM_LED, &ARM_LED, &candidates(spec))
}

/// The arm factors `q_θ` of [`candidates`].
pub const ARM: [f64; 3] = [1.0, 4.0, 16.0];

/// The factors `q_α` on the pendulum weights [`candidates`] tries, the file's first.
///
/// With the file's measurement noise, a margins-only grid over `q_θ` (1, 4, 16), `q_α` (0.25,
/// 1, 4), `ρ` (1–100) and the recovery found weights with which LQR, LQG and the MPC all met
/// 6 dB / 30° on generated rigs 3, 4, 5, 7, 8, 14, 15 and 16, mostly with `q_α = 0.25`. They
/// come after every candidate of the file's pendulum weight, so a rig those already balance
/// keeps the weights it had.
pub const PENDULUM: [f64; 2] = [1.0, 0.25];

/// The pendulum factors `q_α` of [`pendulum_led_candidates`] (with [`PENDULUM`]'s).
pub const PENDULUM_LED: [f64; 4] = [4.0, 16.0, 1.0, 0.25];

/// The arm factors `q_θ` of [`pendulum_led_candidates`].
pub const ARM_LED: [f64; 4] = [0.25, 1.0, 4.0, 16.0];

/// The weights of every `q_α` in `pendulums`, integral action or not, measurement-noise
/// factor, `q_θ` in `arms` and `ρ`, in that nesting; the file's own and those in `skip` left
/// out.
fn grid(spec: &Spec, pendulums: &[f64], arms: &[f64], skip: &[Weights]) -> Vec<Weights> {
    let mut out = Vec::new();
    let q0 = spec.lqr.Q[0];
    for &pendulum in pendulums {
        for integral in [0.0, 1.0] {
            for noise in [1.0, 0.1, 0.01, 0.001] {
                for &arm in arms {
                    for input in [1.0, 3.0, 10.0, 30.0, 100.0] {
                        let w = Weights {
                            arm,
                            pendulum,
                            input,
                            integral_weight: integral * q0 * arm,
                            measurement_noise: noise,
                            recovery: 1.0,
                        };
                        if w != Weights::FILE && !skip.contains(&w) {
                            out.push(w);
                        }
                    }
                }
            }
        }
    }
    out
}

/// The controllers' own keys [`tune`] changed on top of the shared weights ([`own`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OwnWeights {
    /// LQR's input-disturbance observer.
    pub lqr: own::LqrWeights,
    /// LQG's filter (which the MPC shares).
    pub kalman: own::KalmanWeights,
    /// The MPC's weights.
    pub mpc: own::MpcWeights,
}

impl OwnWeights {
    /// Nothing changed: the shared weights throughout.
    pub const SHARED: OwnWeights = OwnWeights {
        lqr: own::LqrWeights::SHARED,
        kalman: own::KalmanWeights::SHARED,
        mpc: own::MpcWeights::SHARED,
    };
}

/// The outcome of [`tune`].
#[derive(Debug, Clone)]
pub struct Tuned {
    /// The spec with the chosen weights.
    pub spec: Spec,
    /// The chosen change to the file's weights ([`Weights::FILE`] when they were kept).
    pub weights: Weights,
    /// Whether every controller works with them (module docs).
    pub works: bool,
    /// Each controller's assessment with them.
    pub assessments: Vec<Assessment>,
    /// Candidates assessed.
    pub tried: usize,
    /// The controllers' own keys changed on top of [`weights`](Self::weights), where the
    /// shared cost left them short of the bar ([`own`]).
    pub own: OwnWeights,
    /// The rig's bar ([`Bar::for_rig`]); the search held its simulations to
    /// [`Bar::guarded`] of it, and so do [`works`](Self::works) and the shortfalls.
    pub bar: Bar,
}

impl Tuned {
    /// Each controller that misses the bar with the weights chosen, with what it misses: the
    /// report says so, and `rip-rt run`'s pre-flight says it through the record
    /// ([`record`]). Empty when every controller works.
    pub fn shortfalls(&self) -> Vec<(ControllerKind, String)> {
        self.assessments
            .iter()
            .filter(|a| !a.works(&self.bar.guarded()))
            .map(|a| {
                (
                    a.kind,
                    format!(
                        "{} cannot meet the bar on this rig's model with any of the {} shared \
                         weights tried: {} (the tuning holds each steady-state figure to {:.0} \
                         % of the bar: {})",
                        a.kind.name(),
                        self.tried,
                        a.misses(&self.bar.guarded()).join("; "),
                        GUARD * 100.0,
                        self.bar_summary()
                    ),
                )
            })
            .collect()
    }

    /// The bar in one line, with the floor it was raised from.
    pub fn bar_summary(&self) -> String {
        let b = &self.bar;
        let floor = match b.floor {
            Some(f) if f.is_finite() => format!(", the sensor's floor {f:.3} rad"),
            Some(_) => {
                ", the sensor's floor unknown: the file's LQR falls without friction".to_string()
            }
            None => String::new(),
        };
        format!(
            "steady-state arm peak-to-peak <= {:.3} rad{floor}, |alpha| and offset <= {} rad; \
             LQR margins >= {} dB and {} deg, LQG and MPC disk margin >= {}; with the \
             compensation {:.0} % off, arm peak-to-peak <= {:.3} rad (MPC {:.3})",
            b.arm_peak_to_peak,
            b.pendulum,
            b.gain_margin_db,
            b.phase_margin_deg,
            b.disk_margin,
            OFF_COMPENSATION * 100.0,
            b.off_limit(ControllerKind::Lqr),
            b.off_limit(ControllerKind::Mpc)
        )
    }

    /// Why the tuning failed outright, if it did: every controller falls on the rig's model
    /// with the weights that missed the bar by least.
    pub fn refusal(&self) -> Option<String> {
        if self.assessments.is_empty() || !self.assessments.iter().all(|a| a.fell) {
            return None;
        }
        Some(format!(
            "every controller falls on this rig's model with the weights that came closest of \
             the {} candidates tried: no shared weights found balance it (a stronger motor, a \
             start nearer upright or a less noisy sensor may)",
            self.tried
        ))
    }
}

/// Chooses shared weights for the rig of `spec` at sample time `ts`, held to the rig's bar
/// ([`Bar::for_rig`]; module docs).
pub fn tune(spec: &Spec, ts: f64) -> Result<Tuned, SpecError> {
    tune_with(spec, ts, &Progress::default(), &AtomicBool::new(false))
}

/// [`tune`], first refusing a rig the pre-flight's voltage check refuses
/// ([`check_voltage`]); counting its steps in `progress` (one per candidate of each grid
/// searched, and one for each grid's final assessment) and stopping with an error between two
/// steps once `cancel` is set.
pub fn tune_with(
    spec: &Spec,
    ts: f64,
    progress: &Progress,
    cancel: &AtomicBool,
) -> Result<Tuned, SpecError> {
    check_voltage(spec, ts)?;
    let bar = Bar::for_rig(spec, ts)?;
    let held = bar.guarded();
    let first = std::iter::once(Weights::FILE).chain(candidates(spec));
    let mut tuned = tune_over(spec, first.collect(), ts, &held, progress, cancel)?;
    // A rig every controller falls on is not helped by holding the pendulum harder: it is
    // refused as it stands ([`Tuned::refusal`]).
    if !tuned.works && tuned.refusal().is_none() {
        let led = tune_over(
            spec,
            pendulum_led_candidates(spec),
            ts,
            &held,
            progress,
            cancel,
        )?;
        // Kept only where fewer controllers are short with it: a rig's tuning changes only
        // where the second grid does better, each verdict through the fall check.
        let tried = tuned.tried + led.tried;
        if short_count(&led, &held) < short_count(&tuned, &held) {
            tuned = led;
        }
        tuned.tried = tried;
    }
    tuned.bar = bar;
    progress.finish();
    Ok(tuned)
}

/// How many controllers of `tuned` miss `bar`.
fn short_count(tuned: &Tuned, bar: &Bar) -> usize {
    tuned.assessments.iter().filter(|a| !a.works(bar)).count()
}

/// The search over `candidates`, then the compensation's gains and the controllers' own keys
/// where they are short, then the fall check ([`check_falls`]; [`tune`]'s steps), held to
/// `held`.
fn tune_over(
    spec: &Spec,
    candidates: Vec<Weights>,
    ts: f64,
    held: &Bar,
    progress: &Progress,
    cancel: &AtomicBool,
) -> Result<Tuned, SpecError> {
    progress.add(candidates.len() + 1);
    let mut tuned = search(spec, candidates, ts, held, progress, cancel)?;
    gains::choose(&mut tuned, ts, held, cancel)?;
    own_keys(&mut tuned, ts, held, cancel)?;
    check_cancel(cancel)?;
    check_falls(&tuned.spec, ts, held, &mut tuned.assessments)?;
    tuned.works = tuned.assessments.iter().all(|a| a.works(held));
    // The search may stop at the first candidate that works: what it skipped is done too, so
    // that a second grid's steps count on from a bar at the end of this one's.
    progress.finish();
    Ok(tuned)
}

/// Whether `kind` of `tuned` is short of `bar`.
fn short(tuned: &Tuned, kind: ControllerKind, bar: &Bar) -> bool {
    tuned
        .assessments
        .iter()
        .any(|a| a.kind == kind && !a.works(bar))
}

/// `tuned`'s assessment of `a.kind` replaced by `a`.
fn replace(tuned: &mut Tuned, a: Assessment) {
    for slot in tuned.assessments.iter_mut().filter(|s| s.kind == a.kind) {
        *slot = a;
    }
}

/// The controllers' own keys searched where the shared weights leave them short
/// ([`own`] module docs: LQR's observer, then LQG's filter, then the MPC's weights).
fn own_keys(tuned: &mut Tuned, ts: f64, bar: &Bar, cancel: &AtomicBool) -> Result<(), SpecError> {
    if short(tuned, ControllerKind::Lqr, bar) {
        if let Some((w, spec, a)) = own::search_lqr(&tuned.spec, ts, bar, cancel)? {
            tuned.spec = spec;
            tuned.own.lqr = w;
            replace(tuned, a);
        }
    }
    if short(tuned, ControllerKind::Lqg, bar) {
        if let Some((w, spec, a)) = own::search_lqg(&tuned.spec, ts, bar, cancel)? {
            let (mut mpc, _) = assess_kinds(&spec, ts, bar, &[ControllerKind::Mpc], &SEEDS, false)?;
            tuned.spec = spec;
            tuned.own.kalman = w;
            replace(tuned, a);
            if let Some(m) = mpc.pop() {
                replace(tuned, m);
            }
        }
    }
    if short(tuned, ControllerKind::Mpc, bar) {
        if let Some((w, spec, a)) = own::search(&tuned.spec, ts, bar, cancel)? {
            tuned.spec = spec;
            tuned.own.mpc = w;
            replace(tuned, a);
        }
    }
    tuned.works = tuned.assessments.iter().all(|a| a.works(bar));
    Ok(())
}

fn search(
    spec: &Spec,
    candidates: Vec<Weights>,
    ts: f64,
    bar: &Bar,
    progress: &Progress,
    cancel: &AtomicBool,
) -> Result<Tuned, SpecError> {
    let mut tried = 0;
    // First each candidate with the recovery its margins ask for, in order. One whose
    // recovered LQG or MPC misses the margins cannot work, so it is simulated only when no
    // candidate works and the one that misses by least is wanted.
    // Each with its shortfall once judged (`None` until then).
    let mut recovered: Vec<(Weights, Option<Shortfall>)> = Vec::new();
    for w in candidates {
        check_cancel(cancel)?;
        let (w, margins_met) = recover(spec, w, ts, bar);
        let mut score = None;
        if margins_met {
            tried += 1;
            match judge(spec, w, ts, bar) {
                Judgement::Works(tuned) => return Ok(Tuned { tried, ..*tuned }),
                Judgement::Misses(s) => score = Some(Some(s)),
                Judgement::NoDesign => score = Some(None),
            }
        }
        recovered.push((w, score));
        progress.step();
    }
    // None works: then those whose recovery was raised are tried again without it (the
    // recovery trusts the sensor more, which may cost the steady state on a coarse or noisy
    // one), and the one that misses by least is kept, the first in this order on a tie.
    let unrecovered: Vec<(Weights, Option<Shortfall>)> = recovered
        .iter()
        .filter(|(w, _)| w.recovery != 1.0)
        .map(|(w, _)| (w.with_recovery(1.0), None))
        .collect();
    let unjudged = recovered.iter().filter(|(_, s)| s.is_none()).count();
    progress.add(unjudged + unrecovered.len());
    let mut scored: Vec<((f64, f64), Weights)> = Vec::new();
    for (w, score) in recovered.into_iter().chain(unrecovered) {
        let score = match score {
            Some(s) => s,
            None => {
                check_cancel(cancel)?;
                progress.step();
                tried += 1;
                match judge(spec, w, ts, bar) {
                    Judgement::Works(tuned) => return Ok(Tuned { tried, ..*tuned }),
                    Judgement::Misses(s) => Some(s),
                    Judgement::NoDesign => None,
                }
            }
        };
        if let Some(s) = score {
            scored.push((s, w));
        }
    }
    if scored.is_empty() {
        return Err(SpecError::new(
            "lqr",
            "no candidate weights could be designed for this rig",
        ));
    }
    // The screening stops at a candidate's first failing controller, so its score cannot say
    // with which of the nearest the most controllers work: those are assessed whole, and the
    // one with which most work is kept, the nearest on a tie (the first in order on an exact
    // one: the sort is stable).
    scored.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap_or(std::cmp::Ordering::Equal));
    let mut best: Option<((usize, f64), Weights, Vec<Assessment>)> = None;
    for (_, w) in scored.into_iter().take(FINALISTS) {
        check_cancel(cancel)?;
        let Ok(assessments) = assess(&w.apply(spec), ts, bar) else {
            continue;
        };
        let failing = assessments.iter().filter(|a| !a.works(bar)).count();
        let shortfall: f64 = assessments.iter().map(|a| a.shortfall(bar)).sum();
        let key = (failing, shortfall);
        if best.as_ref().map_or(true, |(k, _, _)| key < *k) {
            best = Some((key, w, assessments));
        }
    }
    let (_, weights, assessments) = best.ok_or_else(|| {
        SpecError::new("lqr", "no candidate weights could be designed for this rig")
    })?;
    Ok(Tuned {
        spec: weights.apply(spec),
        weights,
        works: false,
        assessments,
        tried,
        own: OwnWeights::SHARED,
        bar: *bar,
    })
}

/// A candidate's `(balance, margins)` shortfall ([`judge`]); `None` when it could not be
/// designed.
type Shortfall = Option<(f64, f64)>;

/// What [`judge`] found of one candidate.
enum Judgement {
    /// Every controller works with it.
    Works(Box<Tuned>),
    /// It misses the bar by `(balance, margins)`, compared in that order.
    Misses((f64, f64)),
    /// It could not be designed or simulated.
    NoDesign,
}

/// Assesses the candidate `w` (module docs). Short of the whole bar, a candidate that
/// balances within the bar and the voltage bound (its margins short) beats any that does
/// not, and among those the one nearer the margins wins; a controller not assessed counts as
/// a fall.
fn judge(spec: &Spec, w: Weights, ts: f64, bar: &Bar) -> Judgement {
    let candidate = w.apply(spec);
    let Ok((assessments, complete)) =
        screen_then_confirm(&candidate, ts, bar, &ControllerKind::ALL)
    else {
        return Judgement::NoDesign;
    };
    if complete && assessments.iter().all(|a| a.works(bar)) {
        return Judgement::Works(Box::new(Tuned {
            spec: candidate,
            weights: w,
            works: true,
            assessments,
            tried: 0,
            own: OwnWeights::SHARED,
            bar: *bar,
        }));
    }
    let missing = ControllerKind::ALL.len() - assessments.len();
    let balance: f64 = assessments
        .iter()
        .map(|a| a.balance_shortfall(bar))
        .sum::<f64>()
        + if complete {
            0.0
        } else {
            100.0 + 12.0 * missing as f64
        };
    let margins: f64 = assessments
        .iter()
        .map(|a| bar.margin_shortfall(a.kind, &a.margins))
        .sum();
    Judgement::Misses((balance, margins))
}

/// `w` with the smallest recovery parameter of [`RECOVERY`] with which the margins of LQG and
/// the MPC (the controllers on the shared estimator) meet the bar; when none does, the one
/// that misses them by least ([`Bar::margin_shortfall`], summed), the smaller on a tie. The
/// margins are the linearised loop's, so this costs no simulation.
pub fn choose_recovery(spec: &Spec, w: Weights, ts: f64, bar: &Bar) -> Weights {
    recover(spec, w, ts, bar).0
}

/// [`choose_recovery`], and whether the margins of LQG and the MPC meet the bar with it.
fn recover(spec: &Spec, w: Weights, ts: f64, bar: &Bar) -> (Weights, bool) {
    let mut best: Option<(f64, f64)> = None;
    for q in RECOVERY {
        let Ok(design) = w.with_recovery(q).apply(spec).design(ts) else {
            continue;
        };
        let mut short = 0.0;
        for kind in [ControllerKind::Lqg, ControllerKind::Mpc] {
            short += design
                .margins(kind)
                .map_or(2.0, |m| bar.margin_shortfall(kind, &m));
        }
        if short == 0.0 {
            return (w.with_recovery(q), true);
        }
        if best.map_or(true, |(s, _)| short < s) {
            best = Some((short, q));
        }
    }
    (w.with_recovery(best.map_or(1.0, |(_, q)| q)), false)
}

/// What `riprs tune` writes: the tuned controllers (their spec the tuned file), the record
/// beside it ([`crate::preflight::tune_record_path`]) as TOML text, and the swing-up search
/// when one ran.
#[derive(Debug, Clone)]
pub struct TunedFile {
    /// The tuned controllers; `tuned.spec` is the tuned file's spec, its `[swing_up]` the
    /// searched settings when the search ran.
    pub tuned: Tuned,
    /// The record's text: each controller's prediction ([`record`]), the swing-up's energy
    /// verdict ([`crate::swingup::StoredFeasibility`]), the search's result
    /// ([`swing::stored`]) and, for a rig whose identification is not trusted, why
    /// ([`crate::preflight::untrusted_section`]).
    pub record: String,
    /// The swing-up search, when it ran.
    pub swing_up: Option<swing::SwingSearch>,
}

/// Tunes the rig of `spec` at sample time `ts` ([`tune_with`]) and, with `swing_up` and a
/// tuning that did not fail outright, searches its swing-up on the controllers just tuned
/// ([`swing::search`]) before the record's checksums are taken; `untrusted` says why the
/// rig's identification is not trusted, for the record. One definition of the tuned file
/// and its record for every caller (`riprs tune`, the end-to-end tests).
pub fn tune_file(
    spec: &Spec,
    ts: f64,
    swing_up: bool,
    untrusted: Option<&str>,
    progress: &Progress,
    cancel: &AtomicBool,
) -> Result<TunedFile, SpecError> {
    let mut tuned = tune_with(spec, ts, progress, cancel)?;
    let searched = if swing_up && tuned.refusal().is_none() {
        let found = swing::search(&tuned.spec, ts, progress, cancel)?;
        tuned.spec.swing_up = found.settings.clone();
        Some(found)
    } else {
        None
    };
    // The swing-up's energy verdict beside the predictions, so that `rip-rt run --swing-up`
    // reads it instead of computing it (crate::swingup::stored).
    let verdict =
        crate::swingup::StoredFeasibility::compute(&tuned.spec.plant()?, &tuned.spec.swing_up);
    let design = tuned.spec.design(ts)?;
    let mut text = format!(
        "{}{}",
        record_of(&tuned, &design).to_toml(),
        verdict.to_section()
    );
    if let Some(found) = &searched {
        text.push_str(&swing::stored(found, &design).to_section());
    }
    if let Some(reason) = untrusted {
        text.push_str(&crate::preflight::untrusted_section(reason));
    }
    Ok(TunedFile {
        tuned,
        record: text,
        swing_up: searched,
    })
}

/// The record `riprs tune` writes beside the tuned file (crate::preflight::TuneRecord):
/// the checksum of the tuned design at sample time `ts` and each controller's prediction,
/// with what of the rig's bar it misses ([`Tuned::shortfalls`]).
pub fn record(tuned: &Tuned, ts: f64) -> Result<TuneRecord, SpecError> {
    Ok(record_of(tuned, &tuned.spec.design(ts)?))
}

/// [`record`] with the tuned spec's `design` made already.
fn record_of(tuned: &Tuned, design: &crate::spec::Design) -> TuneRecord {
    let bar = &tuned.bar.guarded();
    let shortfalls = tuned.shortfalls();
    TuneRecord {
        inputs: design_checksum(design),
        runs: format!(
            "noise seeds {SEEDS:?}, {} s each; with the compensation off, noise seeds \
             {FALL_CHECK_SEEDS:?} too (the fall check)",
            tuned.spec.reference.duration
        ),
        prediction: tuned
            .assessments
            .iter()
            .map(|a| {
                let p = StoredPrediction {
                    fell: a.fell,
                    arm_max: a.arm_max,
                    arm_peak_to_peak: a.arm_peak_to_peak,
                    pendulum: a.pendulum,
                    disk_margin: a.margins.disk_margin,
                    works: a.works(bar),
                    misses: shortfalls
                        .iter()
                        .find(|(k, _)| *k == a.kind)
                        .map(|(_, why)| why.clone()),
                };
                (a.kind.name().to_string(), p)
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The floor's rig and the off-compensation rigs must be specs every command would accept,
    /// or the bar would be measured on a rig no one can run.
    #[test]
    fn the_bar_rigs_are_valid_specs() {
        let spec = Spec::parse(&crate::rig::Rig::random(3).to_toml()).unwrap();
        let floor = frictionless(&spec);
        floor.validate().unwrap();
        let p = floor.plant.params();
        assert_eq!((p.vd, p.cr, p.cp), (0.0, 0.0, 0.0));
        assert!(floor.compensation().unwrap().is_none());
        for e in [-OFF_COMPENSATION, OFF_COMPENSATION] {
            let off = off_compensation(&spec, e).unwrap();
            off.validate().unwrap();
            let c = off.compensation().unwrap().unwrap();
            let p = spec.plant.params();
            assert!((c.dead_zone() - (1.0 + e) * p.vd).abs() < 1e-12);
            assert!((c.friction_voltage() - (1.0 + e) * p.cr * p.rm / p.kt).abs() < 1e-12);
            assert_eq!(off.plant.arm_breakaway, Some(STICTION_RATIO * p.cr));
            // The plant itself is the file's: only what the compensation assumes is off.
            assert_eq!(off.plant.params(), p);
        }
        // The paper preset compensates nothing: no error to apply.
        assert!(off_compensation(&Spec::default(), 0.3).is_none());
    }

    /// The second grid tries only weights the first did not, each once, and every one of them
    /// weights the pendulum more or the arm less than any of the first grid's does.
    #[test]
    fn the_second_grid_is_new_weights_led_by_the_pendulum() {
        let spec = Spec::parse(&crate::rig::Rig::random(3).to_toml()).unwrap();
        let first = candidates(&spec);
        let second = pendulum_led_candidates(&spec);
        assert_eq!(first.len(), 2 * 2 * 4 * ARM.len() * 5 - 1);
        let all = PENDULUM_LED.len() * 2 * 4 * ARM_LED.len() * 5;
        assert_eq!(second.len(), all - first.len() - 1);
        for (i, w) in second.iter().enumerate() {
            assert!(!first.contains(w) && *w != Weights::FILE, "{w:?}");
            assert!(!second[..i].contains(w), "{w:?} twice");
            assert!(w.pendulum > 1.0 || w.arm < 1.0, "{w:?}");
            assert_eq!(w.recovery, 1.0);
            assert!(w.integral_weight == 0.0 || w.integral_weight == spec.lqr.Q[0] * w.arm);
        }
    }
}
