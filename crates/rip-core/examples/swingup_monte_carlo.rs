//! Monte Carlo of the swing-up and catch: for each balance controller (the paper's LQR, LQG and
//! MPC), N runs from hanging at rest, each on a plant whose every physical parameter (all but
//! `g`) is drawn uniformly within ±10 % of the preset's, with its own noise seed, 2048-count
//! encoders and 1 mrad noise; the swing-up is designed on the nominal preset. A run succeeds when
//! it catches and stays up to the end (15 s, the arm stepping 0 → 1 rad at 8 s); the report is
//! the success rate and the time to upright (the catch) median and 95th percentile.
//!
//! ```text
//! cargo run --release -p rip-core --example swingup_monte_carlo -- [N] [preset]
//! ```

use rand::{Rng, SeedableRng};
use rip_core::mpc::{self, QpSolver};
use rip_core::paper;
use rip_core::regulators::DEFAULT_RATE_CUTOFF_HZ;
use rip_core::sim::{simulate_runs, Reference, SensorModel};
use rip_core::{
    Controller, FurutaParams, Lqg, Lqr, Mpc, Plant, SimConfig, State, SwingUp, SwingUpSettings,
};

fn balance(name: &str, nominal: &Plant, preset: &str) -> Box<dyn Controller> {
    let (ad, bd) = if preset == "paper" {
        let m = paper::discrete_model();
        (m.a, m.b)
    } else {
        nominal
            .linearize_discrete(&State::zeros(), 0.0, paper::TS)
            .expect("the preset linearises")
    };
    let (q, r) = paper::lqr_weights();
    let lqr = Lqr::design(&ad, &bd, &q, &r, paper::TS, DEFAULT_RATE_CUTOFF_HZ).unwrap();
    let mpc = Mpc::new(
        &ad,
        &bd,
        &paper::output_matrix(),
        paper::TS,
        mpc::paper::settings(QpSolver::ActiveSet),
    )
    .unwrap();
    match name {
        "LQR" => Box::new(lqr),
        "LQG" => {
            let (m, kf) = (mpc.model(), mpc.kalman_design());
            Box::new(Lqg::new(&lqr.gain(), &m.a, &m.b, &m.c, &kf.l, &kf.m, paper::TS).unwrap())
        }
        _ => Box::new(mpc),
    }
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args
        .get(1)
        .map_or(200, |v| v.parse().expect("N is a count"));
    let preset = args.get(2).map_or("paper", String::as_str);
    let base = if preset == "paper" {
        FurutaParams::paper()
    } else {
        FurutaParams::qube_servo2()
    };
    let nominal = Plant::new(base).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(2024);
    let plants: Vec<Plant> = (0..n)
        .map(|_| {
            let mut p = base.to_array();
            // Every physical parameter but g (the last).
            for v in p.iter_mut().take(11) {
                *v *= rng.gen_range(0.9..1.1);
            }
            Plant::new(FurutaParams::from_array(p)).unwrap()
        })
        .collect();
    let runs: Vec<(usize, u64)> = (0..n).map(|i| (i, 1000 + i as u64)).collect();
    let config = SimConfig {
        duration: 15.0,
        x0: [0.0, 0.0, std::f64::consts::PI, 0.0],
        reference: Reference::Step {
            time: 8.0,
            value: [1.0, 0.0],
        },
        sensor: SensorModel {
            counts_per_rev: Some([2048.0, 2048.0]),
            noise_std: [1e-3, 1e-3],
            offsets: [0.0; 2],
        },
        ..Default::default()
    };
    let limit = SwingUpSettings::default().arm_limit;
    println!("preset {preset}, {n} runs per controller, ±10 % on every physical parameter");
    println!("controller  success  no catch  fell  timeout  upright median  p95   max|θ|  max|u|");
    for name in ["LQR", "LQG", "MPC"] {
        let controllers = (0..n)
            .map(|_| {
                Box::new(
                    SwingUp::new(
                        balance(name, &nominal, preset),
                        &nominal,
                        SwingUpSettings::default(),
                    )
                    .unwrap(),
                ) as Box<dyn Controller>
            })
            .collect();
        let results = simulate_runs(&plants, &runs, &config, controllers).unwrap();
        let (mut ok, mut no_catch, mut fell, mut timeout) = (0, 0, 0, 0);
        let mut times = Vec::new();
        let (mut max_arm, mut max_u) = (0.0f64, 0.0f64);
        for res in &results {
            max_arm = res.x.iter().fold(max_arm, |m, x| m.max(x[0].abs()));
            max_u = res.u.iter().fold(max_u, |m, u| m.max(u.abs()));
            if let Some(t) = res.catch_time {
                times.push(t);
            }
            if res.stop_cause.is_some() {
                timeout += 1;
            } else if res.fell {
                fell += 1;
                if std::env::var("SWINGUP_MC_VERBOSE").is_ok() {
                    let k = res
                        .t
                        .iter()
                        .position(|&t| Some(t) == res.catch_time)
                        .unwrap();
                    eprintln!(
                        "{name} fell: catch {:?} fall {:?} at catch x {:?} final {:?}",
                        res.catch_time, res.fall_time, res.x[k], res.x_final
                    );
                }
            } else if res.catch_time.is_none() {
                no_catch += 1;
            } else {
                ok += 1;
            }
        }
        times.sort_by(f64::total_cmp);
        println!(
            "{name:<10} {:>6.1} % {no_catch:>8} {fell:>5} {timeout:>8} {:>11.2} s {:>5.2} s {max_arm:>7.3} {max_u:>6.2}",
            100.0 * ok as f64 / n as f64,
            percentile(&times, 0.5),
            percentile(&times, 0.95),
        );
    }
    println!("arm limit {limit} rad");
}
