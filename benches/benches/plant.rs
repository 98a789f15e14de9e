//! The plant and the paper's regulators: one RK4 step, one controller step, and a 10 s
//! closed-loop run per controller (1000 control periods, 10 RK4 substeps each, encoder and
//! noise model; the MPC once per QP backend).

use criterion::{black_box, criterion_main, Criterion};
use rip_core::mpc::QpSolver;
use rip_core::sim::{Reference, SensorModel};
use rip_core::{
    simulate, Compensated, Compensation, Controller, Lqg, Lqr, Plant, SimConfig, State,
};

fn paper_run() -> SimConfig {
    SimConfig {
        duration: 10.0,
        x0: [0.0, 0.0, 0.1, 0.0],
        reference: Reference::Step {
            time: 1.0,
            value: [1.0, 0.0],
        },
        sensor: SensorModel {
            counts_per_rev: Some([2048.0, 2048.0]),
            noise_std: [1e-3, 1e-3],
            offsets: [0.0; 2],
        },
        ..Default::default()
    }
}

fn plant(c: &mut Criterion) {
    let plant = Plant::paper();
    c.bench_function("rk4_step", |b| {
        let mut x = State::new(0.1, 0.2, 0.05, -0.3);
        b.iter(|| {
            plant.rk4_step(black_box(&mut x), black_box(1.0), 0.0, 1e-3);
            x[2] = 0.05;
        })
    });

    let y = [0.01, -0.02];
    let r = [1.0, 0.0];
    let mut u = [0.0];
    let mut lqr = Lqr::paper().unwrap();
    c.bench_function("lqr_step", |b| {
        b.iter(|| lqr.step(black_box(&y), black_box(&r), &mut u))
    });
    // The same step behind the dead-zone and friction compensation (QUBE-Servo 3's 0.65 V
    // dead band, 0.003 N m arm friction): the difference to lqr_step is its cost.
    let law = Compensation::new(0.65, 0.5, 0.05, 0.05, (-12.0, 12.0)).unwrap();
    let (lo, hi) = law.inner_bounds();
    let mut compensated = Compensated::new(
        Lqr::paper().unwrap().with_input_bounds(lo, hi).unwrap(),
        law,
    );
    c.bench_function("lqr_step_compensated", |b| {
        b.iter(|| compensated.step(black_box(&y), black_box(&r), &mut u))
    });
    c.bench_function("compensation_apply", |b| {
        b.iter(|| law.apply(black_box(0.3), black_box(0.02)))
    });
    let mut lqg = Lqg::paper().unwrap();
    c.bench_function("lqg_step", |b| {
        b.iter(|| {
            lqg.step(black_box(&y), black_box(&r), &mut u);
        })
    });

    let config = paper_run();
    let mut group = c.benchmark_group("closed_loop_10s");
    group.sample_size(50);
    group.bench_function("lqr", |b| {
        let mut ctrl = Lqr::paper().unwrap();
        b.iter(|| simulate(&plant, &mut ctrl, black_box(&config)).unwrap())
    });
    group.bench_function("lqg", |b| {
        let mut ctrl = Lqg::paper().unwrap();
        b.iter(|| simulate(&plant, &mut ctrl, black_box(&config)).unwrap())
    });
    for solver in [QpSolver::ActiveSet, QpSolver::Clarabel] {
        group.bench_function(format!("mpc_{}", solver.name()), |b| {
            let mut ctrl = rip_core::mpc::paper::controller(solver).unwrap();
            b.iter(|| simulate(&plant, &mut ctrl, black_box(&config)).unwrap())
        });
    }
    group.finish();
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API, so it needs no doc comment.
mod group {
    criterion::criterion_group!(benches, super::plant);
}
criterion_main!(group::benches);
