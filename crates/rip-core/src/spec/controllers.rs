//! The controller sections of the experiment file: `[lqr]`, `[kalman]` and `[mpc]`, each with
//! its defaults (in its `Default`; `[mpc]` in [`MpcSettings::paper`]) and its value checks (in
//! its `validate`, which names the key path).

use serde::{Deserialize, Serialize};

use super::sections::{bad, each, non_negative, positive};
use super::SpecError;
use crate::mpc::MpcSettings;
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
    /// LQR only: the bandwidth `f_d` (Hz) of an observer of a disturbance at the plant input
    /// whose estimate the law cancels (`Lqr::with_input_disturbance_cancelled`); 0, the
    /// default, for the paper's LQR without one.
    pub disturbance_bandwidth: f64,
}

impl Default for LqrSpec {
    fn default() -> Self {
        Self {
            Q: crate::paper::LQR_Q,
            R: crate::paper::LQR_R,
            rate_cutoff: DEFAULT_RATE_CUTOFF_HZ,
            integral_weight: 0.0,
            disturbance_bandwidth: 0.0,
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
        if !(self.disturbance_bandwidth.is_finite() && self.disturbance_bandwidth >= 0.0) {
            return Err(bad(
                "lqr.disturbance_bandwidth",
                format!(
                    "must be finite and >= 0 (Hz; 0 for none), got {}",
                    self.disturbance_bandwidth
                ),
            ));
        }
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
    /// LQG only: the variance `q_d` (V² per period) of a random-walk disturbance at the plant
    /// input that LQG's own filter estimates and its law cancels (`Design::lqg`); 0, the
    /// default, for the paper's LQG on the shared filter.
    pub input_disturbance: f64,
    /// LQG only: its law regulates the estimated outputs, the plant part of the shared
    /// filter's estimate plus what the output disturbance of eq. (1) adds to each angle, as
    /// the MPC's cost does (rip-control's `Design::regulates_outputs`); `false`, the default,
    /// for the paper's LQG on the plant part alone.
    pub regulate_outputs: bool,
}

impl Default for KalmanSpec {
    fn default() -> Self {
        Self {
            disturbance_gain: crate::mpc::paper::DISTURBANCE_GAIN,
            measurement_noise: [1.0, 1.0],
            input_disturbance: 0.0,
            regulate_outputs: false,
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
        )?;
        non_negative("kalman.input_disturbance", self.input_disturbance)?;
        if self.regulate_outputs && self.input_disturbance > 0.0 {
            return Err(bad(
                "kalman.regulate_outputs",
                "LQG's own filter (kalman.input_disturbance > 0) has no output disturbance to \
                 regulate; set one of the two"
                    .to_string(),
            ));
        }
        Ok(())
    }
}

/// `[mpc]` is [`MpcSettings`] itself (its serde schema; missing keys take
/// [`MpcSettings::paper`]). What the experiment adds to its own checks
/// ([`MpcSettings::check`], [`MpcSettings::check_sizes`], [`MpcSettings::check_condensed`]):
/// one input, two outputs, and `input_bounds` given and finite, since it is the actuator range
/// `[u_min, u_max]` (V) of every controller: the MPC's hard constraint and the clamp of LQR
/// and LQG. `output_bounds` holds `[y_min, y_max]` per output, `[-inf, inf]` for none; the
/// default bounds the pendulum angle (see [`crate::mpc::paper`] for why).
pub(super) fn validate_mpc(m: &MpcSettings) -> Result<(), SpecError> {
    let in_mpc = |e| SpecError::in_section("mpc", e);
    // A file that shortens only the prediction horizon below the default control horizon is
    // refused through the key it wrote.
    let default_m = MpcSettings::paper().control_horizon;
    let p = m.prediction_horizon;
    if m.control_horizon == default_m && (1..default_m).contains(&p) {
        return Err(bad(
            "mpc.prediction_horizon",
            format!(
                "must be at least mpc.control_horizon ({default_m}, its default), got {p}; or \
                 set mpc.control_horizon in 1..={p}"
            ),
        ));
    }
    m.check().map_err(in_mpc)?;
    m.check_sizes(1, 2).map_err(in_mpc)?;
    // The estimator's model: 4 plant states and the one output-disturbance state.
    m.check_condensed(5, 1, 2).map_err(in_mpc)?;
    let Some(&(lo, hi)) = m.input_bounds.first() else {
        return Err(bad(
            "mpc.input_bounds",
            "must give [u_min, u_max]: the actuator range of every controller",
        ));
    };
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(bad(
            "mpc.input_bounds[0]",
            format!("must be finite with u_min < u_max, got [{lo}, {hi}]"),
        ));
    }
    Ok(())
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
    /// The multiple of the dead zone (`dead_zone`, else the plant's `Vd`) the inverse
    /// applies: `riprs tune` raises it above 1 where an identified dead zone 30 % off would
    /// leave a limit cycle ([`crate::tune::gains`]).
    pub dead_zone_gain: f64,
    /// The multiple of the arm friction (`arm_friction`, else the plant's `Cr`) the
    /// feed-forward applies, chosen by `riprs tune` as [`dead_zone_gain`](Self::dead_zone_gain).
    pub friction_gain: f64,
}

impl Default for CompensationSpec {
    fn default() -> Self {
        Self {
            enabled: true,
            dead_zone: None,
            arm_friction: None,
            voltage_scale: 0.05,
            velocity_scale: 0.05,
            dead_zone_gain: 1.0,
            friction_gain: 1.0,
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
        positive("compensation.velocity_scale", self.velocity_scale)?;
        non_negative("compensation.dead_zone_gain", self.dead_zone_gain)?;
        non_negative("compensation.friction_gain", self.friction_gain)
    }
}
