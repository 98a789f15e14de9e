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

use super::*;

/// `|Λ|` (module docs) past which the arm encoder's sign is taken as known.
pub const COUPLING_THRESHOLD: f64 = 30.0;

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
        }
    }

    /// Takes the readings of one period: the arm `theta` and the pendulum `alpha` (rad, 0
    /// upright). Readings come one period apart; after a gap call [`gap`](Self::gap).
    pub fn observe(&mut self, theta: R, alpha: R) {
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
        }
        self.readings = [self.readings[1], [theta, alpha]];
        self.valid = (self.valid + 1).min(2);
    }

    /// A period without readings: the next second differences start afresh.
    pub fn gap(&mut self) {
        self.valid = 0;
    }

    /// `Λ` so far (module docs): positive for the arm encoder's sign as configured.
    pub fn statistic(&self) -> R {
        self.llr
    }

    /// `s_e`, once the evidence is decisive: `1` as configured, `−1` reversed; `None` before.
    pub fn sign(&self) -> Option<R> {
        let threshold: R = c(COUPLING_THRESHOLD);
        if self.llr > threshold {
            Some(R::ONE)
        } else if self.llr < -threshold {
            Some(-R::ONE)
        } else {
            None
        }
    }
}
