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
        name: String,
        expected: String,
        rows: usize,
        cols: usize,
    },
    /// An argument holds NaN or an infinity.
    #[error("{name} contains NaN or Inf")]
    NonFinite { name: String },
    /// A weight or covariance that must be symmetric is not.
    #[error("{name} must be symmetric (max |{name} - {name}ᵀ| = {asymmetry:.3e})")]
    NotSymmetric { name: String, asymmetry: f64 },
    /// A matrix that must be positive definite is not.
    #[error("{name} must be positive definite")]
    NotPositiveDefinite { name: String },
    /// A matrix that must be positive semidefinite is not.
    #[error("{name} must be positive semidefinite (smallest eigenvalue {min_eigenvalue:.3e})")]
    NotPositiveSemidefinite { name: String, min_eigenvalue: f64 },
    /// The pair (A, B) has an unstable mode that the input cannot reach.
    #[error("{pair} is not stabilizable: mode {re:.6}{im:+.6}i (|λ| = {modulus:.6}) cannot be reached from the input")]
    NotStabilizable {
        pair: String,
        re: f64,
        im: f64,
        modulus: f64,
    },
    /// The pair (A, C) has an unstable mode that the output cannot see.
    #[error("{pair} is not detectable: mode {re:.6}{im:+.6}i (|λ| = {modulus:.6}) is invisible to the output")]
    NotDetectable {
        pair: String,
        re: f64,
        im: f64,
        modulus: f64,
    },
    /// The Riccati equation has no stabilizing solution (for example an unobservable mode of the
    /// weights on the unit circle), or the solver could not reach it to the required accuracy.
    #[error("no stabilizing solution: {reason}")]
    NoStabilizingSolution { reason: String },
    /// A computation from finite inputs overflowed to NaN or Inf (for example an integration
    /// step far too long for the dynamics); the reason says which inputs were involved.
    #[error("the computation diverged: {reason}")]
    Diverged { reason: String },
    /// A scalar setting or parameter is out of its valid range.
    #[error("invalid {name}: {reason}")]
    InvalidParameter { name: String, reason: String },
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

/// Result alias used throughout the crate.
pub type Result<T> = std::result::Result<T, RipError>;
