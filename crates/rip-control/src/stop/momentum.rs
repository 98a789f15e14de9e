//! The arm's angular momentum about its axis: the rate the braking law takes when the arm
//! encoder's sign against the pendulum is known, and its mean over a block of periods from the
//! readings themselves, which tells when the law has braked it out.

use super::*;

/// The arm rate that the braking law takes when the wiring is trusted: the arm's angular
/// momentum about its axis in units of its inertia,
///
/// ```text
/// ω_H = H / (J₀ + J_α sin²α),   H = (J₀ + J_α sin²α) θ̇ − m₁₂ cos α α̇
/// ```
///
/// from the measured rates. Only the motor's torque changes `H`, so a law on `ω_H` leaves
/// nothing to walk the arm once the windings open; a law on `θ̇` under a pendulum still
/// swinging from its fall held the arm near still for 8 s and left `H` to the pendulum, and
/// the arm walked on to 10.2 rad with the windings open (generated rig 79, a healthy rig, at
/// the end of an MPC balance). `ω_H = θ̇` when the pendulum rests.
pub fn momentum_rate<R: Real>(model: &ArmModel<R>, rate: R, alpha: R, alpha_rate: R) -> R {
    model.arm_momentum(rate, alpha, alpha_rate) / model.arm_inertia(alpha)
}

/// The mechanical energy `T + V` (J) of the arm at rate `rate` and the pendulum at `alpha`,
/// `alpha_rate`, with `V = G cos α` (rip-core's `Plant::energy`).
pub(super) fn energy<R: Real>(model: &ArmModel<R>, rate: R, alpha: R, alpha_rate: R) -> R {
    let co = alpha.cos();
    let half: R = c(0.5);
    half * model.arm_inertia(alpha) * rate * rate - model.m12 * co * rate * alpha_rate
        + half * model.ja * alpha_rate * alpha_rate
        + model.grav * co
}

/// The arm's angular momentum averaged over blocks of [`REST_S`], from the readings rather
/// than from their rates:
///
/// ```text
/// ∫ H dt = ∫ I(α) θ̇ dt − m₁₂ ∫ cos α α̇ dt ≈ Σₖ I(ᾱₖ) Δθₖ − s_e m₁₂ (sin α_end − sin α_start)
/// ω̄_H = ∫ H dt / (Σₖ I(ᾱₖ) T)
/// ```
///
/// with `ᾱₖ` the mid angle of period `k` and `s_e` the arm encoder's sign against the
/// pendulum (coupling module docs). The coupling term is exact, and the readings' quantisation
/// telescopes: the mean's error is about a count of each encoder over the block, where each
/// period's `ω_H` carries a count per period of both. On a coarse pendulum encoder that
/// difference decides whether the stop ever finds the momentum braked out: each period's
/// `ω_H` scattered by ±0.7 rad/s about a true one within ±0.5 (dead band 0.47), its 20
/// periods in a row within the dead band never came, and the hold law that takes the
/// pendulum's energy out began 7 s into an 8 s stop (generated rig 90, motor lead swapped
/// mid-swing; the pendulum still swinging ±2 rad walked the arm to 5.4 rad once the windings
/// opened).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct MomentumBlock<R: Real> {
    period_s: f64,
    length: u32,
    last: Option<[R; 2]>,
    start_sin: R,
    sum_h: R,
    sum_inertia: R,
    periods: u32,
    mean: Option<R>,
}

impl<R: Real> MomentumBlock<R> {
    /// Blocks of [`REST_S`] at the loop period `period_s` (s).
    pub(super) fn new(period_s: f64) -> Self {
        Self {
            period_s,
            length: periods_in(REST_S, period_s),
            last: None,
            start_sin: R::ZERO,
            sum_h: R::ZERO,
            sum_inertia: R::ZERO,
            periods: 0,
            mean: None,
        }
    }

    /// Starts afresh: a gap in the readings, or the sign `s_e` the block was taken with
    /// changed. The last block's mean is forgotten.
    pub(super) fn restart(&mut self) {
        *self = Self::new(self.period_s);
    }

    /// Takes the readings of one period (the arm `theta`, the pendulum `alpha`, rad) with the
    /// arm encoder's sign `s_e`.
    pub(super) fn observe(&mut self, model: &ArmModel<R>, theta: R, alpha: R, s_e: R) {
        if !(theta.is_finite() && alpha.is_finite()) {
            self.restart();
            return;
        }
        let Some([theta0, alpha0]) = self.last.replace([theta, alpha]) else {
            self.start_sin = alpha.sin();
            return;
        };
        let half: R = c(0.5);
        let inertia = model.arm_inertia(alpha0 + half * wrap_angle(alpha - alpha0));
        self.sum_h += inertia * (theta - theta0);
        self.sum_inertia += inertia;
        self.periods += 1;
        if self.periods >= self.length {
            let h = self.sum_h - s_e * model.m12 * (alpha.sin() - self.start_sin);
            self.mean = Some(h / (self.sum_inertia * c(self.period_s)));
            self.start_sin = alpha.sin();
            self.sum_h = R::ZERO;
            self.sum_inertia = R::ZERO;
            self.periods = 0;
        }
    }

    /// `ω̄_H` (rad/s) over the last whole block (type docs); `None` before the first.
    pub(super) fn mean(&self) -> Option<R> {
        self.mean
    }
}
