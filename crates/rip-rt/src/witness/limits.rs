//! The witness's thresholds: the measured choice, and the lowering's.

use super::{ARM_THRESHOLD, DRIFT, PENDULUM_THRESHOLD, REVERSAL_THRESHOLD, SIGN_THRESHOLD};

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
    /// The reversed observers' threshold (log-likelihood ratio); `f64::INFINITY` only
    /// measures.
    pub reversal: f64,
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
    /// [`LOWERING_THRESHOLD_FACTOR`] times them too. The reversed observers only measure: the
    /// lowering brakes the pendulum's fall through the arm, so the pendulum's pull and the
    /// voltage push the arm the same way, and a reading at a quarter of the arm's motion,
    /// which moves less than either, fits a reversed voltage better than the model as wired
    /// (generated rig 17: named a reversal, and braked with the sign that drove the arm on to
    /// 14 rad).
    pub fn lowering(self) -> Self {
        Self {
            drift: self.drift,
            arm: LOWERING_THRESHOLD_FACTOR * self.arm,
            pendulum: LOWERING_THRESHOLD_FACTOR * self.pendulum,
            sign: LOWERING_THRESHOLD_FACTOR * self.sign,
            reversal: f64::INFINITY,
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
            reversal: REVERSAL_THRESHOLD,
        }
    }
}
