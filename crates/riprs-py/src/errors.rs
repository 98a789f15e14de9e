//! Python exception classes, one per [`RipError`] variant, all deriving from `ValueError`.

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rip_core::RipError;

create_exception!(
    _riprs,
    RiprsError,
    PyValueError,
    "Base class of every riprs input or design error."
);
create_exception!(
    _riprs,
    ShapeError,
    RiprsError,
    "An argument has the wrong shape."
);
create_exception!(
    _riprs,
    NonFiniteError,
    RiprsError,
    "An argument contains NaN or Inf."
);
create_exception!(
    _riprs,
    NotSymmetricError,
    RiprsError,
    "A weight or covariance is not symmetric."
);
create_exception!(
    _riprs,
    NotPositiveDefiniteError,
    RiprsError,
    "A matrix that must be positive definite is not."
);
create_exception!(
    _riprs,
    NotPositiveSemidefiniteError,
    RiprsError,
    "A matrix that must be positive semidefinite is not."
);
create_exception!(
    _riprs,
    NotStabilizableError,
    RiprsError,
    "(A, B) has an unstable mode the input cannot reach."
);
create_exception!(
    _riprs,
    NotDetectableError,
    RiprsError,
    "(A, C) has an unstable mode the output cannot see."
);
create_exception!(
    _riprs,
    NoStabilizingSolutionError,
    RiprsError,
    "The Riccati equation has no stabilizing solution."
);
create_exception!(
    _riprs,
    DivergedError,
    RiprsError,
    "A computation from finite inputs overflowed to NaN or Inf."
);
create_exception!(
    _riprs,
    InvalidParameterError,
    RiprsError,
    "A setting or parameter is out of range."
);

/// Converts a core error into the matching Python exception.
pub fn to_py(err: RipError) -> PyErr {
    let msg = err.to_string();
    match err {
        RipError::Shape { .. } => ShapeError::new_err(msg),
        RipError::NonFinite { .. } => NonFiniteError::new_err(msg),
        RipError::NotSymmetric { .. } => NotSymmetricError::new_err(msg),
        RipError::NotPositiveDefinite { .. } => NotPositiveDefiniteError::new_err(msg),
        RipError::NotPositiveSemidefinite { .. } => NotPositiveSemidefiniteError::new_err(msg),
        RipError::NotStabilizable { .. } => NotStabilizableError::new_err(msg),
        RipError::NotDetectable { .. } => NotDetectableError::new_err(msg),
        RipError::NoStabilizingSolution { .. } => NoStabilizingSolutionError::new_err(msg),
        RipError::Diverged { .. } => DivergedError::new_err(msg),
        RipError::InvalidParameter { .. } => InvalidParameterError::new_err(msg),
        // The bindings cancel only on a pending signal, whose own exception is raised instead.
        RipError::Cancelled => pyo3::exceptions::PyKeyboardInterrupt::new_err(msg),
    }
}

/// Extension for `rip_core::Result` so call sites read `core_call(...).py()?`.
pub trait IntoPyResult<T> {
    fn py(self) -> PyResult<T>;
}

impl<T> IntoPyResult<T> for Result<T, RipError> {
    fn py(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("RiprsError", py.get_type::<RiprsError>())?;
    m.add("ShapeError", py.get_type::<ShapeError>())?;
    m.add("NonFiniteError", py.get_type::<NonFiniteError>())?;
    m.add("NotSymmetricError", py.get_type::<NotSymmetricError>())?;
    m.add(
        "NotPositiveDefiniteError",
        py.get_type::<NotPositiveDefiniteError>(),
    )?;
    m.add(
        "NotPositiveSemidefiniteError",
        py.get_type::<NotPositiveSemidefiniteError>(),
    )?;
    m.add(
        "NotStabilizableError",
        py.get_type::<NotStabilizableError>(),
    )?;
    m.add("NotDetectableError", py.get_type::<NotDetectableError>())?;
    m.add(
        "NoStabilizingSolutionError",
        py.get_type::<NoStabilizingSolutionError>(),
    )?;
    m.add("DivergedError", py.get_type::<DivergedError>())?;
    m.add(
        "InvalidParameterError",
        py.get_type::<InvalidParameterError>(),
    )?;
    Ok(())
}
