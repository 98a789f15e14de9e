//! The sections of the experiment file, each with its defaults (declared once, in its
//! `Default`) and its value checks (in its `validate`, which names the key path); the
//! controller sections (`[lqr]`, `[kalman]`, `[mpc]`) are in `controllers.rs`.

use std::f64::consts::PI;

use serde::{Deserialize, Serialize};

use super::SpecError;
use crate::paper;
use crate::plant::FurutaParams;
use crate::sim::{DEFAULT_DURATION, DEFAULT_FALL_LIMIT, DEFAULT_SUBSTEPS, MAX_SUBSTEPS};

/// Longest simulated run (s): an hour of the paper's 100 Hz loop.
pub const MAX_DURATION: f64 = 3600.0;

/// Most Monte Carlo runs one file may ask for.
pub const MAX_MONTE_CARLO_RUNS: usize = 1_000_000;

pub(super) fn bad(key: impl Into<String>, reason: impl Into<String>) -> SpecError {
    SpecError::new(key, reason)
}

pub(super) fn positive(key: &str, v: f64) -> Result<(), SpecError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(bad(key, format!("must be positive and finite, got {v}")))
    }
}

pub(super) fn non_negative(key: &str, v: f64) -> Result<(), SpecError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(bad(
            key,
            format!("must be non-negative and finite, got {v}"),
        ))
    }
}

pub(super) fn each(
    key: &str,
    values: &[f64],
    check: fn(&str, f64) -> Result<(), SpecError>,
) -> Result<(), SpecError> {
    for (i, &v) in values.iter().enumerate() {
        check(&format!("{key}[{i}]"), v)?;
    }
    Ok(())
}

/// A controller `riprs compare` runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ControllerKind {
    /// LQR on measured angles, rates by filtered difference.
    #[serde(rename = "LQR")]
    Lqr,
    /// The LQR gain on the shared Kalman filter's estimate.
    #[serde(rename = "LQG")]
    Lqg,
    /// The constrained MPC with the shared Kalman filter.
    #[serde(rename = "MPC")]
    Mpc,
}

impl ControllerKind {
    /// All three, in the paper's order.
    pub const ALL: [ControllerKind; 3] = [Self::Lqr, Self::Lqg, Self::Mpc];

    /// The name used in files and tables (`"LQR"`, `"LQG"`, `"MPC"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Lqr => "LQR",
            Self::Lqg => "LQG",
            Self::Mpc => "MPC",
        }
    }

    /// Parses a name, case-insensitively.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(name))
    }
}

/// A named physical parameter set of [`FurutaParams`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    /// Fitted to the paper's printed model ([`FurutaParams::paper`]); the controllers are
    /// designed on the paper's recovered linear model ([`paper::continuous_model`]).
    #[default]
    Paper,
    /// Quanser QUBE-Servo 2 published parameters ([`FurutaParams::qube_servo2`]).
    QubeServo2,
}

impl Preset {
    /// Every preset, as spelled in files.
    pub const ALL: [Preset; 2] = [Self::Paper, Self::QubeServo2];

    /// The preset's parameters.
    pub fn params(self) -> FurutaParams {
        match self {
            Self::Paper => FurutaParams::paper(),
            Self::QubeServo2 => FurutaParams::qube_servo2(),
        }
    }

    /// The name as spelled in files (`"paper"`, `"qube_servo2"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::QubeServo2 => "qube_servo2",
        }
    }

    /// Parses a name as spelled in files.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// A physical parameter that `[plant]` can override and `[monte_carlo]` can perturb, named
/// as in [`FurutaParams`]' Python API.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Param {
    /// Arm mass (kg).
    #[serde(rename = "mr")]
    Mr,
    /// Arm length (m).
    #[serde(rename = "Lr")]
    Lr,
    /// Arm inertia about its centre of mass (kg·m²).
    #[serde(rename = "Jr")]
    Jr,
    /// Pendulum mass (kg).
    #[serde(rename = "mp")]
    Mp,
    /// Pendulum length (m).
    #[serde(rename = "Lp")]
    Lp,
    /// Pendulum inertia about its centre of mass (kg·m²).
    #[serde(rename = "Jp")]
    Jp,
    /// Arm viscous friction (N·m·s/rad).
    #[serde(rename = "Dr")]
    Dr,
    /// Pendulum viscous friction (N·m·s/rad).
    #[serde(rename = "Dp")]
    Dp,
    /// Motor resistance (Ω).
    #[serde(rename = "Rm")]
    Rm,
    /// Motor torque constant (N·m/A).
    #[serde(rename = "kt")]
    Kt,
    /// Motor back-EMF constant (V·s/rad).
    #[serde(rename = "km")]
    Km,
    /// Arm Coulomb friction (N·m).
    #[serde(rename = "Cr")]
    Cr,
    /// Pendulum Coulomb friction (N·m).
    #[serde(rename = "Cp")]
    Cp,
    /// Voltage dead zone of the motor drive (V).
    #[serde(rename = "Vd")]
    Vd,
}

impl Param {
    /// Every parameter, in the order of the `[plant]` section.
    pub const ALL: [Param; 14] = [
        Self::Mr,
        Self::Lr,
        Self::Jr,
        Self::Mp,
        Self::Lp,
        Self::Jp,
        Self::Dr,
        Self::Dp,
        Self::Rm,
        Self::Kt,
        Self::Km,
        Self::Cr,
        Self::Cp,
        Self::Vd,
    ];

    /// The name as spelled in files and in Python.
    pub fn name(self) -> &'static str {
        match self {
            Self::Mr => "mr",
            Self::Lr => "Lr",
            Self::Jr => "Jr",
            Self::Mp => "mp",
            Self::Lp => "Lp",
            Self::Jp => "Jp",
            Self::Dr => "Dr",
            Self::Dp => "Dp",
            Self::Rm => "Rm",
            Self::Kt => "kt",
            Self::Km => "km",
            Self::Cr => "Cr",
            Self::Cp => "Cp",
            Self::Vd => "Vd",
        }
    }

    /// Parses a name as spelled in files and in Python.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The parameter's field of `p`.
    pub fn field(self, p: &mut FurutaParams) -> &mut f64 {
        match self {
            Self::Mr => &mut p.mr,
            Self::Lr => &mut p.lr,
            Self::Jr => &mut p.jr,
            Self::Mp => &mut p.mp,
            Self::Lp => &mut p.lp,
            Self::Jp => &mut p.jp,
            Self::Dr => &mut p.dr,
            Self::Dp => &mut p.dp,
            Self::Rm => &mut p.rm,
            Self::Kt => &mut p.kt,
            Self::Km => &mut p.km,
            Self::Cr => &mut p.cr,
            Self::Cp => &mut p.cp,
            Self::Vd => &mut p.vd,
        }
    }

    /// Whether the parameter may be zero (friction, back-EMF, dead zone); the others must be
    /// positive.
    pub fn may_be_zero(self) -> bool {
        matches!(
            self,
            Self::Km | Self::Dr | Self::Dp | Self::Cr | Self::Cp | Self::Vd
        )
    }
}

/// `[plant]`: the simulated (or emulated) nonlinear plant, and through it the design model.
///
/// `preset` names a parameter set; each of `mr, Lr, Jr, mp, Lp, Jp, Dr, Dp, Rm, kt, km, Cr, Cp,
/// Vd` given overrides the preset's value, so an identified rig is a file of its own. `Cr`,
/// `Cp` (Coulomb friction) and `Vd` (dead zone) are 0 in both presets; they act on the
/// simulated plant but not on the design model ([`crate::plant`] explains why). The controllers
/// are designed on this plant's linearisation about upright, discretised at the loop period;
/// the `paper` preset without changed parameters keeps the paper's recovered model
/// ([`paper::continuous_model`]) so that the paper's numbers do not move.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
#[allow(non_snake_case)]
pub struct PlantSpec {
    /// The parameter set the overrides start from.
    pub preset: Preset,
    /// Arm mass (kg).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mr: Option<f64>,
    /// Arm length, motor axis to pendulum joint (m).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Lr: Option<f64>,
    /// Arm inertia about its centre of mass (kg·m²).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Jr: Option<f64>,
    /// Pendulum mass (kg).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mp: Option<f64>,
    /// Pendulum length (m).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Lp: Option<f64>,
    /// Pendulum inertia about its centre of mass (kg·m²).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Jp: Option<f64>,
    /// Arm viscous friction (N·m·s/rad).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Dr: Option<f64>,
    /// Pendulum viscous friction (N·m·s/rad).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Dp: Option<f64>,
    /// Motor terminal resistance (Ω).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Rm: Option<f64>,
    /// Motor torque constant (N·m/A).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kt: Option<f64>,
    /// Motor back-EMF constant (V·s/rad).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub km: Option<f64>,
    /// Coulomb friction torque of the arm joint (N·m), `cr` of [`crate::plant`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Cr: Option<f64>,
    /// Coulomb friction torque of the pendulum joint (N·m), `cp` of [`crate::plant`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Cp: Option<f64>,
    /// Voltage dead zone of the motor drive (V), `vd` of [`crate::plant`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub Vd: Option<f64>,
    /// The arm's breakaway torque (N·m, at least `Cr`): stiction of the simulated plant
    /// ([`crate::plant::Plant::with_arm_breakaway`]); none when absent. Not a parameter the
    /// controllers or the compensation know.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arm_breakaway: Option<f64>,
    /// RK4 steps per control period in simulation.
    pub substeps: usize,
    /// Initial state `[θ, θ̇, α, α̇]` of a simulated run (rad, rad/s; α = 0 upright).
    pub initial_state: [f64; 4],
    /// A simulated run stops as a fall when `|α|` exceeds this (rad).
    pub fall_limit: f64,
}

impl Default for PlantSpec {
    fn default() -> Self {
        Self {
            preset: Preset::Paper,
            mr: None,
            Lr: None,
            Jr: None,
            mp: None,
            Lp: None,
            Jp: None,
            Dr: None,
            Dp: None,
            Rm: None,
            kt: None,
            km: None,
            Cr: None,
            Cp: None,
            Vd: None,
            arm_breakaway: None,
            substeps: DEFAULT_SUBSTEPS,
            initial_state: [0.0, 0.0, 0.05, 0.0],
            fall_limit: DEFAULT_FALL_LIMIT,
        }
    }
}

impl PlantSpec {
    fn overrides(&self) -> [Option<f64>; 14] {
        [
            self.mr, self.Lr, self.Jr, self.mp, self.Lp, self.Jp, self.Dr, self.Dp, self.Rm,
            self.kt, self.km, self.Cr, self.Cp, self.Vd,
        ]
    }

    fn overrides_mut(&mut self) -> [&mut Option<f64>; 14] {
        [
            &mut self.mr,
            &mut self.Lr,
            &mut self.Jr,
            &mut self.mp,
            &mut self.Lp,
            &mut self.Jp,
            &mut self.Dr,
            &mut self.Dp,
            &mut self.Rm,
            &mut self.kt,
            &mut self.km,
            &mut self.Cr,
            &mut self.Cp,
            &mut self.Vd,
        ]
    }

    /// The preset's parameters with the given ones in their place.
    pub fn params(&self) -> FurutaParams {
        let mut p = self.preset.params();
        for (param, value) in Param::ALL.into_iter().zip(self.overrides()) {
            if let Some(v) = value {
                *param.field(&mut p) = v;
            }
        }
        p
    }

    /// Every parameter written out (the preset's value where none was given).
    pub fn resolved(&self) -> Self {
        let mut out = self.clone();
        let mut p = self.params();
        for (param, slot) in Param::ALL.into_iter().zip(out.overrides_mut()) {
            *slot = Some(*param.field(&mut p));
        }
        out
    }

    /// Whether the design model is the paper's recovered one: the `paper` preset with every
    /// parameter at the preset's value.
    pub fn is_paper_model(&self) -> bool {
        self.preset == Preset::Paper && self.params() == FurutaParams::paper()
    }

    fn validate(&self) -> Result<(), SpecError> {
        if let Some(cs) = self.arm_breakaway {
            let cr = self.params().cr;
            if !(cs.is_finite() && cs >= cr) {
                return Err(bad(
                    "plant.arm_breakaway",
                    format!("must be finite and at least plant.Cr = {cr}, got {cs}"),
                ));
            }
        }
        for (param, value) in Param::ALL.into_iter().zip(self.overrides()) {
            if let Some(v) = value {
                let key = format!("plant.{}", param.name());
                if param.may_be_zero() {
                    non_negative(&key, v)?;
                } else {
                    positive(&key, v)?;
                }
            }
        }
        if self.substeps == 0 || self.substeps > MAX_SUBSTEPS {
            return Err(bad(
                "plant.substeps",
                format!("must be in 1..={MAX_SUBSTEPS}, got {}", self.substeps),
            ));
        }
        positive("plant.fall_limit", self.fall_limit)?;
        for (i, &v) in self.initial_state.iter().enumerate() {
            if !v.is_finite() {
                return Err(bad(
                    format!("plant.initial_state[{i}]"),
                    format!("must be finite, got {v}"),
                ));
            }
        }
        if self.initial_state[2].abs() > self.fall_limit {
            return Err(bad(
                "plant.initial_state[2]",
                format!(
                    "the pendulum angle {} is already beyond plant.fall_limit ({})",
                    self.initial_state[2], self.fall_limit
                ),
            ));
        }
        Ok(())
    }
}

/// `[sensor]`: encoders and white measurement noise of a simulated run.
///
/// The defaults model a 2048-count quadrature encoder on each joint (the QUBE-Servo 2's) and
/// 1 mrad of white noise, about a third of one count: the paper does not state its sensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorSpec {
    /// Counts per revolution of the arm and pendulum encoders.
    pub encoder_counts: [u32; 2],
    /// Standard deviation of the noise on the arm and pendulum angles (rad).
    pub noise_std: [f64; 2],
    /// Where each encoder's zero lies (rad): an encoder reads `angle + offset`, so a simulated
    /// run measures `[θ + o₀, α + o₁]` and the emulator's counters count from it. 0 is a
    /// calibrated sensor; on a rig the calibration (pendulum hanging at rest) removes it.
    pub encoder_offsets: [f64; 2],
}

impl Default for SensorSpec {
    fn default() -> Self {
        Self {
            encoder_counts: [2048, 2048],
            noise_std: [1e-3, 1e-3],
            encoder_offsets: [0.0, 0.0],
        }
    }
}

impl SensorSpec {
    fn validate(&self) -> Result<(), SpecError> {
        for (i, &c) in self.encoder_counts.iter().enumerate() {
            if c == 0 {
                return Err(bad(
                    format!("sensor.encoder_counts[{i}]"),
                    "must be at least 1 count per revolution, got 0",
                ));
            }
        }
        // Noise beyond a full turn is no sensor; the bound also keeps every sum finite.
        for (i, &s) in self.noise_std.iter().enumerate() {
            let key = format!("sensor.noise_std[{i}]");
            non_negative(&key, s)?;
            if s > PI {
                return Err(bad(key, format!("must be at most π rad, got {s}")));
            }
        }
        for (i, &o) in self.encoder_offsets.iter().enumerate() {
            if !(o.is_finite() && o.abs() <= PI) {
                return Err(bad(
                    format!("sensor.encoder_offsets[{i}]"),
                    format!("must be within [-π, π] rad, got {o}"),
                ));
            }
        }
        Ok(())
    }
}

/// `[reference]`: the arm-angle step of the paper's experiment (section 7).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReferenceSpec {
    /// Step height (rad).
    pub arm_step: f64,
    /// Time of the step (s).
    pub step_time: f64,
    /// Length of a simulated run (s).
    pub duration: f64,
}

impl Default for ReferenceSpec {
    fn default() -> Self {
        Self {
            arm_step: 1.0,
            step_time: 1.0,
            duration: DEFAULT_DURATION,
        }
    }
}

impl ReferenceSpec {
    fn validate(&self) -> Result<(), SpecError> {
        if !(self.arm_step.is_finite() && self.arm_step.abs() <= PI) {
            return Err(bad(
                "reference.arm_step",
                format!("must be within [-π, π] rad, got {}", self.arm_step),
            ));
        }
        non_negative("reference.step_time", self.step_time)?;
        if !(self.duration.is_finite() && (paper::TS..=MAX_DURATION).contains(&self.duration)) {
            return Err(bad(
                "reference.duration",
                format!(
                    "must be between one sample ({} s) and {MAX_DURATION} s, got {}",
                    paper::TS,
                    self.duration
                ),
            ));
        }
        Ok(())
    }
}

/// `[monte_carlo]`: runs over noise seeds and plant-parameter perturbations.
///
/// Run `i` uses noise seed `seed + 1 + i` and multiplies each parameter named in `parameters`
/// by an independent factor drawn uniformly from `[1 − perturbation, 1 + perturbation]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MonteCarloSpec {
    /// Number of runs per controller (0 for none).
    pub runs: usize,
    /// Relative half-width of the uniform perturbation, in `[0, 1)`.
    pub perturbation: f64,
    /// The perturbed parameters.
    pub parameters: Vec<Param>,
}

impl Default for MonteCarloSpec {
    fn default() -> Self {
        Self {
            runs: 0,
            perturbation: 0.1,
            parameters: Param::ALL.to_vec(),
        }
    }
}

impl MonteCarloSpec {
    fn validate(&self) -> Result<(), SpecError> {
        if self.runs > MAX_MONTE_CARLO_RUNS {
            return Err(bad(
                "monte_carlo.runs",
                format!("must be in 0..={MAX_MONTE_CARLO_RUNS}, got {}", self.runs),
            ));
        }
        non_negative("monte_carlo.perturbation", self.perturbation)?;
        if self.perturbation >= 1.0 {
            return Err(bad(
                "monte_carlo.perturbation",
                format!("must be below 1, got {}", self.perturbation),
            ));
        }
        Ok(())
    }
}

pub(super) fn validate_sections(spec: &super::Spec) -> Result<(), SpecError> {
    if spec.controllers.is_empty() {
        return Err(bad(
            "controllers",
            "must name at least one of LQR, LQG, MPC",
        ));
    }
    for (i, c) in spec.controllers.iter().enumerate() {
        if spec.controllers[..i].contains(c) {
            return Err(bad(
                format!("controllers[{i}]"),
                format!("{} is listed twice", c.name()),
            ));
        }
    }
    spec.plant.validate()?;
    spec.sensor.validate()?;
    spec.reference.validate()?;
    spec.lqr.validate()?;
    spec.kalman.validate()?;
    spec.mpc.validate()?;
    spec.compensation.validate()?;
    spec.monte_carlo.validate()?;
    spec.swing_up.validate().map_err(|e| match e {
        // The key is already `swing_up.<key>`.
        crate::error::RipError::InvalidParameter { name, reason } => bad(name, reason),
        other => bad("swing_up", other.to_string()),
    })
}
