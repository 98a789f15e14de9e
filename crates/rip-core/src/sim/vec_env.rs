//! Reinforcement-learning environments on the nonlinear [`Plant`]: `N` independent pendulums
//! stepped in one call ([`VecEnv`]), the engine behind `riprs.envs` (Gymnasium).
//!
//! # One environment
//!
//! Every environment is the closed loop of [`crate::sim`] with the controller replaced by an
//! agent's action `a ∈ [−1, 1]`. Each step `k` (one control period `Ts`):
//!
//! ```text
//! u_cmd[k] = u_limit · clamp(a[k], −1, 1)
//! u[k]     = u_cmd[k − d]                   action delay d periods (0 V before the first)
//! x(t_{k+1}) = RK4 over [t_k, t_{k+1}] with u[k], `substeps` steps (the plant of `crate::plant`)
//! y[k+1]   = quantise(θ, α) + v             the sensor model of `crate::sim` (counts, noise)
//! o[k+1]   = [cos y₀, sin y₀, cos y₁, sin y₁, ω̂₀, ω̂₁]   delivered `l` periods late
//! ```
//!
//! The rates `ω̂` are estimated the way the rig's LQR estimates them ([`crate::regulators::Lqr`]):
//! the backward difference of the measured angles through a first-order low-pass,
//!
//! ```text
//! ω̂[k] = a ω̂[k−1] + (1 − a) (y[k] − y[k−1]) / Ts,   a = e^{−2π f_c Ts}
//! ```
//!
//! starting at zero after a reset, and clipped to ±[`MAX_OBS_RATE`] in the observation. Angles enter as cosine and sine (continuous across ±π, as in
//! gym-brt and Armandpl/furuta). The observation latency `l` models the USB round trip: the
//! agent sees the measurement of `l` periods ago (before the episode's first, the first).
//!
//! # Reward and termination
//!
//! With `θ` and `α` (wrapped to (−π, π], 0 upright) the true state after the step,
//!
//! ```text
//! r[k] = 1 − (0.8 |α| + 0.2 |θ|) / π − c_u a[k]²
//! ```
//!
//! gym-brt's reward for both tasks: at most 1 per step, upright and centred, so that surviving
//! pays and the arm is kept near its centre; `c_u` ([`EnvConfig::action_cost`]) discourages
//! bang-bang voltages that a real motor driver and gearless arm punish. The reward uses the
//! true state: it is a training signal, never an observation, and quantisation noise in it
//! would only slow learning.
//!
//! An episode *terminates* when `|θ| > arm_limit` (the arm's travel: the cable or the end stops
//! of a real rig; default [`crate::swingup::SwingUpSettings`]' `arm_limit`), in the balance task
//! also when `|α| > fall_limit` (default [`crate::sim::DEFAULT_FALL_LIMIT`]: past horizontal
//! the pendulum cannot be balanced and the task has become a swing-up), and when the
//! integration diverges (a state that overflows: the state is kept at its last finite value).
//! It is *truncated* after [`EnvConfig::max_steps`] steps (default: the
//! [`crate::sim::DEFAULT_DURATION`] of a simulated run).
//!
//! # Starts and domain randomisation
//!
//! Each reset draws, from the environment's own generator and in this order: the plant's
//! parameters ([`Randomisation`]), the action delay, the noise level, then the initial state
//! `x₀ = x_nominal + U(−s, s)⁴` with `x_nominal` upright (balance) or hanging (swing-up, α = π)
//! at rest and `s` = [`EnvConfig::init_spread`], then the first measurement. A reset with a seed
//! restarts the generator (`StdRng::seed_from_u64`); one without continues it. An environment
//! is therefore a function of its seed and its actions alone: the `i`-th environment of a
//! [`VecEnv`] and a [`VecEnv`] of one environment seeded alike produce the same bits.
//!
//! # Autoreset
//!
//! [`VecEnv::step`] with `autoreset` follows Gymnasium 1.x's default (next-step mode): the step
//! after the one that ended an episode resets that environment instead of stepping it, ignores
//! its action and reports its first observation with reward 0 and neither flag set.
//!
//! Stepping allocates nothing; resets build the drawn [`Plant`] (which computes its RK4
//! stability limit). [`VecEnv::step`] integrates [`LANES`] environments per call of
//! [`Plant::advance_lanes`] (each in its own SIMD lane, with its own drawn plant: the bits of
//! [`Plant::advance`]), and spreads these chunks over threads (rayon) from
//! [`PARALLEL_MIN_ENVS`] environments on.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use crate::error::{Result, RipError};
use crate::plant::{FurutaParams, Plant, State};
use crate::sim::{
    SensorModel, DEFAULT_DURATION, DEFAULT_FALL_LIMIT, DEFAULT_SUBSTEPS, MAX_NOISE_STD,
};
use crate::spec::Param;
use crate::swingup::wrap_angle;

/// Length of an observation `[cos θ, sin θ, cos α, sin α, ω̂_θ, ω̂_α]`.
pub const OBS_DIM: usize = 6;

/// Bound (rad/s) of the observed rates, which are clipped to it (the filter itself is not):
/// a finite observation space. Far above the fastest motion of the envelope of rigs
/// (`docs/design.md`): a pendulum of 0.08 m falling from upright reaches `√(12 g / L) ≈ 38`
/// rad/s.
pub const MAX_OBS_RATE: f64 = 100.0;

/// Longest action delay and observation latency (control periods).
pub const MAX_DELAY: usize = 16;

/// From this many environments on, [`VecEnv::step`] runs them on rayon's threads.
pub const PARALLEL_MIN_ENVS: usize = 256;

/// Most environments of one [`VecEnv`].
pub const MAX_ENVS: usize = 1 << 20;

/// Default half-width (rad, rad/s) of the uniform spread of the initial state.
pub const DEFAULT_INIT_SPREAD: f64 = 0.05;

/// Default weight `c_u` of the action's square in the reward.
pub const DEFAULT_ACTION_COST: f64 = 0.01;

/// Draws of a parameter set are retried this many times when the drawn plant is invalid or
/// too stiff for the RK4 step before the reset fails.
const MAX_REDRAWS: usize = 100;

/// The task of an environment (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Task {
    /// Start near upright, keep it there: terminates past `fall_limit`.
    Balance,
    /// Start hanging, swing up and balance.
    SwingUp,
}

/// A parameter covariance (e.g. an identification's): the draw is `p = p̂ + L z`, `z ~ N(0, I)`,
/// `L Lᵀ = Σ`, on the listed parameters about their values in the environment's plant.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamCovariance {
    /// The parameters, in the order of the matrix's rows.
    pub params: Vec<Param>,
    /// `Σ` (row-major, `n × n`, symmetric positive semidefinite), in the parameters' SI units.
    pub matrix: Vec<f64>,
}

/// Per-episode draws (module docs); every `None` keeps the nominal value.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Randomisation {
    /// Drawn first: a Gaussian about the nominal parameters.
    pub covariance: Option<ParamCovariance>,
    /// Then each listed parameter is multiplied by an independent `1 + U(−r, r)`, `0 ≤ r < 1`.
    pub relative: Vec<(Param, f64)>,
    /// Dead zone `Vd ~ U(lo, hi)` (V).
    pub dead_zone: Option<[f64; 2]>,
    /// Arm Coulomb friction `Cr ~ U(lo, hi)` (N·m).
    pub arm_friction: Option<[f64; 2]>,
    /// Pendulum Coulomb friction `Cp ~ U(lo, hi)` (N·m).
    pub pendulum_friction: Option<[f64; 2]>,
    /// Action delay `d ~ U{lo, …, hi}` (periods), replacing [`EnvConfig::action_delay`].
    pub action_delay: Option<[usize; 2]>,
    /// Noise standard deviation of each angle `~ U(lo, hi)` (rad), replacing the sensor's.
    pub noise_std: Option<[f64; 2]>,
}

/// Everything an environment needs (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct EnvConfig {
    /// Balance or swing-up.
    pub task: Task,
    /// The nominal plant.
    pub params: FurutaParams,
    /// Control period (s).
    pub ts: f64,
    /// RK4 steps per period.
    pub substeps: usize,
    /// Voltage of the action 1 (V); the actuator's bound.
    pub u_limit: f64,
    /// Encoders and noise (the nominal noise level).
    pub sensor: SensorModel,
    /// Cut-off (Hz) of the rate filter; `inf` for the plain difference.
    pub rate_cutoff_hz: f64,
    /// Episode length (steps) before truncation.
    pub max_steps: u32,
    /// Balance task: terminate when `|α| > fall_limit` (rad).
    pub fall_limit: f64,
    /// Terminate when `|θ| > arm_limit` (rad).
    pub arm_limit: f64,
    /// Action delay (periods, at most [`MAX_DELAY`]).
    pub action_delay: usize,
    /// Observation latency (periods, at most [`MAX_DELAY`]).
    pub observation_latency: usize,
    /// Half-width of the initial state's uniform spread (rad, rad/s).
    pub init_spread: f64,
    /// `c_u` of the reward.
    pub action_cost: f64,
    /// Per-episode draws.
    pub randomisation: Randomisation,
}

impl Default for EnvConfig {
    fn default() -> Self {
        Self {
            task: Task::Balance,
            params: FurutaParams::paper(),
            ts: crate::paper::TS,
            substeps: DEFAULT_SUBSTEPS,
            u_limit: crate::paper::INPUT_LIMIT,
            sensor: SensorModel {
                counts_per_rev: Some([2048.0, 2048.0]),
                noise_std: [1e-3, 1e-3],
                offsets: [0.0; 2],
            },
            rate_cutoff_hz: crate::regulators::DEFAULT_RATE_CUTOFF_HZ,
            max_steps: (DEFAULT_DURATION / crate::paper::TS).round() as u32,
            fall_limit: DEFAULT_FALL_LIMIT,
            arm_limit: crate::swingup::SwingUpSettings::default().arm_limit,
            action_delay: 0,
            observation_latency: 0,
            init_spread: DEFAULT_INIT_SPREAD,
            action_cost: DEFAULT_ACTION_COST,
            randomisation: Randomisation::default(),
        }
    }
}

impl EnvConfig {
    /// The environment of an experiment file's `[plant]`, `[sensor]`, voltage bound
    /// (`[mpc] input_bounds`), rate filter (`[lqr] rate_cutoff`) and arm limit
    /// (`[swing_up] arm_limit`), as `riprs compare` simulates it at period `ts`; every other
    /// setting at its default.
    pub fn from_spec(spec: &crate::spec::Spec, task: Task, ts: f64) -> Self {
        let sim = spec.sim_config(ts, 0);
        Self {
            task,
            params: spec.plant.params(),
            ts,
            substeps: sim.substeps,
            u_limit: sim.u_limit,
            sensor: sim.sensor,
            rate_cutoff_hz: spec.lqr.rate_cutoff,
            max_steps: (DEFAULT_DURATION / ts).round().max(1.0) as u32,
            fall_limit: sim.fall_limit,
            arm_limit: spec.swing_up.arm_limit,
            ..Self::default()
        }
    }
}

fn bad(name: &str, reason: String) -> RipError {
    RipError::invalid(name, reason)
}

fn check_range(name: &str, r: [f64; 2], max: f64) -> Result<()> {
    if !(r[0].is_finite() && r[1].is_finite() && 0.0 <= r[0] && r[0] <= r[1] && r[1] <= max) {
        return Err(bad(
            name,
            format!("needs 0 <= lo <= hi <= {max:e}, got [{}, {}]", r[0], r[1]),
        ));
    }
    Ok(())
}

impl EnvConfig {
    /// Checks every setting; the error names it.
    pub fn validate(&self) -> Result<()> {
        self.params.validate()?;
        crate::plant::check_step(self.ts, self.substeps)?;
        if !(self.u_limit.is_finite() && self.u_limit > 0.0) {
            return Err(bad(
                "u_limit",
                format!("must be positive, got {}", self.u_limit),
            ));
        }
        if self.rate_cutoff_hz.is_nan() || self.rate_cutoff_hz <= 0.0 {
            return Err(bad(
                "rate_cutoff",
                format!("must be positive (Hz) or inf, got {}", self.rate_cutoff_hz),
            ));
        }
        if self.max_steps == 0 {
            return Err(bad("max_episode_steps", "must be at least 1, got 0".into()));
        }
        for (name, v) in [
            ("fall_limit", self.fall_limit),
            ("arm_limit", self.arm_limit),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(name, format!("must be positive, got {v}")));
            }
        }
        if !(self.init_spread.is_finite() && self.init_spread >= 0.0) {
            return Err(bad(
                "init_spread",
                format!("must be non-negative, got {}", self.init_spread),
            ));
        }
        if self.task == Task::Balance && self.init_spread >= self.fall_limit {
            return Err(bad(
                "init_spread",
                format!(
                    "{} would start the pendulum beyond fall_limit {}",
                    self.init_spread, self.fall_limit
                ),
            ));
        }
        if self.init_spread >= self.arm_limit {
            return Err(bad(
                "init_spread",
                format!("{} would start the arm beyond arm_limit", self.init_spread),
            ));
        }
        if !(self.action_cost.is_finite() && self.action_cost >= 0.0) {
            return Err(bad(
                "action_cost",
                format!("must be non-negative, got {}", self.action_cost),
            ));
        }
        for (name, d) in [
            ("action_delay", self.action_delay),
            ("observation_latency", self.observation_latency),
        ] {
            if d > MAX_DELAY {
                return Err(bad(
                    name,
                    format!("must be at most {MAX_DELAY} periods, got {d}"),
                ));
            }
        }
        if let Some(cpr) = self.sensor.counts_per_rev {
            for c in cpr {
                if !(c.is_finite() && c >= 1.0) {
                    return Err(bad(
                        "encoder_counts",
                        format!("must be at least 1, got {c}"),
                    ));
                }
            }
        }
        for s in self.sensor.noise_std {
            if !(s.is_finite() && (0.0..=MAX_NOISE_STD).contains(&s)) {
                return Err(bad(
                    "noise_std",
                    format!("must be in [0, {MAX_NOISE_STD:e}], got {s}"),
                ));
            }
        }
        if self.sensor.offsets.iter().any(|o| !o.is_finite()) {
            return Err(RipError::NonFinite {
                name: "encoder_offsets".into(),
            });
        }
        self.randomisation.validate()?;
        // The nominal plant must be integrable at this step; draws are checked at each reset.
        Plant::new(self.params)?.step_checked(&State::zeros(), 0.0, 0.0, self.ts, self.substeps)?;
        Ok(())
    }
}

impl Randomisation {
    /// Checks the ranges; the error names the setting.
    pub fn validate(&self) -> Result<()> {
        if let Some(c) = &self.covariance {
            let n = c.params.len();
            if n == 0 || c.matrix.len() != n * n {
                return Err(RipError::Shape {
                    name: "covariance".into(),
                    expected: format!("({n}, {n}), one row per parameter"),
                    rows: c.matrix.len(),
                    cols: 1,
                });
            }
            cholesky(&c.matrix, n).ok_or_else(|| {
                bad(
                    "covariance",
                    "must be a finite symmetric positive semidefinite matrix".into(),
                )
            })?;
        }
        for (p, r) in &self.relative {
            if !(r.is_finite() && (0.0..1.0).contains(r)) {
                return Err(bad(
                    &format!("randomize.{}", p.name()),
                    format!("relative half-width must be in [0, 1), got {r}"),
                ));
            }
        }
        if let Some(r) = self.dead_zone {
            check_range("randomize.Vd", r, 1e3)?;
        }
        if let Some(r) = self.arm_friction {
            check_range("randomize.Cr", r, 1e3)?;
        }
        if let Some(r) = self.pendulum_friction {
            check_range("randomize.Cp", r, 1e3)?;
        }
        if let Some(r) = self.noise_std {
            check_range("randomize.noise_std", r, MAX_NOISE_STD)?;
        }
        if let Some([lo, hi]) = self.action_delay {
            if lo > hi || hi > MAX_DELAY {
                return Err(bad(
                    "randomize.action_delay",
                    format!("needs lo <= hi <= {MAX_DELAY}, got [{lo}, {hi}]"),
                ));
            }
        }
        Ok(())
    }
}

/// Lower Cholesky factor of a symmetric positive semidefinite `n × n` matrix (semidefinite
/// pivots are set to zero), or `None` when it is not one.
fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    if a.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let scale = a
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    let tol = 1e-12 * scale;
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            if (a[i * n + j] - a[j * n + i]).abs() > tol {
                return None;
            }
        }
    }
    for j in 0..n {
        let d = a[j * n + j] - (0..j).map(|k| l[j * n + k] * l[j * n + k]).sum::<f64>();
        if d < -tol {
            return None;
        }
        let ljj = d.max(0.0).sqrt();
        l[j * n + j] = ljj;
        for i in j + 1..n {
            let s = a[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
            l[i * n + j] = if ljj > 0.0 { s / ljj } else { 0.0 };
            if ljj == 0.0 && s.abs() > tol {
                return None;
            }
        }
    }
    Some(l)
}

/// A fixed-capacity ring of the last `MAX_DELAY + 1` values.
#[derive(Debug, Clone, Copy)]
struct Ring<T: Copy> {
    items: [T; MAX_DELAY + 1],
    head: usize,
}

impl<T: Copy> Ring<T> {
    fn filled(v: T) -> Self {
        Self {
            items: [v; MAX_DELAY + 1],
            head: 0,
        }
    }

    fn push(&mut self, v: T) {
        self.head = (self.head + 1) % (MAX_DELAY + 1);
        self.items[self.head] = v;
    }

    /// The value pushed `age` pushes ago (0: the last).
    fn back(&self, age: usize) -> T {
        self.items[(self.head + MAX_DELAY + 1 - age) % (MAX_DELAY + 1)]
    }
}

/// The measurement side of an environment: the sensor model of [`crate::sim`], then the rate
/// filter and the observation of the module docs. Also what a policy trained on the
/// environment needs to run on measured angles (`riprs.simulate` with a callable, `rip-rt`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observer {
    a: f64,
    ts: f64,
    prev: [f64; 2],
    rates: [f64; 2],
    started: bool,
}

impl Observer {
    /// A filter for period `ts` (s) and cut-off `rate_cutoff_hz` (Hz, `inf` for none).
    pub fn new(ts: f64, rate_cutoff_hz: f64) -> Self {
        Self {
            a: (-2.0 * std::f64::consts::PI * rate_cutoff_hz * ts).exp(),
            ts,
            prev: [0.0; 2],
            rates: [0.0; 2],
            started: false,
        }
    }

    /// Forgets the previous angle (the next rates start at zero).
    pub fn reset(&mut self) {
        self.started = false;
        self.rates = [0.0; 2];
    }

    /// The observation of the measured angles `y = [θ, α]` (module docs).
    #[inline]
    pub fn observe(&mut self, y: [f64; 2]) -> [f64; OBS_DIM] {
        if self.started {
            for ((rate, yi), prev) in self.rates.iter_mut().zip(y).zip(self.prev) {
                let d = (yi - prev) / self.ts;
                *rate = self.a * *rate + (1.0 - self.a) * d;
            }
        } else {
            self.rates = [0.0; 2];
            self.started = true;
        }
        self.prev = y;
        let (s0, c0) = crate::trig::sin_cos(y[0]);
        let (s1, c1) = crate::trig::sin_cos(y[1]);
        let clip = |r: f64| r.clamp(-MAX_OBS_RATE, MAX_OBS_RATE);
        [c0, s0, c1, s1, clip(self.rates[0]), clip(self.rates[1])]
    }
}

/// What one step of one environment returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// The observation.
    pub obs: [f64; OBS_DIM],
    /// The reward.
    pub reward: f64,
    /// Whether the episode ended (a fall, the arm limit, a divergence).
    pub terminated: bool,
    /// Whether the episode hit its step limit.
    pub truncated: bool,
}

/// One environment (module docs).
#[derive(Debug, Clone)]
pub struct Env {
    rng: StdRng,
    plant: Plant,
    x: State,
    noise_std: [f64; 2],
    delay: usize,
    actions: Ring<f64>,
    observations: Ring<[f64; OBS_DIM]>,
    observer: Observer,
    steps: u32,
    /// Ended at the last step: the next autoreset step resets.
    done: bool,
}

impl Env {
    fn new(config: &EnvConfig, seed: u64) -> Result<Self> {
        Ok(Self {
            rng: StdRng::seed_from_u64(seed),
            plant: Plant::new(config.params)?,
            x: State::zeros(),
            noise_std: config.sensor.noise_std,
            delay: config.action_delay,
            actions: Ring::filled(0.0),
            observations: Ring::filled([0.0; OBS_DIM]),
            observer: Observer::new(config.ts, config.rate_cutoff_hz),
            steps: 0,
            done: false,
        })
    }

    /// The true state `[θ, θ̇, α, α̇]`.
    pub fn state(&self) -> [f64; 4] {
        [self.x[0], self.x[1], self.x[2], self.x[3]]
    }

    /// The plant of the current episode.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// The action delay of the current episode (periods).
    pub fn action_delay(&self) -> usize {
        self.delay
    }

    /// The noise standard deviations of the current episode (rad).
    pub fn noise_std(&self) -> [f64; 2] {
        self.noise_std
    }

    fn uniform(&mut self, [lo, hi]: [f64; 2]) -> f64 {
        lo + (hi - lo) * self.rng.gen::<f64>()
    }

    fn draw_params(&mut self, config: &EnvConfig) -> FurutaParams {
        let r = &config.randomisation;
        let mut p = config.params;
        if let Some(c) = &r.covariance {
            let n = c.params.len();
            let l = cholesky(&c.matrix, n).expect("validated");
            let z: Vec<f64> = (0..n)
                .map(|_| StandardNormal.sample(&mut self.rng))
                .collect();
            for (i, param) in c.params.iter().enumerate() {
                let dx: f64 = (0..=i).map(|k| l[i * n + k] * z[k]).sum();
                *param.field(&mut p) += dx;
            }
        }
        for &(param, half) in &r.relative {
            let f = 1.0 + self.uniform([-half, half]);
            *param.field(&mut p) *= f;
        }
        if let Some(range) = r.dead_zone {
            p.vd = self.uniform(range);
        }
        if let Some(range) = r.arm_friction {
            p.cr = self.uniform(range);
        }
        if let Some(range) = r.pendulum_friction {
            p.cp = self.uniform(range);
        }
        p
    }

    fn measure(&mut self, config: &EnvConfig) -> [f64; 2] {
        config
            .sensor
            .measure(&self.state(), self.noise_std, &mut self.rng)
    }

    /// Starts an episode (module docs), restarting the generator from `seed` if given.
    pub fn reset(&mut self, config: &EnvConfig, seed: Option<u64>) -> Result<[f64; OBS_DIM]> {
        if let Some(s) = seed {
            self.rng = StdRng::seed_from_u64(s);
        }
        let h = config.ts / config.substeps as f64;
        let mut drawn = None;
        for _ in 0..MAX_REDRAWS {
            let p = self.draw_params(config);
            if let Ok(plant) = Plant::new(p) {
                if h <= plant.max_rk4_substep() {
                    drawn = Some(plant);
                    break;
                }
            }
        }
        self.plant = drawn.ok_or_else(|| {
            bad(
                "randomize",
                format!(
                    "{MAX_REDRAWS} parameter draws in a row gave invalid plants or plants too \
                     stiff for RK4 at {} substeps: narrow the ranges",
                    config.substeps
                ),
            )
        })?;
        let r = &config.randomisation;
        self.delay = match r.action_delay {
            Some([lo, hi]) => self.rng.gen_range(lo..=hi),
            None => config.action_delay,
        };
        self.noise_std = match r.noise_std {
            Some(range) => [self.uniform(range), self.uniform(range)],
            None => config.sensor.noise_std,
        };
        let s = config.init_spread;
        let alpha0 = match config.task {
            Task::Balance => 0.0,
            Task::SwingUp => std::f64::consts::PI,
        };
        let mut x0 = [0.0, 0.0, alpha0, 0.0];
        for v in &mut x0 {
            *v += self.uniform([-s, s]);
        }
        self.x = State::from_row_slice(&x0);
        self.actions = Ring::filled(0.0);
        self.observer.reset();
        self.steps = 0;
        self.done = false;
        let y = self.measure(config);
        let obs = self.observer.observe(y);
        self.observations = Ring::filled(obs);
        Ok(obs)
    }

    /// One step with action `a` (clamped to [−1, 1]; a non-finite one is 0 V).
    #[inline]
    pub fn step(&mut self, config: &EnvConfig, a: f64) -> Transition {
        let (a, u) = self.begin_step(config, a);
        let before = self.x;
        self.plant
            .advance(&mut self.x, u, 0.0, config.ts, config.substeps);
        self.finish_step(config, a, before)
    }

    /// The first part of [`step`](Self::step): the clamped action and the voltage the plant
    /// gets this period (after the action delay).
    #[inline]
    fn begin_step(&mut self, config: &EnvConfig, a: f64) -> (f64, f64) {
        let a = if a.is_finite() {
            a.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        self.actions.push(a * config.u_limit);
        (a, self.actions.back(self.delay))
    }

    /// The last part of [`step`](Self::step), once the plant has advanced from `before`.
    #[inline]
    fn finish_step(&mut self, config: &EnvConfig, a: f64, before: State) -> Transition {
        let diverged = !self.x.iter().all(|v| v.is_finite());
        if diverged {
            self.x = before;
        }
        self.steps += 1;
        let y = self.measure(config);
        let obs = self.observer.observe(y);
        self.observations.push(obs);
        let theta = self.x[0];
        let alpha = wrap_angle(self.x[2]);
        let reward = 1.0
            - (0.8 * alpha.abs() + 0.2 * theta.abs().min(std::f64::consts::PI))
                / std::f64::consts::PI
            - config.action_cost * a * a;
        let fell = config.task == Task::Balance && alpha.abs() > config.fall_limit;
        let terminated = diverged || fell || theta.abs() > config.arm_limit;
        let truncated = !terminated && self.steps >= config.max_steps;
        self.done = terminated || truncated;
        Transition {
            obs: self.observations.back(config.observation_latency),
            reward,
            terminated,
            truncated,
        }
    }

    /// The transition of an autoreset step (module docs).
    fn autoreset(&mut self, config: &EnvConfig) -> Transition {
        // A reset that failed at the episode's start cannot fail now: the same draws are
        // retried. Should it, the environment stays ended and says so.
        match self.reset(config, None) {
            Ok(obs) => Transition {
                obs,
                reward: 0.0,
                terminated: false,
                truncated: false,
            },
            Err(_) => Transition {
                obs: self.observations.back(0),
                reward: 0.0,
                terminated: true,
                truncated: false,
            },
        }
    }
}

/// Environments integrated together by [`VecEnv::step`]: one SIMD lane each.
pub const LANES: usize = 8;

/// [`Plant::advance_lanes`] of one chunk, compiled for AVX-512 or AVX2 where the CPU has them.
/// The lanes' arithmetic is the same IEEE operations either way (no fused multiply-add is
/// enabled), so the bits are those of [`Plant::advance`].
#[inline]
fn advance_chunk(
    plants: [&Plant; LANES],
    x: &mut [State; LANES],
    u: &[f64; LANES],
    ts: f64,
    substeps: usize,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU supports AVX-512F, checked just above.
        unsafe { advance_chunk_avx512(plants, x, u, ts, substeps) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe { advance_chunk_avx2(plants, x, u, ts, substeps) };
        return;
    }
    Plant::advance_lanes(plants, x, u, &[0.0; LANES], ts, substeps);
}

/// [`advance_chunk`] compiled for AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn advance_chunk_avx512(
    plants: [&Plant; LANES],
    x: &mut [State; LANES],
    u: &[f64; LANES],
    ts: f64,
    substeps: usize,
) {
    Plant::advance_lanes(plants, x, u, &[0.0; LANES], ts, substeps);
}

/// [`advance_chunk`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn advance_chunk_avx2(
    plants: [&Plant; LANES],
    x: &mut [State; LANES],
    u: &[f64; LANES],
    ts: f64,
    substeps: usize,
) {
    Plant::advance_lanes(plants, x, u, &[0.0; LANES], ts, substeps);
}

/// One [`VecEnv::step`] of up to [`LANES`] environments: each is reset or begins its step, the
/// stepping ones are integrated together, then each finishes its step.
#[allow(clippy::too_many_arguments)]
fn step_chunk(
    config: &EnvConfig,
    autoreset: bool,
    envs: &mut [Env],
    actions: &[f32],
    obs: &mut [f32],
    reward: &mut [f64],
    terminated: &mut [bool],
    truncated: &mut [bool],
) {
    let n = envs.len();
    let mut transitions = [None; LANES];
    let mut stepping = [false; LANES];
    let mut a = [0.0; LANES];
    let mut u = [0.0; LANES];
    for (i, env) in envs.iter_mut().enumerate() {
        if autoreset && env.done {
            transitions[i] = Some(env.autoreset(config));
        } else {
            stepping[i] = true;
            (a[i], u[i]) = env.begin_step(config, f64::from(actions[i]));
        }
    }
    if stepping.iter().any(|s| *s) {
        // Lanes without a stepping environment integrate a copy of the first one's, unused.
        let lane = |l: usize| if l < n { l } else { 0 };
        let before: [State; LANES] = std::array::from_fn(|l| envs[lane(l)].x);
        let mut x = before;
        let plants = std::array::from_fn(|l| &envs[lane(l)].plant);
        advance_chunk(plants, &mut x, &u, config.ts, config.substeps);
        for (i, env) in envs.iter_mut().enumerate() {
            if stepping[i] {
                env.x = x[i];
                transitions[i] = Some(env.finish_step(config, a[i], before[i]));
            }
        }
    }
    for (i, t) in transitions.iter().take(n).enumerate() {
        let t = t.expect("every environment was reset or stepped");
        write_obs(&mut obs[i * OBS_DIM..(i + 1) * OBS_DIM], &t.obs);
        reward[i] = t.reward;
        terminated[i] = t.terminated;
        truncated[i] = t.truncated;
    }
}

/// `N` environments stepped together (module docs).
#[derive(Debug, Clone)]
pub struct VecEnv {
    config: EnvConfig,
    envs: Vec<Env>,
}

fn write_obs(out: &mut [f32], obs: &[f64; OBS_DIM]) {
    for (o, v) in out.iter_mut().zip(obs) {
        *o = *v as f32;
    }
}

impl VecEnv {
    /// `n` environments of `config`; each must be [`reset`](Self::reset) before it is stepped.
    pub fn new(config: EnvConfig, n: usize) -> Result<Self> {
        config.validate()?;
        if n == 0 || n > MAX_ENVS {
            return Err(bad(
                "num_envs",
                format!("must be in 1..={MAX_ENVS}, got {n}"),
            ));
        }
        let envs = (0..n)
            .map(|i| Env::new(&config, i as u64))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { config, envs })
    }

    /// The configuration.
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// Always false: a [`VecEnv`] has at least one environment.
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// Environment `i`.
    pub fn env(&self, i: usize) -> &Env {
        &self.envs[i]
    }

    fn check_len(&self, name: &str, len: usize, per_env: usize) -> Result<()> {
        let expected = self.envs.len() * per_env;
        if len != expected {
            return Err(RipError::Shape {
                name: name.into(),
                expected: format!("{expected} values ({} environments)", self.envs.len()),
                rows: len,
                cols: 1,
            });
        }
        Ok(())
    }

    /// Resets the environments where `mask` is true (all if `mask` is empty), environment `i`
    /// from `seeds[i]` if `seeds` is not empty, writing their observations into `obs`
    /// (`N × OBS_DIM`, row-major; other rows are left untouched).
    pub fn reset(&mut self, seeds: &[u64], mask: &[bool], obs: &mut [f32]) -> Result<()> {
        let n = self.envs.len();
        if !seeds.is_empty() {
            self.check_len("seed", seeds.len(), 1)?;
        }
        if !mask.is_empty() {
            self.check_len("mask", mask.len(), 1)?;
        }
        self.check_len("obs", obs.len(), OBS_DIM)?;
        for i in 0..n {
            if mask.is_empty() || mask[i] {
                let seed = seeds.get(i).copied();
                let o = self.envs[i].reset(&self.config, seed)?;
                write_obs(&mut obs[i * OBS_DIM..(i + 1) * OBS_DIM], &o);
            }
        }
        Ok(())
    }

    /// Steps every environment with its action (`actions[i]`, which must be finite), writing
    /// observations (`N × OBS_DIM`), rewards and flags. With `autoreset`, an environment whose
    /// last step ended its episode is reset instead (module docs). Nothing changes when an
    /// argument is bad.
    pub fn step(
        &mut self,
        actions: &[f32],
        autoreset: bool,
        obs: &mut [f32],
        reward: &mut [f64],
        terminated: &mut [bool],
        truncated: &mut [bool],
    ) -> Result<()> {
        self.check_len("actions", actions.len(), 1)?;
        self.check_len("obs", obs.len(), OBS_DIM)?;
        self.check_len("reward", reward.len(), 1)?;
        self.check_len("terminated", terminated.len(), 1)?;
        self.check_len("truncated", truncated.len(), 1)?;
        if let Some(i) = actions.iter().position(|a| !a.is_finite()) {
            return Err(bad(
                "actions",
                format!("must be finite, got {} for environment {i}", actions[i]),
            ));
        }
        let config = &self.config;
        if self.envs.len() >= PARALLEL_MIN_ENVS {
            self.envs
                .par_chunks_mut(LANES)
                .zip(actions.par_chunks(LANES))
                .zip(obs.par_chunks_mut(LANES * OBS_DIM))
                .zip(reward.par_chunks_mut(LANES))
                .zip(terminated.par_chunks_mut(LANES))
                .zip(truncated.par_chunks_mut(LANES))
                // Jobs of at least PARALLEL_MIN_ENVS / 2 environments: a few per thread, each
                // far longer than rayon's scheduling of it, which on a loaded machine (workers
                // preempted) otherwise costs more than the parallelism gains.
                .with_min_len(PARALLEL_MIN_ENVS / (2 * LANES))
                .for_each(|(((((e, a), o), r), te), tr)| {
                    step_chunk(config, autoreset, e, a, o, r, te, tr)
                });
        } else {
            self.envs
                .chunks_mut(LANES)
                .zip(actions.chunks(LANES))
                .zip(obs.chunks_mut(LANES * OBS_DIM))
                .zip(reward.chunks_mut(LANES))
                .zip(terminated.chunks_mut(LANES))
                .zip(truncated.chunks_mut(LANES))
                .for_each(|(((((e, a), o), r), te), tr)| {
                    step_chunk(config, autoreset, e, a, o, r, te, tr)
                });
        }
        Ok(())
    }
}

/// The fit of a replayed log (sim-to-real check).
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayFit {
    /// The simulated angles `[θ, α]` at each logged sample.
    pub y: Vec<[f64; 2]>,
    /// Normalised RMSE of each output, `‖y − ŷ‖ / ‖y − mean(y)‖`: 0 is a perfect fit, 1 no
    /// better than the mean (MATLAB's `goodnessOfFit` NRMSE; `riprs identify`'s fit % is
    /// `100 (1 − NRMSE)`).
    pub nrmse: [f64; 2],
}

/// Replays logged voltages through `plant` from the logged start and compares the angles.
///
/// `y` are the measured angles at `t_k = k ts`, `u[k]` the voltage held over `[t_k, t_{k+1}]`.
/// The start is `[y₀, (y₁ − y₀)/ts]` per joint; the simulated angles are the plant's true
/// ones (no sensor model: the log already holds the rig's). A simulation that diverges is an
/// error.
pub fn replay(
    plant: &Plant,
    y: &[[f64; 2]],
    u: &[f64],
    ts: f64,
    substeps: usize,
) -> Result<ReplayFit> {
    if y.len() < 2 || u.len() != y.len() {
        return Err(RipError::Shape {
            name: "log".into(),
            expected: "at least 2 samples, as many voltages as angles".into(),
            rows: y.len(),
            cols: u.len(),
        });
    }
    if y.iter().flatten().any(|v| !v.is_finite()) {
        return Err(RipError::NonFinite { name: "y".into() });
    }
    let x0 = State::new(
        y[0][0],
        (y[1][0] - y[0][0]) / ts,
        y[0][1],
        (y[1][1] - y[0][1]) / ts,
    );
    let traj = plant.integrate(&x0, &u[..u.len() - 1], ts, substeps)?;
    let sim: Vec<[f64; 2]> = traj.iter().map(|x| [x[0], x[2]]).collect();
    let nrmse = std::array::from_fn(|j| {
        let n = y.len() as f64;
        let mean = y.iter().map(|v| v[j]).sum::<f64>() / n;
        let dev: f64 = y.iter().map(|v| (v[j] - mean).powi(2)).sum();
        let err: f64 = y.iter().zip(&sim).map(|(a, b)| (a[j] - b[j]).powi(2)).sum();
        (err / dev).sqrt()
    });
    Ok(ReplayFit { y: sim, nrmse })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(config: &EnvConfig, n: usize, seeds: &[u64], steps: usize) -> Vec<f32> {
        let mut env = VecEnv::new(config.clone(), n).unwrap();
        let mut obs = vec![0.0f32; n * OBS_DIM];
        env.reset(seeds, &[], &mut obs).unwrap();
        let mut all = obs.clone();
        let (mut r, mut te, mut tr) = (vec![0.0; n], vec![false; n], vec![false; n]);
        for k in 0..steps {
            // Each environment's actions depend on its seed, not on its place in the vector.
            let a: Vec<f32> = seeds
                .iter()
                .map(|s| ((k as u64 * 7 + s * 3) % 11) as f32 / 5.0 - 1.0)
                .collect();
            env.step(&a, true, &mut obs, &mut r, &mut te, &mut tr)
                .unwrap();
            all.extend_from_slice(&obs);
            all.extend(r.iter().map(|v| *v as f32));
        }
        all
    }

    fn randomised() -> EnvConfig {
        EnvConfig {
            task: Task::SwingUp,
            max_steps: 50,
            observation_latency: 2,
            randomisation: Randomisation {
                relative: vec![(Param::Mp, 0.2), (Param::Rm, 0.2)],
                dead_zone: Some([0.0, 0.5]),
                arm_friction: Some([0.0, 0.003]),
                pendulum_friction: Some([0.0, 2e-5]),
                action_delay: Some([0, 3]),
                noise_std: Some([0.0, 2e-3]),
                covariance: Some(ParamCovariance {
                    params: vec![Param::Dr, Param::Dp],
                    matrix: vec![1e-8, 0.0, 0.0, 1e-10],
                }),
            },
            ..Default::default()
        }
    }

    #[test]
    fn each_environment_of_a_vector_is_the_single_environment_of_its_seed() {
        let config = randomised();
        let seeds = [11u64, 5, 99, 3, 42];
        let together = run(&config, seeds.len(), &seeds, 130);
        let per_step = seeds.len() * (OBS_DIM + 1);
        for (i, &s) in seeds.iter().enumerate() {
            let alone = run(&config, 1, &[s], 130);
            for k in 0..130 {
                let base = seeds.len() * OBS_DIM + k * per_step;
                let o = &together[base + i * OBS_DIM..base + (i + 1) * OBS_DIM];
                let a = &alone[OBS_DIM + k * (OBS_DIM + 1)..OBS_DIM + k * (OBS_DIM + 1) + OBS_DIM];
                assert_eq!(o, a, "env {i} step {k}");
            }
        }
    }

    #[test]
    fn the_lanes_integrate_each_environment_with_the_bits_of_plant_advance() {
        // Randomised plants (different coefficients in every lane, dead zone, Coulomb friction
        // in some), 7 environments (a partial chunk of lanes), short episodes so that lanes
        // reset while their neighbours step: every true state is Plant::advance's, to the bit.
        let config = EnvConfig {
            max_steps: 9,
            ..randomised()
        };
        let n = 2 * LANES - 1;
        let mut env = VecEnv::new(config.clone(), n).unwrap();
        let mut obs = vec![0.0f32; n * OBS_DIM];
        let seeds: Vec<u64> = (0..n as u64).map(|s| 1000 + s).collect();
        env.reset(&seeds, &[], &mut obs).unwrap();
        let (mut r, mut te, mut tr) = (vec![0.0; n], vec![false; n], vec![false; n]);
        let mut inputs: Vec<Vec<f64>> = vec![Vec::new(); n];
        let mut checked = 0;
        for k in 0..40 {
            let a: Vec<f32> = (0..n)
                .map(|i| ((k * 5 + i * 3) % 9) as f32 / 4.0 - 1.0)
                .collect();
            let before: Vec<(State, bool)> = (0..n)
                .map(|i| (State::from(env.env(i).state()), env.env(i).done))
                .collect();
            env.step(&a, true, &mut obs, &mut r, &mut te, &mut tr)
                .unwrap();
            for i in 0..n {
                let e = env.env(i);
                let (x0, was_done) = before[i];
                if was_done {
                    inputs[i].clear();
                    continue;
                }
                inputs[i].push(config.u_limit * f64::from(a[i]).clamp(-1.0, 1.0));
                let u = inputs[i][inputs[i].len() - 1 - e.action_delay().min(inputs[i].len() - 1)];
                let u = if e.action_delay() >= inputs[i].len() {
                    0.0
                } else {
                    u
                };
                let mut x = x0;
                e.plant()
                    .advance(&mut x, u, 0.0, config.ts, config.substeps);
                let want: [f64; 4] = x.into();
                assert_eq!(
                    e.state().map(f64::to_bits),
                    want.map(f64::to_bits),
                    "env {i} step {k}"
                );
                checked += 1;
            }
        }
        assert!(checked > 200, "{checked}");
        assert!(env.envs.iter().any(|e| e.plant().params().cr > 0.0));
    }

    #[test]
    fn parallel_and_serial_steps_agree_bit_for_bit() {
        let config = randomised();
        let n = PARALLEL_MIN_ENVS + 3;
        let seeds: Vec<u64> = (0..n as u64).collect();
        let big = run(&config, n, &seeds, 20);
        let first = run(&config, 3, &seeds[..3], 20);
        for k in 0..20 {
            let b = n * OBS_DIM + k * n * (OBS_DIM + 1);
            let f = 3 * OBS_DIM + k * 3 * (OBS_DIM + 1);
            assert_eq!(&big[b..b + 3 * OBS_DIM], &first[f..f + 3 * OBS_DIM]);
        }
    }

    #[test]
    fn the_plant_step_is_rip_cores_rk4_and_the_observation_its_sensor() {
        // No noise, no quantisation: the observation is cos/sin of the true state that
        // Plant::advance gives, and the rates the documented filter of the true angles.
        let config = EnvConfig {
            sensor: SensorModel::default(),
            init_spread: 0.0,
            ..Default::default()
        };
        let mut env = VecEnv::new(config.clone(), 1).unwrap();
        let mut obs = vec![0.0f32; OBS_DIM];
        env.reset(&[0], &[], &mut obs).unwrap();
        let plant = Plant::new(config.params).unwrap();
        let mut x = State::new(0.0, 0.0, 0.0, 0.0);
        let a_f = (-2.0 * std::f64::consts::PI * 20.0 * 0.01f64).exp();
        let mut rates = [0.0; 2];
        let mut prev = [0.0; 2];
        let (mut r, mut te, mut tr) = ([0.0], [false], [false]);
        for k in 0..30 {
            let a = if k % 2 == 0 { 0.3f32 } else { -0.2 };
            env.step(&[a], false, &mut obs, &mut r, &mut te, &mut tr)
                .unwrap();
            plant.advance(&mut x, 12.0 * f64::from(a), 0.0, 0.01, 10);
            for i in 0..2 {
                rates[i] = a_f * rates[i] + (1.0 - a_f) * (x[2 * i] - prev[i]) / 0.01;
                prev[i] = x[2 * i];
            }
            let expected = [
                x[0].cos(),
                x[0].sin(),
                x[2].cos(),
                x[2].sin(),
                rates[0],
                rates[1],
            ];
            for (o, e) in obs.iter().zip(expected) {
                assert!(
                    (f64::from(*o) - e).abs() < 1e-6 * (1.0 + e.abs()),
                    "{o} vs {e}"
                );
            }
            let want = 1.0
                - (0.8 * x[2].abs() + 0.2 * x[0].abs()) / std::f64::consts::PI
                - 0.01 * f64::from(a).powi(2);
            assert!((r[0] - want).abs() < 1e-12);
        }
    }

    #[test]
    fn action_delay_and_latency_shift_by_whole_periods() {
        let base = EnvConfig {
            sensor: SensorModel::default(),
            init_spread: 0.0,
            ..Default::default()
        };
        let trace = |c: &EnvConfig, actions: &[f32]| {
            let mut env = VecEnv::new(c.clone(), 1).unwrap();
            let mut obs = vec![0.0f32; OBS_DIM];
            env.reset(&[1], &[], &mut obs).unwrap();
            let mut out = vec![obs.clone()];
            let (mut r, mut te, mut tr) = ([0.0], [false], [false]);
            for a in actions {
                env.step(&[*a], false, &mut obs, &mut r, &mut te, &mut tr)
                    .unwrap();
                out.push(obs.clone());
            }
            out
        };
        let pulse: Vec<f32> = (0..20).map(|k| if k == 0 { 0.5 } else { 0.0 }).collect();
        let delayed = EnvConfig {
            action_delay: 3,
            ..base.clone()
        };
        let mut shifted = vec![0.0f32; 3];
        shifted.extend_from_slice(&pulse[..17]);
        assert_eq!(trace(&delayed, &pulse), trace(&base, &shifted));
        let late = EnvConfig {
            observation_latency: 2,
            ..base.clone()
        };
        let now = trace(&base, &pulse);
        let seen = trace(&late, &pulse);
        for k in 2..seen.len() {
            assert_eq!(seen[k], now[k - 2]);
        }
    }

    #[test]
    fn autoreset_resets_on_the_step_after_the_end() {
        let config = EnvConfig {
            max_steps: 3,
            ..Default::default()
        };
        let mut env = VecEnv::new(config, 2).unwrap();
        let mut obs = vec![0.0f32; 2 * OBS_DIM];
        env.reset(&[1, 2], &[], &mut obs).unwrap();
        let (mut r, mut te, mut tr) = ([0.0; 2], [false; 2], [false; 2]);
        for _ in 0..3 {
            env.step(&[0.0, 0.0], true, &mut obs, &mut r, &mut te, &mut tr)
                .unwrap();
        }
        assert_eq!(tr, [true, true]);
        env.step(&[1.0, 1.0], true, &mut obs, &mut r, &mut te, &mut tr)
            .unwrap();
        assert_eq!((r, te, tr), ([0.0; 2], [false; 2], [false; 2]));
        assert_eq!(env.env(0).steps, 0);
    }

    #[test]
    fn draws_follow_the_stated_ranges_and_the_covariance() {
        let config = randomised();
        let mut env = VecEnv::new(config.clone(), 1).unwrap();
        let mut obs = vec![0.0f32; OBS_DIM];
        let nominal = config.params;
        let (mut dr, mut dr2) = (0.0, 0.0);
        let n = 4000;
        for s in 0..n {
            env.reset(&[s], &[], &mut obs).unwrap();
            let p = env.env(0).plant().params();
            assert!((p.mp / nominal.mp - 1.0).abs() <= 0.2);
            assert!((0.0..=0.5).contains(&p.vd) && (0.0..=0.003).contains(&p.cr));
            assert!(env.env(0).action_delay() <= 3);
            let d = p.dr - nominal.dr;
            dr += d;
            dr2 += d * d;
        }
        let mean = dr / n as f64;
        let std = (dr2 / n as f64 - mean * mean).sqrt();
        // Σ₀₀ = 1e-8: standard deviation 1e-4, estimated to within a few per cent.
        assert!((std / 1e-4 - 1.0).abs() < 0.05, "std {std}");
        assert!(mean.abs() < 5.0 * 1e-4 / (n as f64).sqrt());
    }

    #[test]
    fn bad_settings_are_named_and_change_nothing() {
        let bad = EnvConfig {
            action_delay: MAX_DELAY + 1,
            ..Default::default()
        };
        assert!(VecEnv::new(bad, 1)
            .unwrap_err()
            .to_string()
            .contains("action_delay"));
        let mut env = VecEnv::new(EnvConfig::default(), 2).unwrap();
        let mut obs = vec![0.0f32; 2 * OBS_DIM];
        env.reset(&[1, 2], &[], &mut obs).unwrap();
        let before = env.env(1).state();
        let (mut r, mut te, mut tr) = ([0.0; 2], [false; 2], [false; 2]);
        let err = env
            .step(&[0.0, f32::NAN], true, &mut obs, &mut r, &mut te, &mut tr)
            .unwrap_err();
        assert!(err.to_string().contains("actions"));
        assert_eq!(env.env(1).state(), before);
    }

    #[test]
    fn replay_fits_the_plants_own_trajectory_and_not_a_wrong_plants() {
        let plant = Plant::qube_servo2();
        let u: Vec<f64> = (0..300).map(|k| 2.0 * (k as f64 * 0.05).sin()).collect();
        let x0 = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
        let traj = plant.integrate(&x0, &u[..299], 0.01, 10).unwrap();
        let y: Vec<[f64; 2]> = traj.iter().map(|x| [x[0], x[2]]).collect();
        // The start's rate estimate is a forward difference, not the true zero rate: the fit is
        // close but not exact, and a wrong plant fits far worse.
        let fit = replay(&plant, &y, &u, 0.01, 10).unwrap();
        assert!(
            fit.nrmse[0] < 0.05 && fit.nrmse[1] < 0.05,
            "{:?}",
            fit.nrmse
        );
        let mut wrong = *plant.params();
        wrong.kt *= 1.5;
        let worse = replay(&Plant::new(wrong).unwrap(), &y, &u, 0.01, 10).unwrap();
        assert!(
            worse.nrmse[0] > 5.0 * fit.nrmse[0].max(1e-3),
            "{:?}",
            worse.nrmse
        );
    }
}
