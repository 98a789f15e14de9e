//! The run-time controller: one [`Controller`] for the three kinds of [`Design`].

use crate::design::{Design, DesignError, Kind, MAX_NCON, MAX_NX, MAX_NY, MAX_NZ, NX_PLANT};
use crate::qp::{FixedQp, QpOutcome};
use crate::real::Real;

mod regulators;

/// One sample's input to [`Controller::step`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measurement<R: Real = f64> {
    /// Measured outputs `[θ, α]` (rad; the first `ny` are used).
    pub angles: [R; MAX_NY],
    /// The output reference `[θ_ref, α_ref]` (rad).
    pub reference: [R; MAX_NY],
}

/// How a move was computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Status {
    /// The controller's own law.
    #[default]
    Nominal,
    /// The measurement or the reference was unusable (NaN, Inf, an overflow computed from
    /// it): the sample was discarded, the move computed on the kept estimate (MPC: the
    /// previous plan's next move).
    InvalidMeasurement,
    /// The QP hit its iteration bound: the fallback law (the unconstrained MPC move, its
    /// blocked inputs clamped to the bounds) was applied.
    IterationLimit,
    /// The QP broke down numerically or reported infeasible: the fallback law was applied.
    SolverFailure,
}

impl Status {
    /// Whether the move is the controller's own law.
    pub fn is_nominal(self) -> bool {
        self == Self::Nominal
    }
}

/// One sample's output of [`Controller::step`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Move<R: Real = f64> {
    /// The voltage to write (V): finite, within the design's input bounds.
    pub voltage: R,
    /// The voltage the controller planned, before the compensation (equal to `voltage`
    /// without one).
    pub planned: R,
    /// How it was computed.
    pub status: Status,
    /// Dual active-set iterations of this step (MPC; 0 otherwise).
    pub iterations: u32,
}

/// Counters since construction or [`Controller::reset`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stats {
    /// Steps taken.
    pub steps: u32,
    /// Steps on a discarded measurement.
    pub invalid_measurements: u32,
    /// Steps where the QP hit its iteration bound.
    pub iteration_limits: u32,
    /// Steps where the QP failed otherwise.
    pub solver_failures: u32,
    /// The most iterations one QP solve took.
    pub max_iterations: u32,
}

/// The LQR's rate estimate for `[θ, α]`: the backward difference through a first-order
/// low-pass, spanning held periods (crate docs, "LQR").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateFilter<R: Real = f64> {
    a: R,
    ts: R,
    angles: [R; 2],
    rates: [R; 2],
    started: bool,
    held: u32,
}

impl<R: Real> RateFilter<R> {
    /// A filter for period `ts` (s, positive) and cut-off `cutoff_hz` (Hz, positive; `+∞` for
    /// the plain difference): `a = e^{−2π f_c Ts}`.
    pub fn new(ts: R, cutoff_hz: R) -> Self {
        let two_pi = R::from_f64(2.0 * core::f64::consts::PI);
        Self {
            a: (-(two_pi * cutoff_hz * ts)).exp(),
            ts,
            angles: [R::ZERO; 2],
            rates: [R::ZERO; 2],
            started: false,
            held: 0,
        }
    }

    /// Takes the measured angles; `false`, with nothing changed, when they or the rates from
    /// them are not finite. The first sample after construction or reset gives zero rates.
    #[inline]
    pub fn update(&mut self, y: [R; 2]) -> bool {
        if !(y[0].is_finite() && y[1].is_finite()) {
            return false;
        }
        if self.started {
            let periods = self.held.saturating_add(1);
            let (dt, a) = if periods == 1 {
                (self.ts, self.a)
            } else {
                (
                    R::from_f64(f64::from(periods)) * self.ts,
                    self.a.powu(periods),
                )
            };
            let mut rates = [R::ZERO; 2];
            for i in 0..2 {
                let d = (y[i] - self.angles[i]) / dt;
                rates[i] = a * self.rates[i] + (R::ONE - a) * d;
            }
            if !(rates[0].is_finite() && rates[1].is_finite()) {
                return false;
            }
            self.rates = rates;
        } else {
            self.rates = [R::ZERO; 2];
            self.started = true;
        }
        self.held = 0;
        self.angles = y;
        true
    }

    /// Counts a period without a measured angle.
    #[inline]
    pub fn hold(&mut self) {
        if self.started {
            self.held = self.held.saturating_add(1);
        }
    }

    /// Sets the angles and rates, as if just measured.
    pub fn seed(&mut self, angles: [R; 2], rates: [R; 2]) {
        self.angles = angles;
        self.rates = rates;
        self.started = true;
        self.held = 0;
    }

    /// Forgets everything.
    pub fn reset(&mut self) {
        *self = Self {
            angles: [R::ZERO; 2],
            rates: [R::ZERO; 2],
            started: false,
            held: 0,
            ..*self
        };
    }

    /// The last measured angles `[θ, α]`.
    pub fn angles(&self) -> [R; 2] {
        self.angles
    }

    /// The rate estimates `[θ̇̂, α̇̂]`.
    pub fn rates(&self) -> [R; 2] {
        self.rates
    }

    /// Whether an angle has been taken since construction or [`reset`](Self::reset), and how
    /// many periods have been held since the last: with [`angles`](Self::angles) and
    /// [`rates`](Self::rates), everything [`restore`](Self::restore) needs.
    pub fn progress(&self) -> (bool, u32) {
        (self.started, self.held)
    }

    /// Puts back a state read from a filter of the same period and cut-off, so that a saved
    /// filter continues exactly as the original would.
    pub fn restore(&mut self, angles: [R; 2], rates: [R; 2], started: bool, held: u32) {
        *self = Self {
            angles,
            rates,
            started,
            held,
            ..*self
        };
    }
}

/// The steady-state Kalman filter in current form (crate docs, "Estimator").
#[derive(Debug, Clone, Copy, PartialEq)]
struct Estimator<R: Real> {
    prior: [R; MAX_NX],
    posterior: [R; MAX_NX],
    innovation: [R; MAX_NY],
}

/// `acc_i = init_i + Σ_j a_ij x_j` for row-major `a` (rows × cols), accumulated left to right
/// (the order nalgebra's `gemv` uses, so the host's earlier results are reproduced bit for bit).
#[inline]
fn gemv_acc<R: Real>(out: &mut [R], a: &[R], x: &[R], rows: usize, cols: usize, sign: R) {
    if cols == 0 {
        return;
    }
    // `sign` is ±1, so `sign · x_j` is exact and taken once per column.
    let mut sx = [R::ZERO; MAX_NX];
    for (s, &xj) in sx.iter_mut().zip(&x[..cols]) {
        *s = sign * xj;
    }
    let sx = &sx[..cols];
    for (o, row) in out[..rows].iter_mut().zip(a.chunks_exact(cols)) {
        let mut acc = *o;
        for (&s, &aij) in sx.iter().zip(row) {
            acc += s * aij;
        }
        *o = acc;
    }
}

/// The parts of a [`Controller::step`], in the order they run: [`Controller::step_probed`]
/// reports the end of each one the step goes through. After the last comes the rest of the
/// step (the MPC's plan and the estimator's time update, the compensation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// The measurement update: the rate filter (LQR) or the Kalman correction (LQG, MPC).
    Estimate,
    /// The MPC's QP data `f` and `b` from the estimate (MPC only).
    Linear,
    /// The MPC's QP solve (MPC only).
    Qp,
}

/// The run-time controller of a [`Design`] (crate docs). Allocation-free; every step runs in
/// bounded time (the MPC's QP is bounded by the design's `max_iterations`).
#[derive(Debug, Clone)]
pub struct Controller<R: Real = f64> {
    design: Design<R>,
    /// Bounds the law plans within: the design's, shrunk by the compensation's largest
    /// correction.
    plan_bounds: [R; 2],
    filter: RateFilter<R>,
    /// LQR: `[θ, θ̇̂, α, α̇̂]`; LQG: the plant part of `x̂[k|k]`.
    x_hat: [R; NX_PLANT],
    integral: R,
    est: Estimator<R>,
    /// LQR cancelling an input disturbance: its estimate `d̂` and, once there is one, the
    /// model's prediction `x̂⁻` of the next `x̂` (crate docs, "LQR").
    disturbance: R,
    x_predicted: Option<[R; NX_PLANT]>,
    /// The last applied (planned, uncompensated) input `u(k−1)`.
    u_prev: R,
    plan: [R; MAX_NZ],
    f: [R; MAX_NZ],
    b: [R; MAX_NCON],
    /// The MPC's solver; of no QP (`n = 0`) for the regulators.
    qp: FixedQp<R>,
    last_written: R,
    last_planned: R,
    stats: Stats,
}

impl<R: Real> Controller<R> {
    /// The controller of `design` (validated first), in its initial state.
    ///
    /// # Errors
    /// The design's first invalid field, or `BadValue("h")` for a Hessian that is not
    /// numerically positive definite.
    pub fn new(design: &Design<R>) -> Result<Self, DesignError> {
        let mut c = Self::unloaded();
        c.design.clone_from(design);
        c.start()?;
        Ok(c)
    }

    /// A controller of no design ([`Design::zeroed`]), `const` for a firmware's static, to be
    /// [`load`](Self::load)ed in place. Do not step it.
    pub const fn unloaded() -> Self {
        let z = R::ZERO;
        Self {
            design: Design::zeroed(),
            plan_bounds: [z; 2],
            filter: RateFilter {
                a: z,
                ts: z,
                angles: [z; 2],
                rates: [z; 2],
                started: false,
                held: 0,
            },
            x_hat: [z; NX_PLANT],
            integral: z,
            disturbance: z,
            x_predicted: None,
            est: Estimator {
                prior: [z; MAX_NX],
                posterior: [z; MAX_NX],
                innovation: [z; MAX_NY],
            },
            u_prev: z,
            plan: [z; MAX_NZ],
            f: [z; MAX_NZ],
            b: [z; MAX_NCON],
            qp: FixedQp::empty(),
            last_written: z,
            last_planned: z,
            stats: Stats {
                steps: 0,
                invalid_measurements: 0,
                iteration_limits: 0,
                solver_failures: 0,
                max_iterations: 0,
            },
        }
    }

    /// [`Design::read_from`] into this controller's own design, then [`new`](Self::new)'s
    /// checks and initial state, all in place: a device keeps its one controller in a static,
    /// and a design or a controller built as a temporary would take tens of kilobytes of its
    /// stack.
    ///
    /// # Errors
    /// As [`Design::from_bytes`] and [`new`](Self::new); the controller is then unspecified
    /// but valid to load again: do not step it.
    pub fn load(&mut self, bytes: &[u8]) -> Result<(), DesignError> {
        self.design.read_from(bytes)?;
        self.start()
    }

    /// Checks the design it holds and sets up the rate filter, the QP's factors and the
    /// initial state.
    fn start(&mut self) -> Result<(), DesignError> {
        let design = &self.design;
        design.validate()?;
        let c = design.compensation;
        let margin = c.dead_zone + c.friction_voltage;
        let [lo, hi] = design.input_bounds;
        self.plan_bounds = [lo + margin, hi - margin];
        if self.plan_bounds[0].partial_cmp(&self.plan_bounds[1]) != Some(core::cmp::Ordering::Less)
        {
            return Err(DesignError::BadValue("compensation"));
        }
        self.filter = RateFilter::new(design.ts, design.rate_cutoff_hz);
        let (nz, ncon) = if design.kind == Kind::Mpc {
            (design.nz(), design.ncon)
        } else {
            (0, 0)
        };
        if !self
            .qp
            .refactor(&design.h, &design.ac, nz, ncon, design.max_iterations)
        {
            return Err(DesignError::BadValue("h"));
        }
        self.reset();
        Ok(())
    }

    /// The design it runs.
    pub fn design(&self) -> &Design<R> {
        &self.design
    }

    /// The counters since construction or reset.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// The bounds the law plans within (the design's, inside the compensation's margin).
    pub fn plan_bounds(&self) -> [R; 2] {
        self.plan_bounds
    }

    /// The state estimate: LQR `[θ, θ̇̂, α, α̇̂]`; LQG and MPC the filter's `x̂[k|k]`
    /// (`nx` values).
    pub fn estimate(&self) -> &[R] {
        match self.design.kind {
            Kind::Lqr => &self.x_hat,
            Kind::Lqg | Kind::Mpc => &self.est.posterior[..self.design.nx],
        }
    }

    /// The input disturbance `d̂` the law cancels (V; zero for a design that cancels none).
    pub fn input_disturbance(&self) -> R {
        match self.design.kind {
            _ if !self.design.cancels_input_disturbance => R::ZERO,
            Kind::Lqr => self.disturbance,
            Kind::Lqg | Kind::Mpc => self.est.posterior[self.design.nx - 1],
        }
    }

    /// The estimator's prior `x̂[k+1|k]` (LQG and MPC; empty for the LQR).
    pub fn prior(&self) -> &[R] {
        match self.design.kind {
            Kind::Lqr => &[],
            Kind::Lqg | Kind::Mpc => &self.est.prior[..self.design.nx],
        }
    }

    /// The last planned input `u(k−1)` (before compensation).
    pub fn last_input(&self) -> R {
        self.u_prev
    }

    /// The MPC's current plan `u(k+j|k)`, `j = 0..m−1` (empty for the regulators).
    pub fn plan(&self) -> &[R] {
        &self.plan[..self.design.control_horizon]
    }

    /// The MPC's last QP solution `z = [Δu(k) … Δu(k+m−1), ε]` (the fallback law's
    /// unconstrained minimiser after a failed solve; empty for the regulators).
    pub fn qp_solution(&self) -> &[R] {
        self.qp.solution()
    }

    /// The integrator state `x_i` of the integral action.
    pub fn integrator(&self) -> R {
        self.integral
    }

    /// Back to the state right after construction (the counters too).
    pub fn reset(&mut self) {
        self.filter.reset();
        self.x_hat = [R::ZERO; NX_PLANT];
        self.integral = R::ZERO;
        self.disturbance = R::ZERO;
        self.x_predicted = None;
        self.est.prior = [R::ZERO; MAX_NX];
        self.est.posterior = [R::ZERO; MAX_NX];
        self.est.innovation = [R::ZERO; MAX_NY];
        self.u_prev = R::ZERO;
        self.plan = [R::ZERO; MAX_NZ];
        self.qp.reset();
        self.last_written = R::ZERO;
        self.last_planned = R::ZERO;
        self.stats = Stats::default();
    }

    fn arm_rate(&self) -> R {
        self.estimate().get(1).copied().unwrap_or(R::ZERO)
    }

    /// One sample: the estimate from `measurement`, the move, the compensation.
    pub fn step(&mut self, measurement: Measurement<R>) -> Move<R> {
        self.step_probed(measurement, |_| {})
    }

    /// [`step`](Self::step), calling `probe` at the end of each [`Phase`] it goes through
    /// (to time them; the move is the same).
    pub fn step_probed(
        &mut self,
        measurement: Measurement<R>,
        mut probe: impl FnMut(Phase),
    ) -> Move<R> {
        let (v, status, iterations) = match self.design.kind {
            Kind::Lqr => self.step_lqr(&measurement, &mut probe),
            Kind::Lqg => self.step_lqg(&measurement, &mut probe),
            Kind::Mpc => self.step_mpc(&measurement, &mut probe),
        };
        self.stats.steps = self.stats.steps.saturating_add(1);
        match status {
            Status::Nominal => {}
            Status::InvalidMeasurement => self.stats.invalid_measurements += 1,
            Status::IterationLimit => self.stats.iteration_limits += 1,
            Status::SolverFailure => self.stats.solver_failures += 1,
        }
        self.stats.max_iterations = self.stats.max_iterations.max(iterations);
        let voltage = self.compensate(v);
        Move {
            voltage,
            planned: v,
            status,
            iterations,
        }
    }

    /// The compensation of the planned `v` (identity without one); remembers the pair so a
    /// later [`hold`](Self::hold) of the written voltage feeds the estimator `v` exactly.
    fn compensate(&mut self, v: R) -> R {
        let c = self.design.compensation;
        if !c.is_active() {
            return v;
        }
        let rate = self.arm_rate();
        let raw = c.unclamped(v, rate);
        let [lo, hi] = self.design.input_bounds;
        let written = raw.clamp(lo, hi);
        self.last_planned = if raw == written {
            v
        } else {
            c.effective(written, rate)
        };
        self.last_written = written;
        written
    }

    /// The planned `v` behind a written `u` (module docs of rip-core's compensation).
    fn planned_for(&self, u: R, rate: R) -> R {
        let c = self.design.compensation;
        if !c.is_active() {
            u
        } else if u == self.last_written {
            self.last_planned
        } else if u.is_finite() {
            c.effective(u, rate)
        } else {
            u
        }
    }

    /// A period without a measurement, in which the plant received the written voltage `u`.
    pub fn hold(&mut self, u: R) {
        let v = self.planned_for(u, self.arm_rate());
        match self.design.kind {
            Kind::Lqr => {
                self.filter.hold();
                self.predict_lqr_over_held(v);
            }
            Kind::Lqg | Kind::Mpc => {
                if v.is_finite() {
                    self.u_prev = v;
                }
                self.predict_without_measurement();
                if self.design.kind == Kind::Lqg {
                    self.sync_plant_estimate();
                } else {
                    self.shift_plan();
                }
            }
        }
    }

    /// A sample whose written input `u` someone else chose (the swing-up's): the estimate
    /// update from `angles`, then `u` as the applied input. Clears the integrator (bumpless).
    pub fn observe(&mut self, angles: [R; MAX_NY], u: R) {
        let v = self.planned_for(u, self.arm_rate());
        self.integral = R::ZERO;
        match self.design.kind {
            Kind::Lqr => {
                // Bumpless, as the integrator: the swing-up's moves are no disturbance.
                self.disturbance = R::ZERO;
                if self.update_lqr_estimate(&angles) {
                    self.predict_lqr(v);
                } else {
                    self.filter.hold();
                    self.predict_lqr_over_held(v);
                }
            }
            Kind::Lqg | Kind::Mpc => {
                let ok = self.correct(&angles);
                if !ok {
                    self.correct_without_measurement();
                }
                if v.is_finite() {
                    self.u_prev = v;
                }
                if self.design.kind == Kind::Mpc {
                    self.fill_plan(self.u_prev);
                }
                self.sync_plant_estimate();
                self.predict_guarded();
            }
        }
    }

    /// Restarts the estimate at the plant state `x = [θ, θ̇, α, α̇]` with `u` the input just
    /// written (the handover from another controller); clears the integrator and LQR's
    /// input-disturbance estimate. A non-finite `x` is a held period instead.
    pub fn seed(&mut self, x: [R; NX_PLANT], u: R) {
        let v = self.planned_for(u, x[1]);
        self.integral = R::ZERO;
        self.disturbance = R::ZERO;
        if !x.iter().all(|v| v.is_finite()) {
            self.hold(u);
            return;
        }
        match self.design.kind {
            Kind::Lqr => {
                self.filter.seed([x[0], x[2]], [x[1], x[3]]);
                self.sync_lqr_estimate();
                self.predict_lqr(v);
            }
            Kind::Lqg | Kind::Mpc => {
                self.est.prior = [R::ZERO; MAX_NX];
                self.est.prior[..NX_PLANT].copy_from_slice(&x);
                self.correct_without_measurement();
                if v.is_finite() {
                    self.u_prev = v;
                }
                if self.design.kind == Kind::Mpc {
                    self.fill_plan(self.u_prev);
                }
                self.sync_plant_estimate();
                self.predict();
            }
        }
    }

    // ---------------------------------------------------------------- estimator

    fn sync_plant_estimate(&mut self) {
        self.x_hat.copy_from_slice(&self.est.posterior[..NX_PLANT]);
    }

    /// `e = y/s − C x̂[k|k−1]`, `x̂[k|k] = x̂[k|k−1] + M e`; `false` (nothing kept) when `y`,
    /// `e` or `x̂[k|k]` is not finite.
    fn correct(&mut self, y: &[R; MAX_NY]) -> bool {
        let (n, ny) = (self.design.nx, self.design.ny);
        if !y[..ny].iter().all(|v| v.is_finite()) {
            return false;
        }
        let mut e = [R::ZERO; MAX_NY];
        for i in 0..ny {
            e[i] = y[i] / self.design.output_scales[i];
        }
        gemv_acc(&mut e, &self.design.c, &self.est.prior, ny, n, -R::ONE);
        let mut post = self.est.prior;
        gemv_acc(&mut post, &self.design.m, &e, n, ny, R::ONE);
        if !(e[..ny].iter().all(|v| v.is_finite()) && post[..n].iter().all(|v| v.is_finite())) {
            return false;
        }
        self.est.innovation = e;
        self.est.posterior = post;
        true
    }

    fn correct_without_measurement(&mut self) {
        self.est.innovation = [R::ZERO; MAX_NY];
        self.est.posterior = self.est.prior;
    }

    /// `x̂[k+1|k] = A x̂[k|k−1] + B_u u(k) + L e`.
    fn predict(&mut self) {
        let (n, ny) = (self.design.nx, self.design.ny);
        let d = &self.design;
        let mut next = [R::ZERO; MAX_NX];
        for i in 0..n {
            let mut acc = d.a[i * n] * self.est.prior[0];
            for j in 1..n {
                acc += d.a[i * n + j] * self.est.prior[j];
            }
            next[i] = acc;
        }
        gemv_acc(&mut next, &d.b, &[self.u_prev], n, 1, R::ONE);
        gemv_acc(&mut next, &d.l, &self.est.innovation, n, ny, R::ONE);
        self.est.prior = next;
    }

    /// [`predict`](Self::predict), redone without the innovation when it overflows.
    fn predict_guarded(&mut self) {
        let backup = self.est.prior;
        self.predict();
        if !self.est.prior[..self.design.nx]
            .iter()
            .all(|v| v.is_finite())
        {
            self.est.prior = backup;
            self.predict_without_measurement();
        }
    }

    /// A whole period without a measurement: `x̂[k|k] = x̂[k|k−1]`, then the time update.
    fn predict_without_measurement(&mut self) {
        self.correct_without_measurement();
        self.predict();
    }

    // ---------------------------------------------------------------- MPC

    /// `u` as every planned move, clamped to the plan bounds.
    fn fill_plan(&mut self, u: R) {
        let [lo, hi] = self.plan_bounds;
        let v = u.max(lo).min(hi);
        for p in &mut self.plan[..self.design.control_horizon] {
            *p = v;
        }
    }

    fn shift_plan(&mut self) {
        let m = self.design.control_horizon;
        if m > 1 {
            self.plan.copy_within(1..m, 0);
        }
    }

    /// `f = f0 + F_x x + F_u u⁻ − F_r r`, `b = b0 + B_x x + B_u u⁻`.
    fn fill_linear(&mut self, r: &[R; MAX_NY]) {
        let d = &self.design;
        let (n, ny, nz, ncon) = (d.nx, d.ny, d.nz(), d.ncon);
        let x = &self.est.posterior;
        let u = [self.u_prev];
        self.f[..nz].copy_from_slice(&d.f0[..nz]);
        gemv_acc(&mut self.f, &d.fx, x, nz, n, R::ONE);
        gemv_acc(&mut self.f, &d.fu, &u, nz, 1, R::ONE);
        gemv_acc(&mut self.f, &d.fr, r, nz, ny, -R::ONE);
        self.b[..ncon].copy_from_slice(&d.b0[..ncon]);
        gemv_acc(&mut self.b, &d.bx, x, ncon, n, R::ONE);
        gemv_acc(&mut self.b, &d.bu, &u, ncon, 1, R::ONE);
    }

    fn step_mpc(
        &mut self,
        meas: &Measurement<R>,
        probe: &mut impl FnMut(Phase),
    ) -> (R, Status, u32) {
        let (nz, ncon, ny) = (self.design.nz(), self.design.ncon, self.design.ny);
        let r_ok = meas.reference[..ny].iter().all(|v| v.is_finite());
        let mut measured = self.correct(&meas.angles);
        probe(Phase::Estimate);
        if measured {
            // A finite but huge estimate can still overflow the QP data (tested even when the
            // reference is unusable, with a zero one).
            let r = if r_ok {
                meas.reference
            } else {
                [R::ZERO; MAX_NY]
            };
            self.fill_linear(&r);
            measured = self.f[..nz].iter().all(|v| v.is_finite())
                && self.b[..ncon].iter().all(|v| v.is_finite());
        }
        if !measured {
            self.correct_without_measurement();
        }
        probe(Phase::Linear);
        let m = self.design.control_horizon;
        let [lo, hi] = self.plan_bounds;
        let u_prev = self.u_prev;
        let (status, iterations) = if measured && r_ok {
            let (outcome, it) = self.qp.solve(&self.f[..nz], &self.b[..ncon]);
            let status = match outcome {
                QpOutcome::Solved => Status::Nominal,
                QpOutcome::IterationLimit => Status::IterationLimit,
                QpOutcome::Infeasible | QpOutcome::NumericalTrouble => Status::SolverFailure,
            };
            (status, it)
        } else {
            (Status::InvalidMeasurement, 0)
        };
        probe(Phase::Qp);
        self.shift_plan();
        match status {
            Status::Nominal => {
                let z = self.qp.solution();
                let mut u = u_prev;
                for j in 0..m {
                    u += z[j];
                    self.plan[j] = u.max(lo).min(hi);
                }
            }
            Status::IterationLimit | Status::SolverFailure => {
                // The fallback law: the unconstrained minimiser −H⁻¹f, its blocked inputs
                // clamped to the bounds (the moves recomputed from the clamped sums).
                let mut z = [R::ZERO; MAX_NZ];
                self.qp.unconstrained(&mut z);
                let mut u = u_prev;
                let mut all = true;
                for j in 0..m {
                    u += z[j];
                    let v = u.max(lo).min(hi);
                    all &= v.is_finite();
                    self.plan[j] = v;
                    u = v;
                }
                if !all {
                    let v = self.plan[0];
                    self.plan[0] = if v.is_finite() {
                        v
                    } else {
                        u_prev.max(lo).min(hi)
                    };
                }
            }
            Status::InvalidMeasurement => {
                self.plan[0] = self.plan[0].max(lo).min(hi);
            }
        }
        let u = self.plan[0];
        self.u_prev = u;
        self.sync_plant_estimate();
        self.predict_guarded();
        (u, status, iterations)
    }
}
