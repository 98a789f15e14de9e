//! The `[swing_up]` settings: every default declared once, here.

use serde::{Deserialize, Serialize};

use crate::error::{Result, RipError};

/// Largest `swing_up.max_time` (s): two minutes of pumping at up to the full voltage. A rig
/// that has not swung up by then will not (the defaults catch within seconds), and an
/// unbounded value would leave no swing-up timeout at all.
pub const MAX_SWING_UP_TIME: f64 = 120.0;

/// What the supervisor does when the pendulum leaves the balance region after a catch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnFall {
    /// Swing up again (the swing-up clock restarts).
    #[default]
    Retry,
    /// Stop with [`StopCause::LeftBalanceRegion`](crate::controller::StopCause) and 0 V.
    Stop,
}

impl OnFall {
    /// Parses `"retry"` or `"stop"`.
    pub fn from_name(name: &str) -> Result<Self> {
        match name {
            "retry" => Ok(Self::Retry),
            "stop" => Ok(Self::Stop),
            _ => Err(RipError::invalid(
                "swing_up.on_fall",
                format!("must be 'retry' or 'stop', got {name:?}"),
            )),
        }
    }

    /// The name accepted by [`from_name`](Self::from_name).
    pub fn name(self) -> &'static str {
        match self {
            Self::Retry => "retry",
            Self::Stop => "stop",
        }
    }
}

/// How the swing-up brings the pendulum up (`swing_up.method`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SwingUpMethod {
    /// Pump energy (Åström & Furuta) until the pendulum arrives in the catch region.
    #[default]
    Energy,
    /// Follow a trajectory planned on the nominal model from hanging to upright at rest,
    /// tracked by time-varying LQR ([module docs](super::plan)); the energy law where no plan is
    /// found, after a fall, or when the rig strays from the plan.
    Trajectory,
}

impl SwingUpMethod {
    /// The name in the file: `"energy"` or `"trajectory"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Energy => "energy",
            Self::Trajectory => "trajectory",
        }
    }
}

/// Settings of the energy swing-up and of its supervisor (the `[swing_up]` section).
///
/// Accelerations are given as fractions of the *stall acceleration*
/// `a_s = (k_t/R_m) U / (J₀ + J_α)`: the arm acceleration that the full swing-up voltage `U`
/// produces at standstill with the largest arm-axis inertia (pendulum horizontal), computed
/// from the nominal plant. That keeps the defaults meaningful on any rig: both presets swing up
/// with them. The law they enter is derived in the [module docs](super).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SwingUpSettings {
    /// How the pendulum is brought up; default [`SwingUpMethod::Energy`].
    pub method: SwingUpMethod,
    /// Largest voltage the swing-up applies, `U` (V); default the paper's bound,
    /// [`INPUT_LIMIT`](crate::paper::INPUT_LIMIT) (12 V).
    pub max_voltage: f64,
    /// The arm stays within `±arm_limit` (rad) during the swing-up, by the law itself; default
    /// 1.5 rad, inside the ±π/2 that many rigs' cables allow. The balance region ends where
    /// braking could no longer stop the arm inside it (module docs, "Balance"), so a fall is
    /// braked inside it too.
    pub arm_limit: f64,
    /// Braking deceleration `a_b` reserved for the arm limit, as a fraction of `a_s`;
    /// default 0.5 (half the stall acceleration is kept in hand for model errors, back-EMF and
    /// the pendulum's reaction on the arm).
    pub brake_fraction: f64,
    /// Largest pumping acceleration `a_p`, as a fraction of `a_s`; default 0.5.
    pub pump_fraction: f64,
    /// Width `w` (rad/s) of the pumping direction `clamp(α̇ cos α / w, −1, 1)`.
    pub pump_width: f64,
    /// Gain `k_E` from the normalised energy error to the pumping acceleration (saturates at
    /// `|k_E ε| = 1`); default 10, so pumping is at full strength until the energy is within
    /// 10 % of `G` of its target (Åström & Furuta's large-gain, near bang-bang case).
    pub energy_gain: f64,
    /// Target energy above the upright rest energy, as a fraction `δ` of the gravity
    /// stiffness `G = m_p g l_p/2` (on top of the viscous loss still to come, module docs
    /// eq. (1a)); default 0.05: the pendulum reaches upright still moving slowly instead of
    /// creeping towards it for ever.
    pub energy_margin: f64,
    /// Natural frequency `ω_c` (rad/s) of the critically damped spring that keeps the arm
    /// centred around 0 while pumping; default 2.5 rad/s.
    pub arm_centering: f64,
    /// Rate `k_r` (1/s) at which the arm's turning is damped on the last rise, `a_c = −k_r θ̇`
    /// in place of the centring spring while the pendulum rises through the upper half
    /// (`cos α > 0`, `α α̇ < 0`) with its energy within `G/k_E` of the target, the energy
    /// pumped being the pendulum's once the arm is stopped ([module docs](super), "Last
    /// rise", eq. (5)); default 0: off. 15 /s raises the Monte Carlo success on `paper` to
    /// 94 / 81 / 99 % (LQR / LQG / MPC, from 85.5 / 76.5 / 91 %) but lowers it on
    /// `qube_servo2` (docs, "Swing-up"), so it is not the default.
    pub rise_damping: f64,
    /// Rate `λ` (1/s) at which the arm's velocity is pulled back inside the braking envelope;
    /// default 20 /s.
    pub barrier_rate: f64,
    /// Cut-off (Hz) of the filtered differences the swing-up estimates both rates with;
    /// default 20 Hz (the LQR's).
    pub rate_cutoff: f64,
    /// Catch region: `|α|` below this (rad from upright); default 0.3 rad.
    pub catch_angle: f64,
    /// Catch region: the pendulum angle predicted this far ahead, `α + α̇ τ` (τ in s), is also
    /// within `catch_angle`, so a pendulum that is falling away from upright is not caught;
    /// default 0.1 s.
    pub catch_lookahead: f64,
    /// Catch region: the upright's unstable mode `z = wᵀ x` of the nominal model within this
    /// fraction of the largest `|z|` the voltage bound can still return to 0,
    /// `|wᵀ b| U / λ` ([module docs](super), "Catch"); default 0.3, which leaves the balance
    /// controller most of the voltage for the arm.
    pub catch_mode_fraction: f64,
    /// Catch region: `|α̇|` below this (rad/s); default 7 rad/s.
    pub catch_rate: f64,
    /// Catch region: `|θ̇|` below this (rad/s); default 3 rad/s: a faster arm carries the
    /// balance controller's transient into the arm limit.
    pub catch_arm_rate: f64,
    /// Catch region: the arm's stopping point `θ + θ̇|θ̇|/(2 a_b)` (where braking at the
    /// envelope's deceleration `a_b` would stop it) within `±catch_arm_angle` (rad), so that the
    /// balance controller takes over with room to stop the arm inside `arm_limit`; default
    /// 0.7 rad (the balance controllers' catch transients move the arm by up to about 0.8 rad).
    pub catch_arm_angle: f64,
    /// Predicted catch: horizon (s) over which the catch is predicted on the nominal model
    /// under a reference LQR (the `[lqr]` section's default weights) holding the arm where it
    /// is; a state inside the other catch conditions is caught when that prediction keeps the
    /// pendulum within `balance_angle − catch_margin` and the arm and its stopping point within
    /// `arm_limit − catch_margin` ([module docs](super), "Predicted catch"). It replaces the
    /// fixed arm windows `catch_arm_rate` and `catch_arm_angle`, which then go unused.
    /// Default 0: off (the arm windows decide).
    pub catch_prediction: f64,
    /// Room (rad) the predicted catch keeps inside `arm_limit` and `balance_angle` for the
    /// difference between the nominal model and the rig; default 0.2 rad, less than both.
    pub catch_margin: f64,
    /// Rate (rad/s) at which the arm reference moves from the arm's angle at the catch back to
    /// the external reference while that stays unchanged; default 0 (held at the catch angle).
    /// 0.5 rad/s raises the Monte Carlo success of the LQR and LQG on `qube_servo2` from
    /// 81.5 / 54 % to 97 / 77.5 % (docs, "Swing-up"), but on a rig whose pendulum encoder
    /// scale is wrong the returning arm reaches the braking-envelope stop before the witness
    /// names the scale, so it is not yet the default.
    pub reference_return_rate: f64,
    /// Balance region: `|α|` up to this (rad from upright); leaving it (or the arm limit) after
    /// a catch is a fall. Default 0.6 rad (`rip-rt`'s default pendulum limit).
    pub balance_angle: f64,
    /// Within this `|α|` (rad from upright) the balance controller's estimator runs on the
    /// measurements and the swing-up's voltage ([`Controller::observe`]); outside it is
    /// restarted every sample from the swing-up's own estimate ([`Controller::seed`]), because
    /// its linear model does not hold far from upright. Default 0.3 rad (the catch angle): the
    /// paper's Kalman filter is slow next to the last rise of the pendulum, and started from
    /// the swing-up's estimate it is closer to the state at the catch than after observing
    /// the rise (its output-disturbance states would take up the model error of the rise).
    ///
    /// [`Controller::observe`]: crate::Controller::observe
    /// [`Controller::seed`]: crate::Controller::seed
    pub estimator_window: f64,
    /// For this long (s) after the catch, the balance controller's estimator is restarted
    /// every sample, once it has computed its move, from the swing-up's own estimate (the
    /// measured angles and filtered differences) and that move ([`Controller::seed`]); its own
    /// estimate takes over after it. Default 1 s: the catch transient (the pendulum 0.3 rad
    /// from upright, the arm turning at up to 10 rad/s) is outside the range where the
    /// Kalman filter's linear model holds, and the paper's slow filter, left to itself there,
    /// was 0.1 rad and 4 rad/s off the pendulum's state within 0.2 s, which made LQG lose a
    /// quarter of its catches; after 1 s the transient has died down. 0 hands over at once.
    ///
    /// [`Controller::seed`]: crate::Controller::seed
    pub handover_time: f64,
    /// Longest swing-up (s) before giving up with
    /// [`StopCause::SwingUpTimeout`](crate::controller::StopCause); default 20 s, at most
    /// [`MAX_SWING_UP_TIME`].
    pub max_time: f64,
    /// What to do after a fall; default [`OnFall::Retry`].
    pub on_fall: OnFall,
}

impl Default for SwingUpSettings {
    fn default() -> Self {
        Self {
            method: SwingUpMethod::Energy,
            max_voltage: crate::paper::INPUT_LIMIT,
            arm_limit: 1.5,
            brake_fraction: 0.5,
            pump_fraction: 3.0,
            pump_width: 2.0,
            energy_gain: 5.0,
            energy_margin: 0.05,
            arm_centering: 1.5,
            rise_damping: 0.0,
            barrier_rate: 20.0,
            rate_cutoff: 20.0,
            catch_angle: 0.3,
            catch_lookahead: 0.1,
            catch_mode_fraction: 0.3,
            catch_rate: 7.0,
            catch_arm_rate: 3.0,
            catch_arm_angle: 0.7,
            catch_prediction: 0.0,
            catch_margin: 0.2,
            reference_return_rate: 0.0,
            balance_angle: 0.6,
            estimator_window: 0.3,
            handover_time: 1.0,
            max_time: 20.0,
            on_fall: OnFall::Retry,
        }
    }
}

fn in_range(key: &str, v: f64, lo: f64, hi: f64, lo_open: bool, hi_open: bool) -> Result<()> {
    let above = if lo_open { v > lo } else { v >= lo };
    let below = if hi_open { v < hi } else { v <= hi };
    if v.is_finite() && above && below {
        return Ok(());
    }
    let (l, r) = (
        if lo_open { '(' } else { '[' },
        if hi_open { ')' } else { ']' },
    );
    let hi_text = if hi.is_infinite() {
        "∞".to_string()
    } else {
        format!("{hi}")
    };
    Err(RipError::invalid(
        format!("swing_up.{key}"),
        format!("must be in {l}{lo}, {hi_text}{r}, got {v}"),
    ))
}

impl SwingUpSettings {
    /// The relations between keys where one side was left at its default and the other
    /// contradicts it: the refusal names the key that moved from its default (the one a file
    /// wrote) and the values of it that fit, not the default it was checked against.
    fn check_written_against_defaults(&self) -> Result<()> {
        let d = Self::default();
        let refuse = |key: &str, reason: String| Err(RipError::invalid(key.to_string(), reason));
        if self.catch_arm_angle == d.catch_arm_angle && self.arm_limit < d.catch_arm_angle {
            return refuse(
                "swing_up.arm_limit",
                format!(
                    "must be at least swing_up.catch_arm_angle ({} rad, its default), got {}; \
                     or set swing_up.catch_arm_angle in (0, {}]",
                    d.catch_arm_angle, self.arm_limit, self.arm_limit
                ),
            );
        }
        if self.balance_angle == d.balance_angle && self.catch_angle > d.balance_angle {
            return refuse(
                "swing_up.catch_angle",
                format!(
                    "must be at most swing_up.balance_angle ({} rad, its default), got {}; or \
                     set swing_up.balance_angle to at least it",
                    d.balance_angle, self.catch_angle
                ),
            );
        }
        let balance_valid = self.balance_angle > 0.0 && self.balance_angle <= std::f64::consts::PI;
        if self.catch_margin == d.catch_margin
            && balance_valid
            && self.balance_angle >= self.catch_angle
            && self.balance_angle <= d.catch_margin
        {
            return refuse(
                "swing_up.balance_angle",
                format!(
                    "must be above swing_up.catch_margin ({} rad, its default), got {}; or set \
                     swing_up.catch_margin below it",
                    d.catch_margin, self.balance_angle
                ),
            );
        }
        Ok(())
    }

    /// Checks every value; the error names the first bad key as `swing_up.<key>`.
    pub fn validate(&self) -> Result<()> {
        use std::f64::consts::PI;
        let inf = f64::INFINITY;
        in_range("max_voltage", self.max_voltage, 0.0, inf, true, true)?;
        in_range("arm_limit", self.arm_limit, 0.0, PI, true, false)?;
        in_range("brake_fraction", self.brake_fraction, 0.0, 1.0, true, false)?;
        in_range("pump_fraction", self.pump_fraction, 0.0, 10.0, true, false)?;
        in_range("pump_width", self.pump_width, 0.0, inf, true, true)?;
        in_range("energy_gain", self.energy_gain, 0.0, inf, true, true)?;
        in_range("energy_margin", self.energy_margin, 0.0, 1.0, false, false)?;
        in_range("arm_centering", self.arm_centering, 0.0, inf, false, true)?;
        in_range("rise_damping", self.rise_damping, 0.0, inf, false, true)?;
        in_range("barrier_rate", self.barrier_rate, 0.0, inf, true, true)?;
        in_range("rate_cutoff", self.rate_cutoff, 0.0, inf, true, false)?;
        in_range("catch_angle", self.catch_angle, 0.0, PI / 2.0, true, false)?;
        in_range(
            "catch_lookahead",
            self.catch_lookahead,
            0.0,
            1.0,
            false,
            false,
        )?;
        in_range(
            "catch_mode_fraction",
            self.catch_mode_fraction,
            0.0,
            1.0,
            true,
            false,
        )?;
        in_range("catch_rate", self.catch_rate, 0.0, inf, true, true)?;
        in_range("catch_arm_rate", self.catch_arm_rate, 0.0, inf, true, true)?;
        self.check_written_against_defaults()?;
        in_range(
            "catch_arm_angle",
            self.catch_arm_angle,
            0.0,
            self.arm_limit,
            true,
            false,
        )?;
        in_range(
            "catch_prediction",
            self.catch_prediction,
            0.0,
            10.0,
            false,
            false,
        )?;
        in_range(
            "reference_return_rate",
            self.reference_return_rate,
            0.0,
            inf,
            false,
            true,
        )?;
        in_range("balance_angle", self.balance_angle, 0.0, PI, true, false)?;
        if self.balance_angle < self.catch_angle {
            return Err(RipError::invalid(
                "swing_up.balance_angle",
                format!(
                    "must be at least swing_up.catch_angle ({}), got {}",
                    self.catch_angle, self.balance_angle
                ),
            ));
        }
        in_range(
            "estimator_window",
            self.estimator_window,
            0.0,
            PI,
            false,
            true,
        )?;
        // Checked after the two it is measured against, so that their own errors come first.
        in_range(
            "catch_margin",
            self.catch_margin,
            0.0,
            self.arm_limit.min(self.balance_angle),
            false,
            true,
        )?;
        in_range("handover_time", self.handover_time, 0.0, 10.0, false, false)?;
        in_range(
            "max_time",
            self.max_time,
            0.0,
            MAX_SWING_UP_TIME,
            true,
            false,
        )?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_is_named_when_bad() {
        type Spoil = fn(&mut SwingUpSettings);
        let cases: [(&str, Spoil); 8] = [
            ("swing_up.rise_damping", |s| s.rise_damping = -1.0),
            ("swing_up.max_time", |s| s.max_time = 0.0),
            ("swing_up.max_time", |s| s.max_time = 1e300),
            ("swing_up.max_voltage", |s| s.max_voltage = f64::NAN),
            ("swing_up.arm_limit", |s| s.arm_limit = 4.0),
            ("swing_up.balance_angle", |s| s.balance_angle = 0.1),
            ("swing_up.brake_fraction", |s| s.brake_fraction = 1.5),
            ("swing_up.rate_cutoff", |s| s.rate_cutoff = -1.0),
        ];
        for (key, spoil) in cases {
            let mut s = SwingUpSettings::default();
            s.validate().unwrap();
            spoil(&mut s);
            let err = s.validate().unwrap_err().to_string();
            assert!(err.contains(key), "{key}: {err}");
        }
        assert!(OnFall::from_name("again")
            .unwrap_err()
            .to_string()
            .contains("swing_up.on_fall"));
    }

    #[test]
    fn a_toml_section_round_trips_and_rejects_unknown_keys() {
        let s: SwingUpSettings = toml::from_str("max_time = 12.5\non_fall = \"stop\"\n").unwrap();
        assert_eq!(s.max_time, 12.5);
        assert_eq!(s.on_fall, OnFall::Stop);
        assert_eq!(s.catch_angle, SwingUpSettings::default().catch_angle);
        let text = toml::to_string(&s).unwrap();
        assert_eq!(toml::from_str::<SwingUpSettings>(&text).unwrap(), s);
        let err = toml::from_str::<SwingUpSettings>("max_tme = 3.0\n").unwrap_err();
        assert!(err.to_string().contains("max_tme"), "{err}");
        let s: SwingUpSettings = toml::from_str("method = \"trajectory\"\n").unwrap();
        assert_eq!(s.method, SwingUpMethod::Trajectory);
        assert_eq!(SwingUpSettings::default().method, SwingUpMethod::Energy);
        let text = toml::to_string(&s).unwrap();
        assert!(text.contains("method = \"trajectory\""), "{text}");
    }

    #[test]
    fn an_unknown_method_is_an_error_naming_the_key() {
        let err = crate::spec::Spec::parse("[swing_up]\nmethod = \"rocket\"\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("swing_up.method"), "{err}");
        assert!(
            err.contains("energy") && err.contains("trajectory"),
            "{err}"
        );
    }
}
