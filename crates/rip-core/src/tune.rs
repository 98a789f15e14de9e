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
//! A candidate **works** when every controller, on the rig's nonlinear model (its dead zone,
//! friction and stiction; `[sensor]`; the `[reference]` step, [`SEEDS`] noise seeds) and with
//! the file's compensation:
//!
//! - balances (no fall, no divergence), with the steady state over the last
//!   [`Bar::window`] seconds inside the bar: arm peak-to-peak, pendulum `|α|`, arm offset
//!   `|mean θ − θ_ref|`;
//! - respects the voltage bound: LQR and LQG never reach their clamp (the MPC plans within
//!   it by construction);
//! - has robustness margins of its linearised loop at the plant input (crate::margins) of at
//!   least [`Bar::gain_margin_db`] both ways and [`Bar::phase_margin_deg`], or the disk margin
//!   of the same disk ([`Bar::disk_margin`]).
//!
//! [`tune`] tries the file's own weights first and keeps them when they work; otherwise the
//! candidates of [`candidates`] in order (closest to the file's first) and keeps the first
//! that works (a candidate whose recovered LQG or MPC misses the margins cannot work, so it is
//! simulated only once none does). When none does, it tries again those whose recovery was
//! raised, without it (a recovered estimator trusts the sensor more, which a coarse or noisy
//! one may not bear), and keeps the one that misses the bar by least (and says so): one that balances
//! within the bar and the voltage bound beats any that does not, and among equals the one
//! nearer the margins wins.
//! [`robustness`] then draws rigs around the file's (each parameter within ±10 %, or from
//! the identification's covariance) and counts the runs each tuned controller balances.

use std::sync::atomic::AtomicBool;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::margins::Margins;
use crate::metrics::table1_rmse;
use crate::plant::{FurutaParams, Plant};
use crate::preflight::{design_checksum, StoredPrediction, TuneRecord};
use crate::sim::simulate;
use crate::spec::rig_sections::COUNTS_PER_REV;
use crate::spec::{ControllerKind, Spec, SpecError};

mod settings;
use settings::check_cancel;
pub use settings::{check_spread, check_ts, check_voltage, Progress, Settings, MAX_RUNS};

/// Noise seeds of each candidate's simulations.
pub const SEEDS: [u64; 2] = [11, 12];

/// What "works" means (module docs). `Default` is the bar: 0.05 rad arm
/// peak-to-peak, 0.02 rad pendulum, 0.02 rad offset over the last 3 s; 6 dB and 30°.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bar {
    /// Largest steady-state arm peak-to-peak (rad).
    pub arm_peak_to_peak: f64,
    /// Largest steady-state `|α|` (rad).
    pub pendulum: f64,
    /// Largest steady-state arm offset from the reference (rad).
    pub offset: f64,
    /// The steady-state window at the end of the run (s).
    pub window: f64,
    /// Smallest gain margin, both ways (dB).
    pub gain_margin_db: f64,
    /// Smallest phase margin (degrees).
    pub phase_margin_deg: f64,
    /// The disk margin accepted in place of the classical ones: the `α` whose disk gives
    /// `gain_margin_db` (`(2 + α)/(2 − α) = 10^{gm/20}`, 0.67 for 6 dB; its phase margin
    /// `2 atan(α/2)` is 36.9°).
    pub disk_margin: f64,
}

impl Bar {
    /// Whether `m` meets the margins of the bar: the classical ones both ways, or the disk's.
    pub fn margins_ok(&self, m: &Margins) -> bool {
        m.meets(self.gain_margin_db, self.phase_margin_deg)
            || (m.stable && m.disk_margin >= self.disk_margin)
    }

    /// How far `m` is from the margins of the bar: 0 when [`margins_ok`](Self::margins_ok),
    /// else the disk margin's relative shortfall (2 for an unstable loop).
    pub fn margin_shortfall(&self, m: &Margins) -> f64 {
        if self.margins_ok(m) {
            0.0
        } else if m.stable {
            (1.0 - m.disk_margin / self.disk_margin).max(0.0)
        } else {
            2.0
        }
    }
}

impl Default for Bar {
    fn default() -> Self {
        let f = 10f64.powf(6.0 / 20.0);
        Self {
            arm_peak_to_peak: 0.05,
            pendulum: 0.02,
            offset: 0.02,
            window: 3.0,
            gain_margin_db: 6.0,
            phase_margin_deg: 30.0,
            disk_margin: 2.0 * (f - 1.0) / (f + 1.0),
        }
    }
}

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
    let mut out = Vec::new();
    let q0 = spec.lqr.Q[0];
    for pendulum in PENDULUM {
        for integral in [0.0, 1.0] {
            for noise in [1.0, 0.1, 0.01, 0.001] {
                for arm in [1.0, 4.0, 16.0] {
                    for input in [1.0, 3.0, 10.0, 30.0, 100.0] {
                        let w = Weights {
                            arm,
                            pendulum,
                            input,
                            integral_weight: integral * q0 * arm,
                            measurement_noise: noise,
                            recovery: 1.0,
                        };
                        if w != Weights::FILE {
                            out.push(w);
                        }
                    }
                }
            }
        }
    }
    out
}

/// The factors `q_α` on the pendulum weights [`candidates`] tries, the file's first.
///
/// With the file's measurement noise, a margins-only grid over `q_θ` (1, 4, 16), `q_α` (0.25,
/// 1, 4), `ρ` (1–100) and the recovery found weights with which LQR, LQG and the MPC all met
/// 6 dB / 30° on generated rigs 3, 4, 5, 7, 8, 14, 15 and 16, mostly with `q_α = 0.25`. They
/// come after every candidate of the file's pendulum weight, so a rig those already balance
/// keeps the weights it had.
pub const PENDULUM: [f64; 2] = [1.0, 0.25];

/// How one controller does on the rig (module docs), the worst over [`SEEDS`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Assessment {
    /// The controller.
    pub kind: ControllerKind,
    /// Its margins at the plant input.
    pub margins: Margins,
    /// The paper's Tab. 1 RMSE `[θ, α, u]` of the first seed's run.
    pub rmse: [f64; 3],
    /// Largest `|u|` applied (V).
    pub peak_voltage: f64,
    /// Whether LQR or LQG reached its clamp.
    pub saturated: bool,
    /// Whether a run fell or diverged.
    pub fell: bool,
    /// Largest `|θ|` over the runs (rad).
    pub arm_max: f64,
    /// Steady-state arm peak-to-peak (rad).
    pub arm_peak_to_peak: f64,
    /// Steady-state largest `|α|` (rad).
    pub pendulum: f64,
    /// Steady-state `|mean θ − θ_ref|` (rad).
    pub offset: f64,
    /// The steady state `(arm peak-to-peak, |α|, offset)` of the same controller with exact
    /// angles (no quantisation, no noise), measured by [`tune`] only for a controller that
    /// balances outside the steady-state bar: when it meets the bar, the miss is the
    /// sensor's ([`sensor_limited`](Self::sensor_limited)), not the weights'.
    pub exact_sensor: Option<(f64, f64, f64)>,
}

impl Assessment {
    /// Whether the margins meet the bar (classical, or the disk's).
    pub fn margins_ok(&self, bar: &Bar) -> bool {
        bar.margins_ok(&self.margins)
    }

    /// Whether the steady state meets the bar and the run did not fall.
    pub fn balances(&self, bar: &Bar) -> bool {
        !self.fell
            && self.arm_peak_to_peak <= bar.arm_peak_to_peak
            && self.pendulum <= bar.pendulum
            && self.offset <= bar.offset
    }

    /// Whether the controller misses the steady-state bar only through the rig's sensor: it
    /// balances, and with exact angles ([`exact_sensor`](Self::exact_sensor)) it meets the
    /// bar. A coarse pendulum encoder (or its noise) is read by the controller as a tilt
    /// `δ`, which it balances by moving the arm about `(K_α / K_θ) δ`: with a few hundred
    /// counts a revolution that alone exceeds the bar, whatever the shared weights.
    pub fn sensor_limited(&self, bar: &Bar) -> bool {
        !self.fell
            && !self.balances(bar)
            && self.exact_sensor.is_some_and(|(pp, alpha, offset)| {
                pp <= bar.arm_peak_to_peak && alpha <= bar.pendulum && offset <= bar.offset
            })
    }

    /// Whether everything of the bar holds (module docs).
    pub fn works(&self, bar: &Bar) -> bool {
        self.balances(bar) && !self.saturated && self.margins_ok(bar)
    }

    /// How far from the bar (0 when it [works](Self::works)): the
    /// [balance shortfall](Self::balance_shortfall) and the margins'
    /// ([`Bar::margin_shortfall`]).
    pub fn shortfall(&self, bar: &Bar) -> f64 {
        self.balance_shortfall(bar) + bar.margin_shortfall(&self.margins)
    }

    /// How far from balancing within the bar and the voltage bound: the relative excess of
    /// each steady-state figure, a fall or saturation counting 10 and 1.
    pub fn balance_shortfall(&self, bar: &Bar) -> f64 {
        let over = |v: f64, limit: f64| (v / limit - 1.0).max(0.0);
        let mut s = if self.fell { 10.0 } else { 0.0 };
        if !self.fell {
            s += over(self.arm_peak_to_peak, bar.arm_peak_to_peak)
                + over(self.pendulum, bar.pendulum)
                + over(self.offset, bar.offset);
        }
        if self.saturated {
            s += 1.0;
        }
        s
    }
}

/// Assesses every controller of `spec` on its rig at sample time `ts` (module docs).
pub fn assess(spec: &Spec, ts: f64, bar: &Bar) -> Result<Vec<Assessment>, SpecError> {
    Ok(assess_until(spec, ts, bar, false)?.0)
}

/// [`assess`]; with `stop_early`, the assessment stops at the first controller that does not
/// balance within the bar and the voltage bound, and the margins are measured only when all
/// do (the search needs no more to rank such a candidate). The flag says whether it is
/// complete.
fn assess_until(
    spec: &Spec,
    ts: f64,
    bar: &Bar,
    stop_early: bool,
) -> Result<(Vec<Assessment>, bool), SpecError> {
    let design = spec.design(ts)?;
    let plant = spec.plant()?;
    let (lo, hi) = design.bounds();
    let clamp = hi.min(-lo);
    let comp = design
        .compensation()
        .map_or(0.0, |c| c.dead_zone() + c.friction_voltage());
    let mut out = Vec::new();
    for kind in ControllerKind::ALL {
        let mut controller = design.controller(kind)?;
        let mut a = Assessment {
            kind,
            margins: Margins::unstable(),
            rmse: [f64::NAN; 3],
            peak_voltage: 0.0,
            saturated: false,
            fell: false,
            arm_max: 0.0,
            arm_peak_to_peak: 0.0,
            pendulum: 0.0,
            offset: 0.0,
            exact_sensor: None,
        };
        for (i, seed) in SEEDS.into_iter().enumerate() {
            let cfg = spec.sim_config(ts, seed);
            let run = simulate(&plant, controller.as_mut(), &cfg)
                .map_err(|e| SpecError::new("plant", format!("simulation: {e}")))?;
            if i == 0 {
                a.rmse = table1_rmse(&run);
            }
            a.fell |= run.fell || run.diverged;
            a.arm_max = run.x.iter().map(|x| x[0].abs()).fold(a.arm_max, f64::max);
            let peak = run.u.iter().map(|u| u.abs()).fold(0.0, f64::max);
            a.peak_voltage = a.peak_voltage.max(peak);
            // The written voltage exceeds the planned clamp by at most the compensation; the
            // controller's own clamp is what saturation means here.
            if kind != ControllerKind::Mpc {
                a.saturated |= peak >= clamp + comp - 1e-9;
            }
            let s = steady_state(&run, bar.window);
            a.arm_peak_to_peak = a.arm_peak_to_peak.max(s.0);
            a.pendulum = a.pendulum.max(s.1);
            a.offset = a.offset.max(s.2);
        }
        let failed = !a.balances(bar) || a.saturated;
        out.push(a);
        if stop_early && failed {
            return Ok((out, false));
        }
    }
    for a in out.iter_mut() {
        a.margins = design.margins(a.kind)?;
    }
    Ok((out, true))
}

/// `(arm peak-to-peak, max |α|, |mean θ − θ_ref|)` of the true state over the last `window`
/// seconds of `run`.
pub fn steady_state(run: &crate::sim::SimResult, window: f64) -> (f64, f64, f64) {
    let Some(&end) = run.t.last() else {
        return (f64::NAN, f64::NAN, f64::NAN);
    };
    let (mut lo, mut hi, mut alpha, mut sum, mut n) =
        (f64::INFINITY, f64::NEG_INFINITY, 0.0f64, 0.0, 0usize);
    for k in 0..run.len() {
        if run.t[k] >= end - window {
            let th = run.x[k][0];
            lo = lo.min(th);
            hi = hi.max(th);
            alpha = alpha.max(run.x[k][2].abs());
            sum += th - run.r[k][0];
            n += 1;
        }
    }
    (hi - lo, alpha, (sum / n.max(1) as f64).abs())
}

/// The rig of `spec` read by exact sensors: the finest resolution the schema accepts
/// (2²⁴ counts, a step of 0.37 µrad, far below any rig's noise), no noise, no offsets; a
/// spec that stays inside [`COUNTS_PER_REV`] so that every run of it can be validated.
fn exact_sensor(spec: &Spec) -> Spec {
    let mut s = spec.clone();
    s.sensor.encoder_counts = [*COUNTS_PER_REV.end(); 2];
    s.sensor.noise_std = [0.0; 2];
    s.sensor.encoder_offsets = [0.0; 2];
    s
}

/// Fills [`Assessment::exact_sensor`] of every controller of `assessments` that balances
/// outside the steady-state bar: the same design (same weights, same estimator) run on the
/// rig read by exact sensors.
fn explain_misses(
    spec: &Spec,
    ts: f64,
    bar: &Bar,
    assessments: &mut [Assessment],
) -> Result<(), SpecError> {
    if assessments.iter().all(|a| a.fell || a.balances(bar)) {
        return Ok(());
    }
    let exact = exact_sensor(spec);
    let design = spec.design(ts)?;
    let plant = spec.plant()?;
    for a in assessments
        .iter_mut()
        .filter(|a| !a.fell && !a.balances(bar))
    {
        let mut controller = design.controller(a.kind)?;
        let mut worst = (0.0f64, 0.0f64, 0.0f64);
        for seed in SEEDS {
            let run = simulate(&plant, controller.as_mut(), &exact.sim_config(ts, seed))
                .map_err(|e| SpecError::new("plant", format!("simulation: {e}")))?;
            let s = if run.fell || run.diverged {
                (f64::INFINITY, f64::INFINITY, f64::INFINITY)
            } else {
                steady_state(&run, bar.window)
            };
            worst = (worst.0.max(s.0), worst.1.max(s.1), worst.2.max(s.2));
        }
        a.exact_sensor = Some(worst);
    }
    Ok(())
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
}

impl Tuned {
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

/// Chooses shared weights for the rig of `spec` at sample time `ts` (module docs).
pub fn tune(spec: &Spec, ts: f64, bar: &Bar) -> Result<Tuned, SpecError> {
    tune_with(spec, ts, bar, &Progress::default(), &AtomicBool::new(false))
}

/// [`tune`], first refusing a rig the pre-flight's voltage check refuses
/// ([`check_voltage`]); counting its steps in `progress` (one per candidate, and one for
/// the final assessment) and stopping with an error between two steps once `cancel` is set.
pub fn tune_with(
    spec: &Spec,
    ts: f64,
    bar: &Bar,
    progress: &Progress,
    cancel: &AtomicBool,
) -> Result<Tuned, SpecError> {
    check_voltage(spec, ts)?;
    let candidates = candidates(spec);
    progress.add(candidates.len() + 2);
    let tuned = search(spec, candidates, ts, bar, progress, cancel)?;
    progress.finish();
    Ok(tuned)
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
    for w in std::iter::once(Weights::FILE).chain(candidates) {
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
    let mut best: Option<((f64, f64), Weights)> = None;
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
            if best.as_ref().map_or(true, |b| s < b.0) {
                best = Some((s, w));
            }
        }
    }
    let (_, weights) = best.ok_or_else(|| {
        SpecError::new("lqr", "no candidate weights could be designed for this rig")
    })?;
    check_cancel(cancel)?;
    let spec = weights.apply(spec);
    let mut assessments = assess(&spec, ts, bar)?;
    explain_misses(&spec, ts, bar, &mut assessments)?;
    Ok(Tuned {
        spec,
        weights,
        works: false,
        assessments,
        tried,
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
    let Ok((assessments, complete)) = assess_until(&candidate, ts, bar, true) else {
        return Judgement::NoDesign;
    };
    if complete && assessments.iter().all(|a| a.works(bar)) {
        return Judgement::Works(Box::new(Tuned {
            spec: candidate,
            weights: w,
            works: true,
            assessments,
            tried: 0,
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
        .map(|a| bar.margin_shortfall(&a.margins))
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
                .map_or(2.0, |m| bar.margin_shortfall(&m));
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

/// The record `riprs tune` writes beside the tuned file (crate::preflight::TuneRecord):
/// the checksum of the tuned design at sample time `ts` and each controller's prediction.
pub fn record(tuned: &Tuned, ts: f64, bar: &Bar) -> Result<TuneRecord, SpecError> {
    let design = tuned.spec.design(ts)?;
    Ok(TuneRecord {
        inputs: design_checksum(&design),
        runs: format!(
            "noise seeds {SEEDS:?}, {} s each",
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
                };
                (a.kind.name().to_string(), p)
            })
            .collect(),
    })
}

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

#[cfg(test)]
mod tests {
    use super::*;

    /// The diagnosis run must be a spec every command would accept, or its verdict would
    /// describe a rig no one can run.
    #[test]
    fn the_exact_sensor_rig_is_a_valid_spec() {
        let spec = Spec::default();
        let exact = exact_sensor(&spec);
        exact.validate().expect("exact-sensor spec validates");
        exact
            .design(crate::paper::TS)
            .expect("exact-sensor spec designs");
    }
}
