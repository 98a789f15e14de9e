//! The configuration of `rip-rt run`, `rip-rt emulate` and `rip-rt config`: the experiment
//! file of `rip_core::spec` (`[plant]`, `[sensor]`, `[reference]`, `[lqr]`, `[kalman]`,
//! `[mpc]`, ... read, defaulted and checked by rip-core, exactly as `riprs compare` reads
//! them) plus rip-rt's own sections `[loop]`, `[device]` and `[safety]`, defined here, and
//! `[calibration]`, defined with the rest check in [`crate::calibrate`]. Every
//! key is optional; the defaults are the paper's settings (Ts = 10 ms, |u| ≤ 12 V) and the
//! encoders of the reference rig (2048 counts per revolution each).
//!
//! Unknown keys are rejected, and every value is checked; errors name the file and the key,
//! e.g. `cfg.toml: safety.pendulum_limit: must be in (0, 1.5] rad, got 4`.

use std::path::Path;

use rip_core::spec::{from_value, Spec, SpecError};

pub use crate::calibrate::CalibrationConfig;
use serde::{Deserialize, Serialize};

/// A configuration problem, naming the file and the key: the experiment file's one error type,
/// so `rip-rt` and `riprs` report a bad key alike.
pub type ConfigError = SpecError;

fn err(key: &str, reason: impl Into<String>) -> ConfigError {
    SpecError::new(key, reason)
}

/// Where the pendulum encoder reads zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum PendulumZero {
    /// Zero counts with the pendulum hanging down (an encoder reset at power-up); the loop
    /// subtracts π so that 0 rad is upright.
    #[default]
    Down,
    /// Zero counts with the pendulum upright.
    Up,
}

/// `[loop]`: timing of the control loop and its overrun rules.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Control period (ms), in [`PERIOD_MS`]. The controllers are designed for this sample
    /// time.
    pub period_ms: f64,
    /// How long to wait for the measurement after the sample request (ms), at least
    /// [`MIN_REPLY_TIMEOUT_MS`] and shorter than the period.
    pub reply_timeout_ms: f64,
    /// Consecutive periods without a valid measurement that stop the loop, in
    /// [`WATCHDOG_PERIODS`], and at most [`MAX_BLIND_MS`] of driving on a repeated command.
    pub watchdog_periods: u32,
    /// A controller step (measurement decoded → command encoded) longer than this many periods
    /// is a compute overrun: the command is not sent and the loop stops. In
    /// [`MAX_STEP_PERIODS`].
    pub max_step_periods: f64,
    /// This many periods in a row whose work (wake-up to command sent) took longer than a
    /// period are a compute overrun. In [`MAX_CONSECUTIVE_MISSES`].
    pub max_consecutive_misses: u32,
}

/// Allowed `loop.period_ms`. Above 20 ms the device's 50 ms command watchdog (protocol.md)
/// would see fewer than three commands per window and the pendulum (unstable pole near
/// 10 rad/s) is no longer controllable at that rate; below 1 ms a serial round trip cannot fit.
pub const PERIOD_MS: std::ops::RangeInclusive<f64> = 1.0..=20.0;
/// Shortest `loop.reply_timeout_ms`: a USB round trip alone takes about this long.
pub const MIN_REPLY_TIMEOUT_MS: f64 = 0.1;
/// Allowed `loop.watchdog_periods`.
pub const WATCHDOG_PERIODS: std::ops::RangeInclusive<u32> = 1..=10;
/// Longest time (ms) the loop may keep the motor enabled on a repeated command without a new
/// measurement, whatever the configuration: `loop.watchdog_periods × loop.period_ms` must not
/// exceed it, and the loop enforces it again at run time.
pub const MAX_BLIND_MS: f64 = 100.0;
/// Allowed `loop.max_step_periods`.
pub const MAX_STEP_PERIODS: std::ops::RangeInclusive<f64> = 0.1..=5.0;
/// Allowed `loop.max_consecutive_misses`.
pub const MAX_CONSECUTIVE_MISSES: std::ops::RangeInclusive<u32> = 1..=20;

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            period_ms: 10.0,
            reply_timeout_ms: 5.0,
            watchdog_periods: 5,
            max_step_periods: 2.0,
            max_consecutive_misses: 5,
        }
    }
}

/// `[device]`: how encoder counts map to angles.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct DeviceConfig {
    /// Arm encoder counts per revolution (after quadrature decoding), in [`COUNTS_PER_REV`].
    pub arm_counts_per_rev: u32,
    /// Pendulum encoder counts per revolution (after quadrature decoding), in
    /// [`COUNTS_PER_REV`].
    pub pendulum_counts_per_rev: u32,
    /// Where the pendulum encoder reads zero.
    pub pendulum_zero: PendulumZero,
    /// +1 or −1: flips the arm encoder's direction to the model's convention.
    pub arm_sign: f64,
    /// +1 or −1: flips the pendulum encoder's direction to the model's convention.
    pub pendulum_sign: f64,
}

impl Default for DeviceConfig {
    fn default() -> Self {
        Self {
            arm_counts_per_rev: 2048,
            pendulum_counts_per_rev: 2048,
            pendulum_zero: PendulumZero::Down,
            arm_sign: 1.0,
            pendulum_sign: 1.0,
        }
    }
}

/// Allowed encoder resolutions: below 64 counts per revolution (0.1 rad) the pendulum angle
/// is too coarse to balance on; above 2²⁴ the multi-turn i32 count overflows within 128 turns.
pub const COUNTS_PER_REV: std::ops::RangeInclusive<u32> = 64..=(1 << 24);
/// Largest `safety.voltage_limit` (V): the rigs this loop is for have 12 V to 24 V motors.
pub const MAX_VOLTAGE_LIMIT: f64 = 24.0;
/// Largest `safety.pendulum_limit` (rad): past horizontal no balancing controller recovers.
pub const MAX_PENDULUM_LIMIT: f64 = std::f64::consts::FRAC_PI_2;
/// Largest `safety.arm_limit` (rad): one turn either way, before the cable winds up.
pub const MAX_ARM_LIMIT: f64 = std::f64::consts::TAU;
/// Longest `safety.wait_upright_s` (s); the motor stays disabled while waiting.
pub const MAX_WAIT_UPRIGHT_S: f64 = 600.0;

/// `[safety]`: limits that stop the motor.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyConfig {
    /// Every command is clamped to ±this (V), in (0, [`MAX_VOLTAGE_LIMIT`]].
    pub voltage_limit: f64,
    /// |pendulum angle| above this (rad from upright) stops the loop while balancing, in
    /// (0, [`MAX_PENDULUM_LIMIT`]].
    pub pendulum_limit: f64,
    /// |arm angle| above this (rad) stops the loop, in (0, [`MAX_ARM_LIMIT`]].
    pub arm_limit: f64,
    /// Balancing starts only with |pendulum angle| below this (rad).
    pub start_tolerance: f64,
    /// How long to wait for the pendulum to be brought upright before refusing (s), in
    /// [0, [`MAX_WAIT_UPRIGHT_S`]]; 0 refuses at once.
    pub wait_upright_s: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            voltage_limit: rip_core::paper::INPUT_LIMIT,
            pendulum_limit: 0.6,
            arm_limit: 3.0,
            start_tolerance: 0.15,
            wait_upright_s: 0.0,
        }
    }
}

/// rip-rt's own sections of the file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct RuntimeSections {
    /// `[loop]`
    #[serde(rename = "loop")]
    pub loop_: LoopConfig,
    /// `[device]`
    pub device: DeviceConfig,
    /// `[safety]`
    pub safety: SafetyConfig,
    /// `[calibration]`
    pub calibration: CalibrationConfig,
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Config {
    /// `[loop]`
    pub loop_: LoopConfig,
    /// `[device]`
    pub device: DeviceConfig,
    /// `[safety]`
    pub safety: SafetyConfig,
    /// `[calibration]`: the rest check and the hanging-down calibration
    /// ([`crate::calibrate`]).
    pub calibration: CalibrationConfig,
    /// The experiment sections, rip-core's (`[plant]`, `[reference]`, `[lqr]`, `[kalman]`,
    /// `[mpc]`, ...).
    pub spec: Spec,
}

fn positive(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(err(key, format!("must be a positive number, got {v}")))
    }
}

fn in_range(
    key: &str,
    v: f64,
    range: std::ops::RangeInclusive<f64>,
    unit: &str,
) -> Result<(), ConfigError> {
    if range.contains(&v) {
        Ok(())
    } else {
        Err(err(
            key,
            format!(
                "must be in [{}, {}] {unit}, got {v}",
                range.start(),
                range.end()
            ),
        ))
    }
}

fn in_open_closed(key: &str, v: f64, max: f64, unit: &str) -> Result<(), ConfigError> {
    if v > 0.0 && v <= max {
        Ok(())
    } else {
        Err(err(key, format!("must be in (0, {max}] {unit}, got {v}")))
    }
}

fn sign(key: &str, v: f64) -> Result<(), ConfigError> {
    if v == 1.0 || v == -1.0 {
        Ok(())
    } else {
        Err(err(key, format!("must be 1 or -1, got {v}")))
    }
}

impl Config {
    /// Parses and validates TOML text.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let (spec, runtime) = Spec::parse_with_runtime(text)?;
        let own: RuntimeSections = from_value(toml::Value::Table(runtime), "")?;
        let cfg = Config {
            loop_: own.loop_,
            device: own.device,
            safety: own.safety,
            calibration: own.calibration,
            spec,
        };
        cfg.validate()?;
        Ok(cfg)
    }

    /// Reads, parses and validates a file; errors name it.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let bytes =
            std::fs::read(path).map_err(|e| err("", format!("cannot read: {e}")).in_file(path))?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|e| err("", format!("invalid TOML: not UTF-8 text ({e})")).in_file(path))?;
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        Self::from_toml(text).map_err(|e| e.in_file(path))
    }

    /// The resolved configuration as TOML, every default filled in: the experiment sections
    /// exactly as `riprs config` prints them, then `[loop]`, `[device]` and `[safety]`.
    pub fn to_toml(&self) -> String {
        let own = RuntimeSections {
            loop_: self.loop_.clone(),
            device: self.device.clone(),
            safety: self.safety.clone(),
            calibration: self.calibration.clone(),
        };
        let own = toml::to_string(&own).expect("every setting has a TOML form");
        format!("{}\n{}", self.spec.to_toml(), own)
    }

    /// Checks every value; the error names the first bad key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.validate_loop()?;
        self.validate_device()?;
        self.validate_safety()?;
        self.calibration.validate(&self.device)?;
        let s = &self.safety;
        let r = &self.spec.reference;
        if r.arm_step.abs() >= s.arm_limit {
            return Err(err(
                "reference.arm_step",
                format!(
                    "must be inside safety.arm_limit ({}), got {}",
                    s.arm_limit, r.arm_step
                ),
            ));
        }
        Ok(())
    }

    fn validate_loop(&self) -> Result<(), ConfigError> {
        let l = &self.loop_;
        in_range("loop.period_ms", l.period_ms, PERIOD_MS, "ms")?;
        if !(l.reply_timeout_ms.is_finite()
            && l.reply_timeout_ms >= MIN_REPLY_TIMEOUT_MS
            && l.reply_timeout_ms < l.period_ms)
        {
            return Err(err(
                "loop.reply_timeout_ms",
                format!(
                    "must be at least {MIN_REPLY_TIMEOUT_MS} ms and shorter than \
                     loop.period_ms ({} ms), got {}",
                    l.period_ms, l.reply_timeout_ms
                ),
            ));
        }
        if !WATCHDOG_PERIODS.contains(&l.watchdog_periods) {
            return Err(err(
                "loop.watchdog_periods",
                format!(
                    "must be in {}..={}, got {}",
                    WATCHDOG_PERIODS.start(),
                    WATCHDOG_PERIODS.end(),
                    l.watchdog_periods
                ),
            ));
        }
        let blind_ms = f64::from(l.watchdog_periods) * l.period_ms;
        if blind_ms > MAX_BLIND_MS {
            return Err(err(
                "loop.watchdog_periods",
                format!(
                    "{} periods of {} ms are {blind_ms} ms without a measurement; at most \
                     {MAX_BLIND_MS} ms are allowed",
                    l.watchdog_periods, l.period_ms
                ),
            ));
        }
        in_range(
            "loop.max_step_periods",
            l.max_step_periods,
            MAX_STEP_PERIODS,
            "periods",
        )?;
        if !MAX_CONSECUTIVE_MISSES.contains(&l.max_consecutive_misses) {
            return Err(err(
                "loop.max_consecutive_misses",
                format!(
                    "must be in {}..={}, got {}",
                    MAX_CONSECUTIVE_MISSES.start(),
                    MAX_CONSECUTIVE_MISSES.end(),
                    l.max_consecutive_misses
                ),
            ));
        }
        Ok(())
    }

    fn validate_device(&self) -> Result<(), ConfigError> {
        let d = &self.device;
        for (key, counts) in [
            ("device.arm_counts_per_rev", d.arm_counts_per_rev),
            ("device.pendulum_counts_per_rev", d.pendulum_counts_per_rev),
        ] {
            if !COUNTS_PER_REV.contains(&counts) {
                return Err(err(
                    key,
                    format!(
                        "must be in {}..={}, got {counts}",
                        COUNTS_PER_REV.start(),
                        COUNTS_PER_REV.end()
                    ),
                ));
            }
        }
        sign("device.arm_sign", d.arm_sign)?;
        sign("device.pendulum_sign", d.pendulum_sign)
    }

    fn validate_safety(&self) -> Result<(), ConfigError> {
        let s = &self.safety;
        in_open_closed(
            "safety.voltage_limit",
            s.voltage_limit,
            MAX_VOLTAGE_LIMIT,
            "V",
        )?;
        in_open_closed(
            "safety.pendulum_limit",
            s.pendulum_limit,
            MAX_PENDULUM_LIMIT,
            "rad",
        )?;
        in_open_closed("safety.arm_limit", s.arm_limit, MAX_ARM_LIMIT, "rad")?;
        positive("safety.start_tolerance", s.start_tolerance)?;
        if s.start_tolerance >= s.pendulum_limit {
            return Err(err(
                "safety.start_tolerance",
                format!(
                    "must be below safety.pendulum_limit ({}), got {}",
                    s.pendulum_limit, s.start_tolerance
                ),
            ));
        }
        in_range(
            "safety.wait_upright_s",
            s.wait_upright_s,
            0.0..=MAX_WAIT_UPRIGHT_S,
            "s",
        )
    }

    /// Checks `[swing_up]` against the loop's limits for a run that swings up: the law's arm
    /// limit inside `safety.arm_limit` (which stays a stop), so that the law, not the stop,
    /// keeps the arm in; the balance region, which replaces `safety.pendulum_limit` after the
    /// catch, within that limit, so that `[safety]` bounds the pendulum whatever `[swing_up]`
    /// says; and the swing voltage within `safety.voltage_limit` (rather than clamped
    /// silently). The error names both keys.
    pub fn validate_swing_up(&self) -> Result<(), ConfigError> {
        let s = &self.spec.swing_up;
        if s.arm_limit >= self.safety.arm_limit {
            return Err(err(
                "swing_up.arm_limit",
                format!(
                    "must be inside safety.arm_limit ({} rad), got {}",
                    self.safety.arm_limit, s.arm_limit
                ),
            ));
        }
        if s.balance_angle > self.safety.pendulum_limit {
            return Err(err(
                "swing_up.balance_angle",
                format!(
                    "must be at most safety.pendulum_limit ({} rad), got {}",
                    self.safety.pendulum_limit, s.balance_angle
                ),
            ));
        }
        if s.max_voltage > self.safety.voltage_limit {
            return Err(err(
                "swing_up.max_voltage",
                format!(
                    "must be at most safety.voltage_limit ({} V), got {}",
                    self.safety.voltage_limit, s.max_voltage
                ),
            ));
        }
        crate::envelope::check_swing_up(self)?;
        // Before the motor moves: a rig the voltage bound and the arm travel cannot swing up
        // (rip-core's energy balance of the last swing) is refused, naming what it would need.
        let plant = self.spec.plant()?;
        let f = rip_core::swingup::feasibility(&plant, s);
        if f.verdict == rip_core::swingup::Verdict::Impossible {
            let key = if f.voltage_needed.is_some() || f.arm_travel_needed.is_none() {
                "swing_up.max_voltage"
            } else {
                "swing_up.arm_limit"
            };
            return Err(err(key, f.to_string()));
        }
        Ok(())
    }

    /// The control period in nanoseconds.
    pub fn period_ns(&self) -> u64 {
        (self.loop_.period_ms * 1e6).round() as u64
    }

    /// The control period in seconds.
    pub fn period_s(&self) -> f64 {
        self.loop_.period_ms * 1e-3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_gives_the_paper_defaults() {
        let cfg = Config::from_toml("").unwrap();
        assert_eq!(cfg, Config::default());
        assert_eq!(cfg.period_ns(), 10_000_000);
        assert_eq!(cfg.spec.lqr.Q, [25.0, 0.0, 50.0, 0.0]);
        assert_eq!(cfg.safety.voltage_limit, 12.0);
    }

    #[test]
    fn a_rig_that_cannot_be_swung_up_is_refused_naming_the_voltage_it_needs() {
        let cfg = Config::from_toml("[swing_up]\nmax_voltage = 0.05\n").unwrap();
        let e = cfg.validate_swing_up().unwrap_err().to_string();
        assert!(e.contains("swing_up.max_voltage"), "{e}");
        assert!(
            e.contains("no swing-up is possible") && e.contains(" V "),
            "{e}"
        );
        Config::default().validate_swing_up().unwrap();
    }

    #[test]
    fn values_are_read() {
        let cfg = Config::from_toml(
            "[loop]\nperiod_ms = 5\nreply_timeout_ms = 2\n[device]\npendulum_zero = \"up\"\n\
             arm_sign = -1\n[mpc]\nprediction_horizon = 20\n",
        )
        .unwrap();
        assert_eq!(cfg.period_ns(), 5_000_000);
        assert_eq!(cfg.device.pendulum_zero, PendulumZero::Up);
        assert_eq!(cfg.device.arm_sign, -1.0);
        assert_eq!(cfg.spec.mpc.prediction_horizon, 20);
        assert_eq!(cfg.spec.mpc.control_horizon, 3);
    }

    #[test]
    fn unknown_keys_are_named() {
        let e = Config::from_toml("[safety]\nvoltage_limt = 5\n").unwrap_err();
        assert!(e.to_string().contains("voltage_limt"), "{e}");
        let e = Config::from_toml("[sefety]\n").unwrap_err();
        assert!(e.to_string().contains("sefety"), "{e}");
    }

    #[test]
    fn bad_values_are_named() {
        for (text, key) in [
            ("[safety]\npendulum_limit = 4.0\n", "safety.pendulum_limit"),
            ("[safety]\nvoltage_limit = -1\n", "safety.voltage_limit"),
            ("[loop]\nreply_timeout_ms = 10\n", "loop.reply_timeout_ms"),
            ("[loop]\nwatchdog_periods = 0\n", "loop.watchdog_periods"),
            (
                "[loop]\nwatchdog_periods = 4294967295\n",
                "loop.watchdog_periods",
            ),
            // 10 periods of 20 ms: 200 ms of driving blind.
            (
                "[loop]\nperiod_ms = 20\nwatchdog_periods = 10\n",
                "loop.watchdog_periods",
            ),
            ("[loop]\nperiod_ms = 1000\n", "loop.period_ms"),
            ("[loop]\nperiod_ms = nan\n", "loop.period_ms"),
            ("[loop]\nreply_timeout_ms = 0.01\n", "loop.reply_timeout_ms"),
            ("[loop]\nmax_step_periods = 0\n", "loop.max_step_periods"),
            ("[loop]\nmax_step_periods = 1e9\n", "loop.max_step_periods"),
            (
                "[loop]\nmax_consecutive_misses = 0\n",
                "loop.max_consecutive_misses",
            ),
            (
                "[loop]\nmax_consecutive_misses = 1000\n",
                "loop.max_consecutive_misses",
            ),
            (
                "[device]\narm_counts_per_rev = 1\n",
                "device.arm_counts_per_rev",
            ),
            (
                "[device]\npendulum_counts_per_rev = 4294967295\n",
                "device.pendulum_counts_per_rev",
            ),
            ("[safety]\nvoltage_limit = 30\n", "safety.voltage_limit"),
            ("[safety]\nvoltage_limit = inf\n", "safety.voltage_limit"),
            ("[safety]\narm_limit = 1e300\n", "safety.arm_limit"),
            ("[safety]\npendulum_limit = 2.0\n", "safety.pendulum_limit"),
            ("[safety]\nwait_upright_s = 1e12\n", "safety.wait_upright_s"),
            (
                "[loop]\nperiod_ms = 0.001\nreply_timeout_ms = 0.0005\n",
                "loop.period_ms",
            ),
            ("[device]\narm_sign = 2\n", "device.arm_sign"),
            ("[lqr]\nR = 0\n", "lqr.R"),
            ("[lqr]\nQ = [1, 2, -3, 4]\n", "lqr.Q[2]"),
            ("[mpc]\ncontrol_horizon = 60\n", "mpc.control_horizon"),
            ("[reference]\narm_step = 5\n", "reference.arm_step"),
            ("[mpc]\nsolver = \"osqp\"\n", "mpc.solver"),
            ("[lqr]\nrate_cutoff = -1\n", "lqr.rate_cutoff"),
            // The old names of this file are gone.
            ("[mpc]\nhorizon = 20\n", "mpc.horizon"),
            ("[lqr]\nq = [1, 2, 3, 4]\n", "lqr.q"),
        ] {
            let e = Config::from_toml(text).unwrap_err();
            assert_eq!(e.key, key, "{text}: {e}");
        }
        let e = Config::from_toml("[loop]\nperiod_ms = \"fast\"\n").unwrap_err();
        assert_eq!(e.key, "loop.period_ms", "{e}");
    }

    #[test]
    fn experiment_sections_get_riprs_messages_and_round_trip() {
        // The same text, the same message as rip-core's (and so riprs's) reader gives.
        for text in [
            "[mpc]\nprediction_horizon = 0\n",
            "[plant]\npreset = \"qube\"\n",
            "[kalman]\nnoise = 1\n",
        ] {
            let ours = Config::from_toml(text).unwrap_err();
            let core = Spec::parse(text).unwrap_err();
            assert_eq!(ours, core, "{text}");
        }
        let text =
            "[loop]\nperiod_ms = 5\nreply_timeout_ms = 2\n[plant]\npreset = \"qube_servo2\"\n";
        let cfg = Config::from_toml(text).unwrap();
        let back = Config::from_toml(&cfg.to_toml()).unwrap();
        assert_eq!(back.to_toml(), cfg.to_toml());
        assert_eq!(back.loop_, cfg.loop_);
        assert!(cfg.to_toml().starts_with(&cfg.spec.to_toml()));
    }
}
