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
    rip_control::swing::envelope_speed(a_b, room)
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

    /// The same model in the `no_std` form the swing-up supervisor and the device evaluate:
    /// the one implementation of (2) and (3).
    pub fn control(&self) -> rip_control::swing::StoppingModel {
        rip_control::swing::StoppingModel {
            a0: self.a0,
            k: self.k,
            drive_per_volt: self.drive_per_volt,
            latency: self.latency,
            voltage: self.voltage,
        }
    }

    /// The braking distance `d(ω)` of (2) from speed `omega` (rad/s, its magnitude is used),
    /// without the latency.
    pub fn braking_distance(&self, omega: f64) -> f64 {
        self.control().braking_distance(omega)
    }

    /// The stopping distance `D(ω, u_a)` of (3) (rad), latency included, with `along` (V)
    /// the voltage applied along the motion during the latency (clamped to `[0, U]`).
    pub fn stopping_distance_with(&self, omega: f64, along: f64) -> f64 {
        self.control().stopping_distance_with(omega, along)
    }

    /// The stopping distance `D(ω, U)` (rad): the full voltage along the motion during the
    /// latency.
    pub fn stopping_distance(&self, omega: f64) -> f64 {
        self.stopping_distance_with(omega, self.voltage)
    }

    /// Where the arm at `theta` moving at `rate` stops with `applied` (V) acting during the
    /// latency: `θ + sgn(θ̇) D(|θ̇|, sgn(θ̇) u_a)`.
    pub fn stopping_point(&self, theta: f64, rate: f64, applied: f64) -> f64 {
        self.control().stopping_point(theta, rate, applied)
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

/// Share of the braking law's voltage that [`SimulatedStop`] counts on: the rest is kept for a
/// motor weaker than `[plant]` says and a larger dead zone (tens of percent before
/// identification). The pendulum's reaction on the arm is simulated, not reserved for.
pub const SIMULATED_BRAKE_FRACTION: f64 = 0.7;

/// Seconds of braking after which [`SimulatedStop`] takes an arm still moving outwards as
/// one it cannot stop: the stop's own braking time (`rip-rt`'s `MAX_BRAKE_S`).
pub const SIMULATED_STOP_S: f64 = 3.0;

/// Seconds the simulated arm must stay at rest or move back before [`SimulatedStop`] takes
/// its farthest point as reached: longer than the half swing of a hanging pendulum
/// (`π √(J_α / G)`, 0.13–0.4 s across the rigs of shared/DESIGN.md), whose reaction can push
/// a braked arm out again.
pub const SIMULATED_REST_S: f64 = 0.5;
/// Arm speed (rad/s) below which [`SimulatedStop`] counts the arm at rest.
pub const SIMULATED_REST_RATE: f64 = 0.05;

/// The stop simulated from the rig's whole state: the braking law run on the model of
/// `[plant]`, the pendulum's reaction on the arm included, from the measured arm and pendulum
/// angles and rates.
///
/// The analytic distance (3) cannot know the pendulum: it reserves a share of the braking
/// torque for its reaction (`STOP_BRAKE_FRACTION`), which is too much for an upright
/// pendulum just caught (its reaction is small; a controlled catch moves the arm fast) and
/// too little for a heavy pendulum falling on a light arm. The simulation takes the reaction
/// from the equations of motion of [`crate::plant`] instead:
///
/// ```text
/// u = applied (full along the motion, SIMULATED_BRAKE_FRACTION of it against)   τ periods
/// u = SIMULATED_BRAKE_FRACTION · BrakingLaw(θ̇_sampled)                          after
/// ```
///
/// on the model without its Coulomb friction (which only helps the stop, and would need
/// small integration steps), until the arm has stayed at rest or moved back for
/// [`SIMULATED_REST_S`], at most [`SIMULATED_STOP_S`]; the stopping point is the farthest the
/// arm went along its motion, and an arm that moved outwards all along the last
/// [`SIMULATED_REST_S`] of that time has none (±∞).
#[derive(Debug, Clone)]
pub struct SimulatedStop {
    plant: Plant,
    law: BrakingLaw,
    ts: f64,
    substeps: usize,
    latency_periods: usize,
    voltage: f64,
}

impl SimulatedStop {
    /// The simulated stop of plant `p` braked at `voltage` (V), sampled every `ts` (s), the
    /// applied voltage acting for `latency_periods` periods before the braking law.
    pub fn new(
        p: &FurutaParams,
        voltage: f64,
        ts: f64,
        latency_periods: usize,
    ) -> crate::error::Result<Self> {
        let smooth = FurutaParams {
            cr: 0.0,
            cp: 0.0,
            ..*p
        };
        let plant = Plant::new(smooth)?;
        let substeps = stable_substeps(&plant, ts);
        Ok(Self {
            plant,
            law: BrakingLaw::new(p, voltage, ts),
            ts,
            substeps,
            latency_periods,
            voltage,
        })
    }

    /// The farthest arm angle (rad) along its motion from state `x` (the pendulum's angle 0
    /// upright) with `applied` (V) across the motor until the stop's first command (class
    /// docs); `x[0]` for an arm at rest, ±∞ for one the stop cannot bring to rest.
    pub fn stopping_point(&self, x: State, applied: f64) -> f64 {
        let dir = x[1].signum();
        if x[1] == 0.0 || !x.iter().all(|v| v.is_finite()) {
            return x[0];
        }
        let along = applied.clamp(-self.voltage, self.voltage);
        let held = if along * dir > 0.0 {
            along
        } else {
            SIMULATED_BRAKE_FRACTION * along
        };
        let mut x = x;
        let mut far = x[0];
        let outwards = |x: &State| x[1] * dir > 0.0;
        for _ in 0..self.latency_periods {
            self.plant
                .advance(&mut x, held, 0.0, self.ts, self.substeps);
            far = if dir > 0.0 {
                far.max(x[0])
            } else {
                far.min(x[0])
            };
        }
        let mut last = x[0];
        let mut rate = x[1];
        let periods = (SIMULATED_STOP_S / self.ts).ceil() as usize;
        let rest = (SIMULATED_REST_S / self.ts).ceil() as u32;
        let (mut still, mut escaping) = (0, 0);
        for _ in 0..periods {
            let u = SIMULATED_BRAKE_FRACTION * self.law.voltage(rate);
            self.plant.advance(&mut x, u, 0.0, self.ts, self.substeps);
            rate = (x[0] - last) / self.ts;
            last = x[0];
            far = if dir > 0.0 {
                far.max(x[0])
            } else {
                far.min(x[0])
            };
            if !far.is_finite() {
                break;
            }
            // At rest, or on its way back, for long enough that the pendulum's reaction has
            // had its swing to push the arm out again.
            if outwards(&x) && x[1].abs() > SIMULATED_REST_RATE {
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
            dir * f64::INFINITY
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
    let substeps = stable_substeps(plant, ts);
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

/// RK4 substeps per sample `ts` (s) within `plant`'s stability limit
/// ([`Plant::max_rk4_substep`]), between 1 and 1000.
fn stable_substeps(plant: &Plant, ts: f64) -> usize {
    (ts / plant.max_rk4_substep()).ceil().clamp(1.0, 1000.0) as usize
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

    /// The simulated stop from the whole state bounds the farthest point of the nonlinear
    /// plant (Coulomb friction and all) braked by the full law, from states of the swing-up
    /// and of a catch; and on a controlled catch it stops the arm well before the analytic
    /// distance, which reserves half the torque for the pendulum.
    #[test]
    fn the_simulated_stop_bounds_the_plant_braked_from_its_whole_state() {
        let ts = 0.01;
        for p in [FurutaParams::qube_servo2(), FurutaParams::paper()] {
            let rough = FurutaParams {
                cr: 0.004,
                cp: 2e-5,
                vd: 0.3,
                ..p
            };
            let plant = Plant::new(rough).unwrap();
            let sim = SimulatedStop::new(&rough, 12.0, ts, 2).unwrap();
            let law = BrakingLaw::new(&rough, 12.0, ts);
            for (w, alpha, alpha_dot, applied) in [
                (15.7, 0.05, 1.0, -6.0),
                (15.7, 0.05, 1.0, 12.0),
                (8.0, std::f64::consts::PI, 0.0, 12.0),
                (8.0, 1.0, -6.0, 3.0),
                (-5.0, 2.5, 8.0, -12.0),
                (3.0, -0.4, 5.0, 0.0),
                (17.18, 0.05, 1.0, 12.0),
            ] {
                let predicted = sim.stopping_point(State::new(0.0, w, alpha, alpha_dot), applied);
                let mut x = State::new(0.0, w, alpha, alpha_dot);
                let (mut far, mut last, mut rate) = (0.0f64, 0.0, w);
                for k in 0..400 {
                    let u = if k < 2 { applied } else { law.voltage(rate) };
                    plant.advance(&mut x, u, 0.0, ts, 50);
                    rate = (x[0] - last) / ts;
                    last = x[0];
                    far = if w > 0.0 {
                        far.max(x[0])
                    } else {
                        far.min(x[0])
                    };
                }
                assert!(x[1].abs() < 0.5, "not at rest: {x:?}");
                assert!(
                    far.abs() <= predicted.abs(),
                    "{w} {alpha}: {far} > {predicted}"
                );
            }
        }
        // The catch of the QUBE: upright, the arm at 15.7 rad/s with the controller braking.
        let p = FurutaParams::qube_servo2();
        let analytic = StoppingModel::new(&p, 12.0, STOP_BRAKE_FRACTION, 2.0 * ts);
        let sim = SimulatedStop::new(&p, 12.0, ts, 2).unwrap();
        let x = State::new(-0.18, 15.7, 0.05, 1.0);
        // The analytic distance stops this arm (exit 5 in 3 of 60 emulated swing-ups); the
        // simulated one, full voltage along the motion for the latency and all, does not.
        assert!(analytic.stopping_point(-0.18, 15.7, 12.0) > 2.95);
        let simulated = sim.stopping_point(x, 12.0);
        assert!(simulated < 2.5, "{simulated}");
        assert!(sim.stopping_point(x, -6.0) < simulated);
        // The fastest catch seen (17.2 rad/s): the pendulum falls as the arm brakes and swings
        // on for seconds, and the arm with it, inside.
        let fastest = sim.stopping_point(State::new(-0.182, 17.18, 0.05, 1.0), 12.0);
        assert!(fastest < 2.95, "{fastest}");
        assert_eq!(
            sim.stopping_point(State::new(0.3, 0.0, 0.0, 0.0), 12.0),
            0.3
        );
    }
}
