//! The augmented prediction model of the module docs (eq. (3)): the plant with its
//! output-disturbance model and measurement-noise model, in scaled output units.

use crate::linalg::Mat;

use super::OutputDisturbance;

/// The augmented prediction model (module docs).
#[derive(Debug, Clone)]
pub struct AugmentedModel {
    /// `A_aug = blkdiag(A, A_od)`.
    pub a: Mat,
    /// `B_u = [B; 0]`.
    pub b: Mat,
    /// `C_aug = [S_y⁻¹ C, C_od]`.
    pub c: Mat,
    /// Noise input matrix `[B S_u 0 0; 0 B_od 0]` of eq. (3).
    pub b_noise: Mat,
    /// Noise feedthrough `[0 0 D_n]` of eq. (3).
    pub d_noise: Mat,
    /// Number of plant states (the first states of the augmented model).
    pub n_plant: usize,
}

/// Builds the augmented model of the module docs.
pub(crate) fn augment(
    a: &Mat,
    b: &Mat,
    c: &Mat,
    su: &[f64],
    sy: &[f64],
    od: Option<&OutputDisturbance>,
    dn: &Mat,
) -> AugmentedModel {
    let (n, nu, ny) = (a.nrows(), b.ncols(), c.nrows());
    let (nd, nw) = od.map_or((0, 0), |od| (od.a.nrows(), od.b.ncols()));
    let nv = dn.ncols();
    let nx = n + nd;
    let mut aa = Mat::zeros(nx, nx);
    aa.view_mut((0, 0), (n, n)).copy_from(a);
    let mut bb = Mat::zeros(nx, nu);
    bb.view_mut((0, 0), (n, nu)).copy_from(b);
    let mut cc = Mat::zeros(ny, nx);
    for i in 0..ny {
        for j in 0..n {
            cc[(i, j)] = c[(i, j)] / sy[i];
        }
    }
    let mut b_noise = Mat::zeros(nx, nu + nw + nv);
    for j in 0..nu {
        for i in 0..n {
            b_noise[(i, j)] = b[(i, j)] * su[j];
        }
    }
    if let Some(od) = od {
        aa.view_mut((n, n), (nd, nd)).copy_from(&od.a);
        cc.view_mut((0, n), (ny, nd)).copy_from(&od.c);
        b_noise.view_mut((n, nu), (nd, nw)).copy_from(&od.b);
    }
    let mut d_noise = Mat::zeros(ny, nu + nw + nv);
    d_noise.view_mut((0, nu + nw), (ny, nv)).copy_from(dn);
    AugmentedModel {
        a: aa,
        b: bb,
        c: cc,
        b_noise,
        d_noise,
        n_plant: n,
    }
}
