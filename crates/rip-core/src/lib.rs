//! # rip-core
//!
//! The numerical core of riprs: control design and simulation for the rotary inverted pendulum
//! (Furuta pendulum), written to agree with MATLAB's Control System / MPC toolboxes and with
//! python-control.
//!
//! - [`linalg`] — argument validation, zero-order-hold [`c2d`] and the Riccati solver [`dare`].
//! - [`lqr`] — [`dlqr`].
//! - [`kalman`](mod@kalman) — MATLAB's [`kalman`](fn@kalman) (both gains `L` and `M`),
//!   python-control's [`dlqe`] and the allocation-free [`CurrentEstimator`].
//!
//! - [`paper`] — the study's model, its recovered unrounded matrices and printed results.
//!
//! Every fallible routine returns [`RipError`], whose variants name the offending argument.

pub mod controller;
pub mod error;
pub mod kalman;
pub mod linalg;
pub mod lqr;
pub mod paper;

pub use controller::{Controller, StepStatus};
pub use error::{Result, RipError};
pub use kalman::{dlqe, kalman, CurrentEstimator, KalmanDesign};
pub use linalg::{c2d, dare, DareSolution, Mat};
pub use lqr::{dlqr, LqrDesign};
