//! The swing-up Monte Carlo of `examples/swingup_monte_carlo.rs`, small enough for every test
//! run: the same ±10 % plants and seeds, judged on the simulated plant's true state.

use rip_core::batch::MonteCarlo;
use rip_core::sim::simulate;
use rip_core::spec::study::{arrivals, hanging_config, supervised};
use rip_core::spec::{ControllerKind, Param};
use rip_core::Spec;

/// Successes and catches on the first arrival near upright over `runs` perturbed plants.
fn monte_carlo(preset: &str, settings: &str, kind: ControllerKind, runs: u64) -> (usize, usize) {
    let spec = Spec::parse(&format!(
        "[plant]\npreset = \"{preset}\"\n[swing_up]\n{settings}\n"
    ))
    .unwrap();
    let ts = rip_core::paper::TS;
    let design = spec.design(ts).unwrap();
    let study = MonteCarlo {
        base: spec.plant.params(),
        perturbation: 0.1,
        parameters: Param::ALL.to_vec(),
        seed: 2024,
    };
    let (mut ok, mut first) = (0, 0);
    for i in 0..runs {
        let (plant, seed) = study.run(i).unwrap();
        let mut sup = supervised(&spec, &design, kind).unwrap();
        let res = simulate(&plant, &mut sup, &hanging_config(&spec, ts, seed)).unwrap();
        ok += usize::from(res.swing_up_succeeded());
        first += usize::from(arrivals(&res, spec.swing_up.catch_angle).caught_on_first);
    }
    (ok, first)
}

/// On the paper preset the pendulum arrives with the arm still turning; the last-rise brake
/// stops the arm on the way up, which is what lets the LQG hold its catches under ±10 %
/// model error (200-run figures in docs/swing-up.md, "The last-rise brake").
#[test]
fn the_last_rise_brake_keeps_more_lqg_catches_on_the_paper_preset() {
    const RUNS: u64 = 20;
    let base = "reference_return_rate = 0.5\ncatch_prediction = 1\ncatch_margin = 0.25\n";
    let (ok_off, _) = monte_carlo("paper", base, ControllerKind::Lqg, RUNS);
    let (ok_on, first_on) = monte_carlo(
        "paper",
        &format!("{base}rise_damping = 15\n"),
        ControllerKind::Lqg,
        RUNS,
    );
    assert!(ok_on >= 19, "{ok_on} of {RUNS} succeeded with the brake");
    assert!(ok_on > ok_off, "{ok_on} with the brake, {ok_off} without");
    assert!(
        first_on >= 14,
        "{first_on} of {RUNS} caught on the first arrival"
    );
}
