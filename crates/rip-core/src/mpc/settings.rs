//! MPC settings: the user-facing [`MpcSettings`], their builder and validation, and the
//! resolution of empty vectors to MATLAB's defaults against the plant's sizes.

use serde::{Deserialize, Serialize};

use crate::error::{KeyError, Result, RipError};
use crate::linalg::{check_finite, check_shape, check_square, Mat};

use super::QpSolver;

/// Largest accepted prediction horizon `P`: 100 s at the paper's 100 Hz, far beyond any useful
/// horizon, while keeping the memory of the condensed problem bounded.
pub const MAX_PREDICTION_HORIZON: usize = 10_000;

/// Largest accepted QP iteration limit: Clarabel converges in tens of iterations and the
/// active-set method in at most a few hundred working-set changes on these problems; the bound
/// keeps one step, which runs without the GIL and cannot be interrupted, short.
pub const MAX_QP_ITERATIONS: usize = 10_000;

/// Largest accepted number of entries (`f64`) in one condensed matrix (80 MB), estimated as
/// `(P·(ny + nu) + 2·m·nu + 1) · (m·nu + 1 + nx + nu)`: the prediction, constraint and
/// linear-term matrices all fit in that many rows and columns.
pub const MAX_CONDENSED_ENTRIES: usize = 10_000_000;

/// Output-disturbance model `x_od⁺ = A_od x_od + B_od w_od`, `y_od = C_od x_od` (eq. (1)),
/// added to the scaled outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputDisturbance {
    /// `A_od` (`nd × nd`): the disturbance states' dynamics (`1` for integrated white noise).
    pub a: Mat,
    /// `B_od` (`nd × nw`): how the unit-variance white noise `w_od` drives the disturbance
    /// states.
    pub b: Mat,
    /// `C_od` (`ny × nd`): how the disturbance states add to the scaled outputs.
    pub c: Mat,
}

impl OutputDisturbance {
    /// One integrated white noise (`A_od = 1`, `B_od = gain`) feeding every one of `ny`
    /// outputs (`C_od = 1`): the paper's eq. (1) with `gain = 0.01`, `ny = 2`.
    pub fn integrated_white_noise(ny: usize, gain: f64) -> Self {
        Self {
            a: Mat::identity(1, 1),
            b: Mat::from_element(1, 1, gain),
            c: Mat::from_element(ny, 1, 1.0),
        }
    }
}

/// MPC settings (MATLAB names in brackets), and the schema of the experiment file's `[mpc]`
/// section: the file deserialises into this type, its keys are these fields' names, and
/// [`check`](Self::check) is the one validation (naming the key path as data).
///
/// Two profiles: [`paper`](Self::paper) (section 3's MPC, the default of every key missing
/// from a file's `[mpc]`) and [`Default`] (MATLAB's `mpc` defaults, e.g. `P = 10`, which the
/// Rust builder and Python's `riprs.Mpc(...)` start from). Empty vectors take MATLAB's
/// defaults; otherwise they have one entry per input or output of the plant
/// ([`check_sizes`](Self::check_sizes)).
///
/// The estimator's model (`output_disturbance`, `measurement_noise`) is not part of `[mpc]`:
/// the spec sets it from `[kalman]`, which LQG shares.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default = "MpcSettings::paper")]
pub struct MpcSettings {
    /// Prediction horizon `P`, at most [`MAX_PREDICTION_HORIZON`] \[`PredictionHorizon`\];
    /// MATLAB's default 10.
    pub prediction_horizon: usize,
    /// Control horizon `m ≤ P` (moves `Δu(k..k+m−1)`, then blocked) \[`ControlHorizon`\];
    /// MATLAB's default 2.
    pub control_horizon: usize,
    /// Sample periods per prediction step (no MATLAB equivalent; default 1): the prediction,
    /// its cost and its soft bounds are on a grid of `prediction_step · Ts`, each planned move
    /// held for one grid step, so the horizon spans `P · prediction_step` periods. A 1 kHz
    /// loop keeps the paper's 0.5 s horizon and its QP's size with `P = 50` and
    /// `prediction_step = 10` (the module docs, "Prediction grid"). `P · prediction_step` is
    /// at most [`MAX_PREDICTION_HORIZON`].
    pub prediction_step: usize,
    /// `w^y ≥ 0` per output \[`Weights.OutputVariables`\]; default 1.
    pub output_weights: Vec<f64>,
    /// `w^u ≥ 0` per input \[`Weights.ManipulatedVariables`\]; default 0.
    pub input_weights: Vec<f64>,
    /// `w^Δu ≥ 0` per input \[`Weights.ManipulatedVariablesRate`\]; default 0.1.
    pub input_rate_weights: Vec<f64>,
    /// Input target `u_t` that `w^u` pulls towards (engineering units); default 0.
    pub input_target: Vec<f64>,
    /// Input scale factors `s^u > 0` \[`MV.ScaleFactor`\]; default 1.
    pub input_scales: Vec<f64>,
    /// Output scale factors `s^y > 0` \[`OV.ScaleFactor`\]; default 1.
    pub output_scales: Vec<f64>,
    /// Hard bounds `[u_min, u_max]` per input, `±∞` for none \[`MV.Min/Max`\]; default none.
    pub input_bounds: Vec<(f64, f64)>,
    /// Soft bounds `[y_min, y_max]` per output (engineering units), `±∞` for none
    /// \[`OV.Min/Max`, ECR 1\]; default none. `y_min = y_max` is a soft equality.
    pub output_bounds: Vec<(f64, f64)>,
    /// Slack weight `ρ_ε > 0` on `ε²` \[`Weights.ECR`\]; MATLAB's default 1e5.
    pub ecr_weight: f64,
    /// Output-disturbance model; `None` for none. Set by `[kalman]` in a file.
    #[serde(skip)]
    pub output_disturbance: Option<OutputDisturbance>,
    /// Measurement-noise model `D_n` (ny × nv) on the scaled outputs; `None` for `I`. Set by
    /// `[kalman]` in a file.
    #[serde(skip)]
    pub measurement_noise: Option<Mat>,
    /// QP solver; the active set by default in both profiles ([`QpSolver`] says why).
    pub solver: QpSolver,
    /// Iteration limit of the QP solver, at most [`MAX_QP_ITERATIONS`].
    pub max_iterations: usize,
}

/// MATLAB's default prediction horizon `P`.
pub const DEFAULT_PREDICTION_HORIZON: usize = 10;
/// MATLAB's default control horizon `m`.
pub const DEFAULT_CONTROL_HORIZON: usize = 2;
/// MATLAB's default slack weight `ρ_ε` (`Weights.ECR`).
pub const DEFAULT_ECR_WEIGHT: f64 = 1e5;
/// Default iteration limit of the QP solver.
pub const DEFAULT_MAX_ITERATIONS: usize = 200;

impl Default for MpcSettings {
    /// MATLAB's `mpc` defaults (type docs), with the active-set solver.
    fn default() -> Self {
        Self {
            prediction_horizon: DEFAULT_PREDICTION_HORIZON,
            control_horizon: DEFAULT_CONTROL_HORIZON,
            prediction_step: 1,
            output_weights: Vec::new(),
            input_weights: Vec::new(),
            input_rate_weights: Vec::new(),
            input_target: Vec::new(),
            input_scales: Vec::new(),
            output_scales: Vec::new(),
            input_bounds: Vec::new(),
            output_bounds: Vec::new(),
            ecr_weight: DEFAULT_ECR_WEIGHT,
            output_disturbance: None,
            measurement_noise: None,
            solver: QpSolver::default(),
            max_iterations: DEFAULT_MAX_ITERATIONS,
        }
    }
}

impl MpcSettings {
    /// The MPC of the reproduced study (section 3, [`super::paper`]): `P = 50`, `m = 3`,
    /// `w^y = (25, 50)`, `w^u = 0`, `w^Δu = 1`, `s^u = 10`, `s^y = (1, 1)`, `|u| ≤ 12 V`, the
    /// soft bound `±π/6` on the pendulum angle, `ρ_ε = 100`, and the output disturbance of
    /// eq. (1). Every key missing from a file's `[mpc]` takes its value from here.
    pub fn paper() -> Self {
        use super::paper as p;
        let free = (f64::NEG_INFINITY, f64::INFINITY);
        Self {
            prediction_horizon: p::PREDICTION_HORIZON,
            control_horizon: p::CONTROL_HORIZON,
            prediction_step: 1,
            output_weights: p::OUTPUT_WEIGHTS.to_vec(),
            input_weights: vec![0.0],
            input_rate_weights: vec![p::INPUT_RATE_WEIGHT],
            input_target: vec![0.0],
            input_scales: vec![crate::paper::INPUT_SCALE],
            output_scales: vec![1.0, 1.0],
            input_bounds: vec![(-crate::paper::INPUT_LIMIT, crate::paper::INPUT_LIMIT)],
            output_bounds: vec![free, (-p::OUTPUT_BOUND, p::OUTPUT_BOUND)],
            ecr_weight: p::ECR_WEIGHT,
            output_disturbance: Some(p::output_disturbance()),
            measurement_noise: None,
            solver: QpSolver::default(),
            max_iterations: DEFAULT_MAX_ITERATIONS,
        }
    }

    /// A builder starting from the defaults.
    pub fn builder() -> MpcSettingsBuilder {
        MpcSettingsBuilder {
            settings: Self::default(),
        }
    }

    /// Checks everything that does not depend on the plant's sizes, including
    /// `1 ≤ P ≤` [`MAX_PREDICTION_HORIZON`]; the error names the key path within `[mpc]`.
    /// The bound on the condensed problem's size, which depends on the sizes, is checked by
    /// [`Mpc::new`](super::Mpc::new).
    pub fn check(&self) -> std::result::Result<(), KeyError> {
        let (p, m) = (self.prediction_horizon, self.control_horizon);
        if p == 0 || p > MAX_PREDICTION_HORIZON {
            return Err(KeyError::new(
                "prediction_horizon",
                format!("must be in 1..={MAX_PREDICTION_HORIZON}, got {p}"),
            ));
        }
        if m == 0 || m > p {
            return Err(KeyError::new(
                "control_horizon",
                format!("must be in 1..=prediction_horizon ({p}), got {m}"),
            ));
        }
        let step = self.prediction_step;
        if step == 0 || step.saturating_mul(p) > MAX_PREDICTION_HORIZON {
            return Err(KeyError::new(
                "prediction_step",
                format!(
                    "must be at least 1 with prediction_horizon · prediction_step at most \
                     {MAX_PREDICTION_HORIZON} periods, got {step} with prediction_horizon {p}"
                ),
            ));
        }
        for (key, v) in [
            ("output_weights", &self.output_weights),
            ("input_weights", &self.input_weights),
            ("input_rate_weights", &self.input_rate_weights),
        ] {
            check_all(key, v, |w| w >= 0.0, "must be non-negative")?;
        }
        check_all("input_target", &self.input_target, |_| true, "")?;
        for (key, v) in [
            ("input_scales", &self.input_scales),
            ("output_scales", &self.output_scales),
        ] {
            check_all(key, v, |s| s > 0.0, "must be positive")?;
        }
        check_bounds("input_bounds", &self.input_bounds)?;
        check_bounds("output_bounds", &self.output_bounds)?;
        if !self.ecr_weight.is_finite() {
            return Err(KeyError::non_finite("ecr_weight", self.ecr_weight));
        }
        if self.ecr_weight <= 0.0 {
            return Err(KeyError::new(
                "ecr_weight",
                format!("must be positive, got {}", self.ecr_weight),
            ));
        }
        // The condensed Hessian holds 2·ecr_weight (MATLAB's ECR term ρ_ε ε², differentiated
        // twice): a weight whose double overflows is this key's fault, not the QP's.
        if !(2.0 * self.ecr_weight).is_finite() {
            return Err(KeyError::new(
                "ecr_weight",
                format!(
                    "must be at most {:e}, half the largest double (the QP's Hessian holds \
                     twice it), got {:e}",
                    f64::MAX / 2.0,
                    self.ecr_weight
                ),
            ));
        }
        if self.max_iterations == 0 || self.max_iterations > MAX_QP_ITERATIONS {
            return Err(KeyError::new(
                "max_iterations",
                format!(
                    "must be in 1..={MAX_QP_ITERATIONS}, got {}",
                    self.max_iterations
                ),
            ));
        }
        Ok(())
    }

    /// Checks that every non-empty vector has one entry per input (`nu`) or output (`ny`).
    pub fn check_sizes(&self, nu: usize, ny: usize) -> std::result::Result<(), KeyError> {
        let sizes = [
            ("output_weights", self.output_weights.len(), ny),
            ("input_weights", self.input_weights.len(), nu),
            ("input_rate_weights", self.input_rate_weights.len(), nu),
            ("input_target", self.input_target.len(), nu),
            ("input_scales", self.input_scales.len(), nu),
            ("output_scales", self.output_scales.len(), ny),
            ("input_bounds", self.input_bounds.len(), nu),
            ("output_bounds", self.output_bounds.len(), ny),
        ];
        for (key, len, n) in sizes {
            if len != 0 && len != n {
                let what = if n == nu { "input" } else { "output" };
                return Err(KeyError::new(
                    key,
                    format!("must have one entry per {what} ({n}), got {len}"),
                ));
            }
        }
        Ok(())
    }

    /// [`check`](Self::check), and the models' shapes, as a [`RipError`].
    pub fn validate(&self) -> Result<()> {
        self.check()?;
        if let Some(od) = &self.output_disturbance {
            let nd = check_square("A_od", &od.a)?;
            check_shape("B_od", &od.b, nd, od.b.ncols())?;
            check_shape("C_od", &od.c, od.c.nrows(), nd)?;
            check_finite("A_od", &od.a)?;
            check_finite("B_od", &od.b)?;
            check_finite("C_od", &od.c)?;
        }
        if let Some(dn) = &self.measurement_noise {
            check_finite("measurement_noise", dn)?;
        }
        Ok(())
    }
}

fn check_all(
    key: &str,
    v: &[f64],
    ok: impl Fn(f64) -> bool,
    what: &str,
) -> std::result::Result<(), KeyError> {
    for (i, &x) in v.iter().enumerate() {
        if !x.is_finite() {
            return Err(KeyError::non_finite(format!("{key}[{i}]"), x));
        }
        if !ok(x) {
            return Err(KeyError::new(
                format!("{key}[{i}]"),
                format!("{what}, got {x}"),
            ));
        }
    }
    Ok(())
}

/// One rule for every bound `[lo, hi]`: no NaN, `lo ≤ hi` (equal is an equality), and not
/// empty by an infinity (`lo = +∞` or `hi = −∞`).
fn check_bounds(key: &str, v: &[(f64, f64)]) -> std::result::Result<(), KeyError> {
    for (i, &(lo, hi)) in v.iter().enumerate() {
        let key = format!("{key}[{i}]");
        if lo.is_nan() || hi.is_nan() {
            return Err(KeyError {
                non_finite: true,
                ..KeyError::new(key, format!("must not be NaN, got [{lo}, {hi}]"))
            });
        }
        if lo == f64::INFINITY || hi == f64::NEG_INFINITY || lo > hi {
            return Err(KeyError::new(
                key,
                format!("must be [min, max] with min <= max (±inf for none), got [{lo}, {hi}]"),
            ));
        }
    }
    Ok(())
}

/// Builder for [`MpcSettings`]; [`build`](Self::build) validates.
#[derive(Debug, Clone)]
pub struct MpcSettingsBuilder {
    settings: MpcSettings,
}

macro_rules! setter {
    ($(#[$doc:meta] $name:ident: $ty:ty),* $(,)?) => {
        $(
            #[$doc]
            pub fn $name(mut self, value: $ty) -> Self {
                self.settings.$name = value;
                self
            }
        )*
    };
}

impl MpcSettingsBuilder {
    setter! {
        /// See [`MpcSettings::prediction_horizon`].
        prediction_horizon: usize,
        /// See [`MpcSettings::control_horizon`].
        control_horizon: usize,
        /// See [`MpcSettings::prediction_step`].
        prediction_step: usize,
        /// See [`MpcSettings::output_weights`].
        output_weights: Vec<f64>,
        /// See [`MpcSettings::input_weights`].
        input_weights: Vec<f64>,
        /// See [`MpcSettings::input_rate_weights`].
        input_rate_weights: Vec<f64>,
        /// See [`MpcSettings::input_target`].
        input_target: Vec<f64>,
        /// See [`MpcSettings::input_scales`].
        input_scales: Vec<f64>,
        /// See [`MpcSettings::output_scales`].
        output_scales: Vec<f64>,
        /// See [`MpcSettings::input_bounds`].
        input_bounds: Vec<(f64, f64)>,
        /// See [`MpcSettings::output_bounds`].
        output_bounds: Vec<(f64, f64)>,
        /// See [`MpcSettings::ecr_weight`].
        ecr_weight: f64,
        /// See [`MpcSettings::output_disturbance`].
        output_disturbance: Option<OutputDisturbance>,
        /// See [`MpcSettings::measurement_noise`].
        measurement_noise: Option<Mat>,
        /// See [`MpcSettings::solver`].
        solver: QpSolver,
        /// See [`MpcSettings::max_iterations`].
        max_iterations: usize,
    }

    /// Validates and returns the settings.
    pub fn build(self) -> Result<MpcSettings> {
        self.settings.validate()?;
        Ok(self.settings)
    }
}

pub(crate) fn fill_default(name: &str, v: &[f64], n: usize, default: f64) -> Result<Vec<f64>> {
    match v.len() {
        0 => Ok(vec![default; n]),
        len if len == n => Ok(v.to_vec()),
        len => Err(RipError::Shape {
            name: name.into(),
            expected: format!("({n},)"),
            rows: len,
            cols: 1,
        }),
    }
}

pub(crate) fn fill_bounds(name: &str, v: &[(f64, f64)], n: usize) -> Result<Vec<(f64, f64)>> {
    match v.len() {
        0 => Ok(vec![(f64::NEG_INFINITY, f64::INFINITY); n]),
        len if len == n => Ok(v.to_vec()),
        len => Err(RipError::Shape {
            name: name.into(),
            expected: format!("({n}, 2)"),
            rows: len,
            cols: 2,
        }),
    }
}

impl MpcSettings {
    /// Rejects horizons whose condensed matrices would exceed [`MAX_CONDENSED_ENTRIES`] for
    /// `nx` (augmented) states, `nu` inputs and `ny` outputs; the arithmetic saturates so that
    /// absurd sizes cannot wrap around to small ones.
    pub fn check_condensed(
        &self,
        nx: usize,
        nu: usize,
        ny: usize,
    ) -> std::result::Result<(), KeyError> {
        let (p, m) = (self.prediction_horizon, self.control_horizon);
        let nd = m.saturating_mul(nu);
        let rows = p
            .saturating_mul(ny.saturating_add(nu))
            .saturating_add(nd.saturating_mul(2))
            .saturating_add(1);
        let cols = nd.saturating_add(1).saturating_add(nx).saturating_add(nu);
        let entries = rows.saturating_mul(cols);
        if entries > MAX_CONDENSED_ENTRIES {
            return Err(KeyError::new(
                "prediction_horizon",
                format!(
                    "P = {p} with control_horizon m = {m}, {nx} states, {nu} inputs and {ny} \
                     outputs needs condensed matrices of about {entries} entries; at most \
                     {MAX_CONDENSED_ENTRIES} are allowed"
                ),
            ));
        }
        Ok(())
    }
}
