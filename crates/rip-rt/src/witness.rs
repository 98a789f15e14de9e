//! The witness: during every run the model checks that the rig moves as the applied voltage
//! must make it move, and stops a rig that does not (a motor lead swapped, an encoder
//! reversed or no longer counting, a wrong `device.arm_sign`) before it drives the arm away.
//!
//! # The observer
//!
//! The witness runs its own observer of the nonlinear plant of `[plant]` (the model the
//! controllers are designed on, valid through the swing-up and the balance alike, whatever the
//! controller): with the measured angles `y = (θ, α)` at step `k` and the voltage `u` the
//! device applied over the period before it,
//!
//! ```text
//! x̄[k]  = Φ(x̂[k−1], u[k−1], Ts)                       (RK4 over one period)
//! e[k]  = y[k] − (x̄_θ[k], x̄_α[k])                     (α wrapped)
//! x̂[k]  = x̄[k] + (ℓ_p e_θ, ℓ_v e_θ / Ts, ℓ_p e_α, ℓ_v e_α / Ts)
//! ```
//!
//! a per-joint α-β correction ([`GAIN_POSITION`], [`GAIN_RATE`]) on top of the model's
//! prediction. On a rig that matches the model the innovation `e` is measurement noise and
//! quantisation; on a rig that does not move as commanded it is the gap between the motion the
//! voltage must produce and the motion measured, every period, with the same sign.
//!
//! # The statistic
//!
//! Each joint's innovation, in units of its measurement's standard deviation
//! `σ_j = √(q_j²/12 + s_j² + (τ ω̂_j)² + δ_j²)` (`q_j` one encoder count, `s_j` the `[sensor]
//! noise_std`, `ω̂_j` the joint's predicted rate, τ = [`TIMING_S`] the uncertainty of the
//! sampling instant and of the command's arrival, and `δ_j` how far the prediction moves when
//! the command arrives at the sample or τ later than expected), feeds a two-sided CUSUM:
//!
//! ```text
//! g⁺[k] = max(0, g⁺[k−1] + e[k]/σ − κ)      g⁻[k] = max(0, g⁻[k−1] − e[k]/σ − κ)
//! ```
//!
//! (held, not updated, for a sample whose interval on the device's clock is off the period by
//! more than half of it: a skipped period, a device catching up), which stays near 0 under
//! zero-mean noise and grows by about `|e|/σ − κ` every period of a
//! persistent disagreement. The run stops ([`WitnessFault`]) when `max(g⁺, g⁻)` of the arm
//! exceeds [`ARM_THRESHOLD`] or the pendulum's [`PENDULUM_THRESHOLD`]. The drift κ and the
//! thresholds were chosen from measurement (docs/rip-rt.md, "The witness"): the largest
//! statistic of normal runs on both presets and on generated rigs, with a stated margin.
//!
//! # The sign statistic
//!
//! The CUSUM is normalised by the measurement's noise, not by how hard the voltage pushes the
//! arm: on a light arm with a strong motor, a reversed motor mid-swing moves the arm half a
//! radian in the 5–7 periods the CUSUM takes. So a second test asks the question the fault
//! poses, with the rig's own model: does the voltage move the arm the way it must? Each
//! period the model also predicts the same period with the voltage reversed (`x̄ʳ`); the
//! log-likelihood ratio of "reversed" against "as modelled" is
//!
//! ```text
//! λ[k] = (e² − eʳ²) / (2 σ²),   eʳ = θ − x̄ʳ_θ                 S[k] = max(0, S[k−1] + λ[k])
//! ```
//!
//! (`e` the arm's innovation, `σ` its standard deviation above). Where the voltage acts
//! linearly, `x̄ʳ_θ = x̄_θ − 2p` with `p = x̄_θ − x̄⁰_θ` the voltage's share of the predicted
//! motion (`x̄⁰` the period at 0 V) and `λ = −2 p (e + p) / σ²`; across a dead zone or the
//! arm's Coulomb friction it does not, and the reversed period is predicted as such. It
//! scales with the rig: a
//! period in which the voltage pushes the arm by `p ≫ σ` adds about `2 p²/σ²` under a
//! reversal; on a rig whose voltage acts with gain `g` relative to the model (the arm
//! measured near `x̄_θ − (1 − g) p`) it is `−2 g p²/σ²` on average, negative for every
//! positive gain (a weaker motor, a wrong scale) and 0 only for none. The run stops when `S`
//! exceeds [`SIGN_THRESHOLD`]. What stopped it is named from the response itself: over the
//! periods since `S` left 0, the regression of the measured change of the arm's mean rate
//! (beyond the model's at 0 V) on the voltage's share of it ([`Witness::response_gain`]); a
//! gain nearer −1 than 0, or below 0 by more than [`REVERSED_SIGMAS`] standard errors, over
//! those periods or over those after the first (whose change of the mean rate reaches back
//! into the interval before `S` left 0, which may or may not lie in the fault), is a
//! reversed motor or arm encoder ([`WitnessFault::ArmWrongWay`], which
//! the stop brakes with the opposite sign), anything else is named as by the CUSUM; a reading
//! that stopped changing when the disagreement began is a dead encoder.
//!
//! # The reversed observers
//!
//! The observer runs twice more, each on the model of one wiring that reverses the arm's
//! response, and the run stops as a reversal when either follows the readings better than
//! the observer as wired by [`REVERSAL_THRESHOLD`] ([`Reversal`] has the statistic).
//!
//! # Friction
//!
//! Near rest the arm's Coulomb friction (and its breakaway torque, `plant.arm_breakaway`)
//! flips sign within `v_c` ([`rip_core::plant::COULOMB_VELOCITY_SCALE`]) of zero speed, and
//! the observer knows the arm's rate only to within `δv = ℓ_v (q₀ + 2 s₀) / T_s` (one count
//! and twice the noise through its rate gain). So the predicted arm position hangs on a sign
//! the observer cannot know, by up to
//!
//! ```text
//! δ_f = ½ (tanh((|θ̇̂| + δv)/v_c) − tanh((|θ̇̂| − δv)/v_c)) · (2 c_s / J_min) · T_s² / 2
//! ```
//!
//! (`c_s` the friction's largest torque, `J_min` the arm's least effective inertia), which
//! enters the arm's `σ²` as `δ_f²`. A balance that holds the arm in stick-slip, its voltage
//! hovering just beyond a dead zone (generated rig 5: 0.53 V dead zone, 4.7 mN m of
//! friction, 1.8 mrad of noise), took the sign statistic to 25.06 after 15 s without it (a
//! false stop), 23.9 with it; the rest is a closed-loop correlation between the observer's
//! carried noise and the controller's reaction to it, which is open (docs/rip-rt.md).
//!
//! # An encoder that stopped counting
//!
//! While the arm balances slowly, an arm encoder that stops counting leaves innovations too
//! small for the CUSUM: the observer follows the constant reading. So a second, free-running
//! copy of the model's arm (its pendulum taken from the observer every period) starts from the
//! observer's state at each change of the arm reading and runs on the applied voltage alone;
//! when the reading has stayed constant while this free arm has moved more than
//! `max(FROZEN_RAD, FROZEN_COUNTS counts)` ([`FROZEN_RAD`], [`FROZEN_COUNTS`]) from it, the
//! run stops ([`WitnessFault::ArmFrozen`]).
//!
//! # What the stop says
//!
//! At a trip the witness compares the arm's motion the model predicted with the motion
//! measured since the disagreement began (the statistic last at 0): a reading that did not
//! change since then (or for [`FROZEN_PERIODS`]) while the model predicted motion is an arm encoder that
//! stopped counting ([`WitnessFault::ArmFrozen`]); a measured motion against the predicted one
//! is a reversed motor lead, a reversed arm encoder or `device.arm_sign`
//! ([`WitnessFault::ArmWrongWay`]); anything else is named with every likely cause
//! ([`WitnessFault::ArmDisagrees`]).
//!
//! # Timing
//!
//! The model predicts each period from the device's sampling instants (its clock) and the
//! command's arrival, `delay` after the sample: the loop passes the time from the sample
//! request to the command's write on the host's clock (0 in lockstep, where the device's
//! plant waits for the host). A period whose timing the loop cannot vouch for — a late
//! wake-up, a skipped deadline, a slow reply, a command sent late: a machine under load
//! delays the device (an emulator catching up on its own clock applies commands late) as
//! much as the loop — is reported with [`Witness::timing_unknown`]: the observer takes the
//! arrival within the interval that best fits both angles, and the statistics are held for
//! that period and the [`HELD_AFTER_UNKNOWN`] after it, so that a late period is no evidence
//! of a fault (docs/rip-rt.md, "The witness").
//!
//! The fit leaves the observer up to half the spread between the two arrivals off, in
//! position and rate, and its correction takes that out only at its gains: the pendulum's
//! `σ²` carries that error, `c_p[k] = (1 − ℓ_p)(c_p[k−1] + c_v[k−1] T_s)`,
//! `c_v[k] = (1 − ℓ_v) c_v[k−1]`, as `(c_p + c_v T_s)²` on each prediction. A catch whose
//! controller reverses the full voltage every period, with late commands in it, otherwise
//! left the pendulum's rate 1–2 rad/s off the observer's for ten periods, past the holds,
//! and its statistic at 32 against 30 (generated rig 5, MPC). The arm's statistics do not
//! take it: they are the ones that must stop a wiring fault within half a radian on a loaded
//! machine, and the holds cover them (measured).
//!
//! A restart after a gap of more than 0.5 s on the device's clock takes the rates from the
//! first two readings rather than assuming rest, and holds the statistics for that period and
//! the [`HELD_AFTER_UNKNOWN`] after it, so that a gap is never evidence of a fault
//! ([`Witness::observe`]); the start of a run or a phase still starts at rest.
//!
//! Everything is allocation-free per step: the plant's RK4 on stack vectors and a few scalars.

use rip_core::plant::{Plant, State};
use rip_core::swingup::wrap_angle;

use crate::config::Config;

mod fault;
mod limits;
mod response;
mod reversal;
pub use fault::WitnessFault;
pub use limits::{WitnessLimits, LOWERING_THRESHOLD_FACTOR};
use response::Response;
use reversal::Reversals;
pub use reversal::{Reversal, REVERSAL_MODEL_ERROR};

/// Position gain ℓ_p of the observer's correction (module docs).
pub const GAIN_POSITION: f64 = 0.5;
/// Rate gain ℓ_v of the observer's correction (module docs).
pub const GAIN_RATE: f64 = 0.1;
/// Uncertainty (s) of when a measurement is taken and a command applied, relative to the
/// loop's grid: wake-up jitter, the reply's latency, the command's delay. A joint moving at
/// rate ω reads up to `ω τ` off the model's sample instant.
pub const TIMING_S: f64 = 1e-3;
/// A period's wake-up lateness, reply time (request to reply) or command delay (request to
/// command) beyond which the loop reports its timing unknown ([`Witness::timing_unknown`]):
/// twice [`TIMING_S`].
pub const LATE_S: f64 = 2.0 * TIMING_S;
/// Periods after one of unknown timing whose statistics are held too: a command that
/// arrived late acts into the next interval, and the observer takes a few periods to settle
/// on the rates it left.
pub const HELD_AFTER_UNKNOWN: u32 = 2;
/// Whether the command may have arrived anywhere in the interval between two samples: a
/// device that does not run in real time (an emulator starved of the CPU catches up on its
/// own clock before it reads the serial line) applies it late without any sign on the host.
pub const ARRIVAL_ANYWHERE: bool = false;
/// CUSUM drift κ (in σ): innovations below it, per period, do not accumulate.
pub const DRIFT: f64 = 3.0;
/// Arm statistic (in σ) at which the run stops.
pub const ARM_THRESHOLD: f64 = 40.0;
/// Pendulum statistic (in σ) at which the run stops.
pub const PENDULUM_THRESHOLD: f64 = 30.0;
/// Arm motion (rad) that the free-running arm model may predict while the arm reading stays
/// constant before the run stops as a frozen arm encoder (at least [`FROZEN_COUNTS`] counts).
pub const FROZEN_RAD: f64 = 0.05;
/// The least arm motion, in encoder counts, of the frozen-encoder rule.
pub const FROZEN_COUNTS: f64 = 8.0;
/// Periods the arm reading must stay constant before a trip is named a frozen encoder.
pub const FROZEN_PERIODS: u32 = 2;
/// Standard errors by which the arm's response gain must lie below 0 for a trip to be named
/// a reversal ([`WitnessFault::ArmWrongWay`]); nearer 0 it is a disagreement, which the stop
/// brakes with the model's sign, checked on the arm's response.
pub const REVERSED_SIGMAS: f64 = 2.0;

/// Threshold of the sign statistic (a log-likelihood ratio, module docs): the run stops as
/// a reversed motor or arm encoder when it exceeds this.
pub const SIGN_THRESHOLD: f64 = 25.0;
/// Threshold of the reversed observers' statistic (a log-likelihood ratio, module docs, "The
/// reversed observers"): the run stops as a reversed motor or arm encoder when either
/// exceeds this.
pub const REVERSAL_THRESHOLD: f64 = 25.0;
/// The evidence of a reversal ([`Witness::reversal_evidence`], a log-likelihood ratio: odds
/// of about 150 to 1) from which a trip on another statistic is stopped as a reversal.
pub const REVERSAL_EVIDENCE: f64 = 5.0;

/// The witness of one run (module docs).
#[derive(Debug, Clone)]
pub struct Witness {
    plant: Plant,
    substeps: usize,
    ts: f64,
    limits: WitnessLimits,
    sigma: [f64; 2],
    arm_count: f64,
    // The full swing of the arm's friction acceleration, 2 c_s / J_min (rad/s²), and the
    // rate uncertainty δv (rad/s) it is weighed at (module docs, "Friction").
    friction_swing: f64,
    rate_uncertainty: f64,
    x: Option<State>,
    // Whether the observer was started on the last reading alone, its rates not yet known
    // (the next reading gives them: [`Witness::acquire_rates`]).
    acquiring: bool,
    cusum: [[f64; 2]; 2],
    // Predicted and measured arm increments, and periods, since the arm statistic left 0.
    predicted: f64,
    measured: f64,
    disagreeing: u32,
    last_theta: f64,
    // Periods since the arm reading last changed, and the model's arm motion meanwhile.
    unchanged: u32,
    predicted_unchanged: f64,
    // The free-running arm (module docs) and how far the frozen rule lets it go (rad).
    free: State,
    frozen_rad: f64,
    // The sign statistic, and since it last left 0: the arm motion the voltage must have
    // added to the model's motion at 0 V, and the measured motion relative to the latter.
    sign: f64,
    sign_expected: [f64; 2],
    sign_response: [f64; 2],
    sign_periods: u32,
    // Whether the last period's command arrival was unknown; whether the loop reported the
    // timing of the coming observation unknown ([`Witness::timing_unknown`]), and of the
    // last one.
    arrival_unknown: bool,
    unknown_next: bool,
    unknown_left: u32,
    // Per joint, how far off (position rad, rate rad/s) the observer may still be from a
    // period of unknown timing (module docs, "Timing").
    carried: [[f64; 2]; 2],
    // The weighted sums of the regression of the response on the voltage's part: over the
    // samples since the sign statistic left 0, and over those of them whose earlier interval
    // lies inside that window too (the statistic above 0 after the period before); whether
    // it stood above 0 after the last period.
    response: [f64; 2],
    response_inside: [f64; 2],
    sign_was_open: bool,
    // The last two arm readings (newest first), the interval between them, and the model's
    // change of the arm rate over the last period: in all, and the voltage's part of it.
    // `history` counts the consecutive on-time samples behind them.
    readings: [f64; 2],
    interval: f64,
    rate_change: [f64; 2],
    last_switch: f64,
    history: u32,
    peak: [f64; 4],
    // The reversed observers (module docs, "The reversed observers").
    reversals: Reversals,
}

impl Witness {
    /// The witness for `cfg` (assumed valid): its `[plant]`, `[sensor]`, `[device]` and period,
    /// with `limits`.
    pub fn new(cfg: &Config, limits: WitnessLimits) -> Result<Self, String> {
        let plant = cfg.spec.plant().map_err(|e| e.to_string())?;
        let ts = cfg.period_s();
        let substeps = (ts / plant.max_rk4_substep()).ceil().clamp(1.0, 1000.0) as usize;
        let arm_count = std::f64::consts::TAU / f64::from(cfg.device.arm_counts_per_rev);
        let s = cfg.spec.sensor.noise_std;
        let p = cfg.spec.plant.params();
        let j_min = p.lumped().arm_min();
        let breakaway = cfg.spec.plant.arm_breakaway.unwrap_or(0.0).max(p.cr);
        let sigma = cfg.reading_sigma();
        Ok(Self {
            plant,
            substeps,
            ts,
            limits,
            sigma,
            arm_count,
            friction_swing: 2.0 * breakaway / j_min,
            rate_uncertainty: GAIN_RATE * (arm_count + 2.0 * s[0]) / ts,
            x: None,
            acquiring: false,
            cusum: [[0.0; 2]; 2],
            predicted: 0.0,
            measured: 0.0,
            disagreeing: 0,
            last_theta: 0.0,
            unchanged: 0,
            predicted_unchanged: 0.0,
            free: State::zeros(),
            frozen_rad: FROZEN_RAD.max(FROZEN_COUNTS * arm_count),
            sign: 0.0,
            sign_expected: [0.0; 2],
            sign_response: [0.0; 2],
            sign_periods: 0,
            response: [0.0; 2],
            response_inside: [0.0; 2],
            sign_was_open: false,
            arrival_unknown: false,
            unknown_next: false,
            unknown_left: 0,
            carried: [[0.0; 2]; 2],
            readings: [0.0; 2],
            interval: 0.0,
            rate_change: [0.0; 2],
            last_switch: 0.0,
            history: 0,
            peak: [0.0; 4],
            reversals: Reversals::default(),
        })
    }

    /// Its thresholds from now on (the statistics so far are kept).
    pub fn set_limits(&mut self, limits: WitnessLimits) {
        self.limits = limits;
    }

    /// Its thresholds.
    pub fn limits(&self) -> WitnessLimits {
        self.limits
    }

    /// Forgets the state: the next [`observe`](Self::observe) starts the observer afresh at
    /// rest where it measures (the largest statistics so far are kept).
    pub fn reset(&mut self) {
        self.x = None;
        self.acquiring = false;
        self.cusum = [[0.0; 2]; 2];
        self.predicted = 0.0;
        self.measured = 0.0;
        self.disagreeing = 0;
        self.unchanged = 0;
        self.predicted_unchanged = 0.0;
        self.sign = 0.0;
        self.sign_expected = [0.0; 2];
        self.sign_response = [0.0; 2];
        self.sign_periods = 0;
        self.response = [0.0; 2];
        self.response_inside = [0.0; 2];
        self.sign_was_open = false;
        self.history = 0;
        self.unknown_next = false;
        self.unknown_left = 0;
        self.carried = [[0.0; 2]; 2];
        self.reversals.reset();
    }

    /// The largest statistics since construction: the arm's and the pendulum's CUSUM (σ), the
    /// free arm's distance from a constant arm reading (in units of the frozen rule's limit:
    /// 1 trips), the sign statistic and the reversed observers' (log-likelihood ratios).
    pub fn peak(&self) -> [f64; 5] {
        let [arm, pendulum, frozen, sign] = self.peak;
        [arm, pendulum, frozen, sign, self.reversals.peak()]
    }

    /// The model's estimate of the rig's state now: the free-running arm's while the arm
    /// reading has not changed (an encoder that may have stopped counting), else the
    /// observer's; `None` before the first measurement.
    pub fn estimate(&self) -> Option<State> {
        let x = self.x?;
        Some(if self.unchanged > 0 { self.free } else { x })
    }

    /// The current sign statistic (a log-likelihood ratio, module docs).
    pub fn sign_statistic(&self) -> f64 {
        self.sign
    }

    /// The reversed observers' larger statistic (a log-likelihood ratio, module docs, "The
    /// reversed observers") and the wiring it favours.
    pub fn reversal_statistic(&self) -> (f64, Reversal) {
        self.reversals.statistic()
    }

    /// The current arm and pendulum statistics (σ).
    pub fn statistic(&self) -> [f64; 2] {
        [
            self.cusum[0][0].max(self.cusum[0][1]),
            self.cusum[1][0].max(self.cusum[1][1]),
        ]
    }

    /// Reports the timing of the next observation unknown: the loop woke late, skipped a
    /// deadline, waited long for the reply or sent the command late, so that neither the
    /// sampling instant nor the command's arrival at the device is known to [`TIMING_S`]
    /// (module docs, "Timing"). Its statistics are held for that period and the next.
    pub fn timing_unknown(&mut self) {
        self.unknown_next = true;
    }

    /// Advances `x` by `dt` seconds: `before` (V) for the first `delay` of them, then `after`.
    fn predict(&self, x: &mut State, (before, after): (f64, f64), dt: f64, delay: f64) {
        let delay = delay.clamp(0.0, dt);
        let n = |span: f64| ((span / self.ts) * self.substeps as f64).ceil().max(1.0) as usize;
        if delay > 0.0 {
            self.plant.advance(x, before, 0.0, delay, n(delay));
        }
        if dt > delay {
            self.plant.advance(x, after, 0.0, dt - delay, n(dt - delay));
        }
    }

    /// Takes the measured arm angle `theta` and pendulum angle `alpha` (rad, 0 upright), `dt`
    /// seconds after the previous measurement (on the device's clock), over which the device
    /// applied `volts.0` (V) until the command `volts.1` (V) arrived `delay` seconds in; an
    /// error names the likely fault. A `dt` outside (0, 0.5] s restarts the observer here.
    pub fn observe(
        &mut self,
        theta: f64,
        alpha: f64,
        volts: (f64, f64),
        dt: f64,
        delay: f64,
    ) -> Result<(), WitnessFault> {
        // A rig seen again after a gap is moving as it was; at the start of a run or a phase
        // it is at rest (or held) where it measures, and its rates are taken as 0 as before:
        // two readings of a rig at rest give nothing better, and a wrong-scale fault from
        // power-up was then named a reversal (measured, witness_sim).
        let gap = dt > 0.5;
        if !(dt > 0.0 && dt <= 0.5) {
            self.reset();
        }
        let Some(mut x) = self.x else {
            let x = State::new(theta, 0.0, alpha, 0.0);
            self.x = Some(x);
            self.free = x;
            self.last_theta = theta;
            self.acquiring = gap;
            return Ok(());
        };
        if std::mem::take(&mut self.acquiring) {
            self.acquire_rates(x, theta, alpha, volts, dt, delay);
            return Ok(());
        }
        let start = x[0];
        // The same period with the command arriving at the sample and TIMING_S after the
        // expected delay: how much the prediction hangs on when the voltage changed. A period
        // the loop could not time, or a skipped one, leaves the arrival unknown within the
        // whole interval (module docs, "Timing").
        let unknown = std::mem::take(&mut self.unknown_next);
        let latest = if ARRIVAL_ANYWHERE || unknown || dt > 1.5 * self.ts {
            dt
        } else {
            delay + TIMING_S
        };
        let (mut early, mut late) = (x, x);
        self.predict(&mut early, volts, dt, 0.0);
        self.predict(&mut late, volts, dt, latest);
        self.predict(&mut x, volts, dt, delay);
        if unknown {
            if let Some(fitted) = self.fit_arrival(&early, &late, theta, alpha) {
                x = fitted;
            }
        }
        // The same period at 0 V: what the voltage adds to the arm's motion, by the model.
        let mut coast = self.x.unwrap_or(x);
        self.predict(&mut coast, (0.0, 0.0), dt, delay);
        let prior = self.x.unwrap_or(x);
        let rate_change = [x[1] - prior[1], x[1] - coast[1]];
        // The same period with the voltage reversed: the hypothesis the sign statistic tests.
        let mut reversed = prior;
        self.predict(&mut reversed, (-volts.0, -volts.1), dt, delay);
        // For the sign statistic, the command may have arrived anywhere in the interval: a
        // late command at a reversal of the voltage leaves the arm on the old voltage's side,
        // which no number of such periods may add up to a reversal (a device starved of the
        // CPU applies commands milliseconds late without a sign on the host).
        let arrival_unknown = latest >= dt;
        let anywhere = if latest < dt {
            let mut last = prior;
            self.predict(&mut last, volts, dt, dt);
            (last[0] - x[0]).abs().max((early[0] - x[0]).abs())
        } else {
            0.0
        };
        let switch = [
            (late[0] - x[0]).abs().max((early[0] - x[0]).abs()),
            (late[2] - x[2]).abs().max((early[2] - x[2]).abs()),
        ];
        let mut free = self.free;
        self.predict(&mut free, volts, dt, delay);
        self.free = free;
        let e = [theta - x[0], wrap_angle(alpha - x[2])];
        let rate = [x[1], x[3]];
        let step = x[0] - start;
        let moved = theta - self.last_theta;
        self.last_theta = theta;
        x[0] += GAIN_POSITION * e[0];
        x[1] += GAIN_RATE * e[0] / self.ts;
        x[2] = wrap_angle(x[2] + GAIN_POSITION * e[1]);
        x[3] += GAIN_RATE * e[1] / self.ts;
        if moved.abs() < 0.5 * self.arm_count {
            self.unchanged = self.unchanged.saturating_add(1);
            self.predicted_unchanged += step;
            self.free[2] = x[2];
            self.free[3] = x[3];
        } else {
            self.unchanged = 0;
            self.predicted_unchanged = 0.0;
            self.free = x;
        }
        self.x = Some(x);
        // An interval off the grid (a skipped period, a device catching up on its clock)
        // leaves the innovation unreliable: the observer takes it, the statistic does not.
        // So does a period whose timing the loop reported unknown, and the
        // HELD_AFTER_UNKNOWN after it.
        let held = unknown || self.unknown_left > 0;
        self.unknown_left = if unknown {
            HELD_AFTER_UNKNOWN
        } else {
            self.unknown_left.saturating_sub(1)
        };
        let on_time = dt >= 0.5 * self.ts && dt <= 1.5 * self.ts && !held;
        let friction = self.friction_uncertainty(prior[1], dt);
        let carried = self.carry_error(dt, unknown.then_some((&early, &late)));
        // The arm's statistics leave it out: they are what stops a wiring fault within half a
        // radian on a loaded machine, and the holds above already cover them (measured,
        // docs/rip-rt.md); the pendulum's, which a chattering catch with a late command in
        // it drove past its threshold, take it in.
        self.accumulate(e, rate, switch, [friction, carried[1]], on_time);
        let sign_var = self.sign_variance(rate[0], switch[0].max(anywhere), friction);
        // Held (not updated) for a period whose command's arrival is unknown (a slow
        // exchange, a skipped period) and for the one after it: a command that arrived late,
        // even after the interval, leaves the arm on the old voltage's side.
        let counted = on_time && !(arrival_unknown || self.arrival_unknown);
        if on_time {
            // The log-likelihood ratio of "the voltage acts reversed" (the arm measured at
            // the 0 V motion less the voltage's part) against "as modelled".
            let e_reversed = theta - reversed[0];
            let llr = (e[0] * e[0] - e_reversed * e_reversed) / (2.0 * sign_var);
            if counted {
                self.sign = (self.sign + llr).max(0.0);
            }
            self.peak[3] = self.peak[3].max(self.sign);
        }
        self.observe_reversals(
            &prior,
            (theta, alpha),
            volts,
            (dt, delay),
            (e[0], sign_var),
            (counted, unknown),
        );
        self.arrival_unknown = arrival_unknown;
        self.response_test(theta, dt, rate_change, switch[0], on_time);
        if self.cusum[0] == [0.0, 0.0] {
            self.predicted = 0.0;
            self.measured = 0.0;
            self.disagreeing = 0;
        } else {
            self.predicted += step;
            self.measured += moved;
            self.disagreeing += 1;
        }
        self.judge(theta)
    }

    /// The observer's rates after a restart, from the first two readings (`start`, then
    /// `theta`, `alpha` `dt` later under `volts`): the mean rates over the interval plus half
    /// the model's change of rate over it (the rates at its end, for a constant acceleration).
    /// A restart at rest where it measured took a moving rig's rates as 0, and the first
    /// periods' innovations (the rig's whole motion) as evidence: 49 σ on the arm after a
    /// 0.6 s gap mid-swing. The statistics are held for [`HELD_AFTER_UNKNOWN`] periods more,
    /// while the correction settles on what the two readings left of the noise.
    fn acquire_rates(
        &mut self,
        start: State,
        theta: f64,
        alpha: f64,
        volts: (f64, f64),
        dt: f64,
        delay: f64,
    ) {
        let mean = [(theta - start[0]) / dt, wrap_angle(alpha - start[2]) / dt];
        let mut ahead = State::new(start[0], mean[0], start[2], mean[1]);
        self.predict(&mut ahead, volts, dt, delay);
        let x = State::new(
            theta,
            mean[0] + 0.5 * (ahead[1] - mean[0]),
            alpha,
            mean[1] + 0.5 * (ahead[3] - mean[1]),
        );
        self.x = Some(x);
        self.reversals.restart();
        self.free = x;
        self.last_theta = theta;
        self.unchanged = 0;
        self.predicted_unchanged = 0.0;
        self.history = 0;
        self.unknown_left = HELD_AFTER_UNKNOWN;
    }

    /// The arrival the measurements show, for a period of unknown timing: the point between
    /// the command at the sample (`early`) and at the next one (`late`) that fits both angles
    /// best in units of their noise, so that the observer leaves the period with the rates
    /// the late command gave the rig. `None` when the two predictions coincide.
    fn fit_arrival(&self, early: &State, late: &State, theta: f64, alpha: f64) -> Option<State> {
        let d = [
            (late[0] - early[0]) / self.sigma[0],
            wrap_angle(late[2] - early[2]) / self.sigma[1],
        ];
        let m = [
            (theta - early[0]) / self.sigma[0],
            wrap_angle(alpha - early[2]) / self.sigma[1],
        ];
        let norm = d[0] * d[0] + d[1] * d[1];
        (norm > 0.0).then(|| {
            let f = ((m[0] * d[0] + m[1] * d[1]) / norm).clamp(0.0, 1.0);
            *early + (*late - *early) * f
        })
    }

    /// The observer's error carried from a period of unknown timing into this prediction
    /// (returned, per joint), advanced by what the correction leaves of it; `fitted`, the
    /// bounds of a new unknown period's arrival, adds its spread.
    fn carry_error(&mut self, dt: f64, fitted: Option<(&State, &State)>) -> [f64; 2] {
        let carried: [f64; 2] =
            std::array::from_fn(|j| self.carried[j][0] + self.carried[j][1] * dt);
        for j in 0..2 {
            self.carried[j] = [
                (1.0 - GAIN_POSITION) * carried[j],
                (1.0 - GAIN_RATE) * self.carried[j][1],
            ];
            if let Some((early, late)) = fitted {
                // The fit chose the arrival within the interval: at most half of it either
                // side of the truth is left.
                let spread = [
                    0.5 * (late[2 * j] - early[2 * j]).abs(),
                    0.5 * (late[2 * j + 1] - early[2 * j + 1]).abs(),
                ];
                self.carried[j][0] = self.carried[j][0].max(spread[0]);
                self.carried[j][1] = self.carried[j][1].max(spread[1]);
            }
        }
        carried
    }

    /// One period's CUSUM update of the arm's and the pendulum's statistics from the
    /// innovations `e`, normalised by the spread of the noise, the sampling instant
    /// (`rate`), the command's arrival (`switch`) and the model (`model`); held while the
    /// period is not `on_time`.
    fn accumulate(
        &mut self,
        e: [f64; 2],
        rate: [f64; 2],
        switch: [f64; 2],
        model: [f64; 2],
        on_time: bool,
    ) {
        let k = self.limits.drift;
        for j in 0..2 {
            let timing = TIMING_S * rate[j];
            let var = self.sigma[j] * self.sigma[j]
                + timing * timing
                + switch[j] * switch[j]
                + model[j] * model[j];
            let z = e[j] / var.sqrt();
            let g = &mut self.cusum[j];
            if on_time {
                g[0] = (g[0] + z - k).max(0.0);
                g[1] = (g[1] - z - k).max(0.0);
            }
            self.peak[j] = self.peak[j].max(g[0].max(g[1]));
        }
    }

    /// The verdict on the statistics after the measurement `theta` (rad): the first limit
    /// passed names the likely fault (module docs).
    fn judge(&mut self, theta: f64) -> Result<(), WitnessFault> {
        let frozen = if self.unchanged >= FROZEN_PERIODS {
            (self.free[0] - theta).abs() / self.frozen_rad
        } else {
            0.0
        };
        self.peak[2] = self.peak[2].max(frozen);
        if frozen > 1.0 {
            return Err(self.frozen_fault(theta));
        }
        // A reading that stopped changing when the disagreement began: a dead encoder (its
        // constant reading against a moving model looks like any wrong response). The
        // reversed observers need no such rule: a constant reading fits a reversed wiring no
        // better than the wired one, and the frozen rule above names it.
        if self.sign > self.limits.sign
            && self.unchanged >= FROZEN_PERIODS.max(self.sign_periods.min(2 * FROZEN_PERIODS))
        {
            return Err(self.frozen_fault(theta));
        }
        let (reversal, _) = self.reversals.statistic();
        if reversal > self.limits.reversal {
            return Err(self.reversal_fault(theta, reversal));
        }
        if self.sign > self.limits.sign {
            // Reversed only when the response itself has the wrong sign: a wrong scale or a
            // weak motor also leaves the arm short of the model's motion.
            if !self.response_reversed() {
                return Err(self.classify(theta, self.sign, self.limits.sign));
            }
            return Err(WitnessFault::ArmWrongWay {
                measured: self.sign_response[1],
                predicted: self.sign_expected[1],
                window_s: f64::from(self.sign_periods) * self.ts,
                stat: self.sign,
                limit: self.limits.sign,
            });
        }
        let [arm, pendulum] = self.statistic();
        if arm > self.limits.arm {
            return Err(self.classify(theta, arm, self.limits.arm));
        }
        if pendulum > self.limits.pendulum {
            return Err(WitnessFault::PendulumDisagrees {
                stat: pendulum,
                limit: self.limits.pendulum,
                reversal: self.reversal_evidence(),
            });
        }
        Ok(())
    }

    /// How far (rad) the arm's predicted position over `dt` hangs on the sign of its friction
    /// (module docs, "Friction"), the observer's arm rate `rate` known to within δv.
    fn friction_uncertainty(&self, rate: f64, dt: f64) -> f64 {
        if self.friction_swing == 0.0 {
            return 0.0;
        }
        let vc = rip_core::plant::COULOMB_VELOCITY_SCALE;
        let (v, dv) = (rate.abs(), self.rate_uncertainty);
        let share = 0.5 * (((v + dv) / vc).tanh() - ((v - dv) / vc).tanh());
        share * self.friction_swing * 0.5 * dt * dt
    }

    /// The arm's response to the voltage since the sign statistic left 0 (module docs), with
    /// the arm reading `theta`, `dt` after the last, the model's change of the arm rate over
    /// the period (in all, and the voltage's part) and how far the command's timing moves the
    /// prediction (`switch`, rad).
    fn response_test(
        &mut self,
        theta: f64,
        dt: f64,
        rate_change: [f64; 2],
        switch: f64,
        on_time: bool,
    ) {
        if !on_time {
            self.history = 0;
        }
        if self.sign == 0.0 {
            self.sign_expected = [0.0; 2];
            self.sign_response = [0.0; 2];
            self.response = [0.0; 2];
            self.response_inside = [0.0; 2];
            self.sign_periods = 0;
        }
        if self.history >= 2 {
            let h1 = self.interval;
            let [t1, t2] = self.readings;
            // The measured change of the mean rate between the last two intervals, and the
            // model's: half the rate changes of the two periods (a piecewise constant
            // acceleration), of which the voltage's part is `push`.
            let measured = (theta - t1) / dt - (t1 - t2) / h1;
            let model = 0.5 * (rate_change[0] + self.rate_change[0]);
            let push = 0.5 * (rate_change[1] + self.rate_change[1]);
            let s2 = self.sigma[0] * self.sigma[0];
            let var = s2 * (1.0 / (dt * dt) + (1.0 / dt + 1.0 / h1).powi(2) + 1.0 / (h1 * h1))
                + (switch / dt).powi(2)
                + (self.last_switch / h1).powi(2);
            // What the measured change beyond the model's at 0 V says of the voltage's gain:
            // the weighted regression of the one on the other.
            let beyond = measured - (model - push);
            let sample = Response {
                push,
                beyond,
                var,
                dt,
            };
            self.reversals.respond(&sample);
            if self.sign > 0.0 {
                sample.regress(&mut self.response);
                // The sample spans this interval and the one before: inside the window only
                // where the statistic already stood above 0 after the period before.
                if self.sign_was_open {
                    sample.regress(&mut self.response_inside);
                }
                sample.displace(&mut self.sign_expected, &mut self.sign_response);
                self.sign_periods += 1;
            }
        }
        self.sign_was_open = self.sign > 0.0;
        self.readings = [theta, self.readings[0]];
        self.interval = dt;
        self.rate_change = rate_change;
        self.last_switch = switch;
        self.history = self.history.saturating_add(1);
    }
}

#[cfg(test)]
mod tests;
