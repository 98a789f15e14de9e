//! The reinforcement-learning environments (`rip_core::sim::vec_env`): one step of `N`
//! balance environments (10 RK4 substeps each, encoder and noise model, rate filter, reward),
//! integrated `LANES` at a time in SIMD lanes, serial below `PARALLEL_MIN_ENVS` and on rayon's
//! threads from it on.

use criterion::{black_box, criterion_main, Criterion};
use rip_core::sim::vec_env::{EnvConfig, VecEnv, OBS_DIM};

fn vec_env(c: &mut Criterion) {
    let mut group = c.benchmark_group("vec_env_step");
    for n in [1usize, 64, 1024] {
        let mut env = VecEnv::new(EnvConfig::default(), n).expect("the default is valid");
        let seeds: Vec<u64> = (0..n as u64).collect();
        let mut obs = vec![0.0f32; n * OBS_DIM];
        env.reset(&seeds, &[], &mut obs).expect("valid buffers");
        let actions = vec![0.0f32; n];
        let (mut r, mut te, mut tr) = (vec![0.0; n], vec![false; n], vec![false; n]);
        group.bench_function(format!("n{n}"), |b| {
            b.iter(|| {
                env.step(
                    black_box(&actions),
                    true,
                    &mut obs,
                    &mut r,
                    &mut te,
                    &mut tr,
                )
                .expect("valid buffers")
            })
        });
    }
    group.finish();
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API, so it needs no doc comment.
mod group {
    criterion::criterion_group!(benches, super::vec_env);
}
criterion_main!(group::benches);
