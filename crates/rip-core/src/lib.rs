//! # rip-core
//!
//! The numerical core of riprs: control design and simulation for the rotary inverted pendulum
//! (Furuta pendulum), written to agree with MATLAB's Control System / MPC toolboxes and with
//! python-control.
//!
//! - [`linalg`] — argument validation, eigenvalues and zero-order-hold [`c2d`].
//! - [`dare`](mod@dare) — the discrete algebraic Riccati equation ([`dare`](fn@dare)).
//! - [`envelope`] — the arm's stopping distance at the voltage bound and the braking law: the
//!   one definition behind every bound on the arm's travel.
//! - [`lqr`] — [`dlqr`], [`dlqr_integral`] (python-control's `integral_action`).
//! - [`kalman`](mod@kalman) — MATLAB's [`kalman`](fn@kalman) (both gains `L` and `M`),
//!   python-control's [`dlqe`] and the allocation-free [`CurrentEstimator`].
//!
//! - [`paper`] — the study's model, its recovered unrounded matrices and printed results.
//! - [`plant`] — the nonlinear Furuta pendulum ([`Plant`], [`FurutaParams`]) and RK4; [`fit`]
//!   recovers physical parameters from a discrete linear model; [`identify`](mod@identify) fits
//!   the nonlinear model to logged excitation runs; [`trig`] is its branch-free `sin`/`cos`.
//! - [`regulators`] — [`Lqr`] and [`Lqg`] behind the [`Controller`] trait; [`sim`] runs them in
//!   closed loop ([`simulate`], [`simulate_batch`]); [`metrics`] computes the paper's Tab. 1;
//!   [`batch`] runs Monte Carlo studies that keep only per-run metrics.
//!   [`sim::vec_env`] steps many pendulums as reinforcement-learning environments.
//! - [`mpc`] — constrained MPC with soft output bounds and the disturbance-model Kalman filter
//!   ([`Mpc`]), solved by Clarabel or a dense active-set method.
//! - [`margins`] — gain, phase and disk margins of a controller's loop at the plant input.
//! - [`preflight`] — the checks before a run: an untrusted identification, a rig no controller
//!   can balance at the voltage bound, a controller predicted to fall.
//! - [`tune`] — shared weights for LQR, LQG and MPC chosen for the rig in the file.
//! - [`spec`] — the experiment file every front end reads ([`Spec`]), and the one assembly of
//!   LQR, LQG and MPC from it; [`files`] is the one bounded reader of it and of the records
//!   beside a rig file.
//! - [`excitation`] — chirp, PRBS, steps and free-swing signals for identification runs, and
//!   the arm-centring law that keeps them inside the arm's travel.
//! - [`swingup`] — energy swing-up from rest with an arm-limit barrier, and the [`SwingUp`]
//!   supervisor that catches with any balance controller.
//!
//! Every fallible routine returns [`RipError`], whose variants name the offending argument.

pub mod batch;
pub mod checksum;
pub mod compensation;
pub mod controller;
pub mod dare;
pub mod envelope;
pub mod error;
pub mod excitation;
pub mod files;
pub mod fit;
pub mod identify;
pub mod kalman;
pub mod linalg;
pub mod lqr;
pub mod margins;
pub mod metrics;
pub mod mpc;
pub mod onboard;
pub mod paper;
pub mod plant;
pub mod preflight;
mod presets;
pub mod regulators;
pub mod rig;
pub mod sim;
pub mod spec;
pub mod stats;
pub mod swing_report;
pub mod swingup;
pub mod trig;
pub mod tune;

pub use compensation::{Compensated, Compensation};
pub use controller::{Controller, Phase, StepStatus, StopCause};
pub use dare::{dare, DareSolution};
pub use error::{Result, RipError};
pub use kalman::{dlqe, kalman, CurrentEstimator, KalmanDesign};
pub use linalg::{c2d, Mat};
pub use lqr::{dlqr, dlqr_integral, LqrDesign};
pub use mpc::{Mpc, MpcSettings, QpSolver, QpStatus};
pub use plant::{FurutaParams, Plant, State};
pub use regulators::{Lqg, Lqr};
pub use sim::{simulate, simulate_batch, SimConfig, SimResult};
pub use spec::{Spec, SpecError};
pub use swingup::{OnFall, SwingUp, SwingUpSettings};
