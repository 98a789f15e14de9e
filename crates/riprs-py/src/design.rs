//! Bindings for the design routines: `dare`, `dlqr`, `dlqe`, `kalman`, `c2d`.

use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use rip_core::Mat;

use crate::convert::{eig_to_py, mat_to_py, matrix_arg, matrix_opt, Real};
use crate::errors::IntoPyResult;

type Py2<'py> = Bound<'py, PyArray2<f64>>;
type PyEig<'py> = Bound<'py, PyArray1<numpy::Complex64>>;

#[pyfunction]
#[pyo3(signature = (a, b, q, r, s=None, e=None))]
fn dare<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
    q: &Bound<'py, PyAny>,
    r: Option<&Bound<'py, PyAny>>,
    s: Option<&Bound<'py, PyAny>>,
    e: Option<&Bound<'py, PyAny>>,
) -> PyResult<(Py2<'py>, PyEig<'py>, Py2<'py>)> {
    let (s, e) = (matrix_opt(s, "S")?, matrix_opt(e, "E")?);
    let (a, b, q) = (
        matrix_arg(a, "A", None, None)?,
        matrix_arg(b, "B", None, None)?,
        matrix_arg(q, "Q", None, None)?,
    );
    // python-control's dare: R = None is the identity of B's input dimension (R stays a
    // required argument, as there).
    let r = matrix_opt(r, "R")?.unwrap_or_else(|| Mat::identity(b.ncols(), b.ncols()));
    let sol = rip_core::dare(&a, &b, &q, &r, s.as_ref(), e.as_ref()).py()?;
    Ok((
        mat_to_py(py, &sol.x),
        eig_to_py(py, &sol.closed_loop_eigenvalues),
        mat_to_py(py, &sol.gain),
    ))
}

#[pyfunction]
#[pyo3(signature = (a, b, q, r, n=None, integral_action=None))]
fn dlqr<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
    q: &Bound<'py, PyAny>,
    r: &Bound<'py, PyAny>,
    n: Option<&Bound<'py, PyAny>>,
    integral_action: Option<&Bound<'py, PyAny>>,
) -> PyResult<(Py2<'py>, Py2<'py>, PyEig<'py>)> {
    let n = matrix_opt(n, "N")?;
    let integral_action = matrix_opt(integral_action, "integral_action")?;
    let (a, b, q, r) = (
        matrix_arg(a, "A", None, None)?,
        matrix_arg(b, "B", None, None)?,
        matrix_arg(q, "Q", None, None)?,
        matrix_arg(r, "R", None, None)?,
    );
    let d = match &integral_action {
        Some(c) => rip_core::dlqr_integral(&a, &b, &q, &r, n.as_ref(), c),
        None => rip_core::dlqr(&a, &b, &q, &r, n.as_ref()),
    }
    .py()?;
    Ok((
        mat_to_py(py, &d.k),
        mat_to_py(py, &d.s),
        eig_to_py(py, &d.e),
    ))
}

#[pyfunction]
#[pyo3(signature = (a, g, c, qn, rn, nn=None))]
fn dlqe<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    g: &Bound<'py, PyAny>,
    c: &Bound<'py, PyAny>,
    qn: &Bound<'py, PyAny>,
    rn: &Bound<'py, PyAny>,
    nn: Option<&Bound<'py, PyAny>>,
) -> PyResult<(Py2<'py>, Py2<'py>, PyEig<'py>)> {
    let nn = matrix_opt(nn, "NN")?;
    let (l, p, e) = rip_core::dlqe(
        &matrix_arg(a, "A", None, None)?,
        &matrix_arg(g, "G", None, None)?,
        &matrix_arg(c, "C", None, None)?,
        &matrix_arg(qn, "QN", None, None)?,
        &matrix_arg(rn, "RN", None, None)?,
        nn.as_ref(),
    )
    .py()?;
    Ok((mat_to_py(py, &l), mat_to_py(py, &p), eig_to_py(py, &e)))
}

/// Steady-state Kalman design; see `riprs.kalman`.
#[pyclass(name = "KalmanDesign", module = "riprs._riprs", frozen)]
pub struct PyKalmanDesign {
    inner: rip_core::KalmanDesign,
}

#[pymethods]
impl PyKalmanDesign {
    /// Predictor gain L (x[k+1|k] update).
    #[getter(L)]
    fn l<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, &self.inner.l)
    }
    /// Innovation gain M (x[k|k] update).
    #[getter(M)]
    fn m<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, &self.inner.m)
    }
    /// Prior error covariance P = cov(x - x[k|k-1]).
    #[getter(P)]
    fn p<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, &self.inner.p)
    }
    /// Posterior error covariance Z = cov(x - x[k|k]).
    #[getter(Z)]
    fn z<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, &self.inner.z)
    }
    /// Estimator poles eig(A - L C).
    #[getter(E)]
    fn e<'py>(&self, py: Python<'py>) -> PyEig<'py> {
        eig_to_py(py, &self.inner.e)
    }
    fn __repr__(&self) -> String {
        format!(
            "KalmanDesign(states={}, outputs={})",
            self.inner.l.nrows(),
            self.inner.l.ncols()
        )
    }
}

#[pyfunction]
#[pyo3(signature = (a, g, c, qn, rn, nn=None, h=None))]
#[allow(clippy::too_many_arguments)]
fn kalman<'py>(
    a: &Bound<'py, PyAny>,
    g: &Bound<'py, PyAny>,
    c: &Bound<'py, PyAny>,
    qn: &Bound<'py, PyAny>,
    rn: &Bound<'py, PyAny>,
    nn: Option<&Bound<'py, PyAny>>,
    h: Option<&Bound<'py, PyAny>>,
) -> PyResult<PyKalmanDesign> {
    let (nn, h) = (matrix_opt(nn, "Nn")?, matrix_opt(h, "H")?);
    let inner = rip_core::kalman(
        &matrix_arg(a, "A", None, None)?,
        &matrix_arg(g, "G", None, None)?,
        &matrix_arg(c, "C", None, None)?,
        &matrix_arg(qn, "Qn", None, None)?,
        &matrix_arg(rn, "Rn", None, None)?,
        nn.as_ref(),
        h.as_ref(),
    )
    .py()?;
    Ok(PyKalmanDesign { inner })
}

#[pyfunction]
// `Ts` as riprs.c2d spells it, so that a refused sample time (e.g. None) is named as the
// caller wrote it.
#[allow(non_snake_case)]
fn c2d<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
    Ts: Real,
) -> PyResult<(Py2<'py>, Py2<'py>)> {
    let (ad, bd) = rip_core::c2d(
        &matrix_arg(a, "A", None, None)?,
        &matrix_arg(b, "B", None, None)?,
        Ts.0,
    )
    .py()?;
    Ok((mat_to_py(py, &ad), mat_to_py(py, &bd)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(dare, m)?)?;
    m.add_function(wrap_pyfunction!(dlqr, m)?)?;
    m.add_function(wrap_pyfunction!(dlqe, m)?)?;
    m.add_function(wrap_pyfunction!(kalman, m)?)?;
    m.add_function(wrap_pyfunction!(c2d, m)?)?;
    m.add_class::<PyKalmanDesign>()?;
    Ok(())
}
