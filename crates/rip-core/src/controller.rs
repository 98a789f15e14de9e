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

/// Which part of its task a controller is in, for the loop that runs it and the record it
/// keeps.
///
/// A balance controller is always in [`Phase::Balance`]; the swing-up supervisor
/// ([`SwingUp`](crate::swingup::SwingUp)) moves between all three.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Phase {
    /// Pumping energy into the hanging pendulum; the pendulum is expected far from upright.
    SwingUp,
    /// Balancing near upright: leaving the balance region is a fall.
    #[default]
    Balance,
    /// Given up; the controller writes 0 V from now on, for the given reason.
    Stopped(StopCause),
}

/// Why a controller gave up ([`Phase::Stopped`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopCause {
    /// The swing-up did not bring the pendulum into the catch region within its maximum time.
    SwingUpTimeout,
    /// The pendulum left the balance region after the catch and the supervisor is set not to
    /// retry.
    LeftBalanceRegion,
}

impl Phase {
    /// Snake-case name (`"swing_up"`, `"balance"`, `"stopped"`), as logs write it.
    pub fn name(self) -> &'static str {
        match self {
            Self::SwingUp => "swing_up",
            Self::Balance => "balance",
            Self::Stopped(_) => "stopped",
        }
    }
}

impl StopCause {
    /// Snake-case name (`"swing_up_timeout"`, `"left_balance_region"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::SwingUpTimeout => "swing_up_timeout",
            Self::LeftBalanceRegion => "left_balance_region",
        }
    }
}

impl std::fmt::Display for StopCause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::SwingUpTimeout => {
                "the swing-up did not reach the catch region in its maximum time"
            }
            Self::LeftBalanceRegion => "the pendulum left the balance region after the catch",
        })
    }
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

    /// A sample whose input someone else chose (a supervisor running another law): the
    /// controller updates its estimator with the measurement `y` and the applied input `u`
    /// exactly as [`step`](Self::step) would have with its own move, and computes no move, so
    /// that it is ready to take over from the next sample on.
    ///
    /// The default treats the sample as [held](Self::hold) with `u`.
    fn observe(&mut self, y: &[f64], u: &[f64]) {
        let _ = y;
        self.hold(u);
    }

    /// Restarts the estimator from a known plant state: `x = [θ, θ̇, α, α̇]` is the state at
    /// this sample (further estimator states, such as a disturbance integrator, start at zero)
    /// and `u` is applied over the coming period, as after an [`observe`](Self::observe).
    ///
    /// A supervisor uses it far from upright, where the linear model the estimator predicts
    /// with does not hold. The default treats the sample as [held](Self::hold) with `u`.
    fn seed(&mut self, x: &[f64], u: &[f64]) {
        let _ = x;
        self.hold(u);
    }

    /// Which part of its task the controller is in; [`Phase::Balance`] unless it supervises a
    /// swing-up.
    fn phase(&self) -> Phase {
        Phase::Balance
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

    /// What a swing-up supervisor's current (or last) swing-up did, for the message of one
    /// that ends without a catch; `None` for a controller that does not swing up.
    fn swing_up_report(&self) -> Option<crate::swing_report::SwingUpReport> {
        None
    }
}

/// Forwards every method to the controller behind a pointer, so supervisors and loops can hold
/// a boxed or borrowed controller of any kind.
macro_rules! forward_controller {
    ($($ty:ty),*) => {$(
        impl<C: Controller + ?Sized> Controller for $ty {
            fn n_outputs(&self) -> usize {
                (**self).n_outputs()
            }

            fn n_inputs(&self) -> usize {
                (**self).n_inputs()
            }

            fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
                (**self).step(y, r, u)
            }

            fn hold(&mut self, u: &[f64]) {
                (**self).hold(u);
            }

            fn observe(&mut self, y: &[f64], u: &[f64]) {
                (**self).observe(y, u);
            }

            fn seed(&mut self, x: &[f64], u: &[f64]) {
                (**self).seed(x, u);
            }

            fn phase(&self) -> Phase {
                (**self).phase()
            }

            fn reset(&mut self) {
                (**self).reset();
            }

            fn state_estimate(&self) -> Option<&[f64]> {
                (**self).state_estimate()
            }

            fn sample_time(&self) -> Option<f64> {
                (**self).sample_time()
            }

            fn swing_up_report(&self) -> Option<crate::swing_report::SwingUpReport> {
                (**self).swing_up_report()
            }
        }
    )*};
}

forward_controller!(Box<C>, &mut C);
