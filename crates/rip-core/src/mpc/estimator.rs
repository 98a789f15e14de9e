//! The Kalman design of the MPC's augmented model (eqs. (1)–(11), module docs of
//! [`crate::mpc`]), separate from the controller so that one design can serve an MPC and an
//! LQG alike.

use super::model::augment;
use super::settings::fill_default;
use super::{AugmentedModel, MpcSettings, OutputDisturbance};
use crate::error::{Result, RipError};
use crate::kalman::{kalman, KalmanDesign};
use crate::linalg::{check_finite, check_shape, check_square, Mat};

/// The augmented model and its steady-state Kalman gains, with the settings they depend on
/// (input and output scales, output disturbance, measurement noise).
#[derive(Debug, Clone)]
pub struct EstimatorDesign {
    model: AugmentedModel,
    kalman: KalmanDesign,
    input_scales: Vec<f64>,
    output_scales: Vec<f64>,
    disturbance: Option<OutputDisturbance>,
    measurement_noise: Mat,
}

impl EstimatorDesign {
    /// Augments the discrete plant `x⁺ = A x + B u`, `y = C x` with the disturbance and noise
    /// models of `settings` and designs `[L, M] = kalman(A_aug, I, C_aug, Q, R, N)` (eq. (11)).
    pub fn new(a: &Mat, b: &Mat, c: &Mat, settings: &MpcSettings) -> Result<Self> {
        let n = check_square("A", a)?;
        let nu = b.ncols();
        let ny = c.nrows();
        if nu == 0 {
            return Err(RipError::invalid("B", "needs at least one input column"));
        }
        if ny == 0 {
            return Err(RipError::invalid("C", "needs at least one output row"));
        }
        check_shape("B", b, n, nu)?;
        check_shape("C", c, ny, n)?;
        check_finite("A", a)?;
        check_finite("B", b)?;
        check_finite("C", c)?;
        let su = fill_default("input_scales", &settings.input_scales, nu, 1.0)?;
        let sy = fill_default("output_scales", &settings.output_scales, ny, 1.0)?;
        if let Some(od) = &settings.output_disturbance {
            check_shape("C_od", &od.c, ny, od.a.nrows())?;
        }
        let dn = match &settings.measurement_noise {
            Some(dn) => {
                if dn.nrows() != ny || dn.ncols() == 0 {
                    return Err(RipError::Shape {
                        name: "measurement_noise".into(),
                        expected: format!("({ny}, nv) with nv ≥ 1"),
                        rows: dn.nrows(),
                        cols: dn.ncols(),
                    });
                }
                if (dn * dn.transpose()).cholesky().is_none() {
                    return Err(RipError::NotPositiveDefinite {
                        name: "measurement_noise D_n D_nᵀ".into(),
                    });
                }
                dn.clone()
            }
            None => Mat::identity(ny, ny),
        };
        let model = augment(a, b, c, &su, &sy, settings.output_disturbance.as_ref(), &dn);
        let nx = model.a.nrows();
        super::model::check_noise_model(&model, settings.output_disturbance.as_ref(), &dn)?;
        let q = &model.b_noise * model.b_noise.transpose();
        let r = &model.d_noise * model.d_noise.transpose();
        let nn = &model.b_noise * model.d_noise.transpose();
        let kalman = kalman(
            &model.a,
            &Mat::identity(nx, nx),
            &model.c,
            &q,
            &r,
            Some(&nn),
            None,
        )
        .map_err(|e| super::model::explain_estimator_failure(e, c, &sy))?;
        Ok(Self {
            model,
            kalman,
            input_scales: su,
            output_scales: sy,
            disturbance: settings.output_disturbance.clone(),
            measurement_noise: dn,
        })
    }

    /// The augmented model of eq. (3).
    pub fn model(&self) -> &AugmentedModel {
        &self.model
    }

    /// The Kalman gains `L`, `M` of eq. (11) (on the scaled outputs `y/s_y`).
    pub fn kalman(&self) -> &KalmanDesign {
        &self.kalman
    }

    /// Number of plant inputs.
    pub fn n_inputs(&self) -> usize {
        self.model.b.ncols()
    }

    /// Number of plant outputs.
    pub fn n_outputs(&self) -> usize {
        self.model.c.nrows()
    }

    /// The output scale factors `s^y` the filter was designed with.
    pub fn output_scales(&self) -> &[f64] {
        &self.output_scales
    }

    /// Fails unless `settings` has the scales, disturbance and noise this design was made
    /// with: an MPC whose prediction model differed from its estimator's would be wrong.
    pub(super) fn check_settings(&self, settings: &MpcSettings) -> Result<()> {
        let (nu, ny) = (self.n_inputs(), self.n_outputs());
        let su = fill_default("input_scales", &settings.input_scales, nu, 1.0)?;
        let sy = fill_default("output_scales", &settings.output_scales, ny, 1.0)?;
        let dn = settings
            .measurement_noise
            .clone()
            .unwrap_or_else(|| Mat::identity(ny, ny));
        let same_od = match (&settings.output_disturbance, &self.disturbance) {
            (None, None) => true,
            (Some(x), Some(y)) => x.a == y.a && x.b == y.b && x.c == y.c,
            _ => false,
        };
        for (name, same) in [
            ("input_scales", su == self.input_scales),
            ("output_scales", sy == self.output_scales),
            ("output_disturbance", same_od),
            ("measurement_noise", dn == self.measurement_noise),
        ] {
            if !same {
                return Err(RipError::invalid(
                    name,
                    "differs from the one the estimator design was made with",
                ));
            }
        }
        Ok(())
    }
}
