//! Steady-state Kalman filter design and the allocation-free "current" estimator.
//!
//! # Design (MATLAB `kalman`, discrete time)
//!
//! For the plant
//!
//! ```text
//! x[k+1] = A x[k] + B u[k] + G w[k]
//! y[k]   = C x[k] + D u[k] + H w[k] + v[k],   E{wwᵀ} = Qn, E{vvᵀ} = Rn, E{wvᵀ} = Nn
//! ```
//!
//! the noise seen by the filter is `Q̄ = G Qn Gᵀ`, `R̄ = Rn + H Nn + Nnᵀ Hᵀ + H Qn Hᵀ`,
//! `N̄ = G (Qn Hᵀ + Nn)`. `P` (the prior covariance of `x − x̂[k|k−1]`) solves the filtering DARE
//!
//! ```text
//! P = A P Aᵀ − (A P Cᵀ + N̄)(C P Cᵀ + R̄)⁻¹(A P Cᵀ + N̄)ᵀ + Q̄
//! ```
//!
//! and the gains and posterior covariance are
//!
//! ```text
//! L = (A P Cᵀ + N̄)(C P Cᵀ + R̄)⁻¹        predictor gain,  x̂[k+1|k]
//! M = P Cᵀ (C P Cᵀ + R̄)⁻¹                innovation gain, x̂[k|k]
//! Z = (I − MC) P (I − MC)ᵀ + M R̄ Mᵀ       covariance of x − x̂[k|k]
//! ```
//!
//! These are the paper's eqs. (7)–(12) (with `G = I`, `H = 0`, `Qn = BBᵀ`, `Rn = DDᵀ`,
//! `Nn = BDᵀ`). [`dlqe`] is python-control's `dlqe`, which returns only `L`.
//!
//! # Estimation (the paper's eqs. (4)–(6))
//!
//! [`CurrentEstimator`] runs, each sample,
//! `e[k] = y[k] − C x̂[k|k−1] − D u[k]`, `x̂[k|k] = x̂[k|k−1] + M e[k]`,
//! `x̂[k+1|k] = A x̂[k|k−1] + B u[k] + L e[k]`, with preallocated buffers only.

use nalgebra::{Complex, DVector};

use crate::dare::solve_dare_validated;
use crate::error::{Result, RipError};
use crate::linalg::{
    check_finite, check_joint_psd, check_psd, check_shape, check_square, check_symmetric,
    eigenvalues, symmetrize, Mat,
};

/// The result of [`kalman`]: MATLAB's `[~, L, P, M, Z] = kalman(sys, Qn, Rn, Nn)`.
#[derive(Debug, Clone)]
pub struct KalmanDesign {
    /// Predictor gain (`x̂[k+1|k]` update).
    pub l: Mat,
    /// Innovation gain (`x̂[k|k]` update).
    pub m: Mat,
    /// Steady-state prior error covariance, `cov(x − x̂[k|k−1])`.
    pub p: Mat,
    /// Steady-state posterior error covariance, `cov(x − x̂[k|k])`.
    pub z: Mat,
    /// Estimator poles, `eig(A − L C)`.
    pub e: Vec<Complex<f64>>,
}

/// Designs the steady-state Kalman filter (see the module docs). `nn` defaults to zero and `h`
/// to zero. Errors name the argument or the pair `(A, C)`.
#[allow(clippy::too_many_arguments)]
pub fn kalman(
    a: &Mat,
    g: &Mat,
    c: &Mat,
    qn: &Mat,
    rn: &Mat,
    nn: Option<&Mat>,
    h: Option<&Mat>,
) -> Result<KalmanDesign> {
    let nx = check_square("A", a)?;
    let nw = g.ncols();
    let ny = c.nrows();
    check_shape("G", g, nx, nw)?;
    check_shape("C", c, ny, nx)?;
    if ny == 0 || nw == 0 {
        return Err(RipError::invalid(
            "C, G",
            "need at least one output and one noise input",
        ));
    }
    check_shape("Qn", qn, nw, nw)?;
    check_shape("Rn", rn, ny, ny)?;
    if let Some(nn) = nn {
        check_shape("Nn", nn, nw, ny)?;
    }
    if let Some(h) = h {
        check_shape("H", h, ny, nw)?;
    }
    for (name, m) in [("A", a), ("G", g), ("C", c), ("Qn", qn), ("Rn", rn)] {
        check_finite(name, m)?;
    }
    if let Some(nn) = nn {
        check_finite("Nn", nn)?;
    }
    if let Some(h) = h {
        check_finite("H", h)?;
    }
    check_symmetric("Qn", qn)?;
    check_symmetric("Rn", rn)?;
    let qn = symmetrize(qn);
    let rn = symmetrize(rn);
    check_noise_covariance(&qn, &rn, nn)?;

    let zeros_wy = Mat::zeros(nw, ny);
    let nn = nn.unwrap_or(&zeros_wy);
    let q_bar = symmetrize(&(g * &qn * g.transpose()));
    let (r_bar, n_bar) = match h {
        Some(h) => (
            symmetrize(&(&rn + h * nn + nn.transpose() * h.transpose() + h * &qn * h.transpose())),
            g * (&qn * h.transpose() + nn),
        ),
        None => (rn.clone(), g * nn),
    };
    if r_bar.clone().cholesky().is_none() {
        return Err(RipError::NotPositiveDefinite {
            name: "Rn + H Nn + Nnᵀ Hᵀ + H Qn Hᵀ".into(),
        });
    }
    let sol = solve_dare_validated(
        &a.transpose(),
        &c.transpose(),
        &q_bar,
        &r_bar,
        Some(&n_bar),
        None,
    )
    .map_err(|f| f.into_error("(A, C)", true))?;
    let p = sol.x;
    let innovation_cov = symmetrize(&(c * &p * c.transpose() + &r_bar));
    let chol = innovation_cov
        .cholesky()
        .ok_or_else(|| RipError::NotPositiveDefinite {
            name: "C P Cᵀ + R̄".into(),
        })?;
    // Gains are right-divisions: K = X S⁻¹ ⇔ Kᵀ = S⁻¹ Xᵀ (S symmetric).
    let l = chol
        .solve(&(a * &p * c.transpose() + &n_bar).transpose())
        .transpose();
    let m = chol.solve(&(c * &p)).transpose();
    let i_mc = Mat::identity(nx, nx) - &m * c;
    let z = symmetrize(&(&i_mc * &p * i_mc.transpose() + &m * &r_bar * m.transpose()));
    let e = eigenvalues(&(a - &l * c));
    Ok(KalmanDesign { l, m, p, z, e })
}

/// python-control's `dlqe(A, G, C, QN, RN, NN)`: the predictor gain `L`, the prior covariance
/// `P` and the estimator poles `eig(A − LC)`. Here `NN` is the cross-covariance `E{wvᵀ}`.
pub fn dlqe(
    a: &Mat,
    g: &Mat,
    c: &Mat,
    qn: &Mat,
    rn: &Mat,
    nn: Option<&Mat>,
) -> Result<(Mat, Mat, Vec<Complex<f64>>)> {
    let design = kalman(a, g, c, qn, rn, nn, None)?;
    Ok((design.l, design.p, design.e))
}

/// `Rn` must be positive definite and the joint covariance `[[Qn, Nn], [Nnᵀ, Rn]]` positive
/// semidefinite: anything else is not the covariance of a noise.
fn check_noise_covariance(qn: &Mat, rn: &Mat, nn: Option<&Mat>) -> Result<()> {
    if rn.clone().cholesky().is_none() {
        return Err(RipError::NotPositiveDefinite { name: "Rn".into() });
    }
    match nn {
        None => check_psd("Qn", qn),
        Some(nn) => check_joint_psd("[[Qn, Nn], [Nnᵀ, Rn]]", qn, nn, rn),
    }
}

/// Steady-state Kalman filter in "current" form (module docs, paper eqs. (4)–(6)).
///
/// All buffers are allocated in [`CurrentEstimator::new`]; [`correct`](Self::correct),
/// [`predict`](Self::predict) and their `_without_measurement` variants only write into them.
#[derive(Debug, Clone)]
pub struct CurrentEstimator {
    a: Mat,
    b: Mat,
    c: Mat,
    d: Mat,
    l: Mat,
    m: Mat,
    x0: DVector<f64>,
    prior: DVector<f64>,
    posterior: DVector<f64>,
    innovation: DVector<f64>,
    scratch: DVector<f64>,
}

impl CurrentEstimator {
    /// Builds the estimator for `x[k+1] = A x + B u`, `y = C x + D u` with gains `L`, `M`,
    /// starting from the prior estimate `x0`.
    pub fn new(
        a: Mat,
        b: Mat,
        c: Mat,
        d: Option<Mat>,
        l: Mat,
        m: Mat,
        x0: DVector<f64>,
    ) -> Result<Self> {
        let nx = check_square("A", &a)?;
        let nu = b.ncols();
        let ny = c.nrows();
        check_shape("B", &b, nx, nu)?;
        check_shape("C", &c, ny, nx)?;
        let d = d.unwrap_or_else(|| Mat::zeros(ny, nu));
        check_shape("D", &d, ny, nu)?;
        check_shape("L", &l, nx, ny)?;
        check_shape("M", &m, nx, ny)?;
        if x0.len() != nx {
            return Err(RipError::Shape {
                name: "x0".into(),
                expected: format!("({nx},)"),
                rows: x0.len(),
                cols: 1,
            });
        }
        for (name, mat) in [
            ("A", &a),
            ("B", &b),
            ("C", &c),
            ("D", &d),
            ("L", &l),
            ("M", &m),
        ] {
            check_finite(name, mat)?;
        }
        if x0.iter().any(|v| !v.is_finite()) {
            return Err(RipError::NonFinite { name: "x0".into() });
        }
        Ok(Self {
            a,
            b,
            c,
            d,
            l,
            m,
            prior: x0.clone(),
            posterior: x0.clone(),
            x0,
            innovation: DVector::zeros(ny),
            scratch: DVector::zeros(nx),
        })
    }

    /// Measurement update: `e = y − C x̂[k|k−1] − D u`, `x̂[k|k] = x̂[k|k−1] + M e`.
    ///
    /// `u` is the input applied over the coming period (it matters only through `D`).
    pub fn correct(&mut self, y: &[f64], u: &[f64]) -> &DVector<f64> {
        debug_assert_eq!(y.len(), self.innovation.len());
        for (e, &yi) in self.innovation.iter_mut().zip(y) {
            *e = yi;
        }
        self.innovation.gemv(-1.0, &self.c, &self.prior, 1.0);
        if self.d.ncols() > 0 {
            let u = nalgebra::DVectorView::from_slice(u, self.d.ncols());
            self.innovation.gemv(-1.0, &self.d, &u, 1.0);
        }
        self.posterior.copy_from(&self.prior);
        self.posterior.gemv(1.0, &self.m, &self.innovation, 1.0);
        &self.posterior
    }

    /// Time update: `x̂[k+1|k] = A x̂[k|k−1] + B u + L e`, with `e` from the last
    /// [`correct`](Self::correct).
    pub fn predict(&mut self, u: &[f64]) {
        let u = nalgebra::DVectorView::from_slice(u, self.b.ncols());
        self.scratch.gemv(1.0, &self.a, &self.prior, 0.0);
        self.scratch.gemv(1.0, &self.b, &u, 1.0);
        self.scratch.gemv(1.0, &self.l, &self.innovation, 1.0);
        self.prior.copy_from(&self.scratch);
    }

    /// Measurement update for a sample without a usable measurement: `e[k] = 0`, so
    /// `x̂[k|k] = x̂[k|k−1]`. Exact, unlike passing `y = C x̂[k|k−1]` to
    /// [`correct`](Self::correct), whose rounding can leave a tiny innovation.
    pub fn correct_without_measurement(&mut self) -> &DVector<f64> {
        self.innovation.fill(0.0);
        self.posterior.copy_from(&self.prior);
        &self.posterior
    }

    /// A whole period without a measurement, the input `u` applied over it: the zero-innovation
    /// update of [`correct_without_measurement`](Self::correct_without_measurement)
    /// (`x̂[k|k] = x̂[k|k−1]`), then the time update `x̂[k+1|k] = A x̂[k|k−1] + B u`.
    ///
    /// The posterior stays the estimate of the state at the period just passed, as after any
    /// other [`correct`](Self::correct); only the prior moves on to the next period.
    pub fn predict_without_measurement(&mut self, u: &[f64]) {
        self.correct_without_measurement();
        self.predict(u);
    }

    /// The current estimate `x̂[k|k]`.
    pub fn posterior(&self) -> &DVector<f64> {
        &self.posterior
    }

    /// The prediction `x̂[k+1|k]` (after [`predict`](Self::predict)).
    pub fn prior(&self) -> &DVector<f64> {
        &self.prior
    }

    /// The model and gains `(A, B, C, L, M)` the estimator runs.
    pub fn matrices(&self) -> (&Mat, &Mat, &Mat, &Mat, &Mat) {
        (&self.a, &self.b, &self.c, &self.l, &self.m)
    }

    /// The last innovation `e[k]`.
    pub fn innovation(&self) -> &DVector<f64> {
        &self.innovation
    }

    /// Restarts from the initial estimate.
    pub fn reset(&mut self) {
        self.prior.copy_from(&self.x0);
        self.posterior.copy_from(&self.x0);
        self.innovation.fill(0.0);
    }

    /// Overwrites the prior estimate `x̂[k|k−1]`.
    pub fn set_prior(&mut self, x: &[f64]) {
        self.prior.copy_from_slice(x);
    }
}
