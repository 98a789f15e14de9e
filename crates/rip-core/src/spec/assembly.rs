//! The one controller assembly: LQR, LQG and MPC built from a [`Spec`] at a sample time.
//!
//! ```text
//! design model   (A_d, B_d) = c2d(A_c, B_c, Ts), C picks θ and α
//!                A_c, B_c: the paper's recovered model for the unchanged `paper` preset,
//!                otherwise the [plant] parameters' linearisation about upright
//! gain           K = dlqr(A_d, B_d, diag(lqr.Q), lqr.R)                          eq. (13)
//!                with lqr.integral_weight q_i > 0: [K k_i] = dlqr of the model with the
//!                integrated arm error x_i⁺ = x_i − Ts θ appended, diag(Q, q_i), R
//!                (crate::regulators, "Integral action")
//! estimator      one Kalman design on the augmented model (mpc::EstimatorDesign):
//!                plant + [kalman] disturbance, MPC scales, eqs. (1)–(11)
//! LQR            K, lqr.rate_cutoff, clamp to mpc.input_bounds
//! LQG            K on the estimator (no MPC is built for it)
//! MPC            [mpc] settings on the same estimator; it runs as rip-control's controller
//!                of its design (the device's code) when that computes the same move
//!                (mpc::Mpc::run_time_controller), as the general Mpc otherwise
//! compensation   when [compensation] finds a dead zone or arm friction to compensate, each
//!                controller plans within the input bounds shrunk by V_d + V_f and its
//!                voltage passes through the compensation (crate::compensation)
//! ```
//!
//! Every failure is a [`SpecError`] naming the key that caused it, so a file whose values are
//! each valid but fail together in a design is refused before any simulation work.

use nalgebra::DVector;

use super::{ControllerKind, Spec, SpecError};
use crate::compensation::{Compensated, Compensation};
use crate::controller::Controller;
use crate::error::RipError;
use crate::linalg::{c2d, Mat};
use crate::lqr::dlqr;
use crate::mpc::{EstimatorDesign, Mpc, MpcSettings, OutputDisturbance};
use crate::paper;
use crate::plant::Plant;
use crate::regulators::{Lqg, Lqr};
use crate::sim::vec_env::{EnvConfig, Task};
use crate::sim::{Reference, SensorModel, SimConfig};

/// How a simulated run of the spec starts ([`Spec::simulation`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Start {
    /// At `plant.initial_state`, near upright: the paper's experiment.
    #[default]
    Upright,
    /// Hanging at rest, swung up and caught by a supervisor; the arm step comes
    /// `reference.step_time` after the catch, as `rip-rt run --swing-up` does on the rig.
    Hanging,
}

/// Time (s) a run that starts hanging gets on top of `reference.duration`: about the 95th
/// percentile of the time to upright over ±10 % parameter errors.
pub const SWING_UP_ALLOWANCE: f64 = 10.0;

/// The variance `q_u` (V² per period) of the white noise at the plant input in LQG's own
/// filter with an input disturbance (`kalman.input_disturbance`): the model's own error,
/// small against the disturbance it leaves to `d`.
pub const LQG_INPUT_NOISE: f64 = 0.01;

/// A built controller and its kind.
pub type Built = (ControllerKind, Box<dyn Controller>);

/// The designed pieces every controller of a spec is built from: the design model, the LQR
/// gain and the one Kalman design LQG and MPC share (module docs).
#[derive(Debug, Clone)]
pub struct Design {
    spec: Spec,
    ts: f64,
    /// `A_d` of the design model.
    pub a: Mat,
    /// `B_d` of the design model.
    pub b: Mat,
    /// `C`: the two angles.
    pub c: Mat,
    /// `K = dlqr(A_d, B_d, diag(Q), R)` (1×4); the state part `K_x` of the augmented design
    /// when there is integral action.
    pub k: Mat,
    /// `k_i`, the gain on the integrated arm error, when `lqr.integral_weight > 0`.
    pub integral_gain: Option<f64>,
    /// The shared Kalman design.
    pub estimator: EstimatorDesign,
    /// The compensation every controller's voltage passes through, if any.
    compensation: Option<Compensation>,
    /// LQG's own filter, when it cancels an input disturbance (`kalman.input_disturbance`).
    lqg_filter: Option<InputDisturbanceFilter>,
}

/// LQG's own filter on the design model augmented by a random-walk disturbance `d` at the
/// plant input ([`input_disturbance_filter`]): `x̂⁺ = A x̂ + B u + L e`, `y = C x̂`.
#[derive(Debug, Clone)]
struct InputDisturbanceFilter {
    a: Mat,
    b: Mat,
    c: Mat,
    l: Mat,
    m: Mat,
}

/// LQG's own filter, on the design model `(a, b, c)` augmented by a random-walk disturbance
/// `d` at the plant input, whose estimate the law cancels (`kalman.input_disturbance` = `q_d`
/// of `spec`):
///
/// ```text
/// [x; d][k+1] = [A_d B_d; 0 1] [x; d] + [B_d; 0] u + [B_d 0; 0 1] w,   y = [C 0] [x; d] + v
/// cov(w) = diag(q_u, q_d),   cov(v) = diag(σ_θ² + δ_θ²/12, σ_α² + δ_α²/12)
/// u = −K (x̂ − x_ref) − d̂
/// ```
///
/// with `q_u` = [`LQG_INPUT_NOISE`], `σ` the `[sensor]`'s noise and `δ` one count of its
/// encoders (their quantisation's variance). What the compensation leaves of a dead zone,
/// friction or breakaway torque acts as such a disturbance, and is cancelled within a few
/// periods instead of holding the arm in a limit cycle.
fn input_disturbance_filter(
    spec: &Spec,
    a: &Mat,
    b: &Mat,
    c: &Mat,
) -> Result<InputDisturbanceFilter, SpecError> {
    let n = a.nrows();
    let mut aa = Mat::zeros(n + 1, n + 1);
    aa.view_mut((0, 0), (n, n)).copy_from(a);
    aa.view_mut((0, n), (n, 1)).copy_from(b);
    aa[(n, n)] = 1.0;
    let mut ba = Mat::zeros(n + 1, 1);
    ba.view_mut((0, 0), (n, 1)).copy_from(b);
    let mut ca = Mat::zeros(c.nrows(), n + 1);
    ca.view_mut((0, 0), (c.nrows(), n)).copy_from(c);
    let mut g = Mat::zeros(n + 1, 2);
    g.view_mut((0, 0), (n, 1)).copy_from(b);
    g[(n, 1)] = 1.0;
    let qn = Mat::from_row_slice(
        2,
        2,
        &[LQG_INPUT_NOISE, 0.0, 0.0, spec.kalman.input_disturbance],
    );
    let [vt, va] = spec.sensor.angle_variance();
    let rn = Mat::from_row_slice(2, 2, &[vt, 0.0, 0.0, va]);
    let kf = crate::kalman::kalman(&aa, &g, &ca, &qn, &rn, None, None).map_err(|e| {
        SpecError::new(
            "kalman.input_disturbance",
            format!("LQG's own filter fails: {e}"),
        )
    })?;
    Ok(InputDisturbanceFilter {
        a: aa,
        b: ba,
        c: ca,
        l: kf.l,
        m: kf.m,
    })
}

/// The weight an LQR design failure is blamed on: `R` when the error's argument is `dlqr`'s
/// `R` (the argument name is the error's data), or when it is so small against `Q` (below
/// 1e-12 of its largest entry) that the Riccati equation is ill-conditioned; `Q` otherwise.
fn lqr_key(e: &RipError, spec: &super::LqrSpec) -> &'static str {
    let q_max = spec.Q.iter().copied().fold(0.0, f64::max);
    if spec.R < 1e-12 * q_max {
        return "lqr.R";
    }
    let name = match e {
        RipError::InvalidParameter { name, .. }
        | RipError::NotPositiveDefinite { name }
        | RipError::NonFinite { name }
        | RipError::NotSymmetric { name, .. }
        | RipError::NotPositiveSemidefinite { name, .. } => name.as_str(),
        _ => "",
    };
    match name {
        "R" => "lqr.R",
        _ => "lqr.Q",
    }
}

impl Spec {
    /// The nonlinear plant of `[plant]`, with its stiction (`plant.arm_breakaway`) if any.
    pub fn plant(&self) -> Result<Plant, SpecError> {
        let params = self.plant.params();
        params
            .check()
            .map_err(|(p, reason)| SpecError::new(format!("plant.{p}"), reason))?;
        let plant = Plant::new(params).map_err(|e| SpecError::new("plant", e.to_string()))?;
        match self.plant.arm_breakaway {
            Some(cs) => plant
                .with_arm_breakaway(cs)
                .map_err(|e| SpecError::new("plant.arm_breakaway", e.to_string())),
            None => Ok(plant),
        }
    }

    /// The continuous-time design model `(A_c, B_c)` (module docs).
    pub fn continuous_design_model(&self) -> Result<(Mat, Mat), SpecError> {
        if self.plant.is_paper_model() {
            Ok(paper::continuous_model())
        } else {
            Ok(self.plant()?.linearize_upright())
        }
    }

    /// The MPC settings: `[mpc]`, with the estimator model of `[kalman]`.
    pub fn mpc_settings(&self) -> MpcSettings {
        let k = &self.kalman;
        MpcSettings {
            output_disturbance: Some(OutputDisturbance::integrated_white_noise(
                2,
                k.disturbance_gain,
            )),
            measurement_noise: if k.measurement_noise == [1.0, 1.0] {
                None
            } else {
                Some(Mat::from_diagonal(&DVector::from_row_slice(
                    &k.measurement_noise,
                )))
            },
            ..self.mpc.clone()
        }
    }

    /// The actuator range `[mpc] input_bounds` `(u_min, u_max)` (V) of every controller.
    pub fn input_bounds(&self) -> (f64, f64) {
        self.mpc.input_bounds[0]
    }

    /// Replaces the actuator range (checked by [`validate`](Self::validate), as in a file).
    pub fn set_input_bounds(&mut self, lo: f64, hi: f64) {
        self.mpc.input_bounds = vec![(lo, hi)];
    }

    /// The compensation of `[compensation]` (module docs of [`crate::compensation`]) for the
    /// `[plant]` and `[mpc] input_bounds`; `None` when it is disabled or there is neither a
    /// dead zone nor arm friction to compensate.
    pub fn compensation(&self) -> Result<Option<Compensation>, SpecError> {
        let c = &self.compensation;
        if !c.enabled {
            return Ok(None);
        }
        let p = self.plant.params();
        let vd = c.dead_zone_gain * c.dead_zone.unwrap_or(p.vd);
        let cr = c.friction_gain * c.arm_friction.unwrap_or(p.cr);
        if vd == 0.0 && cr == 0.0 {
            return Ok(None);
        }
        let (lo, hi) = self.input_bounds();
        let vf = cr * p.rm / p.kt;
        Compensation::new(vd, vf, c.voltage_scale, c.velocity_scale, (lo, hi))
            .map(Some)
            .map_err(|e| match e.name {
                "input_bounds" => SpecError::new("mpc.input_bounds", e.to_string()),
                // Both corrections default to [plant] values: the refusal names whichever key
                // the file wrote for the larger one, with the range of it that fits.
                "dead_zone" if e.value == vd + vf => self.no_room_to_compensate(vd, vf),
                name => SpecError::new(format!("compensation.{name}"), e.to_string()),
            })
    }

    /// The refusal of a dead zone `vd` and friction voltage `vf` (V) that together leave no
    /// room inside `[mpc] input_bounds`: against the written key (`[compensation]`'s when it
    /// is given, else `[plant]`'s) of the larger of the two, stating the values of it that
    /// fit beside the other; against `mpc.input_bounds` when they do not hold 0 V inside.
    fn no_room_to_compensate(&self, vd: f64, vf: f64) -> SpecError {
        let c = &self.compensation;
        let p = self.plant.params();
        let (lo, hi) = self.input_bounds();
        let room = hi.min(-lo);
        let bounds = format!("mpc.input_bounds [{lo}, {hi}] V");
        if room <= 0.0 {
            return SpecError::new(
                "mpc.input_bounds",
                format!(
                    "must hold 0 V strictly inside to compensate a dead zone of {vd} V and an \
                     arm friction voltage of {vf:.2} V, got [{lo}, {hi}]; or set \
                     compensation.enabled = false"
                ),
            );
        }
        // A gain other than 1 is what made the value larger than the one written.
        let vd_key = match (c.dead_zone_gain != 1.0, c.dead_zone) {
            (true, _) => "compensation.dead_zone_gain",
            (false, Some(_)) => "compensation.dead_zone",
            (false, None) => "plant.Vd",
        };
        let cr_key = match (c.friction_gain != 1.0, c.arm_friction) {
            (true, _) => "compensation.friction_gain",
            (false, Some(_)) => "compensation.arm_friction",
            (false, None) => "plant.Cr",
        };
        let alternatives = "widen mpc.input_bounds, or set compensation.enabled = false";
        let (key, reason) = if vf > vd {
            let cr = vf * p.kt / p.rm;
            let fits = if vd < room && c.friction_gain != 1.0 {
                format!(
                    "{cr_key} must be below {} here (the friction voltage below {} V)",
                    Floor4((room - vd) / (vf / c.friction_gain)),
                    Floor4(room - vd)
                )
            } else if vd < room {
                format!(
                    "{cr_key} must be below {} N·m here (the friction voltage below {} V)",
                    Floor4(((room - vd) * p.kt / p.rm).max(0.0)),
                    Floor4(room - vd)
                )
            } else {
                format!("and {vd_key} = {vd} V alone leaves none either")
            };
            (
                cr_key,
                format!(
                    "the arm friction {cr} N·m is compensated as the voltage Cr·Rm/kt = {vf:.2} V, \
                     which with the dead zone of {vd} V leaves no room inside {bounds}: \
                     {fits}; or {alternatives}"
                ),
            )
        } else {
            let fits = if vf < room && c.dead_zone_gain != 1.0 {
                format!(
                    "{vd_key} must be below {} here (the dead zone compensated below {} V)",
                    Floor4((room - vf) / (vd / c.dead_zone_gain)),
                    Floor4(room - vf)
                )
            } else if vf < room {
                format!("{vd_key} must be below {} V here", Floor4(room - vf))
            } else {
                format!("and {cr_key}'s friction voltage {vf:.2} V alone leaves none either")
            };
            (
                vd_key,
                format!(
                    "the dead zone of {vd} V, with the arm friction voltage of {vf:.2} V, leaves \
                     no room inside {bounds}: {fits}; or {alternatives}"
                ),
            )
        };
        SpecError::new(key, reason)
    }

    /// The simulation of `[plant]`, `[sensor]` and `[reference]` at sample time `ts`, started
    /// upright ([`simulation`](Self::simulation) with [`Start::Upright`]).
    pub fn sim_config(&self, ts: f64, seed: u64) -> SimConfig {
        self.simulation(ts, seed, Start::Upright)
    }

    /// The one mapping of the file onto a simulated run, used by `riprs compare`,
    /// `riprs.simulate` through `Spec.simulation_options`, the campaigns and the vector
    /// environments:
    ///
    /// ```text
    /// plant.substeps, plant.fall_limit      the integration and the fall test
    /// plant.initial_state                   x0 (Upright); [0, 0, π, 0] (Hanging)
    /// sensor.encoder_counts                 the quantisation of each angle
    /// sensor.noise_std, sensor.encoder_offsets   the measurement y = q(x + o) + n
    /// reference.arm_step, reference.step_time   the step at step_time (Upright), or
    ///                                       step_time after the catch (Hanging), as on the rig
    /// reference.duration                    the run (+ SWING_UP_ALLOWANCE when Hanging)
    /// mpc.input_bounds                      the actuator's saturation max(|u_min|, |u_max|)
    /// ```
    pub fn simulation(&self, ts: f64, seed: u64, start: Start) -> SimConfig {
        let (lo, hi) = self.input_bounds();
        let value = [self.reference.arm_step, 0.0];
        let (duration, x0, reference) = match start {
            Start::Upright => (
                self.reference.duration,
                self.plant.initial_state,
                Reference::Step {
                    time: self.reference.step_time,
                    value,
                },
            ),
            Start::Hanging => (
                self.reference.duration + SWING_UP_ALLOWANCE,
                [0.0, 0.0, std::f64::consts::PI, 0.0],
                Reference::StepAfterCatch {
                    delay: self.reference.step_time,
                    value,
                },
            ),
        };
        SimConfig {
            duration,
            ts,
            substeps: self.plant.substeps,
            x0,
            reference,
            sensor: SensorModel {
                counts_per_rev: Some(self.sensor.encoder_counts.map(f64::from)),
                noise_std: self.sensor.noise_std,
                offsets: self.sensor.encoder_offsets,
            },
            output_disturbance: None,
            torque_disturbance: None,
            u_limit: lo.abs().max(hi.abs()),
            fall_limit: self.plant.fall_limit,
            seed,
            end_after_catch: None,
        }
    }

    /// Designs the model, the gain and the shared Kalman filter at sample time `ts` (s).
    pub fn design(&self, ts: f64) -> Result<Design, SpecError> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(SpecError::new(
                "Ts",
                format!("must be positive and finite, got {ts}"),
            ));
        }
        self.validate()?;
        let compensation = self.compensation()?;
        let (ac, bc) = self.continuous_design_model()?;
        let (a, b) = c2d(&ac, &bc, ts)
            .map_err(|e| SpecError::new("plant", format!("discretisation at Ts = {ts} s: {e}")))?;
        let c = paper::output_matrix();
        let (ad, bd, q) = if self.lqr.integral_weight > 0.0 {
            integral_model(&a, &b, ts, &self.lqr.Q, self.lqr.integral_weight)
        } else {
            let q = Mat::from_diagonal(&DVector::from_row_slice(&self.lqr.Q));
            (a.clone(), b.clone(), q)
        };
        let r = Mat::from_element(1, 1, self.lqr.R);
        let k_full = match dlqr(&ad, &bd, &q, &r, None) {
            Ok(d) => d.k,
            Err(e @ RipError::NotStabilizable { .. }) => {
                return Err(SpecError::new("plant", format!("the design model: {e}")))
            }
            Err(e) => {
                return Err(SpecError::new(
                    lqr_key(&e, &self.lqr),
                    format!(
                        "the LQR design with Q = {:?}, R = {} fails: {e}",
                        self.lqr.Q, self.lqr.R
                    ),
                ))
            }
        };
        let k = k_full.columns(0, 4).into_owned();
        let integral_gain = (k_full.ncols() > 4).then(|| k_full[(0, 4)]);
        if !k_full.iter().all(|v| v.is_finite()) {
            return Err(SpecError::new(
                "lqr.R",
                format!("the LQR gain is not finite with R = {}", self.lqr.R),
            ));
        }
        // Every [mpc] and [kalman] value is checked by `validate`: what remains is the
        // model's detectability, or the Kalman design itself.
        let estimator = EstimatorDesign::new(&a, &b, &c, &self.mpc_settings()).map_err(|e| {
            let key = match e {
                RipError::NotDetectable { .. } => "plant",
                _ => "kalman",
            };
            SpecError::new(key, format!("the Kalman design fails: {e}"))
        })?;
        let lqg_filter = (self.kalman.input_disturbance > 0.0)
            .then(|| input_disturbance_filter(self, &a, &b, &c))
            .transpose()?;
        Ok(Design {
            spec: self.clone(),
            ts,
            a,
            b,
            c,
            k,
            integral_gain,
            estimator,
            compensation,
            lqg_filter,
        })
    }
}

/// A positive bound written to four significant digits, rounded down, so that every value
/// below the written one is below the bound too.
struct Floor4(f64);

impl std::fmt::Display for Floor4 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = self.0;
        if !(v.is_finite() && v > 0.0) {
            return write!(f, "{v}");
        }
        let scale = 10f64.powi(3 - v.log10().floor() as i32);
        let down = (v * scale).floor() / scale;
        let decimals = (3 - v.log10().floor() as i32).max(0) as usize;
        write!(f, "{down:.decimals$}")
    }
}

/// The design model with the integrated arm error appended (MATLAB's `lqi`, discrete):
/// `A_i = [A_d 0; −Ts e_θᵀ 1]`, `B_i = [B_d; 0]`, `Q_i = diag(Q, q_i)`.
fn integral_model(a: &Mat, b: &Mat, ts: f64, q: &[f64; 4], qi: f64) -> (Mat, Mat, Mat) {
    let mut ai = Mat::zeros(5, 5);
    ai.view_mut((0, 0), (4, 4)).copy_from(a);
    ai[(4, 0)] = -ts;
    ai[(4, 4)] = 1.0;
    let mut bi = Mat::zeros(5, 1);
    bi.view_mut((0, 0), (4, 1)).copy_from(b);
    let mut diag = q.to_vec();
    diag.push(qi);
    (ai, bi, Mat::from_diagonal(&DVector::from_vec(diag)))
}

impl Design {
    /// The spec this design was built from.
    pub fn spec(&self) -> &Spec {
        &self.spec
    }

    /// The sample time (s) of every controller of this design.
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// The bounds the controllers plan within: `[mpc] input_bounds`, shrunk by the
    /// compensation's largest correction when there is one.
    pub fn bounds(&self) -> (f64, f64) {
        match &self.compensation {
            Some(c) => c.inner_bounds(),
            None => self.spec.input_bounds(),
        }
    }

    /// The compensation every controller's voltage passes through, if any.
    pub fn compensation(&self) -> Option<&Compensation> {
        self.compensation.as_ref()
    }

    /// `controller` with this design's compensation around it, or unchanged when there is
    /// none. `controller` should plan within [`bounds`](Self::bounds).
    pub fn compensate<'a>(&self, controller: Box<dyn Controller + 'a>) -> Box<dyn Controller + 'a> {
        match self.compensation {
            Some(law) => Box::new(Compensated::new(controller, law)),
            None => controller,
        }
    }

    /// LQR: `K` on measured angles and filtered-difference rates (and `k_i` on the integrated
    /// arm error, when there is integral action), clamped to the input bounds; with
    /// `lqr.disturbance_bandwidth` > 0, cancelling the estimate of a disturbance at the plant
    /// input ([`Lqr::with_input_disturbance_cancelled`] on the design model).
    pub fn lqr(&self) -> Result<Lqr, SpecError> {
        let (lo, hi) = self.bounds();
        let lqr = Lqr::new(&self.k, self.ts, self.spec.lqr.rate_cutoff)
            .and_then(|c| c.with_input_bounds(lo, hi))
            .and_then(|c| c.with_integral_action(self.integral_gain.unwrap_or(0.0)))
            .map_err(|e| SpecError::new("lqr.rate_cutoff", e.to_string()))?;
        let bandwidth = self.spec.lqr.disturbance_bandwidth;
        if bandwidth == 0.0 {
            return Ok(lqr);
        }
        lqr.with_input_disturbance_cancelled(
            &self.a,
            &self.b,
            bandwidth,
            self.spec.sensor.angle_variance(),
        )
        .map_err(|e| SpecError::new("lqr.disturbance_bandwidth", e.to_string()))
    }

    /// LQG: `K` on the shared Kalman filter's estimate.
    ///
    /// The filter is designed on the MPC's scaled outputs `y/s_y`; LQG reads engineering
    /// units, so it runs the same filter with `C' = S_y C_aug`, `L' = L S_y⁻¹`,
    /// `M' = M S_y⁻¹`, whose innovation `y − C' x̂ = S_y (y/s_y − C_aug x̂)` gives the same
    /// corrections.
    ///
    /// With `kalman.input_disturbance` > 0, LQG runs its own filter instead, with a
    /// disturbance at the plant input whose estimate its law cancels
    /// ([`Lqg::with_input_disturbance_cancelled`]; designed with the spec, the model and the
    /// noise in the docs of `input_disturbance_filter`). With `kalman.regulate_outputs`, its law
    /// regulates the estimated outputs ([`Lqg::with_outputs_regulated`]).
    pub fn lqg(&self) -> Result<Lqg, SpecError> {
        let (lo, hi) = self.bounds();
        if let Some(f) = &self.lqg_filter {
            return Lqg::new(&self.k, &f.a, &f.b, &f.c, &f.l, &f.m, self.ts)
                .and_then(|g| g.with_input_bounds(lo, hi))
                .and_then(|g| g.with_integral_action(self.integral_gain.unwrap_or(0.0)))
                .and_then(Lqg::with_input_disturbance_cancelled)
                .map_err(|e| SpecError::new("kalman.input_disturbance", e.to_string()));
        }
        let model = self.estimator.model();
        let kf = self.estimator.kalman();
        let sy = &self.spec.mpc.output_scales;
        let mut c = model.c.clone();
        let mut l = kf.l.clone();
        let mut m = kf.m.clone();
        for (i, &s) in sy.iter().enumerate() {
            c.row_mut(i).scale_mut(s);
            l.column_mut(i).scale_mut(1.0 / s);
            m.column_mut(i).scale_mut(1.0 / s);
        }
        let lqg = Lqg::new(&self.k, &model.a, &model.b, &c, &l, &m, self.ts)
            .and_then(|g| g.with_input_bounds(lo, hi))
            .and_then(|g| g.with_integral_action(self.integral_gain.unwrap_or(0.0)));
        let lqg = if self.spec.kalman.regulate_outputs {
            lqg.and_then(Lqg::with_outputs_regulated)
        } else {
            lqg
        };
        lqg.map_err(|e| SpecError::new("kalman", format!("the LQG estimator: {e}")))
    }

    /// The MPC of `[mpc]` on the shared Kalman filter, planning within
    /// [`bounds`](Self::bounds).
    pub fn mpc(&self) -> Result<Mpc, SpecError> {
        let mut settings = self.spec.mpc_settings();
        settings.input_bounds = vec![self.bounds()];
        Mpc::with_estimator(&self.estimator, self.ts, settings).map_err(|e| {
            // On checked settings, what remains is the condensed problem's conditioning,
            // which `Mpc` reports as an `InvalidParameter` naming the `MpcSettings` field,
            // i.e. the [mpc] key, at fault.
            let key = match &e {
                RipError::InvalidParameter { name, .. } => format!("mpc.{name}"),
                _ => "mpc".to_string(),
            };
            SpecError::new(key, format!("the MPC design fails: {e}"))
        })
    }

    /// The MPC as `rip-rt`, the simulations and `riprs compare` run it, planning within
    /// [`bounds`](Self::bounds): [`mpc`](Self::mpc)'s design stepped by rip-control, the code
    /// the device runs, whenever that computes the same move
    /// ([`Mpc::run_time_controller`]: the active-set solver, a design within rip-control's
    /// capacities); otherwise the general [`Mpc`] itself (Clarabel, a design too large for
    /// the device).
    pub fn run_time_mpc(&self) -> Result<Box<dyn Controller>, SpecError> {
        let mpc = self.mpc()?;
        Ok(match mpc.run_time_controller() {
            Some(onboard) => Box::new(onboard),
            None => Box::new(mpc),
        })
    }

    /// The controller `kind` as it runs: [`balance`](Self::balance) with the compensation
    /// around it ([`compensate`](Self::compensate)).
    pub fn controller(&self, kind: ControllerKind) -> Result<Box<dyn Controller>, SpecError> {
        Ok(self.compensate(self.balance(kind)?))
    }

    /// The controller `kind` without the compensation, planning within
    /// [`bounds`](Self::bounds): for a supervisor that puts the compensation around itself.
    pub fn balance(&self, kind: ControllerKind) -> Result<Box<dyn Controller>, SpecError> {
        Ok(match kind {
            ControllerKind::Lqr => Box::new(self.lqr()?),
            ControllerKind::Lqg => Box::new(self.lqg()?),
            ControllerKind::Mpc => self.run_time_mpc()?,
        })
    }

    /// Builds every controller kind once, so that a file that cannot be designed is refused
    /// before any run; returns the spec's `controllers`, in order.
    pub fn controllers(&self) -> Result<Vec<Built>, SpecError> {
        let mut out = Vec::new();
        for kind in ControllerKind::ALL {
            let c = self.controller(kind)?;
            if self.spec.controllers.contains(&kind) {
                out.push((kind, c));
            }
        }
        out.sort_by_key(|(k, _)| self.spec.controllers.iter().position(|c| c == k));
        Ok(out)
    }
}

impl EnvConfig {
    /// The environment of an experiment file's `[plant]`, `[sensor]`, voltage bound
    /// (`[mpc] input_bounds`), rate filter (`[lqr] rate_cutoff`) and arm limit
    /// (`[swing_up] arm_limit`), as `riprs compare` simulates it at period `ts`; every other
    /// setting at its default.
    pub fn from_spec(spec: &Spec, task: Task, ts: f64) -> Self {
        let sim = spec.sim_config(ts, 0);
        Self {
            task,
            params: spec.plant.params(),
            ts,
            substeps: sim.substeps,
            u_limit: sim.u_limit,
            sensor: sim.sensor,
            rate_cutoff_hz: spec.lqr.rate_cutoff,
            max_steps: (crate::sim::DEFAULT_DURATION / ts).round().max(1.0) as u32,
            fall_limit: sim.fall_limit,
            arm_limit: spec.swing_up.arm_limit,
            ..Self::default()
        }
    }
}
