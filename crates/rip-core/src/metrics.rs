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
    let n = result.len();
    if n == 0 {
        return [f64::NAN; 3];
    }
    let mut acc = [0.0; 3];
    for k in 0..n {
        let (x, r) = (result.x[k], result.r[k]);
        acc[0] += (x[0] - r[0]).powi(2);
        acc[1] += (x[2] - r[1]).powi(2);
        acc[2] += result.u[k].powi(2);
    }
    acc.map(|s| (s / n as f64).sqrt())
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
