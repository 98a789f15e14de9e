//! The swing-up experiment of a [`Spec`], set up once for the tests, the Monte Carlo example
//! and `riprs compare --start down`: the pendulum hangs at rest, the supervisor swings it up
//! and catches it with the spec's balance controller, and [`STEP_AFTER_CATCH`] seconds after
//! the catch the arm reference steps to `reference.arm_step` (the paper's 0 → 1 rad step).

use super::SwingUp;
use crate::controller::Controller;
use crate::error::RipError;
use crate::sim::{Reference, SimConfig};
use crate::spec::{ControllerKind, Design, Spec, SpecError};

/// Time (s) from the catch to the arm step: the catch transient of every balance controller
/// has died down by then (it lasts about 1 s on both presets).
pub const STEP_AFTER_CATCH: f64 = 2.0;

pub use crate::spec::SWING_UP_ALLOWANCE;

/// The simulation of `spec` ([`Spec::sim_config`]) started hanging at rest, `x0 = [0, 0, π, 0]`,
/// with the arm step [`STEP_AFTER_CATCH`] after the catch and
/// `reference.duration + `[`SWING_UP_ALLOWANCE`] seconds long.
pub fn hanging_config(spec: &Spec, ts: f64, seed: u64) -> SimConfig {
    let base = spec.sim_config(ts, seed);
    SimConfig {
        duration: spec.reference.duration + SWING_UP_ALLOWANCE,
        x0: [0.0, 0.0, std::f64::consts::PI, 0.0],
        reference: Reference::StepAfterCatch {
            delay: STEP_AFTER_CATCH,
            value: [spec.reference.arm_step, 0.0],
        },
        ..base
    }
}

/// The supervisor around `design`'s controller `kind`, with the swing-up designed on `spec`'s
/// `[plant]` and `[swing_up]` settings.
pub fn supervised(
    spec: &Spec,
    design: &Design,
    kind: ControllerKind,
) -> Result<SwingUp<Box<dyn Controller>>, SpecError> {
    let plant = spec.plant()?;
    let balance = design.controller(kind)?;
    SwingUp::new(balance, &plant, spec.swing_up.clone()).map_err(|e| match e {
        RipError::InvalidParameter { name, reason } => SpecError::new(name, reason),
        e => SpecError::new("swing_up", e.to_string()),
    })
}
