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
///
/// The exponential's a-posteriori error estimate ([`Exponential::error_estimate`]) decides
/// whether the result is returned: above [`C2D_ERROR_TOLERANCE`] the discretisation is refused,
/// naming `Ts`.
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
    let Some(exp) = expm_with_estimate(&block) else {
        return Err(RipError::invalid(
            "Ts",
            format!(
                "A·Ts is too large to discretise at Ts = {ts}: e^(A·Ts) is not representable \
                 in double precision (‖[A B]·Ts‖₁ = {:.3e})",
                one_norm(&block)
            ),
        ));
    };
    if exp.error_estimate.is_nan() || exp.error_estimate > C2D_ERROR_TOLERANCE {
        return Err(RipError::invalid(
            "Ts",
            format!(
                "A·Ts is too large to discretise accurately at Ts = {ts}: the estimated \
                 relative error of e^([A B; 0 0]·Ts) in double precision is {:.1e} (above \
                 {C2D_ERROR_TOLERANCE:.0e}, after {} squarings; ‖A·Ts‖₁ = {:.3e}); a shorter \
                 Ts or states in other units avoid it",
                exp.error_estimate,
                exp.squarings,
                one_norm(a) * ts
            ),
        ));
    }
    let e = exp.value;
    Ok((
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, m)).into_owned(),
    ))
}

/// Largest accepted [`Exponential::error_estimate`] of a discretisation: six significant
/// digits, in norm. The estimate is one to three orders of magnitude above the true error on
/// scipy's and Burkardt's tests, so what passes is accurate and what fails has really lost
/// digits (a rotation by 10¹⁰ rad per sample: estimate 1.5·10⁻⁶, true error 1.2·10⁻⁷; by
/// 10¹⁵ rad: estimate 0.085, true error 8.8·10⁻³).
pub const C2D_ERROR_TOLERANCE: f64 = 1e-6;

/// Largest number of squarings [`expm`] performs. `‖A‖₁ ≤ f64::MAX < 2¹⁰²⁴` needs at most
/// `1024 − log₂ θ₁₃ < 1022` halvings to reach `θ₁₃`, and the correction against overscaling
/// adds at most a few dozen more, so this bound is never the limit for a finite matrix; it
/// makes the loop's bound explicit.
const EXPM_MAX_SQUARINGS: u32 = 1100;

/// Padé [m/m] coefficients `b₀ … b_m` of Higham (2005), Table 2.3, for m = 3, 5, 7, 9.
const PADE3: [f64; 4] = [120.0, 60.0, 12.0, 1.0];
const PADE5: [f64; 6] = [30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0];
const PADE7: [f64; 8] = [
    17_297_280.0,
    8_648_640.0,
    1_995_840.0,
    277_200.0,
    25_200.0,
    1_512.0,
    56.0,
    1.0,
];
const PADE9: [f64; 10] = [
    17_643_225_600.0,
    8_821_612_800.0,
    2_075_673_600.0,
    302_702_400.0,
    30_270_240.0,
    2_162_160.0,
    110_880.0,
    3_960.0,
    90.0,
    1.0,
];

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

/// `θ_m` of Higham (2005), Table 2.3, for m = 3, 5, 7, 9: the largest `‖A‖` for which the
/// Padé [m/m] approximant has a backward error below the unit round-off.
const THETA: [(usize, f64); 4] = [
    (3, 1.495_585_217_958_292e-2),
    (5, 2.539_398_330_063_23e-1),
    (7, 9.504_178_996_162_932e-1),
    (9, 2.097_847_961_257_068),
];

/// `θ₁₃` of Higham (2005): the largest `‖A‖₁` for which the Padé [13/13] approximant of `e^A`
/// has a backward error below the unit round-off.
const THETA13: f64 = 5.371_920_351_148_152;

/// `1/|c_{2m+1}|`, the reciprocal of the leading coefficient of the Padé [m/m] approximant's
/// backward-error series (Al-Mohy & Higham 2009, eq. (5.1)), for m = 3, 5, 7, 9, 13.
fn backward_error_coefficient_reciprocal(m: usize) -> f64 {
    match m {
        3 => 100_800.0,
        5 => 10_059_033_600.0,
        7 => 4_487_938_430_976_000.0,
        9 => 5_914_384_781_877_411_840_000.0,
        _ => 113_250_775_606_021_113_483_283_660_800_000_000.0,
    }
}

/// The 1-norm (largest absolute column sum) of a matrix.
pub fn one_norm(m: &Mat) -> f64 {
    m.column_iter()
        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// `‖ |M|ᵖ ‖₁` divided by `‖M‖₁ᵖ`, by `p` products of `|M|ᵀ/‖M‖₁` with the vector of ones (the
/// 1-norm of a nonnegative matrix is the largest entry of `1ᵀ|M|ᵖ`); the division keeps it
/// finite for any finite `M`.
fn normalised_abs_power_norm(m: &Mat, norm: f64, p: usize) -> f64 {
    let abs_t = m.abs().transpose() / norm;
    let mut v = nalgebra::DVector::from_element(m.nrows(), 1.0);
    for _ in 0..p {
        v = &abs_t * v;
    }
    v.max()
}

/// `ℓ(A, m)` of Al-Mohy & Higham (2009), eq. (5.2): the extra squarings that bring the
/// Padé [m/m] approximant's backward-error bound, evaluated on `|A|`, below the unit
/// round-off `u = 2⁻⁵³`:
///
/// ```text
/// ℓ = max(0, ⌈log₂(α/u) / (2m)⌉),   α = |c_{2m+1}| ‖ |A|^{2m+1} ‖₁ / ‖A‖₁.
/// ```
fn overscaling_correction(a: &Mat, m: usize) -> i32 {
    let norm = one_norm(a);
    if norm == 0.0 {
        return 0;
    }
    let power = normalised_abs_power_norm(a, norm, 2 * m + 1);
    if power == 0.0 {
        return 0;
    }
    let log2_alpha = power.log2() + (2 * m) as f64 * norm.log2()
        - backward_error_coefficient_reciprocal(m).log2();
    (((log2_alpha + 53.0) / (2 * m) as f64).ceil()).max(0.0) as i32
}

/// `‖A^k‖₁^(1/k)`, or `∞` when the power overflowed.
fn power_norm_root(power: &Mat, k: i32) -> f64 {
    let norm = one_norm(power);
    if norm.is_finite() {
        norm.powf(1.0 / f64::from(k))
    } else {
        f64::INFINITY
    }
}

/// The result of [`expm_with_estimate`].
#[derive(Debug, Clone)]
pub struct Exponential {
    /// `e^A`.
    pub value: Mat,
    /// Degree `m` of the Padé [m/m] approximant used (3, 5, 7, 9 or 13).
    pub degree: usize,
    /// Number of squarings `s`.
    pub squarings: u32,
    /// A-posteriori estimate of the relative error `‖X̂ − e^A‖₁ / ‖X̂‖₁` (see
    /// [`expm_with_estimate`]); `∞` where every digit may be lost.
    pub error_estimate: f64,
}

/// The matrix exponential `e^A`; [`expm_with_estimate`] without the estimate.
pub fn expm(a: &Mat) -> Option<Mat> {
    expm_with_estimate(a).map(|e| e.value)
}

/// The matrix exponential `e^A` by scaling and squaring with a Padé [m/m] approximant, with the
/// choice of `m` and `s` of Al-Mohy & Higham, "A new scaling and squaring algorithm for the
/// matrix exponential", SIAM J. Matrix Anal. Appl. 31(3), 2009, Algorithm 5.1 (scipy's
/// `expm`): with `d_k = ‖A^k‖₁^(1/k)`, `m` is the smallest of 3, 5, 7, 9 with
/// `max(d₄, d₆) ≤ θ_m` (m = 3, 5) or `max(d₆, d₈) ≤ θ_m` (m = 7, 9) and `ℓ(A, m) = 0`, else
/// `m = 13` and
///
/// ```text
/// s = max(0, ⌈log₂(min(max(d₆, d₈), max(d₈, d₁₀)) / θ₁₃)⌉) + ℓ(2⁻ˢA, 13),
/// e^A = r_m(2⁻ˢA)^(2ˢ),   r_m = (V − U)⁻¹(V + U).
/// ```
///
/// Using `d_k` instead of `‖A‖₁` (Higham 2005) avoids the overscaling of non-normal matrices,
/// whose norm can be far above their powers' (`[[1, b], [0, −1]]` squares to `I` for every `b`).
///
/// **Error estimate.** The rounding errors are propagated to first order through the
/// squarings, as a matrix: the Padé solve `M X = N` (`M = V − U`, `N = V + U`) starts with
/// LAPACK's componentwise forward-error bound `F₀ = |M⁻¹| (|M X̂ − N| + γ_{n+1}(|M||X̂| + |N|))`,
/// and each squaring `X₊ = fl(X²)` maps the error `E` to
///
/// ```text
/// E₊ = X E + E X + Σₖ ∘ γ_n |X|²,     γ_n = n u / (1 − n u),   u = 2⁻⁵³,
/// ```
///
/// where `∘ γ_n |X|²` is the bound on the rounding error of the product, entry by entry, and
/// `Σₖ` a fixed pattern of signs ±1 standing for the unknown signs of those errors (each
/// entry of `F₀` gets one too). The estimate is `‖E_s‖₁ / ‖X̂_s‖₁`. Propagating the matrix
/// rather than norm bounds keeps the cancellations of non-normal and badly scaled matrices,
/// which norm bounds overestimate by many orders of magnitude (Moler's example: `10⁵⁶` by the
/// norm recursion, `2.9·10⁻¹²` by this one, true error `2.8·10⁻¹³`). Once the estimate passes
/// one, the first-order model no longer holds and the estimate is `∞`.
///
/// `None` when the result is not representable (an entry overflows, or `A` has a non-finite
/// entry or 1-norm): the number of squarings is computed from finite norms and stays below
/// `EXPM_MAX_SQUARINGS`, and the squaring stops at the first overflow, so huge inputs end at
/// once. `A` must be square.
pub fn expm_with_estimate(a: &Mat) -> Option<Exponential> {
    let n = a.nrows();
    let norm = one_norm(a);
    if !norm.is_finite() {
        return None;
    }
    let eye = Mat::identity(n, n);
    if norm == 0.0 {
        return Some(Exponential {
            value: eye,
            degree: 0,
            squarings: 0,
            error_estimate: 0.0,
        });
    }
    let a2 = a * a;
    let a4 = &a2 * &a2;
    let a6 = &a4 * &a2;
    let (d4, d6) = (power_norm_root(&a4, 4), power_norm_root(&a6, 6));
    let eta1 = d4.max(d6);
    for (m, theta) in &THETA[..2] {
        if eta1 <= *theta && overscaling_correction(a, *m) == 0 {
            return finish(a, &[eye, a2, a4], *m, 0);
        }
    }
    let a8 = &a4 * &a4;
    let d8 = power_norm_root(&a8, 8);
    let eta3 = d6.max(d8);
    for (m, theta) in &THETA[2..] {
        if eta3 <= *theta && overscaling_correction(a, *m) == 0 {
            return finish(a, &[eye, a2, a4, a6, a8], *m, 0);
        }
    }
    let d10 = power_norm_root(&(&a4 * &a6), 10);
    // d_k ≤ ‖A‖₁ always; the norm stands in where a power overflowed.
    let eta5 = eta3.min(d8.max(d10)).min(norm);
    let s = if eta5 > 0.0 {
        (eta5 / THETA13).log2().ceil().max(0.0)
    } else {
        0.0
    };
    if s > f64::from(EXPM_MAX_SQUARINGS) {
        return None;
    }
    let s = s as i32;
    let s = s + overscaling_correction(&(a * 2f64.powi(-s)), 13);
    if s > EXPM_MAX_SQUARINGS as i32 {
        return None;
    }
    // The powers of the scaled matrix are formed afresh: those of A may have overflowed.
    let scaled = a * 2f64.powi(-s);
    let s2 = &scaled * &scaled;
    let s4 = &s2 * &s2;
    let s6 = &s4 * &s2;
    finish(&scaled, &[eye, s2, s4, s6], 13, s as u32)
}

/// Evaluates `r_m(A)` from the even powers `[I, A², A⁴, …]`, squares it `s` times and
/// estimates the error (see [`expm_with_estimate`]).
fn finish(a: &Mat, powers: &[Mat], m: usize, s: u32) -> Option<Exponential> {
    let n = a.nrows();
    let (u_inner, v) = match m {
        13 => {
            let b = &PADE13;
            let (eye, a2, a4, a6) = (&powers[0], &powers[1], &powers[2], &powers[3]);
            (
                a6 * (a6 * b[13] + a4 * b[11] + a2 * b[9])
                    + a6 * b[7]
                    + a4 * b[5]
                    + a2 * b[3]
                    + eye * b[1],
                a6 * (a6 * b[12] + a4 * b[10] + a2 * b[8])
                    + a6 * b[6]
                    + a4 * b[4]
                    + a2 * b[2]
                    + eye * b[0],
            )
        }
        _ => {
            let b: &[f64] = match m {
                3 => &PADE3,
                5 => &PADE5,
                7 => &PADE7,
                _ => &PADE9,
            };
            let mut u_inner = Mat::zeros(n, n);
            let mut v = Mat::zeros(n, n);
            for (j, power) in powers.iter().enumerate().take(b.len() / 2) {
                u_inner += power * b[2 * j + 1];
                v += power * b[2 * j];
            }
            (u_inner, v)
        }
    };
    let u = a * u_inner;
    let lhs = &v - &u;
    let rhs = &v + &u;
    let lu = lhs.clone().lu();
    let mut x = lu.solve(&rhs)?;
    let lhs_inv = lu.try_inverse()?;
    let unit = f64::EPSILON / 2.0;
    let gamma = |k: usize| k as f64 * unit / (1.0 - k as f64 * unit);
    let residual = &lhs * &x - &rhs;
    let forward =
        lhs_inv.abs() * (residual.abs() + (lhs.abs() * x.abs() + rhs.abs()) * gamma(n + 1));
    // The first-order error of the iterate, E, with the rounding errors of unknown sign given
    // the fixed pseudo-random signs of `error_signs`.
    let mut error = forward.component_mul(&error_signs(n, 0));
    let triangular = is_upper_triangular(a);
    if triangular {
        replace_triangular_entries(&mut x, a, 0);
    }
    let mut estimate = relative_error(&error, &x).unwrap_or(0.0);
    for step in 1..=s {
        if !x.iter().all(|v| v.is_finite()) {
            return None;
        }
        let abs = x.abs();
        let rounding = (&abs * &abs).component_mul(&error_signs(n, step)) * gamma(n);
        error = &x * &error + &error * &x + rounding;
        x = &x * &x;
        if triangular {
            replace_triangular_entries(&mut x, a, step);
        }
        match relative_error(&error, &x) {
            // Every mode has decayed below the smallest double: the zero matrix is the
            // correctly rounded answer, as accurate as the iterate before it.
            None => break,
            Some(next) => estimate = next,
        }
        // Beyond a relative error of one the first-order model no longer bounds anything.
        if estimate.is_nan() || estimate > 1.0 {
            estimate = f64::INFINITY;
            break;
        }
    }
    if !x.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(Exponential {
        value: x,
        degree: m,
        squarings: s,
        error_estimate: estimate,
    })
}

/// Whether every entry below the diagonal is zero.
fn is_upper_triangular(a: &Mat) -> bool {
    (0..a.ncols()).all(|j| (j + 1..a.nrows()).all(|i| a[(i, j)] == 0.0))
}

/// For an upper triangular `2⁻ˢT` (`scaled`), replaces the diagonal and first superdiagonal
/// of the iterate `X ≈ e^{2^(step−s) T}` by their exact values (Al-Mohy & Higham 2009, Code
/// Fragment 2.1): `e^{λ_k}` and, from Higham, *Functions of Matrices* (2008), eq. (10.42),
/// `t₁₂ e^{(λ₁+λ₂)/2} sinh((λ₁−λ₂)/2) / ((λ₁−λ₂)/2)`. The squarings then cannot accumulate
/// errors on them, which makes stiff triangular models (the zero-order hold's block matrix of
/// a triangular `A`) accurate to the last digits.
fn replace_triangular_entries(x: &mut Mat, scaled: &Mat, step: u32) {
    let n = x.nrows();
    // 2^(step − s) T = 2^step · 2⁻ˢT: exact, a power of two.
    let factor = 2f64.powi(step as i32);
    for k in 0..n {
        x[(k, k)] = (factor * scaled[(k, k)]).exp();
    }
    if step == 0 {
        return;
    }
    for k in 0..n.saturating_sub(1) {
        let (l1, l2) = (factor * scaled[(k, k)], factor * scaled[(k + 1, k + 1)]);
        let t12 = factor * scaled[(k, k + 1)];
        let (mean, half) = ((l1 + l2) / 2.0, (l1 - l2) / 2.0);
        let value = if half.abs() < 0.0135 {
            let h2 = half * half;
            t12 * mean.exp() * (1.0 + h2 / 6.0 * (1.0 + h2 / 20.0 * (1.0 + h2 / 42.0)))
        } else {
            let (e, sh) = (mean.exp(), half.sinh());
            if e > 0.0 && e.is_finite() && sh.is_finite() {
                t12 * e * (sh / half)
            } else {
                // |λ₁ − λ₂| is large here, so the difference does not cancel.
                t12 * (l1.exp() - l2.exp()) / (l1 - l2)
            }
        };
        x[(k, k + 1)] = value;
    }
}

/// `‖E‖₁ / ‖X‖₁`; `None` for the zero matrix `X`, infinite when `E` overflowed.
fn relative_error(error: &Mat, x: &Mat) -> Option<f64> {
    let norm = one_norm(x);
    if norm == 0.0 {
        return None;
    }
    let ratio = one_norm(error) / norm;
    Some(if ratio.is_nan() { f64::INFINITY } else { ratio })
}

/// A fixed `n × n` pattern of signs ±1 for step `step` (splitmix64 of the entry's index): the
/// signs of the rounding errors the estimate propagates. Fixed, so that the estimate, and
/// whether `c2d` accepts a model, is reproducible.
fn error_signs(n: usize, step: u32) -> Mat {
    let base = (u64::from(step) + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    Mat::from_fn(n, n, |i, j| {
        let mut z = base.wrapping_add((i * n + j) as u64 + 1);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        if z & 1 == 0 {
            1.0
        } else {
            -1.0
        }
    })
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

    /// Largest elementwise error in units of the unit round-off of each entry of `want`.
    fn ulps(got: &Mat, want: &Mat) -> f64 {
        got.iter()
            .zip(want.iter())
            .map(|(g, w)| (g - w).abs() / (w.abs().max(f64::MIN_POSITIVE) * f64::EPSILON))
            .fold(0.0, f64::max)
    }

    #[test]
    fn expm_does_not_overscale_a_non_normal_matrix() {
        // [[1, b], [0, −1]] squares to I for every b, so no squaring is needed; scaling by ‖A‖₁
        // (Higham 2005) squared log₂ b times and lost 7.5e-9 at b = 1e12.
        // e^A = [[e, b sinh 1], [0, 1/e]] exactly.
        for b in [1.0, 1e4, 1e8, 1e12, 1e13, 1e16, 1e50, 1e100] {
            let a = mat(2, 2, &[1.0, b, 0.0, -1.0]);
            let exp = expm_with_estimate(&a).unwrap();
            let want = mat(
                2,
                2,
                &[std::f64::consts::E, b * 1f64.sinh(), 0.0, (-1f64).exp()],
            );
            let err = ulps(&exp.value, &want);
            assert!(err <= 4.0, "b = {b:e}: {err} ulps");
            assert_eq!(exp.squarings, 0, "b = {b:e}");
            assert!(
                exp.error_estimate < 1e-14,
                "b = {b:e}: {}",
                exp.error_estimate
            );
        }
    }

    #[test]
    fn expm_of_molers_badly_scaled_matrix_matches_the_published_values() {
        // Burkardt's test 14 (Moler's example, which defeated Higham 2005's scaling): the
        // reference values are Burkardt's, to 15 digits.
        let a = mat(
            3,
            3,
            &[
                0.0,
                1e-8,
                0.0,
                -(2e10 + 4e8 / 6.0),
                -3.0,
                2e10,
                200.0 / 3.0,
                0.0,
                -200.0 / 3.0,
            ],
        );
        let want = mat(
            3,
            3,
            &[
                0.446849468283175,
                1.54044157383952e-09,
                0.462811453558774,
                -5743067.77947947,
                -0.0152830038686819,
                -4526542.71278401,
                0.447722977849494,
                1.54270484519591e-09,
                0.463480648837651,
            ],
        );
        let exp = expm_with_estimate(&a).unwrap();
        let rel = exp
            .value
            .iter()
            .zip(want.iter())
            .map(|(g, w)| ((g - w) / w).abs())
            .fold(0.0, f64::max);
        assert!(rel < 1e-11, "{rel:e}");
        assert!(
            exp.error_estimate < C2D_ERROR_TOLERANCE,
            "{}",
            exp.error_estimate
        );
        assert!(c2d(&a, &mat(3, 1, &[0.0, 1.0, 0.0]), 1.0).is_ok());
    }

    #[test]
    fn c2d_of_stiff_triangular_models_is_accepted_and_exact() {
        // A = [[−1, 1], [0, −λ]]: e^{AT} = [[e^{−T}, (e^{−T} − e^{−λT})/(λ − 1)], [0, e^{−λT}]].
        // det e^{AT} = e^{−(1+λ)T} is below the rounding of the computed determinant for
        // λ ≥ 37 at T = 1, which is what the determinant test refused.
        for lambda in [37.0, 50.0, 100.0, 1e3, 1e4] {
            let a = mat(2, 2, &[-1.0, 1.0, 0.0, -lambda]);
            let (ad, bd) = c2d(&a, &mat(2, 1, &[0.0, 1.0]), 1.0).unwrap();
            let (e1, el) = ((-1f64).exp(), (-lambda).exp());
            let want = mat(2, 2, &[e1, (e1 - el) / (lambda - 1.0), 0.0, el]);
            assert!(
                (&ad - &want).amax() < 4.0 * f64::EPSILON,
                "λ = {lambda}: {} {ad} {want}",
                (&ad - &want).amax() / f64::EPSILON
            );
            // B_d = ∫₀¹ e^{Aτ} dτ [0; 1].
            let bd_want = mat(
                2,
                1,
                &[
                    ((1.0 - e1) - (1.0 - el) / lambda) / (lambda - 1.0),
                    (1.0 - el) / lambda,
                ],
            );
            assert!((&bd - &bd_want).amax() < 4.0 * f64::EPSILON, "λ = {lambda}");
        }
    }

    #[test]
    fn c2d_of_the_pascal_matrix_is_accepted_and_exact() {
        // scipy's test: the subdiagonal 1, 2, …, n has e^A with entries binom(i, j).
        for n in [10, 40, 41, 60, 78] {
            let mut a = Mat::zeros(n + 1, n + 1);
            for i in 1..=n {
                a[(i, i - 1)] = i as f64;
            }
            let (ad, _) = c2d(&a, &Mat::zeros(n + 1, 1), 1.0).unwrap();
            let mut want = Mat::zeros(n + 1, n + 1);
            for i in 0..=n {
                want[(i, 0)] = 1.0;
                for j in 1..=i {
                    want[(i, j)] =
                        want[(i - 1, j - 1)] + if j < i { want[(i - 1, j)] } else { 0.0 };
                }
            }
            let err = (&ad - &want).amax() / want.amax();
            assert!(err < 1e-14, "n = {n}: {err:e}");
        }
    }

    #[test]
    fn expm_estimate_tracks_the_lost_digits_of_a_fast_rotation() {
        // e^{[[0, w], [−w, 0]]} = [[cos w, sin w], [−sin w, cos w]]: every squaring doubles the
        // relative error, so ~2^log₂(w) u of it is real.
        for (w, lo, hi) in [
            (1e3, 1e-14, 1e-11),
            (1e10, 1e-7, 1e-4),
            (1e15, 1e-3, f64::INFINITY),
            (1e20, f64::INFINITY, f64::INFINITY),
        ] {
            let a = mat(2, 2, &[0.0, w, -w, 0.0]);
            let exp = expm_with_estimate(&a).unwrap();
            let err = (exp.value[(0, 0)] - w.cos()).abs();
            assert!(
                err <= exp.error_estimate * 2.0,
                "w = {w:e}: {err:e} > {:e}",
                exp.error_estimate
            );
            assert!(
                (lo..=hi).contains(&exp.error_estimate),
                "w = {w:e}: {:e}",
                exp.error_estimate
            );
        }
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
