//! One iteration of the real-time loop without I/O: decode a measurement frame, step the
//! controller, clamp and encode the command (`rip_rt::loop_core::LoopCore::iterate`).

use criterion::{black_box, criterion_main, Criterion};
use rip_rt::config::Config;
use rip_rt::controllers::{build, ControllerKind};
use rip_rt::loop_core::LoopCore;
use rip_rt::protocol::{encode, Frame, Measurement, Message, MAX_FRAME};

fn rt_loop(c: &mut Criterion) {
    let cfg = Config::default();
    for kind in [
        ControllerKind::Lqr,
        ControllerKind::Lqg,
        ControllerKind::Mpc,
    ] {
        let controller =
            build(kind, &cfg).expect("the default configuration builds every controller");
        let mut core = LoopCore::new(controller, &cfg).unwrap();
        let mut rx = [0u8; MAX_FRAME];
        let mut out = [0u8; MAX_FRAME];
        let mut k: u32 = 0;
        c.bench_function(&format!("rt_loop_iteration_{kind}"), |bench| {
            bench.iter(|| {
                k = k.wrapping_add(1);
                // A small oscillation around upright so the controller does real work.
                let wobble = ((k % 16) as i32) - 8;
                let n = encode(
                    &Frame {
                        seq: k as u16,
                        message: Message::Measurement(Measurement {
                            ack_seq: k as u16,
                            arm_counts: wobble,
                            pendulum_counts: 1024 + wobble / 2,
                            ..Default::default()
                        }),
                    },
                    &mut rx,
                );
                let step = core
                    .iterate(black_box(&rx[..n]), k as u16, 2.0, &mut out)
                    .unwrap()
                    .unwrap();
                black_box(out[..step.len].len())
            })
        });
    }
}

// criterion_group! expands to an undocumented `pub fn`; inside a private module it is not
// public API, so it needs no doc comment.
mod group {
    criterion::criterion_group!(benches, super::rt_loop);
}
criterion_main!(group::benches);
