//! The bar a tuned controller is held to on one rig ([`Bar`]), the sensor's floor it starts
//! from ([`Bar::for_rig`]) and the rigs with the compensation 30 % off ([`off_compensation`]).
//!
//! **Balance.** Over the last [`Bar::window`] seconds of the `[reference]` run:
//!
//! ```text
//! arm peak-to-peak ≤ max(0.05 rad, 2 · floor),   |α| ≤ 0.02 rad,   |mean θ − θ_ref| ≤ 0.02 rad
//! ```
//!
//! where the *floor* is the arm peak-to-peak of the file's own LQR (its weights before any
//! tuning) on the same rig with no dead zone, no Coulomb friction and no stiction, read by
//! the same encoders with the same noise: what the sensor alone costs that rig. It is
//! measured before the search, on the file's weights, so that no candidate can raise its own
//! bar by being noisier.
//!
//! **Margins** at the plant input (crate::margins): LQR's classical ones, at least
//! [`Bar::gain_margin_db`] up and down and [`Bar::phase_margin_deg`]; LQG's and the MPC's
//! balanced disk margin at least [`Bar::disk_margin`] (0.5, about 4.4 dB and 28°).
//!
//! **Compensation off** by [`OFF_COMPENSATION`] either way (the dead zone and the arm's
//! Coulomb friction the compensation assumes, 0.7 and 1.3 times the plant's: an
//! identification that far off; the file's `compensation.dead_zone_gain` and
//! `friction_gain` still multiply them, as they multiply what a rig's identification found,
//! [`super::gains`]), with the arm's
//! stiction on ([`STICTION_RATIO`] times its Coulomb level where the file gives no breakaway
//! torque): no fall, and an arm peak-to-peak of at most [`Bar::off_peak_to_peak`]
//! ([`Bar::off_peak_to_peak_mpc`] for the MPC) — never below the rig's own balance bar, which
//! the exact compensation is held to.

use crate::margins::Margins;
use crate::plant::Param;
use crate::sim::simulate;
use crate::spec::{ControllerKind, Spec, SpecError};

use super::{steady_state, SEEDS};

/// The relative error of the compensation the bar is met with: the dead zone and the arm's
/// Coulomb friction assumed `1 ± 0.3` times the plant's.
pub const OFF_COMPENSATION: f64 = 0.3;

/// The arm's breakaway torque relative to its Coulomb friction in the off-compensation runs,
/// where the file gives none: stiction the compensation does not know.
pub const STICTION_RATIO: f64 = 2.0;

/// The arm peak-to-peak every rig may reach whatever its sensor (rad).
pub const BASE_PEAK_TO_PEAK: f64 = 0.05;

/// The share of each steady-state figure of the bar the tuning accepts on its own noise seeds
/// ([`Bar::guarded`]). A steady state is the worst of a few seconds of noise: with 90 %, the
/// worst of four seeds was exceeded on one of two others by up to 17 % (generated rigs 3 and
/// 13, the QUBE-like rig with a dead zone: `tests/tune_rigs.rs` checks unseen seeds).
pub const GUARD: f64 = 0.8;

/// What "works" means on one rig (module docs). `Default` is the bar of a rig whose sensor
/// costs nothing ([`BASE_PEAK_TO_PEAK`]); [`Bar::for_rig`] raises the arm's to the rig's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bar {
    /// Largest steady-state arm peak-to-peak (rad): `max(0.05, 2 · floor)`.
    pub arm_peak_to_peak: f64,
    /// The sensor's floor it was raised from (rad), when measured ([`Bar::for_rig`]);
    /// infinite when the file's own LQR falls on the rig without dead zone and friction.
    pub floor: Option<f64>,
    /// Largest steady-state `|α|` (rad).
    pub pendulum: f64,
    /// Largest steady-state arm offset from the reference (rad).
    pub offset: f64,
    /// The steady-state window at the end of the run (s).
    pub window: f64,
    /// LQR's smallest gain margin, both ways (dB).
    pub gain_margin_db: f64,
    /// LQR's smallest phase margin (degrees).
    pub phase_margin_deg: f64,
    /// LQG's and the MPC's smallest balanced disk margin `α` (the disk's gain margin
    /// `(2 + α)/(2 − α)`, its phase margin `2 atan(α/2)`).
    pub disk_margin: f64,
    /// Largest arm peak-to-peak of LQR and LQG with the compensation off (rad).
    pub off_peak_to_peak: f64,
    /// Largest arm peak-to-peak of the MPC with the compensation off (rad).
    pub off_peak_to_peak_mpc: f64,
}

impl Default for Bar {
    fn default() -> Self {
        Self {
            arm_peak_to_peak: BASE_PEAK_TO_PEAK,
            floor: None,
            pendulum: 0.02,
            offset: 0.02,
            window: 3.0,
            gain_margin_db: 6.0,
            phase_margin_deg: 30.0,
            disk_margin: 0.5,
            off_peak_to_peak: 0.1,
            off_peak_to_peak_mpc: 0.05,
        }
    }
}

impl Bar {
    /// The default bar with the arm's raised to `max(0.05, 2 · floor)` for the rig of
    /// `spec` at sample time `ts` (module docs). A file whose own LQR falls on the rig without
    /// dead zone and friction leaves the floor unknown (infinite) and the bar at 0.05 rad.
    pub fn for_rig(spec: &Spec, ts: f64) -> Result<Self, SpecError> {
        let floor = sensor_floor(spec, ts)?;
        let base = Self::default();
        let arm = if floor.is_finite() {
            base.arm_peak_to_peak.max(2.0 * floor)
        } else {
            base.arm_peak_to_peak
        };
        Ok(Self {
            arm_peak_to_peak: arm,
            floor: Some(floor),
            ..base
        })
    }

    /// Whether `m`, the margins of `kind`'s loop, meet the bar (module docs).
    pub fn margins_ok(&self, kind: ControllerKind, m: &Margins) -> bool {
        match kind {
            ControllerKind::Lqr => m.meets(self.gain_margin_db, self.phase_margin_deg),
            ControllerKind::Lqg | ControllerKind::Mpc => {
                m.stable && m.disk_margin >= self.disk_margin
            }
        }
    }

    /// How far `m` is from the margins of the bar: 0 when [`margins_ok`](Self::margins_ok),
    /// else the disk margin's relative shortfall from the disk of the same gain margin
    /// (2 for an unstable loop).
    pub fn margin_shortfall(&self, kind: ControllerKind, m: &Margins) -> f64 {
        if self.margins_ok(kind, m) {
            return 0.0;
        }
        if !m.stable {
            return 2.0;
        }
        let disk = match kind {
            // The disk whose gain margin is LQR's classical bar: (2 + α)/(2 − α) = 10^{gm/20}.
            ControllerKind::Lqr => {
                let f = 10f64.powf(self.gain_margin_db / 20.0);
                2.0 * (f - 1.0) / (f + 1.0)
            }
            ControllerKind::Lqg | ControllerKind::Mpc => self.disk_margin,
        };
        (1.0 - m.disk_margin / disk).max(0.0).max(1e-3)
    }

    /// The bar the tuning holds its simulations to: every steady-state figure [`GUARD`] times
    /// this bar's, the margins as they are, so that what it keeps meets this bar on noise it
    /// did not simulate.
    pub fn guarded(&self) -> Self {
        Self {
            arm_peak_to_peak: GUARD * self.arm_peak_to_peak,
            pendulum: GUARD * self.pendulum,
            offset: GUARD * self.offset,
            off_peak_to_peak: GUARD * self.off_peak_to_peak,
            off_peak_to_peak_mpc: GUARD * self.off_peak_to_peak_mpc,
            ..*self
        }
    }

    /// The largest arm peak-to-peak `kind` may reach with the compensation off (module docs).
    pub fn off_limit(&self, kind: ControllerKind) -> f64 {
        let limit = match kind {
            ControllerKind::Mpc => self.off_peak_to_peak_mpc,
            ControllerKind::Lqr | ControllerKind::Lqg => self.off_peak_to_peak,
        };
        limit.max(self.arm_peak_to_peak)
    }
}

/// The rig of `spec` with no dead zone, no Coulomb friction and no stiction, uncompensated:
/// the rig whose steady state is its sensor's alone.
pub fn frictionless(spec: &Spec) -> Spec {
    let mut s = spec.clone();
    for param in [Param::Vd, Param::Cr, Param::Cp] {
        s.plant.set(param, Some(0.0));
    }
    s.plant.arm_breakaway = None;
    s.compensation.enabled = false;
    s
}

/// The sensor's floor of `spec`'s rig (module docs): the worst arm peak-to-peak over
/// [`SEEDS`] of the file's own LQR on [`frictionless`]; infinite when a run falls.
pub fn sensor_floor(spec: &Spec, ts: f64) -> Result<f64, SpecError> {
    let rig = frictionless(spec);
    let design = rig.design(ts)?;
    let plant = rig.plant()?;
    let mut controller = design.controller(ControllerKind::Lqr)?;
    let mut worst = 0.0f64;
    for seed in SEEDS {
        let run = simulate(&plant, controller.as_mut(), &rig.sim_config(ts, seed))
            .map_err(|e| SpecError::new("plant", format!("simulation: {e}")))?;
        if run.fell || run.diverged {
            return Ok(f64::INFINITY);
        }
        worst = worst.max(steady_state(&run, 3.0).0);
    }
    Ok(worst)
}

/// `spec` with its compensation assuming `1 + error` times the plant's dead zone and arm
/// Coulomb friction (each times the file's gains) and the arm's stiction on (module docs);
/// `None` when the file compensates nothing
/// (compensation disabled, or a rig with neither), where the error has nothing to act on.
pub fn off_compensation(spec: &Spec, error: f64) -> Option<Spec> {
    let p = spec.plant.params();
    if !spec.compensation.enabled || (p.vd == 0.0 && p.cr == 0.0) {
        return None;
    }
    let mut s = spec.clone();
    s.compensation.dead_zone = Some((1.0 + error) * p.vd);
    s.compensation.arm_friction = Some((1.0 + error) * p.cr);
    if s.plant.arm_breakaway.is_none() && p.cr > 0.0 {
        s.plant.arm_breakaway = Some(STICTION_RATIO * p.cr);
    }
    Some(s)
}
