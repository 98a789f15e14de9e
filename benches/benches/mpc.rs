//! The MPC hot path on the paper's settings (P = 50, m = 3, 5 states, 2 outputs): estimator
//! update, QP solve per backend, and the full step (estimator + QP).
//!
//! Inputs are replayed from a closed loop on the paper's linear model (pendulum released at
//! 0.1 rad, arm reference 0 → 1 rad at 1 s), which saturates the input and uses the slack, so
//! the timings average over active and inactive constraint sets, not just the trivial
//! steady state. Each benchmark iteration is one sample of that trajectory.

use criterion::{black_box, criterion_main, Criterion};
use nalgebra::DVector;
use rip_core::mpc::{paper, QpSolver};
use rip_core::Controller;

const STEPS: usize = 400;

struct Trace {
    y: Vec<[f64; 2]>,
    r: Vec<[f64; 2]>,
    xhat: Vec<Vec<f64>>,
    u_prev: Vec<f64>,
}

fn trace() -> Trace {
    let plant = rip_core::paper::discrete_model();
    let mut mpc = paper::controller(QpSolver::ActiveSet).unwrap();
    let mut x = DVector::from_row_slice(&[0.0, 0.0, 0.1, 0.0]);
    let mut t = Trace {
        y: Vec::new(),
        r: Vec::new(),
        xhat: Vec::new(),
        u_prev: Vec::new(),
    };
    let mut u = [0.0];
    for k in 0..STEPS {
        let y = &plant.c * &x;
        let r = [if k < 100 { 0.0 } else { 1.0 }, 0.0];
        t.u_prev.push(mpc.last_input()[0]);
        mpc.step(y.as_slice(), &r, &mut u);
        t.y.push([y[0], y[1]]);
        t.r.push(r);
        t.xhat.push(mpc.state_estimate().unwrap().to_vec());
        x = &plant.a * &x + &plant.b * u[0];
    }
    t
}

fn mpc(c: &mut Criterion) {
    let t = trace();

    let est_src = paper::controller(QpSolver::ActiveSet).unwrap();
    let mut est = est_src.estimator().clone();
    let mut k = 0;
    c.bench_function("mpc_estimator_update_5state", |b| {
        b.iter(|| {
            est.correct(black_box(&t.y[k]), &[0.0]);
            est.predict(black_box(&[t.u_prev[k]]));
            k = (k + 1) % STEPS;
        })
    });

    for (name, solver) in [
        ("active_set", QpSolver::ActiveSet),
        ("clarabel", QpSolver::Clarabel),
    ] {
        let mut m = paper::controller(solver).unwrap();
        let mut k = 0;
        c.bench_function(&format!("mpc_qp_solve_{name}_paper"), |b| {
            b.iter(|| {
                let s = m
                    .solve(black_box(&t.xhat[k]), &[t.u_prev[k]], &t.r[k])
                    .unwrap();
                k = (k + 1) % STEPS;
                s.u[0]
            })
        });

        let mut m = paper::controller(solver).unwrap();
        let mut k = 0;
        let mut u = [0.0];
        c.bench_function(&format!("mpc_full_step_{name}_paper"), |b| {
            b.iter(|| {
                if k == 0 {
                    m.reset();
                }
                m.step(black_box(&t.y[k]), &t.r[k], &mut u);
                k = (k + 1) % STEPS;
                u[0]
            })
        });
    }
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API, so it needs no doc comment.
mod group {
    criterion::criterion_group!(benches, super::mpc);
}
criterion_main!(group::benches);
