//! One environment: the measurement side ([`Observer`]) and the episode's plant, delays,
//! reward and termination.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;
use rand_distr::{Distribution, StandardNormal};

use super::config::{bad, cholesky};
use super::snapshot::{invalid, Reader, Writer};
use super::{EnvConfig, Task, MAX_DELAY, MAX_OBS_RATE, MAX_REDRAWS, OBS_DIM};
use crate::error::Result;
use crate::plant::{FurutaParams, Plant, State};
use crate::regulators::RateFilter;
use crate::trig::wrap_angle;

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
///
/// The rates are the LQR's ([`RateFilter`]), so a measurement that is not finite is skipped as
/// the LQR skips it: the rates are kept and the next difference spans the skipped period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observer {
    filter: RateFilter,
}

impl Observer {
    /// A filter for period `ts` (s) and cut-off `rate_cutoff_hz` (Hz, `inf` for none).
    pub fn new(ts: f64, rate_cutoff_hz: f64) -> Self {
        Self {
            filter: RateFilter::new(ts, rate_cutoff_hz),
        }
    }

    /// Forgets the previous angle (the next rates start at zero).
    pub fn reset(&mut self) {
        self.filter.reset();
    }

    fn encode(&self, w: &mut Writer) {
        let (started, held) = self.filter.progress();
        w.f64s(&self.filter.angles());
        w.f64s(&self.filter.rates());
        w.bool(started);
        w.u32(held);
    }

    fn decode(&mut self, r: &mut Reader<'_>) -> Result<()> {
        let (angles, rates) = (r.f64s()?, r.f64s()?);
        let (started, held) = (r.bool()?, r.u32()?);
        self.filter.restore(angles, rates, started, held);
        Ok(())
    }

    /// The observation of the measured angles `y = [θ, α]` (module docs).
    #[inline]
    pub fn observe(&mut self, y: [f64; 2]) -> [f64; OBS_DIM] {
        if !self.filter.update(y) {
            self.filter.hold();
        }
        let rates = self.filter.rates();
        let (s0, c0) = crate::trig::sin_cos(y[0]);
        let (s1, c1) = crate::trig::sin_cos(y[1]);
        let clip = |r: f64| r.clamp(-MAX_OBS_RATE, MAX_OBS_RATE);
        [c0, s0, c1, s1, clip(rates[0]), clip(rates[1])]
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
    /// `rand`'s `StdRng` (the same ChaCha12 bits), named so that its position in the stream
    /// can be saved and restored ([`Env::encode`]).
    rng: ChaCha12Rng,
    pub(super) plant: Plant,
    pub(super) x: State,
    noise_std: [f64; 2],
    delay: usize,
    actions: Ring<f64>,
    observations: Ring<[f64; OBS_DIM]>,
    observer: Observer,
    pub(super) steps: u32,
    /// Ended at the last step: the next autoreset step resets.
    pub(super) done: bool,
}

impl Env {
    pub(super) fn new(config: &EnvConfig, seed: u64) -> Result<Self> {
        Ok(Self {
            rng: ChaCha12Rng::seed_from_u64(seed),
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
            self.rng = ChaCha12Rng::seed_from_u64(s);
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
    pub(super) fn begin_step(&mut self, config: &EnvConfig, a: f64) -> (f64, f64) {
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
    pub(super) fn finish_step(&mut self, config: &EnvConfig, a: f64, before: State) -> Transition {
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

    /// Appends the environment's whole state to a snapshot ([`super::snapshot`]).
    pub(super) fn encode(&self, w: &mut Writer) {
        // Destructured whole, so that a field added to the environment fails to compile here
        // until the snapshot carries it.
        let Self {
            rng,
            plant,
            x,
            noise_std,
            delay,
            actions,
            observations,
            observer,
            steps,
            done,
        } = self;
        w.bytes(&rng.get_seed());
        w.u64(rng.get_stream());
        w.u128(rng.get_word_pos());
        // The plant is a function of its parameters (`Plant::new`), rebuilt on reading.
        w.f64s(&plant.params().to_array());
        w.f64s(x.as_slice());
        w.f64s(noise_std);
        w.usize(*delay);
        w.f64s(&actions.items);
        w.usize(actions.head);
        for o in &observations.items {
            w.f64s(o);
        }
        w.usize(observations.head);
        observer.encode(w);
        w.u32(*steps);
        w.bool(*done);
    }

    /// Reads back what [`encode`](Self::encode) wrote for an environment of `config`.
    pub(super) fn decode(r: &mut Reader<'_>, config: &EnvConfig) -> Result<Self> {
        let mut rng = ChaCha12Rng::from_seed(r.array()?);
        rng.set_stream(r.u64()?);
        rng.set_word_pos(r.u128()?);
        let plant = Plant::new(FurutaParams::from_array(r.f64s()?))
            .map_err(|_| invalid("an invalid plant"))?;
        let x: [f64; 4] = r.f64s()?;
        if !x.iter().all(|v| v.is_finite()) {
            return Err(invalid("a state that is not finite"));
        }
        let noise_std = r.f64s()?;
        let delay = r.usize(MAX_DELAY)?;
        let actions = Ring {
            items: r.f64s()?,
            head: r.usize(MAX_DELAY)?,
        };
        let mut items = [[0.0; OBS_DIM]; MAX_DELAY + 1];
        for o in &mut items {
            *o = r.f64s()?;
        }
        let observations = Ring {
            items,
            head: r.usize(MAX_DELAY)?,
        };
        let mut observer = Observer::new(config.ts, config.rate_cutoff_hz);
        observer.decode(r)?;
        Ok(Self {
            rng,
            plant,
            x: State::from_row_slice(&x),
            noise_std,
            delay,
            actions,
            observations,
            observer,
            steps: r.u32()?,
            done: r.bool()?,
        })
    }

    /// The transition of an autoreset step (module docs).
    pub(super) fn autoreset(&mut self, config: &EnvConfig) -> Transition {
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
