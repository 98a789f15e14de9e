//! Bindings for `rip_core::paper`: the study's model, noise model and printed numbers.

use numpy::PyArray2;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rip_core::{paper, Mat};

use crate::convert::mat_to_py;
use crate::errors::IntoPyResult;

type Py2<'py> = Bound<'py, PyArray2<f64>>;

fn rows<const C: usize>(data: &[[f64; C]]) -> Mat {
    Mat::from_fn(data.len(), C, |i, j| data[i][j])
}

/// `(A, B, C, D, Ts)` of the paper's `"continuous"`, `"discrete"` or `"augmented"` model.
#[pyfunction]
fn paper_state_space<'py>(
    py: Python<'py>,
    kind: &str,
) -> PyResult<(Py2<'py>, Py2<'py>, Py2<'py>, Py2<'py>, f64)> {
    let ss = match kind {
        "continuous" => {
            let (a, b) = paper::continuous_model();
            paper::StateSpace {
                a,
                b,
                c: paper::output_matrix(),
                d: Mat::zeros(2, 1),
                ts: 0.0,
            }
        }
        "discrete" => paper::discrete_model(),
        "augmented" => paper::augmented_model(),
        other => {
            return Err(PyValueError::new_err(format!(
                "kind must be 'continuous', 'discrete' or 'augmented', got {other:?}"
            )))
        }
    };
    Ok((
        mat_to_py(py, &ss.a),
        mat_to_py(py, &ss.b),
        mat_to_py(py, &ss.c),
        mat_to_py(py, &ss.d),
        ss.ts,
    ))
}

/// `(Q, R, N)` of eqs. (8)–(10).
#[pyfunction]
fn paper_noise_model(py: Python<'_>) -> (Py2<'_>, Py2<'_>, Py2<'_>) {
    let n = paper::noise_model();
    (
        mat_to_py(py, &n.q),
        mat_to_py(py, &n.r),
        mat_to_py(py, &n.n),
    )
}

/// The numbers exactly as printed in the paper, and the fitted continuous-time parameters.
#[pyfunction]
fn paper_printed(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("Ad", mat_to_py(py, &rows(&paper::PRINTED_AD)))?;
    d.set_item(
        "Bd",
        mat_to_py(py, &Mat::from_column_slice(4, 1, &paper::PRINTED_BD)),
    )?;
    d.set_item("L", mat_to_py(py, &rows(&paper::PRINTED_L)))?;
    d.set_item("M", mat_to_py(py, &rows(&paper::PRINTED_M)))?;
    let table = PyDict::new(py);
    for (name, values) in paper::TABLE1 {
        table.set_item(name, values.to_vec())?;
    }
    d.set_item("table1", table)?;
    d.set_item(
        "continuous_parameters",
        paper::CONTINUOUS_PARAMETERS.to_vec(),
    )?;
    d.set_item("input_scale", paper::INPUT_SCALE)?;
    Ok(d)
}

/// `(L, M, P, Z)` of the eq. (11) design.
#[pyfunction]
fn paper_kalman(py: Python<'_>) -> PyResult<(Py2<'_>, Py2<'_>, Py2<'_>, Py2<'_>)> {
    let k = paper::kalman_design().py()?;
    Ok((
        mat_to_py(py, &k.l),
        mat_to_py(py, &k.m),
        mat_to_py(py, &k.p),
        mat_to_py(py, &k.z),
    ))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(paper_state_space, m)?)?;
    m.add_function(wrap_pyfunction!(paper_noise_model, m)?)?;
    m.add_function(wrap_pyfunction!(paper_printed, m)?)?;
    m.add_function(wrap_pyfunction!(paper_kalman, m)?)?;
    Ok(())
}
