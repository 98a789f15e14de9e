//! The emulated device's settings and the faults it injects, with their validation.

use super::*;

/// Settings of the emulated device and of the faults it injects.
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorConfig {
    /// Physical parameters of the simulated pendulum.
    pub model: Model,
    /// Simulation step rate (Hz).
    pub sim_rate_hz: f64,
    /// Arm encoder counts per revolution.
    pub arm_counts_per_rev: u32,
    /// Pendulum encoder counts per revolution (zero hanging down).
    pub pendulum_counts_per_rev: u32,
    /// Where each encoder's zero lies (rad; `[sensor] encoder_offsets`): the arm encoder
    /// reads `θ + o₀`, the pendulum's `α + π + o₁` (zero hanging down when `o₁ = 0`).
    pub encoder_offsets: [f64; 2],
    /// Initial arm angle (rad).
    pub initial_arm: f64,
    /// Initial pendulum angle from upright (rad).
    pub initial_pendulum: f64,
    /// Hold the pendulum still until the first enabling command.
    pub hold_until_enabled: bool,
    /// The device watchdog: zero the motor when no command arrived for this long (s).
    pub command_timeout_s: f64,
    /// The device's own voltage limit (V); commands beyond it are clamped. Not the controller's
    /// input bound (`safety.voltage_limit`, default `paper::INPUT_LIMIT`): by default the
    /// emulated device allows the largest limit rip-rt accepts
    /// ([`MAX_VOLTAGE_LIMIT`](crate::config::MAX_VOLTAGE_LIMIT)), so the clamp a run exercises is
    /// the loop's own.
    pub voltage_limit: f64,
    /// H-bridge supply (V): the voltage at 100 % PWM duty. A physical property of the emulated
    /// bridge, by default `MAX_VOLTAGE_LIMIT` too (a bridge able to drive every rig's motor).
    pub supply: f64,
    /// Standard deviation (rad) of the Gaussian noise on the arm and the pendulum angle
    /// (`[sensor] noise_std`). As in the simulation's `SensorModel`, the noise is added to the
    /// quantised angle; an encoder reports whole counts, so it arrives rounded to a count.
    pub noise_std: [f64; 2],
    /// Probability that a measurement is not sent.
    pub drop_rate: f64,
    /// Probability that a measurement is corrupted on the wire (a flipped byte, or garbage
    /// bytes inserted before it).
    pub corrupt_rate: f64,
    /// Close the device this long after the first command (s): a vanished USB device.
    pub vanish_after_s: Option<f64>,
    /// Seed of the fault and noise generator.
    pub seed: u64,
    /// Stop after this long (s).
    pub duration_s: Option<f64>,
    /// CSV file receiving every command the device accepted (`t_s,seq,voltage_mv,flags`).
    pub record: Option<PathBuf>,
    /// CSV file receiving the simulated plant's true state ([`TRUE_STATE_HEADER`]), not the
    /// encoders' view of it.
    pub true_state: Option<PathBuf>,
    /// Interval between rows of `true_state` (s); 0 writes a row every simulation step.
    pub true_state_period_s: f64,
    /// Publish the true state on the live stream to `127.0.0.1:port` (`--live`), every
    /// `true_state_period_s`, with these bounds ([`crate::live`]).
    pub live: Option<(u16, crate::live::Bounds)>,
    /// Wiring faults, for testing the sign check ([`crate::sign_check`]) and the witness
    /// ([`crate::witness`]).
    pub wiring: Wiring,
    /// When the wiring faults begin (s after the first enabling command); `None`: from
    /// power-up. A fault that begins mid-run acts from the readings at its onset: a frozen
    /// encoder keeps the count it had, a reversed one counts backwards from it (a quadrature
    /// counter with its channels swapped), so neither makes the reading jump.
    pub fault_at_s: Option<f64>,
    /// The emulated bridge can brake (short the windings) when not driving; without it the
    /// windings are open whenever the motor is not driven (`--no-brake`).
    pub can_brake: bool,
    /// Lockstep with the host (`--lockstep`): the plant advances by exactly this period (s,
    /// the host's `loop.period_ms`) before each sample request is answered, instead of in
    /// real time; measurements carry [`STATUS_LOCKSTEP`]. `None`: real time.
    pub lockstep_period_s: Option<f64>,
    /// The device answers nothing for `.1` seconds starting `.0` seconds after the first
    /// enabling command (`--silent-at`, `--silent-for`): a USB hub's or a serial adapter's
    /// hiccup, every measurement in the window lost while commands still arrive. Unlike
    /// `drop_rate` it starts mid-run, so that a stop can be made to run blind.
    pub silence: Option<(f64, f64)>,
    /// An operator raises the pendulum (`--raise-at`): this many seconds after the first
    /// enabling command it is set 0.05 rad from upright at rest, the arm where it is, and held
    /// there until the next enabling command (a run that checked the wiring with the pendulum
    /// hanging, then waits for it upright).
    pub raise_at_s: Option<f64>,
    /// A breakpoint (`--pause-at-arm`, lockstep only): the first time a sample request finds
    /// the true arm past ±this angle (rad) and moving outwards, the emulator stops itself
    /// (SIGSTOP) before it answers, with a true-state row of that state written; `kill -CONT`
    /// resumes it (a SIGINT or SIGTERM sent meanwhile ends it only then). The lockstep host
    /// waits for the answer, so the rig stands still at a state chosen in advance while
    /// something is done to the host (a signal at the arm's widest swing), however loaded the
    /// machine, for up to the host's lockstep wait (5 s, `timing::LOCKSTEP_REPLY_WAIT_NS`),
    /// after which it counts the period as one without a measurement.
    pub pause_at_arm: Option<f64>,
}

/// How the emulated rig is wired: the motor's leads and each encoder's direction, and
/// encoders that do not count (a loose cable). The default is a correctly wired rig.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wiring {
    /// The motor's leads are swapped: a positive voltage turns the arm the negative way.
    pub motor_reversed: bool,
    /// The arm and the pendulum encoder count backwards.
    pub encoder_reversed: [bool; 2],
    /// The arm and the pendulum encoder do not count (stuck at their power-up reading).
    pub encoder_frozen: [bool; 2],
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        let [arm, pendulum] = rip_core::spec::SensorSpec::default().encoder_counts;
        Self {
            model: Model::Paper,
            sim_rate_hz: 1000.0,
            arm_counts_per_rev: arm,
            pendulum_counts_per_rev: pendulum,
            encoder_offsets: [0.0, 0.0],
            initial_arm: 0.0,
            initial_pendulum: 0.05,
            hold_until_enabled: true,
            command_timeout_s: 0.05,
            voltage_limit: crate::config::MAX_VOLTAGE_LIMIT,
            supply: crate::config::MAX_VOLTAGE_LIMIT,
            noise_std: [0.0; 2],
            drop_rate: 0.0,
            corrupt_rate: 0.0,
            vanish_after_s: None,
            seed: 1,
            duration_s: None,
            record: None,
            true_state: None,
            true_state_period_s: 0.01,
            live: None,
            wiring: Wiring::default(),
            fault_at_s: None,
            can_brake: true,
            lockstep_period_s: None,
            silence: None,
            raise_at_s: None,
            pause_at_arm: None,
        }
    }
}

/// An emulator setting out of range, naming the command-line option (or setting) at fault.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{option}: {reason}")]
pub struct EmulatorConfigError {
    /// The option, e.g. `--drop-rate`.
    pub option: String,
    /// What is wrong with its value.
    pub reason: String,
}

impl EmulatorConfigError {
    fn new(option: &str, reason: impl Into<String>) -> Self {
        Self {
            option: option.into(),
            reason: reason.into(),
        }
    }
}

impl EmulatorConfig {
    /// The encoders of `sensor`, the simulation's sensor of a spec (`Spec::simulation`, the
    /// one mapping of `[sensor]`): resolutions, zero offsets and noise.
    pub fn with_sensor(self, sensor: &rip_core::sim::SensorModel) -> Self {
        let [arm, pendulum] = sensor.counts_per_rev.map_or(
            [self.arm_counts_per_rev, self.pendulum_counts_per_rev],
            |c| c.map(|n| n as u32),
        );
        Self {
            arm_counts_per_rev: arm,
            pendulum_counts_per_rev: pendulum,
            encoder_offsets: sensor.offsets,
            noise_std: sensor.noise_std,
            ..self
        }
    }

    /// The breakpoint's angle (`--pause-at-arm`): positive, and only in lockstep (in real time
    /// the plant would run on while the emulator is stopped).
    fn validate_breakpoint(&self) -> Result<(), EmulatorConfigError> {
        let Some(angle) = self.pause_at_arm else {
            return Ok(());
        };
        if !(angle.is_finite() && angle > 0.0) {
            return Err(EmulatorConfigError::new(
                "--pause-at-arm",
                format!("must be a positive angle (rad), got {angle}"),
            ));
        }
        if self.lockstep_period_s.is_none() {
            return Err(EmulatorConfigError::new(
                "--pause-at-arm",
                "needs --lockstep (in real time the plant would run on while paused)",
            ));
        }
        Ok(())
    }

    /// Checks the values; the error names the command-line flag.
    pub fn validate(&self) -> Result<(), EmulatorConfigError> {
        let prob = |name: &str, p: f64| {
            if (0.0..=1.0).contains(&p) {
                Ok(())
            } else {
                Err(EmulatorConfigError::new(
                    name,
                    format!("must be a probability in [0, 1], got {p}"),
                ))
            }
        };
        prob("--drop-rate", self.drop_rate)?;
        prob("--corrupt-rate", self.corrupt_rate)?;
        if !self.noise_std.iter().all(|s| s.is_finite() && *s >= 0.0) {
            return Err(EmulatorConfigError::new(
                "--noise",
                format!("must be non-negative, got {:?} rad", self.noise_std),
            ));
        }
        if !(self.sim_rate_hz.is_finite() && (100.0..=100_000.0).contains(&self.sim_rate_hz)) {
            return Err(EmulatorConfigError::new(
                "--sim-rate",
                format!("must be in [100, 100000] Hz, got {}", self.sim_rate_hz),
            ));
        }
        if !(self.voltage_limit.is_finite()
            && self.voltage_limit > 0.0
            && self.voltage_limit <= 32.767)
        {
            return Err(EmulatorConfigError::new(
                "voltage limit",
                format!("must be in (0, 32.767] V, got {}", self.voltage_limit),
            ));
        }
        if !(self.supply.is_finite() && self.supply >= self.voltage_limit && self.supply <= 65.535)
        {
            return Err(EmulatorConfigError::new(
                "supply",
                format!(
                    "must be between the voltage limit and 65.535 V, got {}",
                    self.supply
                ),
            ));
        }
        if !(self.command_timeout_s.is_finite() && self.command_timeout_s > 0.0) {
            return Err(EmulatorConfigError::new(
                "--command-timeout",
                format!("must be positive, got {}", self.command_timeout_s),
            ));
        }
        for (name, v) in [
            ("--initial-arm", self.initial_arm),
            ("--initial-pendulum", self.initial_pendulum),
        ] {
            if !v.is_finite() {
                return Err(EmulatorConfigError::new(
                    name,
                    format!("must be finite, got {v}"),
                ));
            }
        }
        for (name, v) in [
            ("--vanish-after", self.vanish_after_s),
            ("--duration", self.duration_s),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(EmulatorConfigError::new(
                        name,
                        format!("must be a non-negative number of seconds, got {v}"),
                    ));
                }
            }
        }
        if !(self.true_state_period_s.is_finite()
            && (0.0..=1.0).contains(&self.true_state_period_s))
        {
            return Err(EmulatorConfigError::new(
                "--true-state-period",
                format!(
                    "must be in [0, 1] s (0: every simulation step), got {}",
                    self.true_state_period_s
                ),
            ));
        }
        if let Some(p) = self.lockstep_period_s {
            let dt = 1.0 / self.sim_rate_hz;
            if !(p.is_finite() && p >= dt && p <= 1.0) {
                return Err(EmulatorConfigError::new(
                    "--lockstep",
                    format!(
                        "the host period must be in [{dt}, 1] s (one simulation step to 1 s), \
                         got {p}"
                    ),
                ));
            }
        }
        if let Some(t) = self.raise_at_s {
            if !(t.is_finite() && t >= 0.0) {
                return Err(EmulatorConfigError::new(
                    "--raise-at",
                    format!("must be a non-negative number of seconds, got {t}"),
                ));
            }
        }
        self.validate_breakpoint()?;
        if let Some(t) = self.fault_at_s {
            if !(t.is_finite() && t >= 0.0) {
                return Err(EmulatorConfigError::new(
                    "--fault-at",
                    format!("must be a non-negative number of seconds, got {t}"),
                ));
            }
            if self.wiring == Wiring::default() {
                return Err(EmulatorConfigError::new(
                    "--fault-at",
                    "needs a wiring fault to start (--reverse-motor, --reverse-arm-encoder, \
                     --freeze-arm-encoder, ...)",
                ));
            }
        }
        if let Some((at, len)) = self.silence {
            for (name, v) in [("--silent-at", at), ("--silent-for", len)] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(EmulatorConfigError::new(
                        name,
                        format!("must be a non-negative number of seconds, got {v}"),
                    ));
                }
            }
        }
        if self.arm_counts_per_rev == 0 || self.pendulum_counts_per_rev == 0 {
            return Err(EmulatorConfigError::new(
                "--counts-per-rev",
                "must be positive",
            ));
        }
        Ok(())
    }
}
