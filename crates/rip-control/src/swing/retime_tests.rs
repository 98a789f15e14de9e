//! Host tests of the plan's retiming (module docs, "Planned swing-up"): a pendulum that swings
//! slower or faster than its plan is followed at its own pace.

use super::tests::{params, Probe, TS};
use super::*;

extern crate std;
use std::vec::Vec;

/// A plan of a pendulum swinging about hanging, `α_j = π + A sin(ω j T)`, with the arm still
/// and no gain: point `j` asks for `j` volts, so the voltage tells which point is followed.
fn swinging_plan(n: usize, amplitude: f64, omega: f64) -> Vec<PlanPoint<f64>> {
    (0..n)
        .map(|j| {
            let phase = omega * j as f64 * TS;
            PlanPoint {
                x: [
                    0.0,
                    0.0,
                    core::f64::consts::PI + amplitude * phase.sin(),
                    amplitude * omega * phase.cos(),
                ],
                u: j as f64,
                k: [0.0; 4],
            }
        })
        .collect()
}

/// Follows `swinging_plan` with a pendulum at `omega_measured`; returns each period's plan
/// index, or `None` from the period the plan is left.
fn follow(omega_plan: f64, omega_measured: f64, seconds: f64) -> Vec<Option<u32>> {
    // Its rate at the start, 1.8 rad/s, within what a plan may start from.
    let amplitude = 0.3;
    let periods = (seconds / TS) as usize;
    let plan = swinging_plan(2 * periods, amplitude, omega_plan);
    let mut sup = SwingSupervisor::new(params(false));
    let mut probe = Probe::default();
    (0..periods)
        .map(|n| {
            let alpha = core::f64::consts::PI + amplitude * (omega_measured * n as f64 * TS).sin();
            let index = sup.plan_index();
            sup.step_planned(&mut probe, &plan, [0.0, alpha], [0.0; 2]);
            index.filter(|_| sup.planning())
        })
        .collect()
}

#[test]
fn a_pendulum_slower_or_faster_than_its_plan_is_followed_at_its_own_pace() {
    let omega = 6.0;
    for ratio in [0.8, 1.0, 1.3] {
        let indices = follow(omega, ratio * omega, 3.0);
        let mut last = None;
        for (n, index) in indices.iter().enumerate().skip(1) {
            let j = index.unwrap_or_else(|| panic!("ratio {ratio}: left at period {n}"));
            // 0, 1 or 2 of the plan's samples a period, never back.
            if let Some(prev) = last {
                assert!((prev..=prev + 2).contains(&j), "{prev} -> {j}");
            }
            last = Some(j);
        }
        // After 3 s the plan's phase is the pendulum's, within a few samples of the rate
        // estimate's lag, where the clock alone would be 3ω|1 − ratio| rad off.
        let j = last.unwrap() as f64;
        let periods = (indices.len() - 1) as f64;
        let lag = omega * j * TS - ratio * omega * periods * TS;
        assert!(lag.abs() < 0.25, "ratio {ratio}: phase off by {lag} rad");
    }
}

#[test]
fn the_plan_runs_by_its_clock_over_its_settling_samples() {
    // A pendulum one sample ahead of its plan: over the settling samples the index is the
    // clock's all the same (the rates are checked there, not the phase); after them it moves
    // to the pendulum's.
    let plan = swinging_plan(50, 0.3, 6.0);
    let mut sup = SwingSupervisor::new(params(false));
    let mut probe = Probe::default();
    for n in 0..PLAN_SETTLE_SAMPLES + 3 {
        let ahead = plan[n as usize + 1].x[2];
        sup.step_planned(&mut probe, &plan, [0.0, ahead], [0.0; 2]);
        if n < PLAN_SETTLE_SAMPLES {
            assert_eq!(sup.plan_index(), Some(n + 1), "settling sample {n}");
        }
    }
    assert_eq!(
        sup.plan_index(),
        Some(PLAN_SETTLE_SAMPLES + 4),
        "retimed to the pendulum"
    );
}

#[test]
fn a_plan_that_waits_for_a_pendulum_that_stays_is_left_once_it_lags_too_far() {
    // The pendulum follows the plan to its first turning point, then stays there: the plan
    // waits at that point, whose angle and rate the pendulum's match, until it lags its clock
    // by a quarter of its length.
    let omega = 6.0;
    let plan = swinging_plan(400, 0.3, omega);
    let turn = (core::f64::consts::FRAC_PI_2 / (omega * TS)).round() as usize;
    let mut sup = SwingSupervisor::new(params(false));
    let mut probe = Probe::default();
    let mut left = None;
    for n in 0..300usize {
        let alpha = plan[n.min(turn)].x[2];
        sup.step_planned(&mut probe, &plan, [0.0, alpha], [0.0; 2]);
        if !sup.planning() {
            left = Some(n);
            break;
        }
    }
    let left = left.expect("the plan is left");
    let bound = turn + (PLAN_MAX_LAG_SHARE * plan.len() as f64) as usize;
    assert!(
        (bound - 15..=bound + 2).contains(&left),
        "left at period {left}, bound {bound}"
    );
}
