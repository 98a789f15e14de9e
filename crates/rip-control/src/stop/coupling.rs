//! Which way the arm reading turns relative to the arm the pendulum feels: the sign `s_e` of
//! the arm encoder against the pendulum's convention, from the pendulum's own equation of
//! motion, which holds whatever the motor does.
//!
//! The pendulum's Lagrange equation (rip-core's `plant` module docs) has no motor term:
//!
//! ```text
//! −m₁₂ cos α θ̈ + J_α α̈ − J_α sin α cos α θ̇² − G sin α = −d_p α̇
//! ```
//!
//! With the arm read as `θ_m` and the true arm `θ = s_e θ_m + const` (`s_e = −1` for an arm
//! encoder counting backwards or a wrong `device.arm_sign`, `+1` otherwise, a swapped motor
//! lead included), the readings satisfy
//!
//! ```text
//! y = J_α α̈ − J_α sin α cos α θ̇_m² − G sin α + d_p α̇ = s_e · m₁₂ cos α θ̈_m = s_e x
//! ```
//!
//! Each sample's accelerations are the second differences of three consecutive readings at
//! the period `T`; their noise (one reading's standard deviation `σ`) has variance `6 σ² / T⁴`.
//! The log-likelihood ratio of `s_e = +1` against `s_e = −1` is
//!
//! ```text
//! Λ = Σ [(y + x)² − (y − x)²] / (2 (v_x + v_y)) = Σ 2 x y / (v_x + v_y),
//! v_x = 6 (m₁₂ cos α σ_θ)² / T⁴,   v_y = 6 (J_α σ_α)² / T⁴
//! ```
//!
//! and the sign is taken as known once `|Λ|` passes [`COUPLING_THRESHOLD`]: the second
//! differences of neighbouring samples share readings, so `Λ` overstates the evidence by a
//! small factor, which the threshold covers. A saturated braking law decelerates the arm by
//! hundreds of rad/s², far above the second difference's noise (tens of rad/s² on a
//! 2048-count encoder at 100 Hz), and settles the sign within a few periods.
//!
//! Why a stop needs it: a stop after a reversal seen on the arm ([`BrakeMode::Reversed`])
//! knows the sign that brakes the arm's rate, not whether the pendulum's terms share it (a
//! swapped motor lead: they do; a reversed arm encoder: they do not). Without the pendulum's
//! terms a heavy pendulum swinging from its fall walks a light arm for seconds (21 rad on a
//! generated rig); with them the stop brakes the arm's angular momentum and the hold law
//! takes the pendulum's energy out, as on a rig whose wiring is trusted.
//!
//! # The drive's sign
//!
//! The arm's equation with the pendulum's acceleration taken from the pendulum's equation
//! (so that only the arm's acceleration is left), in the reading's frame and multiplied
//! through by `s_e`, carries the motor:
//!
//! ```text
//! (M₁₁ − (m₁₂ cos α)²/J_α) θ̈_m + c θ̇_m + 2 J_α sin α cos α θ̇_m α̇ − s_e Q = s_d · b ū
//! Q = m₁₂ cos α (J_α sin α cos α θ̇_m² + G sin α − d_p α̇)/J_α − m₁₂ sin α α̇²
//! ```
//!
//! with `s_d = s_e s_m`, `s_m = −1` for a swapped motor lead, and `ū` the mean of the voltages
//! commanded over the two periods of the second difference. `s_d` is the sign that brakes the
//! measured arm rate ([`BrakeMode::Reversed`] takes `−1`, [`BrakeMode::Checked`] `+1`). The
//! test takes the left side without `Q` as `y_d` against `x_d = b ū` with the same
//! log-likelihood ratio, and counts `Q` (gravity and the rates' terms, no acceleration) as
//! noise whatever is known of `s_e`: read at a wrong scale the arm's equation no longer
//! balances, and a full-scale pendulum term against a quarter-scale arm named a right sign
//! wrong and flipped it (generated rigs 71 and 79, 8192 counts set on a 2048-count encoder: the
//! arm driven to 22 rad). Eliminating the pendulum's acceleration matters: it follows the
//! drive through the coupling, and counted as noise it halved the evidence on a heavy
//! pendulum. The variance is widened too by what the model leaves out: a share
//! [`DRIVE_MODEL_ERROR`] of the drive (the dead zone, Coulomb friction, the motor's constants)
//! and half of a voltage step (the command lands somewhere in its period). A saturated drive
//! of the wrong sign accelerates the arm along its motion by `bU/M₁₁` (hundreds of rad/s²) and
//! is named within two samples, where the brake's rule on a rising speed waits four periods
//! past the latency (a strong motor drove a light arm to 40 rad/s and 1.9 rad in those
//! periods, generated rig 71).

use super::*;

/// `|Λ|` (module docs) past which the arm encoder's sign, or the drive's, is taken as known.
pub const COUPLING_THRESHOLD: f64 = 30.0;

/// The drive's share that the arm's equation may miss (module docs, "The drive's sign"):
/// each sample's evidence on the drive's sign is at most `2 / 0.3²` ≈ 22.
pub const DRIVE_MODEL_ERROR: f64 = 0.3;

/// The running test of the arm encoder's sign against the pendulum (module docs).
/// Allocation-free, `Copy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CouplingTest<R: Real = f64> {
    model: ArmModel<R>,
    period_s: R,
    // One reading's standard deviation (rad): arm, pendulum.
    sigma: [R; 2],
    // The last two readings (oldest first) and how many of them are valid.
    readings: [[R; 2]; 2],
    valid: u32,
    llr: R,
    // The voltages commanded over the last two periods (oldest first; NaN: not known), and
    // the drive's statistic.
    volts: [R; 2],
    drive_llr: R,
}

impl<R: Real> CouplingTest<R> {
    /// The test on the smooth `model` at the loop's period `period_s` (s), one reading's
    /// standard deviation being `sigma` (rad; arm, pendulum: a count over √12 and the
    /// noise).
    pub fn new(model: ArmModel<R>, period_s: R, sigma: [R; 2]) -> Self {
        Self {
            model,
            period_s,
            sigma,
            readings: [[R::ZERO; 2]; 2],
            valid: 0,
            llr: R::ZERO,
            volts: [c(f64::NAN); 2],
            drive_llr: R::ZERO,
        }
    }

    /// Takes the readings of one period: the arm `theta` and the pendulum `alpha` (rad, 0
    /// upright), and the voltage `volts` (V) commanded over the period that ended with them
    /// (`None`: not known, as before a stop's first command). Readings come one period apart;
    /// after a gap call [`gap`](Self::gap).
    pub fn observe(&mut self, theta: R, alpha: R, volts: Option<R>) {
        self.volts = [self.volts[1], volts.unwrap_or(c(f64::NAN))];
        if !(theta.is_finite() && alpha.is_finite()) {
            self.gap();
            return;
        }
        if self.valid >= 2 {
            let [[t0, a0], [t1, a1]] = self.readings;
            let ts = self.period_s;
            let t2 = ts * ts;
            let da1 = wrap_angle(a1 - a0);
            let da2 = wrap_angle(alpha - a1);
            let arm_acc = (theta - c::<R>(2.0) * t1 + t0) / t2;
            let pend_acc = (da2 - da1) / t2;
            let arm_rate = (theta - t0) / (c::<R>(2.0) * ts);
            let pend_rate = (da1 + da2) / (c::<R>(2.0) * ts);
            let (s, co) = (a1.sin(), a1.cos());
            let m = &self.model;
            let x = m.m12 * co * arm_acc;
            let y = m.ja * pend_acc - m.ja * s * co * arm_rate * arm_rate - m.grav * s
                + m.dp * pend_rate;
            let six: R = c(6.0);
            let vx = six * (m.m12 * co * self.sigma[0]).powu(2) / (t2 * t2);
            let vy = six * (m.ja * self.sigma[1]).powu(2) / (t2 * t2);
            let v = vx + vy;
            if v > R::ZERO && (x * y).is_finite() {
                self.llr += c::<R>(2.0) * x * y / v;
            }
            let acc_var = six * self.sigma[0].powu(2) / (t2 * t2);
            self.observe_drive(arm_acc, [arm_rate, pend_rate], a1, acc_var);
        }
        self.readings = [self.readings[1], [theta, alpha]];
        self.valid = (self.valid + 1).min(2);
    }

    /// The drive's sample (module docs, "The drive's sign") from the arm's second-difference
    /// acceleration `arm_acc`, the rates `rates` (arm, pendulum) and the middle reading's
    /// pendulum angle `alpha`, the arm acceleration's variance `acc_var`.
    fn observe_drive(&mut self, arm_acc: R, rates: [R; 2], alpha: R, acc_var: R) {
        let [u0, u1] = self.volts;
        if !(u0.is_finite() && u1.is_finite()) {
            return;
        }
        let m = &self.model;
        let (s, co) = (alpha.sin(), alpha.cos());
        let two: R = c(2.0);
        let [arm_rate, pend_rate] = rates;
        let inertia = m.arm_inertia(alpha) - (m.m12 * co).powu(2) / m.ja;
        let y = inertia * arm_acc + m.c_arm * arm_rate + two * m.ja * s * co * arm_rate * pend_rate;
        let pendulum =
            m.m12 * co * (m.ja * s * co * arm_rate * arm_rate + m.grav * s - m.dp * pend_rate)
                / m.ja
                - m.m12 * s * pend_rate * pend_rate;
        let x = m.b * (u0 + u1) / two;
        let step = m.b * (u1 - u0) / two;
        let var = inertia * inertia * acc_var
            + pendulum * pendulum
            + (c::<R>(DRIVE_MODEL_ERROR) * x).powu(2)
            + step * step;
        if var > R::ZERO && (x * y).is_finite() {
            self.drive_llr += two * x * y / var;
        }
    }

    /// A period without readings: the next second differences start afresh.
    pub fn gap(&mut self) {
        self.valid = 0;
    }

    /// The drive's `Λ` so far (module docs, "The drive's sign"): positive for a voltage that
    /// moves the arm reading its own way.
    pub fn drive_statistic(&self) -> R {
        self.drive_llr
    }

    /// `s_d`, once the evidence is decisive: `1` when a positive voltage moves the arm reading
    /// positive, `−1` when it moves it negative; `None` before.
    pub fn drive_sign(&self) -> Option<R> {
        decided(self.drive_llr)
    }

    /// `Λ` so far (module docs): positive for the arm encoder's sign as configured.
    pub fn statistic(&self) -> R {
        self.llr
    }

    /// `s_e`, once the evidence is decisive: `1` as configured, `−1` reversed; `None` before.
    pub fn sign(&self) -> Option<R> {
        decided(self.llr)
    }
}

/// The sign a log-likelihood ratio `llr` of `+1` against `−1` decides past
/// [`COUPLING_THRESHOLD`]; `None` short of it.
fn decided<R: Real>(llr: R) -> Option<R> {
    let threshold: R = c(COUPLING_THRESHOLD);
    if llr > threshold {
        Some(R::ONE)
    } else if llr < -threshold {
        Some(-R::ONE)
    } else {
        None
    }
}
