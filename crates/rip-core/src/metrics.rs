//! Performance indices of a closed-loop run, as the paper reports them (Tab. 1).

use crate::sim::SimResult;

/// Root-mean-square of `a − b` over equal-length slices (`NaN` for empty input).
pub fn rmse(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    let n = a.len().min(b.len());
    if n == 0 {
        return f64::NAN;
    }
    let s: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    (s / n as f64).sqrt()
}

/// The paper's Tab. 1 indices of a run, the one definition every report uses (`riprs
/// compare`'s table and `summary.csv`, `SimResult.rmse`, Monte Carlo, `rip-rt` logs).
///
/// Computed from what a rig records, the **measured** angles `y = [θ_m, α_m]` (encoder
/// quantisation and sensor noise included) and the **applied** voltage `u`, against the
/// reference `r = [θ_ref, α_ref]`, over **every sample of the run** from `t = 0` (a run that
/// falls is cut at the fall; there is no settling window, since the paper states none):
///
/// ```text
/// [ √(Σ (θ_m,k − θ_ref,k)²/N),  √(Σ (α_m,k − α_ref,k)²/N),  √(Σ u_k²/N) ]
/// ```
///
/// Measured rather than true angles so that a simulation and a hardware log of the same
/// experiment are scored alike. A sample with a non-finite value (a gap in a log) is left out.
pub fn table1_rmse(result: &SimResult) -> [f64; 3] {
    let mut acc = Table1::default();
    for k in 0..result.len() {
        acc.push(&result.y[k], result.u[k], &result.r[k]);
    }
    acc.finish()
}

/// [`table1_rmse`] of recorded signals (a log): arm and pendulum angle, voltage and arm
/// reference, one entry per sample (the pendulum reference is 0).
pub fn table1_rmse_of(
    arm: &[f64],
    pendulum: &[f64],
    voltage: &[f64],
    arm_reference: &[f64],
) -> [f64; 3] {
    let mut acc = Table1::default();
    for (((&a, &p), &u), &r) in arm.iter().zip(pendulum).zip(voltage).zip(arm_reference) {
        acc.push(&[a, p], u, &[r, 0.0]);
    }
    acc.finish()
}

/// [`table1_rmse`] accumulated one sample at a time, so a batch that keeps no trajectory
/// (`crate::batch`) computes exactly the same indices in constant memory.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Table1 {
    sums: [f64; 3],
    n: usize,
}

impl Table1 {
    /// Adds one sample: measured outputs `y`, applied input `u`, reference `r`.
    #[inline]
    pub fn push(&mut self, y: &[f64; 2], u: f64, r: &[f64; 2]) {
        let e = [y[0] - r[0], y[1] - r[1], u];
        if e.iter().all(|v| v.is_finite()) {
            for (s, v) in self.sums.iter_mut().zip(e) {
                *s += v * v;
            }
            self.n += 1;
        }
    }

    /// The indices so far (`NaN` before the first sample).
    pub fn finish(&self) -> [f64; 3] {
        if self.n == 0 {
            return [f64::NAN; 3];
        }
        self.sums.map(|s| (s / self.n as f64).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rmse_of_a_constant_offset_is_the_offset() {
        assert!((rmse(&[1.0, 2.0, 3.0], &[0.5, 1.5, 2.5]) - 0.5).abs() < 1e-15);
        assert!(rmse(&[], &[]).is_nan());
    }

    #[test]
    fn table1_uses_measured_angles_and_skips_gaps() {
        let arm = [0.0, 1.0, f64::NAN, 1.0];
        let pendulum = [0.1, -0.1, 0.0, 0.1];
        let volts = [3.0, -3.0, 1.0, 3.0];
        let reference = [0.0, 0.0, 0.0, 1.0];
        let got = table1_rmse_of(&arm, &pendulum, &volts, &reference);
        // Three usable samples: arm errors 0, 1, 0; pendulum 0.1 each; voltage 3 each.
        assert!((got[0] - (1.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert!((got[1] - 0.1).abs() < 1e-15);
        assert!((got[2] - 3.0).abs() < 1e-15);
    }
}
