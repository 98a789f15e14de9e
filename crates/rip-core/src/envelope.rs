//! The arm's braking envelope: how far the arm still travels when it is braked at the voltage
//! bound, and the law that brakes it. One definition for every bound on the arm's travel:
//! the swing-up's limit ([`crate::swingup`]) and the stops of `rip-rt` (`safety.arm_limit`).
//!
//! # Stopping distance
//!
//! Braked against its motion with `u = −U sgn θ̇`, the arm of the model in [`crate::plant`]
//! decelerates as
//!
//! ```text
//! J ω̇ = −f (b U + c ω),    ω = |θ̇| > 0,   b = k_t / R_m,   c = d_r + k_t k_m / R_m        (1)
//! ```
//!
//! (the motor's torque at `−U`, its back-EMF and the viscous friction all oppose the motion).
//! `J = J₀ + J_α` is the largest inertia the arm presents (the pendulum horizontal), and
//! `f ≤ 1` the share of that deceleration counted on: the rest is kept for the pendulum's
//! reaction on the arm (its centrifugal and Coriolis torques), for dead zone and for the
//! difference between the model and the rig. With `a₀ = f b U / J` and `k = f c / J`, (1)
//! stops the arm after
//!
//! ```text
//! d(ω) = ω / k − (a₀ / k²) ln(1 + k ω / a₀)        (→ ω² / (2 a₀) as k → 0)           (2)
//! ```
//!
//! A stop is not instantaneous: the state it starts from was measured up to `τ` earlier
//! (the loop's latency, two periods), during which the voltage already applied, `u_a`, still
//! acts: along the motion it accelerates the arm by at most `a_l = b u_a⁺ / J_min`
//! (`J_min = J₀ − m₁₂² / J_α`, the least effective inertia; `u_a⁺` its part along the
//! motion, 0 when it already brakes). The stopping distance from speed `ω` is therefore
//!
//! ```text
//! D(ω, u_a) = ω τ + ½ a_l τ² + d(ω + a_l τ)                                                 (3)
//! ```
//!
//! and, not knowing `u_a`, at most `D(ω, U)`.
//!
//! and the stopping point `θ + sgn(θ̇) D(|θ̇|)`. An arm whose stopping point is inside the
//! limit (less a margin) can still be stopped there; the loop stops it the period that is no
//! longer so.
//!
//! The constant-deceleration envelope of the swing-up, `v(θ) = √(2 a_b (θ_L − θ)⁺)`, is (2)
//! with `k = 0` solved for the speed ([`envelope_speed`]).

use crate::excitation::{Excitation, ExcitationSettings};
use crate::plant::{FurutaParams, Plant, State};

/// Share `f` of the braking deceleration (1) that the stops of `rip-rt` count on: half, as the
/// swing-up's default `brake_fraction` reserves, for the pendulum's reaction, dead zone and
/// model error of tens of percent.
pub const STOP_BRAKE_FRACTION: f64 = 0.5;

/// The speed (rad/s) from which a constant deceleration `a_b` (rad/s²) stops within `room`
/// (rad): `√(2 a_b room⁺)`.
#[inline]
pub fn envelope_speed(a_b: f64, room: f64) -> f64 {
    (2.0 * a_b * room.max(0.0)).sqrt()
}

/// The arm's stopping model (module docs, (1)–(3)) for one plant, voltage bound and latency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StoppingModel {
    /// `a₀ = f b U / J` (rad/s²).
    pub a0: f64,
    /// `k = f c / J` (1/s).
    pub k: f64,
    /// `b / J_min` (rad/s² per V), the drive's acceleration per volt at the least inertia.
    pub drive_per_volt: f64,
    /// `τ` (s).
    pub latency: f64,
    /// The voltage bound `U` (V).
    pub voltage: f64,
}

impl StoppingModel {
    /// The model of plant `p` braked at `voltage` (V) with the share `fraction` of (1), the
    /// stop starting `latency` seconds after the state was measured.
    pub fn new(p: &FurutaParams, voltage: f64, fraction: f64, latency: f64) -> Self {
        let j0 = p.jr + p.mr * p.lr * p.lr / 4.0 + p.mp * p.lr * p.lr;
        let ja = p.jp + p.mp * p.lp * p.lp / 4.0;
        let m12 = p.mp * p.lr * p.lp / 2.0;
        let j = j0 + ja;
        let j_min = (j0 - m12 * m12 / ja).max(1e-3 * j0);
        let b = p.kt / p.rm;
        let c = p.dr + p.kt * p.km / p.rm;
        Self {
            a0: fraction * b * voltage / j,
            k: fraction * c / j,
            drive_per_volt: b / j_min,
            latency,
            voltage,
        }
    }

    /// The braking distance `d(ω)` of (2) from speed `omega` (rad/s, its magnitude is used),
    /// without the latency.
    pub fn braking_distance(&self, omega: f64) -> f64 {
        let w = omega.abs();
        let x = self.k * w / self.a0;
        if x < 1e-6 {
            // The series of (2): ω²/(2a₀) (1 − (2/3) x + …).
            w * w / (2.0 * self.a0) * (1.0 - 2.0 * x / 3.0)
        } else {
            w / self.k - self.a0 / (self.k * self.k) * x.ln_1p()
        }
    }

    /// The stopping distance `D(ω, u_a)` of (3) (rad), latency included, with `along` (V)
    /// the voltage applied along the motion during the latency (clamped to `[0, U]`).
    pub fn stopping_distance_with(&self, omega: f64, along: f64) -> f64 {
        let w = omega.abs();
        let tau = self.latency;
        let a = self.drive_per_volt * along.clamp(0.0, self.voltage);
        w * tau + 0.5 * a * tau * tau + self.braking_distance(w + a * tau)
    }

    /// The stopping distance `D(ω, U)` (rad): the full voltage along the motion during the
    /// latency.
    pub fn stopping_distance(&self, omega: f64) -> f64 {
        self.stopping_distance_with(omega, self.voltage)
    }

    /// Where the arm at `theta` moving at `rate` stops with `applied` (V) acting during the
    /// latency: `θ + sgn(θ̇) D(|θ̇|, sgn(θ̇) u_a)`.
    pub fn stopping_point(&self, theta: f64, rate: f64, applied: f64) -> f64 {
        let along = if rate >= 0.0 { applied } else { -applied };
        theta + rate.signum() * self.stopping_distance_with(rate, along)
    }

    /// The largest speed (rad/s) from which the arm stops within `room` (rad) by (3) with
    /// `along` (V) during the latency; 0 when even an arm at rest could not.
    pub fn max_speed(&self, room: f64, along: f64) -> f64 {
        let d = |w: f64| self.stopping_distance_with(w, along);
        if d(0.0) >= room {
            return 0.0;
        }
        // D is increasing in ω: bisect between 0 and a speed that is too fast.
        let mut hi = 1.0;
        while d(hi) < room && hi < 1e6 {
            hi *= 2.0;
        }
        let mut lo = 0.0;
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if d(mid) < room {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }
}

/// The stop's braking law: full voltage against the arm's motion, proportional near rest so
/// that it does not chatter about zero speed.
///
/// ```text
/// u = −U · clamp(θ̇ / ω_lin, −1, 1),    ω_lin = U / K,   K = J / (2 b T_s)
/// ```
///
/// The gain `K` removes half the arm's speed per period on the model (a faster gain would
/// overshoot through the loop's delay); `ω_lin` is the speed below which the law is linear.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrakingLaw {
    /// `U` (V).
    pub voltage: f64,
    /// `ω_lin` (rad/s).
    pub linear_below: f64,
}

impl BrakingLaw {
    /// The law for plant `p`, voltage bound `voltage` (V) and loop period `ts` (s).
    pub fn new(p: &FurutaParams, voltage: f64, ts: f64) -> Self {
        let j0 = p.jr + p.mr * p.lr * p.lr / 4.0 + p.mp * p.lr * p.lr;
        let ja = p.jp + p.mp * p.lp * p.lp / 4.0;
        let gain = (j0 + ja) / (2.0 * p.kt / p.rm * ts);
        Self {
            voltage,
            linear_below: voltage / gain,
        }
    }

    /// The voltage for arm rate `rate` (rad/s).
    pub fn voltage(&self, rate: f64) -> f64 {
        if !rate.is_finite() {
            return 0.0;
        }
        -self.voltage * (rate / self.linear_below).clamp(-1.0, 1.0)
    }
}

/// The stop's hold law, once the braking law has the arm at rest: the arm held where it
/// stopped while the pendulum's energy is taken out through it. A pendulum that falls from
/// upright, or still swings after a swing-up, pushes the arm with its reaction torque; a
/// weak motor's shorted windings cannot hold the arm against it (it walks on, swing after
/// swing), and the pendulum's own damping takes tens of seconds.
///
/// The law is the discrete LQR of the plant linearised about the hanging equilibrium at the
/// arm's hold point `θ_h`, with the state `z = (θ − θ_h, θ̇, φ, α̇)`, `φ = wrap(α − π)`,
///
/// ```text
/// u = −U · clamp(K z / U, −1, 1),   K = dlqr(A_d, B_d, Q, R),
/// Q = diag(1/θ_m², 0, 1/φ_m², 0),   R = 1/U²
/// ```
///
/// (Bryson's rule: the arm held within `θ_m` = [`HOLD_ARM_RAD`], the pendulum brought within
/// `φ_m` = [`HOLD_PENDULUM_RAD`], with up to the voltage bound). When only the arm's reading
/// can be trusted (the wiring's sign learnt from the arm's response, the pendulum's not),
/// [`HoldLaw::arm_voltage`] uses the arm's terms alone: a stiff, damped position loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldLaw {
    /// The gain `K` on `(θ − θ_h, θ̇, φ, α̇)`.
    pub k: [f64; 4],
    /// `U` (V).
    pub voltage: f64,
}

/// `θ_m` of [`HoldLaw`] (rad): the arm's deviation from its hold point weighed against a
/// full-voltage command.
pub const HOLD_ARM_RAD: f64 = 0.05;
/// `φ_m` of [`HoldLaw`] (rad): the pendulum's swing weighed against a full-voltage command.
pub const HOLD_PENDULUM_RAD: f64 = 0.5;

impl HoldLaw {
    /// The law for plant `p`, voltage bound `voltage` (V) and loop period `ts` (s).
    pub fn new(p: &FurutaParams, voltage: f64, ts: f64) -> crate::error::Result<Self> {
        use crate::linalg::Mat;
        let plant = Plant::new(*p)?;
        let hanging = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
        let (a, b) = plant.linearize_discrete(&hanging, 0.0, ts)?;
        let q = Mat::from_diagonal(&nalgebra::DVector::from_vec(vec![
            1.0 / (HOLD_ARM_RAD * HOLD_ARM_RAD),
            0.0,
            1.0 / (HOLD_PENDULUM_RAD * HOLD_PENDULUM_RAD),
            0.0,
        ]));
        let r = Mat::from_element(1, 1, 1.0 / (voltage * voltage).max(1e-6));
        let design = crate::lqr::dlqr(&a, &b, &q, &r, None)?;
        Ok(Self {
            k: std::array::from_fn(|i| design.k[(0, i)]),
            voltage,
        })
    }

    /// The voltage for the arm at `offset` (rad) from its hold point moving at `rate`
    /// (rad/s), the pendulum at `alpha` (rad, 0 upright) moving at `alpha_rate` (rad/s).
    pub fn voltage(&self, offset: f64, rate: f64, alpha: f64, alpha_rate: f64) -> f64 {
        let phi = crate::trig::wrap_angle(alpha - std::f64::consts::PI);
        let u = -(self.k[0] * offset + self.k[1] * rate + self.k[2] * phi + self.k[3] * alpha_rate);
        if u.is_finite() {
            u.clamp(-self.voltage, self.voltage)
        } else {
            0.0
        }
    }

    /// [`voltage`](Self::voltage) with the arm's terms alone (class docs).
    pub fn arm_voltage(&self, offset: f64, rate: f64) -> f64 {
        let u = -(self.k[0] * offset + self.k[1] * rate);
        if u.is_finite() {
            u.clamp(-self.voltage, self.voltage)
        } else {
            0.0
        }
    }
}

/// Where a simulated run first left the envelope: the stop that the loop would make there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Breach {
    /// Seconds from the start.
    pub t: f64,
    /// Arm angle (rad).
    pub theta: f64,
    /// Arm rate (rad/s), the backward difference the loop measures.
    pub rate: f64,
    /// The stopping point (rad).
    pub stop_at: f64,
}

/// Runs `law` (`(t, θ, θ̇) ↦ u`, clamped to `±model.voltage`) on `plant` from `x0` for
/// `duration` seconds, sampled every `ts` as the loop samples it (the rate a backward
/// difference, the voltage held between samples), and returns the first sample whose
/// stopping point (with the voltage held over it) is past `±bound`: where the loop's envelope
/// would stop the run. `None` when the run stays inside.
pub fn first_breach(
    plant: &Plant,
    x0: State,
    ts: f64,
    duration: f64,
    model: &StoppingModel,
    bound: f64,
    mut law: impl FnMut(f64, f64, f64) -> f64,
) -> Option<Breach> {
    let substeps = (ts / plant.max_rk4_substep()).ceil().clamp(1.0, 1000.0) as usize;
    let steps = (duration / ts).ceil() as usize;
    let mut x = x0;
    let mut last = x[0];
    let mut u = 0.0;
    for k in 0..=steps {
        let t = k as f64 * ts;
        let theta = x[0];
        let rate = if k == 0 { 0.0 } else { (theta - last) / ts };
        last = theta;
        let stop_at = model.stopping_point(theta, rate, u);
        if stop_at.is_nan() || stop_at.abs() > bound {
            return Some(Breach {
                t,
                theta,
                rate,
                stop_at,
            });
        }
        u = law(t, theta, rate).clamp(-model.voltage, model.voltage);
        plant.advance(&mut x, u, 0.0, ts, substeps);
    }
    None
}

/// [`first_breach`] of an open-loop excitation (`rip-rt excite`) on `plant`, the pendulum
/// hanging at rest and the arm at 0: its signal through its arm-centring law with
/// `arm_limit`, sampled every `ts`.
pub fn excitation_breach(
    settings: ExcitationSettings,
    plant: &Plant,
    ts: f64,
    model: &StoppingModel,
    bound: f64,
    arm_limit: f64,
) -> crate::error::Result<Option<Breach>> {
    let mut x = Excitation::new(settings, ts)?;
    let x0 = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    Ok(first_breach(
        plant,
        x0,
        ts,
        settings.duration,
        model,
        bound,
        |t, theta, rate| {
            let e = x.value(t);
            x.command(e, theta, rate, arm_limit)
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (2) against a direct integration of (1), and the limits it must have.
    #[test]
    fn the_braking_distance_is_the_integral_of_the_deceleration() {
        let p = FurutaParams::qube_servo2();
        let m = StoppingModel::new(&p, 12.0, 0.5, 0.0);
        for w0 in [0.5, 3.0, 10.0, 40.0] {
            // ω̇ = −(a₀ + k ω), integrated with small Euler steps until rest.
            let (mut w, mut x, h) = (w0, 0.0, 1e-6);
            while w > 0.0 {
                x += w * h;
                w -= (m.a0 + m.k * w) * h;
            }
            let d = m.braking_distance(w0);
            assert!((d - x).abs() < 1e-3 * x, "{w0}: {d} vs {x}");
            // Back-EMF only helps: less than the constant-deceleration distance.
            assert!(d < w0 * w0 / (2.0 * m.a0));
        }
        assert_eq!(m.braking_distance(0.0), 0.0);
        let with_latency = StoppingModel::new(&p, 12.0, 0.5, 0.02);
        assert!(with_latency.stopping_distance(5.0) > m.stopping_distance(5.0) + 5.0 * 0.02);
        // max_speed inverts D.
        let v = with_latency.max_speed(2.0, 12.0);
        assert!((with_latency.stopping_distance(v) - 2.0).abs() < 1e-9);
        // A voltage that already brakes adds only the latency's travel.
        let d = with_latency.stopping_distance_with(5.0, -3.0);
        assert!((d - 5.0 * 0.02 - with_latency.braking_distance(5.0)).abs() < 1e-12);
        assert_eq!(
            with_latency.stopping_point(1.0, -5.0, -12.0),
            1.0 - with_latency.stopping_distance(5.0)
        );
        assert_eq!(envelope_speed(2.0, 4.0), 4.0);
        assert_eq!(envelope_speed(2.0, -1.0), 0.0);
    }

    /// The nonlinear plant braked by the law from its envelope's speed stops within the
    /// predicted distance, the pendulum hanging or upright and swinging.
    #[test]
    fn the_nonlinear_plant_stops_within_the_stopping_distance() {
        for p in [FurutaParams::qube_servo2(), FurutaParams::paper()] {
            let plant = Plant::new(p).unwrap();
            let ts = 0.01;
            let model = StoppingModel::new(&p, 12.0, STOP_BRAKE_FRACTION, 2.0 * ts);
            let law = BrakingLaw::new(&p, 12.0, ts);
            for (alpha, alpha_dot) in [(std::f64::consts::PI, 0.0), (0.3, 4.0), (2.0, -6.0)] {
                for w in [2.0, 8.0, 20.0] {
                    let mut x = State::new(0.0, w, alpha, alpha_dot);
                    let predicted = model.stopping_distance(w);
                    // Two periods of latency at full drive along the motion, then the law on
                    // the rate sampled each period.
                    let mut far: f64 = 0.0;
                    for k in 0..400 {
                        let u = if k < 2 { 12.0 } else { law.voltage(x[1]) };
                        plant.advance(&mut x, u, 0.0, ts, 10);
                        far = far.max(x[0]);
                    }
                    assert!(x[1].abs() < 0.5, "not at rest: {x:?}");
                    assert!(far <= predicted, "{w} rad/s: {far} > {predicted}");
                }
            }
        }
    }
}
