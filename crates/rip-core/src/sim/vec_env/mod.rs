//! Reinforcement-learning environments on the nonlinear [`Plant`](crate::plant::Plant): `N`
//! independent pendulums stepped in one call ([`VecEnv`]), the engine behind `riprs.envs`
//! (Gymnasium).
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
//! The rates `ω̂` are the rig's LQR's ([`crate::regulators::RateFilter`], one definition):
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
//! # Saving
//!
//! [`VecEnv::to_bytes`] saves everything an environment is, its generator's position in its
//! stream included, and [`VecEnv::from_bytes`] restores it: the restored environment continues
//! with the same bits as the original (what `pickle` of `riprs.envs` relies on).
//!
//! Stepping allocates nothing; resets build the drawn [`Plant`](crate::plant::Plant) (which
//! computes its RK4 stability limit). [`VecEnv::step`] integrates [`LANES`] environments per call
//! of [`Plant::advance_lanes`](crate::plant::Plant::advance_lanes) (each in its own SIMD lane, with
//! its own drawn plant: the bits of [`Plant::advance`](crate::plant::Plant::advance)), and spreads
//! these chunks over threads (rayon) from [`PARALLEL_MIN_ENVS`] environments on.

mod config;
mod env;
mod replay;
mod snapshot;
#[cfg(test)]
mod tests;
mod vector;

pub use config::{EnvConfig, ParamCovariance, Randomisation};
pub use env::{Env, Observer, Transition};
pub use replay::{replay, ReplayFit};
pub use vector::{VecEnv, LANES};

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
