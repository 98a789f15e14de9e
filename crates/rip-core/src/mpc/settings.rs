//! MPC settings: the user-facing [`MpcSettings`], their builder and validation, and the
//! resolution of empty vectors to MATLAB's defaults against the plant's sizes.

use crate::error::{Result, RipError};
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
#[derive(Debug, Clone)]
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

/// MPC settings (MATLAB names in brackets). Empty vectors take MATLAB's defaults; otherwise
/// they have one entry per input or output of the plant. Validated by
/// [`validate`](Self::validate) (intrinsic checks) and [`Mpc::new`](super::Mpc::new) (sizes).
#[derive(Debug, Clone)]
pub struct MpcSettings {
    /// Prediction horizon `P`, at most [`MAX_PREDICTION_HORIZON`] \[`PredictionHorizon`\];
    /// default 10.
    pub prediction_horizon: usize,
    /// Control horizon `m ≤ P` (moves `Δu(k..k+m−1)`, then blocked) \[`ControlHorizon`\];
    /// default 2.
    pub control_horizon: usize,
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
    /// Hard bounds `(u_min, u_max)` per input, `±∞` for none \[`MV.Min/Max`\]; default none.
    pub input_bounds: Vec<(f64, f64)>,
    /// Soft bounds `(y_min, y_max)` per output (engineering units), `±∞` for none
    /// \[`OV.Min/Max`, ECR 1\]; default none.
    pub output_bounds: Vec<(f64, f64)>,
    /// Slack weight `ρ_ε > 0` on `ε²` \[`Weights.ECR`\]; default 1e5.
    pub ecr_weight: f64,
    /// Output-disturbance model; `None` for none.
    pub output_disturbance: Option<OutputDisturbance>,
    /// Measurement-noise model `D_n` (ny × nv) on the scaled outputs; `None` for `I`.
    pub measurement_noise: Option<Mat>,
    /// QP solver.
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
    fn default() -> Self {
        Self {
            prediction_horizon: DEFAULT_PREDICTION_HORIZON,
            control_horizon: DEFAULT_CONTROL_HORIZON,
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
            solver: QpSolver::Clarabel,
            max_iterations: DEFAULT_MAX_ITERATIONS,
        }
    }
}

impl MpcSettings {
    /// A builder starting from the defaults.
    pub fn builder() -> MpcSettingsBuilder {
        MpcSettingsBuilder {
            settings: Self::default(),
        }
    }

    /// Checks everything that does not depend on the plant's sizes, including
    /// `1 ≤ P ≤` [`MAX_PREDICTION_HORIZON`]. The bound on the condensed problem's size, which
    /// does, is checked by [`Mpc::new`](super::Mpc::new).
    pub fn validate(&self) -> Result<()> {
        let (p, m) = (self.prediction_horizon, self.control_horizon);
        if p == 0 || p > MAX_PREDICTION_HORIZON {
            return Err(RipError::invalid(
                "prediction_horizon",
                format!("must be between 1 and {MAX_PREDICTION_HORIZON}, got {p}"),
            ));
        }
        if m == 0 || m > p {
            return Err(RipError::invalid(
                "control_horizon",
                format!("must be between 1 and prediction_horizon = {p}, got {m}"),
            ));
        }
        for (name, v) in [
            ("output_weights", &self.output_weights),
            ("input_weights", &self.input_weights),
            ("input_rate_weights", &self.input_rate_weights),
        ] {
            check_all(name, v, |w| w >= 0.0, "must be nonnegative")?;
        }
        check_all("input_target", &self.input_target, |_| true, "")?;
        for (name, v) in [
            ("input_scales", &self.input_scales),
            ("output_scales", &self.output_scales),
        ] {
            check_all(name, v, |s| s > 0.0, "must be positive")?;
        }
        check_bounds("input_bounds", &self.input_bounds)?;
        check_bounds("output_bounds", &self.output_bounds)?;
        if !(self.ecr_weight.is_finite() && self.ecr_weight > 0.0) {
            return Err(RipError::invalid(
                "ecr_weight",
                format!("must be positive and finite, got {}", self.ecr_weight),
            ));
        }
        if self.max_iterations == 0 || self.max_iterations > MAX_QP_ITERATIONS {
            return Err(RipError::invalid(
                "max_iterations",
                format!(
                    "must be between 1 and {MAX_QP_ITERATIONS}, got {}",
                    self.max_iterations
                ),
            ));
        }
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

fn check_all(name: &str, v: &[f64], ok: impl Fn(f64) -> bool, what: &str) -> Result<()> {
    for (i, &x) in v.iter().enumerate() {
        if !x.is_finite() {
            return Err(RipError::NonFinite {
                name: format!("{name}[{i}]"),
            });
        }
        if !ok(x) {
            return Err(RipError::invalid(
                name,
                format!("{what}, got {x} at index {i}"),
            ));
        }
    }
    Ok(())
}

fn check_bounds(name: &str, v: &[(f64, f64)]) -> Result<()> {
    for (i, &(lo, hi)) in v.iter().enumerate() {
        if lo.is_nan() || hi.is_nan() {
            return Err(RipError::NonFinite {
                name: format!("{name}[{i}]"),
            });
        }
        if lo == f64::INFINITY || hi == f64::NEG_INFINITY {
            return Err(RipError::invalid(
                name,
                format!("bound {i} = ({lo}, {hi}) excludes every value"),
            ));
        }
        if lo > hi {
            return Err(RipError::invalid(
                name,
                format!("bound {i} is empty: lower {lo} > upper {hi}"),
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

/// Rejects horizons whose condensed matrices would exceed [`MAX_CONDENSED_ENTRIES`]; the
/// arithmetic saturates so that absurd sizes cannot wrap around to small ones.
pub(crate) fn check_condensed_size(
    settings: &MpcSettings,
    nx: usize,
    nu: usize,
    ny: usize,
) -> Result<()> {
    let (p, m) = (settings.prediction_horizon, settings.control_horizon);
    let nd = m.saturating_mul(nu);
    let rows = p
        .saturating_mul(ny.saturating_add(nu))
        .saturating_add(nd.saturating_mul(2))
        .saturating_add(1);
    let cols = nd.saturating_add(1).saturating_add(nx).saturating_add(nu);
    let entries = rows.saturating_mul(cols);
    if entries > MAX_CONDENSED_ENTRIES {
        return Err(RipError::invalid(
            "prediction_horizon",
            format!(
                "P = {p} with control_horizon m = {m}, {nx} states, {nu} inputs and {ny} outputs \
                 needs condensed matrices of about {entries} entries; at most \
                 {MAX_CONDENSED_ENTRIES} are allowed"
            ),
        ));
    }
    Ok(())
}
