//! One step of the swing-up supervisor: in the swing (energy law, the balance estimator seeded
//! or observed), along a plan (its point retimed, the tracking law) and after the catch (the
//! balance controller's step behind the supervisor). `swing_planned_lqg` also prints the
//! periods' compute time over a whole planned swing-up and catch (median, p99, largest).

use criterion::{black_box, criterion_main, BatchSize, Criterion};
use rip_core::mpc::paper::controller;
use rip_core::swingup::SwingUpMethod;
use rip_core::{Controller, Lqg, Lqr, Plant, QpSolver, State, SwingUp, SwingUpSettings};

/// A supervisor driven `samples` periods from hanging on the nominal plant, returned with the
/// plant state and input to step from.
fn prepared<C: Controller>(balance: C, samples: usize) -> (SwingUp<C>, State, [f64; 1]) {
    prepared_with(balance, samples, SwingUpSettings::default())
}

fn prepared_with<C: Controller>(
    balance: C,
    samples: usize,
    settings: SwingUpSettings,
) -> (SwingUp<C>, State, [f64; 1]) {
    let plant = Plant::paper();
    let mut sup = SwingUp::new(balance, &plant, settings).unwrap();
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
    // Along the paper's plan of several swings, 1 s in: each step from the same state, on a
    // fresh copy (a step moves the plan on).
    let planned = SwingUpSettings {
        method: SwingUpMethod::Trajectory,
        ..SwingUpSettings::default()
    };
    print_periods(&planned);
    let (sup, x, u) = prepared_with(Lqg::paper().unwrap(), 100, planned);
    assert!(!sup.plan().is_empty(), "the paper's plan");
    let y = [x[0], x[2]];
    group.bench_function("swing_planned_lqg", |b| {
        b.iter_batched(
            || (sup.clone(), u),
            |(mut sup, mut u)| sup.step(black_box(&y), black_box(&[0.0, 0.0]), &mut u),
            BatchSize::SmallInput,
        )
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

/// Prints each period's compute time over 6 s from hanging on the nominal paper plant with
/// the LQG behind a supervisor with `settings`: the swing, the catch and the balance.
fn print_periods(settings: &SwingUpSettings) {
    let plant = Plant::paper();
    let mut sup = SwingUp::new(Lqg::paper().unwrap(), &plant, settings.clone()).unwrap();
    let mut x = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    let mut u = [0.0];
    let mut times: Vec<f64> = (0..600)
        .map(|_| {
            let started = std::time::Instant::now();
            sup.step(black_box(&[x[0], x[2]]), &[0.0, 0.0], &mut u);
            let took = started.elapsed().as_secs_f64();
            plant.advance(&mut x, u[0], 0.0, 0.01, 10);
            took
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let at = |q: f64| 1e6 * times[((times.len() - 1) as f64 * q).round() as usize];
    println!(
        "swingup_step/planned_lqg_periods: median {:.2} µs, p99 {:.2} µs, largest {:.2} µs over 600 periods ({:?})",
        at(0.5),
        at(0.99),
        at(1.0),
        sup.phase()
    );
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API, so it needs no doc comment.
mod group {
    criterion::criterion_group!(benches, super::swingup);
}
criterion_main!(group::benches);
