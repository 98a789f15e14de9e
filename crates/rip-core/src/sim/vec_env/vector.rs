//! `N` environments stepped together, [`LANES`] at a time in SIMD lanes and on threads.

use rayon::prelude::*;

use super::config::bad;
use super::snapshot::{Reader, Writer};
use super::{Env, EnvConfig, MAX_ENVS, OBS_DIM, PARALLEL_MIN_ENVS};
use crate::error::{Result, RipError};
use crate::plant::{Plant, State};

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

/// Defines `$name`, [`advance_chunk`] compiled with the target feature `$feature` (the
/// function the CPU test above calls; the attribute cannot be chosen at run time).
macro_rules! advance_chunk_with {
    ($name:ident, $feature:literal) => {
        #[doc = concat!("[`advance_chunk`] compiled for `", $feature, "`.")]
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        unsafe fn $name(
            plants: [&Plant; LANES],
            x: &mut [State; LANES],
            u: &[f64; LANES],
            ts: f64,
            substeps: usize,
        ) {
            Plant::advance_lanes(plants, x, u, &[0.0; LANES], ts, substeps);
        }
    };
}

advance_chunk_with!(advance_chunk_avx512, "avx512f");
advance_chunk_with!(advance_chunk_avx2, "avx2");

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
    pub(super) envs: Vec<Env>,
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

    /// The seeds of a reset from one seed `base`: environment `i` gets `base + i`, as
    /// Gymnasium's `SyncVectorEnv` seeds its environments. A `base` for which some `base + i`
    /// would not fit 64 bits is an error: wrapped around, two environments' seeds would meet.
    pub fn seeds_from(&self, base: u64) -> Result<Vec<u64>> {
        let n = self.envs.len() as u64;
        let last = base.checked_add(n - 1).ok_or_else(|| {
            bad(
                "seed",
                format!(
                    "environment i is seeded with seed + i, which must fit 64 bits: with {n} \
                     environments the seed must be at most {}, got {base}",
                    u64::MAX - (n - 1)
                ),
            )
        })?;
        Ok((base..=last).collect())
    }

    /// The whole state (configuration, and each environment's plant, generator, delays,
    /// filter and step count) as bytes, which [`from_bytes`](Self::from_bytes) turns back into
    /// an environment that continues exactly as this one would.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new();
        self.config.encode(&mut w);
        w.usize(self.envs.len());
        for env in &self.envs {
            env.encode(&mut w);
        }
        w.finish()
    }

    /// The environment [`to_bytes`](Self::to_bytes) saved. Bytes that are not one are an
    /// error naming `state`.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let mut r = Reader::new(bytes)?;
        let config = EnvConfig::decode(&mut r)?;
        let n = r.usize(MAX_ENVS)?;
        if n == 0 {
            return Err(super::snapshot::invalid("no environments"));
        }
        let envs = (0..n)
            .map(|_| Env::decode(&mut r, &config))
            .collect::<Result<Vec<_>>>()?;
        r.finish()?;
        Ok(Self { config, envs })
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
