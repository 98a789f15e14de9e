//! Builds the selected controller from the configuration by rip-core's one assembly
//! (`rip_core::spec`): designed on the `[plant]` model discretised at the loop period, LQR and
//! LQG sharing the gain, LQG and MPC sharing one Kalman design, exactly as `riprs compare`
//! builds them, and the swing-up supervisor around any of them. This module only chooses and
//! converts.

use std::fmt;
use std::str::FromStr;

use rip_core::spec::ControllerKind as Kind;
use rip_core::{Controller, SwingUp};

use crate::config::Config;

/// The controllers `rip-rt run --controller` accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerKind {
    /// LQR on measured angles, rates by filtered difference.
    Lqr,
    /// LQR gain on the steady-state Kalman filter's estimate.
    Lqg,
    /// Constrained MPC sharing the Kalman filter.
    Mpc,
}

impl ControllerKind {
    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            ControllerKind::Lqr => "lqr",
            ControllerKind::Lqg => "lqg",
            ControllerKind::Mpc => "mpc",
        }
    }
}

impl fmt::Display for ControllerKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ControllerKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "lqr" => Ok(ControllerKind::Lqr),
            "lqg" => Ok(ControllerKind::Lqg),
            "mpc" => Ok(ControllerKind::Mpc),
            _ => Err(format!("must be lqr, lqg or mpc, got {s:?}")),
        }
    }
}

impl From<ControllerKind> for Kind {
    fn from(k: ControllerKind) -> Self {
        match k {
            ControllerKind::Lqr => Kind::Lqr,
            ControllerKind::Lqg => Kind::Lqg,
            ControllerKind::Mpc => Kind::Mpc,
        }
    }
}

/// The one assembly's design for `kind` at the loop period, with `[mpc] input_bounds` inside
/// `±safety.voltage_limit`.
pub(crate) fn design(kind: ControllerKind, cfg: &Config) -> Result<rip_core::spec::Design, String> {
    let mut spec = cfg.spec.clone();
    let v = cfg.safety.voltage_limit;
    let (lo0, hi0) = spec.input_bounds();
    let (lo, hi) = (lo0.max(-v), hi0.min(v));
    if lo >= hi {
        return Err(format!(
            "safety.voltage_limit: ±{v} V leaves nothing of mpc.input_bounds [{lo0}, {hi0}]"
        ));
    }
    spec.set_input_bounds(lo, hi);
    spec.design(cfg.period_s())
        .map_err(|e| format!("{kind} design: {e}"))
}

/// The pre-flight check (rip-core's [`rip_core::preflight`]) of the balance controller `kind`
/// as [`build`] designs it, on the rig of `cfg` (from the file `rig_file`), with
/// `safety.arm_limit` as the arm's bound; with `swing_up`, for a run that swings up first
/// (its swing_up check, the rig's feasibility, then applies).
pub fn preflight(
    kind: ControllerKind,
    cfg: &Config,
    rig_file: Option<&std::path::Path>,
    swing_up: bool,
) -> Result<rip_core::preflight::Report, String> {
    let design = design(kind, cfg)?;
    Ok(rip_core::preflight::run(&rip_core::preflight::Input {
        design: &design,
        controller: kind.into(),
        rig_file,
        arm_limit: Some(cfg.safety.arm_limit),
        swing_up,
    }))
}

/// Builds the controller `kind` as configured, at the loop period. Its input bounds are the
/// file's `[mpc] input_bounds` inside `±safety.voltage_limit`, so that no controller plans
/// with more voltage than the loop will send; the `[compensation]` of the dead zone and arm
/// friction is applied to the voltage it writes (rip-core's assembly).
pub fn build(kind: ControllerKind, cfg: &Config) -> Result<Box<dyn Controller>, String> {
    design(kind, cfg)?
        .controller(kind.into())
        .map_err(|e| format!("{kind} design: {e}"))
}

/// Builds the swing-up supervisor (rip-core's [`SwingUp`]) around the balance controller
/// `kind` ([`build`]), with the `[swing_up]` settings designed on the `[plant]` model. The law's
/// voltage is at most `safety.voltage_limit` (so that its arm-limit envelope plans with the
/// voltage the loop sends) and inside the bounds the compensation leaves; the compensation is
/// applied around the whole supervisor, to the swing-up law's voltage as to the balance
/// controller's. [`Config::validate_swing_up`] checks the settings against the
/// loop's.
pub fn build_swing_up(kind: ControllerKind, cfg: &Config) -> Result<Box<dyn Controller>, String> {
    let mut settings = cfg.spec.swing_up.clone();
    let design = design(kind, cfg)?;
    // The law, like the balance controller, plans within the bounds the compensation leaves.
    settings.max_voltage = settings.max_voltage.min(cfg.safety.voltage_limit);
    if let Some(c) = design.compensation() {
        settings.max_voltage = c.planned_limit(settings.max_voltage);
    }
    let balance = design
        .balance(kind.into())
        .map_err(|e| format!("{kind} design: {e}"))?;
    let plant = cfg.spec.plant().map_err(|e| e.to_string())?;
    SwingUp::new(balance, &plant, settings)
        .map(|s| design.compensate(Box::new(s)))
        .map_err(|e| format!("swing-up around {kind}: {e}"))
}
