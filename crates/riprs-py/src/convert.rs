//! The one coercion policy of the bindings: how a Python value becomes a matrix, a vector, a
//! real number or a count, and how a bad one is reported (always naming the argument).
//!
//! - Arrays: any array-like of real numbers (nested lists, numpy arrays of any real dtype,
//!   scalars). A complex array is a `TypeError` (numpy's cast would drop the imaginary part); a
//!   ragged nested list is a `ShapeError`; anything else that is not numbers is a `TypeError`;
//!   NaN or Inf is a `NonFiniteError`. For matrices a scalar is 1×1 and a 1-D input one row, as
//!   in python-control.
//! - `None`: where an argument is optional its binding gives `None` its meaning, a default such
//!   as zero or the identity (python-control's, where python-control has one; `matrix_opt`
//!   passes `None` through for this). Anywhere else `None` is a `TypeError` naming the
//!   argument: numpy would read it as a NaN scalar, and the caller be told of a NaN never given.
//! - Real numbers ([`Real`]): a Python `int` too large for a float is `±inf`, which the core's
//!   own range checks then reject by name, instead of an `OverflowError` from the conversion.
//! - Counts ([`Count`]): negative or huge integers are an `InvalidParameterError` naming the
//!   argument, not an `OverflowError`; the core checks the range that applies.

use nalgebra::{Complex, DMatrix};
use numpy::ndarray::{Array1, Array2};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArrayLikeDyn};
use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyFloat, PyInt};
use rip_core::{Mat, RipError};

use crate::errors::{to_py, ShapeError};

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

/// The shape and the row-major values of an array-like of real numbers (module docs).
pub(crate) fn real_array(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    if obj.is_none() {
        return Err(PyTypeError::new_err(format!(
            "{name} must be an array of real numbers, got None"
        )));
    }
    let complex = obj
        .getattr("dtype")
        .and_then(|dtype| dtype.getattr("kind"))
        .and_then(|kind| kind.extract::<String>())
        .is_ok_and(|kind| kind == "c");
    if complex {
        return Err(PyTypeError::new_err(format!(
            "{name} must be an array of real numbers, got a complex array"
        )));
    }
    let arr: PyArrayLikeDyn<'_, f64, AllowTypeChange> = obj.extract().map_err(|e| {
        // numpy raises ValueError for a ragged nested sequence ("inhomogeneous shape").
        let ragged =
            e.is_instance_of::<PyValueError>(obj.py()) && e.to_string().contains("inhomogeneous");
        if ragged {
            ShapeError::new_err(format!(
                "{name}: expected a rectangular array, got a ragged nested sequence (rows of \
                 different lengths)"
            ))
        } else {
            PyTypeError::new_err(format!("{name} must be an array of real numbers: {e}"))
        }
    })?;
    let view = arr.as_array();
    Ok((view.shape().to_vec(), view.iter().copied().collect()))
}

/// [`real_array`] whose every value is finite.
pub(crate) fn array_like(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    let (shape, values) = real_array(obj, name)?;
    if values.iter().any(|v| !v.is_finite()) {
        return Err(to_py(RipError::NonFinite { name: name.into() }));
    }
    Ok((shape, values))
}

/// A finite matrix of the given shape from an array-like (a 1-D input counts as one row, a
/// scalar as 1×1, as in python-control); `None` for a dimension accepts any size.
pub(crate) fn matrix_arg(
    obj: &Bound<'_, PyAny>,
    name: &str,
    rows: Option<usize>,
    cols: Option<usize>,
) -> PyResult<Mat> {
    let (shape, values) = array_like(obj, name)?;
    let (r, c) = match shape.as_slice() {
        [] => (1, 1),
        [n] => (1, *n),
        [r, c] => (*r, *c),
        _ => {
            return Err(to_py(RipError::Shape {
                name: name.into(),
                expected: "a 2-D array".into(),
                rows: shape[0],
                cols: shape[1..].iter().product(),
            }))
        }
    };
    if rows.is_some_and(|n| n != r) || cols.is_some_and(|n| n != c) {
        let show = |d: Option<usize>| d.map_or("n".to_string(), |v| v.to_string());
        return Err(to_py(RipError::Shape {
            name: name.into(),
            expected: format!("({}, {})", show(rows), show(cols)),
            rows: r,
            cols: c,
        }));
    }
    Ok(Mat::from_row_slice(r, c, &values))
}

/// [`matrix_arg`] of any shape for an optional argument (`None` passes through).
pub(crate) fn matrix_opt(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<Mat>> {
    match obj {
        Some(o) if !o.is_none() => matrix_arg(o, name, None, None).map(Some),
        _ => Ok(None),
    }
}

/// A vector of exactly `N` finite entries from a 1-D array-like.
pub(crate) fn vector_arg<const N: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; N]> {
    let (shape, values) = array_like(obj, name)?;
    if shape.len() > 1 || values.len() != N {
        let (rows, cols) = match shape.as_slice() {
            [] => (1, 1),
            [n] => (*n, 1),
            s => (s[0], s[1..].iter().product()),
        };
        return Err(to_py(RipError::Shape {
            name: name.into(),
            expected: format!("({N},)"),
            rows,
            cols,
        }));
    }
    let mut out = [0.0; N];
    out.copy_from_slice(&values);
    Ok(out)
}

/// A pair for the two outputs from a scalar (both) or exactly two finite entries.
pub(crate) fn pair_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 2]> {
    let (shape, values) = array_like(obj, name)?;
    match (shape.len(), values.as_slice()) {
        (0 | 1, [v]) => Ok([*v, *v]),
        (1, [a, b]) => Ok([*a, *b]),
        _ => Err(to_py(RipError::Shape {
            name: name.into(),
            expected: "a scalar or (2,)".into(),
            rows: shape.first().copied().unwrap_or(1),
            cols: shape[1.min(shape.len())..].iter().product(),
        })),
    }
}

/// A real-number argument. An `int` beyond the float range becomes `±inf` (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Real(pub f64);

impl<'py> FromPyObject<'py> for Real {
    fn extract_bound(ob: &Bound<'py, PyAny>) -> PyResult<Self> {
        match ob.extract::<f64>() {
            Ok(v) => Ok(Self(v)),
            Err(e) if e.is_instance_of::<PyOverflowError>(ob.py()) => {
                let positive = ob.gt(0)?;
                Ok(Self(if positive {
                    f64::INFINITY
                } else {
                    f64::NEG_INFINITY
                }))
            }
            Err(e) => Err(e),
        }
    }
}

/// An integer argument, kept as given until the binding names it (module docs).
#[derive(Debug, Clone)]
pub struct Count {
    value: Option<i64>,
    text: String,
}

impl Count {
    /// A count with the given value (for signature defaults).
    pub const fn of(value: i64) -> Self {
        Self {
            value: Some(value),
            text: String::new(),
        }
    }

    /// The value as a `usize`; a negative or huge one is an `InvalidParameterError` naming
    /// `name`.
    pub fn get(&self, name: &str) -> PyResult<usize> {
        self.value
            .and_then(|v| usize::try_from(v).ok())
            .ok_or_else(|| {
                let shown = match self.value {
                    Some(v) => v.to_string(),
                    None => self.text.clone(),
                };
                to_py(RipError::invalid(
                    name,
                    format!("must be a non-negative integer that fits in 64 bits, got {shown}"),
                ))
            })
    }

    /// The value as a `u64` (same errors as [`get`](Self::get)).
    pub fn get_u64(&self, name: &str) -> PyResult<u64> {
        self.get(name).map(|v| v as u64)
    }
}

/// A random seed: an integer in `[0, 2⁶⁴)`, the `u64` of every seed in rip-core and `rip-rt`
/// (`rip-rt excite --seed`), so that any run's signal can be regenerated from Python.
#[derive(Debug, Clone, Copy)]
pub struct Seed(pub u64);

impl Seed {
    /// Extracts `ob` as a seed named `name` in the error.
    pub fn extract(ob: &Bound<'_, PyAny>, name: &str) -> PyResult<u64> {
        if ob.is_instance_of::<PyBool>()
            || ob.is_instance_of::<PyFloat>()
            || !(ob.is_instance_of::<PyInt>() || ob.hasattr("__index__")?)
        {
            return Err(PyTypeError::new_err(format!(
                "{name} must be an integer, got {}",
                ob.get_type().name()?
            )));
        }
        ob.extract::<u64>().map_err(|_| {
            to_py(RipError::invalid(
                name,
                format!(
                    "must be in [0, 2**64), got {}",
                    ob.str().map(|s| s.to_string()).unwrap_or_default()
                ),
            ))
        })
    }
}

impl<'py> FromPyObject<'py> for Seed {
    fn extract_bound(ob: &Bound<'py, PyAny>) -> PyResult<Self> {
        Seed::extract(ob, "seed").map(Seed)
    }
}

impl<'py> FromPyObject<'py> for Count {
    fn extract_bound(ob: &Bound<'py, PyAny>) -> PyResult<Self> {
        if ob.is_instance_of::<PyBool>() || ob.is_instance_of::<PyFloat>() {
            return Err(PyTypeError::new_err(format!(
                "expected an integer, got {}",
                ob.get_type().name()?
            )));
        }
        if !ob.is_instance_of::<PyInt>() && !ob.hasattr("__index__")? {
            return Err(PyTypeError::new_err(format!(
                "expected an integer, got {}",
                ob.get_type().name()?
            )));
        }
        match ob.extract::<i64>() {
            Ok(v) => Ok(Self::of(v)),
            Err(e) if e.is_instance_of::<PyOverflowError>(ob.py()) => {
                let text = ob.str()?.to_string();
                let text = if text.len() > 40 {
                    format!("{}… ({} digits)", &text[..20], text.len())
                } else {
                    text
                };
                Ok(Self { value: None, text })
            }
            Err(e) => Err(e),
        }
    }
}
