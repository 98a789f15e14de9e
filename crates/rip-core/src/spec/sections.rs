//! The sections of the experiment file, each with its defaults (declared once, in its
//! `Default`) and its value checks (in its `validate`, which names the key path); the
//! controller sections (`[lqr]`, `[kalman]`, `[mpc]`) are in `controllers.rs`.

use std::f64::consts::PI;

use serde::{Deserialize, Serialize};

use super::SpecError;
use crate::paper;
use crate::plant::{FurutaParams, Param};
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

/// `[plant]`: the simulated (or emulated) nonlinear plant, and through it the design model.
///
/// `preset` names a parameter set; each [`Param::ALL`] key given (`mr, Lr, Jr, mp, Lp, Jp,
/// Dr, Dp, Rm, kt, km, Cr, Cp, Vd, Kc`) overrides the preset's value, so an identified rig is a
/// file of its own. `Cr`, `Cp` (Coulomb friction) and `Vd` (dead zone) are 0 in both presets;
/// they act on the simulated plant but not on the design model ([`crate::plant`] explains
/// why). `Kc` (the cable's stiffness, 0 in both presets) is smooth and enters both. The controllers are designed on this plant's linearisation about upright, discretised
/// at the loop period; the `paper` preset without changed parameters keeps the paper's
/// recovered model ([`paper::continuous_model`]) so that the paper's numbers do not move.
///
/// The parameter keys are not fields: they are [`Param`]'s names, read and written by this
/// type's own serde implementation, so the names exist once.
#[derive(Debug, Clone, PartialEq)]
pub struct PlantSpec {
    /// The parameter set the overrides start from.
    pub preset: Preset,
    /// The parameters given, indexed by [`Param::index`] (never [`Param::G`]).
    pub overrides: [Option<f64>; Param::COUNT],
    /// The arm's breakaway torque (N·m, at least `Cr`): stiction of the simulated plant
    /// ([`crate::plant::Plant::with_arm_breakaway`]); none when absent. Not a parameter the
    /// controllers or the compensation know.
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
            overrides: [None; Param::COUNT],
            arm_breakaway: None,
            substeps: DEFAULT_SUBSTEPS,
            initial_state: [0.0, 0.0, 0.05, 0.0],
            fall_limit: DEFAULT_FALL_LIMIT,
        }
    }
}

/// The `[plant]` keys that are not parameters.
const PLANT_FIELDS: [&str; 5] = [
    "preset",
    "arm_breakaway",
    "substeps",
    "initial_state",
    "fall_limit",
];

impl Serialize for PlantSpec {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(None)?;
        map.serialize_entry("preset", &self.preset)?;
        for p in Param::ALL {
            if let Some(v) = self.get(p) {
                map.serialize_entry(p.name(), &v)?;
            }
        }
        if let Some(v) = self.arm_breakaway {
            map.serialize_entry("arm_breakaway", &v)?;
        }
        map.serialize_entry("substeps", &self.substeps)?;
        map.serialize_entry("initial_state", &self.initial_state)?;
        map.serialize_entry("fall_limit", &self.fall_limit)?;
        map.end()
    }
}

impl<'de> Deserialize<'de> for PlantSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = PlantSpec;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("the [plant] table")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<PlantSpec, A::Error> {
                use serde::de::Error;
                let mut out = PlantSpec::default();
                let mut seen: Vec<String> = Vec::new();
                while let Some(key) = map.next_key::<String>()? {
                    if seen.contains(&key) {
                        return Err(A::Error::custom(format!("duplicate field `{key}`")));
                    }
                    match key.as_str() {
                        "preset" => out.preset = map.next_value()?,
                        "arm_breakaway" => out.arm_breakaway = Some(map.next_value()?),
                        "substeps" => out.substeps = map.next_value()?,
                        "initial_state" => out.initial_state = map.next_value()?,
                        "fall_limit" => out.fall_limit = map.next_value()?,
                        name => match Param::from_name(name) {
                            Some(p) => out.overrides[p.index()] = Some(map.next_value()?),
                            None => {
                                let expected: Vec<String> = PLANT_FIELDS[..1]
                                    .iter()
                                    .copied()
                                    .chain(Param::ALL.map(Param::name))
                                    .chain(PLANT_FIELDS[1..].iter().copied())
                                    .map(|n| format!("`{n}`"))
                                    .collect();
                                return Err(A::Error::custom(format!(
                                    "unknown field `{name}`, expected one of {}",
                                    expected.join(", ")
                                )));
                            }
                        },
                    }
                    seen.push(key);
                }
                Ok(out)
            }
        }
        d.deserialize_map(Visitor)
    }
}

impl PlantSpec {
    /// The `preset` with every `[plant]` parameter given as in `params` (its `g` is the
    /// preset's).
    pub fn with_params(preset: Preset, params: &FurutaParams) -> Self {
        let mut out = Self {
            preset,
            ..Self::default()
        };
        for param in Param::ALL {
            out.set(param, Some(params.get(param)));
        }
        out
    }

    /// The value given for `param`, if any.
    pub fn get(&self, param: Param) -> Option<f64> {
        self.overrides[param.index()]
    }

    /// Gives `param` the value `value` (`None`: the preset's).
    ///
    /// # Panics
    /// On [`Param::G`], which is not a `[plant]` key.
    pub fn set(&mut self, param: Param, value: Option<f64>) {
        assert!(param != Param::G, "g is not a [plant] key");
        self.overrides[param.index()] = value;
    }

    /// The preset's parameters with the given ones in their place.
    pub fn params(&self) -> FurutaParams {
        let mut p = self.preset.params();
        for param in Param::ALL {
            if let Some(v) = self.get(param) {
                p.set(param, v);
            }
        }
        p
    }

    /// Every parameter written out (the preset's value where none was given).
    pub fn resolved(&self) -> Self {
        let mut out = self.clone();
        let p = self.params();
        for param in Param::ALL {
            out.overrides[param.index()] = Some(p.get(param));
        }
        out
    }

    /// Whether the design model is the paper's recovered one: the `paper` preset with every
    /// parameter at the preset's value.
    pub fn is_paper_model(&self) -> bool {
        self.preset == Preset::Paper && self.params() == FurutaParams::paper()
    }

    fn validate(&self) -> Result<(), SpecError> {
        for param in Param::ALL {
            if let Some(v) = self.get(param) {
                param
                    .check(v)
                    .map_err(|reason| bad(format!("plant.{param}"), reason))?;
            }
        }
        if let Some(cs) = self.arm_breakaway {
            let cr = self.params().cr;
            if !(cs.is_finite() && cs >= cr) {
                return Err(bad(
                    "plant.arm_breakaway",
                    format!("must be finite and at least plant.Cr = {cr}, got {cs}"),
                ));
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
            // A file that writes only the fall limit is refused through it, not through the
            // start state it left at its default.
            if self.initial_state == Self::default().initial_state {
                return Err(bad(
                    "plant.fall_limit",
                    format!(
                        "must be at least |plant.initial_state[2]| ({} rad, its default: a                          simulated run starts there), got {}",
                        self.initial_state[2].abs(),
                        self.fall_limit
                    ),
                ));
            }
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

pub use crate::sim::COUNTS_PER_REV;

/// `[sensor]`: the encoders and white measurement noise of the rig, simulated (`riprs
/// compare`, `rip-rt emulate`) or real (`rip-rt` turns counts into angles with
/// `encoder_counts`).
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
    /// Each measured angle's noise variance (rad²): `σ² + δ²/12`, the white noise and the
    /// quantisation of one encoder count `δ = 2π / counts`.
    pub fn angle_variance(&self) -> [f64; 2] {
        std::array::from_fn(|i| {
            let count = 2.0 * PI / f64::from(self.encoder_counts[i]);
            self.noise_std[i].powi(2) + count * count / 12.0
        })
    }

    fn validate(&self) -> Result<(), SpecError> {
        for (i, &c) in self.encoder_counts.iter().enumerate() {
            if !COUNTS_PER_REV.contains(&c) {
                return Err(bad(
                    format!("sensor.encoder_counts[{i}]"),
                    format!(
                        "must be in {}..={} counts per revolution, got {c}",
                        COUNTS_PER_REV.start(),
                        COUNTS_PER_REV.end()
                    ),
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
    super::controllers::validate_mpc(&spec.mpc)?;
    spec.compensation.validate()?;
    spec.monte_carlo.validate()?;
    spec.swing_up.validate().map_err(|e| match e {
        // The key is already `swing_up.<key>`.
        crate::error::RipError::InvalidParameter { name, reason } => bad(name, reason),
        other => bad("swing_up", other.to_string()),
    })
}
