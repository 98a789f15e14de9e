//! The design of the arm's stop for a plant: the stopping model, the braking and hold laws'
//! gains, the simulated stop and the gentle end's lowering, each filled from the plant's
//! lumped constants into the run-time types of [`rip_control::stop`], which run the rule on
//! the host, in `rip-rt` and on the device. One definition for every bound on the arm's
//! travel: the swing-up's limit ([`crate::swingup`]) and the stops of `rip-rt`
//! (`safety.arm_limit`).
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
use rip_control::swing::ArmModel;

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

/// The arm's stopping model (module docs, (1)–(3)): the `no_std` one the swing-up
/// supervisor, the stop and the device evaluate, defined once in `rip-control`; rip-core
/// designs it for a plant ([`stopping_model`]).
pub use rip_control::swing::StoppingModel;

/// The stopping model of plant `p` braked at `voltage` (V) with the share `fraction` of (1),
/// the stop starting `latency` seconds after the state was measured.
pub fn stopping_model(
    p: &FurutaParams,
    voltage: f64,
    fraction: f64,
    latency: f64,
) -> StoppingModel {
    let l = p.lumped();
    let j = l.arm_axis();
    let j_min = l.arm_min();
    let b = p.kt / p.rm;
    let c = p.dr + p.kt * p.km / p.rm;
    StoppingModel {
        a0: fraction * b * voltage / j,
        k: fraction * c / j,
        drive_per_volt: b / j_min,
        latency,
        voltage,
    }
}

/// The stop's braking law ([`rip_control::stop::BrakingLaw`]).
pub use rip_control::stop::BrakingLaw;

/// The braking law of plant `p` at voltage bound `voltage` (V) and loop period `ts` (s):
/// `ω_lin = U / K` with `K = J / (2 b T_s)`, the gain that removes half the arm's speed per
/// period on the model (a faster gain would overshoot through the loop's delay).
pub fn braking_law(p: &FurutaParams, voltage: f64, ts: f64) -> BrakingLaw {
    let gain = p.lumped().arm_axis() / (2.0 * p.kt / p.rm * ts);
    BrakingLaw {
        voltage,
        linear_below: voltage / gain,
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
/// [`HoldLaw::arm_voltage`](rip_control::stop::HoldLaw::arm_voltage) uses the arm's terms alone: a stiff, damped position loop.
pub use rip_control::stop::HoldLaw;

/// `θ_m` of [`HoldLaw`] (rad): the arm's deviation from its hold point weighed against a
/// full-voltage command.
pub const HOLD_ARM_RAD: f64 = 0.05;
/// `φ_m` of [`HoldLaw`] (rad): the pendulum's swing weighed against a full-voltage command.
pub const HOLD_PENDULUM_RAD: f64 = 0.5;

/// The hold law of plant `p` at voltage bound `voltage` (V) and loop period `ts` (s) ([`HoldLaw`]
/// above: Bryson's weights [`HOLD_ARM_RAD`], [`HOLD_PENDULUM_RAD`]).
pub fn hold_law(p: &FurutaParams, voltage: f64, ts: f64) -> crate::error::Result<HoldLaw> {
    let q = [
        1.0 / (HOLD_ARM_RAD * HOLD_ARM_RAD),
        0.0,
        1.0 / (HOLD_PENDULUM_RAD * HOLD_PENDULUM_RAD),
        0.0,
    ];
    hold_law_with_weights(p, voltage, ts, q)
}

/// The law of [`HoldLaw`] with `Q = diag(q)` on `z = (θ − θ_h, θ̇, φ, α̇)` ([`Lowering`]
/// searches over it).
pub fn hold_law_with_weights(
    p: &FurutaParams,
    voltage: f64,
    ts: f64,
    q: [f64; 4],
) -> crate::error::Result<HoldLaw> {
    use crate::linalg::Mat;
    let plant = Plant::new(*p)?;
    let hanging = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    let (a, b) = plant.linearize_discrete(&hanging, 0.0, ts)?;
    let q = Mat::from_diagonal(&nalgebra::DVector::from_vec(q.to_vec()));
    let r = Mat::from_element(1, 1, 1.0 / (voltage * voltage).max(1e-6));
    let design = crate::lqr::dlqr(&a, &b, &q, &r, None)?;
    Ok(HoldLaw {
        k: std::array::from_fn(|i| design.k[(0, i)]),
        voltage,
    })
}

/// The gentle end of a run: the balanced pendulum lowered to hanging at rest under control,
/// the arm brought to rest at its hold point (rip-rt's: the centre), before the driver is
/// disabled (rather than letting the pendulum fall and braking the arm against it).
///
/// The law is [`HoldLaw`]'s — the discrete LQR about the hanging equilibrium, run on the whole
/// circle (its pendulum term is ±π at upright, kept on one side by
/// [`pendulum_angle`](Self::pendulum_angle), so it tips the pendulum off at once, and then takes
/// the energy of its fall out through the arm) — with the weights
/// `Q = diag(1/θ_m², q_θ̇, 1/φ_m², q_α̇)` chosen per rig from [`LOWER_ARM_RAD`] ×
/// [`LOWER_RATE_WEIGHTS`] × [`LOWER_PENDULUM_RAD`] × [`LOWER_PENDULUM_RATE_WEIGHTS`] by
/// simulating the lowering on the model: from upright at rest (tilted by
/// [`LOWER_START_TILT`]), the command applied one period late, the law that settles first —
/// pendulum within [`LOWERED_PENDULUM_RAD`] of hanging and arm slower than
/// [`LOWERED_ARM_RATE`] from then on — among those whose arm stays within a given travel of
/// the hold point all along, refined weight by weight from the best of the
/// grid ([`LOWER_REFINE_STEP`]). Hand-picked weights settled the paper's rig in
/// 7 s and generated rigs in 2–7 s; the chosen ones take 1–4.3 s.
///
/// The travel bound is the design's; on the rig the loop's own braking envelope decides, as it
/// does while balancing: a lowering whose stopping point leaves `safety.arm_limit` gives way
/// to the braking law and the hold law of a fault's stop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lowering {
    /// The law.
    pub law: HoldLaw,
    /// Seconds the model takes to settle under it.
    pub seconds: f64,
    /// The arm's largest travel from its hold point on the model (rad).
    pub travel: f64,
    /// The diagonal of the law's `Q` on `(θ − θ_h, θ̇, φ, α̇)`.
    pub weights: [f64; 4],
}

/// Candidate `θ_m` of [`Lowering`] (rad).
pub const LOWER_ARM_RAD: [f64; 7] = [0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 3.2];
/// Candidate `φ_m` of [`Lowering`] (rad).
pub const LOWER_PENDULUM_RAD: [f64; 7] = [0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 3.2];
/// Candidate weights on `θ̇²` of [`Lowering`] (s²/rad²).
pub const LOWER_RATE_WEIGHTS: [f64; 3] = [0.0, 0.1, 0.5];
/// Candidate weights on `α̇²` of [`Lowering`] (s²/rad²).
pub const LOWER_PENDULUM_RATE_WEIGHTS: [f64; 3] = [0.0, 0.01, 0.05];
/// Factor by which [`Lowering`]'s design refines each weight after its grid.
pub const LOWER_REFINE_STEP: f64 = 1.5;
/// Rounds of that refinement at most.
pub const LOWER_REFINE_ROUNDS: usize = 6;
/// The weights the refinement starts a weight that is 0 on the grid from (divided or
/// multiplied by [`LOWER_REFINE_STEP`]).
pub const LOWER_REFINE_FLOOR: [f64; 4] = [0.1, 0.1, 0.1, 0.01];
/// The pendulum's tilt from upright (rad) that the design's simulation starts from.
pub const LOWER_START_TILT: f64 = 0.01;
/// Pendulum angle from hanging (rad) within which [`Lowering`]'s design counts it lowered:
/// half the 0.1 rad the end of a run is judged by, for the rig's difference from the model.
pub const LOWERED_PENDULUM_RAD: f64 = 0.05;
/// Arm speed (rad/s) below which [`Lowering`]'s design counts the arm at rest: half the
/// 0.2 rad/s the end of a run is judged by.
pub const LOWERED_ARM_RATE: f64 = 0.1;
/// Share of the room between the arm's envelope bound and the centre that a [`Lowering`]'s
/// design lets the arm travel: the rest is for the rig's difference from the model and for the
/// stopping distance the loop's envelope keeps.
pub const LOWER_TRAVEL_SHARE: f64 = 2.0 / 3.0;
/// The longest a lowering may take (s) ([`rip_control::stop::MAX_LOWER_S`]).
pub use rip_control::stop::MAX_LOWER_S;

impl Lowering {
    /// The lowering of plant `p` at voltage bound `voltage` (V) and loop period `ts` (s)
    /// (class docs), its arm kept within `max_travel` (rad) of where it starts; `None` when no
    /// candidate settles within [`MAX_LOWER_S`] inside it.
    pub fn design(
        p: &FurutaParams,
        voltage: f64,
        ts: f64,
        max_travel: f64,
    ) -> crate::error::Result<Option<Self>> {
        // The whole model, dead zone and Coulomb friction included: on a rig with a large
        // dead zone a law chosen on the smooth model swung the arm three times as far.
        let plant = Plant::new(*p)?;
        let substeps = (ts / plant.max_rk4_substep()).ceil().clamp(1.0, 1000.0) as usize;
        let periods = (MAX_LOWER_S / ts).ceil() as usize;
        let candidate = |q: [f64; 4]| -> Option<Self> {
            let law = hold_law_with_weights(p, voltage, ts, q).ok()?;
            let (seconds, travel) =
                Self::simulate(&plant, &law, ts, substeps, periods, max_travel)?;
            Some(Self {
                law,
                seconds,
                travel,
                weights: q,
            })
        };
        let faster = |a: Option<Self>, b: Option<Self>| match (a, b) {
            (Some(a), Some(b)) => Some(if b.seconds < a.seconds { b } else { a }),
            (a, b) => a.or(b),
        };
        let mut best: Option<Self> = None;
        for &arm_rad in &LOWER_ARM_RAD {
            for &pendulum_rad in &LOWER_PENDULUM_RAD {
                for &rate_weight in &LOWER_RATE_WEIGHTS {
                    for &pendulum_rate_weight in &LOWER_PENDULUM_RATE_WEIGHTS {
                        let q = [
                            1.0 / (arm_rad * arm_rad),
                            rate_weight,
                            1.0 / (pendulum_rad * pendulum_rad),
                            pendulum_rate_weight,
                        ];
                        best = faster(best, candidate(q));
                    }
                }
            }
        }
        // The grid is a decade wide per step: refine each weight in turn by factors of
        // LOWER_REFINE_STEP while that settles sooner (the pendulum's rate weight, 0 on the
        // grid, starts from a small one).
        let Some(mut found) = best else {
            return Ok(None);
        };
        for _ in 0..LOWER_REFINE_ROUNDS {
            let mut improved = false;
            for i in 0..4 {
                for factor in [LOWER_REFINE_STEP, 1.0 / LOWER_REFINE_STEP] {
                    let mut q = found.weights;
                    q[i] = if q[i] == 0.0 {
                        LOWER_REFINE_FLOOR[i] * factor
                    } else {
                        q[i] * factor
                    };
                    if let Some(c) = candidate(q).filter(|c| c.seconds < found.seconds) {
                        found = c;
                        improved = true;
                    }
                }
            }
            if !improved {
                break;
            }
        }
        Ok(Some(found))
    }

    /// The pendulum's angle from hanging (rad) that the lowering law takes
    /// ([`rip_control::stop::pendulum_angle`]).
    pub fn pendulum_angle(alpha: f64, side: &mut f64) -> f64 {
        rip_control::stop::pendulum_angle(alpha, side)
    }

    /// The settling time and the arm's largest travel of `law` on `plant` (class docs);
    /// `None` when it does not settle or its arm travels farther than `max_travel`.
    fn simulate(
        plant: &Plant,
        law: &HoldLaw,
        ts: f64,
        substeps: usize,
        periods: usize,
        max_travel: f64,
    ) -> Option<(f64, f64)> {
        let mut x = State::new(0.0, 0.0, LOWER_START_TILT, 0.0);
        let mut held = 0.0;
        let mut travel: f64 = 0.0;
        let mut settled_at = None;
        let mut side = 0.0;
        for k in 0..periods {
            let phi = Self::pendulum_angle(x[2], &mut side);
            let u = law.voltage_from_hanging(x[0], x[1], phi, x[3]);
            plant.advance(&mut x, held, 0.0, ts, substeps);
            held = u;
            travel = travel.max(x[0].abs());
            if travel.is_nan() || travel > max_travel {
                return None;
            }
            let phi = crate::trig::wrap_angle(x[2] - std::f64::consts::PI);
            let settled = phi.abs() <= LOWERED_PENDULUM_RAD && x[1].abs() <= LOWERED_ARM_RATE;
            settled_at = match (settled, settled_at) {
                (true, None) => Some(k + 1),
                (true, at) => at,
                (false, _) => None,
            };
        }
        settled_at.map(|k| (k as f64 * ts, travel))
    }
}

pub use rip_control::stop::{
    SimulatedStop, StopDesign, MAX_BRAKE_S, SIMULATED_BRAKE_FRACTION, SIMULATED_REST_RATE,
    SIMULATED_REST_S,
};

/// The arm's stop of a plant, designed at once by [`design_stop`]: what rip-rt's stop runs on
/// the host (the braking law with its dead band, the hold law, the arm's model for its
/// momentum, the simulated stop of the envelope and the modelled brake) and, from the same
/// parts, what a device runs ([`StopParts::device`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopParts {
    /// The braking law ([`braking_law`]).
    pub law: BrakingLaw,
    /// Below this arm rate (rad/s) the braking law applies 0 V.
    pub dead_band: f64,
    /// The hold law ([`hold_law`]), where the plant's LQR about hanging exists.
    pub hold: Option<HoldLaw>,
    /// The plant's arm model (the arm's momentum in the stop's sequence).
    pub model: ArmModel,
    /// The stop simulated from the whole state ([`simulated_stop`]).
    pub simulated: SimulatedStop,
    /// The plant's dead zone (V).
    pub dead_zone: f64,
}

impl StopParts {
    /// What a device needs to run the stop itself ([`StopDesign`]); `None` without a hold law
    /// or where the parts do not make a valid design (a non-finite dead band).
    pub fn device(&self) -> Option<StopDesign> {
        let design = StopDesign {
            law: self.law,
            dead_band: self.dead_band,
            hold: self.hold?,
            model: self.model,
            dead_zone: self.dead_zone,
        };
        design.validate().ok().map(|()| design)
    }
}

/// The stop of plant `p` braked at the voltage bound `voltage` (V) every loop period `ts`
/// (s), its braking law applying 0 V below `dead_band` (rad/s), the applied voltage acting for
/// `latency_periods` periods before the stop's first command: [`braking_law`], [`hold_law`],
/// the plant's arm model, [`simulated_stop`] and the dead zone ([`StopParts`]).
///
/// # Errors
/// A plant the model refuses.
pub fn design_stop(
    p: &FurutaParams,
    voltage: f64,
    ts: f64,
    dead_band: f64,
    latency_periods: usize,
) -> crate::error::Result<StopParts> {
    Ok(StopParts {
        law: braking_law(p, voltage, ts),
        dead_band,
        hold: hold_law(p, voltage, ts).ok(),
        model: Plant::new(*p)?.arm_model(),
        simulated: simulated_stop(p, voltage, ts, latency_periods)?,
        dead_zone: p.vd,
    })
}

/// The simulated stop ([`SimulatedStop`]) of plant `p` braked at `voltage` (V), sampled every
/// `ts` (s), the applied voltage acting for `latency_periods` periods before the braking law:
/// the smooth model of `p` with its dead zone, integrated within its RK4 stability limit.
pub fn simulated_stop(
    p: &FurutaParams,
    voltage: f64,
    ts: f64,
    latency_periods: usize,
) -> crate::error::Result<SimulatedStop> {
    let smooth = FurutaParams {
        cr: 0.0,
        cp: 0.0,
        ..*p
    };
    let plant = Plant::new(smooth)?;
    Ok(SimulatedStop {
        model: plant.arm_model(),
        dead_zone: p.vd,
        law: braking_law(p, voltage, ts),
        ts,
        substeps: stable_substeps(&plant, ts) as u32,
        latency_periods: u32::try_from(latency_periods).unwrap_or(u32::MAX),
    })
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

    /// The lowering found for the presets and generated rigs, replayed on the whole model with
    /// ten times finer steps and the command one period late: the pendulum hangs within
    /// 0.1 rad and the arm moves slower than 0.2 rad/s within 5 s of the start, and the arm
    /// stays inside the default safety.arm_limit's envelope.
    #[test]
    fn the_lowering_brings_a_balanced_pendulum_down_within_five_seconds() {
        let ts = 0.01;
        let mut rigs = vec![
            ("paper".to_string(), FurutaParams::paper()),
            ("qube_servo2".to_string(), FurutaParams::qube_servo2()),
        ];
        rigs.extend(
            (0..8).map(|seed| (format!("rig {seed}"), crate::rig::Rig::random(seed).params)),
        );
        for (name, p) in rigs {
            let voltage = 10.0;
            // The design's share of the default safety.arm_limit's envelope (3 − 0.05 rad).
            let limit = 2.95;
            let room = LOWER_TRAVEL_SHARE * limit;
            let lowering = Lowering::design(&p, voltage, ts, room)
                .unwrap()
                .unwrap_or_else(|| panic!("{name}: no lowering"));
            assert!(lowering.seconds < 5.0, "{name}: {lowering:?}");
            let plant = Plant::new(p).unwrap();
            let substeps = 10 * (ts / plant.max_rk4_substep()).ceil() as usize;
            for tilt in [LOWER_START_TILT, -0.03] {
                let mut x = State::new(0.0, 0.0, tilt, 0.0);
                let mut held = 0.0;
                let mut last_unsettled = 0.0;
                let mut side = 0.0;
                for k in 0..(MAX_LOWER_S / ts) as usize {
                    let phi = Lowering::pendulum_angle(x[2], &mut side);
                    let u = lowering.law.voltage_from_hanging(x[0], x[1], phi, x[3]);
                    plant.advance(&mut x, held, 0.0, ts, substeps);
                    held = u;
                    assert!(x[0].abs() < limit, "{name}: arm {} at {k}", x[0]);
                    let phi = crate::trig::wrap_angle(x[2] - std::f64::consts::PI);
                    if phi.abs() > 0.1 || x[1].abs() > 0.2 {
                        last_unsettled = (k + 1) as f64 * ts;
                    }
                }
                assert!(
                    last_unsettled < 5.0,
                    "{name} {tilt}: settled at {last_unsettled} s"
                );
                println!(
                    "{name}: designed {:.2} s, replayed {last_unsettled:.2} s",
                    lowering.seconds
                );
            }
        }
    }

    /// The device's stop design is the laws the host's stop runs, and travels unchanged.
    #[test]
    fn the_stop_design_is_the_hosts_laws_and_travels_whole() {
        for p in [FurutaParams::paper(), FurutaParams::qube_servo2()] {
            let parts = design_stop(&p, 10.0, 0.01, 0.46, 2).unwrap();
            assert_eq!(parts.simulated, simulated_stop(&p, 10.0, 0.01, 2).unwrap());
            let d = parts.device().unwrap();
            assert_eq!(d.law, braking_law(&p, 10.0, 0.01));
            assert_eq!(d.hold, hold_law(&p, 10.0, 0.01).unwrap());
            assert_eq!(d.model, Plant::new(p).unwrap().arm_model());
            let mut bytes = [0u8; rip_control::stop::STOP_DESIGN_LEN];
            d.write(&mut bytes).unwrap();
            assert_eq!(StopDesign::read(&bytes).unwrap(), d);
        }
        let parts = design_stop(&FurutaParams::paper(), 10.0, 0.01, f64::NAN, 2).unwrap();
        assert!(parts.device().is_none());
        let no_hold = StopParts {
            hold: None,
            ..design_stop(&FurutaParams::paper(), 10.0, 0.01, 0.46, 2).unwrap()
        };
        assert!(no_hold.device().is_none());
    }

    /// (2) against a direct integration of (1), and the limits it must have.
    #[test]
    fn the_braking_distance_is_the_integral_of_the_deceleration() {
        let p = FurutaParams::qube_servo2();
        let m = stopping_model(&p, 12.0, 0.5, 0.0);
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
        let with_latency = stopping_model(&p, 12.0, 0.5, 0.02);
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
            let model = stopping_model(&p, 12.0, STOP_BRAKE_FRACTION, 2.0 * ts);
            let law = braking_law(&p, 12.0, ts);
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
            let sim = simulated_stop(&rough, 12.0, ts, 2).unwrap();
            let law = braking_law(&rough, 12.0, ts);
            for (w, alpha, alpha_dot, applied) in [
                (15.7, 0.05, 1.0, -6.0),
                (15.7, 0.05, 1.0, 12.0),
                (8.0, std::f64::consts::PI, 0.0, 12.0),
                (8.0, 1.0, -6.0, 3.0),
                (-5.0, 2.5, 8.0, -12.0),
                (3.0, -0.4, 5.0, 0.0),
                (17.18, 0.05, 1.0, 12.0),
            ] {
                let predicted = sim.stopping_point([0.0, w, alpha, alpha_dot], applied);
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
        let analytic = stopping_model(&p, 12.0, STOP_BRAKE_FRACTION, 2.0 * ts);
        let sim = simulated_stop(&p, 12.0, ts, 2).unwrap();
        let x = State::new(-0.18, 15.7, 0.05, 1.0);
        // The analytic distance stops this arm (exit 5 in 3 of 60 emulated swing-ups); the
        // simulated one, full voltage along the motion for the latency and all, does not.
        assert!(analytic.stopping_point(-0.18, 15.7, 12.0) > 2.95);
        let simulated = sim.stopping_point(x.into(), 12.0);
        assert!(simulated < 2.5, "{simulated}");
        assert!(sim.stopping_point(x.into(), -6.0) < simulated);
        // The fastest catch seen (17.2 rad/s): the pendulum falls as the arm brakes and swings
        // on for seconds, and the arm with it, inside.
        let fastest = sim.stopping_point([-0.182, 17.18, 0.05, 1.0], 12.0);
        assert!(fastest < 2.95, "{fastest}");
        assert_eq!(sim.stopping_point([0.3, 0.0, 0.0, 0.0], 12.0), 0.3);
    }
}
