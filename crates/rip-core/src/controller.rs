//! The one interface every controller implements, so the simulator, the Python layer and the
//! real-time loop (`rip-rt`) can drive LQR, LQG and MPC alike.
//!
//! Each sample `k` the caller hands over the measured outputs `y[k]` and the reference `r[k]`
//! (one entry per output; for the pendulum: arm angle, pendulum angle) and receives the input
//! `u[k]` to hold over the next period. When a period passes without a measurement the caller
//! calls [`Controller::hold`] instead, with the input the plant keeps receiving, so that the
//! controller's notion of elapsed time and applied input stays true.
//!
//! `step` and `hold` run inside a 100 Hz loop. The regulators ([`Lqr`](crate::Lqr),
//! [`Lqg`](crate::Lqg)) and the MPC with the active-set backend never allocate in them; the MPC
//! with the Clarabel backend allocates inside Clarabel's own `solve` (about one allocation per
//! step), which this crate cannot avoid.

/// What happened inside one [`Controller::step`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StepStatus {
    /// The move was computed as designed.
    #[default]
    Nominal,
    /// The optimiser failed (max iterations, numerical trouble, infeasible); the controller
    /// applied its documented safe fallback instead.
    Fallback,
}

/// A discrete-time output-feedback controller.
///
/// [`step`](Self::step) and [`hold`](Self::hold) are allocation-free for [`Lqr`](crate::Lqr),
/// [`Lqg`](crate::Lqg) and the [`Mpc`](crate::Mpc) with
/// [`QpSolver::ActiveSet`](crate::QpSolver::ActiveSet); with
/// [`QpSolver::Clarabel`](crate::QpSolver::Clarabel) the MPC allocates inside the solver on
/// every step that solves a QP.
pub trait Controller: Send {
    /// Number of measured outputs in `y` (and of references in `r`).
    fn n_outputs(&self) -> usize;

    /// Number of inputs written to `u`.
    fn n_inputs(&self) -> usize;

    /// Computes `u[k]` from `y[k]` and `r[k]`. Slices have lengths [`n_outputs`](Self::n_outputs),
    /// [`n_outputs`](Self::n_outputs) and [`n_inputs`](Self::n_inputs). The written input is
    /// finite and within the controller's input bounds.
    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus;

    /// No measurement this period; the input `u` (length [`n_inputs`](Self::n_inputs)) is held
    /// over it instead of a newly computed one.
    ///
    /// Takes the place of one [`step`](Self::step): the next `step` then belongs to the period
    /// after this one. Controllers with memory of time or of the applied input (rate filters,
    /// estimators, move plans) advance it by one period, as if a sample with no information
    /// had arrived. The default does nothing, which suits memoryless controllers.
    fn hold(&mut self, u: &[f64]) {
        let _ = u;
    }

    /// Returns to the state right after construction (estimator, previous input, filters).
    fn reset(&mut self);

    /// The current state estimate `x̂[k|k]`, for controllers that have one.
    fn state_estimate(&self) -> Option<&[f64]> {
        None
    }

    /// The sample time (s) the controller was designed for, when it has one: a loop that
    /// runs it at another period feeds it rates and predictions for the wrong interval.
    fn sample_time(&self) -> Option<f64> {
        None
    }
}
