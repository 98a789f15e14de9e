//! Design-time routines on the paper's plant: DARE, dlqr and the 5-state Kalman design.

use criterion::{black_box, criterion_main, Criterion};
use rip_core::{dare, dlqr, kalman, paper, Mat};

fn design(c: &mut Criterion) {
    let plant = paper::discrete_model();
    let (q, r) = paper::lqr_weights();
    c.bench_function("dare_paper_4state", |bench| {
        bench.iter(|| dare(black_box(&plant.a), &plant.b, &q, &r, None, None).unwrap())
    });
    c.bench_function("dlqr_paper_4state", |bench| {
        bench.iter(|| dlqr(black_box(&plant.a), &plant.b, &q, &r, None).unwrap())
    });
    let aug = paper::augmented_model();
    let noise = paper::noise_model();
    let g = Mat::identity(aug.a.nrows(), aug.a.nrows());
    c.bench_function("kalman_paper_5state", |bench| {
        bench.iter(|| {
            kalman(
                black_box(&aug.a),
                &g,
                &aug.c,
                &noise.q,
                &noise.r,
                Some(&noise.n),
                None,
            )
            .unwrap()
        })
    });
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API, so it needs no doc comment.
mod group {
    criterion::criterion_group!(benches, super::design);
}
criterion_main!(group::benches);
