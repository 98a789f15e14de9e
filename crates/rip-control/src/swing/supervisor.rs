//! The supervisor: the swing, the catch and the handover to the balance controller (module docs, "Supervisor and catch").

use super::*;

/// The swing-up's own estimate: angles and filtered-difference rates `[θ, θ̇, α, α̇]`, α
/// wrapped; the LQR's rate filter (crate docs, "LQR") with the pendulum's difference wrapped.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SwingRates<R: Real> {
    ts: R,
    a: R,
    x: [R; 4],
    started: bool,
    held: u32,
}

impl<R: Real> SwingRates<R> {
    fn new(ts: R, cutoff_hz: R) -> Self {
        let two_pi: R = c(2.0 * core::f64::consts::PI);
        Self {
            ts,
            a: (-(two_pi * cutoff_hz * ts)).exp(),
            x: [R::ZERO; 4],
            started: false,
            held: 0,
        }
    }

    /// Takes the angles `[θ, α]`; `false` (estimate kept, the period counted as held) when
    /// they are not finite.
    fn update(&mut self, y: [R; 2]) -> bool {
        if !(y[0].is_finite() && y[1].is_finite()) {
            self.hold();
            return false;
        }
        let alpha = wrap_angle(y[1]);
        if self.started {
            let periods = self.held.saturating_add(1);
            let dt = c::<R>(f64::from(periods)) * self.ts;
            let a = self.a.powu(periods);
            let d_theta = (y[0] - self.x[0]) / dt;
            let d_alpha = wrap_angle(alpha - self.x[2]) / dt;
            self.x[1] = a * self.x[1] + (R::ONE - a) * d_theta;
            self.x[3] = a * self.x[3] + (R::ONE - a) * d_alpha;
        } else {
            self.started = true;
        }
        self.held = 0;
        self.x[0] = y[0];
        self.x[2] = alpha;
        true
    }

    fn hold(&mut self) {
        if self.started {
            self.held = self.held.saturating_add(1);
        }
    }

    fn reset(&mut self) {
        self.x = [R::ZERO; 4];
        self.started = false;
        self.held = 0;
    }
}

/// Largest distance (rad) of the pendulum from hanging at which a swing-up starts its plan.
pub const PLAN_START_ANGLE: f64 = 0.15;

/// Largest `|θ̇|` and `|α̇|` (rad/s) from the plan's over its first [`PLAN_SETTLE_SAMPLES`]
/// samples: a swing-up that starts its plan from a moving pendulum leaves it. (A count of an
/// 800-count encoder reads as 0.56 rad/s in the estimate's first difference.)
pub const PLAN_START_RATE: f64 = 2.0;

/// Samples of the plan over which the rates are checked against [`PLAN_START_RATE`] (the
/// estimate has no rate at its first sample, two differences by the third).
pub const PLAN_SETTLE_SAMPLES: u32 = 3;

/// How many samples the plan's point may move from its clock each period (module docs,
/// "Planned swing-up"): with 1, the plan runs at 0, 1 or 2 of its samples per period,
/// whichever point is nearest the pendulum's measured phase.
pub const PLAN_RETIME_SAMPLES: u32 = 1;

/// How far the retimed plan may fall behind its clock before it is left for the energy law,
/// as a share of its length: a pendulum that lags by more than a quarter of the swing-up is
/// not one swinging a little slower than the nominal model, and a plan point it does not
/// leave (a pendulum held still where the plan turns) would otherwise be followed until
/// `max_time`.
pub const PLAN_MAX_LAG_SHARE: f64 = 0.25;

/// Largest distance (rad) of the arm or the pendulum from the plan (and of the arm's
/// stopping point from the plan's, once it is past the envelope's limit) before the plan is
/// left for the energy law.
pub const PLAN_ABORT_ANGLE: f64 = 0.6;

/// One period of a planned swing-up (module docs, "Planned swing-up"): the planned state, the
/// planned voltage and the tracking gain.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlanPoint<R: Real = f64> {
    /// The planned state `x_k = [θ, θ̇, α, α̇]` (α unwrapped from π).
    pub x: [R; 4],
    /// The planned voltage `u_k` (V) on the smooth model.
    pub u: R,
    /// The time-varying LQR gain `K_k`.
    pub k: [R; 4],
}

impl<R: Real> PlanPoint<R> {
    /// The error `x − x_k`, the pendulum's wrapped.
    #[inline]
    pub fn error(&self, x: &[R; 4]) -> [R; 4] {
        [
            x[0] - self.x[0],
            x[1] - self.x[1],
            wrap_angle(x[2] - self.x[2]),
            x[3] - self.x[3],
        ]
    }

    /// The tracking voltage `sat_U(u_k − K_k (x − x_k))` (module docs).
    #[inline]
    pub fn voltage(&self, x: &[R; 4], max_voltage: R) -> R {
        let e = self.error(x);
        let mut u = self.u;
        for i in 0..4 {
            u -= self.k[i] * e[i];
        }
        if u.is_finite() {
            u.clamp(-max_voltage, max_voltage)
        } else {
            R::ZERO
        }
    }
}

/// The balance controller the supervisor hands over to: what [`SwingSupervisor`] needs of
/// it. rip-control's [`Controller`] implements it; rip-core adapts its own controllers.
pub trait Balance<R: Real> {
    /// What a balance step reports, passed through in [`SwingStatus::Balance`].
    type Status;
    /// One balance sample on the angles `[θ, α]` (α wrapped) and the reference `[θ_ref,
    /// α_ref]`: the voltage written and the step's status.
    fn step(&mut self, angles: [R; 2], reference: [R; 2]) -> (R, Self::Status);
    /// A sample whose voltage `u` the swing-up chose: the estimator runs on `angles`.
    fn observe(&mut self, angles: [R; 2], u: R);
    /// Restarts the estimator at the plant state `x` with `u` the voltage just written.
    fn seed(&mut self, x: [R; 4], u: R);
    /// A period without a measurement, the plant receiving `u`.
    fn hold(&mut self, u: R);
    /// Back to the initial state.
    fn reset(&mut self);
}

impl<R: Real> Balance<R> for Controller<R> {
    type Status = Status;

    fn step(&mut self, angles: [R; 2], reference: [R; 2]) -> (R, Status) {
        let mut m = Measurement {
            angles: [R::ZERO; MAX_NY],
            reference: [R::ZERO; MAX_NY],
        };
        m.angles[..2].copy_from_slice(&angles);
        m.reference[..2].copy_from_slice(&reference);
        let mv = Controller::step(self, m);
        (mv.voltage, mv.status)
    }

    fn observe(&mut self, angles: [R; 2], u: R) {
        let mut y = [R::ZERO; MAX_NY];
        y[..2].copy_from_slice(&angles);
        Controller::observe(self, y, u);
    }

    fn seed(&mut self, x: [R; 4], u: R) {
        let mut s = [R::ZERO; NX_PLANT];
        s[..4].copy_from_slice(&x);
        Controller::seed(self, s, u);
    }

    fn hold(&mut self, u: R) {
        Controller::hold(self, u);
    }

    fn reset(&mut self) {
        Controller::reset(self);
    }
}

/// Why the supervisor gave up ([`SwingPhase::Stopped`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwingStop {
    /// No catch within [`SwingParams::max_time`].
    Timeout,
    /// A fall with [`OnFall::Stop`].
    LeftBalanceRegion,
}

/// Where the supervisor is (module docs, "Supervisor and catch").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwingPhase {
    /// Pumping energy by the law (1)–(4).
    SwingUp,
    /// The balance controller in charge.
    Balance,
    /// 0 V from now on.
    Stopped(SwingStop),
}

/// What one supervisor step did, besides its voltage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwingStatus<S> {
    /// The law's voltage (or 0 V stopped), from a usable measurement.
    Nominal,
    /// A swing-up sample with an unusable measurement: the estimate is kept and the balance
    /// controller told the period was held.
    Held,
    /// The balance controller's step and its status.
    Balance(S),
}

/// The swing-up supervisor (module docs): the law, the catch, the handover and the balance
/// region's fall test, driving a [`Balance`] controller passed in at every call.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwingSupervisor<R: Real = f64> {
    params: SwingParams<R>,
    rates: SwingRates<R>,
    phase: SwingPhase,
    /// Samples spent in the current swing-up.
    swing_samples: u32,
    /// Samples since the catch (0 while swinging up).
    balance_samples: u32,
    /// The arm reference held since the catch, and the external one at the catch.
    hold_reference: Option<(R, R)>,
    /// The last voltage the swing-up applied.
    u_swing: R,
    /// The last voltage the balance controller applied: it acts during the stop's latency.
    u_balance: R,
    /// The plan's next sample while the swing-up follows one (module docs, "Planned
    /// swing-up"); `None` pumping.
    plan_step: Option<u32>,
    /// Whether the plan has just been left with the arm outside the envelope (module docs,
    /// "Planned swing-up"): braked with the whole bound until it is inside or turns back.
    left_plan: bool,
}

impl<R: Real> SwingSupervisor<R> {
    /// The supervisor with `params`, swinging up from its first sample.
    pub fn new(params: SwingParams<R>) -> Self {
        Self {
            rates: SwingRates::new(params.ts, params.rate_cutoff_hz),
            params,
            phase: SwingPhase::SwingUp,
            swing_samples: 0,
            balance_samples: 0,
            hold_reference: None,
            u_swing: R::ZERO,
            u_balance: R::ZERO,
            plan_step: None,
            left_plan: false,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &SwingParams<R> {
        &self.params
    }

    /// The phase.
    pub fn phase(&self) -> SwingPhase {
        self.phase
    }

    /// The swing-up's own estimate `[θ, θ̇, α, α̇]` (α wrapped).
    pub fn estimate(&self) -> [R; 4] {
        self.rates.x
    }

    /// Whether the estimate has had a usable measurement since the start or the last reset
    /// (the law writes 0 V until it has).
    pub fn started(&self) -> bool {
        self.rates.started
    }

    /// Whether the swing-up is following its plan.
    pub fn planning(&self) -> bool {
        self.plan_step.is_some()
    }

    /// One period: the measured angles `y = [θ, α]` (non-finite: unusable) and the external
    /// reference `r = [θ_ref, α_ref]`; the voltage to write and what the step did.
    pub fn step<B: Balance<R>>(
        &mut self,
        balance: &mut B,
        y: [R; 2],
        r: [R; 2],
    ) -> (R, SwingStatus<B::Status>) {
        self.step_planned(balance, &[], y, r)
    }

    /// [`step`](Self::step) with a plan (module docs, "Planned swing-up"), the same slice at
    /// every call; an empty plan pumps.
    pub fn step_planned<B: Balance<R>>(
        &mut self,
        balance: &mut B,
        plan: &[PlanPoint<R>],
        y: [R; 2],
        r: [R; 2],
    ) -> (R, SwingStatus<B::Status>) {
        let usable = self.rates.update(y);
        match self.phase {
            SwingPhase::Stopped(_) => (R::ZERO, SwingStatus::Nominal),
            SwingPhase::SwingUp => {
                let near_end = self.plan_step.map_or(true, |k| {
                    plan.get(k as usize).map_or(true, |point| {
                        wrap_angle(point.x[2]).abs() <= self.params.catch_angle
                    })
                });
                if usable && near_end && self.params.in_catch_region(&self.rates.x) {
                    self.phase = SwingPhase::Balance;
                    self.plan_step = None;
                    self.left_plan = false;
                    self.balance_samples = 0;
                    self.u_balance = self.u_swing;
                    self.hold_reference = Some((self.rates.x[0], r[0]));
                    self.balance_step(balance, y, r)
                } else {
                    self.swing(balance, plan, y, usable)
                }
            }
            SwingPhase::Balance => {
                if !usable || self.params.in_balance_region(&self.rates.x, self.u_balance) {
                    return self.balance_step(balance, y, r);
                }
                match self.params.on_fall {
                    OnFall::Stop => self.stop(SwingStop::LeftBalanceRegion),
                    OnFall::Retry => {
                        self.phase = SwingPhase::SwingUp;
                        self.swing_samples = 0;
                        self.hold_reference = None;
                        self.plan_step = None;
                        self.left_plan = false;
                        self.swing(balance, &[], y, usable)
                    }
                }
            }
        }
    }

    /// A period without a measurement, the plant receiving `u`.
    pub fn hold<B: Balance<R>>(&mut self, balance: &mut B, u: R) {
        self.rates.hold();
        if self.phase == SwingPhase::SwingUp {
            self.swing_samples = self.swing_samples.saturating_add(1);
            // The plan's clock runs with the plant's.
            self.plan_step = self.plan_step.map(|k| k.saturating_add(1));
        }
        balance.hold(u);
    }

    /// Back to swinging up from scratch; `balance` reset too.
    pub fn reset<B: Balance<R>>(&mut self, balance: &mut B) {
        balance.reset();
        self.rates.reset();
        self.phase = SwingPhase::SwingUp;
        self.swing_samples = 0;
        self.balance_samples = 0;
        self.hold_reference = None;
        self.u_swing = R::ZERO;
        self.u_balance = R::ZERO;
        self.plan_step = None;
        self.left_plan = false;
    }

    fn stop<S>(&mut self, cause: SwingStop) -> (R, SwingStatus<S>) {
        self.phase = SwingPhase::Stopped(cause);
        self.plan_step = None;
        self.left_plan = false;
        (R::ZERO, SwingStatus::Nominal)
    }

    /// One swing-up sample: the law's voltage, the balance estimator kept in step, the clock.
    fn swing<B: Balance<R>>(
        &mut self,
        balance: &mut B,
        plan: &[PlanPoint<R>],
        y: [R; 2],
        usable: bool,
    ) -> (R, SwingStatus<B::Status>) {
        self.swing_samples = self.swing_samples.saturating_add(1);
        if c::<R>(f64::from(self.swing_samples)) * self.params.ts > self.params.max_time {
            return self.stop(SwingStop::Timeout);
        }
        let x = self.rates.x;
        if self.swing_samples == 1 && self.rates.started && !plan.is_empty() {
            // The estimate has no rate yet at its first sample: the rest is checked on the
            // angle here and on the rates over the plan's first samples (below).
            let hanging = wrap_angle(x[2] - c(core::f64::consts::PI)).abs() <= c(PLAN_START_ANGLE);
            self.plan_step = hanging.then_some(0);
        }
        let p = &self.params;
        if usable {
            self.plan_step = self.plan_step.map(|k| retimed(plan, k, &x, p));
        }
        let planned = self.plan_step.and_then(|k| {
            let point = plan.get(k as usize)?;
            if !usable {
                // A stale estimate against this period's point would read as a jump: the
                // planned voltage alone.
                return Some(point.u.clamp(-p.max_voltage, p.max_voltage));
            }
            let e = point.error(&x);
            let abort: R = c(PLAN_ABORT_ANGLE);
            let start: R = c(PLAN_START_RATE);
            let settled = k >= PLAN_SETTLE_SAMPLES || (e[1].abs() <= start && e[3].abs() <= start);
            // Retimed, the plan may wait for a pendulum behind it, not for one that stays.
            let behind = self.swing_samples.saturating_sub(1).saturating_sub(k);
            let on_time = f64::from(behind) <= PLAN_MAX_LAG_SHARE * plan.len() as f64;
            let arm_stop = p.braked_stop(x[0], x[1]);
            let plan_stop = p.braked_stop(point.x[0], point.x[1]);
            let arm_inside = x[0].abs() <= p.envelope_limit
                && (arm_stop.abs() <= p.envelope_limit || (arm_stop - plan_stop).abs() <= abort);
            (settled && on_time && e[0].abs() <= abort && e[2].abs() <= abort && arm_inside)
                .then(|| point.voltage(&x, p.max_voltage))
        });
        self.left_plan |= planned.is_none() && self.plan_step.is_some();
        self.plan_step = match (planned, self.plan_step) {
            (Some(_), Some(k)) => Some(k + 1),
            _ => None,
        };
        // After the plan, the envelope holds only from inside it: an arm whose stopping point
        // at `a_b` is past the limit and still moving out is braked with the whole bound.
        if self.left_plan {
            let outward = x[0] * x[1] > R::ZERO;
            self.left_plan = outward && p.braked_stop(x[0], x[1]).abs() > p.envelope_limit;
        }
        let u = match planned {
            Some(u) => u,
            None if self.left_plan => -p.max_voltage * x[1].signum(),
            None if self.rates.started => p.voltage(&x, p.acceleration(&x)),
            None => R::ZERO,
        };
        self.u_swing = u;
        if !usable {
            balance.hold(u);
            return (u, SwingStatus::Held);
        }
        if x[2].abs() <= p.estimator_window {
            balance.observe([y[0], wrap_angle(y[1])], u);
        } else {
            balance.seed(x, u);
        }
        (u, SwingStatus::Nominal)
    }

    /// The index of the plan's point the supervisor follows, while it follows one.
    pub fn plan_index(&self) -> Option<u32> {
        self.plan_step
    }

    fn balance_step<B: Balance<R>>(
        &mut self,
        balance: &mut B,
        y: [R; 2],
        r: [R; 2],
    ) -> (R, SwingStatus<B::Status>) {
        let ts = self.params.ts;
        let theta_ref = match self.hold_reference {
            Some((held, at_catch)) if r[0] == at_catch => {
                // Back to the external reference at a bounded rate (module docs, "catch").
                let step = self.params.reference_return_rate * ts;
                let next = held + (at_catch - held).clamp(-step, step);
                self.hold_reference = Some((next, at_catch));
                next
            }
            // The external reference changed while the held one was still on its way back
            // (an arm caught off centre): the reference moves towards the new value by at
            // most the change itself, and what is left goes on at the return rate. Passed
            // through at once, the change would carry the arm's remaining offset with it (a
            // 1 rad step 1 s after a catch at −0.37 rad became a 1.37 rad step and threw an
            // LQG's pendulum out of the balance region on generated rig 5); added to where
            // the way back is, it would overshoot the new value when the offset lies on the
            // side of the change.
            Some((held, at_catch))
                if held != at_catch && self.params.reference_return_rate > R::ZERO =>
            {
                let step = self.params.reference_return_rate * ts;
                let change = (r[0] - at_catch).abs();
                let shifted = held + (r[0] - held).clamp(-change, change);
                let next = shifted + (r[0] - shifted).clamp(-step, step);
                self.hold_reference = Some((next, r[0]));
                next
            }
            Some(_) => {
                self.hold_reference = None;
                r[0]
            }
            None => r[0],
        };
        let (u, status) = balance.step([y[0], wrap_angle(y[1])], [theta_ref, r[1]]);
        self.u_balance = u;
        // The handover (module docs, "Balance"): the swing-up's estimate carries the balance
        // controller's estimator through the catch transient.
        self.balance_samples = self.balance_samples.saturating_add(1);
        if c::<R>(f64::from(self.balance_samples)) * ts <= self.params.handover_time {
            balance.seed(self.rates.x, u);
        }
        (u, SwingStatus::Balance(status))
    }
}

/// The plan's point to follow at this period, `k` the plan's clock (module docs, "Planned
/// swing-up"): of the points within [`PLAN_RETIME_SAMPLES`] of `k`, the one nearest `x` in
/// the pendulum's phase plane, `(α − α_j)² + (J_α/G)(α̇ − α̇_j)²` (the rate's error scaled by
/// the pendulum's own time constant `√(J_α/G)`), the clock's own where none is nearer. Not
/// before the plan's
/// rates are checked ([`PLAN_SETTLE_SAMPLES`]), nor at or past its end.
fn retimed<R: Real>(plan: &[PlanPoint<R>], k: u32, x: &[R; 4], p: &SwingParams<R>) -> u32 {
    let last = plan.len().saturating_sub(1) as u32;
    if k < PLAN_SETTLE_SAMPLES || k >= last {
        return k;
    }
    let scale = p.model.ja / p.model.grav;
    let distance = |j: u32| {
        let e = plan[j as usize].error(x);
        e[2] * e[2] + scale * e[3] * e[3]
    };
    let lo = k.saturating_sub(PLAN_RETIME_SAMPLES);
    let hi = (k + PLAN_RETIME_SAMPLES).min(last);
    let mut best = k;
    let mut nearest = distance(k);
    for j in lo..=hi {
        let d = distance(j);
        // Strictly nearer only: the clock's point stands against an equal one (a plan that
        // holds still is followed by the clock), and against a NaN distance.
        if d < nearest {
            best = j;
            nearest = d;
        }
    }
    best
}
