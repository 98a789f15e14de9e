//! The stop's rule per period (`rip_control::stop`), in the host's `f64` and the device's
//! `f32`: the braking envelope's check at its worst (a state whose analytic stopping point is
//! past the bound, so the stop is simulated from the whole state, `latency + ⌈3 s / T_s⌉`
//! periods of RK4), and one period of the stop's sequence.

use criterion::{black_box, criterion_main, Criterion};
use rip_control::stop::{ArmEnvelope, SimulatedStop, StoppingModel};
use rip_control::swing::ArmModel;
use rip_rt::config::Config;
use rip_rt::envelope::{arm_envelope, brake, stop_parts, stop_sequence, BrakeMode};

fn envelope_f32(e: &ArmEnvelope) -> ArmEnvelope<f32> {
    let m = e.model();
    let model = StoppingModel {
        a0: m.a0 as f32,
        k: m.k as f32,
        drive_per_volt: m.drive_per_volt as f32,
        latency: m.latency as f32,
        voltage: m.voltage as f32,
    };
    let cfg = Config::default();
    let s = stop_parts(&cfg)
        .expect("the default rig has a plant")
        .simulated;
    let a = s.model;
    let to = |v: f64| v as f32;
    let sim = SimulatedStop {
        model: ArmModel {
            j0: to(a.j0),
            ja: to(a.ja),
            m12: to(a.m12),
            grav: to(a.grav),
            b: to(a.b),
            c_arm: to(a.c_arm),
            dp: to(a.dp),
        },
        dead_zone: to(s.dead_zone),
        law: rip_control::stop::BrakingLaw {
            voltage: to(s.law.voltage),
            linear_below: to(s.law.linear_below),
        },
        ts: to(s.ts),
        substeps: s.substeps,
        latency_periods: s.latency_periods,
    };
    ArmEnvelope::new(model, Some(sim), e.bound() as f32)
}

fn stop(c: &mut Criterion) {
    let cfg = Config::default();
    let parts = stop_parts(&cfg);
    let env = arm_envelope(&cfg, parts.as_ref());
    // 2 rad out at 8 rad/s, the pendulum just past upright and falling: past the analytic
    // bound, so the whole-state simulation decides.
    let (theta, rate, alpha, alpha_rate) = (2.0, 8.0, 0.3, 2.0);
    assert!(env.model().stopping_point(theta, rate, 12.0) > env.bound());
    c.bench_function("stop_envelope_simulated_f64", |b| {
        b.iter(|| black_box(&env).check_state(black_box(theta), rate, alpha, alpha_rate, 12.0))
    });
    let env32 = envelope_f32(&env);
    c.bench_function("stop_envelope_simulated_f32", |b| {
        b.iter(|| black_box(&env32).check_state(black_box(theta as f32), 8.0, 0.3, 2.0, 12.0))
    });
    let mut seq = stop_sequence(
        &cfg,
        parts.as_ref(),
        brake(parts.as_ref(), BrakeMode::Active),
    );
    let mut k = 0u32;
    c.bench_function("stop_sequence_period_f64", |b| {
        b.iter(|| {
            k = k.wrapping_add(1);
            let wobble = f64::from(k % 16) * 1e-3;
            black_box(seq.step(black_box(0.5 + wobble), 3.0, 2.0, 1.0))
        })
    });
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// part of any public API.
mod group {
    criterion::criterion_group!(benches, super::stop);
}
criterion_main!(group::benches);
