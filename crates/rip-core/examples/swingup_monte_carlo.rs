//! Monte Carlo of the swing-up and catch: for each balance controller (LQR, LQG and MPC as the
//! spec designs them), N runs from hanging at rest, each on a plant whose every physical
//! parameter (all but `g`) is drawn uniformly within ±10 % of the preset's, with its own noise
//! seed, 2048-count encoders and 1 mrad noise; the swing-up is designed on the nominal preset.
//! The runs are [`rip_core::spec::study`]'s experiment (the arm steps 0 → 1 rad
//! `reference.step_time`, by default 1 s, after the catch); success and time to upright are [`rip_core::sim::swing_up_succeeded`] and the
//! catch time, and [`rip_core::spec::study::arrivals`] counts the arrivals near upright
//! and the passes over the top of each run from its true state. The success rate is printed
//! with its Wilson 95 % interval ([`rip_core::stats::wilson`]).
//!
//! ```text
//! cargo run --release -p rip-core --example swingup_monte_carlo -- [N] [preset] [swing_up settings]
//! ```

use rip_core::batch::MonteCarlo;
use rip_core::sim::simulate;
use rip_core::spec::study::{arrivals, hanging_config, supervised, Arrivals};
use rip_core::spec::{ControllerKind, Param};
use rip_core::Spec;

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i]
}

struct Run {
    ok: bool,
    caught: bool,
    fell: bool,
    upright: f64,
    arrivals: Arrivals,
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: u64 = args
        .get(1)
        .map_or(200, |v| v.parse().expect("N is a count"));
    let preset = args.get(2).map_or("paper", String::as_str);
    // Further `[swing_up]` settings, as TOML lines ("energy_margin = 0.1; catch_rate = 6").
    let extra = args.get(3).map_or(String::new(), |v| v.replace(';', "\n"));
    let spec = Spec::parse(&format!(
        "[plant]\npreset = \"{preset}\"\n[swing_up]\n{extra}\n"
    ))
    .expect("a preset and valid [swing_up] settings");
    let ts = rip_core::paper::TS;
    let design = spec.design(ts).expect("the preset's design");
    let study = MonteCarlo {
        base: spec.plant.params(),
        perturbation: 0.1,
        // Every physical parameter (friction and dead zone are 0 in the presets).
        parameters: Param::ALL.to_vec(),
        seed: 2024,
    };
    let limit = spec.swing_up.arm_limit;
    let catch_angle = spec.swing_up.catch_angle;
    println!("preset {preset}, {n} runs per controller, ±10 % on every physical parameter");
    println!(
        "controller  success (Wilson 95 %)  no catch  fell  first arrival  max over-tops  upright median    p95   max|θ|  after fall"
    );
    for kind in ControllerKind::ALL {
        // One supervisor per thread, designed once (a planned swing-up takes seconds to
        // design): `simulate` resets it before each run.
        let one = |sup: &mut Box<dyn rip_core::Controller>, i: u64| -> Run {
            let (plant, seed) = study.run(i).expect("a perturbed plant");
            let config = hanging_config(&spec, ts, seed);
            let res = simulate(&plant, sup, &config).expect("the run");
            Run {
                ok: res.swing_up_succeeded(),
                caught: res.catch_time.is_some(),
                fell: res.fell,
                upright: res.catch_time.unwrap_or(f64::NAN),
                arrivals: arrivals(&res, catch_angle),
            }
        };
        let half = n / 2;
        let runs: Vec<Run> = std::thread::scope(|s| {
            let runs = |range: std::ops::Range<u64>| {
                let mut sup = supervised(&spec, &design, kind).expect("the supervisor");
                range.map(|i| one(&mut sup, i)).collect::<Vec<_>>()
            };
            let a = s.spawn(move || runs(0..half));
            let mut b = runs(half..n);
            let mut out = a.join().expect("the runs");
            out.append(&mut b);
            out
        });
        let count = |f: &dyn Fn(&Run) -> bool| runs.iter().filter(|r| f(r)).count();
        let ok = count(&|r| r.ok);
        let no_catch = count(&|r| !r.caught);
        let fell = count(&|r| r.fell);
        let first = count(&|r| r.arrivals.caught_on_first);
        let over = runs.iter().map(|r| r.arrivals.over_tops).max().unwrap_or(0);
        let mut times: Vec<f64> = runs
            .iter()
            .map(|r| r.upright)
            .filter(|t| t.is_finite())
            .collect();
        times.sort_by(f64::total_cmp);
        let max_arm = runs.iter().fold(0.0f64, |a, r| a.max(r.arrivals.peak_arm));
        let after_fall = runs
            .iter()
            .fold(0.0f64, |a, r| a.max(r.arrivals.peak_arm_after_fall));
        let (low, high) = rip_core::stats::wilson(ok as u64, n, rip_core::stats::Z_95)
            .unwrap_or((f64::NAN, f64::NAN));
        println!(
            "{:<10} {:>6.1} % [{:>5.1}, {:>5.1}] {no_catch:>8} {fell:>5} {:>12.1} % {over:>14} {:>11.2} s {:>6.2} s {max_arm:>7.3} {after_fall:>11.3}",
            kind.name(),
            100.0 * ok as f64 / n as f64,
            100.0 * low,
            100.0 * high,
            100.0 * first as f64 / n as f64,
            percentile(&times, 0.5),
            percentile(&times, 0.95),
        );
    }
    println!("arm limit {limit} rad");
}
