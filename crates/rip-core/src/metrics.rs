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

/// The paper's Tab. 1 indices of a run: RMSE of the arm angle against its reference, RMSE of the
/// pendulum angle against its reference (rad, true angles), and RMS of the input voltage (V):
///
/// ```text
/// [ √(Σ (θ_k − θ_ref,k)²/N),  √(Σ (α_k − α_ref,k)²/N),  √(Σ u_k²/N) ]
/// ```
pub fn table1_rmse(result: &SimResult) -> [f64; 3] {
    let mut acc = Table1::default();
    for k in 0..result.len() {
        acc.push(&result.x[k], &result.y[k], result.u[k], &result.r[k]);
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
    /// Adds sample `k`: true state `x`, measured outputs `y`, applied input `u`, reference `r`.
    #[inline]
    pub fn push(&mut self, x: &[f64; 4], y: &[f64; 2], u: f64, r: &[f64; 2]) {
        let _ = y;
        self.sums[0] += (x[0] - r[0]).powi(2);
        self.sums[1] += (x[2] - r[1]).powi(2);
        self.sums[2] += u * u;
        self.n += 1;
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
}
