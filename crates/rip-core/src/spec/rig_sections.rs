//! rip-rt's sections of the experiment file, `[loop]`, `[device]`, `[safety]` and
//! `[calibration]`: their types, defaults, ranges and validation, defined once here so that
//! `riprs config` (through the binding), `rip-rt config` and every `rip-rt` run check a file
//! with the same function ([`parse_file`], [`load_file`]).
//!
//! Besides each key's own range, the sections are checked against the experiment: the arm
//! reference step must lie inside `safety.arm_limit`, and a file that sets `[swing_up]`
//! (anything other than its defaults) must keep the swing-up inside the safety limits
//! (`swing_up.arm_limit < safety.arm_limit`, `swing_up.balance_angle ≤ safety.pendulum_limit`,
//! `swing_up.max_voltage ≤ safety.voltage_limit`); `rip-rt run --swing-up` checks those
//! whatever the file sets, and adds the stopping-distance check of its braking envelope.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{from_value, parse_table, Spec, SpecError, RUNTIME_SECTIONS};

fn err(key: &str, reason: impl Into<String>) -> SpecError {
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
    /// [`MIN_REPLY_TIMEOUT_MS`] and shorter than the period. Default
    /// [`DEFAULT_REPLY_TIMEOUT_MS`], or half the period on a period no longer than that
    /// ([`RigSections::resolve_derived_defaults`]).
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
    /// UDP port on 127.0.0.1 to which every period's telemetry is published for `riprs
    /// watch` (rip-rt's `live` module), 0 for none; `--live PORT` overrides it. A viewer that
    /// is slow or absent loses frames, never the loop's timing.
    pub live_port: u16,
}

pub use crate::sim::PERIOD_MS;
/// Default `loop.reply_timeout_ms` (ms), on a period longer than it.
pub const DEFAULT_REPLY_TIMEOUT_MS: f64 = 5.0;
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
            // The controllers are designed at the paper's sample time.
            period_ms: crate::paper::TS * 1000.0,
            reply_timeout_ms: DEFAULT_REPLY_TIMEOUT_MS,
            watchdog_periods: 5,
            max_step_periods: 2.0,
            max_consecutive_misses: 5,
            live_port: 0,
        }
    }
}

/// `[device]`: how encoder counts map to angles.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct DeviceConfig {
    /// Arm encoder counts per revolution (after quadrature decoding). Not a key of
    /// `[device]`: the file gives it once, as `[sensor] encoder_counts[0]`, and
    /// [`parse_file`] copies it here.
    #[serde(skip)]
    pub arm_counts_per_rev: u32,
    /// Pendulum encoder counts per revolution: `[sensor] encoder_counts[1]`, as the arm's.
    #[serde(skip)]
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
        // The counts are `[sensor] encoder_counts`; unparsed, its default.
        let [arm, pendulum] = super::sections::SensorSpec::default().encoder_counts;
        Self {
            arm_counts_per_rev: arm,
            pendulum_counts_per_rev: pendulum,
            pendulum_zero: PendulumZero::Down,
            arm_sign: 1.0,
            pendulum_sign: 1.0,
        }
    }
}

pub use super::sections::COUNTS_PER_REV;
/// Largest `safety.voltage_limit` (V): the rigs this loop is for have 12 V to 24 V motors.
pub const MAX_VOLTAGE_LIMIT: f64 = 24.0;
/// Largest `safety.pendulum_limit` (rad): past horizontal no balancing controller recovers.
pub const MAX_PENDULUM_LIMIT: f64 = std::f64::consts::FRAC_PI_2;
/// Largest `safety.arm_limit` (rad): one turn either way, before the cable winds up.
pub const MAX_ARM_LIMIT: f64 = std::f64::consts::TAU;
/// Default `safety.start_tolerance` (rad), on a `safety.pendulum_limit` wider than it.
pub const DEFAULT_START_TOLERANCE: f64 = 0.15;
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
    /// Balancing starts only with |pendulum angle| below this (rad), below `pendulum_limit`.
    /// Default [`DEFAULT_START_TOLERANCE`], or half of `pendulum_limit` on a limit no wider
    /// than that ([`RigSections::resolve_derived_defaults`]).
    pub start_tolerance: f64,
    /// How long to wait for the pendulum to be brought upright before refusing (s), in
    /// [0, [`MAX_WAIT_UPRIGHT_S`]]; 0 refuses at once.
    pub wait_upright_s: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            voltage_limit: crate::paper::INPUT_LIMIT,
            pendulum_limit: 0.6,
            arm_limit: 3.0,
            start_tolerance: DEFAULT_START_TOLERANCE,
            wait_upright_s: 0.0,
        }
    }
}

/// rip-rt's own sections of the file: `[loop]`, `[device]`, `[safety]`, `[calibration]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct RigSections {
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

/// The span (s) over which rates are taken from encoder differences (module docs).
pub const RATE_SPAN_S: f64 = 0.1;
/// Default rest-rate threshold (rad/s) of `[calibration]`, on encoders fine enough for it.
pub const DEFAULT_REST_RATE: f64 = 0.2;
/// The default rest-rate threshold on an encoder too coarse for [`DEFAULT_REST_RATE`]:
/// this many counts per [`RATE_SPAN_S`] (one count more than the validation's floor of 2).
pub const DEFAULT_REST_RATE_COUNTS: f64 = 3.0;
/// Allowed `calibration.rest_window_s` (s): at least a few rate spans, at most a patient wait.
pub const REST_WINDOW_S: std::ops::RangeInclusive<f64> = 0.2..=10.0;
/// Default `calibration.rest_timeout_s` (s), on a window no longer than it.
pub const DEFAULT_REST_TIMEOUT_S: f64 = 3.0;
/// Longest `calibration.rest_timeout_s` (s); the motor stays disabled while waiting.
pub const MAX_REST_TIMEOUT_S: f64 = 600.0;
/// Largest rate threshold (rad/s): above it a gently swinging pendulum would pass.
pub const MAX_REST_RATE: f64 = 1.0;
/// Largest `calibration.max_pendulum_offset` (rad, about 11°): the accepted offset becomes an
/// error of the upright by as much, and already a tenth of a radian makes the balance
/// controllers drop the pendulum they caught.
pub const MAX_PENDULUM_OFFSET: f64 = 0.2;
/// Allowed `calibration.rest_counts`.
pub const REST_COUNTS: std::ops::RangeInclusive<u32> = 1..=64;

/// `[calibration]`: when the rig counts as at rest, and how far from hanging its rest pose may
/// be (module docs). Every key is optional.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationConfig {
    /// Both joints must be still for this long (s), in [`REST_WINDOW_S`]; the encoder zeros
    /// are the means over this window. Default 1 s.
    pub rest_window_s: f64,
    /// The check refuses when no window was still this long (s) after it started, in
    /// [`rest_window_s`, [`MAX_REST_TIMEOUT_S`]]. Default [`DEFAULT_REST_TIMEOUT_S`], or
    /// three windows when `rest_window_s` is longer than that
    /// ([`RigSections::resolve_derived_defaults`]).
    ///
    /// [`rest_window_s`]: Self::rest_window_s
    pub rest_timeout_s: f64,
    /// After the sign check's pulse of a swing-up run the rig must be at rest again (the same
    /// window and thresholds) within this long (s), in [`rest_window_s`,
    /// [`MAX_REST_TIMEOUT_S`]], before it is calibrated and swung up: a swing that starts
    /// from the pulse's aftermath starts from a state the swing-up was not tuned for. The
    /// pendulum, swinging a few tenths of a radian after the pulse, may need several of its
    /// damping time constants. Default 30 s.
    ///
    /// [`rest_window_s`]: Self::rest_window_s
    pub settle_timeout_s: f64,
    /// Largest arm rate (rad/s) over any [`RATE_SPAN_S`] of the window, in
    /// (2 counts per span, [`MAX_REST_RATE`]]. Default 0.2 rad/s, or 3 counts per span on an
    /// encoder too coarse for that ([`CalibrationConfig::resolve_default_rates`]).
    pub rest_arm_rate: f64,
    /// Largest pendulum rate (rad/s), as [`rest_arm_rate`](Self::rest_arm_rate), with the
    /// same default.
    pub rest_pendulum_rate: f64,
    /// Largest spread (max − min, counts) of either encoder's 0.1 s means over the window, in
    /// [`REST_COUNTS`]. Default 6 counts (2048 counts per revolution: 18 mrad).
    pub rest_counts: u32,
    /// Largest distance (rad) of the pendulum's rest pose from hanging as `[device]` reads it
    /// (`pendulum_zero`), in (0, [`MAX_PENDULUM_OFFSET`]]. Default 0.05 rad (about 3°, 16
    /// counts at 2048 per revolution): Coulomb friction lets a free pendulum rest within about
    /// a degree of hanging, and a pose farther off (held, leaning on the cable) would shift the
    /// upright by as much, since the calibration takes it as exactly π.
    pub max_pendulum_offset: f64,
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        Self {
            rest_window_s: 1.0,
            rest_timeout_s: DEFAULT_REST_TIMEOUT_S,
            settle_timeout_s: 30.0,
            rest_arm_rate: DEFAULT_REST_RATE,
            rest_pendulum_rate: DEFAULT_REST_RATE,
            rest_counts: 6,
            max_pendulum_offset: 0.05,
        }
    }
}

impl CalibrationConfig {
    /// The rest rates the file did not set (`given` false), for encoders of `counts` per
    /// revolution (arm, pendulum): the default [`DEFAULT_REST_RATE`], or
    /// [`DEFAULT_REST_RATE_COUNTS`] counts per [`RATE_SPAN_S`] where that is more (an encoder
    /// under about 940 counts per revolution), so that the default stays a count above the
    /// validation's floor of 2 counts per span on every encoder of the rig envelope (512
    /// counts and up; at 512 the floor, 0.245 rad/s, is above 0.2 rad/s).
    pub fn resolve_default_rates(&mut self, counts: [u32; 2], given: [bool; 2]) {
        let rates = [&mut self.rest_arm_rate, &mut self.rest_pendulum_rate];
        for ((rate, counts), given) in rates.into_iter().zip(counts).zip(given) {
            if !given {
                let coarse = DEFAULT_REST_RATE_COUNTS * std::f64::consts::TAU
                    / f64::from(counts.max(1))
                    / RATE_SPAN_S;
                *rate = DEFAULT_REST_RATE.max(coarse).min(MAX_REST_RATE);
            }
        }
    }

    /// Checks every value against its range (and the rate thresholds against the encoders'
    /// resolution in `device`); the error names the key.
    pub fn validate(&self, device: &DeviceConfig) -> Result<(), SpecError> {
        let bad = |key: &str, reason: String| Err(SpecError::new(key, reason));
        if !REST_WINDOW_S.contains(&self.rest_window_s) {
            return bad(
                "calibration.rest_window_s",
                format!(
                    "must be in [{}, {}] s, got {}",
                    REST_WINDOW_S.start(),
                    REST_WINDOW_S.end(),
                    Shown(self.rest_window_s)
                ),
            );
        }
        if !(self.rest_timeout_s >= self.rest_window_s && self.rest_timeout_s <= MAX_REST_TIMEOUT_S)
        {
            return bad(
                "calibration.rest_timeout_s",
                format!(
                    "must be in [calibration.rest_window_s ({}), {MAX_REST_TIMEOUT_S}] s, got {}",
                    self.rest_window_s,
                    Shown(self.rest_timeout_s)
                ),
            );
        }
        if !(self.settle_timeout_s >= self.rest_window_s
            && self.settle_timeout_s <= MAX_REST_TIMEOUT_S)
        {
            return bad(
                "calibration.settle_timeout_s",
                format!(
                    "must be in [calibration.rest_window_s ({}), {MAX_REST_TIMEOUT_S}] s, got {}",
                    self.rest_window_s,
                    Shown(self.settle_timeout_s)
                ),
            );
        }
        for (key, rate, counts) in [
            (
                "calibration.rest_arm_rate",
                self.rest_arm_rate,
                device.arm_counts_per_rev,
            ),
            (
                "calibration.rest_pendulum_rate",
                self.rest_pendulum_rate,
                device.pendulum_counts_per_rev,
            ),
        ] {
            let floor = 2.0 * std::f64::consts::TAU / f64::from(counts.max(1)) / RATE_SPAN_S;
            if !(rate > floor && rate <= MAX_REST_RATE) {
                return bad(
                    key,
                    format!(
                        "must be in ({floor:.4}, {MAX_REST_RATE}] rad/s (above 2 counts per \
                         {RATE_SPAN_S} s at {counts} counts/rev), got {rate}"
                    ),
                );
            }
        }
        if !REST_COUNTS.contains(&self.rest_counts) {
            return bad(
                "calibration.rest_counts",
                format!(
                    "must be in {}..={}, got {}",
                    REST_COUNTS.start(),
                    REST_COUNTS.end(),
                    self.rest_counts
                ),
            );
        }
        if !(self.max_pendulum_offset > 0.0 && self.max_pendulum_offset <= MAX_PENDULUM_OFFSET) {
            return bad(
                "calibration.max_pendulum_offset",
                format!(
                    "must be in (0, {MAX_PENDULUM_OFFSET}] rad (the accepted offset shifts the \
                     upright by as much), got {}",
                    self.max_pendulum_offset
                ),
            );
        }
        Ok(())
    }
}

/// A value as an error shows it: `{}` of an `f64` writes 1e300 as 301 digits, so values
/// outside `[1e-4, 1e15)` in magnitude are written in exponent form.
struct Shown(f64);

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a.is_finite() && a != 0.0 && !(1e-4..1e15).contains(&a) {
            write!(f, "{:e}", self.0)
        } else {
            write!(f, "{}", self.0)
        }
    }
}

fn positive(key: &str, v: f64) -> Result<(), SpecError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(err(
            key,
            format!("must be a positive number, got {}", Shown(v)),
        ))
    }
}

fn in_range(
    key: &str,
    v: f64,
    range: std::ops::RangeInclusive<f64>,
    unit: &str,
) -> Result<(), SpecError> {
    if range.contains(&v) {
        Ok(())
    } else {
        Err(err(
            key,
            format!(
                "must be in [{}, {}] {unit}, got {}",
                range.start(),
                range.end(),
                Shown(v)
            ),
        ))
    }
}

fn in_open_closed(key: &str, v: f64, max: f64, unit: &str) -> Result<(), SpecError> {
    if v > 0.0 && v <= max {
        Ok(())
    } else {
        Err(err(
            key,
            format!("must be in (0, {max}] {unit}, got {}", Shown(v)),
        ))
    }
}

fn sign(key: &str, v: f64) -> Result<(), SpecError> {
    if v == 1.0 || v == -1.0 {
        Ok(())
    } else {
        Err(err(key, format!("must be 1 or -1, got {}", Shown(v))))
    }
}

impl RigSections {
    /// Reads the sections from the runtime tables of a file ([`Spec::parse_with_runtime`]);
    /// an unknown key or a value of the wrong type names its key. Values are not checked
    /// ([`validate`](Self::validate)).
    pub fn from_runtime(runtime: toml::Table) -> Result<Self, SpecError> {
        from_value(toml::Value::Table(runtime), "")
    }

    /// Checks every value of these sections and their relations to `spec` (module docs);
    /// the error names the first bad key.
    pub fn validate(&self, spec: &Spec) -> Result<(), SpecError> {
        self.validate_loop()?;
        self.validate_device()?;
        self.validate_safety()?;
        self.calibration.validate(&self.device)?;
        let s = &self.safety;
        let r = &spec.reference;
        if r.arm_step.abs() >= s.arm_limit {
            // A file that narrows only the arm limit is refused through it, not through the
            // step it left at its default.
            let default_step = super::ReferenceSpec::default().arm_step;
            if r.arm_step == default_step {
                return Err(err(
                    "safety.arm_limit",
                    format!(
                        "must be above |reference.arm_step| ({} rad, its default), got {}; or \
                         set reference.arm_step inside it",
                        default_step.abs(),
                        s.arm_limit
                    ),
                ));
            }
            return Err(err(
                "reference.arm_step",
                format!(
                    "must be inside safety.arm_limit ({}), got {}",
                    s.arm_limit, r.arm_step
                ),
            ));
        }
        if spec.swing_up != crate::swingup::SwingUpSettings::default() {
            self.validate_swing_up(spec)?;
        }
        Ok(())
    }

    fn validate_loop(&self) -> Result<(), SpecError> {
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

    fn validate_device(&self) -> Result<(), SpecError> {
        let d = &self.device;
        sign("device.arm_sign", d.arm_sign)?;
        sign("device.pendulum_sign", d.pendulum_sign)
    }

    fn validate_safety(&self) -> Result<(), SpecError> {
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
    /// silently). The error names both keys, and is against the swing-up key unless the file
    /// left that at its default.
    pub fn validate_swing_up(&self, spec: &Spec) -> Result<(), SpecError> {
        let s = &spec.swing_up;
        let d = crate::swingup::SwingUpSettings::default();
        let safety = &self.safety;
        // (swing-up key, its value, its default, safety key, its value, whether the pair
        // fails, what the swing-up key must be of the limit, what the limit must be of it)
        let relations = [
            (
                "swing_up.arm_limit",
                s.arm_limit,
                d.arm_limit,
                "safety.arm_limit",
                safety.arm_limit,
                s.arm_limit >= safety.arm_limit,
                ("inside", "above"),
                "rad",
            ),
            (
                "swing_up.balance_angle",
                s.balance_angle,
                d.balance_angle,
                "safety.pendulum_limit",
                safety.pendulum_limit,
                s.balance_angle > safety.pendulum_limit,
                ("at most", "at least"),
                "rad",
            ),
            (
                "swing_up.max_voltage",
                s.max_voltage,
                d.max_voltage,
                "safety.voltage_limit",
                safety.voltage_limit,
                s.max_voltage > safety.voltage_limit,
                ("at most", "at least"),
                "V",
            ),
        ];
        for (swing_key, v, default, safety_key, limit, fails, (relation, inverse), unit) in
            relations
        {
            if !fails {
                continue;
            }
            // A swing-up key the file left at its default is not the file's doing: the
            // refusal names the safety limit it wrote.
            return Err(if v == default {
                err(
                    safety_key,
                    format!(
                        "must be {inverse} {swing_key} ({v} {unit}, its default) for a \
                         swing-up, got {limit}; or set {swing_key} to fit"
                    ),
                )
            } else {
                err(
                    swing_key,
                    format!("must be {relation} {safety_key} ({limit} {unit}), got {v}"),
                )
            });
        }
        Ok(())
    }

    /// Fills in the defaults that follow from other keys, for each key `given` says the file
    /// did not write (`given("loop.reply_timeout_ms")`): the rest rates from the encoders'
    /// `encoder_counts` ([`CalibrationConfig::resolve_default_rates`]); and, where the key they
    /// are checked against leaves no room for their fixed default, `loop.reply_timeout_ms`
    /// half the period, `safety.start_tolerance` half of `safety.pendulum_limit`,
    /// `calibration.rest_timeout_s` three windows. Every file the fixed defaults passed keeps
    /// them; a written key can no longer make a default it did not write fail.
    pub fn resolve_derived_defaults(
        &mut self,
        encoder_counts: [u32; 2],
        given: impl Fn(&str) -> bool,
    ) {
        self.calibration.resolve_default_rates(
            encoder_counts,
            [
                given("calibration.rest_arm_rate"),
                given("calibration.rest_pendulum_rate"),
            ],
        );
        let l = &mut self.loop_;
        if !given("loop.reply_timeout_ms") && l.period_ms <= DEFAULT_REPLY_TIMEOUT_MS {
            l.reply_timeout_ms = l.period_ms / 2.0;
        }
        let s = &mut self.safety;
        if !given("safety.start_tolerance") && s.pendulum_limit <= DEFAULT_START_TOLERANCE {
            s.start_tolerance = s.pendulum_limit / 2.0;
        }
        let c = &mut self.calibration;
        if !given("calibration.rest_timeout_s") && c.rest_window_s > DEFAULT_REST_TIMEOUT_S {
            c.rest_timeout_s = 3.0 * c.rest_window_s;
        }
    }
}

/// Names every top-level section of the file in an "unknown field" error of the experiment's
/// reader, which knows only its own.
fn name_every_section(e: SpecError) -> SpecError {
    let top_level = !e.key.is_empty() && !e.key.contains('.');
    if !(top_level && e.reason.starts_with("unknown field") && e.reason.contains("expected one of"))
    {
        return e;
    }
    let mut reason = e.reason.clone();
    for name in RUNTIME_SECTIONS {
        reason.push_str(&format!(", `{name}`"));
    }
    SpecError { reason, ..e }
}

/// rip-rt's sections of a file, `runtime` as the file gave them ([`Spec::parse_with_runtime`]),
/// completed from `spec` (the encoder resolution is `sensor.encoder_counts`) and by the
/// defaults that follow from other keys ([`RigSections::resolve_derived_defaults`]), and
/// checked in full, their relations to `spec` included
/// ([`RigSections::validate`]): the one check of a file's rig, whether it was read from text
/// or changed in memory (`riprs.Spec.updated`).
pub fn resolve(spec: &Spec, runtime: &toml::Table) -> Result<RigSections, SpecError> {
    let mut rig = RigSections::from_runtime(runtime.clone())?;
    [
        rig.device.arm_counts_per_rev,
        rig.device.pendulum_counts_per_rev,
    ] = spec.sensor.encoder_counts;
    let given = |path: &str| {
        let (section, key) = path.split_once('.').unwrap_or((path, ""));
        runtime.get(section).and_then(|c| c.get(key)).is_some()
    };
    rig.resolve_derived_defaults(spec.sensor.encoder_counts, given);
    rig.validate(spec)?;
    Ok(rig)
}

/// Parses and checks a whole file: the experiment's sections ([`Spec::parse_with_runtime`])
/// and rip-rt's ([`resolve`]).
pub fn parse_file(text: &str) -> Result<(Spec, RigSections), SpecError> {
    // A TOML syntax error is reported as by the experiment's reader.
    parse_table(text)?;
    let (spec, runtime) = Spec::parse_with_runtime(text).map_err(name_every_section)?;
    let rig = resolve(&spec, &runtime)?;
    Ok((spec, rig))
}

/// Reads and checks a whole file ([`parse_file`]); errors name it.
pub fn load_file(path: &Path) -> Result<(Spec, RigSections), SpecError> {
    parse_file(&super::read_text(path)?).map_err(|e| e.in_file(path))
}

/// Parses and checks a whole file as [`parse_file`] does, returning rip-rt's sections as the
/// file gave them: what a file written back ([`file_toml`]) carries so that it describes the
/// same rig (a `[safety] voltage_limit` of a 6 V motor, a reversed encoder's `arm_sign`).
pub fn parse_file_as_given(text: &str) -> Result<(Spec, toml::Table), SpecError> {
    let (spec, _) = parse_file(text)?;
    let (_, given) = Spec::parse_with_runtime(text)?;
    Ok((spec, given))
}

/// [`parse_file_as_given`] of the file at `path`; errors name the file.
pub fn load_file_as_given(path: &Path) -> Result<(Spec, toml::Table), SpecError> {
    parse_file_as_given(&super::read_text(path)?).map_err(|e| e.in_file(path))
}

/// The text of a whole file: the resolved experiment ([`Spec::to_toml`]), then rip-rt's
/// sections as given (`rig`, from [`parse_file_as_given`]). [`parse_file`] reads it back to
/// the same spec and the same rig sections.
pub fn file_toml(spec: &Spec, rig: &toml::Table) -> String {
    let mut text = spec.to_toml();
    if !rig.is_empty() {
        text.push('\n');
        text.push_str(&toml::to_string(rig).expect("a parsed table has a TOML form"));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key_of(text: &str) -> String {
        parse_file(text).unwrap_err().key
    }

    #[test]
    fn a_huge_value_is_shown_in_exponent_form() {
        let e = parse_file("[safety]\nwait_upright_s = 1e300\n").unwrap_err();
        assert!(e.reason.ends_with("got 1e300"), "{e}");
        let e = parse_file("[calibration]\nsettle_timeout_s = 1e300\n").unwrap_err();
        assert!(e.reason.ends_with("got 1e300"), "{e}");
        assert_eq!(Shown(0.2).to_string(), "0.2");
        assert_eq!(Shown(-1e-7).to_string(), "-1e-7");
    }

    #[test]
    fn a_written_file_keeps_the_rig_sections_it_was_read_with() {
        let text = "[plant]\npreset = \"qube_servo2\"\n[sensor]\nencoder_counts = [1024, 512]\n\
                    [safety]\nvoltage_limit = 6.0\narm_limit = 1.2\n[device]\narm_sign = -1.0\n\
                    [loop]\nperiod_ms = 5.0\nreply_timeout_ms = 2.0\n[calibration]\nrest_window_s = 0.5\n";
        let (spec, given) = parse_file_as_given(text).unwrap();
        let written = file_toml(&spec, &given);
        let ((back, rig), (read, read_rig)) =
            (parse_file(&written).unwrap(), parse_file(text).unwrap());
        assert_eq!((back.resolved(), &rig), (read.resolved(), &read_rig));
        assert_eq!(rig.safety.voltage_limit, 6.0);
        assert_eq!(rig.device.arm_sign, -1.0);
        assert_eq!(rig.device.arm_counts_per_rev, 1024);
        assert_eq!(rig.loop_.period_ms, 5.0);
        // Without rig sections the text is the spec's own.
        let (plain, none) = parse_file_as_given("[reference]\nstep_time = 0.5\n").unwrap();
        assert_eq!(file_toml(&plain, &none), plain.to_toml());
    }

    #[test]
    fn the_default_rest_rates_follow_a_coarse_encoder_and_a_given_rate_is_checked() {
        let tau = std::f64::consts::TAU;
        let (_, rig) = parse_file("[sensor]\nencoder_counts = [512, 4096]\n").unwrap();
        let c = &rig.calibration;
        assert!((c.rest_arm_rate - 3.0 * tau / 512.0 / RATE_SPAN_S).abs() < 1e-12);
        assert_eq!(c.rest_pendulum_rate, DEFAULT_REST_RATE);
        let (_, rig) = parse_file("").unwrap();
        assert_eq!(rig.calibration.rest_arm_rate, DEFAULT_REST_RATE);
        // A rate the file sets is used as given, and refused below the encoder's floor.
        let text = "[sensor]\nencoder_counts = [512, 4096]\n[calibration]\nrest_arm_rate = 0.2\n";
        assert_eq!(key_of(text), "calibration.rest_arm_rate");
        let text = "[sensor]\nencoder_counts = [512, 4096]\n[calibration]\nrest_arm_rate = 0.5\n";
        assert_eq!(parse_file(text).unwrap().1.calibration.rest_arm_rate, 0.5);
    }

    #[test]
    fn defaults_pass_and_keep_the_paper_settings() {
        let (spec, rig) = parse_file("").unwrap();
        assert_eq!(spec, Spec::default());
        assert_eq!(rig, RigSections::default());
        assert_eq!(rig.loop_.period_ms, 10.0);
        assert_eq!(rig.safety.voltage_limit, crate::paper::INPUT_LIMIT);
    }

    #[test]
    fn the_rig_sections_are_checked_in_full() {
        for (text, key) in [
            ("loop = 3\n", "loop"),
            ("[device]\narm_sign = 0\n", "device.arm_sign"),
            ("[loop]\nperiod_ms = \"x\"\n", "loop.period_ms"),
            ("[loop]\nperiod_ms = 1e308\n", "loop.period_ms"),
            ("[safety]\nvoltage_limt = 5\n", "safety.voltage_limt"),
            (
                "[calibration]\nrest_counts = 0\n",
                "calibration.rest_counts",
            ),
            ("[reference]\narm_step = 3.5\n", "reference.arm_step"),
        ] {
            assert_eq!(key_of(text), key, "{text}");
        }
    }

    #[test]
    fn a_file_that_sets_the_swing_up_keeps_it_inside_the_safety_limits() {
        for (text, key) in [
            (
                "[swing_up]\nbalance_angle = 0.7\n",
                "swing_up.balance_angle",
            ),
            ("[swing_up]\nmax_voltage = 13\n", "swing_up.max_voltage"),
            ("[swing_up]\narm_limit = 3.1\n", "swing_up.arm_limit"),
        ] {
            assert_eq!(key_of(text), key, "{text}");
        }
        // The same values pass with safety limits that hold them.
        parse_file("[swing_up]\narm_limit = 3.1\n[safety]\narm_limit = 3.5\n").unwrap();
    }

    #[test]
    fn an_unknown_section_lists_every_section() {
        let e = parse_file("[sefety]\n").unwrap_err();
        assert_eq!(e.key, "sefety");
        for name in ["plant", "mpc", "loop", "device", "safety", "calibration"] {
            assert!(e.reason.contains(&format!("`{name}`")), "{e}");
        }
    }
}
