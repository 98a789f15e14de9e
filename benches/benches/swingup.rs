//! One step of the swing-up supervisor: in the swing (energy law, the balance estimator seeded
//! or observed) and after the catch (the balance controller's step behind the supervisor).

use criterion::{black_box, criterion_main, Criterion};
use rip_core::mpc::paper::controller;
use rip_core::{Controller, Lqg, Lqr, Plant, QpSolver, State, SwingUp, SwingUpSettings};

/// A supervisor driven `samples` periods from hanging on the nominal plant, returned with the
/// plant state and input to step from.
fn prepared<C: Controller>(balance: C, samples: usize) -> (SwingUp<C>, State, [f64; 1]) {
    let plant = Plant::paper();
    let mut sup = SwingUp::new(balance, &plant, SwingUpSettings::default()).unwrap();
    let mut x = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    let mut u = [0.0];
    for _ in 0..samples {
        sup.step(&[x[0], x[2]], &[0.0, 0.0], &mut u);
        plant.advance(&mut x, u[0], 0.0, 0.01, 10);
    }
    (sup, x, u)
}

fn swingup(c: &mut Criterion) {
    let mut group = c.benchmark_group("swingup_step");
    // 1 s into the swing the pendulum is far from upright: the law plus the estimator seed.
    let (mut sup, x, mut u) = prepared(Lqg::paper().unwrap(), 100);
    let y = [x[0], x[2]];
    group.bench_function("swing_lqg", |b| {
        b.iter(|| sup.step(black_box(&y), black_box(&[0.0, 0.0]), &mut u))
    });
    for (name, balance) in [
        (
            "balance_lqr",
            Box::new(Lqr::paper().unwrap()) as Box<dyn Controller>,
        ),
        ("balance_lqg", Box::new(Lqg::paper().unwrap())),
        (
            "balance_mpc_active_set",
            Box::new(controller(QpSolver::ActiveSet).unwrap()),
        ),
    ] {
        let (mut sup, x, mut u) = prepared(balance, 600);
        assert_eq!(sup.phase(), rip_core::Phase::Balance, "{name}: caught");
        let y = [x[0], x[2]];
        group.bench_function(name, |b| {
            b.iter(|| sup.step(black_box(&y), black_box(&[0.0, 0.0]), &mut u))
        });
    }
    group.finish();
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API, so it needs no doc comment.
mod group {
    criterion::criterion_group!(benches, super::swingup);
}
criterion_main!(group::benches);
