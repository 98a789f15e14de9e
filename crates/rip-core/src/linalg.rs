//! Dense linear algebra for control design: argument validation, eigenvalues and
//! zero-order-hold discretisation. The Riccati solver is in [`crate::dare`](mod@crate::dare).

use nalgebra::{Complex, DMatrix};

use crate::error::{Result, RipError};

/// Dynamically sized `f64` matrix used by the design routines.
pub type Mat = DMatrix<f64>;

/// Fails with [`RipError::Shape`] unless `m` is `rows × cols`.
pub fn check_shape(name: &str, m: &Mat, rows: usize, cols: usize) -> Result<()> {
    if m.nrows() != rows || m.ncols() != cols {
        return Err(RipError::Shape {
            name: name.to_string(),
            expected: format!("({rows}, {cols})"),
            rows: m.nrows(),
            cols: m.ncols(),
        });
    }
    Ok(())
}

/// Fails unless `m` is square and non-empty; returns its size.
pub fn check_square(name: &str, m: &Mat) -> Result<usize> {
    if m.nrows() != m.ncols() || m.nrows() == 0 {
        return Err(RipError::Shape {
            name: name.to_string(),
            expected: "(n, n) with n ≥ 1".to_string(),
            rows: m.nrows(),
            cols: m.ncols(),
        });
    }
    Ok(m.nrows())
}

/// Checks that `a` is square and returns its size `n`, naming `a` (not the others) when it is
/// the odd one out: if every dimension in `others` (each `(argument, size)` a dimension that
/// must equal `n`) agrees on another size, `a` is the wrongly shaped argument.
pub fn check_state_matrix(name: &str, a: &Mat, others: &[(&str, usize)]) -> Result<usize> {
    let n = check_square(name, a)?;
    if let Some(&(_, m)) = others.first() {
        if m != n && others.iter().all(|&(_, d)| d == m) {
            let names: Vec<&str> = others.iter().map(|&(o, _)| o).collect();
            return Err(RipError::Shape {
                name: name.to_string(),
                expected: format!("({m}, {m}) to match {}", names.join(", ")),
                rows: a.nrows(),
                cols: a.ncols(),
            });
        }
    }
    Ok(n)
}

/// Fails with [`RipError::NonFinite`] if `m` holds NaN or ±Inf.
pub fn check_finite(name: &str, m: &Mat) -> Result<()> {
    if m.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(RipError::NonFinite {
            name: name.to_string(),
        })
    }
}

/// Fails unless `m` is symmetric to `1e-8` relative to its largest entry.
pub fn check_symmetric(name: &str, m: &Mat) -> Result<()> {
    let scale = m.amax().max(1.0);
    let asymmetry = (m - m.transpose()).amax();
    if asymmetry > 1e-8 * scale {
        return Err(RipError::NotSymmetric {
            name: name.to_string(),
            asymmetry,
        });
    }
    Ok(())
}

/// Fails unless the symmetric matrix `m` is positive semidefinite (to a relative `1e-10`).
pub fn check_psd(name: &str, m: &Mat) -> Result<()> {
    // Bounded like `eigenvalues`; a matrix whose iteration fails is reported as indefinite.
    let min_eigenvalue = m
        .clone()
        .try_symmetric_eigen(f64::EPSILON, 100 * m.nrows().max(1))
        .map_or(f64::NAN, |e| e.eigenvalues.min());
    if min_eigenvalue.is_nan() {
        return Err(RipError::NotPositiveSemidefinite {
            name: name.to_string(),
            min_eigenvalue,
        });
    }
    if min_eigenvalue < -1e-10 * m.amax().max(1e-300) {
        return Err(RipError::NotPositiveSemidefinite {
            name: name.to_string(),
            min_eigenvalue,
        });
    }
    Ok(())
}

/// Fails unless the symmetric matrix `m` is positive definite (it has a Cholesky factor).
pub fn check_pd(name: &str, m: &Mat) -> Result<()> {
    if m.clone().cholesky().is_none() {
        return Err(RipError::NotPositiveDefinite {
            name: name.to_string(),
        });
    }
    Ok(())
}

/// `(m + mᵀ)/2`: removes the round-off asymmetry that products like `AᵀXA` accumulate.
pub fn symmetrize(m: &Mat) -> Mat {
    (m + m.transpose()) * 0.5
}

/// Largest eigenvalue modulus of a square matrix.
pub fn spectral_radius(m: &Mat) -> f64 {
    eigenvalues(m).iter().map(|z| z.norm()).fold(0.0, f64::max)
}

/// Eigenvalues of a square real matrix (real Schur form).
///
/// nalgebra's Schur iteration first divides the matrix by its largest entry and never returns
/// when that is zero or not finite (the zero matrix of order three or more is the closed loop
/// of every deadbeat design). Those inputs are answered here: zeros for the zero matrix, NaN,
/// which every caller rejects, for non-finite entries.
pub fn eigenvalues(m: &Mat) -> Vec<Complex<f64>> {
    let n = m.nrows();
    if m.iter().any(|v| !v.is_finite()) {
        return vec![Complex::new(f64::NAN, f64::NAN); n];
    }
    if m.iter().all(|&v| v == 0.0) {
        return vec![Complex::new(0.0, 0.0); n];
    }
    // nalgebra's `complex_eigenvalues` iterates without a limit; 100 sweeps per eigenvalue is
    // far beyond the handful the Francis iteration needs.
    match m.clone().try_schur(f64::EPSILON, 100 * n.max(1)) {
        Some(schur) => schur.complex_eigenvalues().iter().copied().collect(),
        None => vec![Complex::new(f64::NAN, f64::NAN); n],
    }
}

/// Zero-order-hold discretisation of `ẋ = A x + B u` with period `ts`:
/// `A_d = e^{A Ts}`, `B_d = ∫₀^{Ts} e^{Aτ} dτ B`, both read off the exponential of the block
/// matrix `[[A, B], [0, 0]] Ts` (Van Loan 1978; MATLAB `c2d(sys, Ts, 'zoh')`).
pub fn c2d(a: &Mat, b: &Mat, ts: f64) -> Result<(Mat, Mat)> {
    let n = check_square("A", a)?;
    if b.nrows() != n {
        return Err(RipError::Shape {
            name: "B".into(),
            expected: format!("({n}, m)"),
            rows: b.nrows(),
            cols: b.ncols(),
        });
    }
    check_finite("A", a)?;
    check_finite("B", b)?;
    if !(ts.is_finite() && ts > 0.0) {
        return Err(RipError::invalid(
            "Ts",
            format!("must be positive and finite, got {ts}"),
        ));
    }
    let m = b.ncols();
    let mut block = Mat::zeros(n + m, n + m);
    block.view_mut((0, 0), (n, n)).copy_from(&(a * ts));
    block.view_mut((0, n), (n, m)).copy_from(&(b * ts));
    let Some(e) = expm(&block) else {
        return Err(RipError::invalid(
            "Ts",
            format!(
                "A·Ts is too large to discretise at Ts = {ts}: e^(A·Ts) is not representable \
                 in double precision (‖[A B]·Ts‖₁ = {:.3e})",
                one_norm(&block)
            ),
        ));
    };
    let ad = e.view((0, 0), (n, n)).into_owned();
    check_liouville(a, &ad, ts)?;
    Ok((ad, e.view((0, n), (n, m)).into_owned()))
}

/// Largest accepted `|ln det e^(A·Ts) − tr(A·Ts)|`. The identity `det e^(A·Ts) = e^(tr A·Ts)`
/// (Liouville's formula) holds exactly; a result that misses it by more than a factor of two
/// has lost every digit. That happens when `‖A·Ts‖` is so large that the argument of an
/// oscillatory mode is below double precision's resolution (a rotation by 10²⁰ rad squared 67
/// times comes out as the zero matrix), not for ordinary stiff or ill-conditioned models,
/// whose determinants stay accurate far below this bound.
const LIOUVILLE_TOLERANCE: f64 = std::f64::consts::LN_2;

/// Fails, naming `Ts`, unless `ad = e^(A·Ts)` satisfies Liouville's formula
/// `det e^(A·Ts) = e^(tr A·Ts)` to [`LIOUVILLE_TOLERANCE`]. Skipped where `e^(tr A·Ts)` is not a
/// normal double (|tr A·Ts| > 700), where the formula cannot be evaluated.
fn check_liouville(a: &Mat, ad: &Mat, ts: f64) -> Result<()> {
    let trace = a.trace() * ts;
    // A NaN trace cannot occur (A is checked finite); an infinite one is out of range too.
    if trace.abs() > 700.0 || trace.is_nan() {
        return Ok(());
    }
    let det = ad.clone().lu().determinant();
    let lost = det.is_nan() || det <= 0.0 || (det.ln() - trace).abs() > LIOUVILLE_TOLERANCE;
    if lost {
        return Err(RipError::invalid(
            "Ts",
            format!(
                "A·Ts is too large to discretise accurately at Ts = {ts}: e^(A·Ts) has lost \
                 every digit in double precision (det e^(A·Ts) = {det:.3e}, e^(tr A·Ts) = \
                 {:.3e}; ‖A·Ts‖₁ = {:.3e})",
                trace.exp(),
                one_norm(a) * ts
            ),
        ));
    }
    Ok(())
}

/// Largest number of squarings [`expm`] performs. `‖A‖₁ ≤ f64::MAX < 2¹⁰²⁴` needs at most
/// `1024 − log₂ θ₁₃ < 1022` halvings to reach `θ₁₃`, so this bound is never the limit for a
/// finite matrix; it makes the loop's bound explicit.
const EXPM_MAX_SQUARINGS: u32 = 1100;

/// Padé [13/13] coefficients `b₀ … b₁₃` of Higham (2005), Table 2.3.
const PADE13: [f64; 14] = [
    64_764_752_532_480_000.0,
    32_382_376_266_240_000.0,
    7_771_770_303_897_600.0,
    1_187_353_796_428_800.0,
    129_060_195_264_000.0,
    10_559_470_521_600.0,
    670_442_572_800.0,
    33_522_128_640.0,
    1_323_241_920.0,
    40_840_800.0,
    960_960.0,
    16_380.0,
    182.0,
    1.0,
];

/// `θ₁₃` of Higham (2005): the largest `‖A‖₁` for which the Padé [13/13] approximant of `e^A`
/// has a backward error below the unit round-off.
const THETA13: f64 = 5.371_920_351_148_152;

/// The 1-norm (largest absolute column sum) of a matrix.
pub fn one_norm(m: &Mat) -> f64 {
    m.column_iter()
        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// The matrix exponential `e^A` by scaling and squaring with the Padé [13/13] approximant
/// (Higham 2005, Algorithm 2.3, which MATLAB's `expm` implements):
///
/// ```text
/// s = max(0, ⌈log₂(‖A‖₁/θ₁₃)⌉),   e^A = r₁₃(A/2ˢ)^(2ˢ),   r₁₃ = (V − U)⁻¹(V + U).
/// ```
///
/// `None` when the result is not representable (an entry overflows, or `A` has a non-finite
/// entry or 1-norm): the number of squarings is computed from a finite norm and stays below
/// `EXPM_MAX_SQUARINGS`, and the squaring stops at the first overflow, so huge inputs end
/// at once instead of looping on an infinite norm estimate. `A` must be square.
pub fn expm(a: &Mat) -> Option<Mat> {
    let n = a.nrows();
    let norm = one_norm(a);
    if !norm.is_finite() {
        return None;
    }
    if norm == 0.0 {
        return Some(Mat::identity(n, n));
    }
    let s = (norm / THETA13).log2().ceil().max(0.0);
    if s > f64::from(EXPM_MAX_SQUARINGS) {
        return None;
    }
    let s = s as i32;
    let a = a * 2f64.powi(-s);
    let eye = Mat::identity(n, n);
    let a2 = &a * &a;
    let a4 = &a2 * &a2;
    let a6 = &a4 * &a2;
    let b = &PADE13;
    let u_inner = &a6 * (&a6 * b[13] + &a4 * b[11] + &a2 * b[9])
        + &a6 * b[7]
        + &a4 * b[5]
        + &a2 * b[3]
        + &eye * b[1];
    let u = &a * u_inner;
    let v = &a6 * (&a6 * b[12] + &a4 * b[10] + &a2 * b[8])
        + &a6 * b[6]
        + &a4 * b[4]
        + &a2 * b[2]
        + &eye * b[0];
    let mut x = (&v - &u).lu().solve(&(&v + &u))?;
    for _ in 0..s {
        if !x.iter().all(|v| v.is_finite()) {
            return None;
        }
        x = &x * &x;
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Fails with [`RipError::InvalidParameter`] named `name` unless `ts` is a positive, finite
/// sample time.
pub fn check_sample_time(name: &str, ts: f64) -> Result<()> {
    if ts.is_finite() && ts > 0.0 {
        Ok(())
    } else {
        Err(RipError::invalid(
            name,
            format!("must be positive and finite, got {ts}"),
        ))
    }
}

/// Fails unless the joint weight or covariance `[[Q, N], [Nᵀ, R]]` is positive semidefinite;
/// the error names it `name`. `q` and `r` must already be symmetric.
pub fn check_joint_psd(name: &str, q: &Mat, n: &Mat, r: &Mat) -> Result<()> {
    let (nq, nr) = (q.nrows(), r.nrows());
    let mut joint = Mat::zeros(nq + nr, nq + nr);
    joint.view_mut((0, 0), (nq, nq)).copy_from(q);
    joint.view_mut((0, nq), (nq, nr)).copy_from(n);
    joint.view_mut((nq, 0), (nr, nq)).copy_from(&n.transpose());
    joint.view_mut((nq, nq), (nr, nr)).copy_from(r);
    check_psd(name, &joint)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mat(rows: usize, cols: usize, v: &[f64]) -> Mat {
        Mat::from_row_slice(rows, cols, v)
    }

    #[test]
    fn c2d_overflow_is_an_error_not_nan() {
        let a = mat(1, 1, &[1e300]);
        let err = c2d(&a, &mat(1, 1, &[1.0]), 0.1).unwrap_err();
        assert!(matches!(err, RipError::InvalidParameter { .. }), "{err}");
    }

    #[test]
    fn c2d_of_a_rotation_beyond_double_precision_is_refused_not_zero() {
        // e^(A·Ts) is a rotation (det 1) for every s; above ~1e15 rad its angle has no
        // significant digit left, and the squarings returned the zero matrix.
        for s in [1e20, 1e30, 1e45] {
            let a = mat(2, 2, &[0.0, s, -s, 0.0]);
            let err = c2d(&a, &mat(2, 1, &[0.0, 1.0]), 1.0).unwrap_err();
            assert!(
                matches!(err, RipError::InvalidParameter { ref name, .. } if name == "Ts"),
                "{s}: {err}"
            );
        }
        // Below that the rotation is still one: det 1 to rounding.
        let a = mat(2, 2, &[0.0, 1e3, -1e3, 0.0]);
        let (ad, _) = c2d(&a, &mat(2, 1, &[0.0, 1.0]), 1.0).unwrap();
        assert!((ad.clone().lu().determinant() - 1.0).abs() < 1e-9);
        assert!((ad[(0, 0)] - 1e3f64.cos()).abs() < 1e-9);
    }

    #[test]
    fn c2d_of_a_stiff_ill_conditioned_model_is_accepted() {
        // Modes e^(±30): condition number e^60, det exactly 1.
        let a = mat(2, 2, &[30.0, 0.0, 0.0, -30.0]);
        let (ad, _) = c2d(&a, &mat(2, 1, &[1.0, 1.0]), 1.0).unwrap();
        assert!((ad[(0, 0)] / 30f64.exp() - 1.0).abs() < 1e-12);
        assert!((ad[(1, 1)] / (-30f64).exp() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn c2d_of_double_integrator() {
        let a = mat(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let b = mat(2, 1, &[0.0, 1.0]);
        let (ad, bd) = c2d(&a, &b, 0.1).unwrap();
        assert!((ad - mat(2, 2, &[1.0, 0.1, 0.0, 1.0])).amax() < 1e-14);
        assert!((bd - mat(2, 1, &[0.005, 0.1])).amax() < 1e-14);
    }
}
