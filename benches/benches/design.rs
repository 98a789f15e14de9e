//! Design-time routines on the paper's plant: DARE, dlqr, the 5-state Kalman design, and the
//! loop margins that `tune` computes for every candidate (the paper's LQG, whose impulse
//! response is short, and generated rig 2's, whose slow integral action makes it long).

use criterion::{black_box, criterion_main, Criterion};
use rip_core::spec::{ControllerKind, Spec};
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
    for (name, text) in [
        ("paper", String::new()),
        ("rig2", rip_core::rig::Rig::random(2).to_toml()),
    ] {
        let design = Spec::parse(&text).unwrap().design(paper::TS).unwrap();
        for kind in [ControllerKind::Lqg, ControllerKind::Mpc] {
            let id = format!("margins_{name}_{}", kind.name().to_lowercase());
            c.bench_function(&id, |bench| {
                bench.iter(|| design.margins(black_box(kind)).unwrap())
            });
        }
    }
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API, so it needs no doc comment.
mod group {
    criterion::criterion_group!(benches, super::design);
}
criterion_main!(group::benches);
