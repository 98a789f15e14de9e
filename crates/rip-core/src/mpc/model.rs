//! The augmented prediction model of the module docs (eq. (3)): the plant with its
//! output-disturbance model and measurement-noise model, in scaled output units.

use crate::error::{Result, RipError};
use crate::linalg::{spectral_radius, Mat};

use super::condense::Condensed;
use super::{MpcSettings, OutputDisturbance};

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

/// Fails, naming the setting responsible, when the estimator's noise covariances
/// `B_n B_nᵀ`, `D_n D_nᵀ` overflow: each block of `B_n` comes from one setting, so the one
/// whose squared entries leave double precision is named.
pub(crate) fn check_noise_model(
    model: &AugmentedModel,
    od: Option<&OutputDisturbance>,
    dn: &Mat,
) -> Result<()> {
    let squares_finite = |m: &Mat| (m * m.transpose()).iter().all(|v| v.is_finite());
    let n = model.n_plant;
    let nu = model.b.ncols();
    let overflow = |name: &str, what: &str| {
        RipError::invalid(
            name,
            format!(
                "{what} is too large: the estimator's noise covariance built from it overflows \
                 double precision (entries beyond 1e308)"
            ),
        )
    };
    if !squares_finite(&model.b_noise.view((0, 0), (n, nu)).into_owned()) {
        return Err(overflow("input_scales", "B·S_u"));
    }
    if let Some(od) = od {
        if !squares_finite(&od.b) {
            return Err(overflow("output_disturbance", "its noise gain B_od"));
        }
    }
    if !squares_finite(dn) {
        return Err(overflow("measurement_noise", "D_n"));
    }
    Ok(())
}

/// Rewrites an estimator-design failure so that it names its cause. A detectable plant turns
/// "not detectable" when output scale factors far from the outputs' ranges shrink (or blow up)
/// the scaled outputs `S_y⁻¹ C` by many orders of magnitude; the error then names
/// `output_scales`.
pub(crate) fn explain_estimator_failure(err: RipError, c: &Mat, sy: &[f64]) -> RipError {
    match err {
        RipError::NotDetectable {
            re, im, modulus, ..
        } => {
            let (lo, hi) = sy.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &s| {
                (lo.min(s), hi.max(s))
            });
            let scaled = Mat::from_fn(c.nrows(), c.ncols(), |i, j| c[(i, j)] / sy[i]);
            let ratio = scaled.amax() / c.amax().max(f64::MIN_POSITIVE);
            if !(1e-8..=1e8).contains(&ratio) || hi / lo > 1e8 {
                return RipError::invalid(
                    "output_scales",
                    format!(
                        "scale factors between {lo:e} and {hi:e} make the scaled outputs \
                         C/s_y numerically invisible to the estimator (mode {re:.6}{im:+.6}i, \
                         |λ| = {modulus:.6}, cannot be seen); a scale factor is the output's \
                         typical range in engineering units"
                    ),
                );
            }
            RipError::NotDetectable {
                pair: "(A_aug, C_aug) of the plant with its output disturbance model".into(),
                re,
                im,
                modulus,
            }
        }
        other => other,
    }
}

/// Fails, naming what is actually wrong, unless the condensed QP is finite and its Hessian
/// factors. In exact arithmetic the Hessian `2(GᵀQ_yG + R_Δu + TᵀQ_uT)` is positive definite
/// when every input has a positive rate or input weight; a failure then comes from the
/// conditioning of the condensed problem, whose predictions grow like `ρ(A)ᴾ`, so the
/// horizon is named, with `ρ` and `P`.
pub(crate) fn check_condensed(
    qp: &Condensed,
    model: &AugmentedModel,
    settings: &MpcSettings,
    wdu: &[f64],
    wu: &[f64],
) -> Result<()> {
    let p = settings.prediction_horizon;
    let rho = spectral_radius(&model.a);
    let growth = || {
        if rho > 1.0 {
            format!(
                "the model's spectral radius is {rho:.6}, so the predictions grow like \
                 ρ^P ≈ 1e{:.0} over P = {p} steps",
                p as f64 * rho.log10()
            )
        } else {
            format!("the model's spectral radius is {rho:.6}, P = {p}")
        }
    };
    let all_finite = |m: &Mat| m.iter().all(|v| v.is_finite());
    // The Hessian holds squares of the predictions: predictions beyond √(f64::MAX) ≈ 1e154
    // overflow it whatever the weights.
    let largest_prediction = qp.phi.amax().max(qp.gamma.amax()).max(qp.g.amax());
    if !(all_finite(&qp.phi) && all_finite(&qp.gamma) && all_finite(&qp.g))
        || (!all_finite(&qp.h) && largest_prediction > 1e150)
    {
        return Err(RipError::invalid(
            "prediction_horizon",
            format!(
                "the predictions overflow double precision: {}; shorten the horizon",
                growth()
            ),
        ));
    }
    if !(all_finite(&qp.h) && all_finite(&qp.a)) {
        return Err(RipError::invalid(
            "output_weights",
            "the weights over the scale factors (output_weights, input_weights, \
             input_rate_weights, ecr_weight, input_scales, output_scales) overflow the \
             condensed QP (entries beyond 1e308); scale them down",
        ));
    }
    if qp.h.clone().cholesky().is_some() {
        return Ok(());
    }
    let unweighted = wdu.iter().zip(wu).position(|(&r, &w)| r == 0.0 && w == 0.0);
    match unweighted {
        Some(j) => Err(RipError::invalid(
            "input_rate_weights",
            format!(
                "input {j} has zero input_rate_weights and input_weights, and the outputs do \
                 not determine its moves, so the QP Hessian is singular; give it a positive \
                 rate (or input) weight"
            ),
        )),
        None => Err(RipError::invalid(
            "prediction_horizon",
            format!(
                "the condensed QP is too ill-conditioned to factor in double precision \
                 although every input has a positive rate or input weight: {}; shorten the \
                 horizon or raise input_rate_weights",
                growth()
            ),
        )),
    }
}
