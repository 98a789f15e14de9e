//! The paper's two linear regulators behind the [`Controller`] interface: [`Lqr`] (measured
//! angles, rates from a filtered difference, no estimator) and [`Lqg`] (the same gain on the
//! state of the steady-state Kalman filter in current form).
//!
//! Both track a reference for the two outputs `r = [θ_ref, α_ref]` (the paper steps θ from 0 to
//! 1 rad; α_ref is normally 0) through the state reference `x_ref = [θ_ref, 0, α_ref, 0]`:
//!
//! ```text
//! u[k] = sat(−K (x̂[k] − x_ref[k]),  u_min, u_max),     K = dlqr(A_d, B_d, Q, R)   (eq. (13))
//! ```
//!
//! This is exact steady-state tracking for this plant because θ is a pure integrator: any
//! constant `[θ_ref, 0, 0, 0]` is an equilibrium with `u = 0`. Both clamp to their input bounds
//! (default ±12 V, the paper's actuator limit) and write only finite inputs.
//!
//! # Integral action (optional)
//!
//! A constant torque on the arm (friction left over by the compensation, a cable, a tilt)
//! needs a constant voltage, which `−K(x − x_ref)` only gives with an arm offset. With
//! [`with_integral_action`](Lqr::with_integral_action), in the manner of MATLAB's `lqi` for
//! discrete systems, the arm error is integrated and fed back as well:
//!
//! ```text
//! x_i[k+1] = x_i[k] + Ts (θ_ref[k] − θ[k])          θ: the measured arm angle
//! u[k]     = sat(−K_x (x̂[k] − x_ref[k]) − k_i x_i[k],  u_min, u_max)
//! [K_x k_i] = dlqr([A_d 0; −Ts e_θᵀ 1], [B_d; 0], diag(Q, q_i), R)
//! ```
//!
//! Anti-windup by conditional integration: while `u` is held at a bound, the integrator does
//! not move in the direction that would push it further in. Bumpless start: `x_i` is zero
//! after construction, [`reset`](Controller::reset), [`seed`](Controller::seed) and every
//! [`observe`](Controller::observe) (a sample whose input someone else chose, such as the
//! swing-up's), so the first own move after a catch is the plain `−K_x(x̂ − x_ref)`.
//!
//! # One implementation
//!
//! Both step with [`rip_control::Controller`], the `no_std` code `rip-rt` and the firmware run
//! too: these types check their arguments, build the [`rip_control::Design`]
//! ([`Lqr::control_design`], [`Lqg::control_design`]) and hand every step to an
//! [`OnboardController`], which converts at the boundary (the run-time MPC uses the same).

use nalgebra::SMatrix;

use crate::controller::{Controller, StepStatus};
use crate::error::{Result, RipError};
use crate::linalg::{check_finite, check_shape, Mat};
use crate::lqr::dlqr;
use crate::onboard::{put, ControlDesign, ControlKind, OnboardController};
use crate::paper;

/// Default cut-off (Hz) of [`Lqr`]'s rate filter.
pub const DEFAULT_RATE_CUTOFF_HZ: f64 = 20.0;

/// Number of plant states `[θ, θ̇, α, α̇]`.
const NX: usize = 4;

/// The rate estimate of [`Lqr`] (its type docs give the equations) for the two angles
/// `[θ, α]`: the backward difference through a first-order low-pass, over all the periods
/// held since the last measured angle. The one definition of the rig's rate estimate
/// (rip-control's): the reinforcement-learning environments observe the same
/// ([`crate::sim::vec_env::Observer`]). Allocation-free and `Copy`.
pub type RateFilter = rip_control::RateFilter<f64>;

fn check_bounds(u_min: f64, u_max: f64) -> Result<()> {
    if !(u_min.is_finite() && u_max.is_finite() && u_min < u_max) {
        return Err(RipError::invalid(
            "input bounds",
            format!("need finite u_min < u_max, got [{u_min}, {u_max}]"),
        ));
    }
    Ok(())
}

fn check_integral_gain(gain: f64) -> Result<()> {
    if !gain.is_finite() {
        return Err(RipError::invalid(
            "integral_gain",
            format!("must be finite, got {gain}"),
        ));
    }
    Ok(())
}

fn gain_row(k: &Mat) -> Result<SMatrix<f64, 1, NX>> {
    check_shape("K", k, 1, NX)?;
    check_finite("K", k)?;
    Ok(SMatrix::<f64, 1, NX>::from_fn(|_, j| k[(0, j)]))
}

/// LQR on measured angles with rates from a filtered difference (the paper's section 4: "the
/// states are measured and computed", no estimator).
///
/// Each sample the rate of each angle `q ∈ {θ, α}` is the backward difference passed through a
/// first-order low-pass filter (the zero-order-hold discretisation of `ωc/(s + ωc)`):
///
/// ```text
/// d[k] = (q[k] − q[k−1]) / Ts,     q̇̂[k] = a q̇̂[k−1] + (1 − a) d[k],     a = e^{−2π f_c Ts}
/// ```
///
/// with `f_c` the cut-off ([`DEFAULT_RATE_CUTOFF_HZ`]; `f64::INFINITY` gives the plain
/// difference, `a = 0`). On the first sample after construction or [`reset`](Controller::reset)
/// there is no previous angle and the rates start at zero. Then
/// `x̂ = [θ, θ̇̂, α, α̇̂]` and `u = sat(−K(x̂ − x_ref))` (module docs).
///
/// When `n − 1` periods were [held](Controller::hold) since the last measured angle, the
/// difference spans `n` periods and the filter advances over all of them at once (the same
/// zero-order-hold discretisation with step `n Ts`):
///
/// ```text
/// d[k] = (q[k] − q[k−n]) / (n Ts),     q̇̂[k] = aⁿ q̇̂[k−n] + (1 − aⁿ) d[k]
/// ```
///
/// During a held period the estimate `x̂` is left as it was. A sample whose angles, or the
/// rates computed from them, are not finite is treated the same way: discarded, the period
/// counted as held, the move computed on the kept `x̂` and reported as
/// [`StepStatus::Fallback`].
///
/// # Input disturbance (optional)
///
/// What the compensation leaves of a dead zone, friction or breakaway torque acts as a slowly
/// varying voltage `d` at the plant input, `x[k+1] = A_d x + B_d (u + d)`. With
/// [`with_input_disturbance_cancelled`](Lqr::with_input_disturbance_cancelled) the regulator
/// estimates it from how `x̂` departs from the model's prediction, and cancels it:
///
/// ```text
/// d̂[k]    = d̂[k−1] + g (x̂[k] − x̂⁻[k]),        g = γ B_dᵀ W / (B_dᵀ W B_d)
/// u[k]     = sat(−K (x̂[k] − x_ref) − k_i x_i[k] − d̂[k])
/// x̂⁻[k+1] = A_d x̂[k] + B_d (u[k] + d̂[k])
/// ```
///
/// On the model (with the exact state) `x̂ − x̂⁻ = B_d (d − d̂)`, so the estimate's error
/// shrinks by `1 − γ` per period: a first-order observer of bandwidth
/// `f_d = −ln(1 − γ) / (2π Ts)`. `g / γ` is the weighted least-squares reading of one period's
/// departure, `W = diag(1/v_θ, 1/v_θ̇, 1/v_α, 1/v_α̇)` the inverse noise variances of `x̂`: `v` of
/// each angle as measured, and of its rate through the filter,
/// `v_q̇ = v_q · 2 (1 − a)² / ((1 + a) Ts²)` (white angle noise through the filtered
/// difference), so that a coarse encoder's noisy rate weighs less. A held period carries `x̂⁻` over with the model; `d̂` is
/// zero after construction, [`reset`](Controller::reset), [`seed`](Controller::seed) and
/// every [`observe`](Controller::observe) (bumpless, as the integrator).
#[derive(Debug, Clone)]
pub struct Lqr {
    inner: OnboardController,
}

impl Lqr {
    /// An LQR with gain `k` (1×4, `u = −K x`), sample time `ts` (s) and rate-filter cut-off
    /// `rate_cutoff_hz` (Hz, positive; infinity for no filtering). Input bounds ±12 V.
    pub fn new(k: &Mat, ts: f64, rate_cutoff_hz: f64) -> Result<Self> {
        let k = gain_row(k)?;
        crate::linalg::check_sample_time("Ts", ts)?;
        if rate_cutoff_hz.is_nan() || rate_cutoff_hz <= 0.0 {
            return Err(RipError::invalid(
                "rate_cutoff",
                format!("must be positive (or infinite), got {rate_cutoff_hz}"),
            ));
        }
        let mut d = ControlDesign {
            kind: ControlKind::Lqr,
            ts,
            input_bounds: [-paper::INPUT_LIMIT, paper::INPUT_LIMIT],
            rate_cutoff_hz,
            ..ControlDesign::default()
        };
        d.k.copy_from_slice(k.as_slice());
        Ok(Self {
            inner: OnboardController::new(&d)?,
        })
    }

    /// Designs `K = dlqr(A_d, B_d, Q, R)` and builds the regulator.
    pub fn design(
        ad: &Mat,
        bd: &Mat,
        q: &Mat,
        r: &Mat,
        ts: f64,
        rate_cutoff_hz: f64,
    ) -> Result<Self> {
        check_shape("A", ad, NX, NX)?;
        check_shape("B", bd, NX, 1)?;
        let design = dlqr(ad, bd, q, r, None)?;
        Self::new(&design.k, ts, rate_cutoff_hz)
    }

    fn rebuilt(mut self, edit: impl FnOnce(&mut ControlDesign)) -> Result<Self> {
        self.inner = self.inner.rebuilt(edit)?;
        Ok(self)
    }

    /// Replaces the input bounds (must be finite with `u_min < u_max`).
    pub fn with_input_bounds(self, u_min: f64, u_max: f64) -> Result<Self> {
        check_bounds(u_min, u_max)?;
        self.rebuilt(|d| d.input_bounds = [u_min, u_max])
    }

    /// Adds integral action on the arm error with gain `k_i` (module docs): `K` is then the
    /// state part `K_x` of the augmented design. A zero gain is no integral action.
    pub fn with_integral_action(self, k_i: f64) -> Result<Self> {
        check_integral_gain(k_i)?;
        self.rebuilt(|d| d.integral_gain = k_i)
    }

    /// The integral gain `k_i`, when the regulator has integral action.
    pub fn integral_gain(&self) -> Option<f64> {
        let g = self.inner.design().integral_gain;
        (g != 0.0).then_some(g)
    }

    /// Adds an observer of a disturbance `d` at the plant input, on the design model
    /// `x[k+1] = A_d x + B_d (u + d)` (`ad` 4×4, `bd` 4×1), whose estimate the law cancels
    /// (type docs, "Input disturbance"). `bandwidth_hz` (positive, finite) sets the observer's
    /// pole `1 − γ`, `γ = 1 − e^{−2π f_d Ts}`; `angle_variance` (rad², positive) is each
    /// measured angle's noise variance, which weighs the rows of `x̂` the estimate is read
    /// from.
    pub fn with_input_disturbance_cancelled(
        self,
        ad: &Mat,
        bd: &Mat,
        bandwidth_hz: f64,
        angle_variance: [f64; 2],
    ) -> Result<Self> {
        check_shape("A", ad, NX, NX)?;
        check_shape("B", bd, NX, 1)?;
        check_finite("A", ad)?;
        check_finite("B", bd)?;
        if !(bandwidth_hz.is_finite() && bandwidth_hz > 0.0) {
            return Err(RipError::invalid(
                "disturbance_bandwidth",
                format!("must be positive and finite (Hz), got {bandwidth_hz}"),
            ));
        }
        if !angle_variance.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(RipError::invalid(
                "angle_variance",
                format!("must be positive and finite (rad²), got {angle_variance:?}"),
            ));
        }
        let ts = self.ts();
        let a = (-2.0 * std::f64::consts::PI * self.rate_cutoff_hz() * ts).exp();
        let rate = 2.0 * (1.0 - a).powi(2) / ((1.0 + a) * ts * ts);
        let [vt, va] = angle_variance;
        let weight = [1.0 / vt, 1.0 / (rate * vt), 1.0 / va, 1.0 / (rate * va)];
        let norm: f64 = (0..NX).map(|i| weight[i] * bd[(i, 0)].powi(2)).sum();
        if !(norm.is_finite() && norm > 0.0) {
            return Err(RipError::invalid(
                "B",
                "the input must move the state for a disturbance at it to be observed",
            ));
        }
        let gamma = -(-2.0 * std::f64::consts::PI * bandwidth_hz * ts).exp_m1();
        self.rebuilt(|d| {
            d.cancels_input_disturbance = true;
            d.nx = NX;
            d.a[..NX * NX].copy_from_slice(ad.transpose().as_slice());
            d.b[..NX].copy_from_slice(bd.as_slice());
            for i in 0..NX {
                d.disturbance_gain[i] = gamma * weight[i] * bd[(i, 0)] / norm;
            }
        })
    }

    /// Whether the law cancels an estimated input disturbance
    /// ([`with_input_disturbance_cancelled`](Self::with_input_disturbance_cancelled)).
    pub fn cancels_input_disturbance(&self) -> bool {
        self.inner.design().cancels_input_disturbance
    }

    /// The input disturbance `d̂` (V) the law cancels now (zero without the observer).
    pub fn input_disturbance(&self) -> f64 {
        self.inner.control().input_disturbance()
    }

    /// The gain `K` (1×4).
    pub fn gain(&self) -> Mat {
        Mat::from_row_slice(1, NX, &self.inner.design().k)
    }

    /// Sample time (s).
    pub fn ts(&self) -> f64 {
        self.inner.design().ts
    }

    /// Rate-filter cut-off (Hz).
    pub fn rate_cutoff_hz(&self) -> f64 {
        self.inner.design().rate_cutoff_hz
    }

    /// Input bounds `(u_min, u_max)`.
    pub fn input_bounds(&self) -> (f64, f64) {
        let [lo, hi] = self.inner.design().input_bounds;
        (lo, hi)
    }

    /// The design rip-control runs for this regulator ([`crate::onboard`]).
    pub fn control_design(&self) -> ControlDesign {
        self.inner.design().clone()
    }

    /// The integrator state `x_i` (zero without integral action).
    pub fn integrator(&self) -> f64 {
        self.inner.control().integrator()
    }
}

impl Controller for Lqr {
    fn n_outputs(&self) -> usize {
        2
    }

    fn n_inputs(&self) -> usize {
        1
    }

    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        self.inner.step(y, r, u)
    }

    /// The estimate update of [`step`](Controller::step) (an unusable sample counts as held);
    /// with the input-disturbance observer, the estimate is cleared and `u` starts the
    /// model's prediction (type docs).
    fn observe(&mut self, y: &[f64], u: &[f64]) {
        self.inner.observe(y, u);
    }

    /// `x̂ = x`, the next rate difference taken from this sample's angles; the
    /// input-disturbance estimate cleared and `u` starting the model's prediction.
    fn seed(&mut self, x: &[f64], u: &[f64]) {
        self.inner.seed(x, u);
    }

    /// Counts the period, so that the next rate difference spans it (type docs); the
    /// input-disturbance observer's prediction advances over it with `u`.
    fn hold(&mut self, u: &[f64]) {
        self.inner.hold(u);
    }

    fn reset(&mut self) {
        self.inner.reset();
    }

    fn sample_time(&self) -> Option<f64> {
        Some(self.ts())
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        self.inner.state_estimate()
    }
}

/// LQG: the LQR gain applied to the plant part of the current Kalman estimate `x̂[k|k]`
/// (paper eqs. (3)–(6) with the gains of eq. (11)).
///
/// The estimator model is `x[k+1] = A x + B_u u`, `y = C x` with `n ≥ 4` states whose first four
/// are the plant's `[θ, θ̇, α, α̇]`; the rest (e.g. the paper's output-disturbance integrator)
/// are used by the estimator but not fed back, unless the law
/// [regulates the estimated outputs](Self::with_outputs_regulated). Each sample:
///
/// ```text
/// e[k]     = y[k] − C x̂[k|k−1]
/// x̂[k|k]   = x̂[k|k−1] + M e[k]                                  (5)
/// u[k]     = sat(−K (x̂_plant[k|k] − x_ref[k]))
/// x̂[k+1|k] = A x̂[k|k−1] + B_u u[k] + L e[k]                     (4)
/// ```
///
/// The prediction uses the input actually applied (after clamping). `x̂[0|−1] = 0`.
///
/// A [held](Controller::hold) period with input `u_h` has no measurement, so `e = 0`:
/// `x̂[k|k] = x̂[k|k−1]` and `x̂[k+1|k] = A x̂[k|k−1] + B_u u_h`
/// (rip-control's time update without innovation). A sample with non-finite angles, or
/// whose correction overflows, is discarded the same way (`e = 0`), the move computed on
/// `x̂[k|k−1]` and reported as [`StepStatus::Fallback`].
#[derive(Debug, Clone)]
pub struct Lqg {
    inner: OnboardController,
    l: Mat,
    m: Mat,
}

impl Lqg {
    /// Builds the LQG from the gain `k` (1×4), the estimator model `a` (n×n), `b_u` (n×1), `c`
    /// (2×n) and the Kalman gains `l` (predictor) and `m` (innovation), both n×2, as returned by
    /// [`kalman`](crate::kalman::kalman). Input bounds ±12 V. At most
    /// [`rip_control::MAX_NX`] states.
    #[allow(clippy::too_many_arguments)]
    pub fn new(k: &Mat, a: &Mat, b_u: &Mat, c: &Mat, l: &Mat, m: &Mat, ts: f64) -> Result<Self> {
        let k = gain_row(k)?;
        crate::linalg::check_sample_time("Ts", ts)?;
        let others = [
            ("B", b_u.nrows()),
            ("C", c.ncols()),
            ("L", l.nrows()),
            ("M", m.nrows()),
        ];
        let n = crate::linalg::check_state_matrix("A", a, &others)?;
        if n < NX {
            return Err(RipError::Shape {
                name: "A".into(),
                expected: "(n, n) with n >= 4".into(),
                rows: a.nrows(),
                cols: a.ncols(),
            });
        }
        check_shape("B", b_u, n, 1)?;
        check_shape("C", c, 2, n)?;
        check_shape("L", l, n, 2)?;
        check_shape("M", m, n, 2)?;
        for (name, x) in [("A", a), ("B", b_u), ("C", c), ("L", l), ("M", m)] {
            check_finite(name, x)?;
        }
        let mut d = ControlDesign {
            kind: ControlKind::Lqg,
            ts,
            input_bounds: [-paper::INPUT_LIMIT, paper::INPUT_LIMIT],
            nx: n,
            ny: 2,
            ..ControlDesign::default()
        };
        d.k.copy_from_slice(k.as_slice());
        let cap = rip_control::MAX_NX;
        put("A", &mut d.a, a, cap, cap)?;
        put("B", &mut d.b, b_u, cap, 1)?;
        put("C", &mut d.c, c, rip_control::MAX_NY, cap)?;
        put("L", &mut d.l, l, cap, rip_control::MAX_NY)?;
        put("M", &mut d.m, m, cap, rip_control::MAX_NY)?;
        Ok(Self {
            inner: OnboardController::new(&d)?,
            l: l.clone(),
            m: m.clone(),
        })
    }

    fn rebuilt(mut self, edit: impl FnOnce(&mut ControlDesign)) -> Result<Self> {
        self.inner = self.inner.rebuilt(edit)?;
        Ok(self)
    }

    /// Replaces the input bounds (must be finite with `u_min < u_max`).
    pub fn with_input_bounds(self, u_min: f64, u_max: f64) -> Result<Self> {
        check_bounds(u_min, u_max)?;
        self.rebuilt(|d| d.input_bounds = [u_min, u_max])
    }

    /// Adds integral action on the arm error with gain `k_i` (module docs): `K` is then the
    /// state part `K_x` of the augmented design. A zero gain is no integral action.
    pub fn with_integral_action(self, k_i: f64) -> Result<Self> {
        check_integral_gain(k_i)?;
        self.rebuilt(|d| d.integral_gain = k_i)
    }

    /// The integral gain `k_i`, when the regulator has integral action.
    pub fn integral_gain(&self) -> Option<f64> {
        let g = self.inner.design().integral_gain;
        (g != 0.0).then_some(g)
    }

    /// Makes the estimator's last state a disturbance at the plant input that the law cancels,
    /// `u = −K (x̂ − x_ref) − d̂` (rip-control's `Design::cancels_input_disturbance`); the
    /// estimator given to [`new`](Self::new) must model it (`x[k+1] = A x + B (u + d)`, at
    /// least 5 states).
    pub fn with_input_disturbance_cancelled(self) -> Result<Self> {
        self.rebuilt(|d| d.cancels_input_disturbance = true)
    }

    /// Whether the law cancels an estimated input disturbance.
    pub fn cancels_input_disturbance(&self) -> bool {
        self.inner.design().cancels_input_disturbance
    }

    /// Makes the law regulate the estimated outputs: each angle's state takes on what the
    /// estimator's states beyond the plant's four add to that output (their columns `C_e` of
    /// `C`, in the angles' units here), `θ̂ ← θ̂ + (C_e x̂_e)_θ`, `α̂ ← α̂ + (C_e x̂_e)_α`, then
    /// `u = sat(−K (x̂ − x_ref))` (rip-control's `Design::regulates_outputs`). With the paper's
    /// output disturbance the plant part alone drifts with the disturbance estimate; the
    /// estimated output does not.
    ///
    /// # Errors
    /// An estimator with no state beyond the plant's four, or one whose law
    /// [cancels an input disturbance](Self::with_input_disturbance_cancelled).
    pub fn with_outputs_regulated(self) -> Result<Self> {
        self.rebuilt(|d| d.regulates_outputs = true)
    }

    /// Whether the law regulates the estimated outputs ([`with_outputs_regulated`](Self::with_outputs_regulated)).
    pub fn regulates_outputs(&self) -> bool {
        self.inner.design().regulates_outputs
    }

    /// The gain `K` (1×4).
    pub fn gain(&self) -> Mat {
        Mat::from_row_slice(1, NX, &self.inner.design().k)
    }

    /// The design rip-control runs for this regulator ([`crate::onboard`]).
    ///
    /// # Errors
    /// None today (the constructor checked the capacity); kept fallible for designs that
    /// grow.
    pub fn control_design(&self) -> Result<ControlDesign> {
        Ok(self.inner.design().clone())
    }

    /// The integrator state `x_i` (zero without integral action).
    pub fn integrator(&self) -> f64 {
        self.inner.control().integrator()
    }

    /// Predictor gain `L` (n×2).
    pub fn predictor_gain(&self) -> &Mat {
        &self.l
    }

    /// Innovation gain `M` (n×2).
    pub fn innovation_gain(&self) -> &Mat {
        &self.m
    }

    /// Number of estimator states `n`.
    pub fn n_states(&self) -> usize {
        self.l.nrows()
    }

    /// Sample time (s).
    pub fn ts(&self) -> f64 {
        self.inner.design().ts
    }

    /// Input bounds `(u_min, u_max)`.
    pub fn input_bounds(&self) -> (f64, f64) {
        let [lo, hi] = self.inner.design().input_bounds;
        (lo, hi)
    }
}

impl Controller for Lqg {
    fn n_outputs(&self) -> usize {
        2
    }

    fn n_inputs(&self) -> usize {
        1
    }

    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        self.inner.step(y, r, u)
    }

    /// The correction of [`step`](Controller::step) with `y`, then the prediction with the
    /// applied `u` (a non-finite `u` keeps the last applied input, as in
    /// [`hold`](Controller::hold)).
    fn observe(&mut self, y: &[f64], u: &[f64]) {
        self.inner.observe(y, u);
    }

    /// `x̂[k|k] = [x; 0]`, then `x̂[k+1|k] = A x̂[k|k] + B_u u`.
    fn seed(&mut self, x: &[f64], u: &[f64]) {
        self.inner.seed(x, u);
    }

    /// Advances the estimator over the period with `u` and no innovation (type docs).
    fn hold(&mut self, u: &[f64]) {
        self.inner.hold(u);
    }

    fn reset(&mut self) {
        self.inner.reset();
    }

    fn sample_time(&self) -> Option<f64> {
        Some(self.ts())
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        self.inner.state_estimate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    /// The design model of the paper's rig at 10 ms.
    fn paper_model() -> (Mat, Mat) {
        let d = crate::spec::Spec::default().design(0.01).unwrap();
        (d.a.clone(), d.b.clone())
    }

    #[test]
    fn the_lqr_observer_reads_an_unbiased_disturbance_weighted_by_the_sensor() {
        let (a, b) = paper_model();
        let gain = |variance: [f64; 2]| {
            let lqr = Lqr::paper()
                .unwrap()
                .with_input_disturbance_cancelled(&a, &b, 2.0, variance)
                .unwrap();
            lqr.control_design().disturbance_gain
        };
        let gamma = 1.0 - (-2.0 * std::f64::consts::PI * 2.0 * 0.01).exp();
        let even = gain([1e-6, 1e-6]);
        let coarse = gain([1e-6, 1e-4]);
        for g in [even, coarse] {
            // Unbiased: a departure B δd is read as δd, times γ.
            let read: f64 = (0..NX).map(|i| g[i] * b[(i, 0)]).sum();
            assert!((read - gamma).abs() < 1e-12, "{read} {gamma}");
        }
        // A noisier pendulum encoder: its rows weigh less against the arm's.
        assert!(coarse[3].abs() / coarse[1].abs() < 0.02 * even[3].abs() / even[1].abs());
    }

    #[test]
    fn the_lqr_cancels_a_constant_disturbance_on_its_model() {
        // The closed loop on the design model with a constant 0.8 V at the plant input and
        // exact angles: the estimate settles on the disturbance and the state on the origin;
        // the paper's LQR holds an arm offset instead.
        let (a, b) = paper_model();
        let run = |mut lqr: Lqr| {
            let mut x = DVector::from_vec(vec![0.05, 0.0, 0.02, 0.0]);
            let mut u = [0.0];
            for _ in 0..800 {
                lqr.step(&[x[0], x[2]], &[0.0, 0.0], &mut u);
                x = &a * &x + &b * (u[0] + 0.8);
            }
            (x, lqr.input_disturbance())
        };
        let observed = Lqr::paper()
            .unwrap()
            .with_input_disturbance_cancelled(&a, &b, 2.0, [1e-6, 1e-6])
            .unwrap();
        let (x, d) = run(observed);
        assert!((d - 0.8).abs() < 1e-6, "{d}");
        assert!(x.amax() < 1e-6, "{x}");
        let (x, d) = run(Lqr::paper().unwrap());
        assert_eq!(d, 0.0);
        assert!(x[0].abs() > 1e-3, "{x}");
    }

    #[test]
    fn the_lqr_observer_refuses_what_it_cannot_use() {
        let (a, b) = paper_model();
        let lqr = || Lqr::paper().unwrap();
        for bw in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(lqr()
                .with_input_disturbance_cancelled(&a, &b, bw, [1e-6, 1e-6])
                .is_err());
        }
        for v in [[0.0, 1e-6], [1e-6, f64::NAN]] {
            assert!(lqr()
                .with_input_disturbance_cancelled(&a, &b, 2.0, v)
                .is_err());
        }
        let zero = Mat::zeros(4, 1);
        assert!(lqr()
            .with_input_disturbance_cancelled(&a, &zero, 2.0, [1e-6, 1e-6])
            .is_err());
    }

    #[test]
    fn an_unusable_sample_leaves_no_nan_behind() {
        for bad in [f64::NAN, f64::INFINITY, 1e308] {
            let mut lqr = Lqr::paper().unwrap();
            let mut twin = Lqr::paper().unwrap();
            let mut lqg = Lqg::paper().unwrap();
            let mut lqg_twin = Lqg::paper().unwrap();
            let r = [0.0, 0.0];
            let mut u = [0.0];
            let mut v = [0.0];
            for k in 0..5 {
                let y = [0.01 * f64::from(k), 0.02];
                lqr.step(&y, &r, &mut u);
                twin.step(&y, &r, &mut v);
                lqg.step(&y, &r, &mut u);
                lqg_twin.step(&y, &r, &mut v);
            }
            // The bad sample is a held period for the twins.
            assert_eq!(lqr.step(&[bad, 0.02], &r, &mut u), StepStatus::Fallback);
            assert!(u[0].is_finite());
            twin.hold(&[u[0]]);
            let status = lqg.step(&[0.05, bad], &r, &mut u);
            if bad.is_finite() {
                // 1e308 is finite: the LQG's correction does not overflow (M is small), so the
                // sample is used; only the LQR's rate overflows.
                assert!(lqg.state_estimate().unwrap().iter().all(|v| v.is_finite()));
                continue;
            }
            assert_eq!(status, StepStatus::Fallback);
            lqg_twin.hold(&[u[0]]);
            let y = [0.06, 0.03];
            lqr.step(&y, &r, &mut u);
            twin.step(&y, &r, &mut v);
            assert_eq!(u, v, "LQR after {bad}");
            assert!(lqr.state_estimate().unwrap().iter().all(|v| v.is_finite()));
            lqg.step(&y, &r, &mut u);
            lqg_twin.step(&y, &r, &mut v);
            assert!(
                (u[0] - v[0]).abs() < 1e-12,
                "LQG after {bad}: {} vs {}",
                u[0],
                v[0]
            );
        }
    }

    #[test]
    fn lqr_rate_filter_follows_a_ramp_and_clamps() {
        let k = Mat::from_row_slice(1, 4, &[0.0, 1.0, 0.0, 0.0]);
        let mut c = Lqr::new(&k, 0.01, 20.0).unwrap();
        let mut u = [0.0];
        // θ ramps at 2 rad/s: the filtered difference converges to 2 and u = −K x̂ → −2.
        for i in 0..200 {
            c.step(&[0.02 * i as f64, 0.0], &[0.0, 0.0], &mut u);
        }
        assert!((u[0] + 2.0).abs() < 1e-9, "{}", u[0]);
        let k = Mat::from_row_slice(1, 4, &[100.0, 0.0, 0.0, 0.0]);
        let mut c = Lqr::new(&k, 0.01, 20.0).unwrap();
        c.step(&[1.0, 0.0], &[0.0, 0.0], &mut u);
        assert_eq!(u[0], -12.0);
        // An unusable sample keeps x̂, so the move stays the feedback on it.
        assert_eq!(
            c.step(&[f64::NAN, 0.0], &[0.0, 0.0], &mut u),
            StepStatus::Fallback
        );
        assert_eq!(u[0], -12.0);
    }

    #[test]
    fn lqg_step_is_the_current_estimator_equations() {
        let mut c = Lqg::paper().unwrap();
        let aug = paper::augmented_model();
        let kf = paper::kalman_design().unwrap();
        let k = c.gain();
        let mut bu = Mat::zeros(5, 1);
        bu.view_mut((0, 0), (4, 1))
            .copy_from(&paper::discrete_model().b);
        let mut prior = DVector::<f64>::zeros(5);
        let mut u = [0.0];
        for i in 0..50 {
            let y = [0.01 * (i as f64).sin(), 0.002 * i as f64];
            let r = [1.0, 0.0];
            c.step(&y, &r, &mut u);
            let e = DVector::from_row_slice(&y) - &aug.c * &prior;
            let post = &prior + &kf.m * &e;
            let err = DVector::from_row_slice(&[post[0] - 1.0, post[1], post[2], post[3]]);
            let want = (-(&k * err)[0]).clamp(-12.0, 12.0);
            assert!((u[0] - want).abs() < 1e-12, "step {i}");
            prior = &aug.a * &prior + &bu * want + &kf.l * &e;
        }
    }

    #[test]
    fn lqr_rate_spans_held_periods() {
        // θ = 0.01 k (1 rad/s) with sample 4 missing: the difference over the gap covers two
        // periods, so the rate, and u = −θ̇̂, stay at −1 instead of jumping to −2.
        let k = Mat::from_row_slice(1, 4, &[0.0, 1.0, 0.0, 0.0]);
        let mut c = Lqr::new(&k, 0.01, f64::INFINITY).unwrap();
        let mut u = [0.0];
        let mut applied = Vec::new();
        for i in 0..8 {
            if i == 4 {
                c.hold(&u);
                continue;
            }
            c.step(&[0.01 * i as f64, 0.0], &[0.0, 0.0], &mut u);
            applied.push(u[0]);
        }
        assert_eq!(applied[0], 0.0);
        for (i, v) in applied.iter().enumerate().skip(1) {
            assert!((v + 1.0).abs() < 1e-12, "sample {i}: {v}");
        }

        // With the filter on, a settled ramp estimate stays settled over three held periods.
        let mut c = Lqr::new(&k, 0.01, 20.0).unwrap();
        let mut i = 0;
        for _ in 0..200 {
            c.step(&[0.02 * i as f64, 0.5], &[0.0, 0.0], &mut u);
            i += 1;
        }
        assert!((u[0] + 2.0).abs() < 1e-9, "{}", u[0]);
        for _ in 0..3 {
            c.hold(&u);
            i += 1;
        }
        c.step(&[0.02 * i as f64, 0.5], &[0.0, 0.0], &mut u);
        assert!((u[0] + 2.0).abs() < 1e-9, "{}", u[0]);
        assert_eq!(c.state_estimate().unwrap()[3], 0.0);

        // An unsettled filter advances over the two periods of a hold with a².
        let mut held = Lqr::new(&k, 0.01, 20.0).unwrap();
        let mut full = held.clone();
        let (mut uh, mut uf) = ([0.0], [0.0]);
        for (j, q) in [0.0, 0.03, 0.01].iter().enumerate() {
            held.step(&[*q, 0.0], &[0.0, 0.0], &mut uh);
            full.step(&[*q, 0.0], &[0.0, 0.0], &mut uf);
            assert_eq!(uh, uf, "sample {j}");
        }
        held.hold(&uh);
        held.step(&[0.05, 0.0], &[0.0, 0.0], &mut uh);
        let a = (-2.0 * std::f64::consts::PI * 20.0 * 0.01f64).exp();
        let rate = full.state_estimate().unwrap()[1];
        let want = a * a * rate + (1.0 - a * a) * (0.05 - 0.01) / 0.02;
        assert!((uh[0] + want).abs() < 1e-12, "{} vs {}", uh[0], -want);
        // reset forgets a pending hold.
        held.hold(&uh);
        held.reset();
        held.step(&[0.0, 0.0], &[0.0, 0.0], &mut uh);
        held.step(&[0.01, 0.0], &[0.0, 0.0], &mut uh);
        full.reset();
        full.step(&[0.0, 0.0], &[0.0, 0.0], &mut uf);
        full.step(&[0.01, 0.0], &[0.0, 0.0], &mut uf);
        assert_eq!(uh, uf);
    }

    #[test]
    fn lqg_hold_is_a_time_update_without_innovation() {
        let mut c = Lqg::paper().unwrap();
        let aug = paper::augmented_model();
        let kf = paper::kalman_design().unwrap();
        let k = c.gain();
        let mut bu = Mat::zeros(5, 1);
        bu.view_mut((0, 0), (4, 1))
            .copy_from(&paper::discrete_model().b);
        let mut prior = DVector::<f64>::zeros(5);
        let mut u = [0.0];
        for i in 0..60 {
            if i % 7 == 3 || i % 11 == 5 {
                // The device keeps applying a command that differs from the last computed one
                // (rounding, the loop's own voltage limit): the estimator must use it.
                let held = u[0] * 0.9 + 0.01;
                c.hold(&[held]);
                let post = c.state_estimate().unwrap();
                assert!(
                    post.iter()
                        .zip(prior.iter())
                        .all(|(a, b)| (a - b).abs() < 1e-12),
                    "step {i}: the posterior of a held period is its prior"
                );
                prior = &aug.a * &prior + &bu * held;
                u[0] = held;
                continue;
            }
            let y = [0.01 * (i as f64).sin(), 0.002 * i as f64];
            let r = [1.0, 0.0];
            c.step(&y, &r, &mut u);
            let e = DVector::from_row_slice(&y) - &aug.c * &prior;
            let post = &prior + &kf.m * &e;
            let err = DVector::from_row_slice(&[post[0] - 1.0, post[1], post[2], post[3]]);
            let want = (-(&k * err)[0]).clamp(-12.0, 12.0);
            assert!((u[0] - want).abs() < 1e-12, "step {i}: {} vs {want}", u[0]);
            prior = &aug.a * &prior + &bu * want + &kf.l * &e;
        }
        // A non-finite held input leaves the estimator on the last applied one.
        let before = c.clone();
        c.hold(&[f64::NAN]);
        assert!(c.state_estimate().unwrap().iter().all(|v| v.is_finite()));
        let mut again = before;
        again.hold(&[u[0]]);
        assert_eq!(c.state_estimate(), again.state_estimate());
    }

    #[test]
    fn integral_action_does_not_wind_up_and_starts_bumpless() {
        let k = Mat::from_row_slice(1, 4, &[10.0, 0.0, 0.0, 0.0]);
        let lqr = Lqr::new(&k, 0.01, f64::INFINITY).unwrap();
        let mut c = lqr.with_integral_action(-50.0).unwrap();
        let mut u = [0.0];
        let zero = [0.0, 0.0];
        // Error 1 rad: the state feedback is 10 V, the integral term adds 50 x_i.
        c.step(&zero, &[1.0, 0.0], &mut u);
        assert_eq!(u[0], 10.0);
        c.step(&zero, &[1.0, 0.0], &mut u);
        assert!((u[0] - 10.5).abs() < 1e-12, "{}", u[0]);
        // At the bound the integrator does not move deeper in: x_i stays 0.02.
        for _ in 0..100 {
            c.step(&zero, &[2.0, 0.0], &mut u);
            assert_eq!(u[0], 12.0);
        }
        c.step(&zero, &zero, &mut u);
        assert!((u[0] - 1.0).abs() < 1e-12, "wound up: {}", u[0]);
        // A sample someone else's input went with clears it, for a bumpless catch.
        c.observe(&zero, &[3.0]);
        c.step(&zero, &zero, &mut u);
        assert_eq!(u[0], 0.0);
        assert_eq!(c.integral_gain(), Some(-50.0));
        assert!(lqr_without_integral_has_none());
        // The LQG clears it on seed the same way.
        let mut g = Lqg::paper().unwrap().with_integral_action(-5.0).unwrap();
        for _ in 0..50 {
            g.step(&[0.0, 0.0], &[1.0, 0.0], &mut u);
        }
        assert!(g.integrator() > 0.0);
        g.seed(&[0.0; 4], &[0.0]);
        assert_eq!(g.integrator(), 0.0);
    }

    fn lqr_without_integral_has_none() -> bool {
        Lqr::paper().unwrap().integral_gain().is_none()
            && Lqr::paper()
                .unwrap()
                .with_integral_action(0.0)
                .unwrap()
                .integral_gain()
                .is_none()
    }

    #[test]
    fn bad_arguments_are_named() {
        let k = Mat::zeros(1, 3);
        assert!(Lqr::new(&k, 0.01, 20.0)
            .unwrap_err()
            .to_string()
            .contains('K'));
        let k = Mat::zeros(1, 4);
        assert!(Lqr::new(&k, 0.0, 20.0)
            .unwrap_err()
            .to_string()
            .contains("Ts"));
        assert!(Lqr::new(&k, 0.01, -1.0)
            .unwrap_err()
            .to_string()
            .contains("rate_cutoff"));
        assert!(Lqr::paper().unwrap().with_input_bounds(3.0, 1.0).is_err());
    }
}
