//! Constrained model predictive control with MATLAB MPC Toolbox semantics (the paper's
//! section 3).
//!
//! # Prediction model
//!
//! The plant `x⁺ = A x + B u`, `y = C x` is augmented with an output-disturbance model
//! `x_od⁺ = A_od x_od + B_od w_od`, `y_od = C_od x_od` (the paper's eq. (1)) and a measurement
//! noise `y_n = D_n w_n` (eq. (2)). Outputs are in scaled units `y/s_y` (scale factors `S_y`),
//! so with `x = [x_p; x_od]`
//!
//! ```text
//! A_aug = [A 0; 0 A_od],   B_u = [B; 0],   C_aug = [S_y⁻¹ C  C_od]          (eq. (3))
//! ```
//!
//! # Estimator
//!
//! A steady-state Kalman filter on the augmented model, with the manipulated variables
//! modelled as unit white noise in scaled units (noise input columns `B S_u`), the disturbance
//! noise `B_od` and the measurement noise `D_n` (default `I`):
//!
//! ```text
//! B_n = [B S_u 0 0; 0 B_od 0],  D_n' = [0 0 D_n],
//! Q = B_n B_nᵀ,  R = D_n' D_n'ᵀ,  N = B_n D_n'ᵀ                              (eqs. (8)–(10))
//! [L, M] = kalman(A_aug, I, C_aug, Q, R, N)                                    (eq. (11))
//! ```
//!
//! run in current form (eqs. (4)–(6)): `e = y/s_y − C_aug x̂[k|k−1]`,
//! `x̂[k|k] = x̂[k|k−1] + M e`, `x̂[k+1|k] = A_aug x̂[k|k−1] + B_u u[k] + L e`.
//!
//! # The move
//!
//! At step `k`, from `x = x̂[k|k]` and the previous move `u(k−1)`:
//!
//! ```text
//! minimise   Σ_{i=1..P} Σ_j ( w^y_j (r_j(k+i) − y_j(k+i|k)) / s^y_j )²
//!          + Σ_{i=0..m−1} Σ_j ( w^Δu_j Δu_j(k+i) / s^u_j )²
//!          + Σ_{i=0..P−1} Σ_j ( w^u_j (u_j(k+i) − u_t,j) / s^u_j )²  +  ρ_ε ε²
//! subject to u_min ≤ u(k+i) ≤ u_max                    (hard, i = 0..P−1)
//!            y_min − ε ≤ y(k+i|k) ≤ y_max + ε          (soft, equal concern, i = 1..P)
//!            ε ≥ 0,   Δu(k+i) = 0 for i ≥ m            (control horizon as move blocking)
//! ```
//!
//! (here `y` is the plant output in engineering units, i.e. `s_y` times the model output, and
//! `ε` is in scaled output units). The problem is condensed over `z = [Δu(k) … Δu(k+m−1), ε]`
//! (see the `condense` module docs for the matrices), all state-independent matrices are built
//! in [`Mpc::new`], and each step only fills two vectors and solves the QP with the selected
//! [`QpSolver`]. The applied input is `u(k) = u(k−1) + Δu(k)`.
//!
//! # Failures and the fallback
//!
//! Every solve reports a [`QpStatus`]. If it is not usable (maximum iterations, numerical
//! trouble, infeasible, non-finite input), the controller applies the previous plan's next
//! move, `u(k|k−1)` from the last successful solve (shifted once per sample, the last planned
//! move held), clamped to the input bounds, and reports [`StepStatus::Fallback`]. The applied
//! input is therefore always finite and within the bounds.
//!
//! A measurement is discarded, as if it had not arrived (zero innovation, so
//! `x̂[k|k] = x̂[k|k−1]`), when it holds NaN or Inf or when anything computed from it overflows:
//! the innovation, the corrected estimate, or the QP data `f`, `b` built on that estimate. The
//! step then applies the fallback, and the estimator keeps predicting from its last good
//! estimate instead of carrying the overflow into every later sample.
//!
//! # Missing samples
//!
//! [`Controller::hold`] stands for a period without a measurement in which the plant receives
//! a given input: the estimator runs the time update with zero innovation and that input, the
//! plan advances one sample as in a fallback step, and the held input becomes the previous move
//! `u(k−1)` of the next step.
//!
//! # Size limits
//!
//! The condensed matrices are dense, so their size is bounded before anything is built:
//! `P ≤` [`MAX_PREDICTION_HORIZON`] ([`MpcSettings::validate`]) and at most
//! [`MAX_CONDENSED_ENTRIES`] entries in the largest condensed matrix ([`Mpc::new`]).

mod active_set;
mod clarabel_backend;
mod condense;
pub mod paper;
#[cfg(test)]
mod tests;

use std::time::Instant;

use nalgebra::DVector;

use crate::controller::{Controller, StepStatus};
use crate::error::{Result, RipError};
use crate::kalman::{kalman, CurrentEstimator, KalmanDesign};
use crate::linalg::{check_finite, check_shape, check_square, Mat};

pub use active_set::{ActiveSetOutcome, ActiveSetSolver};
pub use clarabel_backend::ClarabelBackend;
use condense::{CondenseInput, Condensed};

/// Largest accepted prediction horizon `P`: 100 s at the paper's 100 Hz, far beyond any useful
/// horizon, while keeping the memory of the condensed problem bounded.
pub const MAX_PREDICTION_HORIZON: usize = 10_000;

/// Largest accepted number of entries (`f64`) in one condensed matrix (80 MB), estimated as
/// `(P·(ny + nu) + 2·m·nu + 1) · (m·nu + 1 + nx + nu)`: the prediction, constraint and
/// linear-term matrices all fit in that many rows and columns.
pub const MAX_CONDENSED_ENTRIES: usize = 10_000_000;

/// Which QP solver computes the move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum QpSolver {
    /// Clarabel interior-point solver (the reference). Clarabel allocates inside its `solve`,
    /// so a step with this backend is not allocation-free.
    #[default]
    Clarabel,
    /// Dense primal active-set solver with warm start (module [`ActiveSetSolver`]); solves
    /// without allocating. A problem whose nearly dependent constraints make its working-set
    /// systems singular (rare: none along the paper's loop) is handed to Clarabel, which
    /// allocates.
    ActiveSet,
}

impl QpSolver {
    /// Parses `"clarabel"` or `"active_set"` (also `"active-set"`, `"dense"`).
    pub fn from_name(name: &str) -> Result<Self> {
        match name.to_ascii_lowercase().as_str() {
            "clarabel" => Ok(Self::Clarabel),
            "active_set" | "active-set" | "activeset" | "dense" => Ok(Self::ActiveSet),
            _ => Err(RipError::invalid(
                "solver",
                format!("must be 'clarabel' or 'active_set', got {name:?}"),
            )),
        }
    }

    /// The name accepted by [`from_name`](Self::from_name).
    pub fn name(self) -> &'static str {
        match self {
            Self::Clarabel => "clarabel",
            Self::ActiveSet => "active_set",
        }
    }
}

/// Outcome of one QP solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum QpStatus {
    /// Solved to the solver's full accuracy.
    #[default]
    Solved,
    /// Clarabel's reduced-accuracy solution; the move is applied.
    AlmostSolved,
    /// The iteration limit was reached.
    MaxIterations,
    /// A factorisation failed or the solution is not finite.
    NumericalTrouble,
    /// The solver reported (or found) an infeasible problem.
    Infeasible,
    /// The state, previous input, measurement or reference held NaN or Inf, or the QP data
    /// computed from them overflowed.
    InvalidInput,
}

impl QpStatus {
    /// Whether the computed move is applied (otherwise the fallback is).
    pub fn is_usable(self) -> bool {
        matches!(self, Self::Solved | Self::AlmostSolved)
    }

    /// Snake-case name (`"solved"`, `"max_iterations"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::Solved => "solved",
            Self::AlmostSolved => "almost_solved",
            Self::MaxIterations => "max_iterations",
            Self::NumericalTrouble => "numerical_trouble",
            Self::Infeasible => "infeasible",
            Self::InvalidInput => "invalid_input",
        }
    }
}

/// Output-disturbance model `x_od⁺ = A_od x_od + B_od w_od`, `y_od = C_od x_od` (eq. (1)),
/// added to the scaled outputs.
#[derive(Debug, Clone)]
pub struct OutputDisturbance {
    pub a: Mat,
    pub b: Mat,
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
/// [`validate`](Self::validate) (intrinsic checks) and [`Mpc::new`] (sizes).
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
    /// Iteration limit of the QP solver.
    pub max_iterations: usize,
}

impl Default for MpcSettings {
    fn default() -> Self {
        Self {
            prediction_horizon: 10,
            control_horizon: 2,
            output_weights: Vec::new(),
            input_weights: Vec::new(),
            input_rate_weights: Vec::new(),
            input_target: Vec::new(),
            input_scales: Vec::new(),
            output_scales: Vec::new(),
            input_bounds: Vec::new(),
            output_bounds: Vec::new(),
            ecr_weight: 1e5,
            output_disturbance: None,
            measurement_noise: None,
            solver: QpSolver::Clarabel,
            max_iterations: 200,
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
    /// does, is checked by [`Mpc::new`].
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
        if self.max_iterations == 0 {
            return Err(RipError::invalid("max_iterations", "must be at least 1"));
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

/// The result of one MPC solve.
#[derive(Debug, Clone)]
pub struct MpcSolution {
    /// The move `u(k)` (applied input; the fallback when [`fallback`](Self::fallback)).
    pub u: DVector<f64>,
    /// `[Δu(k); …; Δu(k+m−1)]` (m·nu, stacked by step) of the applied plan.
    pub du: DVector<f64>,
    /// The slack `ε ≥ 0` (scaled output units): the largest predicted soft-bound violation of
    /// the plan, which is the optimal `ε` for the computed moves; NaN when the QP failed.
    pub slack: f64,
    /// Solver status.
    pub status: QpStatus,
    /// Whether the fallback move was applied.
    pub fallback: bool,
    /// Solver iterations (interior-point iterations or active-set subproblems).
    pub iterations: usize,
    /// Wall time of the QP setup and solve (s).
    pub solve_time: f64,
}

enum Backend {
    Clarabel(Box<ClarabelBackend>),
    /// The active-set solver, and Clarabel on the same QP for the rare problem whose nearly
    /// dependent constraints (output rows late in a long horizon converge to the steady-state
    /// gain) make its working-set systems singular.
    ActiveSet(Box<ActiveSetSolver>, Box<ClarabelBackend>),
}

impl Clone for Backend {
    fn clone(&self) -> Self {
        match self {
            Self::Clarabel(c) => Self::Clarabel(c.clone()),
            Self::ActiveSet(a, rescue) => Self::ActiveSet(a.clone(), rescue.clone()),
        }
    }
}

impl std::fmt::Debug for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Clarabel(c) => c.fmt(f),
            Self::ActiveSet(..) => f.write_str("ActiveSetSolver"),
        }
    }
}

/// The augmented prediction model (module docs).
#[derive(Debug, Clone)]
pub struct AugmentedModel {
    /// `A_aug = blkdiag(A, A_od)`.
    pub a: Mat,
    /// `B_u = [B; 0]`.
    pub b: Mat,
    /// `C_aug = [S_y⁻¹ C, C_od]`.
    pub c: Mat,
    /// Noise input matrix `[B S_u 0 0; 0 B_od 0]` of eq. (3).
    pub b_noise: Mat,
    /// Noise feedthrough `[0 0 D_n]` of eq. (3).
    pub d_noise: Mat,
    /// Number of plant states (the first states of the augmented model).
    pub n_plant: usize,
}

/// Constrained MPC with a built-in Kalman filter (module docs). `Clone + Send`.
#[derive(Debug, Clone)]
pub struct Mpc {
    settings: MpcSettings,
    ts: f64,
    model: AugmentedModel,
    kalman: KalmanDesign,
    estimator: CurrentEstimator,
    qp: Condensed,
    backend: Backend,
    u_lo: Vec<f64>,
    u_hi: Vec<f64>,
    output_scales: Vec<f64>,
    // Workspace and controller state.
    f: DVector<f64>,
    b: DVector<f64>,
    z: DVector<f64>,
    az: DVector<f64>,
    x: Vec<f64>,
    y_scaled: DVector<f64>,
    /// `x̂[k|k−1]` before the time update, to undo one that overflowed.
    prior_backup: DVector<f64>,
    /// A zero reference, to test the QP data of an estimate when the given reference is bad.
    r_zero: Vec<f64>,
    u_prev: Vec<f64>,
    plan: Vec<f64>,
    solution: MpcSolution,
}

fn fill_default(name: &str, v: &[f64], n: usize, default: f64) -> Result<Vec<f64>> {
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

fn fill_bounds(name: &str, v: &[(f64, f64)], n: usize) -> Result<Vec<(f64, f64)>> {
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
fn check_condensed_size(settings: &MpcSettings, nx: usize, nu: usize, ny: usize) -> Result<()> {
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

fn check_len(name: &str, v: &[f64], n: usize) -> Result<()> {
    if v.len() != n {
        return Err(RipError::Shape {
            name: name.into(),
            expected: format!("({n},)"),
            rows: v.len(),
            cols: 1,
        });
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(RipError::NonFinite { name: name.into() });
    }
    Ok(())
}

impl Mpc {
    /// Builds the controller for the discrete plant `x⁺ = A x + B u`, `y = C x` sampled at
    /// `ts`: the augmented model, the Kalman gains, the condensed QP and the solver.
    pub fn new(a: &Mat, b: &Mat, c: &Mat, ts: f64, settings: MpcSettings) -> Result<Self> {
        settings.validate()?;
        let n = check_square("A", a)?;
        let nu = b.ncols();
        let ny = c.nrows();
        if nu == 0 {
            return Err(RipError::invalid("B", "needs at least one input column"));
        }
        if ny == 0 {
            return Err(RipError::invalid("C", "needs at least one output row"));
        }
        check_shape("B", b, n, nu)?;
        check_shape("C", c, ny, n)?;
        check_finite("A", a)?;
        check_finite("B", b)?;
        check_finite("C", c)?;
        crate::linalg::check_sample_time("Ts", ts)?;
        let wy = fill_default("output_weights", &settings.output_weights, ny, 1.0)?;
        let wu = fill_default("input_weights", &settings.input_weights, nu, 0.0)?;
        let wdu = fill_default("input_rate_weights", &settings.input_rate_weights, nu, 0.1)?;
        let ut = fill_default("input_target", &settings.input_target, nu, 0.0)?;
        let su = fill_default("input_scales", &settings.input_scales, nu, 1.0)?;
        let sy = fill_default("output_scales", &settings.output_scales, ny, 1.0)?;
        let ub = fill_bounds("input_bounds", &settings.input_bounds, nu)?;
        let yb = fill_bounds("output_bounds", &settings.output_bounds, ny)?;
        if let Some(od) = &settings.output_disturbance {
            check_shape("C_od", &od.c, ny, od.a.nrows())?;
        }
        let dn = match &settings.measurement_noise {
            Some(dn) => {
                if dn.nrows() != ny || dn.ncols() == 0 {
                    return Err(RipError::Shape {
                        name: "measurement_noise".into(),
                        expected: format!("({ny}, nv) with nv ≥ 1"),
                        rows: dn.nrows(),
                        cols: dn.ncols(),
                    });
                }
                if (dn * dn.transpose()).cholesky().is_none() {
                    return Err(RipError::NotPositiveDefinite {
                        name: "measurement_noise D_n D_nᵀ".into(),
                    });
                }
                dn.clone()
            }
            None => Mat::identity(ny, ny),
        };

        let model = augment(a, b, c, &su, &sy, settings.output_disturbance.as_ref(), &dn);
        let nx = model.a.nrows();
        check_condensed_size(&settings, nx, nu, ny)?;
        let q = &model.b_noise * model.b_noise.transpose();
        let r = &model.d_noise * model.d_noise.transpose();
        let nn = &model.b_noise * model.d_noise.transpose();
        let kalman = kalman(
            &model.a,
            &Mat::identity(nx, nx),
            &model.c,
            &q,
            &r,
            Some(&nn),
            None,
        )
        .map_err(|e| match e {
            RipError::NotDetectable {
                re, im, modulus, ..
            } => RipError::NotDetectable {
                pair: "(A_aug, C_aug) of the plant with its output disturbance model".into(),
                re,
                im,
                modulus,
            },
            other => other,
        })?;
        let estimator = CurrentEstimator::new(
            model.a.clone(),
            model.b.clone(),
            model.c.clone(),
            None,
            kalman.l.clone(),
            kalman.m.clone(),
            DVector::zeros(nx),
        )?;

        let qp = Condensed::new(&CondenseInput {
            a: &model.a,
            b: &model.b,
            c: &model.c,
            p: settings.prediction_horizon,
            m: settings.control_horizon,
            output_weights: &wy,
            input_weights: &wu,
            input_rate_weights: &wdu,
            input_target: &ut,
            input_scales: &su,
            output_scales: &sy,
            input_bounds: &ub,
            output_bounds: &yb,
            ecr_weight: settings.ecr_weight,
        });
        if qp.h.iter().chain(qp.a.iter()).any(|v| !v.is_finite()) {
            return Err(RipError::invalid(
                "output_weights",
                "the weights and scales overflow the condensed QP (entries beyond 1e308); \
                 scale them down",
            ));
        }
        if qp.h.clone().cholesky().is_none() {
            return Err(RipError::invalid(
                "input_rate_weights",
                "the QP Hessian is singular: the outputs do not determine every move; \
                 give positive input_rate_weights (or input_weights)",
            ));
        }
        let backend = match settings.solver {
            QpSolver::Clarabel => Backend::Clarabel(Box::new(ClarabelBackend::new(
                &qp.h,
                &qp.a,
                settings.max_iterations,
            )?)),
            QpSolver::ActiveSet => Backend::ActiveSet(
                Box::new(
                    ActiveSetSolver::new(&qp.h, &qp.a, Some(qp.nz - 1), settings.max_iterations)
                        .ok_or_else(|| RipError::NotPositiveDefinite {
                            name: "QP Hessian".into(),
                        })?,
                ),
                Box::new(ClarabelBackend::new(&qp.h, &qp.a, settings.max_iterations)?),
            ),
        };
        let (nz, ncon, m) = (qp.nz, qp.ncon, qp.m);
        Ok(Self {
            ts,
            kalman,
            estimator,
            backend,
            u_lo: ub.iter().map(|b| b.0).collect(),
            u_hi: ub.iter().map(|b| b.1).collect(),
            output_scales: sy,
            f: DVector::zeros(nz),
            b: DVector::zeros(ncon),
            z: DVector::zeros(nz),
            az: DVector::zeros(ncon),
            x: vec![0.0; nx],
            y_scaled: DVector::zeros(ny),
            prior_backup: DVector::zeros(nx),
            r_zero: vec![0.0; ny],
            u_prev: vec![0.0; nu],
            plan: vec![0.0; m * nu],
            solution: MpcSolution {
                u: DVector::zeros(nu),
                du: DVector::zeros(m * nu),
                slack: 0.0,
                status: QpStatus::Solved,
                fallback: false,
                iterations: 0,
                solve_time: 0.0,
            },
            model,
            qp,
            settings,
        })
    }

    /// The settings the controller was built with.
    pub fn settings(&self) -> &MpcSettings {
        &self.settings
    }

    /// Sample time (s).
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// The augmented prediction model.
    pub fn model(&self) -> &AugmentedModel {
        &self.model
    }

    /// The built-in Kalman filter design (`L`, `M`, covariances, poles).
    pub fn kalman_design(&self) -> &KalmanDesign {
        &self.kalman
    }

    /// Number of augmented states.
    pub fn n_states(&self) -> usize {
        self.qp.nx
    }

    /// Prediction horizon `P`.
    pub fn prediction_horizon(&self) -> usize {
        self.qp.p
    }

    /// Control horizon `m`.
    pub fn control_horizon(&self) -> usize {
        self.qp.m
    }

    /// Number of QP variables (`m·nu + 1`) and constraint rows.
    pub fn qp_size(&self) -> (usize, usize) {
        (self.qp.nz, self.qp.ncon)
    }

    /// How many constraint rows are hard input bounds (first) and soft output bounds (next);
    /// the last row is `−ε ≤ 0`.
    pub fn constraint_layout(&self) -> (usize, usize) {
        (self.qp.rows.n_input, self.qp.rows.n_soft)
    }

    /// Input bounds `(u_min, u_max)`, `±∞` where unbounded.
    pub fn input_bounds(&self) -> (&[f64], &[f64]) {
        (&self.u_lo, &self.u_hi)
    }

    /// The previous move `u(k−1)` the next [`step`](Controller::step) starts from.
    pub fn last_input(&self) -> &[f64] {
        &self.u_prev
    }

    /// The result of the last solve or step.
    pub fn last_solution(&self) -> &MpcSolution {
        &self.solution
    }

    /// The condensed QP `(H, f, A_c, b)` for the given data (`½zᵀHz + fᵀz`, `A_c z ≤ b`),
    /// for checking against an independent formulation. Allocates.
    pub fn qp_matrices(
        &self,
        x: &[f64],
        u_prev: &[f64],
        r: &[f64],
    ) -> Result<(Mat, DVector<f64>, Mat, DVector<f64>)> {
        self.check_solve_args(x, u_prev, r)?;
        let mut f = DVector::zeros(self.qp.nz);
        let mut b = DVector::zeros(self.qp.ncon);
        self.qp.fill_linear(x, u_prev, r, &mut f, &mut b);
        Ok((self.qp.h.clone(), f, self.qp.a.clone(), b))
    }

    /// Predicted outputs `y(k+i|k)`, `i = 1..P` (P × ny, engineering units), for the
    /// augmented state `x`, previous input `u_prev` and moves `du` (m·nu). Allocates.
    pub fn predict_outputs(&self, x: &[f64], u_prev: &[f64], du: &[f64]) -> Result<Mat> {
        check_len("x", x, self.qp.nx)?;
        check_len("u_prev", u_prev, self.qp.nu)?;
        check_len("du", du, self.qp.m * self.qp.nu)?;
        let y = self.qp.predict(x, u_prev, du);
        let ny = self.qp.ny;
        Ok(Mat::from_fn(self.qp.p, ny, |i, j| {
            y[i * ny + j] * self.output_scales[j]
        }))
    }

    fn check_solve_args(&self, x: &[f64], u_prev: &[f64], r: &[f64]) -> Result<()> {
        check_len("x", x, self.qp.nx)?;
        check_len("u_prev", u_prev, self.qp.nu)?;
        self.check_reference(r)
    }

    fn check_reference(&self, r: &[f64]) -> Result<()> {
        let ny = self.qp.ny;
        if r.is_empty() || r.len() % ny != 0 || r.len() / ny > self.qp.p {
            return Err(RipError::Shape {
                name: "r".into(),
                expected: format!("({ny},) or (q, {ny}) with 1 ≤ q ≤ P = {}", self.qp.p),
                rows: r.len() / ny.max(1),
                cols: ny,
            });
        }
        if r.iter().any(|v| !v.is_finite()) {
            return Err(RipError::NonFinite { name: "r".into() });
        }
        Ok(())
    }

    /// Computes the move for the augmented state `x` (plant states, then disturbance
    /// states), the previous input `u_prev` and the reference `r` (`ny` values, or a preview of
    /// `q ≤ P` rows of `ny` values for `r(k+1) … r(k+q)`, the last row held to `k+P`), in
    /// engineering units. Does not touch the estimator; does update the warm start and the plan
    /// the fallback uses. Errors name a wrong-length or non-finite argument.
    pub fn solve(&mut self, x: &[f64], u_prev: &[f64], r: &[f64]) -> Result<&MpcSolution> {
        self.check_solve_args(x, u_prev, r)?;
        self.x.copy_from_slice(x);
        self.solve_buffers(u_prev, r, QpStatus::Solved, false);
        Ok(&self.solution)
    }

    /// One controller sample with a reference preview (see [`solve`](Self::solve) for `r`):
    /// estimator correction with `y`, move, estimator prediction with the applied move.
    /// The written `u` is always finite and within the input bounds. A measurement that is
    /// non-finite or overflows the correction or the QP data is discarded (module docs).
    pub fn step_preview(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        let ny = self.qp.ny;
        let r_ok = self.check_reference(r).is_ok();
        let mut measured = y.len() == ny && y.iter().all(|v| v.is_finite());
        if measured {
            for ((ys, &yi), &s) in self.y_scaled.iter_mut().zip(y).zip(&self.output_scales) {
                *ys = yi / s;
            }
            let posterior = self
                .estimator
                .correct(self.y_scaled.as_slice(), &self.u_prev);
            self.x.copy_from_slice(posterior.as_slice());
            measured = all_finite(&self.x) && all_finite(self.estimator.innovation().as_slice());
        }
        if measured {
            // A finite but huge estimate can still overflow the QP data; kept, it would make
            // every later step fail too. Tested even when this step's reference is unusable.
            let r_fill = if r_ok { r } else { &self.r_zero };
            self.qp
                .fill_linear(&self.x, &self.u_prev, r_fill, &mut self.f, &mut self.b);
            measured = all_finite(self.f.as_slice()) && all_finite(self.b.as_slice());
        }
        if !measured {
            let posterior = self.estimator.correct_without_measurement();
            self.x.copy_from_slice(posterior.as_slice());
        }
        let pre_status = if measured && r_ok {
            QpStatus::Solved
        } else {
            QpStatus::InvalidInput
        };
        let u_prev = std::mem::take(&mut self.u_prev);
        self.solve_buffers(&u_prev, if r_ok { r } else { &[] }, pre_status, true);
        self.u_prev = u_prev;
        self.u_prev.copy_from_slice(self.solution.u.as_slice());
        self.prior_backup.copy_from(self.estimator.prior());
        self.estimator.predict(&self.u_prev);
        if !all_finite(self.estimator.prior().as_slice()) {
            // Same reasoning for the time update: redo it from the last good prior, without
            // the innovation, rather than carry an overflow into every later sample.
            self.estimator.set_prior(self.prior_backup.as_slice());
            self.estimator.predict_without_measurement(&self.u_prev);
        }
        let n = u.len().min(self.u_prev.len());
        u[..n].copy_from_slice(&self.u_prev[..n]);
        if self.solution.fallback {
            StepStatus::Fallback
        } else {
            StepStatus::Nominal
        }
    }

    /// A period without a measurement in which the plant receives `u` (the
    /// [`Controller::hold`] of this controller; module docs): the estimator's time update with
    /// zero innovation, the plan shifted by one sample, and `u` as the next step's `u(k−1)`.
    /// Non-finite entries of `u` keep the previous input. [`last_solution`](Self::last_solution)
    /// is left as it was.
    pub fn hold_input(&mut self, u: &[f64]) {
        for (prev, &held) in self.u_prev.iter_mut().zip(u) {
            if held.is_finite() {
                *prev = held;
            }
        }
        self.estimator.predict_without_measurement(&self.u_prev);
        self.x
            .copy_from_slice(self.estimator.posterior().as_slice());
        let nu = self.qp.nu;
        if self.qp.m > 1 {
            self.plan.copy_within(nu.., 0);
        }
    }

    /// Solves from `self.x`, writes `self.solution`, shifts the plan. `pre_status` other than
    /// `Solved` skips the QP and applies the fallback. `filled`: `f` and `b` already hold the
    /// data for `self.x`, `u_prev` and `r`.
    #[allow(clippy::needless_range_loop)] // input index c runs over several arrays
    fn solve_buffers(&mut self, u_prev: &[f64], r: &[f64], pre_status: QpStatus, filled: bool) {
        let start = Instant::now();
        let (nu, m) = (self.qp.nu, self.qp.m);
        let (status, iterations) = if pre_status == QpStatus::Solved {
            if !filled {
                self.qp
                    .fill_linear(&self.x, u_prev, r, &mut self.f, &mut self.b);
            }
            if !(all_finite(self.f.as_slice()) && all_finite(self.b.as_slice())) {
                (QpStatus::InvalidInput, 0)
            } else {
                match &mut self.backend {
                    Backend::Clarabel(solver) => solver.solve(&self.f, &self.b, &mut self.z),
                    Backend::ActiveSet(solver, rescue) => {
                        let (lo, hi) = (&self.u_lo, &self.u_hi);
                        let out = solver
                            .solve(&self.f, &self.b, |z| project_inputs(z, u_prev, lo, hi, m));
                        self.z.copy_from(solver.solution());
                        let status =
                            if out.status.is_usable() && self.z.iter().any(|v| !v.is_finite()) {
                                QpStatus::NumericalTrouble
                            } else {
                                out.status
                            };
                        if status == QpStatus::NumericalTrouble {
                            let (status, iterations) = rescue.solve(&self.f, &self.b, &mut self.z);
                            (status, out.iterations + iterations)
                        } else {
                            (status, out.iterations)
                        }
                    }
                }
            }
        } else {
            (pre_status, 0)
        };

        // The previous plan advances one sample whatever happens now.
        if m > 1 {
            self.plan.copy_within(nu.., 0);
        }
        let slack = if status.is_usable() {
            self.exact_slack()
        } else {
            f64::NAN
        };
        let sol = &mut self.solution;
        sol.status = status;
        sol.iterations = iterations;
        if status.is_usable() {
            for c in 0..nu {
                let mut u = u_prev[c];
                for j in 0..m {
                    u += self.z[j * nu + c];
                    self.plan[j * nu + c] = u.max(self.u_lo[c]).min(self.u_hi[c]);
                }
            }
            sol.slack = slack;
            sol.fallback = false;
        } else {
            for c in 0..nu {
                self.plan[c] = self.plan[c].max(self.u_lo[c]).min(self.u_hi[c]);
            }
            sol.slack = slack;
            sol.fallback = true;
        }
        for c in 0..nu {
            let mut prev = if u_prev[c].is_finite() {
                u_prev[c]
            } else {
                self.plan[c]
            };
            for j in 0..m {
                sol.du[j * nu + c] = self.plan[j * nu + c] - prev;
                prev = self.plan[j * nu + c];
            }
            sol.u[c] = self.plan[c];
        }
        sol.solve_time = start.elapsed().as_secs_f64();
    }

    /// The optimal `ε` for the computed moves: given `Δ`, the cost grows with `ε`, so the
    /// optimum is the largest soft-bound violation of the plan, `max(0, max_i a_iᵀΔ − b_i)`.
    /// Recomputing it removes the interior-point error in `ε`, which the objective weighs so
    /// little (`ρ_ε ε²` next to terms of `10⁴`) that a solver leaves it at `~10⁻⁴`.
    fn exact_slack(&mut self) -> f64 {
        let nd = self.qp.nz - 1;
        self.z[nd] = 0.0;
        self.az.gemv(1.0, &self.qp.a, &self.z, 0.0);
        let (start, len) = (self.qp.rows.n_input, self.qp.rows.n_soft);
        let mut eps = 0.0f64;
        for i in start..start + len {
            eps = eps.max(self.az[i] - self.b[i]);
        }
        self.z[nd] = eps;
        eps
    }

    /// Returns to the state right after construction.
    pub fn reset_state(&mut self) {
        self.estimator.reset();
        self.u_prev.fill(0.0);
        self.plan.fill(0.0);
        if let Backend::ActiveSet(s, _) = &mut self.backend {
            s.reset();
        }
    }

    /// The estimator (its posterior `x̂[k|k]` and prior `x̂[k+1|k]`).
    pub fn estimator(&self) -> &CurrentEstimator {
        &self.estimator
    }
}

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Moves `Δ` so that every blocked input `u(k+j) = u⁻ + Σ_{l≤j} Δu(k+l)` lies in its bounds:
/// the running sums are clamped and the moves recomputed from them.
fn project_inputs(z: &mut [f64], u_prev: &[f64], lo: &[f64], hi: &[f64], m: usize) {
    let nu = u_prev.len();
    for c in 0..nu {
        let mut target = u_prev[c];
        let mut prev = u_prev[c];
        for j in 0..m {
            target += z[j * nu + c];
            let v = target.max(lo[c]).min(hi[c]);
            z[j * nu + c] = v - prev;
            prev = v;
        }
    }
}

/// Builds the augmented model of the module docs.
fn augment(
    a: &Mat,
    b: &Mat,
    c: &Mat,
    su: &[f64],
    sy: &[f64],
    od: Option<&OutputDisturbance>,
    dn: &Mat,
) -> AugmentedModel {
    let (n, nu, ny) = (a.nrows(), b.ncols(), c.nrows());
    let (nd, nw) = od.map_or((0, 0), |od| (od.a.nrows(), od.b.ncols()));
    let nv = dn.ncols();
    let nx = n + nd;
    let mut aa = Mat::zeros(nx, nx);
    aa.view_mut((0, 0), (n, n)).copy_from(a);
    let mut bb = Mat::zeros(nx, nu);
    bb.view_mut((0, 0), (n, nu)).copy_from(b);
    let mut cc = Mat::zeros(ny, nx);
    for i in 0..ny {
        for j in 0..n {
            cc[(i, j)] = c[(i, j)] / sy[i];
        }
    }
    let mut b_noise = Mat::zeros(nx, nu + nw + nv);
    for j in 0..nu {
        for i in 0..n {
            b_noise[(i, j)] = b[(i, j)] * su[j];
        }
    }
    if let Some(od) = od {
        aa.view_mut((n, n), (nd, nd)).copy_from(&od.a);
        cc.view_mut((0, n), (ny, nd)).copy_from(&od.c);
        b_noise.view_mut((n, nu), (nd, nw)).copy_from(&od.b);
    }
    let mut d_noise = Mat::zeros(ny, nu + nw + nv);
    d_noise.view_mut((0, nu + nw), (ny, nv)).copy_from(dn);
    AugmentedModel {
        a: aa,
        b: bb,
        c: cc,
        b_noise,
        d_noise,
        n_plant: n,
    }
}

impl Controller for Mpc {
    fn n_outputs(&self) -> usize {
        self.qp.ny
    }

    fn n_inputs(&self) -> usize {
        self.qp.nu
    }

    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        self.step_preview(y, r, u)
    }

    fn hold(&mut self, u: &[f64]) {
        self.hold_input(u);
    }

    fn reset(&mut self) {
        self.reset_state();
    }

    fn sample_time(&self) -> Option<f64> {
        Some(self.ts())
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        Some(self.estimator.posterior().as_slice())
    }
}
