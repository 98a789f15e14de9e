//! One step of each rip-control controller (the code the host, rip-rt and the device share),
//! in `f64` and `f32`, on the paper's design at 100 Hz: LQR, LQG and the MPC (P = 50, m = 3,
//! dual active set).
//!
//! The measurements are replayed from a closed loop of the `f64` controller on the paper's
//! linear model (pendulum released at 0.1 rad, arm reference 0 → 1 rad at 1 s), which
//! saturates the input and uses the MPC's slack. Each benchmark iteration is one sample.

use criterion::{black_box, criterion_main, Criterion};
use nalgebra::DVector;
use rip_control::{Controller, Design, Measurement, Real};
use rip_core::spec::Spec;

const STEPS: usize = 400;

fn replay(design: &Design<f64>) -> Vec<Measurement<f64>> {
    let plant = rip_core::paper::discrete_model();
    let mut c = Controller::new(design).unwrap();
    let mut x = DVector::from_row_slice(&[0.0, 0.0, 0.1, 0.0]);
    let mut out = Vec::with_capacity(STEPS);
    for k in 0..STEPS {
        let y = &plant.c * &x;
        let m = Measurement {
            angles: [y[0], y[1]],
            reference: [if k < 100 { 0.0 } else { 1.0 }, 0.0],
        };
        let u = c.step(m).voltage;
        out.push(m);
        x = &plant.a * &x + &plant.b * u;
    }
    out
}

/// The design rounded to `R` by the bytes it travels in, as the device reads it.
fn as_real<R: Real>(design: &Design<f64>) -> Design<R> {
    let mut buf = vec![0u8; design.encoded_len()];
    design.to_bytes(&mut buf).unwrap();
    Design::<R>::from_bytes(&buf).unwrap()
}

fn bench_one<R: Real>(
    c: &mut Criterion,
    name: &str,
    design: &Design<f64>,
    trace: &[Measurement<f64>],
) {
    let d = as_real::<R>(design);
    let trace: Vec<Measurement<R>> = trace
        .iter()
        .map(|m| Measurement {
            angles: m.angles.map(R::from_f64),
            reference: m.reference.map(R::from_f64),
        })
        .collect();
    let mut ctl = Controller::new(&d).unwrap();
    let mut k = 0;
    c.bench_function(name, |b| {
        b.iter(|| {
            if k == trace.len() {
                k = 0;
                ctl.reset();
            }
            let mv = ctl.step(black_box(trace[k]));
            k += 1;
            black_box(mv)
        })
    });
}

fn control(c: &mut Criterion) {
    let design = Spec::default().design(0.01).unwrap();
    let designs = [
        ("lqr", design.lqr().unwrap().control_design()),
        ("lqg", design.lqg().unwrap().control_design().unwrap()),
        ("mpc", design.mpc().unwrap().control_design().unwrap()),
    ];
    for (name, d) in &designs {
        let trace = replay(d);
        bench_one::<f64>(c, &format!("control_step_{name}_f64_paper"), d, &trace);
        bench_one::<f32>(c, &format!("control_step_{name}_f32_paper"), d, &trace);
    }
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API.
mod group {
    criterion::criterion_group!(benches, super::control);
}
criterion_main!(group::benches);
