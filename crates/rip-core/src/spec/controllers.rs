//! The controller sections of the experiment file: `[lqr]`, `[kalman]` and `[mpc]`, each with
//! its defaults (in its `Default`) and its value checks (in its `validate`, which names the key
//! path).

use std::f64::consts::FRAC_PI_6;

use serde::{Deserialize, Serialize};

use super::sections::{bad, each, non_negative, positive};
use super::SpecError;
use crate::mpc::{QpSolver, MAX_PREDICTION_HORIZON};
use crate::paper;
use crate::paper::INPUT_LIMIT;
use crate::regulators::DEFAULT_RATE_CUTOFF_HZ;

/// `[lqr]`: the weights of eq. (13), shared by LQR and LQG (`K = dlqr(A_d, B_d, diag(Q), R)`),
/// and LQR's rate filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
#[allow(non_snake_case)]
pub struct LqrSpec {
    /// Diagonal of `Q` over `[θ, θ̇, α, α̇]`.
    pub Q: [f64; 4],
    /// `R`.
    pub R: f64,
    /// Cut-off (Hz) of LQR's filtered-difference rate estimate; `inf` for the plain difference.
    pub rate_cutoff: f64,
    /// Weight `q_i` of the integrated arm error in LQR's and LQG's integral action
    /// (`crate::regulators`, MATLAB's `lqi`); 0 (the paper's setting) for none.
    pub integral_weight: f64,
}

impl Default for LqrSpec {
    fn default() -> Self {
        Self {
            Q: [25.0, 0.0, 50.0, 0.0],
            R: 0.1,
            rate_cutoff: DEFAULT_RATE_CUTOFF_HZ,
            integral_weight: 0.0,
        }
    }
}

impl LqrSpec {
    pub(super) fn validate(&self) -> Result<(), SpecError> {
        each("lqr.Q", &self.Q, non_negative)?;
        // The arm angle is an integrator (eigenvalue 1 of A_d): unweighted, it is a mode on
        // the unit circle that Q cannot see, and no stabilizing Riccati solution exists.
        if self.Q[0] == 0.0 {
            return Err(bad(
                "lqr.Q[0]",
                "must be positive: the arm angle is an integrator that an LQR design must weight",
            ));
        }
        positive("lqr.R", self.R)?;
        non_negative("lqr.integral_weight", self.integral_weight)?;
        if self.rate_cutoff.is_nan() || self.rate_cutoff <= 0.0 {
            return Err(bad(
                "lqr.rate_cutoff",
                format!("must be positive (Hz) or inf, got {}", self.rate_cutoff),
            ));
        }
        Ok(())
    }
}

/// `[kalman]`: the one steady-state Kalman filter LQG and MPC share (eqs. (1)–(11)).
///
/// The estimator model is the plant plus one integrated white noise `x_od⁺ = x_od + g w_od`
/// feeding both outputs (eq. (1)), with measurement noise `D_n = diag(measurement_noise)`
/// (eq. (2)); the filter is MATLAB's `kalman` on that model with the MPC's input and output
/// scale factors (`[mpc] input_scales`, `output_scales`), as MATLAB's MPC designs it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct KalmanSpec {
    /// Gain `g` of the output-disturbance integrator, eq. (1).
    pub disturbance_gain: f64,
    /// Diagonal of the measurement-noise model `D_n` (scaled output units), eq. (2).
    pub measurement_noise: [f64; 2],
}

impl Default for KalmanSpec {
    fn default() -> Self {
        Self {
            disturbance_gain: crate::mpc::paper::DISTURBANCE_GAIN,
            measurement_noise: [1.0, 1.0],
        }
    }
}

impl KalmanSpec {
    pub(super) fn validate(&self) -> Result<(), SpecError> {
        positive("kalman.disturbance_gain", self.disturbance_gain)?;
        each(
            "kalman.measurement_noise",
            &self.measurement_noise,
            positive,
        )
    }
}

/// The QP solver of the MPC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Solver {
    /// The dense warm-started active-set method (about 2 µs per step).
    #[default]
    ActiveSet,
    /// Clarabel's interior-point method (the reference, about 200 µs per step).
    Clarabel,
}

impl From<Solver> for QpSolver {
    fn from(s: Solver) -> Self {
        match s {
            Solver::ActiveSet => QpSolver::ActiveSet,
            Solver::Clarabel => QpSolver::Clarabel,
        }
    }
}

/// `[mpc]`: the MPC of section 3 (MATLAB MPC Toolbox semantics, [`crate::mpc`]); names as in
/// Python's `riprs.Mpc`.
///
/// `input_bounds` is the actuator range `[u_min, u_max]` (V) for every controller: the MPC's
/// hard constraint, and the clamp of LQR and LQG. `output_bounds` holds `[y_min, y_max]` per
/// output, `[-inf, inf]` for none; the default bounds the pendulum angle (see
/// [`crate::mpc::paper`] for why).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MpcSpec {
    /// Prediction horizon `P`.
    pub prediction_horizon: usize,
    /// Control horizon `m ≤ P`.
    pub control_horizon: usize,
    /// Output weights `w^y` (arm, pendulum).
    pub output_weights: [f64; 2],
    /// Input-rate weight `w^Δu`.
    pub input_rate_weights: [f64; 1],
    /// Input weight `w^u`.
    pub input_weights: [f64; 1],
    /// Hard input bounds `[u_min, u_max]` (V), finite.
    pub input_bounds: [[f64; 2]; 1],
    /// Soft output bounds `[y_min, y_max]` per output (rad).
    pub output_bounds: [[f64; 2]; 2],
    /// Slack weight `ρ_ε`.
    pub ecr_weight: f64,
    /// Input scale factor `s^u` (the paper's `L_su`).
    pub input_scales: [f64; 1],
    /// Output scale factors `s^y`.
    pub output_scales: [f64; 2],
    /// QP solver.
    pub solver: Solver,
    /// Iteration limit of the QP solver.
    pub max_iterations: usize,
}

impl Default for MpcSpec {
    fn default() -> Self {
        use crate::mpc::paper as p;
        let free = [f64::NEG_INFINITY, f64::INFINITY];
        Self {
            prediction_horizon: p::PREDICTION_HORIZON,
            control_horizon: p::CONTROL_HORIZON,
            output_weights: p::OUTPUT_WEIGHTS,
            input_rate_weights: [p::INPUT_RATE_WEIGHT],
            input_weights: [0.0],
            input_bounds: [[-INPUT_LIMIT, INPUT_LIMIT]],
            output_bounds: [free, [-FRAC_PI_6, FRAC_PI_6]],
            ecr_weight: p::ECR_WEIGHT,
            input_scales: [paper::INPUT_SCALE],
            output_scales: [1.0, 1.0],
            solver: Solver::ActiveSet,
            max_iterations: 200,
        }
    }
}

impl MpcSpec {
    pub(super) fn validate(&self) -> Result<(), SpecError> {
        let (p, m) = (self.prediction_horizon, self.control_horizon);
        if p == 0 || p > MAX_PREDICTION_HORIZON {
            return Err(bad(
                "mpc.prediction_horizon",
                format!("must be in 1..={MAX_PREDICTION_HORIZON}, got {p}"),
            ));
        }
        if m == 0 || m > p {
            return Err(bad(
                "mpc.control_horizon",
                format!("must be in 1..=mpc.prediction_horizon ({p}), got {m}"),
            ));
        }
        each("mpc.output_weights", &self.output_weights, non_negative)?;
        each(
            "mpc.input_rate_weights",
            &self.input_rate_weights,
            non_negative,
        )?;
        each("mpc.input_weights", &self.input_weights, non_negative)?;
        let [lo, hi] = self.input_bounds[0];
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(bad(
                "mpc.input_bounds[0]",
                format!("must be finite with u_min < u_max, got [{lo}, {hi}]"),
            ));
        }
        for (i, &[lo, hi]) in self.output_bounds.iter().enumerate() {
            if lo.is_nan() || hi.is_nan() || lo >= hi || lo == f64::INFINITY {
                return Err(bad(
                    format!("mpc.output_bounds[{i}]"),
                    format!("must be [y_min, y_max] with y_min < y_max (±inf for none), got [{lo}, {hi}]"),
                ));
            }
        }
        positive("mpc.ecr_weight", self.ecr_weight)?;
        each("mpc.input_scales", &self.input_scales, positive)?;
        each("mpc.output_scales", &self.output_scales, positive)?;
        if self.max_iterations == 0 {
            return Err(bad("mpc.max_iterations", "must be at least 1, got 0"));
        }
        Ok(())
    }
}

/// `[compensation]`: the dead-zone inverse and arm-friction feed-forward every controller's
/// voltage passes through ([`crate::compensation`]).
///
/// The corrections default to the `[plant]`'s own `vd` and `cr` (what the identification
/// found); set them to compensate other values, or `enabled = false` to run the controllers
/// as designed. A rig with neither (every preset) gets no compensation at all.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CompensationSpec {
    /// Compensate at all.
    pub enabled: bool,
    /// Dead zone compensated (V); `plant.vd` when absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dead_zone: Option<f64>,
    /// Arm Coulomb friction compensated (N·m), as the voltage `cr·rm/kt`; `plant.cr` when
    /// absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arm_friction: Option<f64>,
    /// Width (V) of the ramp that replaces the sign of the dead-zone inverse.
    pub voltage_scale: f64,
    /// Width (rad/s) of the ramp that replaces the sign of the arm rate in the friction
    /// feed-forward.
    pub velocity_scale: f64,
}

impl Default for CompensationSpec {
    fn default() -> Self {
        Self {
            enabled: true,
            dead_zone: None,
            arm_friction: None,
            voltage_scale: 0.05,
            velocity_scale: 0.05,
        }
    }
}

impl CompensationSpec {
    pub(super) fn validate(&self) -> Result<(), SpecError> {
        if let Some(v) = self.dead_zone {
            non_negative("compensation.dead_zone", v)?;
        }
        if let Some(v) = self.arm_friction {
            non_negative("compensation.arm_friction", v)?;
        }
        positive("compensation.voltage_scale", self.voltage_scale)?;
        positive("compensation.velocity_scale", self.velocity_scale)
    }
}
