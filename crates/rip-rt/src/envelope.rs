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
//! the whole measured state ([`SimulatedStop`]: the pendulum's reaction on the arm from the
//! model, not a share of the torque reserved for it), and the run stops
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

use rip_core::envelope::{BrakingLaw, HoldLaw, Lowering, SimulatedStop, StoppingModel};
use rip_core::excitation::ExcitationSettings;
use rip_core::plant::{Plant, State};

use crate::config::{Config, ConfigError, MAX_VOLTAGE_LIMIT};
use crate::stop::StopReason;
use crate::witness::WitnessFault;

pub use rip_core::envelope::MAX_BRAKE_S;
pub use rip_core::preflight::motion::{ENVELOPE_MARGIN, LATENCY_PERIODS, PREFLIGHT_HEADROOM};

/// The arm counts as at rest once it moved less than [`REST_TRAVEL`] over this long (s).
pub const REST_S: f64 = 0.2;
/// Travel (rad) below which the arm is at rest over [`REST_S`].
pub const REST_TRAVEL: f64 = 0.01;

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
    let voltage = cfg.safety.voltage_limit.clamp(0.0, MAX_VOLTAGE_LIMIT);
    let room = rip_core::envelope::LOWER_TRAVEL_SHARE * envelope_limit(cfg);
    Lowering::design(&cfg.spec.plant.params(), voltage, cfg.period_s(), room)
        .ok()
        .flatten()
}

/// The arm's and the pendulum's rates (rad/s) from the sample `before` (its angles, rad, and
/// the device's clock, µs, wrapping) to this one at `theta`, `alpha` and `now_us`: the
/// difference over the device's clock between the two sampling instants, not the host's
/// wake-ups. 0 without a sample before, or for two samples in the same microsecond or a clock
/// that jumped back.
pub fn sample_rates(
    before: Option<(f64, f64, u32)>,
    theta: f64,
    alpha: f64,
    now_us: u32,
) -> (f64, f64) {
    match before {
        Some((theta0, alpha0, at)) if (1..u32::MAX / 2).contains(&now_us.wrapping_sub(at)) => {
            let dt = now_us.wrapping_sub(at) as f64 * 1e-6;
            (
                (theta - theta0) / dt,
                rip_core::trig::wrap_angle(alpha - alpha0) / dt,
            )
        }
        _ => (0.0, 0.0),
    }
}

/// The braking envelope of `safety.arm_limit` in the loop (module docs). Allocation-free.
#[derive(Debug, Clone)]
pub struct ArmEnvelope {
    model: StoppingModel,
    simulated: Option<SimulatedStop>,
    bound: f64,
    // The last arm and pendulum angles and the device's clock (µs, wrapping) when they were
    // sampled.
    last: Option<(f64, f64, u32)>,
}

impl ArmEnvelope {
    /// The envelope of `cfg`.
    pub fn new(cfg: &Config) -> Self {
        Self {
            model: stopping_model(cfg),
            simulated: SimulatedStop::new(
                &cfg.spec.plant.params(),
                cfg.safety.voltage_limit.clamp(0.0, MAX_VOLTAGE_LIMIT),
                cfg.period_s(),
                LATENCY_PERIODS as usize,
            )
            .ok(),
            bound: envelope_limit(cfg),
            last: None,
        }
    }

    /// The stopping model it uses.
    pub fn model(&self) -> &StoppingModel {
        &self.model
    }

    /// Forgets the last measurement (a new phase of the run).
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// Takes the arm angle `theta` and the pendulum angle `alpha` (rad, 0 upright) sampled at
    /// the device's clock `device_us` with `applied` (V) across the motor (the device's
    /// report, which acts until the stop's first command); the stop reason when the arm's
    /// stopping point is past the envelope's bound (module docs: the analytic distance first,
    /// and where it is past the bound, the stop simulated from the whole state).
    pub fn check(
        &mut self,
        theta: f64,
        alpha: f64,
        device_us: u32,
        applied: f64,
    ) -> Result<(), StopReason> {
        let before = self.last.replace((theta, alpha, device_us));
        let (rate, alpha_rate) = sample_rates(before, theta, alpha, device_us);
        self.check_state(theta, rate, alpha, alpha_rate, applied)
    }

    /// [`check`](Self::check) on a state whose rates the caller measured: the arm at `theta`
    /// moving at `rate`, the pendulum at `alpha` moving at `alpha_rate` (rad, rad/s).
    pub fn check_state(
        &self,
        theta: f64,
        rate: f64,
        alpha: f64,
        alpha_rate: f64,
        applied: f64,
    ) -> Result<(), StopReason> {
        let mut stop_at = self.model.stopping_point(theta, rate, applied);
        if stop_at.abs() > self.bound {
            if let Some(sim) = &self.simulated {
                stop_at = sim.stopping_point(State::new(theta, rate, alpha, alpha_rate), applied);
            }
        }
        // A NaN stopping point (no finite state to simulate) stops too.
        if stop_at.is_nan() || stop_at.abs() > self.bound {
            return Err(StopReason::ArmEnvelope {
                angle: theta,
                rate,
                stop_at,
                limit: self.bound + ENVELOPE_MARGIN,
            });
        }
        Ok(())
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

/// How a stop brakes the arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrakeMode {
    /// The braking law on the measured rate (the motor and encoders are trusted).
    Active,
    /// The braking law with its sign reversed: the witness saw the arm move against the
    /// voltage (a swapped motor lead or a reversed arm encoder), and in both cases a voltage
    /// along the *measured* motion is the one that opposes the true motion. The sign is
    /// checked on the arm's response ([`Brake`]): wrong, the law flips once to
    /// [`BrakeMode::Checked`].
    Reversed,
    /// The braking law with the model's sign, checked on the arm's response: the witness found
    /// the rig's motion unlike the model's, its arm encoder still counting (a wrong scale, a
    /// pendulum that disagrees), so the sign is not known for sure. Wrong, the law flips once
    /// to [`BrakeMode::Reversed`]; a law that fails both ways gives way to the short.
    Checked,
    /// The braking law on the model's arm rate, run open loop from the witness's estimate
    /// at the stop (the arm encoder stopped counting; the motor is trusted), until the
    /// model's arm is at rest; then the short.
    Modelled,
    /// The brake command only: windings shorted, whatever the wiring's sign.
    Short,
    /// Nothing can be sent (the device is gone), or the motor was never enabled.
    None,
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
        StopReason::Witness(WitnessFault::ArmWrongWay { .. }) => BrakeMode::Reversed,
        // The arm encoder stopped counting: brake on the model's arm.
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

/// Periods in a row of a rising arm speed under the saturated braking law with the sign under
/// test after which that sign is taken to be wrong (the sign the arm showed was not the
/// wiring's: a wrong scale, say): the law flips once, then gives way to the short.
pub const WRONG_SIGN_PERIODS: u32 = 4;
/// Periods over which the saturated law with the sign under test must take a tenth off the
/// arm's speed, or the sign is taken to be wrong.
pub const PROGRESS_PERIODS: u32 = 10;

/// What the stop applies for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BrakeCommand {
    /// Drive this voltage (V).
    Volts(f64),
    /// Short the windings (the brake command).
    Short,
}

/// The stop's command, period by period (module docs): one definition for `rip-rt`'s stops
/// and for the simulations that test them. Allocation-free.
#[derive(Debug, Clone)]
pub struct Brake {
    mode: BrakeMode,
    law: BrakingLaw,
    dead_band: f64,
    last_speed: f64,
    rising: u32,
    // The speed at the start of the current progress window, and the periods into it.
    window_speed: f64,
    window: u32,
    // Whether the checked law may still flip its sign once; the largest saturated speed
    // since its sign was last set, and whether the law has since halved it (its sign shown
    // right on the arm's response).
    may_flip: bool,
    peak_speed: f64,
    verified: bool,
    // The model braked open loop (BrakeMode::Modelled): the plant, its state, RK4 substeps
    // per period, the period (s), and how long its arm has been at rest (periods).
    model: Option<(Plant, State, usize, f64, u32)>,
}

impl Brake {
    /// The stop of `cfg` braking in `mode`.
    pub fn new(cfg: &Config, mode: BrakeMode) -> Self {
        let period_s = cfg.period_s();
        let voltage = cfg.safety.voltage_limit.clamp(0.0, MAX_VOLTAGE_LIMIT);
        Self {
            mode,
            law: BrakingLaw::new(&cfg.spec.plant.params(), voltage, period_s),
            // One count per period and a half: below it the measured rate is the encoder's
            // quantisation, and the law would chatter between ±its gain per count.
            dead_band: 1.5 * std::f64::consts::TAU
                / cfg.device.arm_counts_per_rev.max(1) as f64
                / period_s,
            last_speed: f64::INFINITY,
            rising: 0,
            window_speed: f64::INFINITY,
            window: 0,
            may_flip: matches!(mode, BrakeMode::Reversed | BrakeMode::Checked),
            peak_speed: 0.0,
            verified: false,
            model: None,
        }
    }

    /// The stop of `cfg` in [`BrakeMode::Modelled`] from the model's state `x` at the stop
    /// decision, `held` (V) still applied for the period until the stop's first command (the
    /// short when there is no state, or the configuration has no plant).
    pub fn modelled(cfg: &Config, x: Option<State>, held: f64) -> Self {
        let plant = cfg.spec.plant().ok();
        let mut brake = Self::new(cfg, BrakeMode::Short);
        if let (Some(plant), Some(x)) = (plant, x) {
            let ts = cfg.period_s();
            let substeps = (ts / plant.max_rk4_substep()).ceil().clamp(1.0, 1000.0) as usize;
            let mut x = x;
            plant.advance(&mut x, held, 0.0, ts, substeps);
            brake.model = Some((plant, x, substeps, ts, 0));
            brake.mode = BrakeMode::Modelled;
        }
        brake
    }

    /// The stop of `cfg` braking in `mode`: [`modelled`](Self::modelled) from the witness's
    /// `estimate` with `held` (V) still applied for [`BrakeMode::Modelled`], else
    /// [`new`](Self::new).
    pub fn for_mode(cfg: &Config, mode: BrakeMode, estimate: Option<State>, held: f64) -> Self {
        match mode {
            BrakeMode::Modelled => Self::modelled(cfg, estimate, held),
            mode => Self::new(cfg, mode),
        }
    }

    /// The model's arm angle (rad) in [`BrakeMode::Modelled`].
    pub fn model_arm(&self) -> Option<f64> {
        self.model.as_ref().map(|m| m.1[0])
    }

    /// Whether the law's sign is known: trusted ([`BrakeMode::Active`]), or shown on the arm's
    /// response (the saturated law has halved the arm's speed with it).
    pub fn sign_known(&self) -> bool {
        match self.mode {
            BrakeMode::Active => true,
            BrakeMode::Checked | BrakeMode::Reversed => self.verified,
            _ => false,
        }
    }

    /// How it brakes now (a law whose sign proved wrong became [`BrakeMode::Short`]).
    pub fn mode(&self) -> BrakeMode {
        self.mode
    }

    /// Whether arm speed `speed` (rad/s) is within the law's dead band (0 V).
    pub(crate) fn below_dead_band(&self, speed: f64) -> bool {
        speed <= self.dead_band
    }

    /// Whether the law is saturated at arm speed `speed` (rad/s).
    pub(crate) fn saturates(&self, speed: f64) -> bool {
        speed > self.law.linear_below
    }

    /// Gives up the law for the short from now on.
    pub fn short(&mut self) {
        if self.mode != BrakeMode::None {
            self.mode = BrakeMode::Short;
        }
    }

    /// The command for the measured arm rate `rate` (rad/s; `None` without a fresh
    /// measurement, which shorts the windings for that period).
    pub fn command(&mut self, rate: Option<f64>) -> BrakeCommand {
        let sign = match self.mode {
            BrakeMode::Active | BrakeMode::Checked => 1.0,
            BrakeMode::Reversed => -1.0,
            // A reading that moves after all: the model's arm is not the arm.
            BrakeMode::Modelled if rate.is_some_and(|r| r.abs() > self.dead_band) => {
                self.mode = BrakeMode::Short;
                return BrakeCommand::Short;
            }
            BrakeMode::Modelled => return self.modelled_command(),
            BrakeMode::Short | BrakeMode::None => return BrakeCommand::Short,
        };
        let Some(rate) = rate.filter(|r| r.is_finite()) else {
            return BrakeCommand::Short;
        };
        let speed = rate.abs();
        let mut sign = sign;
        if matches!(self.mode, BrakeMode::Reversed | BrakeMode::Checked) && self.wrong_sign(speed) {
            if !self.may_flip {
                self.mode = BrakeMode::Short;
                return BrakeCommand::Short;
            }
            // The sign the diagnosis suggested drove the arm on: the other one brakes it.
            self.may_flip = false;
            self.mode = if self.mode == BrakeMode::Reversed {
                BrakeMode::Checked
            } else {
                BrakeMode::Reversed
            };
            self.rising = 0;
            self.window = 0;
            self.last_speed = f64::INFINITY;
            self.peak_speed = 0.0;
            sign = -sign;
        }
        if speed > self.law.linear_below {
            self.peak_speed = self.peak_speed.max(speed);
        } else if self.peak_speed > 0.0 && speed < 0.5 * self.peak_speed {
            self.verified = true;
        }
        if speed <= self.dead_band {
            BrakeCommand::Volts(0.0)
        } else {
            BrakeCommand::Volts(sign * self.law.voltage(rate))
        }
    }

    /// The law on the model's arm rate; the model then advances a period under it.
    fn modelled_command(&mut self) -> BrakeCommand {
        let rest_periods = (REST_S / self.law_period()).ceil() as u32;
        let Some((plant, x, substeps, ts, still)) = self.model.as_mut() else {
            self.mode = BrakeMode::Short;
            return BrakeCommand::Short;
        };
        let rate = x[1];
        let v = if rate.abs() <= self.dead_band {
            *still += 1;
            0.0
        } else {
            *still = 0;
            self.law.voltage(rate)
        };
        plant.advance(x, v, 0.0, *ts, *substeps);
        if *still >= rest_periods {
            self.mode = BrakeMode::Short;
            return BrakeCommand::Short;
        }
        BrakeCommand::Volts(v)
    }

    fn law_period(&self) -> f64 {
        self.model.as_ref().map_or(0.01, |m| m.3)
    }

    /// Whether the law with the sign under test proves not to brake: a law that opposes the
    /// motion slows the arm after the latency; one whose sign is wrong speeds it up period
    /// after period, or holds it at the speed where the motor's back-EMF balances it (both
    /// judged while the law is saturated: in its linear range the pendulum's push on the arm
    /// is as large as the law's, and a test there flips a law that was right).
    fn wrong_sign(&mut self, speed: f64) -> bool {
        let saturated = speed > self.law.linear_below;
        if saturated && speed > self.last_speed + self.dead_band {
            self.rising += 1;
        } else {
            self.rising = 0;
        }
        self.last_speed = speed;
        if !saturated {
            self.window = 0;
            self.window_speed = f64::INFINITY;
            return false;
        }
        if self.window == 0 {
            self.window_speed = speed;
        }
        self.window += 1;
        let stalled = self.window > PROGRESS_PERIODS && speed > 0.9 * self.window_speed;
        if self.window > PROGRESS_PERIODS {
            self.window = 0;
        }
        self.rising >= WRONG_SIGN_PERIODS || stalled
    }
}

mod sequence;
pub use sequence::{
    momentum_rate, StopSequence, HOLD_BLIND_PERIODS, HOLD_GIVE_UP_RAD, LOWERED_HANGING_RAD,
    LOWER_FROM_RAD, LOWER_SIDE_FROM_RAD, MAX_HOLD_S, MOMENTUM_ENERGY_GAIN, PENDULUM_REST_RAD,
};

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
            BrakeMode::Modelled => "braked at the voltage bound on the model's arm",
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

/// The stop's rest test: the arm moved less than [`REST_TRAVEL`] over the last [`REST_S`].
/// Allocation-free (a ring of the recent angles).
#[derive(Debug, Clone)]
pub struct RestTest {
    history: [f64; 64],
    ring: usize,
    seen: usize,
}

impl RestTest {
    /// The test for a loop of period `period_s` (s).
    pub fn new(period_s: f64) -> Self {
        let rest_periods = (REST_S / period_s).ceil().max(1.0) as usize;
        Self {
            history: [f64::NAN; 64],
            ring: (rest_periods + 1).min(64),
            seen: 0,
        }
    }

    /// Takes the next measured arm angle (rad); whether the arm is at rest.
    pub fn observe(&mut self, theta: f64) -> bool {
        self.observe_within(theta, REST_TRAVEL)
    }

    /// Takes the next angle (rad); whether it moved less than `travel` (rad) over
    /// [`REST_S`].
    pub fn observe_within(&mut self, theta: f64, travel: f64) -> bool {
        self.history[self.seen % self.ring] = theta;
        self.seen += 1;
        if self.seen < self.ring {
            return false;
        }
        let (lo, hi) = self.history[..self.ring]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        hi - lo < travel
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rip_core::excitation::Signal;

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
        let cfg = Config::from_toml("").unwrap();
        // The law as it stands drives a reversed rig away; reversed, it brakes it, as far as
        // the trusted law brakes a rig wired right.
        let (right, v_right) = braked(Brake::new(&cfg, BrakeMode::Active), false, 10.0);
        let (rev, v_rev) = braked(Brake::new(&cfg, BrakeMode::Reversed), true, 10.0);
        assert!(
            v_right.abs() < 0.1 && v_rev.abs() < 0.1,
            "{v_right} {v_rev}"
        );
        assert!((rev - right).abs() < 0.05 * right, "{rev} vs {right}");
        // The reversed law on a rig wired right speeds the arm up: the stop shorts instead
        // after a few periods (here 9.2 rad of travel from 10 rad/s, against 6.9 rad for the
        // short alone and 1.4 rad for the law with the right sign).
        let (short, _) = braked(Brake::new(&cfg, BrakeMode::Short), false, 10.0);
        let (travel, v) = braked(Brake::new(&cfg, BrakeMode::Reversed), false, 10.0);
        assert!(v.abs() < 1.0, "{v}");
        assert!(travel < 1.4 * short, "{travel} vs {short}");
        assert!(short > 2.0 * right, "{short} {right}");
    }

    #[test]
    fn a_stop_before_the_sign_check_passed_checks_the_sign_and_stops_a_reversed_rig() {
        let cfg = Config::from_toml("").unwrap();
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
        let (right, _) = braked(Brake::new(&cfg, BrakeMode::Active), false, 10.0);
        let (away, _) = braked(Brake::new(&cfg, BrakeMode::Active), true, 10.0);
        let (checked, v) = braked(Brake::new(&cfg, BrakeMode::Checked), true, 10.0);
        assert!(v.abs() < 1.0, "{v}");
        assert!(away > 5.0 * right, "{away} vs {right}");
        assert!(checked < 0.5 * away, "{checked} vs {away}");
    }

    #[test]
    fn a_modelled_stop_brakes_as_the_trusted_law_and_a_moving_reading_ends_it() {
        let cfg = Config::from_toml("").unwrap();
        let x = State::new(0.0, 10.0, std::f64::consts::PI, 0.0);
        let (right, _) = braked(Brake::new(&cfg, BrakeMode::Active), false, 10.0);
        // The reading is frozen: the model's rate is all the stop has.
        let mut brake = Brake::modelled(&cfg, Some(x), 0.0);
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
        let mut brake = Brake::modelled(&cfg, Some(x), 0.0);
        assert_eq!(brake.command(Some(3.0)), BrakeCommand::Short);
        assert_eq!(brake.mode(), BrakeMode::Short);
        assert_eq!(Brake::modelled(&cfg, None, 0.0).mode(), BrakeMode::Short);
    }

    #[test]
    fn the_envelope_stops_a_fast_arm_before_its_limit_and_lets_a_slow_one_run() {
        let cfg = Config::from_toml("").unwrap();
        let mut env = ArmEnvelope::new(&cfg);
        let model = *env.model();
        let hanging = std::f64::consts::PI;
        // At 2 rad from the 3 rad limit, the fastest speed it may still move outwards: by the
        // analytic distance, and by the stop simulated from the whole state (the pendulum
        // hanging still), which decides.
        let room = envelope_limit(&cfg) - 2.0;
        let v = model.max_speed(room, 12.0);
        let sim = SimulatedStop::new(&cfg.spec.plant.params(), 12.0, 0.01, 2).unwrap();
        let stops_inside = |w: f64| {
            sim.stopping_point(State::new(2.0, w, hanging, 0.0), 12.0) <= envelope_limit(&cfg)
        };
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
        let stop = env.check(2.0, hanging, 5_000, 12.0).unwrap_err();
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
