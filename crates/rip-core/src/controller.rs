//! The one interface every controller implements, so the simulator, the Python layer and the
//! real-time loop (`rip-rt`) can drive LQR, LQG and MPC alike.
//!
//! Each sample `k` the caller hands over the measured outputs `y[k]` and the reference `r[k]`
//! (one entry per output; for the pendulum: arm angle, pendulum angle) and receives the input
//! `u[k]` to hold over the next period. `step` must not allocate: it runs inside a 100 Hz loop.

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
pub trait Controller: Send {
    /// Number of measured outputs in `y` (and of references in `r`).
    fn n_outputs(&self) -> usize;

    /// Number of inputs written to `u`.
    fn n_inputs(&self) -> usize;

    /// Computes `u[k]` from `y[k]` and `r[k]`. Slices have lengths [`n_outputs`](Self::n_outputs),
    /// [`n_outputs`](Self::n_outputs) and [`n_inputs`](Self::n_inputs). The written input is
    /// finite and within the controller's input bounds.
    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus;

    /// Returns to the state right after construction (estimator, previous input, filters).
    fn reset(&mut self);

    /// The current state estimate `x̂[k|k]`, for controllers that have one.
    fn state_estimate(&self) -> Option<&[f64]> {
        None
    }
}
