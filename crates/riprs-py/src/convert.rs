//! numpy ⇄ nalgebra conversion.

use nalgebra::{Complex, DMatrix};
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;

/// Copies a 2-D float64 array into a column-major `DMatrix`.
pub fn to_mat(a: &PyReadonlyArray2<'_, f64>) -> DMatrix<f64> {
    let view = a.as_array();
    let (rows, cols) = view.dim();
    DMatrix::from_fn(rows, cols, |i, j| view[[i, j]])
}

/// Copies an optional 2-D array.
pub fn to_mat_opt(a: &Option<PyReadonlyArray2<'_, f64>>) -> Option<DMatrix<f64>> {
    a.as_ref().map(to_mat)
}

/// A new numpy array holding `m`.
pub fn mat_to_py<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn(m.shape(), |(i, j)| m[(i, j)]).into_pyarray(py)
}

/// A new complex numpy array holding eigenvalues.
pub fn eig_to_py<'py>(
    py: Python<'py>,
    e: &[Complex<f64>],
) -> Bound<'py, PyArray1<numpy::Complex64>> {
    Array1::from_iter(e.iter().map(|z| numpy::Complex64::new(z.re, z.im))).into_pyarray(py)
}
