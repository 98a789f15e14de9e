//! Discrete-time linear-quadratic regulator design (python-control `dlqr`, MATLAB `dlqr`).
//!
//! Minimises `Σ xᵀQx + uᵀRu + 2xᵀNu` subject to `x[k+1] = A x[k] + B u[k]`; the optimal law is
//! `u = −K x` with `K = (BᵀSB + R)⁻¹(BᵀSA + Nᵀ)` and `S` the stabilizing DARE solution.
//!
//! [`dlqr_integral`] is python-control's `dlqr(..., integral_action=C)`: the same design on the
//! plant augmented with the discrete integrators `z[k+1] = z[k] + C x[k]`,
//!
//! ```text
//! A_aug = [[A, 0], [C, I]],   B_aug = [[B], [0]],
//! ```
//!
//! whose gain `K = [K_x, K_z]` feeds back the state and the integrated `C x`.

use nalgebra::Complex;

use crate::dare::dare;
use crate::error::{Result, RipError};
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

/// [`dlqr`] on the plant augmented with integrators of `C x` (module docs): `c` (named
/// `integral_action`) is `p × n`, `q` is `(n + p) × (n + p)` and `n` (the cross weight)
/// `(n + p) × m`. Returns the gain `[K_x, K_z]`, the Riccati solution and the closed-loop
/// eigenvalues of the augmented system.
pub fn dlqr_integral(
    a: &Mat,
    b: &Mat,
    q: &Mat,
    r: &Mat,
    n: Option<&Mat>,
    c: &Mat,
) -> Result<LqrDesign> {
    let (a_aug, b_aug) = integral_augmentation(a, b, c)?;
    dlqr(&a_aug, &b_aug, q, r, n)
}

/// `A_aug = [[A, 0], [C, I]]`, `B_aug = [[B], [0]]` (module docs); `c` is named
/// `integral_action` in errors.
pub fn integral_augmentation(a: &Mat, b: &Mat, c: &Mat) -> Result<(Mat, Mat)> {
    let nx = check_state_matrix("A", a, &[("B", b.nrows())])?;
    let nu = b.ncols();
    check_shape("B", b, nx, nu)?;
    if c.nrows() == 0 || c.ncols() != nx {
        return Err(RipError::Shape {
            name: "integral_action".into(),
            expected: format!("(p, {nx}) with p ≥ 1, one row per integrated output of the state"),
            rows: c.nrows(),
            cols: c.ncols(),
        });
    }
    check_finite("integral_action", c)?;
    let p = c.nrows();
    let mut a_aug = Mat::zeros(nx + p, nx + p);
    a_aug.view_mut((0, 0), (nx, nx)).copy_from(a);
    a_aug.view_mut((nx, 0), (p, nx)).copy_from(c);
    a_aug
        .view_mut((nx, nx), (p, p))
        .copy_from(&Mat::identity(p, p));
    let mut b_aug = Mat::zeros(nx + p, nu);
    b_aug.view_mut((0, 0), (nx, nu)).copy_from(b);
    Ok((a_aug, b_aug))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integral_action_of_a_scalar_plant_matches_the_closed_form_riccati_solution() {
        // x[k+1] = a x + u with z[k+1] = z + x: A_aug = [[a, 0], [1, 1]], B_aug = [1; 0].
        let a = Mat::from_row_slice(1, 1, &[0.5]);
        let b = Mat::from_row_slice(1, 1, &[1.0]);
        let c = Mat::from_row_slice(1, 1, &[1.0]);
        let (a_aug, b_aug) = integral_augmentation(&a, &b, &c).unwrap();
        assert_eq!(a_aug, Mat::from_row_slice(2, 2, &[0.5, 0.0, 1.0, 1.0]));
        assert_eq!(b_aug, Mat::from_row_slice(2, 1, &[1.0, 0.0]));
        let q = Mat::identity(2, 2);
        let r = Mat::from_row_slice(1, 1, &[1.0]);
        let design = dlqr_integral(&a, &b, &q, &r, None, &c).unwrap();
        // The Riccati equation holds at the returned S and the loop is stable.
        let s = &design.s;
        let btsb_r = (b_aug.transpose() * s * &b_aug)[(0, 0)] + 1.0;
        let cross = a_aug.transpose() * s * &b_aug;
        let residual =
            a_aug.transpose() * s * &a_aug - s - &cross * cross.transpose() / btsb_r + &q;
        assert!(residual.amax() < 1e-12, "{residual}");
        assert!(design.e.iter().all(|z| z.norm() < 1.0));
        assert_eq!(design.k.ncols(), 2);
    }

    #[test]
    fn integral_action_of_the_wrong_width_names_the_argument() {
        let a = Mat::identity(3, 3);
        let b = Mat::from_element(3, 1, 1.0);
        let err = integral_augmentation(&a, &b, &Mat::identity(2, 2)).unwrap_err();
        assert!(matches!(err, RipError::Shape { ref name, .. } if name == "integral_action"));
    }
}
