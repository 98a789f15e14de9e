//! The swing-up on generated rigs ([`rip_core::rig::Rig::random`]): for each seed, each
//! `swing_up.method` and each balance controller, a few runs from hanging at rest on the rig's
//! own model (its dead zone and friction compensated as the rig file says), counting the
//! catches on the first arrival, the successes and the most passes over the top in a run.
//!
//! ```text
//! cargo run --release -p rip-core --example swingup_rigs -- [SEEDS] [NOISE_SEEDS]
//! ```

use rip_core::rig::Rig;
use rip_core::sim::simulate;
use rip_core::spec::study::{arrivals, hanging_config, supervised};
use rip_core::spec::ControllerKind;
use rip_core::swingup::SwingUpMethod;
use rip_core::Spec;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seeds: u64 = args
        .get(1)
        .map_or(16, |v| v.parse().expect("SEEDS is a count"));
    let noise: u64 = args
        .get(2)
        .map_or(3, |v| v.parse().expect("NOISE_SEEDS is a count"));
    let ts = rip_core::paper::TS;
    let runs = noise * ControllerKind::ALL.len() as u64;
    println!("rig   method       first arrival  success  most over-tops  ({runs} runs each)");
    for seed in 0..seeds {
        for method in [SwingUpMethod::Energy, SwingUpMethod::Trajectory] {
            let mut spec = Spec::parse(&Rig::random(seed).to_toml()).expect("a generated rig");
            spec.swing_up.method = method;
            let (Ok(design), Ok(plant)) = (spec.design(ts), spec.plant()) else {
                println!("{seed:>3}   {:<12} no design", method.name());
                continue;
            };
            let (mut first, mut ok, mut over, mut ran) = (0, 0, 0, 0);
            for kind in ControllerKind::ALL {
                let Ok(mut sup) = supervised(&spec, &design, kind) else {
                    continue;
                };
                for n in 0..noise {
                    let config = hanging_config(&spec, ts, n);
                    let Ok(res) = simulate(&plant, sup.as_mut(), &config) else {
                        continue;
                    };
                    sup.reset();
                    let a = arrivals(&res, spec.swing_up.catch_angle);
                    ran += 1;
                    first += u32::from(a.caught_on_first);
                    ok += u32::from(res.swing_up_succeeded());
                    over = over.max(a.over_tops);
                }
            }
            println!(
                "{seed:>3}   {:<12} {first:>6} / {ran:<5} {ok:>4} / {ran:<3} {over:>8}",
                method.name()
            );
        }
    }
}
