//! Discrete-time linear-quadratic regulator design (python-control `dlqr`, MATLAB `dlqr`).
//!
//! Minimises `Σ xᵀQx + uᵀRu + 2xᵀNu` subject to `x[k+1] = A x[k] + B u[k]`; the optimal law is
//! `u = −K x` with `K = (BᵀSB + R)⁻¹(BᵀSA + Nᵀ)` and `S` the stabilizing DARE solution.

use nalgebra::Complex;

use crate::dare::dare;
use crate::error::Result;
use crate::linalg::{
    check_finite, check_joint_psd, check_psd, check_shape, check_state_matrix, check_symmetric,
    symmetrize, Mat,
};

/// The result of [`dlqr`], in python-control's order `(K, S, E)`.
#[derive(Debug, Clone)]
pub struct LqrDesign {
    /// State-feedback gain; the control law is `u = −K x`.
    pub k: Mat,
    /// Stabilizing solution of the Riccati equation.
    pub s: Mat,
    /// Closed-loop eigenvalues `eig(A − BK)`.
    pub e: Vec<Complex<f64>>,
}

/// Designs the discrete LQR gain.
///
/// Besides the checks of [`dare`], the joint weight `[[Q, N], [Nᵀ, R]]` must be positive
/// semidefinite, as MATLAB requires, so that the cost is bounded below.
pub fn dlqr(a: &Mat, b: &Mat, q: &Mat, r: &Mat, n: Option<&Mat>) -> Result<LqrDesign> {
    let nx = check_state_matrix(
        "A",
        a,
        &[("B", b.nrows()), ("Q", q.nrows()), ("Q", q.ncols())],
    )?;
    let nu = b.ncols();
    check_shape("B", b, nx, nu)?;
    check_shape("Q", q, nx, nx)?;
    check_shape("R", r, nu, nu)?;
    check_finite("Q", q)?;
    check_finite("R", r)?;
    check_symmetric("Q", q)?;
    check_symmetric("R", r)?;
    match n {
        Some(n) => {
            check_shape("N", n, nx, nu)?;
            check_finite("N", n)?;
            check_joint_psd("[[Q, N], [Nᵀ, R]]", &symmetrize(q), n, &symmetrize(r))?;
        }
        None => check_psd("Q", &symmetrize(q))?,
    }
    let sol = dare(a, b, q, r, n, None)?;
    Ok(LqrDesign {
        k: sol.gain,
        s: sol.x,
        e: sol.closed_loop_eigenvalues,
    })
}
