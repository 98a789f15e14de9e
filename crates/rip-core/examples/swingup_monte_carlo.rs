//! Monte Carlo of the swing-up and catch: for each balance controller (LQR, LQG and MPC as the
//! spec designs them), N runs from hanging at rest, each on a plant whose every physical
//! parameter (all but `g`) is drawn uniformly within ±10 % of the preset's, with its own noise
//! seed, 2048-count encoders and 1 mrad noise; the swing-up is designed on the nominal preset.
//! The runs are [`rip_core::swingup::study`]'s experiment (the arm steps 0 → 1 rad 2 s after
//! the catch) through the metrics-only batch; success and time to upright are
//! [`rip_core::sim::swing_up_succeeded`] and the catch time.
//!
//! ```text
//! cargo run --release -p rip-core --example swingup_monte_carlo -- [N] [preset]
//! ```

use std::sync::atomic::{AtomicBool, AtomicU64};

use rip_core::batch::{simulate_metrics, MetricsOptions, MonteCarlo};
use rip_core::spec::{ControllerKind, Param};
use rip_core::swingup::study::{hanging_config, supervised};
use rip_core::{Controller, Spec};

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: u64 = args
        .get(1)
        .map_or(200, |v| v.parse().expect("N is a count"));
    let preset = args.get(2).map_or("paper", String::as_str);
    let spec = Spec::parse(&format!("[plant]\npreset = \"{preset}\"\n")).expect("a preset");
    let ts = rip_core::paper::TS;
    let design = spec.design(ts).expect("the preset's design");
    let study = MonteCarlo {
        base: spec.plant.params(),
        perturbation: 0.1,
        // Every physical parameter (friction and dead zone are 0 in the presets).
        parameters: Param::ALL.to_vec(),
        seed: 2024,
    };
    let config = hanging_config(&spec, ts, 0);
    let limit = spec.swing_up.arm_limit;
    println!("preset {preset}, {n} runs per controller, ±10 % on every physical parameter");
    println!("controller  success  no catch  fell  upright median    p95   max|θ|  max|u|");
    for kind in ControllerKind::ALL {
        let make = || -> Box<dyn Controller> {
            Box::new(supervised(&spec, &design, kind).expect("the supervisor"))
        };
        let runs = simulate_metrics(
            0..n,
            &config,
            &MetricsOptions::default(),
            &|i| study.run(i),
            &make,
            &AtomicU64::new(0),
            &AtomicBool::new(false),
        )
        .expect("the runs");
        let ok = runs.iter().filter(|m| m.swing_up_succeeded).count();
        let no_catch = runs.iter().filter(|m| m.time_to_upright.is_nan()).count();
        let fell = runs.iter().filter(|m| m.fell).count();
        let mut times: Vec<f64> = runs
            .iter()
            .map(|m| m.time_to_upright)
            .filter(|t| t.is_finite())
            .collect();
        times.sort_by(f64::total_cmp);
        let max_arm = runs.iter().fold(0.0f64, |a, m| a.max(m.peak_arm));
        let max_u = runs.iter().fold(0.0f64, |a, m| a.max(m.peak_voltage));
        println!(
            "{:<10} {:>6.1} % {no_catch:>8} {fell:>5} {:>11.2} s {:>6.2} s {max_arm:>7.3} {max_u:>6.2}",
            kind.name(),
            100.0 * ok as f64 / n as f64,
            percentile(&times, 0.5),
            percentile(&times, 0.95),
        );
    }
    println!("arm limit {limit} rad");
}
