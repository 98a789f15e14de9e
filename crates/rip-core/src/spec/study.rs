//! The swing-up experiment of a [`Spec`], set up once for the tests, the Monte Carlo example
//! and `riprs compare --start down`: the pendulum hangs at rest, the supervisor swings it up
//! and catches it with the spec's balance controller, and `reference.step_time` seconds after
//! the catch the arm reference steps to `reference.arm_step` (the paper's 0 → 1 rad step), as
//! `rip-rt run --swing-up` steps it on the rig.

use super::{ControllerKind, Design, Spec, SpecError, Start};
use crate::controller::Controller;
use crate::error::RipError;
use crate::sim::SimConfig;
use crate::swingup::{wrap_angle, SwingUp};

/// The simulation of `spec` started hanging at rest: [`Spec::simulation`] with
/// [`Start::Hanging`] (`x0 = [0, 0, π, 0]`, the arm step `reference.step_time` after the catch,
/// `reference.duration + SWING_UP_ALLOWANCE` seconds long).
pub fn hanging_config(spec: &Spec, ts: f64, seed: u64) -> SimConfig {
    spec.simulation(ts, seed, Start::Hanging)
}

/// The supervisor around `design`'s balance controller `kind`, with the swing-up designed on
/// `spec`'s `[plant]` and `[swing_up]` settings, assembled as `rip-rt` and `riprs.SwingUp`
/// assemble it: the law plans within the bounds the compensation leaves, and the
/// compensation (when the design has one) is applied around the whole supervisor, to the
/// swing-up's voltage as to the balance controller's.
pub fn supervised(
    spec: &Spec,
    design: &Design,
    kind: ControllerKind,
) -> Result<Box<dyn Controller>, SpecError> {
    let plant = spec.plant()?;
    let balance = design.balance(kind)?;
    let mut settings = spec.swing_up.clone();
    if let Some(c) = design.compensation() {
        settings.max_voltage = c.planned_limit(settings.max_voltage);
    }
    let sup = SwingUp::new(balance, &plant, settings).map_err(|e| match e {
        RipError::InvalidParameter { name, reason } => SpecError::new(name, reason),
        e => SpecError::new("swing_up", e.to_string()),
    })?;
    Ok(design.compensate(Box::new(sup)))
}

/// How a swing-up run approached upright, from its true state (not the supervisor's
/// estimate): the figures of the first-arrival requirement.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Arrivals {
    /// Arrivals near upright (the true `|wrap(α)|` entering `catch_angle`) while swinging up,
    /// up to and including the one in which the catch happened.
    pub before_catch: u32,
    /// Whether the catch happened during the first arrival near upright.
    pub caught_on_first: bool,
    /// Passes of the pendulum over the top (the unwrapped α crossing a multiple of 2π) while
    /// the supervisor was swinging up: each one is an arrival that was not caught.
    pub over_tops: u32,
    /// Largest true `|θ|` (rad) over the run.
    pub peak_arm: f64,
    /// Largest true `|θ|` (rad) from the first fall on; 0 without a fall.
    pub peak_arm_after_fall: f64,
}

/// The [`Arrivals`] of `res`, a run of a swing-up supervisor, with `catch_angle` the
/// supervisor's `swing_up.catch_angle`.
pub fn arrivals(res: &crate::SimResult, catch_angle: f64) -> Arrivals {
    use crate::controller::Phase;
    use std::f64::consts::TAU;
    let mut out = Arrivals::default();
    let mut near = false;
    let mut caught = false;
    for k in 0..res.len() {
        let x = res.x[k];
        out.peak_arm = out.peak_arm.max(x[0].abs());
        if res.fall_time.is_some_and(|t| res.t[k] >= t) {
            out.peak_arm_after_fall = out.peak_arm_after_fall.max(x[0].abs());
        }
        let swinging = res.phase[k] == Phase::SwingUp;
        let is_near = wrap_angle(x[2]).abs() <= catch_angle;
        if is_near && !near && !caught && (swinging || res.phase[k] == Phase::Balance) {
            out.before_catch += 1;
        }
        near = is_near;
        if !caught && res.phase[k] == Phase::Balance {
            caught = true;
            out.caught_on_first = out.before_catch == 1;
        }
        if swinging && k + 1 < res.len() {
            let (a, b) = (x[2] / TAU, res.x[k + 1][2] / TAU);
            if a.floor() != b.floor() {
                out.over_tops += 1;
            }
        }
    }
    out
}
