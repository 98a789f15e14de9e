//! The error type shared by every fallible routine in `rip-core`.
//!
//! Each variant names the offending argument so that a caller (and the Python layer, which maps
//! the variants onto exception classes) can say exactly what was wrong.

use thiserror::Error;

/// Everything that can go wrong in `rip-core`.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RipError {
    /// An argument does not have the shape the routine needs.
    #[error("{name}: expected shape {expected}, got ({rows}, {cols})")]
    Shape {
        /// The argument's name as the caller spells it (e.g. `"Q"`).
        name: String,
        /// The shape the routine needs, in words or as `(rows, cols)` (e.g. `"(4, 4)"`).
        expected: String,
        /// Number of rows the argument has.
        rows: usize,
        /// Number of columns the argument has.
        cols: usize,
    },
    /// An argument holds NaN or an infinity.
    #[error("{name} contains NaN or Inf")]
    NonFinite {
        /// The argument's name as the caller spells it.
        name: String,
    },
    /// A weight or covariance that must be symmetric is not.
    #[error("{name} must be symmetric (max |{name} - {name}ᵀ| = {asymmetry:.3e})")]
    NotSymmetric {
        /// The argument's name as the caller spells it.
        name: String,
        /// The largest absolute entry of `X − Xᵀ`, in the argument's own units.
        asymmetry: f64,
    },
    /// A matrix that must be positive definite is not.
    #[error("{name} must be positive definite")]
    NotPositiveDefinite {
        /// The argument's name as the caller spells it.
        name: String,
    },
    /// A matrix that must be positive semidefinite is not.
    #[error("{name} must be positive semidefinite (smallest eigenvalue {min_eigenvalue:.3e})")]
    NotPositiveSemidefinite {
        /// The argument's name as the caller spells it.
        name: String,
        /// The smallest eigenvalue of the (symmetric) argument; negative beyond the tolerance.
        min_eigenvalue: f64,
    },
    /// The pair (A, B) has an unstable mode that the input cannot reach.
    #[error("{pair} is not stabilizable: mode {re:.6}{im:+.6}i (|λ| = {modulus:.6}) cannot be reached from the input")]
    NotStabilizable {
        /// Which pair was checked, e.g. `"(A, B)"` or a description of the augmented model.
        pair: String,
        /// Real part of the unreachable eigenvalue λ of `A`.
        re: f64,
        /// Imaginary part of the unreachable eigenvalue λ of `A`.
        im: f64,
        /// `|λ|`; at least 1 (on or outside the unit circle) for a discrete-time `A`.
        modulus: f64,
    },
    /// The pair (A, C) has an unstable mode that the output cannot see.
    #[error("{pair} is not detectable: mode {re:.6}{im:+.6}i (|λ| = {modulus:.6}) is invisible to the output")]
    NotDetectable {
        /// Which pair was checked, e.g. `"(A, C)"` or a description of the augmented model.
        pair: String,
        /// Real part of the unobservable eigenvalue λ of `A`.
        re: f64,
        /// Imaginary part of the unobservable eigenvalue λ of `A`.
        im: f64,
        /// `|λ|`; at least 1 (on or outside the unit circle) for a discrete-time `A`.
        modulus: f64,
    },
    /// The Riccati equation has no stabilizing solution (for example an unobservable mode of the
    /// weights on the unit circle), or the solver could not reach it to the required accuracy.
    #[error("no stabilizing solution: {reason}")]
    NoStabilizingSolution {
        /// What failed, in words (which check and by how much).
        reason: String,
    },
    /// A computation from finite inputs overflowed to NaN or Inf (for example an integration
    /// step far too long for the dynamics); the reason says which inputs were involved.
    #[error("the computation diverged: {reason}")]
    Diverged {
        /// Which computation overflowed and from which inputs.
        reason: String,
    },
    /// A scalar setting or parameter is out of its valid range.
    #[error("invalid {name}: {reason}")]
    InvalidParameter {
        /// The setting's or parameter's name as the caller spells it (a config key where there
        /// is one).
        name: String,
        /// Why the value is not accepted (the valid range, or what it conflicts with).
        reason: String,
    },
    /// The caller asked a long computation to stop (for example on Ctrl-C) before it finished.
    #[error("cancelled before the computation finished")]
    Cancelled,
}

impl RipError {
    /// Shorthand for [`RipError::InvalidParameter`].
    pub fn invalid(name: impl Into<String>, reason: impl Into<String>) -> Self {
        RipError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        }
    }
}

/// A setting out of range, located by its key path as data: relative to the settings type
/// that found it (`prediction_horizon`, `output_bounds[1]`), which is the key of that type's
/// section in the experiment file, so the spec names `mpc.output_bounds[1]` by prefixing the
/// section ([`crate::spec::SpecError::in_section`]) and the Python API by the keyword.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyError {
    /// The key path within the section.
    pub key: String,
    /// Why the value is not accepted.
    pub reason: String,
    /// Whether the value is NaN or infinite where a finite one is needed (Python's
    /// `NonFiniteError`, a `ValueError` like the others).
    pub non_finite: bool,
}

impl KeyError {
    /// `key` is out of range for `reason`.
    pub fn new(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            reason: reason.into(),
            non_finite: false,
        }
    }

    /// `key` holds NaN or an infinity (`value`) where a finite value is needed.
    pub fn non_finite(key: impl Into<String>, value: f64) -> Self {
        Self {
            key: key.into(),
            reason: format!("must be finite, got {value}"),
            non_finite: true,
        }
    }
}

impl std::fmt::Display for KeyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.key, self.reason)
    }
}

impl From<KeyError> for RipError {
    fn from(e: KeyError) -> Self {
        if e.non_finite {
            RipError::NonFinite { name: e.key }
        } else {
            RipError::InvalidParameter {
                name: e.key,
                reason: e.reason,
            }
        }
    }
}

/// Result alias used throughout the crate.
pub type Result<T> = std::result::Result<T, RipError>;
