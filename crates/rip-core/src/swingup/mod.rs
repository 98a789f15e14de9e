//! Swing-up from rest and catch: an energy-pumping law (Åström & Furuta, "Swinging up a
//! pendulum by energy control", Automatica 36(2), 2000) that keeps the arm inside its limit,
//! and a supervisor, [`SwingUp`], that hands over to a balance controller (LQR, LQG or MPC,
//! unchanged) inside a catch region, bumplessly.
//!
//! Conventions are the [`plant`](crate::plant)'s: `x = [θ, θ̇, α, α̇]`, α = 0 upright and ±π
//! hanging. Measured angles may be unwrapped or wrapped; the pendulum angle is wrapped to
//! (−π, π] ([`wrap_angle`]) wherever its value, not only its sine and cosine, matters.
//!
//! # Energy pumping (Åström & Furuta, section 3)
//!
//! The pendulum's own energy relative to upright rest is
//!
//! ```text
//! E = ½ J_α α̇² + G (cos α − 1),          J_α = J_p + m_p l_p²/4,   G = m_p g l_p/2
//! ```
//!
//! (`E = 0` upright at rest, `−2G` hanging at rest). From the pendulum's equation of motion
//! (plant module: `J_α α̈ = m₁₂ cos α θ̈ + J_α sin α cos α θ̇² + G sin α − d_p α̇`),
//!
//! ```text
//! dE/dt = m₁₂ cos α α̇ θ̈ + J_α sin α cos α α̇ θ̇² − d_p α̇²
//! ```
//!
//! so the arm acceleration `θ̈` drives the energy with the sign of `α̇ cos α`; the other two terms
//! are second order while the arm moves slowly, and friction is made up for by the feedback.
//! The pumping law (their eq. (8) with a saturated gain) is
//!
//! ```text
//! ε = (E_t(α) − E)/G                                                                   (1)
//! a_pump = a_p · sat(k_E ε) · s(α̇ cos α),   s(v) = sat(v / w), s(0) = 1
//! ```
//!
//! The target is the upright energy raised by a small margin `δ G` plus the viscous loss still
//! to come on the way up: along the homoclinic orbit `½ J_α α̇² = G (1 − cos α)` the pendulum
//! loses `d_p ∫ |α̇| dα` between `α` and upright, so
//!
//! ```text
//! E_t(α) = δ G + D (1 − cos(α/2)),     D = 4 d_p √(G/J_α)                             (1a)
//! ```
//!
//! (`D` is the loss from hanging to upright, α wrapped to (−π, π]). Without it the pendulum
//! arrives short of upright on a damped rig, and a margin `δ` large enough to make up for that
//! brings it over the top too fast to be caught: `D` is 0.35 G on the `paper` preset and
//! 0.14 G on `qube_servo2`.
//!
//! With `a_pump` in place of `θ̈`, `dE/dt = m₁₂ a_p sat(k_E ε) |α̇ cos α| s(·)/… ≥ 0` while
//! `E < E_t` and `≤ 0` above it: `E → E_t`, the homoclinic orbit through upright (raised by a
//! small margin `δ` so that the pendulum reaches upright in finite time). `s(0) = 1` starts a
//! pendulum that hangs perfectly still. `a_p` is a fraction of the stall acceleration
//! `a_s = (k_t/R_m) U / (J₀ + J_α)` ([`SwingUpSettings`]).
//!
//! # Keeping the arm centred and inside its limit
//!
//! A critically damped spring pulls the arm towards 0 (the middle of its travel):
//! `a_c = −ω_c² θ − 2 ω_c θ̇`, and `a_w = a_pump + a_c` is the wanted acceleration.
//!
//! The arm limit `θ_L` is enforced by a braking envelope (a control-barrier function). With a
//! deceleration `a_b` kept in reserve, the arm can still stop before `+θ_L` exactly when
//!
//! ```text
//! h⁺ = v⁺(θ) − θ̇ ≥ 0,     v⁺(θ) = √(2 a_b (θ_L − θ)⁺)                                  (2)
//! ```
//!
//! (`v⁺` is the speed from which braking at `a_b` stops at `θ_L`). Along the boundary
//! `θ̇ = v⁺`, `dv⁺/dt = −a_b θ̇ / v⁺ = −a_b`. Requiring `dh⁺/dt ≥ −λ h⁺` gives the upper bound
//!
//! ```text
//! θ̈ ≤ a_hi = λ (v⁺ − θ̇) − a_b · clamp(θ̇ / v⁺, 0, 1)                                    (3)
//! ```
//!
//! (the factor is `θ̇/v⁺` inside the envelope, where it is exact, and capped at 1 outside, where
//! the `λ` term already brakes harder; it is 0 while the arm moves away from the limit). The
//! mirror image gives `θ̈ ≥ a_lo = −λ (v⁻ + θ̇) + a_b · clamp(−θ̇ / v⁻, 0, 1)`,
//! `v⁻ = √(2 a_b (θ_L + θ)⁺)`. The law applies `a = clamp(a_w, a_lo, a_hi)`. Far from the
//! limits the bounds are loose and the pumping acts unchanged; near one they dominate.
//! If `θ̈ = a` is achieved, `h⁺ ≥ 0` and `h⁻ ≥ 0` are invariant (Nagumo / comparison lemma on
//! `ḣ ≥ −λh`) and, as `v^± → 0` at `±θ_L`, `|θ| ≤ θ_L` for all time from any start inside the
//! envelope (an arm at rest inside the limit is inside it).
//!
//! `θ̈ = a` is achieved as long as the voltage it needs stays within `±U`: the law inverts the
//! nominal equations of motion, which are affine in `u`,
//!
//! ```text
//! u = (a − θ̈(x, 0)) / (θ̈(x, 1) − θ̈(x, 0)),   clamped to ±U                                (4)
//! ```
//!
//! on the model's smooth part (no dead zone, no Coulomb friction): the voltage `v` the smooth
//! model needs, which the compensation ([`crate::compensation`], applied around the whole
//! supervisor) turns into the voltage the rig needs. Inverting the dead zone here instead
//! would divide by its slope, which is 0 at rest when `V_d ≥ 1 V`.
//!
//! At the boundary `a = −a_b` with `a_b = 0.5 a_s` by default: half the stall acceleration is
//! kept for back-EMF at the envelope's top speed `√(4 a_b θ_L)`, the pendulum's reaction on the
//! arm and ±10 % model error. The simulation tests check `|θ| ≤ θ_L` over perturbed plants.
//!
//! # Last rise (opt-in)
//!
//! The pumping leaves the arm turning when the pendulum arrives, so the catch starts with the
//! arm's rate to stop as well as the pendulum's. With [`SwingUpSettings::rise_damping`]
//! `k_r > 0` the arm is stopped on the way up instead. A torque on the arm alone changes the
//! rates in the ratio `Δα̇/Δθ̇ = −M₁₂/M₂₂ = r` (the mass matrix `M` of the equations of motion;
//! `r = Δα̈/Δθ̈` between two voltages), so stopping the arm leaves the pendulum with
//!
//! ```text
//! E' = ½ J_α (α̇ − r θ̇)² + G (cos α − 1)                                               (5)
//! ```
//!
//! and `α̇ − r θ̇ = p_α / M₂₂` (the pendulum's generalised momentum) does not depend on `θ̈` at
//! all: braking changes `E'` only through the arm's rate, which it takes to 0. The law then
//! regulates `E'` instead of `E` in (1), and on the last rise (the pendulum in the upper half,
//! `cos α > 0`, moving towards upright, `α α̇ < 0`, with `|k_E ε| < 1`) replaces the centring
//! spring by `a_c = −k_r θ̇`: the arm comes to rest while the pendulum arrives with the energy
//! of (1a). The barrier (3) bounds it as before.
//!
//! # Supervisor and catch
//!
//! [`SwingUp`] wraps a balance controller `C` and moves through [`Phase`]s:
//!
//! - **SwingUp**: applies (1)–(4) on its own estimate (angles and filtered differences,
//!   [`SwingUpSettings::rate_cutoff`]). The balance controller follows along: within
//!   [`SwingUpSettings::estimator_window`] of upright its estimator runs on the measurements
//!   and the applied voltage ([`Controller::observe`]); further out, where its linear model does
//!   not hold, it is restarted every sample from the swing-up's estimate
//!   ([`Controller::seed`]). The MPC's previous move is therefore the swing-up's last voltage.
//! - **catch** when `|α| ≤ catch_angle`, `|α̇| ≤ catch_rate`, `|θ̇| ≤ catch_arm_rate`, the
//!   arm's stopping point is within `catch_arm_angle`, and the upright's unstable mode is small
//!   enough for the voltage bound: with the nominal model linearised about upright,
//!   `ẋ = A x + b u`, and `wᵀ A = λ wᵀ` (`λ > 0`, `w_α = 1`), `z = wᵀ x` obeys
//!   `ż = λ z + (wᵀ b) u`, which `|u| ≤ U` can return to 0 only while `|z| < |wᵀ b| U / λ`;
//!   the catch needs `|z| ≤ catch_mode_fraction · |wᵀ b| U / λ`. A pendulum that is close to
//!   upright but falling away from it (or rising too fast) is not caught. The balance
//!   controller computes the move of that same sample. The arm reference starts at the
//!   arm's angle at the catch, `θ_c` (a step from there to the external reference would be a
//!   step of up to `catch_arm_angle` on top of any the user asks for), and moves back to the
//!   external reference at [`SwingUpSettings::reference_return_rate`] (0 by default: held
//!   there) until the external reference changes from the value it had at the catch; from that change on the external
//!   reference is passed through (so a later 0 → 1 rad step is tracked as given, from the
//!   arm's place rather than from `θ_c`).
//! - **Predicted catch** (opt-in, [`SwingUpSettings::catch_prediction`] `> 0`): the fixed arm
//!   windows (`catch_arm_rate`, `catch_arm_angle`) are replaced by a prediction. From the
//!   swing-up's estimate `x`, the nominal model without dead zone and Coulomb friction is
//!   simulated (RK4) for `catch_prediction` seconds under a reference LQR holding the arm
//!   where it is,
//!
//!   ```text
//!   u_k = sat_U(−K (x_k − [θ_c, 0, 0, 0]ᵀ)),   K = dlqr(A_d, b_d, diag(25, 0, 50, 0), 0.1)
//!   ```
//!
//!   (`A_d, b_d` the upright linearisation sampled at `T_s`; the `[lqr]` section's default
//!   weights), and the state is caught when every predicted sample keeps
//!   `|α_k| ≤ balance_angle − m` and both `|θ_k|` and the arm's stopping point braked at the
//!   bound within `arm_limit − m` (`m` = [`SwingUpSettings::catch_margin`]). It is the part
//!   of the LQR's region of attraction that respects the balance region, found by simulation
//!   instead of a level set, so an arm that is off centre or still turning is caught when the
//!   balance controller can stop it in time, and not otherwise. The prediction runs only on
//!   samples that meet the pendulum's conditions (a few per arrival) and allocates nothing.
//! - **Balance**: the balance controller runs on `[θ, wrap(α)]`. For
//!   [`SwingUpSettings::handover_time`] after the catch its estimator is restarted every
//!   sample, after it has computed its move, from the swing-up's estimate and that move
//!   ([`Controller::seed`]), so a Kalman filter does not have to follow the catch transient,
//!   which its linear model does not describe. Leaving the balance region
//!   is a fall: swing up again or stop ([`OnFall`]). The region ends at `|α| > balance_angle`
//!   and where the arm's stopping point, braked at the voltage bound
//!   ([`crate::envelope`]'s stopping point, one period of latency with the balance
//!   controller's last voltage acting, the whole deceleration (1) counted on), leaves `±arm_limit`, not only at `|θ| > arm_limit`: an arm that reaches the
//!   limit still moving cannot be stopped there, while one handed to the swing-up law with
//!   its stopping point inside is braked by the law's barrier (3), which asks for more than
//!   the voltage bound gives outside its own envelope, so it brakes at the bound.
//! - **Stopped** ([`StopCause`]): after [`SwingUpSettings::max_time`] in the swing-up, or a fall
//!   with [`OnFall::Stop`]. The output is 0 V from then on.
//!
//! Every step is allocation-free when the balance controller's is.

mod catch;
pub mod feasibility;
mod law;

mod settings;
pub mod stored;

pub use crate::swing_report::{SwingUpReport, STILL_ARM};
pub use crate::trig::wrap_angle;
pub use feasibility::{feasibility, Feasibility, Verdict};
pub use settings::{OnFall, SwingUpSettings, MAX_SWING_UP_TIME};
pub use stored::{feasibility_inputs, stored_or_computed, StoredFeasibility, VerdictSource};

use crate::controller::{Controller, Phase, StepStatus, StopCause};
use crate::envelope::StoppingModel;
use crate::error::{Result, RipError};
use crate::plant::Plant;

use catch::CatchPredictor;
use law::{EnergyLaw, RateEstimator, UnstableMode};

/// The swing-up supervisor around the balance controller `C` (module docs).
#[derive(Debug, Clone)]
pub struct SwingUp<C> {
    balance: C,
    settings: SwingUpSettings,
    law: EnergyLaw,
    mode: UnstableMode,
    /// The predicted catch, when `catch_prediction > 0`.
    predictor: Option<CatchPredictor>,
    /// How far the arm still travels when braked at the voltage bound: the balance region
    /// ends where that would take it beyond `arm_limit`.
    stopping: StoppingModel,
    ts: f64,
    rates: RateEstimator,
    phase: Phase,
    /// Samples spent in the current swing-up.
    swing_samples: u64,
    /// Samples since the catch (0 while swinging up).
    balance_samples: u64,
    /// The arm reference held since the catch, and the external one at the catch.
    hold_reference: Option<(f64, f64)>,
    /// The last voltage the swing-up applied.
    u_swing: [f64; 1],
    /// The last voltage the balance controller applied: it acts during the stop's latency.
    u_balance: f64,
    /// What the current swing-up has done so far.
    report: SwingUpReport,
}

impl<C: Controller> SwingUp<C> {
    /// The supervisor around `balance`, with the swing-up designed on `plant` (the nominal
    /// model of the rig; the simulated or real plant may differ). `balance` must have 2
    /// outputs, 1 input and a sample time.
    pub fn new(balance: C, plant: &Plant, settings: SwingUpSettings) -> Result<Self> {
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
        let mode = UnstableMode::new(plant, settings.max_voltage).ok_or_else(|| {
            RipError::invalid(
                "plant",
                "the nominal model has no real unstable mode about upright to catch",
            )
        })?;
        let mut out = Self {
            law: EnergyLaw::new(plant, &settings, ts),
            mode,
            predictor: CatchPredictor::new(plant, &settings, ts),
            stopping: StoppingModel::new(plant.params(), settings.max_voltage, 1.0, ts),
            rates: RateEstimator::new(ts, settings.rate_cutoff),
            balance,
            settings,
            ts,
            phase: Phase::SwingUp,
            swing_samples: 0,
            balance_samples: 0,
            hold_reference: None,
            u_swing: [0.0],
            u_balance: 0.0,
            report: SwingUpReport::start(0.0, 0.0, 0.0),
        };
        out.reset();
        Ok(out)
    }

    /// The settings.
    pub fn settings(&self) -> &SwingUpSettings {
        &self.settings
    }

    /// The balance controller.
    pub fn balance(&self) -> &C {
        &self.balance
    }

    /// Sample time (s), the balance controller's.
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// The swing-up's own estimate `[θ, θ̇, α, α̇]` (α wrapped).
    pub fn swing_estimate(&self) -> [f64; 4] {
        let x = self.rates.state();
        [x[0], x[1], x[2], x[3]]
    }

    /// The pendulum energy `E` (J, 0 upright at rest) of the swing-up's estimate.
    pub fn energy(&self) -> f64 {
        self.law.energy(self.rates.state())
    }

    /// What the current swing-up (or the last, once balancing or stopped) has done: peak
    /// energy against the target, the largest voltage asked for, the arm travel used.
    pub fn report(&self) -> SwingUpReport {
        self.report
    }

    fn start_report(&mut self) {
        let grav = self.law.gravity();
        self.report =
            SwingUpReport::start(self.law.target(0.0), -2.0 * grav, self.settings.arm_limit);
    }

    /// The braking deceleration `a_b` (rad/s²) the arm-limit envelope reserves.
    pub fn brake_deceleration(&self) -> f64 {
        self.law.brake()
    }

    fn in_catch_region(&self) -> bool {
        let x = self.rates.state();
        let s = &self.settings;
        let arm_stop = x[0] + x[1] * x[1].abs() / (2.0 * self.law.brake());
        let pendulum = x[2].abs() <= s.catch_angle
            && self.mode.load(x) <= s.catch_mode_fraction
            && (x[2] + x[3] * s.catch_lookahead).abs() <= s.catch_angle
            && x[3].abs() <= s.catch_rate;
        pendulum
            && match &self.predictor {
                Some(p) => p.recoverable(x, x[0]),
                None => x[1].abs() <= s.catch_arm_rate && arm_stop.abs() <= s.catch_arm_angle,
            }
    }

    fn in_balance_region(&self) -> bool {
        let x = self.rates.state();
        let limit = self.settings.arm_limit;
        let stop = self.stopping.stopping_point(x[0], x[1], self.u_balance);
        x[2].abs() <= self.settings.balance_angle && x[0].abs() <= limit && stop.abs() <= limit
    }

    /// One swing-up sample: the law's voltage, the balance estimator kept in step, the clock.
    fn swing(&mut self, y: &[f64], usable: bool, u: &mut [f64]) -> StepStatus {
        self.swing_samples += 1;
        if self.swing_samples as f64 * self.ts > self.settings.max_time {
            return self.stop(StopCause::SwingUpTimeout, u);
        }
        let x = *self.rates.state();
        let value = if self.rates.started() {
            self.law.voltage(&x, self.law.acceleration(&x))
        } else {
            0.0
        };
        self.u_swing[0] = value;
        u[0] = value;
        if self.rates.started() {
            self.report.record(self.law.energy(&x), x[0], x[2], value);
        }
        if !usable {
            self.balance.hold(&self.u_swing);
            return StepStatus::Fallback;
        }
        if x[2].abs() <= self.settings.estimator_window {
            let y_b = [y[0], wrap_angle(y[1])];
            self.balance.observe(&y_b, &self.u_swing);
        } else {
            let seed = [x[0], x[1], x[2], x[3]];
            self.balance.seed(&seed, &self.u_swing);
        }
        StepStatus::Nominal
    }

    fn stop(&mut self, cause: StopCause, u: &mut [f64]) -> StepStatus {
        self.phase = Phase::Stopped(cause);
        u[0] = 0.0;
        StepStatus::Nominal
    }

    fn balance_step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        let theta_ref = match self.hold_reference {
            Some((held, at_catch)) if r[0] == at_catch => {
                // Back to the external reference at a bounded rate (module docs, "Catch").
                let step = self.settings.reference_return_rate * self.ts;
                let next = held + (at_catch - held).clamp(-step, step);
                self.hold_reference = Some((next, at_catch));
                next
            }
            Some(_) => {
                self.hold_reference = None;
                r[0]
            }
            None => r[0],
        };
        let y_b = [y[0], wrap_angle(y[1])];
        let status = self.balance.step(&y_b, &[theta_ref, r[1]], u);
        self.u_balance = u[0];
        // The handover (module docs, "Balance"): the swing-up's estimate carries the balance
        // controller's estimator through the catch transient.
        self.balance_samples += 1;
        if (self.balance_samples as f64) * self.ts <= self.settings.handover_time {
            let x = self.rates.state();
            self.balance.seed(&[x[0], x[1], x[2], x[3]], &u[..1]);
        }
        status
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
        let usable = self.rates.update(y);
        match self.phase {
            Phase::Stopped(_) => {
                u[0] = 0.0;
                StepStatus::Nominal
            }
            Phase::SwingUp => {
                if usable && self.in_catch_region() {
                    self.phase = Phase::Balance;
                    self.balance_samples = 0;
                    self.u_balance = self.u_swing[0];
                    self.hold_reference = Some((self.rates.state()[0], r[0]));
                    self.balance_step(y, r, u)
                } else {
                    self.swing(y, usable, u)
                }
            }
            Phase::Balance => {
                if !usable || self.in_balance_region() {
                    return self.balance_step(y, r, u);
                }
                match self.settings.on_fall {
                    OnFall::Stop => self.stop(StopCause::LeftBalanceRegion, u),
                    OnFall::Retry => {
                        self.phase = Phase::SwingUp;
                        self.swing_samples = 0;
                        self.hold_reference = None;
                        self.start_report();
                        self.swing(y, usable, u)
                    }
                }
            }
        }
    }

    fn hold(&mut self, u: &[f64]) {
        self.rates.hold();
        if self.phase == Phase::SwingUp {
            self.swing_samples += 1;
        }
        self.balance.hold(u);
    }

    fn phase(&self) -> Phase {
        self.phase
    }

    fn reset(&mut self) {
        self.balance.reset();
        self.rates.reset();
        self.phase = Phase::SwingUp;
        self.swing_samples = 0;
        self.balance_samples = 0;
        self.hold_reference = None;
        self.u_swing = [0.0];
        self.u_balance = 0.0;
        self.start_report();
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        self.balance.state_estimate()
    }

    fn sample_time(&self) -> Option<f64> {
        Some(self.ts)
    }

    fn swing_up_report(&self) -> Option<SwingUpReport> {
        Some(self.report)
    }
}

#[cfg(test)]
mod tests;
