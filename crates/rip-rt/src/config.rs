//! The configuration of `rip-rt run`, `rip-rt emulate` and `rip-rt config`: the experiment
//! file of `rip_core::spec` (`[plant]`, `[sensor]`, `[reference]`, `[lqr]`, `[kalman]`,
//! `[mpc]`, ... read, defaulted and checked by rip-core, exactly as `riprs compare` reads
//! them) plus rip-rt's own sections `[loop]`, `[device]`, `[safety]` and `[calibration]`,
//! defined and checked in rip-core too ([`rip_core::spec::rig_sections`]), so that
//! `riprs config` and `rip-rt config` run one validation. Every key is optional; the defaults are the paper's settings (Ts = 10 ms, |u| ≤ 12 V) and the
//! encoders of the reference rig (2048 counts per revolution each).
//!
//! Unknown keys are rejected, and every value is checked; errors name the file and the key,
//! e.g. `cfg.toml: safety.pendulum_limit: must be in (0, 1.5] rad, got 4`.

use std::path::Path;

use rip_core::spec::{Spec, SpecError};

pub use rip_core::spec::rig_sections::{
    CalibrationConfig, DeviceConfig, LoopConfig, PendulumZero, RigSections, SafetyConfig,
    COUNTS_PER_REV, MAX_ARM_LIMIT, MAX_BLIND_MS, MAX_CONSECUTIVE_MISSES, MAX_PENDULUM_LIMIT,
    MAX_STEP_PERIODS, MAX_VOLTAGE_LIMIT, MAX_WAIT_UPRIGHT_S, MIN_REPLY_TIMEOUT_MS, PERIOD_MS,
    WATCHDOG_PERIODS,
};

/// A configuration problem, naming the file and the key: the experiment file's one error type,
/// so `rip-rt` and `riprs` report a bad key alike.
pub type ConfigError = SpecError;

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

impl Config {
    /// Parses and validates TOML text ([`rip_core::spec::rig_sections::parse_file`], the
    /// check `riprs config` runs too).
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let (spec, rig) = rip_core::spec::rig_sections::parse_file(text)?;
        Ok(Self::from_parts(spec, rig))
    }

    /// Reads, parses and validates a file; errors name it.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let (spec, rig) = rip_core::spec::rig_sections::load_file(path)?;
        Ok(Self::from_parts(spec, rig))
    }

    fn from_parts(spec: Spec, rig: RigSections) -> Self {
        Config {
            loop_: rig.loop_,
            device: rig.device,
            safety: rig.safety,
            calibration: rig.calibration,
            spec,
        }
    }

    /// rip-rt's sections of this configuration.
    pub fn rig(&self) -> RigSections {
        RigSections {
            loop_: self.loop_.clone(),
            device: self.device.clone(),
            safety: self.safety.clone(),
            calibration: self.calibration.clone(),
        }
    }

    /// The resolved configuration as TOML, every default filled in: the experiment sections
    /// exactly as `riprs config` prints them, then `[loop]`, `[device]`, `[safety]` and
    /// `[calibration]`.
    pub fn to_toml(&self) -> String {
        let own = toml::to_string(&self.rig()).expect("every setting has a TOML form");
        format!("{}\n{}", self.spec.to_toml(), own)
    }

    /// Checks every value ([`RigSections::validate`]); the error names the first bad key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.spec.validate()?;
        self.rig().validate(&self.spec)
    }

    /// The swing-up's settings against the safety limits, as [`RigSections::validate`] checks
    /// them for a file that sets `[swing_up]`: what `rip-rt run --swing-up` requires whatever
    /// the file sets, before its braking envelope (`envelope::check_swing_up`). Whether the rig
    /// can be swung up at all is not a setting's fault but the rig's: the pre-flight's
    /// swing_up check judges it (`rip_core::preflight::swing`), which `--force` can override.
    pub fn validate_swing_up(&self) -> Result<(), ConfigError> {
        self.rig().validate_swing_up(&self.spec)
    }

    /// The control period in nanoseconds.
    pub fn period_ns(&self) -> u64 {
        (self.loop_.period_ms * 1e6).round() as u64
    }

    /// The control period in seconds.
    pub fn period_s(&self) -> f64 {
        self.loop_.period_ms * 1e-3
    }

    /// One reading's standard deviation (rad) of the arm and the pendulum: a count's
    /// quantisation (`q/√12`) and `[sensor] noise_std` together.
    pub fn reading_sigma(&self) -> [f64; 2] {
        let tau = std::f64::consts::TAU;
        let d = &self.device;
        let q = [
            tau / f64::from(d.arm_counts_per_rev.max(1)),
            tau / f64::from(d.pendulum_counts_per_rev.max(1)),
        ];
        let s = self.spec.sensor.noise_std;
        std::array::from_fn(|j| (q[j] * q[j] / 12.0 + s[j] * s[j]).sqrt())
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
    fn a_rig_that_cannot_be_swung_up_is_left_to_the_preflight() {
        // Its settings are valid: the refusal is the pre-flight's, which --force overrides.
        let cfg = Config::from_toml("[swing_up]\nmax_voltage = 0.05\n").unwrap();
        cfg.validate_swing_up().unwrap();
        let lqr = crate::controllers::ControllerKind::Lqr;
        let report = crate::controllers::preflight(lqr, &cfg, None, true).unwrap();
        let f = report.finding("swing_up").unwrap();
        assert_eq!(f.verdict, rip_core::preflight::Verdict::Refuse, "{report}");
        assert!(f.message.contains("swing_up.max_voltage"), "{f}");
        assert!(
            f.message.contains("no swing-up is possible") && f.message.contains(" V "),
            "{f}"
        );
        Config::default().validate_swing_up().unwrap();
        // A bad setting is still the configuration's error.
        let mut wide = Config::default();
        wide.spec.swing_up.max_voltage = wide.safety.voltage_limit + 1.0;
        let e = wide.validate_swing_up().unwrap_err();
        assert_eq!(e.key, "swing_up.max_voltage", "{e}");
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
            ("[loop]\nlive_port = 70000\n", "loop.live_port"),
            ("[loop]\nlive_port = -1\n", "loop.live_port"),
            ("[loop]\nlive_port = \"9870\"\n", "loop.live_port"),
            (
                "[sensor]\nencoder_counts = [1, 2048]\n",
                "sensor.encoder_counts[0]",
            ),
            (
                "[sensor]\nencoder_counts = [2048, 4294967295]\n",
                "sensor.encoder_counts[1]",
            ),
            // A key that moved is refused naming the one that replaced it.
            (
                "[device]\npendulum_counts_per_rev = 4096\n",
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
