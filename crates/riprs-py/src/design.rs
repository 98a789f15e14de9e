//! Bindings for the design routines: `dare`, `dlqr`, `dlqe`, `kalman`, `c2d`.

use numpy::{PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::convert::{eig_to_py, mat_to_py, to_mat, to_mat_opt};
use crate::errors::IntoPyResult;

type Py2<'py> = Bound<'py, PyArray2<f64>>;
type PyEig<'py> = Bound<'py, PyArray1<numpy::Complex64>>;

#[pyfunction]
#[pyo3(signature = (a, b, q, r, s=None, e=None))]
fn dare<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    r: PyReadonlyArray2<'py, f64>,
    s: Option<PyReadonlyArray2<'py, f64>>,
    e: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<(Py2<'py>, PyEig<'py>, Py2<'py>)> {
    let (s, e) = (to_mat_opt(&s), to_mat_opt(&e));
    let sol = rip_core::dare(
        &to_mat(&a),
        &to_mat(&b),
        &to_mat(&q),
        &to_mat(&r),
        s.as_ref(),
        e.as_ref(),
    )
    .py()?;
    Ok((
        mat_to_py(py, &sol.x),
        eig_to_py(py, &sol.closed_loop_eigenvalues),
        mat_to_py(py, &sol.gain),
    ))
}

#[pyfunction]
#[pyo3(signature = (a, b, q, r, n=None))]
fn dlqr<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    r: PyReadonlyArray2<'py, f64>,
    n: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<(Py2<'py>, Py2<'py>, PyEig<'py>)> {
    let n = to_mat_opt(&n);
    let d = rip_core::dlqr(
        &to_mat(&a),
        &to_mat(&b),
        &to_mat(&q),
        &to_mat(&r),
        n.as_ref(),
    )
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
    a: PyReadonlyArray2<'py, f64>,
    g: PyReadonlyArray2<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    qn: PyReadonlyArray2<'py, f64>,
    rn: PyReadonlyArray2<'py, f64>,
    nn: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<(Py2<'py>, Py2<'py>, PyEig<'py>)> {
    let nn = to_mat_opt(&nn);
    let (l, p, e) = rip_core::dlqe(
        &to_mat(&a),
        &to_mat(&g),
        &to_mat(&c),
        &to_mat(&qn),
        &to_mat(&rn),
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
    a: PyReadonlyArray2<'py, f64>,
    g: PyReadonlyArray2<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    qn: PyReadonlyArray2<'py, f64>,
    rn: PyReadonlyArray2<'py, f64>,
    nn: Option<PyReadonlyArray2<'py, f64>>,
    h: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<PyKalmanDesign> {
    let (nn, h) = (to_mat_opt(&nn), to_mat_opt(&h));
    let inner = rip_core::kalman(
        &to_mat(&a),
        &to_mat(&g),
        &to_mat(&c),
        &to_mat(&qn),
        &to_mat(&rn),
        nn.as_ref(),
        h.as_ref(),
    )
    .py()?;
    Ok(PyKalmanDesign { inner })
}

#[pyfunction]
fn c2d<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    ts: f64,
) -> PyResult<(Py2<'py>, Py2<'py>)> {
    let (ad, bd) = rip_core::c2d(&to_mat(&a), &to_mat(&b), ts).py()?;
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
