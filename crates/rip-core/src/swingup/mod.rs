//! Swing-up from rest and catch: an energy-pumping law (Åström & Furuta, "Swinging up a
//! pendulum by energy control", Automatica 36(2), 2000) that keeps the arm inside its limit,
//! and a supervisor, [`SwingUp`], that hands over to a balance controller (LQR, LQG or MPC,
//! unchanged) inside a catch region, bumplessly.
//!
//! Every per-step decision (the energy law with its target, the centring spring, the braking
//! envelope, the voltage from the wanted acceleration, the catch test, the handover and the
//! fall test, the swing-up's own rate filter) is rip-control's `no_std`
//! [`rip_control::swing`], whose docs derive the equations: the same code runs here, in
//! `rip-rt` and on the chip. This module designs its constants ([`SwingParams`]: `J_α`, `G`,
//! `a_s`, `D`, `a_b`, the unstable mode, the predicted catch's reference LQR) from
//! [`SwingUpSettings`] and the nominal [`Plant`], and wraps the supervisor as a
//! [`Controller`] around any balance controller, keeping the [`SwingUpReport`].
//!
//! Conventions are the [`plant`](crate::plant)'s: `x = [θ, θ̇, α, α̇]`, α = 0 upright and ±π
//! hanging; the pendulum angle is wrapped to (−π, π] ([`wrap_angle`]) wherever its value
//! matters. Every step is allocation-free when the balance controller's is.

mod catch;
mod design;
pub mod feasibility;
pub mod plan;

mod settings;
pub mod stored;

pub use crate::swing_report::{SwingUpReport, STILL_ARM};
pub use crate::trig::wrap_angle;
pub use feasibility::{feasibility, Feasibility, Verdict};
pub use rip_control::swing::{PlanPoint, SwingParams};
pub use settings::{OnFall, SwingUpMethod, SwingUpSettings, MAX_SWING_UP_TIME};
pub use stored::{feasibility_inputs, stored_or_computed, StoredFeasibility, VerdictSource};

use rip_control::swing::{Balance, SwingPhase, SwingStatus, SwingStop, SwingSupervisor};

use crate::controller::{Controller, Phase, StepStatus, StopCause};
use crate::error::{Result, RipError};
use crate::plant::Plant;

/// The swing-up supervisor around the balance controller `C` (module docs): rip-control's
/// [`SwingSupervisor`] driving `C`.
#[derive(Debug, Clone)]
pub struct SwingUp<C> {
    balance: C,
    settings: SwingUpSettings,
    supervisor: SwingSupervisor,
    /// The planned swing-up ([`plan`]); empty with the energy method or when none was found.
    /// Shared: the studies run many supervisors on one plan.
    plan: std::sync::Arc<[PlanPoint]>,
    /// What the current swing-up has done so far.
    report: SwingUpReport,
}

/// The plan [`SwingUp::new`] designs for `settings` on `plant` at sample time `ts`: empty with
/// the energy method, where none is found, or where the swing-up cannot be designed.
pub(crate) fn designed_plan(
    plant: &Plant,
    settings: &SwingUpSettings,
    ts: f64,
) -> std::sync::Arc<[PlanPoint]> {
    if settings.method != SwingUpMethod::Trajectory || settings.validate().is_err() {
        return std::sync::Arc::from([]);
    }
    design::params(plant, settings, ts)
        .and_then(|params| plan::plan(plant, settings, &params, ts))
        .unwrap_or_default()
        .into()
}

/// A balance controller of this crate as the `no_std` supervisor drives it.
struct Host<'a, C>(&'a mut C);

impl<C: Controller> Balance<f64> for Host<'_, C> {
    type Status = StepStatus;

    fn step(&mut self, angles: [f64; 2], reference: [f64; 2]) -> (f64, StepStatus) {
        let mut u = [0.0];
        let status = self.0.step(&angles, &reference, &mut u);
        (u[0], status)
    }

    fn observe(&mut self, angles: [f64; 2], u: f64) {
        self.0.observe(&angles, &[u]);
    }

    fn seed(&mut self, x: [f64; 4], u: f64) {
        self.0.seed(&x, &[u]);
    }

    fn hold(&mut self, u: f64) {
        self.0.hold(&[u]);
    }

    fn reset(&mut self) {
        self.0.reset();
    }
}

impl<C: Controller> SwingUp<C> {
    /// The supervisor around `balance`, with the swing-up designed on `plant` (the nominal
    /// model of the rig; the simulated or real plant may differ). `balance` must have 2
    /// outputs, 1 input and a sample time.
    pub fn new(balance: C, plant: &Plant, settings: SwingUpSettings) -> Result<Self> {
        Self::planned(balance, plant, settings, None)
    }

    /// [`new`](Self::new) with the plan given, where one designed on the same `plant` and
    /// `settings` at the balance controller's sample time is at hand
    /// ([`designed_plan`]); `None` designs it.
    pub(crate) fn planned(
        balance: C,
        plant: &Plant,
        settings: SwingUpSettings,
        plan: Option<std::sync::Arc<[PlanPoint]>>,
    ) -> Result<Self> {
        settings.validate()?;
        if balance.n_outputs() != 2 || balance.n_inputs() != 1 {
            return Err(RipError::invalid(
                "balance",
                format!(
                    "must have 2 outputs and 1 input, has {} and {}",
                    balance.n_outputs(),
                    balance.n_inputs()
                ),
            ));
        }
        let ts = balance
            .sample_time()
            .ok_or_else(|| RipError::invalid("balance", "needs a sample time to be supervised"))?;
        let params = design::params(plant, &settings, ts).ok_or_else(|| {
            RipError::invalid(
                "plant",
                "the nominal model has no real unstable mode about upright to catch",
            )
        })?;
        let plan = match (settings.method, plan) {
            (SwingUpMethod::Energy, _) => std::sync::Arc::from([]),
            (SwingUpMethod::Trajectory, Some(plan)) => plan,
            (SwingUpMethod::Trajectory, None) => designed_plan(plant, &settings, ts),
        };
        let mut out = Self {
            balance,
            settings,
            plan,
            supervisor: SwingSupervisor::new(params),
            report: SwingUpReport::start(0.0, 0.0, 0.0),
        };
        out.reset();
        Ok(out)
    }

    /// The planned swing-up, one point per period from hanging ([`plan`]); empty with the
    /// energy method or when no plan was found.
    pub fn plan(&self) -> &[PlanPoint] {
        &self.plan
    }

    /// The settings.
    pub fn settings(&self) -> &SwingUpSettings {
        &self.settings
    }

    /// The balance controller.
    pub fn balance(&self) -> &C {
        &self.balance
    }

    /// The constants the supervisor runs with, as designed from the settings and the plant.
    pub fn params(&self) -> &SwingParams {
        self.supervisor.params()
    }

    /// Sample time (s), the balance controller's.
    pub fn ts(&self) -> f64 {
        self.params().ts
    }

    /// The swing-up's own estimate `[θ, θ̇, α, α̇]` (α wrapped).
    pub fn swing_estimate(&self) -> [f64; 4] {
        self.supervisor.estimate()
    }

    /// The pendulum energy `E` (J, 0 upright at rest) of the swing-up's estimate.
    pub fn energy(&self) -> f64 {
        self.params().energy(&self.supervisor.estimate())
    }

    /// What the current swing-up (or the last, once balancing or stopped) has done: peak
    /// energy against the target, the largest voltage asked for, the arm travel used.
    pub fn report(&self) -> SwingUpReport {
        self.report
    }

    fn start_report(&mut self) {
        let p = self.params();
        self.report =
            SwingUpReport::start(p.target(0.0), -2.0 * p.model.grav, self.settings.arm_limit);
    }

    /// The braking deceleration `a_b` (rad/s²) the arm-limit envelope reserves.
    pub fn brake_deceleration(&self) -> f64 {
        self.params().brake
    }
}

impl<C: Controller> Controller for SwingUp<C> {
    fn n_outputs(&self) -> usize {
        2
    }

    fn n_inputs(&self) -> usize {
        1
    }

    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        let before = self.supervisor.phase();
        let (v, status) = self.supervisor.step_planned(
            &mut Host(&mut self.balance),
            &self.plan,
            [y[0], y[1]],
            [r[0], r[1]],
        );
        u[0] = v;
        let after = self.supervisor.phase();
        // A fall with a retry starts a new swing-up, and a new report with it; every swing-up
        // sample with an estimate is recorded in it.
        if before == SwingPhase::Balance && after == SwingPhase::SwingUp {
            self.start_report();
        }
        if after == SwingPhase::SwingUp && self.supervisor.started() {
            let x = self.supervisor.estimate();
            let energy = self.params().energy(&x);
            self.report.record(energy, x[0], x[2], v);
        }
        match status {
            SwingStatus::Nominal => StepStatus::Nominal,
            SwingStatus::Held => StepStatus::Fallback,
            SwingStatus::Balance(s) => s,
        }
    }

    fn hold(&mut self, u: &[f64]) {
        self.supervisor.hold(&mut Host(&mut self.balance), u[0]);
    }

    fn phase(&self) -> Phase {
        match self.supervisor.phase() {
            SwingPhase::SwingUp => Phase::SwingUp,
            SwingPhase::Balance => Phase::Balance,
            SwingPhase::Stopped(SwingStop::Timeout) => Phase::Stopped(StopCause::SwingUpTimeout),
            SwingPhase::Stopped(SwingStop::LeftBalanceRegion) => {
                Phase::Stopped(StopCause::LeftBalanceRegion)
            }
        }
    }

    fn reset(&mut self) {
        self.supervisor.reset(&mut Host(&mut self.balance));
        self.start_report();
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        self.balance.state_estimate()
    }

    fn sample_time(&self) -> Option<f64> {
        Some(self.ts())
    }

    fn swing_up_report(&self) -> Option<SwingUpReport> {
        Some(self.report)
    }
}

#[cfg(test)]
mod tests;
