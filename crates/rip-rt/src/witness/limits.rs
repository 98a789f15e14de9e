//! The witness's thresholds: the measured choice, and the lowering's.

use super::{ARM_THRESHOLD, DRIFT, PENDULUM_THRESHOLD, SIGN_THRESHOLD};

/// The thresholds and gains (module docs); [`WitnessLimits::default`] is the measured choice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WitnessLimits {
    /// CUSUM drift κ (σ).
    pub drift: f64,
    /// Arm threshold (σ); `f64::INFINITY` only measures.
    pub arm: f64,
    /// Pendulum threshold (σ); `f64::INFINITY` only measures.
    pub pendulum: f64,
    /// Sign statistic's threshold (log-likelihood ratio); `f64::INFINITY` only measures.
    pub sign: f64,
}

/// Factor on the arm's, the pendulum's and the sign statistic's thresholds while the gentle end
/// lowers the pendulum ([`WitnessLimits::lowering`]).
pub const LOWERING_THRESHOLD_FACTOR: f64 = 2.0;

impl WitnessLimits {
    /// The thresholds while the gentle end lowers the pendulum: the lowering law drives at the
    /// voltage bound and reverses it every few periods, where the prediction hangs most on when
    /// each command arrived, and with a quarter of the replies lost the balance's thresholds
    /// were crossed by 1 lockstep run in 100 and 1 real-time run in 20 (statistics 27–40
    /// against 25–40). The faults the lowering must not steer (an arm read at a quarter of its
    /// motion, an encoder that stopped) move the arm by many σ a period under it and cross
    /// [`LOWERING_THRESHOLD_FACTOR`] times them too.
    pub fn lowering(self) -> Self {
        Self {
            drift: self.drift,
            arm: LOWERING_THRESHOLD_FACTOR * self.arm,
            pendulum: LOWERING_THRESHOLD_FACTOR * self.pendulum,
            sign: LOWERING_THRESHOLD_FACTOR * self.sign,
        }
    }
}

impl Default for WitnessLimits {
    fn default() -> Self {
        Self {
            drift: DRIFT,
            arm: ARM_THRESHOLD,
            pendulum: PENDULUM_THRESHOLD,
            sign: SIGN_THRESHOLD,
        }
    }
}
