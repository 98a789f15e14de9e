//! The arm's stop at run time: one rule for `rip-rt`, the emulator's device, the firmware and
//! the simulations of stops. `no_std`, without `alloc`, generic over [`Real`]; rip-core
//! designs what it needs from a plant (its `envelope` module: the stopping model, the laws'
//! gains, the lowering's weights) and `rip-rt` does the I/O, the loop's timing and the exit
//! codes.
//!
//! # Stopping distance
//!
//! Braked against its motion with `u = −U sgn θ̇`, the arm decelerates as
//!
//! ```text
//! J ω̇ = −f (b U + c ω),    ω = |θ̇| > 0,   b = k_t / R_m,   c = d_r + k_t k_m / R_m        (1)
//! ```
//!
//! (the motor's torque at `−U`, its back-EMF and the viscous friction all oppose the motion).
//! `J = J₀ + J_α` is the largest inertia the arm presents (the pendulum horizontal), and
//! `f ≤ 1` the share of that deceleration counted on: the rest is kept for the pendulum's
//! reaction on the arm, for dead zone and for the difference between the model and the rig.
//! With `a₀ = f b U / J` and `k = f c / J`, (1) stops the arm after
//!
//! ```text
//! d(ω) = ω / k − (a₀ / k²) ln(1 + k ω / a₀)        (→ ω² / (2 a₀) as k → 0)           (2)
//! ```
//!
//! The state a stop starts from was measured up to `τ` earlier (the loop's latency), during
//! which the voltage already applied, `u_a`, still acts: along the motion it accelerates the
//! arm by at most `a_l = b u_a⁺ / J_min` (`J_min = J₀ − m₁₂² / J_α`, the least effective
//! inertia). The stopping distance from speed `ω` is therefore
//!
//! ```text
//! D(ω, u_a) = ω τ + ½ a_l τ² + d(ω + a_l τ)                                                 (3)
//! ```
//!
//! and the stopping point `θ + sgn(θ̇) D(|θ̇|, u_a)` ([`StoppingModel`]).
//!
//! # The envelope ([`ArmEnvelope`])
//!
//! Every period the arm's rate is the difference of its last two angles over the device's
//! clock between them ([`sample_rates`]). Where the stopping point (3) is past the bound
//! (`safety.arm_limit` less a margin), the stop is simulated from the whole state
//! ([`SimulatedStop`]: the pendulum's reaction on the arm from the smooth model, not a share
//! of the torque reserved for it), and the run stops in the period the simulated stopping
//! point is past the bound too ([`Breach`]).
//!
//! # The stop ([`StopSequence`])
//!
//! The braking law ([`BrakingLaw`], full voltage against the motion, proportional near rest)
//! in the mode the stop's cause allows ([`BrakeMode`], [`Brake`]: the sign trusted, learnt
//! from the arm's response, or the windings shorted), until the arm rests ([`RestTest`]);
//! then, where the wiring's sign is known, the hold law ([`HoldLaw`]) takes the pendulum's
//! energy out through the arm; then the short. An orderly end instead lowers a balanced
//! pendulum under control first (the lowering: the hold law's form with its own weights).

use crate::real::Real;
use crate::swing::{wrap_angle, ArmModel};

mod brake;
mod coupling;
mod design;
mod momentum;
mod sequence;

pub use brake::{Brake, BrakeCommand, BrakeMode, PROGRESS_PERIODS, WRONG_SIGN_PERIODS};
pub use coupling::{CouplingTest, COUPLING_THRESHOLD, DRIVE_MODEL_ERROR};
pub use design::{StopDesign, StopDesignError, STOP_DESIGN_LEN, STOP_LAYOUT_VERSION, STOP_MAGIC};
pub use momentum::momentum_rate;
use momentum::{energy, MomentumBlock};
pub use sequence::{
    StopSequence, HOLD_BLIND_PERIODS, HOLD_GIVE_UP_RAD, LOWERED_HANGING_RAD, LOWER_FROM_RAD,
    LOWER_SIDE_FROM_RAD, MAX_HOLD_S, MAX_LOWER_S, MOMENTUM_ENERGY_GAIN, PENDULUM_REST_RAD,
};

#[inline]
fn c<R: Real>(v: f64) -> R {
    R::from_f64(v)
}

/// Periods in `seconds` at period `ts` (s), rounded up, at least 1.
fn periods_in(seconds: f64, ts: f64) -> u32 {
    let n = libm::ceil(seconds / ts);
    if n.is_finite() && n >= 1.0 {
        n.min(f64::from(u32::MAX)) as u32
    } else {
        1
    }
}

/// The arm's stopping model: how far the arm still travels when braked at the voltage bound
/// (rip-core's `envelope` module docs derive it),
///
/// ```text
/// d(ω) = ω / k − (a₀ / k²) ln(1 + k ω / a₀)                   (→ ω² / (2 a₀) as k → 0)
/// D(ω, u_a) = ω τ + ½ a_l τ² + d(ω + a_l τ),   a_l = (b / J_min) clamp(u_a, 0, U)
/// ```
///
/// with `u_a` the voltage acting along the motion during the latency `τ`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StoppingModel<R: Real = f64> {
    /// `a₀ = f b U / J` (rad/s²).
    pub a0: R,
    /// `k = f c / J` (1/s).
    pub k: R,
    /// `b / J_min` (rad/s² per V), the drive's acceleration per volt at the least inertia.
    pub drive_per_volt: R,
    /// `τ` (s).
    pub latency: R,
    /// The voltage bound `U` (V).
    pub voltage: R,
}

impl<R: Real> StoppingModel<R> {
    /// The braking distance `d(ω)` from speed `omega` (rad/s, its magnitude is used), without
    /// the latency.
    pub fn braking_distance(&self, omega: R) -> R {
        let w = omega.abs();
        let x = self.k * w / self.a0;
        if x < c(1e-6) {
            // The series of d: ω²/(2a₀) (1 − (2/3) x + …).
            w * w / (c::<R>(2.0) * self.a0) * (R::ONE - c::<R>(2.0) * x / c(3.0))
        } else {
            w / self.k - self.a0 / (self.k * self.k) * x.ln_1p()
        }
    }

    /// The stopping distance `D(ω, u_a)` (rad), latency included, with `along` (V) the
    /// voltage applied along the motion during the latency (clamped to `[0, U]`).
    pub fn stopping_distance_with(&self, omega: R, along: R) -> R {
        let w = omega.abs();
        let tau = self.latency;
        let a = self.drive_per_volt * along.clamp(R::ZERO, self.voltage);
        w * tau + c::<R>(0.5) * a * tau * tau + self.braking_distance(w + a * tau)
    }

    /// The stopping distance `D(ω, U)` (rad): the full voltage along the motion during the
    /// latency.
    pub fn stopping_distance(&self, omega: R) -> R {
        self.stopping_distance_with(omega, self.voltage)
    }

    /// Where the arm at `theta` moving at `rate` stops with `applied` (V) acting during the
    /// latency: `θ + sgn(θ̇) D(|θ̇|, sgn(θ̇) u_a)`.
    pub fn stopping_point(&self, theta: R, rate: R, applied: R) -> R {
        let along = if rate >= R::ZERO { applied } else { -applied };
        theta + rate.signum() * self.stopping_distance_with(rate, along)
    }

    /// The largest speed (rad/s) from which the arm stops within `room` (rad) with `along`
    /// (V) during the latency; 0 when even an arm at rest could not. `D` increases with `ω`:
    /// a bisection of 60 steps between 0 and the first doubling of 1 rad/s that is too fast
    /// (at most 10⁶ rad/s), so its work is bounded whatever the model.
    pub fn max_speed(&self, room: R, along: R) -> R {
        let d = |w: R| self.stopping_distance_with(w, along);
        if d(R::ZERO) >= room {
            return R::ZERO;
        }
        let mut hi = R::ONE;
        while d(hi) < room && hi < c(1e6) {
            hi *= c(2.0);
        }
        let mut lo = R::ZERO;
        for _ in 0..60 {
            let mid = c::<R>(0.5) * (lo + hi);
            if d(mid) < room {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }
}

/// Share of the braking law's voltage that [`SimulatedStop`] counts on: the rest is kept for a
/// motor weaker than `[plant]` says and a larger dead zone (tens of percent before
/// identification). The pendulum's reaction on the arm is simulated, not reserved for.
pub const SIMULATED_BRAKE_FRACTION: f64 = 0.7;

/// The longest an active stop brakes (s): `rip-rt` sends the stop frame after it whatever
/// the arm does, and [`SimulatedStop`] takes an arm still moving outwards after it as one it
/// cannot stop.
pub const MAX_BRAKE_S: f64 = 3.0;

/// Seconds the simulated arm must stay at rest or move back before [`SimulatedStop`] takes
/// its farthest point as reached: longer than the half swing of a hanging pendulum
/// (`π √(J_α / G)`, 0.13–0.4 s across the rigs of shared/DESIGN.md), whose reaction can push
/// a braked arm out again.
pub const SIMULATED_REST_S: f64 = 0.5;
/// Arm speed (rad/s) below which [`SimulatedStop`] counts the arm at rest.
pub const SIMULATED_REST_RATE: f64 = 0.05;

/// The shortest period (s) the stop's sequence runs at: the host loop's default, which its
/// rest windows, blind rule and dead band were measured at. A device that steps faster runs
/// it every `⌈STOP_PERIOD_S / T_s⌉` steps and holds its command in between: at 1 kHz the
/// 64-sample rest ring would span 63 ms, the blind rule 5 ms, and the dead band of 1.5
/// counts a period 4.6 rad/s on a 2048-count encoder.
pub const STOP_PERIOD_S: f64 = 0.01;

/// The steps of period `step_s` (s) between two periods of the stop's sequence on a device:
/// `⌈STOP_PERIOD_S / step_s⌉`, within 1 to 1000 (a design steps at 0.1 ms at the fastest);
/// 1 for a period that is not positive and finite.
pub fn steps_per_stop_period(step_s: f64) -> u32 {
    let steps = libm::ceil(STOP_PERIOD_S / step_s - 1e-9);
    if steps.is_finite() {
        steps.clamp(1.0, 1000.0) as u32
    } else {
        1
    }
}

/// The longest a stop after a fault runs (s): the braking law for up to [`MAX_BRAKE_S`], the
/// hold law for up to [`MAX_HOLD_S`]; then the driver is disabled whatever the arm does.
pub const MAX_STOP_S: f64 = MAX_BRAKE_S + MAX_HOLD_S;

/// The arm counts as at rest once it moved less than [`REST_TRAVEL`] over this long (s).
pub const REST_S: f64 = 0.2;
/// Travel (rad) below which the arm is at rest over [`REST_S`].
pub const REST_TRAVEL: f64 = 0.01;

/// The stop's braking law: full voltage against the arm's motion, proportional near rest so
/// that it does not chatter about zero speed.
///
/// ```text
/// u = −U · clamp(θ̇ / ω_lin, −1, 1),    ω_lin = U / K,   K = J / (2 b T_s)
/// ```
///
/// The gain `K` removes half the arm's speed per period on the model (a faster gain would
/// overshoot through the loop's delay); `ω_lin` is the speed below which the law is linear.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BrakingLaw<R: Real = f64> {
    /// `U` (V).
    pub voltage: R,
    /// `ω_lin` (rad/s).
    pub linear_below: R,
}

impl<R: Real> BrakingLaw<R> {
    /// The voltage for arm rate `rate` (rad/s); 0 for a rate that is not finite.
    #[inline]
    pub fn voltage(&self, rate: R) -> R {
        if !rate.is_finite() {
            return R::ZERO;
        }
        -self.voltage * (rate / self.linear_below).clamp(-R::ONE, R::ONE)
    }
}

/// The stop's hold law, once the braking law has the arm at rest: the arm held where it
/// stopped while the pendulum's energy is taken out through it. A linear law about the
/// hanging equilibrium at the arm's hold point `θ_h`, on `z = (θ − θ_h, θ̇, φ, α̇)`,
/// `φ = wrap(α − π)`:
///
/// ```text
/// u = clamp(−K z, −U, U)
/// ```
///
/// rip-core designs `K` (the discrete LQR of the plant linearised about hanging; its
/// `envelope::HoldLaw` docs give the weights). [`arm_voltage`](Self::arm_voltage) uses the
/// arm's terms alone, for a stop that learnt only the arm's sign.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HoldLaw<R: Real = f64> {
    /// The gain `K` on `(θ − θ_h, θ̇, φ, α̇)`.
    pub k: [R; 4],
    /// `U` (V).
    pub voltage: R,
}

impl<R: Real> HoldLaw<R> {
    /// The voltage for the arm at `offset` (rad) from its hold point moving at `rate`
    /// (rad/s), the pendulum at `alpha` (rad, 0 upright) moving at `alpha_rate` (rad/s).
    pub fn voltage(&self, offset: R, rate: R, alpha: R, alpha_rate: R) -> R {
        let phi = wrap_angle(alpha - c(core::f64::consts::PI));
        self.voltage_from_hanging(offset, rate, phi, alpha_rate)
    }

    /// [`voltage`](Self::voltage) with the pendulum's angle from hanging `phi` (rad) given
    /// rather than wrapped from `α` ([`pendulum_angle`]).
    pub fn voltage_from_hanging(&self, offset: R, rate: R, phi: R, alpha_rate: R) -> R {
        let u = -(self.k[0] * offset + self.k[1] * rate + self.k[2] * phi + self.k[3] * alpha_rate);
        self.bounded(u)
    }

    /// [`voltage`](Self::voltage) with the arm's terms alone.
    pub fn arm_voltage(&self, offset: R, rate: R) -> R {
        self.bounded(-(self.k[0] * offset + self.k[1] * rate))
    }

    fn bounded(&self, u: R) -> R {
        if u.is_finite() {
            u.clamp(-self.voltage, self.voltage)
        } else {
            R::ZERO
        }
    }
}

/// The pendulum's angle from hanging (rad) that the lowering law takes, for the pendulum at
/// `alpha` (rad, 0 upright) on the `side` (±1; 0 before the first call) it is lowered on,
/// which it updates.
///
/// `wrap(α − π)` jumps from +π to −π as the pendulum crosses upright: the law's pendulum term
/// flips with it, and a pendulum near upright is balanced there by it rather than lowered (on
/// the emulator it stayed up for 3.4 s). In the upper half the angle is kept on the side the
/// pendulum was last on in the lower half (or first found on), past ±π if it crosses upright,
/// so that the law keeps tipping it the one way.
pub fn pendulum_angle<R: Real>(alpha: R, side: &mut R) -> R {
    let phi = wrap_angle(alpha - c(core::f64::consts::PI));
    if !phi.is_finite() {
        return phi;
    }
    if alpha.cos() < R::ZERO || *side == R::ZERO {
        *side = if phi < R::ZERO { -R::ONE } else { R::ONE };
        return phi;
    }
    if phi * *side < R::ZERO {
        phi + *side * c(core::f64::consts::TAU)
    } else {
        phi
    }
}

/// The stop simulated from the rig's whole state: the braking law run on the smooth model
/// ([`ArmModel`], with the dead zone), the pendulum's reaction on the arm included, from the
/// measured arm and pendulum angles and rates.
///
/// The analytic distance (3) cannot know the pendulum: it reserves a share of the braking
/// torque for its reaction, which is too much for an upright pendulum just caught (its
/// reaction is small; a controlled catch moves the arm fast) and too little for a heavy
/// pendulum falling on a light arm. The simulation takes the reaction from the equations of
/// motion instead:
///
/// ```text
/// u = applied (full along the motion, SIMULATED_BRAKE_FRACTION of it against)   τ periods
/// u = SIMULATED_BRAKE_FRACTION · BrakingLaw(θ̇_sampled)                          after
/// ```
///
/// without Coulomb friction (which only helps the stop), until the arm has stayed at rest or
/// moved back for [`SIMULATED_REST_S`], at most [`MAX_BRAKE_S`]; the stopping point is the
/// farthest the arm went along its motion, and an arm that moved outwards all along the last
/// [`SIMULATED_REST_S`] of that time has none (±∞). Its work is bounded:
/// `latency + ⌈MAX_BRAKE_S / T_s⌉` periods of `substeps` RK4 steps.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimulatedStop<R: Real = f64> {
    /// The smooth model.
    pub model: ArmModel<R>,
    /// The motor's dead zone `V_d` (V): the model sees `u − clamp(u, −V_d, V_d)`.
    pub dead_zone: R,
    /// The braking law.
    pub law: BrakingLaw<R>,
    /// The loop's period (s).
    pub ts: R,
    /// RK4 substeps per period.
    pub substeps: u32,
    /// Periods the applied voltage acts before the braking law.
    pub latency_periods: u32,
}

impl<R: Real> SimulatedStop<R> {
    fn advance(&self, x: &mut [R; 4], u: R) {
        let applied = u - u.clamp(-self.dead_zone, self.dead_zone);
        self.model.advance(x, applied, self.ts, self.substeps);
    }

    /// The farthest arm angle (rad) along its motion from state `x` (the pendulum's angle 0
    /// upright) with `applied` (V) across the motor until the stop's first command (type
    /// docs); `x[0]` for an arm at rest, ±∞ for one the stop cannot bring to rest.
    pub fn stopping_point(&self, x: [R; 4], applied: R) -> R {
        if x[1] == R::ZERO || !x.iter().all(|v| v.is_finite()) {
            return x[0];
        }
        let dir = x[1].signum();
        let fraction: R = c(SIMULATED_BRAKE_FRACTION);
        let voltage = self.law.voltage;
        let along = applied.clamp(-voltage, voltage);
        let held = if along * dir > R::ZERO {
            along
        } else {
            fraction * along
        };
        let farther = |far: R, theta: R| {
            if dir > R::ZERO {
                far.max(theta)
            } else {
                far.min(theta)
            }
        };
        let mut x = x;
        let mut far = x[0];
        for _ in 0..self.latency_periods {
            self.advance(&mut x, held);
            far = farther(far, x[0]);
        }
        let ts = self.ts.to_f64();
        let mut last = x[0];
        let mut rate = x[1];
        let periods = periods_in(MAX_BRAKE_S, ts);
        let rest = periods_in(SIMULATED_REST_S, ts);
        let rest_rate: R = c(SIMULATED_REST_RATE);
        let (mut still, mut escaping) = (0u32, 0u32);
        for _ in 0..periods {
            let u = fraction * self.law.voltage(rate);
            self.advance(&mut x, u);
            rate = (x[0] - last) / self.ts;
            last = x[0];
            far = farther(far, x[0]);
            if !far.is_finite() {
                break;
            }
            // At rest, or on its way back, for long enough that the pendulum's reaction has
            // had its swing to push the arm out again.
            if x[1] * dir > R::ZERO && x[1].abs() > rest_rate {
                (still, escaping) = (0, escaping + 1);
            } else {
                (still, escaping) = (still + 1, 0);
            }
            if still >= rest {
                return far;
            }
        }
        // Still swinging with its pendulum after the braking time, the arm has its farthest
        // point behind it; one that has moved outwards all along its last SIMULATED_REST_S
        // is not being stopped.
        if far.is_finite() && escaping < rest {
            far
        } else {
            dir * c(f64::INFINITY)
        }
    }
}

/// The arm's and the pendulum's rates (rad/s) from the sample `before` (its angles, rad, and
/// the device's clock, µs, wrapping) to this one at `theta`, `alpha` and `now_us`: the
/// difference over the device's clock between the two sampling instants, not the host's
/// wake-ups. 0 without a sample before, or for two samples in the same microsecond or a clock
/// that jumped back.
pub fn sample_rates<R: Real>(
    before: Option<(R, R, u32)>,
    theta: R,
    alpha: R,
    now_us: u32,
) -> (R, R) {
    match before {
        Some((theta0, alpha0, at)) if (1..u32::MAX / 2).contains(&now_us.wrapping_sub(at)) => {
            let dt = R::from_f64(f64::from(now_us.wrapping_sub(at)) * 1e-6);
            ((theta - theta0) / dt, wrap_angle(alpha - alpha0) / dt)
        }
        _ => (R::ZERO, R::ZERO),
    }
}

/// Where the arm's stopping point left the envelope: the state the stop decision was made
/// on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Breach<R: Real = f64> {
    /// Arm angle (rad).
    pub angle: R,
    /// Arm rate (rad/s).
    pub rate: R,
    /// The stopping point (rad; ±∞ or NaN when there is none).
    pub stop_at: R,
    /// The bound it is past (rad).
    pub bound: R,
}

/// The braking envelope in the loop (module docs). Allocation-free, `Copy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmEnvelope<R: Real = f64> {
    model: StoppingModel<R>,
    simulated: Option<SimulatedStop<R>>,
    bound: R,
    // The last arm and pendulum angles and the device's clock (µs, wrapping) when they were
    // sampled.
    last: Option<(R, R, u32)>,
}

impl<R: Real> ArmEnvelope<R> {
    /// The envelope of stopping `model` (and where it is past `bound`, the stop `simulated`
    /// from the whole state) on the stopping point's `bound` (rad).
    pub fn new(model: StoppingModel<R>, simulated: Option<SimulatedStop<R>>, bound: R) -> Self {
        Self {
            model,
            simulated,
            bound,
            last: None,
        }
    }

    /// The stopping model it uses.
    pub fn model(&self) -> &StoppingModel<R> {
        &self.model
    }

    /// The bound on the stopping point (rad).
    pub fn bound(&self) -> R {
        self.bound
    }

    /// Forgets the last measurement (a new phase of the run).
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// Takes the arm angle `theta` and the pendulum angle `alpha` (rad, 0 upright) sampled at
    /// the device's clock `device_us` with `applied` (V) across the motor (which acts until
    /// the stop's first command); the breach when the arm's stopping point is past the bound.
    pub fn check(
        &mut self,
        theta: R,
        alpha: R,
        device_us: u32,
        applied: R,
    ) -> Result<(), Breach<R>> {
        let before = self.last.replace((theta, alpha, device_us));
        let (rate, alpha_rate) = sample_rates(before, theta, alpha, device_us);
        self.check_state(theta, rate, alpha, alpha_rate, applied)
    }

    /// [`check`](Self::check) on a state whose rates the caller measured.
    pub fn check_state(
        &self,
        theta: R,
        rate: R,
        alpha: R,
        alpha_rate: R,
        applied: R,
    ) -> Result<(), Breach<R>> {
        let mut stop_at = self.model.stopping_point(theta, rate, applied);
        if stop_at.abs() > self.bound {
            if let Some(sim) = &self.simulated {
                stop_at = sim.stopping_point([theta, rate, alpha, alpha_rate], applied);
            }
        }
        // A NaN stopping point (no finite state to simulate) fails the comparison and stops.
        if stop_at.abs() <= self.bound {
            return Ok(());
        }
        Err(Breach {
            angle: theta,
            rate,
            stop_at,
            bound: self.bound,
        })
    }
}

/// The angles `[θ, α]` (rad) of the encoder counts `[n_θ, n_α]`: one definition for the host's
/// loop and the device's onboard law,
///
/// ```text
/// θ = n_θ s_θ − o_θ,   α = wrap(n_α s_α − o_α) ∈ (−π, π]
/// ```
///
/// with `rad_per_count = [s_θ, s_α]` (signed: a reversed encoder counts the other way) and
/// `offsets = [o_θ, o_α]`.
#[inline]
pub fn angles<R: Real>(counts: [i32; 2], rad_per_count: [R; 2], offsets: [R; 2]) -> [R; 2] {
    let angle = |i: usize| {
        angle_of(
            R::from_f64(f64::from(counts[i])),
            rad_per_count[i],
            offsets[i],
        )
    };
    [angle(0), wrap_angle(angle(1))]
}

/// `n s − o`: the angle (rad, unwrapped) of a count `n` (or a mean of counts) on an encoder of
/// `rad_per_count` `s` and offset `o` ([`angles`]).
#[inline]
pub fn angle_of<R: Real>(counts: R, rad_per_count: R, offset: R) -> R {
    counts * rad_per_count - offset
}

/// The position rule, the last resort behind the envelope: whether the arm at `theta` (rad)
/// is past `limit` (rad) from the centre. An angle that is not a number is past it.
#[inline]
pub fn past_limit<R: Real>(theta: R, limit: R) -> bool {
    use core::cmp::Ordering::{Equal, Less};
    !matches!(theta.abs().partial_cmp(&limit), Some(Less | Equal))
}

/// The stop's rest test: the arm moved less than a travel over the last [`REST_S`].
/// Allocation-free (a ring of the recent angles).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestTest<R: Real = f64> {
    history: [R; 64],
    ring: usize,
    seen: usize,
}

impl<R: Real> RestTest<R> {
    /// The test for a loop of period `period_s` (s).
    pub fn new(period_s: f64) -> Self {
        let rest_periods = periods_in(REST_S, period_s) as usize;
        Self {
            history: [c(f64::NAN); 64],
            ring: (rest_periods + 1).min(64),
            seen: 0,
        }
    }

    /// Takes the next measured arm angle (rad); whether the arm is at rest
    /// (moved less than [`REST_TRAVEL`]).
    pub fn observe(&mut self, theta: R) -> bool {
        self.observe_within(theta, c(REST_TRAVEL))
    }

    /// Takes the next angle (rad); whether it moved less than `travel` (rad) over
    /// [`REST_S`]. A window holding an angle that is not finite is not at rest.
    pub fn observe_within(&mut self, theta: R, travel: R) -> bool {
        self.history[self.seen % self.ring] = theta;
        self.seen += 1;
        if self.seen < self.ring {
            return false;
        }
        let (mut lo, mut hi): (R, R) = (c(f64::INFINITY), c(f64::NEG_INFINITY));
        for &v in &self.history[..self.ring] {
            // A reading that is not a number is no evidence of rest.
            if !v.is_finite() {
                return false;
            }
            lo = lo.min(v);
            hi = hi.max(v);
        }
        hi - lo < travel
    }
}

#[cfg(test)]
mod tests;
