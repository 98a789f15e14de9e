//! Closed-loop simulation: the nonlinear [`Plant`] integrated by RK4 at a fine step, a
//! [`Controller`] sampled every `Ts` with its input held (zero-order hold), and a sensor model.
//!
//! Each control period `k` (time `t_k = k Ts`):
//!
//! ```text
//! y[k] = quantise(C x(t_k)) + v[k] + d_y(t_k)         v ~ N(0, diag(σ²)), seeded
//! u[k] = controller.step(y[k], r[k])                   timed with a monotonic clock
//! x(t_{k+1}) = RK4 over [t_k, t_{k+1}] with sat(u[k], ±u_limit), torque disturbance τ_d(t)
//! ```
//!
//! - quantise: an encoder of `N` counts per revolution reports `q·round(angle/q)`, `q = 2π/N`
//!   (rounding to the nearest count keeps the error zero-mean, `|error| ≤ q/2`);
//! - `d_y`: an optional output step disturbance (time, size per output);
//! - `τ_d`: an optional step torque on the arm (N·m) from a given time;
//! - the reference is a step (time, value per output) or a full sequence, one row per sample.
//!
//! The run stops early when the pendulum falls (`|α| > fall_limit`, α wrapped to (−π, π],
//! checked after every RK4 substep while the controller is in [`Phase::Balance`]) or when the integration diverges (the state overflows to NaN or Inf: a numerical
//! failure, not a fall, so it is flagged [`SimResult::diverged`] instead of
//! [`SimResult::fell`]); the result is then truncated to the samples taken and flagged, so it
//! never holds NaN. A swing-up supervisor ([`crate::swingup::SwingUp`]) starts in
//! [`Phase::SwingUp`], so a run may start hanging; its catch is recorded
//! ([`SimResult::catch_time`]), leaving [`Phase::Balance`] after it is a fall, and a
//! [`Phase::Stopped`] controller ends the run ([`SimResult::stop_cause`]). Everything a run needs is preallocated before the
//! loop. [`simulate_batch`] runs many seeds and parameter variants in parallel with rayon.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

use crate::controller::{Controller, Phase, StepStatus, StopCause};
use crate::error::{Result, RipError};
use crate::plant::{Plant, State};
use crate::trig::wrap_angle;

mod runs;
pub mod vec_env;
pub use runs::{
    batch_runs, simulate_batch, simulate_batch_cloned, simulate_runs, simulate_runs_cancellable,
    Pairing,
};

/// Largest number of control samples one run may have (guards against accidental huge
/// allocations, e.g. a duration in ms passed as s).
pub const MAX_SAMPLES: usize = 10_000_000;

pub use crate::plant::MAX_SUBSTEPS;

/// Default length of a run (s): the span of the paper's step-response figures.
pub const DEFAULT_DURATION: f64 = 10.0;

/// Default RK4 substeps per control period: 1 ms steps at `Ts = 0.01 s`, well inside RK4's
/// stability limit for the pendulum's fastest mode.
pub const DEFAULT_SUBSTEPS: usize = 10;

/// Default fall limit on `|α|` (rad): past horizontal the pendulum cannot be balanced.
pub const DEFAULT_FALL_LIMIT: f64 = std::f64::consts::FRAC_PI_2;

/// The reference `r[k] = [θ_ref, α_ref]`.
#[derive(Debug, Clone, PartialEq)]
pub enum Reference {
    /// `r = 0` before `time`, `value` from `time` on.
    Step {
        /// Switching time (s) from the start of the run.
        time: f64,
        /// `[θ_ref, α_ref]` (rad) held from `time` on.
        value: [f64; 2],
    },
    /// One row per control sample; its length must equal the number of samples.
    Sequence(Vec<[f64; 2]>),
    /// `r = 0` until `delay` seconds after the catch of a swing-up supervisor
    /// ([`SimResult::catch_time`]), `value` from then on; 0 throughout a run without a catch.
    /// The experiment of `riprs compare --start down`: swing up, catch, then the step.
    StepAfterCatch {
        /// Time (s) from the catch to the step.
        delay: f64,
        /// `[θ_ref, α_ref]` (rad) held from the step on.
        value: [f64; 2],
    },
}

impl Default for Reference {
    fn default() -> Self {
        Reference::Step {
            time: 0.0,
            value: [0.0, 0.0],
        }
    }
}

/// Allowed encoder resolutions (`sensor.encoder_counts` of an experiment file, and of the
/// environments of [`vec_env`]). Below 128 counts per revolution (0.05 rad) the calibration's
/// rest check cannot tell a still joint from a turning one: its rate threshold must lie above
/// 2 counts per `spec::rig_sections::RATE_SPAN_S` and at most
/// `spec::rig_sections::MAX_REST_RATE`, an empty range under 126 counts (and quadrature
/// encoders count in fours); the pendulum angle is too coarse to balance on well before that.
/// Above 2²⁴ the multi-turn i32 count overflows within 128 turns. Defined here, with the
/// sensor model, so that `spec` and [`vec_env`] share it.
pub const COUNTS_PER_REV: std::ops::RangeInclusive<u32> = 128..=(1 << 24);

/// Allowed control periods (ms: `loop.period_ms` of a rig file, and `Ts` of the environments
/// of [`vec_env`]). Above 20 ms the device's 50 ms command watchdog (protocol.md) would see
/// fewer than three commands per window and the pendulum (unstable pole near 10 rad/s) is no
/// longer controllable at that rate; below 1 ms a serial round trip cannot fit. Defined here
/// so that `spec` and [`vec_env`] share it.
pub const PERIOD_MS: std::ops::RangeInclusive<f64> = 1.0..=20.0;

/// Largest accepted measurement-noise standard deviation (rad): far beyond any angle (noise
/// above π already hides the angle completely), and small enough that the squared noise in an
/// RMSE never overflows.
pub const MAX_NOISE_STD: f64 = 1e3;

/// Encoder quantisation and white measurement noise.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorModel {
    /// Encoder counts per revolution of `[θ, α]`; `None` for exact angles.
    pub counts_per_rev: Option<[f64; 2]>,
    /// Standard deviation (rad) of the Gaussian noise added to `[θ, α]`, at most
    /// [`MAX_NOISE_STD`].
    pub noise_std: [f64; 2],
    /// Encoder zero offsets (rad): the encoders read `[θ + o₀, α + o₁]` before quantisation.
    pub offsets: [f64; 2],
}

impl SensorModel {
    /// The measured angles `[θ, α]` of the true state `x` (module docs): offset, quantised,
    /// then noise of standard deviation `noise_std` (this model's, or a drawn one), one
    /// standard-normal draw from `rng` per angle with a positive deviation.
    #[inline]
    pub fn measure<R: rand::Rng + ?Sized>(
        &self,
        x: &[f64; 4],
        noise_std: [f64; 2],
        rng: &mut R,
    ) -> [f64; 2] {
        let mut y = [0.0; 2];
        for (i, yi) in y.iter_mut().enumerate() {
            let angle = x[2 * i] + self.offsets[i];
            let mut v = match self.counts_per_rev {
                Some(cpr) => quantise(angle, cpr[i]),
                None => angle,
            };
            if noise_std[i] > 0.0 {
                let z: f64 = StandardNormal.sample(rng);
                v += noise_std[i] * z;
            }
            *yi = v;
        }
        y
    }
}

/// A step that starts at `time`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepDisturbance<T> {
    /// Start time (s).
    pub time: f64,
    /// Size.
    pub value: T,
}

/// Everything a run needs besides the plant and the controller.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Length of the run (s); the number of samples is `round(duration / ts)`.
    pub duration: f64,
    /// Control period (s).
    pub ts: f64,
    /// RK4 steps per control period.
    pub substeps: usize,
    /// Initial state `[θ, θ̇, α, α̇]`.
    pub x0: [f64; 4],
    /// Reference of the two outputs.
    pub reference: Reference,
    /// Sensor model.
    pub sensor: SensorModel,
    /// Step added to the measured outputs `[θ, α]` (rad).
    pub output_disturbance: Option<StepDisturbance<[f64; 2]>>,
    /// Step torque on the arm (N·m).
    pub torque_disturbance: Option<StepDisturbance<f64>>,
    /// Actuator saturation: the plant receives `clamp(u, −u_limit, u_limit)` (V).
    pub u_limit: f64,
    /// The run stops, flagged as a fall, when `|α|` (wrapped) exceeds this (rad) while the
    /// controller balances.
    pub fall_limit: f64,
    /// Seed of the measurement noise.
    pub seed: u64,
    /// Where a swing-up's run ends once caught: this long (s) after the catch, however long
    /// `duration` would have run on (`None`: `duration` alone). A study that only judges the
    /// catch and the hold after it (`crate::spec::study`) simulates no further.
    pub end_after_catch: Option<f64>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            duration: DEFAULT_DURATION,
            ts: crate::paper::TS,
            substeps: DEFAULT_SUBSTEPS,
            x0: [0.0; 4],
            reference: Reference::default(),
            sensor: SensorModel::default(),
            output_disturbance: None,
            torque_disturbance: None,
            u_limit: crate::paper::INPUT_LIMIT,
            fall_limit: DEFAULT_FALL_LIMIT,
            seed: 0,
            end_after_catch: None,
        }
    }
}

fn finite(name: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(RipError::NonFinite { name: name.into() })
    }
}

fn positive(name: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(RipError::invalid(
            name,
            format!("must be positive and finite, got {v}"),
        ))
    }
}

impl SimConfig {
    /// Validates the configuration and returns the number of control samples.
    pub fn validate(&self) -> Result<usize> {
        positive("duration", self.duration)?;
        positive("Ts", self.ts)?;
        let samples = (self.duration / self.ts).round();
        if samples < 1.0 || samples > MAX_SAMPLES as f64 {
            return Err(RipError::invalid(
                "duration",
                format!(
                    "gives {samples} samples of Ts = {}; need 1 to {MAX_SAMPLES}",
                    self.ts
                ),
            ));
        }
        let n = samples as usize;
        if self.substeps == 0 || self.substeps > MAX_SUBSTEPS {
            return Err(RipError::invalid(
                "substeps",
                format!(
                    "must be between 1 and {MAX_SUBSTEPS}, got {}",
                    self.substeps
                ),
            ));
        }
        if self.x0.iter().any(|v| !v.is_finite()) {
            return Err(RipError::NonFinite { name: "x0".into() });
        }
        positive("fall_limit", self.fall_limit)?;
        positive("u_limit", self.u_limit)?;
        if let Some(end) = self.end_after_catch {
            positive("end_after_catch", end)?;
        }
        match &self.reference {
            Reference::Step { time, value } => {
                finite("reference time", *time)?;
                finite("reference", value[0])?;
                finite("reference", value[1])?;
            }
            Reference::StepAfterCatch { delay, value } => {
                if !(delay.is_finite() && *delay >= 0.0) {
                    return Err(RipError::invalid(
                        "step_after_catch",
                        format!("must be non-negative and finite, got {delay}"),
                    ));
                }
                finite("reference", value[0])?;
                finite("reference", value[1])?;
            }
            Reference::Sequence(seq) => {
                if seq.len() != n {
                    return Err(RipError::Shape {
                        name: "reference".into(),
                        expected: format!("({n}, 2), one row per sample"),
                        rows: seq.len(),
                        cols: 2,
                    });
                }
                if seq.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(RipError::NonFinite {
                        name: "reference".into(),
                    });
                }
            }
        }
        if let Some(cpr) = self.sensor.counts_per_rev {
            for c in cpr {
                positive("encoder_counts", c)?;
            }
        }
        if self.sensor.offsets.iter().any(|o| !o.is_finite()) {
            return Err(RipError::NonFinite {
                name: "offsets".into(),
            });
        }
        for s in self.sensor.noise_std {
            if !(s.is_finite() && (0.0..=MAX_NOISE_STD).contains(&s)) {
                return Err(RipError::invalid(
                    "noise_std",
                    format!("must be between 0 and {MAX_NOISE_STD:e} rad, got {s}"),
                ));
            }
        }
        if let Some(d) = &self.output_disturbance {
            finite("output_disturbance time", d.time)?;
            finite("output_disturbance", d.value[0])?;
            finite("output_disturbance", d.value[1])?;
        }
        if let Some(d) = &self.torque_disturbance {
            finite("torque_disturbance time", d.time)?;
            finite("torque_disturbance", d.value)?;
        }
        Ok(n)
    }
}

/// The record of one run; every `Vec` has one entry per control sample taken.
#[derive(Debug, Clone, PartialEq)]
pub struct SimResult {
    /// Sample times `k Ts` (s).
    pub t: Vec<f64>,
    /// True state at each sample.
    pub x: Vec<[f64; 4]>,
    /// Measured outputs `[θ, α]`.
    pub y: Vec<[f64; 2]>,
    /// Input applied to the plant over the following period (after actuator saturation).
    pub u: Vec<f64>,
    /// Reference at each sample.
    pub r: Vec<[f64; 2]>,
    /// The controller's state estimate after each step, row-major with `n_estimate` columns;
    /// empty when the controller has none.
    pub x_hat: Vec<f64>,
    /// Columns of `x_hat` (0 when there is no estimate).
    pub n_estimate: usize,
    /// Wall-clock time of each `Controller::step` call (s).
    pub compute_time: Vec<f64>,
    /// Number of steps the controller reported as [`StepStatus::Fallback`].
    pub fallbacks: usize,
    /// The controller's [`Phase`] after each step (always [`Phase::Balance`] for a balance
    /// controller).
    pub phase: Vec<Phase>,
    /// Time of the first sample balanced after a swing-up (the catch; time to upright), when
    /// the controller swung up and caught.
    pub catch_time: Option<f64>,
    /// Why the controller gave up, when it did (the run ends at that sample).
    pub stop_cause: Option<StopCause>,
    /// Whether the pendulum fell (`|α| > fall_limit` while balancing, or the supervisor left
    /// its balance region after the catch) before the end.
    pub fell: bool,
    /// Whether the integration diverged (the state overflowed to NaN or Inf) before the end:
    /// a numerical failure of the model or its parameters, not a fall. [`x_final`](Self::x_final)
    /// is then the last finite state.
    pub diverged: bool,
    /// Time of the fall, to the RK4 substep (s).
    pub fall_time: Option<f64>,
    /// State at the end of the run (or at the fall).
    pub x_final: [f64; 4],
}

/// Whether a run that starts with a swing-up succeeded, the one definition used by every
/// report: the supervisor caught the pendulum (time to upright = the catch time, the first
/// balanced sample) and then stayed in its balance region to the end of the run, without a
/// stop or a numerical divergence.
pub fn swing_up_succeeded(
    catch_time: Option<f64>,
    fell: bool,
    diverged: bool,
    stop_cause: Option<StopCause>,
) -> bool {
    catch_time.is_some() && !fell && !diverged && stop_cause.is_none()
}

impl SimResult {
    /// The time to upright (s): the catch time of a swing-up, `None` without one.
    pub fn time_to_upright(&self) -> Option<f64> {
        self.catch_time
    }

    /// [`swing_up_succeeded`] for this run.
    pub fn swing_up_succeeded(&self) -> bool {
        swing_up_succeeded(self.catch_time, self.fell, self.diverged, self.stop_cause)
    }

    fn with_capacity(n: usize, n_estimate: usize) -> Self {
        Self {
            t: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            u: Vec::with_capacity(n),
            r: Vec::with_capacity(n),
            x_hat: Vec::with_capacity(n * n_estimate),
            n_estimate,
            compute_time: Vec::with_capacity(n),
            fallbacks: 0,
            phase: Vec::with_capacity(n),
            catch_time: None,
            stop_cause: None,
            fell: false,
            diverged: false,
            fall_time: None,
            x_final: [0.0; 4],
        }
    }

    /// Number of samples recorded.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether no sample was recorded.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
}

#[inline]
fn quantise(angle: f64, counts: f64) -> f64 {
    let q = std::f64::consts::TAU / counts;
    q * (angle / q).round()
}

/// Never set: the cancel flag of the calls that cannot be cancelled.
pub(super) static NEVER: AtomicBool = AtomicBool::new(false);

/// What one closed-loop run hands to its record, once per control sample.
pub(crate) trait Recorder {
    /// Sample `k` at time `t`: true state `x`, measured `y`, applied input `u`, reference `r`,
    /// the controller's estimate after its step and the step's wall-clock time (s).
    #[allow(clippy::too_many_arguments)]
    fn sample(
        &mut self,
        t: f64,
        x: &[f64; 4],
        y: &[f64; 2],
        u: f64,
        r: &[f64; 2],
        estimate: Option<&[f64]>,
        elapsed: f64,
    );

    /// The controller's phase after the step of the sample just recorded.
    #[inline]
    fn phase(&mut self, phase: Phase) {
        let _ = phase;
    }
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Outcome {
    pub fallbacks: usize,
    pub fell: bool,
    pub diverged: bool,
    pub fall_time: Option<f64>,
    pub catch_time: Option<f64>,
    pub stop_cause: Option<StopCause>,
    pub x_final: [f64; 4],
}

impl Recorder for SimResult {
    #[inline]
    fn sample(
        &mut self,
        t: f64,
        x: &[f64; 4],
        y: &[f64; 2],
        u: f64,
        r: &[f64; 2],
        estimate: Option<&[f64]>,
        elapsed: f64,
    ) {
        self.t.push(t);
        self.x.push(*x);
        self.y.push(*y);
        self.u.push(u);
        self.r.push(*r);
        self.compute_time.push(elapsed);
        if let Some(est) = estimate {
            self.x_hat
                .extend_from_slice(&est[..self.n_estimate.min(est.len())]);
        }
    }

    #[inline]
    fn phase(&mut self, phase: Phase) {
        self.phase.push(phase);
    }
}

/// Validates a run and returns its number of samples: the configuration, and a controller
/// with 2 outputs, 1 input and (if it has one) the configured sample time.
pub(crate) fn prepare(controller: &dyn Controller, config: &SimConfig) -> Result<usize> {
    let n = config.validate()?;
    if controller.n_outputs() != 2 || controller.n_inputs() != 1 {
        return Err(RipError::invalid(
            "controller",
            format!(
                "must have 2 outputs and 1 input, has {} and {}",
                controller.n_outputs(),
                controller.n_inputs()
            ),
        ));
    }
    if let Some(designed) = controller.sample_time() {
        if (designed - config.ts).abs() > 1e-9 * designed {
            return Err(RipError::invalid(
                "Ts",
                format!(
                    "the controller was designed for Ts = {designed} s; sampling it every {} s \
                     would run it at the wrong rate",
                    config.ts
                ),
            ));
        }
    }
    Ok(n)
}

/// The closed loop of the module docs over `n` samples of a [`prepare`]d run, feeding `record`.
/// Checks `cancel` once per control sample.
pub(crate) fn run_loop(
    plant: &Plant,
    controller: &mut dyn Controller,
    config: &SimConfig,
    n: usize,
    record: &mut impl Recorder,
    cancel: &AtomicBool,
) -> Result<Outcome> {
    controller.reset();
    // A controller that starts by swinging up expects the pendulum anywhere; a balance
    // controller started beyond the fall limit would fall at once.
    let mut was = controller.phase();
    if was == Phase::Balance && wrap_angle(config.x0[2]).abs() > config.fall_limit {
        return Err(RipError::invalid(
            "x0",
            format!(
                "pendulum angle {} is already beyond fall_limit {}",
                config.x0[2], config.fall_limit
            ),
        ));
    }
    let mut rng = StdRng::seed_from_u64(config.seed);
    let mut x = State::from_row_slice(&config.x0);
    let (ts, substeps) = (config.ts, config.substeps);
    let h = ts / substeps as f64;
    let mut u = [0.0];
    let mut y = [0.0; 2];
    let mut out = Outcome {
        fallbacks: 0,
        fell: false,
        diverged: false,
        fall_time: None,
        catch_time: None,
        stop_cause: None,
        x_final: [0.0; 4],
    };

    for k in 0..n {
        if cancel.load(Ordering::Relaxed) {
            return Err(RipError::Cancelled);
        }
        let t = k as f64 * ts;
        let measured =
            config
                .sensor
                .measure(&[x[0], x[1], x[2], x[3]], config.sensor.noise_std, &mut rng);
        for (i, (yi, v)) in y.iter_mut().zip(measured).enumerate() {
            *yi = match &config.output_disturbance {
                Some(d) if t >= d.time => v + d.value[i],
                _ => v,
            };
        }
        let r = match &config.reference {
            Reference::Step { time, value } => {
                if t >= *time {
                    *value
                } else {
                    [0.0, 0.0]
                }
            }
            Reference::Sequence(seq) => seq[k],
            Reference::StepAfterCatch { delay, value } => match out.catch_time {
                // Within a rounding of the sample grid: `t − t_c` is a multiple of `Ts`.
                Some(tc) if t - tc >= *delay - 1e-9 * ts => *value,
                _ => [0.0, 0.0],
            },
        };

        let start = Instant::now();
        let status = controller.step(&y, &r, &mut u);
        let elapsed = start.elapsed().as_secs_f64();
        if status == StepStatus::Fallback {
            out.fallbacks += 1;
        }
        let u_applied = if u[0].is_finite() {
            u[0].clamp(-config.u_limit, config.u_limit)
        } else {
            0.0
        };
        record.sample(
            t,
            &[x[0], x[1], x[2], x[3]],
            &y,
            u_applied,
            &r,
            controller.state_estimate(),
            elapsed,
        );
        let phase = controller.phase();
        record.phase(phase);
        if phase == Phase::Balance && was == Phase::SwingUp && out.catch_time.is_none() {
            out.catch_time = Some(t);
        }
        if was == Phase::Balance && phase != Phase::Balance {
            // The supervisor's own balance region ends before the fall limit: a fall.
            out.fell = true;
            out.fall_time = Some(t);
        }
        if let Phase::Stopped(cause) = phase {
            out.stop_cause = Some(cause);
        }
        if out.fell || out.stop_cause.is_some() {
            break;
        }
        // The sample at `t_c + end` is the run's last: a judge of the hold that far after
        // the catch sees it (`t − t_c` is a multiple of `Ts`, within a rounding).
        if let (Some(end), Some(tc)) = (config.end_after_catch, out.catch_time) {
            if t - tc >= end - 1e-9 * ts {
                break;
            }
        }
        was = phase;

        for j in 0..substeps {
            let t_sub = t + j as f64 * h;
            let tau = match &config.torque_disturbance {
                Some(d) if t_sub >= d.time => d.value,
                _ => 0.0,
            };
            let before = x;
            plant.rk4_step(&mut x, u_applied, tau, h);
            if !x.iter().all(|v| v.is_finite()) {
                out.diverged = true;
                x = before;
                break;
            }
            if phase == Phase::Balance && wrap_angle(x[2]).abs() > config.fall_limit {
                out.fell = true;
                out.fall_time = Some(t_sub + h);
                break;
            }
        }
        if out.fell || out.diverged {
            break;
        }
    }
    out.x_final = [x[0], x[1], x[2], x[3]];
    Ok(out)
}

/// Runs one closed loop (module docs). The controller is [`reset`](Controller::reset) first and
/// must have 2 outputs and 1 input.
pub fn simulate(
    plant: &Plant,
    controller: &mut dyn Controller,
    config: &SimConfig,
) -> Result<SimResult> {
    simulate_cancellable(plant, controller, config, &NEVER)
}

/// [`simulate`] that stops with [`RipError::Cancelled`] within one control sample of `cancel`
/// being set (by another thread, e.g. on Ctrl-C).
pub fn simulate_cancellable(
    plant: &Plant,
    controller: &mut dyn Controller,
    config: &SimConfig,
    cancel: &AtomicBool,
) -> Result<SimResult> {
    let n = prepare(controller, config)?;
    let n_est = controller.state_estimate().map_or(0, |s| s.len());
    let mut out = SimResult::with_capacity(n, n_est);
    let end = run_loop(plant, controller, config, n, &mut out, cancel)?;
    out.fallbacks = end.fallbacks;
    out.fell = end.fell;
    out.diverged = end.diverged;
    out.fall_time = end.fall_time;
    out.catch_time = end.catch_time;
    out.stop_cause = end.stop_cause;
    out.x_final = end.x_final;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::regulators::{Lqg, Lqr};

    fn tilted(reference: Reference) -> SimConfig {
        SimConfig {
            duration: 10.0,
            x0: [0.0, 0.0, 0.1, 0.0],
            reference,
            ..Default::default()
        }
    }

    #[test]
    fn lqr_and_lqg_balance_the_paper_plant_and_track_the_step() {
        let plant = Plant::paper();
        let step = Reference::Step {
            time: 1.0,
            value: [1.0, 0.0],
        };
        let config = SimConfig {
            sensor: SensorModel {
                counts_per_rev: Some([2048.0, 2048.0]),
                noise_std: [1e-3, 1e-3],
                offsets: [0.0; 2],
            },
            ..tilted(step)
        };
        for (name, mut c) in [
            (
                "lqr",
                Box::new(Lqr::paper().unwrap()) as Box<dyn Controller>,
            ),
            ("lqg", Box::new(Lqg::paper().unwrap())),
        ] {
            let res = simulate(&plant, c.as_mut(), &config).unwrap();
            assert!(!res.fell, "{name} fell at {:?}", res.fall_time);
            assert_eq!(res.len(), 1000);
            let last = res.x.last().unwrap();
            assert!((last[0] - 1.0).abs() < 0.05, "{name}: θ = {}", last[0]);
            assert!(last[2].abs() < 0.02, "{name}: α = {}", last[2]);
            assert!(res.u.iter().all(|u| u.abs() <= 12.0));
        }
    }

    #[test]
    fn a_fall_is_flagged_and_truncates_the_record() {
        let plant = Plant::paper();
        let mut c = Lqr::new(&crate::linalg::Mat::zeros(1, 4), 0.01, 20.0).unwrap();
        let res = simulate(&plant, &mut c, &tilted(Reference::default())).unwrap();
        assert!(res.fell);
        let tf = res.fall_time.unwrap();
        assert!(tf > 0.0 && tf < 10.0);
        assert_eq!(res.len(), (tf / 0.01).ceil() as usize);
        assert!(res.x.iter().flatten().all(|v| v.is_finite()));
        assert!(res.x_final[2].abs() > std::f64::consts::FRAC_PI_2);
    }

    #[test]
    fn runs_are_reproducible_and_batch_equals_serial() {
        let plants = [Plant::paper(), Plant::qube_servo2()];
        let seeds = [1, 2, 3];
        let config = SimConfig {
            duration: 2.0,
            sensor: SensorModel {
                counts_per_rev: None,
                noise_std: [2e-3, 2e-3],
                offsets: [0.0; 2],
            },
            ..tilted(Reference::default())
        };
        let lqg = Lqg::paper().unwrap();
        let batch = simulate_batch_cloned(&plants, &seeds, &config, &lqg).unwrap();
        assert_eq!(batch.len(), 6);
        for (i, res) in batch.iter().enumerate() {
            let cfg = SimConfig {
                seed: seeds[i % 3],
                ..config.clone()
            };
            let serial = simulate(&plants[i / 3], &mut lqg.clone(), &cfg).unwrap();
            assert_eq!(serial.x, res.x);
            assert_eq!(serial.y, res.y);
        }
        assert_ne!(batch[0].y, batch[1].y);
    }

    #[test]
    fn bad_configuration_is_rejected() {
        let plant = Plant::paper();
        let mut c = Lqr::paper().unwrap();
        let bad = [
            SimConfig {
                ts: 0.0,
                ..Default::default()
            },
            SimConfig {
                substeps: 0,
                ..Default::default()
            },
            SimConfig {
                x0: [0.0, 0.0, 2.0, 0.0],
                ..Default::default()
            },
            SimConfig {
                reference: Reference::Sequence(vec![[0.0; 2]; 3]),
                ..Default::default()
            },
            SimConfig {
                sensor: SensorModel {
                    counts_per_rev: None,
                    noise_std: [-1.0, 0.0],
                    offsets: [0.0; 2],
                },
                ..Default::default()
            },
        ];
        let names = ["Ts", "substeps", "x0", "reference", "noise_std"];
        for (cfg, name) in bad.iter().zip(names) {
            let err = simulate(&plant, &mut c, cfg).unwrap_err();
            assert!(err.to_string().contains(name), "{err}");
        }
    }

    #[test]
    fn batch_runs_pair_plants_and_seeds_and_name_the_bad_argument() {
        assert_eq!(
            batch_runs(2, &[7, 9], Pairing::Product).unwrap(),
            [(0, 7), (0, 9), (1, 7), (1, 9)]
        );
        assert_eq!(
            batch_runs(2, &[7, 9], Pairing::OneToOne).unwrap(),
            [(0, 7), (1, 9)]
        );
        let name = |e: RipError| match e {
            RipError::InvalidParameter { name, .. } => name,
            other => panic!("{other}"),
        };
        assert_eq!(
            name(batch_runs(0, &[1], Pairing::Product).unwrap_err()),
            "plants"
        );
        assert_eq!(
            name(batch_runs(1, &[], Pairing::OneToOne).unwrap_err()),
            "seeds"
        );
        let err = batch_runs(2, &[1, 2, 3], Pairing::OneToOne).unwrap_err();
        assert!(err.to_string().contains("2 plants, 3 seeds"), "{err}");
        assert_eq!(name(err), "seeds");
    }
}
