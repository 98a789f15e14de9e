//! `safety.arm_limit` for the arm, not for its last measurement: the braking envelope that
//! decides when the loop must stop, and the active stop that brings the arm to rest.
//!
//! # The envelope ([`ArmEnvelope`])
//!
//! Every period the arm's rate is the difference of its last two measured angles over the
//! device's clock between them (its sampling instants, not the host's wake-ups), and its
//! stopping point `θ + sgn(θ̇) D(|θ̇|)` the one of `rip_core::envelope`: braked at
//! `safety.voltage_limit` with half the braking deceleration counted on
//! ([`rip_core::envelope::STOP_BRAKE_FRACTION`]), two periods of latency at full drive, and the largest inertia
//! of the arm, all on the configuration's `[plant]` (a preset until the rig is identified).
//! Where that point is past `safety.arm_limit − ENVELOPE_MARGIN`, the stop is simulated from
//! the whole measured state ([`SimulatedStop`](rip_control::stop::SimulatedStop): the
//! pendulum's reaction on the arm from the model, not a share of the torque reserved for it),
//! and the run stops
//! ([`StopReason::ArmEnvelope`], exit 5) in the period the simulated stopping point is past
//! it too, so that the stop that follows ends inside the limit. A controlled catch, whose
//! arm moves fast with the pendulum near upright, is not stopped by the analytic distance's
//! reserve. The position rule (`|θ| > safety.arm_limit`, [`StopReason::AngleLimit`]) stays
//! as a last resort.
//!
//! # The active stop ([`crate::braking::bring_to_rest`])
//!
//! Whatever ended the run, the arm is then braked to rest before the driver is disabled: the
//! braking law of `rip_core::envelope` (full voltage against the arm's measured motion,
//! proportional near rest) until the arm has stood still for [`REST_S`], at most
//! [`MAX_BRAKE_S`]; then the stop frame. When the run ended because the rig's motion or its
//! device cannot be trusted (a failed sign check, a driver fault, a fault of the wiring), a
//! voltage could drive the arm the wrong way: the stop sends the brake command instead
//! (`COMMAND_BRAKE`: the windings shorted, which brakes whatever the wiring's sign) for as
//! long. A period without a measurement (a lost reply, a silent device) gets the brake command
//! too, and the law resumes once measurements return (the period after the gap shorted as well,
//! its rate a mean over the gap); a short kept after a gap left the pendulum free to walk the
//! arm past the limit. A device
//! that cannot brake (protocol.md rule 9) leaves the windings open on it; the active law does
//! not depend on it.

use rip_core::envelope::{Lowering, StoppingModel};
use rip_core::excitation::ExcitationSettings;
use rip_core::plant::State;

use crate::config::{Config, ConfigError, MAX_VOLTAGE_LIMIT};
use crate::stop::StopReason;
use crate::witness::WitnessFault;

/// The stop's rule, defined once in the `no_std` run-time layer ([`rip_control::stop`]).
pub use rip_control::stop::{
    momentum_rate, sample_rates, ArmEnvelope, Brake, BrakeCommand, BrakeMode, Breach, CouplingTest,
    RestTest, StopDesign, StopSequence, HOLD_BLIND_PERIODS, HOLD_GIVE_UP_RAD, LOWERED_HANGING_RAD,
    LOWER_FROM_RAD, LOWER_SIDE_FROM_RAD, MAX_BRAKE_S, MAX_HOLD_S, MAX_LOWER_S,
    MOMENTUM_ENERGY_GAIN, PENDULUM_REST_RAD, PROGRESS_PERIODS, REST_S, REST_TRAVEL,
    WRONG_SIGN_PERIODS,
};
pub use rip_core::envelope::StopParts;
pub use rip_core::preflight::motion::{ENVELOPE_MARGIN, LATENCY_PERIODS, PREFLIGHT_HEADROOM};

/// The stopping model of a configuration: its `[plant]`, `safety.voltage_limit`, two loop
/// periods of latency (rip-core's [`rip_core::preflight::motion::stopping_model`]).
pub fn stopping_model(cfg: &Config) -> StoppingModel {
    rip_core::preflight::motion::stopping_model(&cfg.spec, &cfg.rig())
}

/// The envelope's bound on the stopping point: `safety.arm_limit − ENVELOPE_MARGIN`
/// ([`rip_core::preflight::motion::envelope_limit`]).
pub fn envelope_limit(cfg: &Config) -> f64 {
    rip_core::preflight::motion::envelope_limit(&cfg.rig())
}

/// The gentle end's law of `cfg` ([`Lowering`]): designed on `[plant]` at
/// `safety.voltage_limit` and the loop's period, its arm's travel within
/// [`rip_core::envelope::LOWER_TRAVEL_SHARE`] of [`envelope_limit`]; `None` without a plant or
/// where no law settles.
pub fn lowering(cfg: &Config) -> Option<Lowering> {
    let room = rip_core::envelope::LOWER_TRAVEL_SHARE * envelope_limit(cfg);
    Lowering::design(
        &cfg.spec.plant.params(),
        stop_voltage(cfg),
        cfg.period_s(),
        room,
    )
    .ok()
    .flatten()
}

/// The voltage the stops of `cfg` brake with: `safety.voltage_limit` within the driver's.
fn stop_voltage(cfg: &Config) -> f64 {
    cfg.safety.voltage_limit.clamp(0.0, MAX_VOLTAGE_LIMIT)
}

/// The stop of `cfg`, designed by rip-core in one ([`rip_core::envelope::design_stop`]):
/// `[plant]` braked at `safety.voltage_limit` every loop period, the braking law's dead band
/// of `[device]`'s arm encoder, [`LATENCY_PERIODS`] of latency; `None` for a plant the model
/// refuses. Every part of the stop below comes from it.
pub fn stop_parts(cfg: &Config) -> Option<StopParts> {
    rip_core::envelope::design_stop(
        &cfg.spec.plant.params(),
        stop_voltage(cfg),
        cfg.period_s(),
        dead_band(cfg),
        LATENCY_PERIODS as usize,
    )
    .ok()
}

/// The braking envelope of `safety.arm_limit` in the loop (module docs): the stopping model
/// of `cfg` and the simulated stop of its stop's `parts` ([`stop_parts`]) on
/// [`envelope_limit`].
pub fn arm_envelope(cfg: &Config, parts: Option<&StopParts>) -> ArmEnvelope {
    ArmEnvelope::new(
        stopping_model(cfg),
        parts.map(|p| p.simulated),
        envelope_limit(cfg),
    )
}

/// The envelope's breach is the run's stop ([`StopReason::ArmEnvelope`], exit 5), reported
/// against `safety.arm_limit` (the bound plus [`ENVELOPE_MARGIN`]).
impl From<Breach> for StopReason {
    fn from(b: Breach) -> Self {
        StopReason::ArmEnvelope {
            angle: b.angle,
            rate: b.rate,
            stop_at: b.stop_at,
            limit: b.bound + ENVELOPE_MARGIN,
        }
    }
}

/// Refuses a swing-up whose arm could not be stopped inside `safety.arm_limit` from every
/// state its own envelope lets the arm into ([`rip_core::preflight::check_swing_up`]). The
/// error names `swing_up.arm_limit` and the largest value that passes, or `safety.arm_limit`
/// with the least value that passes when the swing-up's is its default.
pub fn check_swing_up(cfg: &Config) -> Result<(), ConfigError> {
    rip_core::preflight::check_swing_up(&cfg.spec, &cfg.rig())
}

/// Refuses an excitation that would come within [`PREFLIGHT_HEADROOM`] of the braking
/// envelope of `safety.arm_limit` on the `[plant]` of `model` (the configuration's, or the
/// preset's it was built from without one), by [`rip_core::preflight::check_excitation`]. The
/// error names `--amplitude` and gives the largest amplitude that passes.
pub fn check_excitation(
    cfg: &Config,
    settings: &ExcitationSettings,
    model: &str,
) -> Result<(), ConfigError> {
    rip_core::preflight::check_excitation(&cfg.spec, &cfg.rig(), settings, model)
}

/// How the stop after `reason` brakes (module docs).
pub fn brake_mode(reason: &StopReason) -> BrakeMode {
    match reason {
        StopReason::Finished
        | StopReason::Signal(_)
        | StopReason::SignalAgain { .. }
        | StopReason::AngleLimit { .. }
        | StopReason::ArmEnvelope { .. }
        | StopReason::Fell { .. }
        | StopReason::SwingUpFailed { .. }
        | StopReason::SwingUpRetriesExhausted { .. }
        | StopReason::SwingUpRunTimeout { .. }
        | StopReason::ControllerFault { .. }
        | StopReason::LogError(_)
        | StopReason::Watchdog(_)
        | StopReason::Panic => BrakeMode::Active,
        // The arm's response to the voltage has the wrong sign, and its encoder counts: brake
        // with the sign the rig showed ([`Brake`] falls back to the short if that is wrong).
        StopReason::Witness(fault) if fault.reversed() => BrakeMode::Reversed,
        // The arm encoder stopped counting: brake the arm's momentum carried by the torque.
        StopReason::Witness(WitnessFault::ArmFrozen { .. }) => BrakeMode::Modelled,
        // The arm encoder counts, but its motion disagrees with the model's: brake with the
        // model's sign and check it on the response (the short alone cannot stop a light arm
        // on a weak motor against its swinging pendulum).
        StopReason::Witness(
            WitnessFault::ArmDisagrees { .. } | WitnessFault::PendulumDisagrees { .. },
        ) => BrakeMode::Checked,
        // The host's timing cannot be trusted to close a loop (a slow step, missed
        // deadlines, a stall): short the windings rather than drive.
        StopReason::Overrun(_) => BrakeMode::Short,
        StopReason::DeviceLost(_)
        | StopReason::TooSlow { .. }
        | StopReason::NotUpright { .. }
        | StopReason::NotAtRest(_) => BrakeMode::None,
        // The sign check, a driver fault and any other fault of the rig's motion: no voltage
        // can be trusted to oppose the motion.
        _ => BrakeMode::Short,
    }
}

/// How the stop after `reason` brakes a run that was `driven` (else nothing is sent:
/// [`BrakeMode::None`]) and whose wiring's sign is `wiring_checked` or not. Before a sign
/// check has passed, a reversed motor lead or arm encoder is as likely as a right one, so a
/// law that would trust the sign ([`BrakeMode::Active`]) brakes as [`BrakeMode::Checked`]
/// instead: with the model's sign, flipped once if the arm speeds up under it, then the short.
pub fn stop_mode(reason: &StopReason, driven: bool, wiring_checked: bool) -> BrakeMode {
    match brake_mode(reason) {
        _ if !driven => BrakeMode::None,
        BrakeMode::Active if !wiring_checked => BrakeMode::Checked,
        mode => mode,
    }
}

/// One encoder count and a half per period (rad/s) on the arm of `cfg`: below it the measured
/// rate is the encoder's quantisation, and the braking law would chatter between ± its gain
/// per count.
fn dead_band(cfg: &Config) -> f64 {
    1.5 * std::f64::consts::TAU / cfg.device.arm_counts_per_rev.max(1) as f64 / cfg.period_s()
}

/// The stop braking in `mode` ([`Brake`]) with the braking law of its `parts`
/// ([`stop_parts`]); the short alone without them (a plant the model refuses).
pub fn brake(parts: Option<&StopParts>, mode: BrakeMode) -> Brake {
    match parts {
        Some(p) => Brake::new(p.law, p.dead_band, mode),
        None => short(),
    }
}

/// The short alone: [`BrakeMode::Short`] never applies its law.
fn short() -> Brake {
    let law = rip_control::stop::BrakingLaw {
        voltage: 0.0,
        linear_below: 1.0,
    };
    Brake::new(law, 0.0, BrakeMode::Short)
}

/// The stop braking in `mode` with its `parts`: in [`BrakeMode::Modelled`] the law on the
/// arm's momentum from the witness's `estimate` with `held` (V) still applied for the period
/// until the stop's first command, carried by the simulated stop's model (the short without
/// parts), else [`brake`].
pub fn brake_for_mode(
    parts: Option<&StopParts>,
    mode: BrakeMode,
    estimate: Option<State>,
    held: f64,
) -> Brake {
    match (mode, parts) {
        (BrakeMode::Modelled, Some(p)) => {
            Brake::modelled(&p.simulated, p.dead_band, estimate.map(Into::into), held)
        }
        (BrakeMode::Modelled, None) => short(),
        (mode, parts) => brake(parts, mode),
    }
}

/// What the device needs to run the stop of `cfg` itself ([`StopDesign`]): the parts of
/// [`stop_parts`]; `None` without a plant or a hold law.
pub fn stop_design(cfg: &Config) -> Option<StopDesign> {
    stop_parts(cfg)?.device()
}

/// The stop of `cfg` with `brake` ([`StopSequence`]): the hold law and the arm's model of its
/// `parts` ([`stop_parts`]).
pub fn stop_sequence(cfg: &Config, parts: Option<&StopParts>, brake: Brake) -> StopSequence {
    let stop = StopSequence::new(
        brake,
        parts.and_then(|p| p.hold),
        parts.map(|p| p.model),
        cfg.period_s(),
        stop_voltage(cfg),
    );
    match parts {
        Some(p) => stop.coupling_test(CouplingTest::new(
            p.model,
            cfg.period_s(),
            cfg.reading_sigma(),
        )),
        None => stop,
    }
}

/// What an active stop did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrakeReport {
    /// How it braked.
    pub mode: BrakeMode,
    /// Seconds until the arm was at rest (or the stop gave up, [`MAX_BRAKE_S`]).
    pub seconds: f64,
    /// The largest arm rate measured while braking (rad/s).
    pub max_rate: f64,
    /// The arm came to rest.
    pub at_rest: bool,
    /// The stop signal that cut the stop short (the driver then disabled at once), if any.
    pub cut_short: Option<i32>,
    /// The gentle end brought the pendulum down and the arm to rest (no braking).
    pub lowered: bool,
    /// The fault the witness found while the gentle end lowered the pendulum, which then
    /// stopped as after that fault.
    pub witness: Option<WitnessFault>,
}

impl std::fmt::Display for BrakeReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let how = match self.mode {
            BrakeMode::Active => "braked at the voltage bound",
            BrakeMode::Reversed => "braked at the voltage bound with the sign the arm showed",
            BrakeMode::Checked => {
                "braked at the voltage bound, the sign checked on the arm's response"
            }
            BrakeMode::Modelled => {
                "braked at the voltage bound on the arm's momentum from the torque (the arm \
                 encoder not counting)"
            }
            BrakeMode::Short => "braked with the windings shorted",
            BrakeMode::None => return write!(f, "no braking (motor not driven)"),
        };
        if let Some(sig) = self.cut_short {
            return write!(
                f,
                "{how} for {:.2} s (arm rate up to {:.2} rad/s), cut short by {}: \
                 the driver disabled before the arm was at rest",
                self.seconds,
                self.max_rate,
                crate::stop::signal_name(sig)
            );
        }
        if self.lowered {
            return write!(
                f,
                "lowered the pendulum to hanging and the arm to rest in {:.2} s (arm rate up \
                 to {:.2} rad/s)",
                self.seconds, self.max_rate
            );
        }
        let end = if self.at_rest {
            "to rest"
        } else {
            "without reaching rest"
        };
        write!(
            f,
            "{how} {end} in {:.2} s (arm rate up to {:.2} rad/s)",
            self.seconds, self.max_rate
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rip_core::excitation::Signal;

    /// The default rig's stop braking in `mode`: [`brake`] with its [`stop_parts`].
    fn brake_in(mode: BrakeMode) -> Brake {
        brake(stop_parts(&Config::from_toml("").unwrap()).as_ref(), mode)
    }

    /// Spins the paper rig's arm to `speed` (rad/s), then runs `brake` on it for 2 s, the
    /// motor's leads swapped if `reversed`, the reading that of a 2048-count encoder; the
    /// arm's travel from the stop's start and its final speed.
    fn braked(mut brake: Brake, reversed: bool, speed: f64) -> (f64, f64) {
        use crate::plant::{Model, PlantSim, Windings};
        let cfg = Config::from_toml("").unwrap();
        let ts = cfg.period_s();
        let q = std::f64::consts::TAU / 2048.0;
        let mut sim = PlantSim::new(Model::Paper, 0.0, std::f64::consts::PI);
        sim.set_state([0.0, speed, std::f64::consts::PI, 0.0]);
        let read = |x: [f64; 4]| (x[0] / q).round() * q;
        let mut last = read(sim.state());
        let mut travel: f64 = 0.0;
        for _ in 0..200 {
            let theta = read(sim.state());
            let rate = (theta - last) / ts;
            last = theta;
            let w = match brake.command(Some(rate)) {
                BrakeCommand::Volts(v) => Windings::Driven(if reversed { -v } else { v }),
                BrakeCommand::Short => Windings::Shorted,
            };
            sim.step_windings(w, ts);
            travel = travel.max(sim.state()[0].abs());
        }
        (travel, sim.state()[1])
    }

    #[test]
    fn a_reversed_rig_is_braked_by_the_reversed_law_and_a_wrong_diagnosis_falls_back_to_the_short()
    {
        // The law as it stands drives a reversed rig away; reversed, it brakes it, as far as
        // the trusted law brakes a rig wired right.
        let (right, v_right) = braked(brake_in(BrakeMode::Active), false, 10.0);
        let (rev, v_rev) = braked(brake_in(BrakeMode::Reversed), true, 10.0);
        assert!(
            v_right.abs() < 0.1 && v_rev.abs() < 0.1,
            "{v_right} {v_rev}"
        );
        assert!((rev - right).abs() < 0.05 * right, "{rev} vs {right}");
        // The reversed law on a rig wired right speeds the arm up: the stop shorts instead
        // after a few periods (here 9.2 rad of travel from 10 rad/s, against 6.9 rad for the
        // short alone and 1.4 rad for the law with the right sign).
        let (short, _) = braked(brake_in(BrakeMode::Short), false, 10.0);
        let (travel, v) = braked(brake_in(BrakeMode::Reversed), false, 10.0);
        assert!(v.abs() < 1.0, "{v}");
        assert!(travel < 1.4 * short, "{travel} vs {short}");
        assert!(short > 2.0 * right, "{short} {right}");
    }

    #[test]
    fn a_stop_before_the_sign_check_passed_checks_the_sign_and_stops_a_reversed_rig() {
        // A watchdog stop during the sign-check pulse: the trusted law would be used.
        let reason = StopReason::Watchdog(3);
        assert_eq!(stop_mode(&reason, true, true), BrakeMode::Active);
        assert_eq!(stop_mode(&reason, true, false), BrakeMode::Checked);
        assert_eq!(stop_mode(&reason, false, false), BrakeMode::None);
        assert_eq!(
            stop_mode(&StopReason::Finished, true, true),
            BrakeMode::Active
        );
        // On a rig with its motor leads swapped, the trusted law drives the arm away; the
        // checked law flips and stops it, within a few times the travel of a right rig.
        let (right, _) = braked(brake_in(BrakeMode::Active), false, 10.0);
        let (away, _) = braked(brake_in(BrakeMode::Active), true, 10.0);
        let (checked, v) = braked(brake_in(BrakeMode::Checked), true, 10.0);
        assert!(v.abs() < 1.0, "{v}");
        assert!(away > 5.0 * right, "{away} vs {right}");
        assert!(checked < 0.5 * away, "{checked} vs {away}");
    }

    #[test]
    fn a_modelled_stop_brakes_as_the_trusted_law_and_a_moving_reading_ends_it() {
        let cfg = Config::from_toml("").unwrap();
        let parts = stop_parts(&cfg);
        let x = State::new(0.0, 10.0, std::f64::consts::PI, 0.0);
        let (right, _) = braked(brake_in(BrakeMode::Active), false, 10.0);
        // The reading is frozen: the model's rate is all the stop has.
        let mut brake = brake_for_mode(parts.as_ref(), BrakeMode::Modelled, Some(x), 0.0);
        assert_eq!(brake.mode(), BrakeMode::Modelled);
        let mut sim = crate::plant::PlantSim::new(crate::plant::Model::Paper, 0.0, 0.0);
        sim.set_state([0.0, 10.0, std::f64::consts::PI, 0.0]);
        // The period until the stop's first command, at the voltage held (0 V).
        sim.step_windings(crate::plant::Windings::Driven(0.0), cfg.period_s());
        let mut travel: f64 = 0.0;
        for _ in 0..200 {
            let w = match brake.command(Some(0.0)) {
                BrakeCommand::Volts(v) => crate::plant::Windings::Driven(v),
                BrakeCommand::Short => crate::plant::Windings::Shorted,
            };
            sim.step_windings(w, cfg.period_s());
            travel = travel.max(sim.state()[0].abs());
        }
        assert_eq!(brake.mode(), BrakeMode::Short);
        // At rest but for the pendulum's swing, which the short then damps.
        assert!(sim.state()[1].abs() < 1.0, "{:?}", sim.state());
        // Within half a radian of the law on the measured rate, which keeps braking against
        // the pendulum's reaction after the arm's rest where the modelled stop shorts (1.55
        // against 1.07 rad from 10 rad/s; the short alone: 6.9 rad).
        assert!(travel < right + 0.5, "{travel} vs {right}");
        // A reading that moves: the model is not the arm.
        let mut brake = brake_for_mode(parts.as_ref(), BrakeMode::Modelled, Some(x), 0.0);
        assert_eq!(brake.command(Some(3.0)), BrakeCommand::Short);
        assert_eq!(brake.mode(), BrakeMode::Short);
        assert_eq!(
            brake_for_mode(None, BrakeMode::Modelled, None, 0.0).mode(),
            BrakeMode::Short
        );
    }

    #[test]
    fn the_envelope_stops_a_fast_arm_before_its_limit_and_lets_a_slow_one_run() {
        let cfg = Config::from_toml("").unwrap();
        let mut env = arm_envelope(&cfg, stop_parts(&cfg).as_ref());
        let model = *env.model();
        let hanging = std::f64::consts::PI;
        // At 2 rad from the 3 rad limit, the fastest speed it may still move outwards: by the
        // analytic distance, and by the stop simulated from the whole state (the pendulum
        // hanging still), which decides.
        let room = envelope_limit(&cfg) - 2.0;
        let v = model.max_speed(room, 12.0);
        let sim =
            rip_core::envelope::simulated_stop(&cfg.spec.plant.params(), 12.0, 0.01, 2).unwrap();
        let stops_inside =
            |w: f64| sim.stopping_point([2.0, w, hanging, 0.0], 12.0) <= envelope_limit(&cfg);
        let (mut lo, mut hi) = (v, 10.0 * v);
        assert!(stops_inside(lo) && !stops_inside(hi));
        while hi - lo > 1e-3 * v {
            let mid = 0.5 * (lo + hi);
            if stops_inside(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let w = lo;
        // The analytic distance reserves half the torque for a pendulum that does not push.
        assert!(0.9 * w > v, "{w} vs {v}");
        env.check(2.0 - 0.9 * w * 0.01, hanging, 0, 12.0).unwrap();
        env.check(2.0, hanging, 10_000, 12.0).unwrap();
        env.reset();
        env.check(2.0 - 1.1 * w * 0.01, hanging, u32::MAX - 4_999, 12.0)
            .unwrap();
        // Across the wrap of the device's clock.
        let stop = StopReason::from(env.check(2.0, hanging, 5_000, 12.0).unwrap_err());
        assert!(
            matches!(stop, StopReason::ArmEnvelope { stop_at, .. } if stop_at > 2.95),
            "{stop}"
        );
        assert_eq!(stop.exit_code(), crate::stop::exit_code::ANGLE_LIMIT);
        // Moving inwards is never stopped.
        env.reset();
        env.check(2.5, hanging, 0, -12.0).unwrap();
        env.check(2.4, hanging, 10_000, -12.0).unwrap();
        // At that speed, an applied voltage already braking leaves room.
        env.reset();
        env.check(2.0 - 1.1 * w * 0.01, hanging, 0, -12.0).unwrap();
        env.check(2.0, hanging, 10_000, -12.0).unwrap();
    }

    #[test]
    fn the_defaults_pass_and_unstoppable_settings_are_refused_naming_them() {
        for preset in ["paper", "qube_servo2"] {
            let cfg = Config::from_toml(&format!("[plant]\npreset = \"{preset}\"\n")).unwrap();
            check_swing_up(&cfg).unwrap();
            for signal in [
                Signal::Chirp,
                Signal::Prbs,
                Signal::Steps,
                Signal::FreeSwing,
            ] {
                check_excitation(&cfg, &ExcitationSettings::new(signal), "the preset")
                    .unwrap_or_else(|e| panic!("{preset} {signal:?}: {e}"));
                let loud = ExcitationSettings {
                    amplitude: 12.0,
                    centering: 0.0,
                    damping: 0.0,
                    kick: 2.0,
                    ..ExcitationSettings::new(signal)
                };
                let e = check_excitation(&cfg, &loud, "the preset").unwrap_err();
                assert_eq!(e.key, "--amplitude", "{e}");
                println!("{preset} {signal:?}: {e}");
            }
            let wide = Config::from_toml(&format!(
                "[plant]\npreset = \"{preset}\"\n[swing_up]\narm_limit = 2.9\n"
            ))
            .unwrap();
            let e = check_swing_up(&wide).unwrap_err();
            assert_eq!(e.key, "swing_up.arm_limit", "{e}");
        }
    }
}
