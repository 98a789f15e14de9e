//! The designs rip-control runs: rip-core makes the design (DARE, Kalman design, condensing)
//! and fills a [`rip_control::Design`], the one description of a controller that the host's
//! controllers, `rip-rt` and the firmware all step with the same code.
//!
//! [`Lqr::control_design`](crate::regulators::Lqr::control_design),
//! [`Lqg::control_design`](crate::regulators::Lqg::control_design) and
//! [`Mpc::control_design`](crate::mpc::Mpc::control_design) give a controller's design;
//! [`with_compensation`] adds a compensation law to one.
//!
//! [`OnboardController`] runs such a design on the host behind rip-core's [`Controller`]
//! interface: [`Lqr`](crate::regulators::Lqr) and [`Lqg`](crate::regulators::Lqg) step with
//! it, and so does the run-time MPC the assembly hands to `rip-rt` and the simulations
//! ([`Mpc::run_time_controller`](crate::mpc::Mpc::run_time_controller) decides when), so the move the PC computes is the move the
//! chip computes from the same design.

pub use rip_control::{
    Controller as ControlStep, Design as ControlDesign, DesignError, Kind as ControlKind,
};

use crate::compensation::Compensation;
use crate::controller::{Controller, StepStatus};
use crate::error::{Result, RipError};
use crate::linalg::Mat;

/// Copies `m` row-major into `dst`, naming `name` when it exceeds the capacity `cap_rows ×
/// cap_cols`.
pub(crate) fn put(
    name: &str,
    dst: &mut [f64],
    m: &Mat,
    cap_rows: usize,
    cap_cols: usize,
) -> Result<()> {
    if m.nrows() > cap_rows || m.ncols() > cap_cols || m.nrows() * m.ncols() > dst.len() {
        return Err(RipError::invalid(
            name,
            format!(
                "{}×{} exceeds the onboard capacity {cap_rows}×{cap_cols}",
                m.nrows(),
                m.ncols()
            ),
        ));
    }
    let cols = m.ncols();
    for i in 0..m.nrows() {
        for j in 0..cols {
            dst[i * cols + j] = m[(i, j)];
        }
    }
    Ok(())
}

/// `design` with `law` compensating every written voltage (its bounds become the design's
/// input bounds; the controller plans inside them by the law's margin).
pub fn with_compensation(mut design: ControlDesign, law: &Compensation) -> ControlDesign {
    let (vs, ws) = law.scales();
    design.compensation = rip_control::CompensationDesign {
        dead_zone: law.dead_zone(),
        friction_voltage: law.friction_voltage(),
        voltage_scale: vs,
        velocity_scale: ws,
    };
    let (lo, hi) = law.bounds();
    design.input_bounds = [lo, hi];
    design
}

/// The error of a design rip-control refuses, as a [`RipError`] naming its field.
pub(crate) fn refused(e: DesignError) -> RipError {
    let name = match e {
        DesignError::BadSize(n) | DesignError::BadValue(n) => n,
        _ => "design",
    };
    RipError::invalid(
        name,
        format!("the onboard controller refuses the design: {e}"),
    )
}

/// rip-control's run-time controller of a [`ControlDesign`] behind rip-core's [`Controller`]
/// interface: every [`step`](Controller::step), [`hold`](Controller::hold),
/// [`observe`](Controller::observe), [`seed`](Controller::seed) and
/// [`reset`](Controller::reset) is rip-control's (its crate docs give the equations), with
/// the slices converted to its fixed-size arguments at the boundary. Allocation-free after
/// construction.
///
/// Any move that is not rip-control's [`Nominal`](rip_control::Status::Nominal) (a discarded
/// measurement, the QP's iteration limit, a solver failure) is reported as
/// [`StepStatus::Fallback`]; [`last_move`](Self::last_move) and [`stats`](Self::stats) tell
/// which.
#[derive(Debug, Clone)]
pub struct OnboardController {
    inner: Box<ControlStep<f64>>,
    last: rip_control::Move<f64>,
}

impl OnboardController {
    /// The controller of `design`, in its initial state.
    ///
    /// # Errors
    /// The field rip-control refuses ([`ControlDesign::validate`]), or a Hessian that is not
    /// numerically positive definite.
    pub fn new(design: &ControlDesign) -> Result<Self> {
        Ok(Self {
            inner: ControlStep::new(design).map(Box::new).map_err(refused)?,
            last: rip_control::Move::default(),
        })
    }

    /// rip-control's controller it steps with (estimate, plan, QP solution, integrator).
    pub fn control(&self) -> &ControlStep<f64> {
        &self.inner
    }

    /// The design it runs.
    pub fn design(&self) -> &ControlDesign {
        self.inner.design()
    }

    /// rip-control's counters since construction or reset (discarded measurements, iteration
    /// limits, solver failures, the most iterations one QP took).
    pub fn stats(&self) -> rip_control::Stats {
        self.inner.stats()
    }

    /// The last [`step`](Controller::step)'s move: the voltage, its status and the QP's
    /// iterations (the default move before the first step).
    pub fn last_move(&self) -> rip_control::Move<f64> {
        self.last
    }

    /// The design rebuilt with `edit` applied, in its initial state.
    pub(crate) fn rebuilt(&self, edit: impl FnOnce(&mut ControlDesign)) -> Result<Self> {
        let mut d = self.design().clone();
        edit(&mut d);
        Self::new(&d)
    }
}

/// The first `n` of `v` in rip-control's two-output array; entries past `v` are NaN, so a
/// short slice is an unusable sample rather than a panic.
fn pair(v: &[f64], n: usize) -> [f64; rip_control::MAX_NY] {
    let mut out = [f64::NAN; rip_control::MAX_NY];
    for (o, &x) in out.iter_mut().zip(v).take(n) {
        *o = x;
    }
    out
}

/// `x` as the four plant states, NaN when it is short (a seed that is then a held period).
fn plant_state(x: &[f64]) -> [f64; rip_control::NX_PLANT] {
    let mut s = [f64::NAN; rip_control::NX_PLANT];
    if let Some(x) = x.get(..s.len()) {
        s.copy_from_slice(x);
    }
    s
}

/// A non-finite stand-in for a missing input: rip-control then keeps the last applied one.
fn first(u: &[f64]) -> f64 {
    u.first().copied().unwrap_or(f64::NAN)
}

impl Controller for OnboardController {
    /// The LQR measures both angles; the LQG and MPC their design's `ny`.
    fn n_outputs(&self) -> usize {
        match self.design().kind {
            ControlKind::Lqr => rip_control::MAX_NY,
            ControlKind::Lqg | ControlKind::Mpc => self.design().ny,
        }
    }

    fn n_inputs(&self) -> usize {
        rip_control::MAX_NU
    }

    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        let n = self.n_outputs();
        self.last = self.inner.step(rip_control::Measurement {
            angles: pair(y, n),
            reference: pair(r, n),
        });
        if let Some(u) = u.first_mut() {
            *u = self.last.voltage;
        }
        if self.last.status.is_nominal() {
            StepStatus::Nominal
        } else {
            StepStatus::Fallback
        }
    }

    fn hold(&mut self, u: &[f64]) {
        self.inner.hold(first(u));
    }

    fn observe(&mut self, y: &[f64], u: &[f64]) {
        let n = self.n_outputs();
        self.inner.observe(pair(y, n), first(u));
    }

    fn seed(&mut self, x: &[f64], u: &[f64]) {
        self.inner.seed(plant_state(x), first(u));
    }

    fn reset(&mut self) {
        self.inner.reset();
        self.last = rip_control::Move::default();
    }

    fn sample_time(&self) -> Option<f64> {
        Some(self.design().ts)
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        Some(self.inner.estimate())
    }
}
