//! The motor-sign and encoder-direction check that `rip-rt excite` runs before any
//! experiment: a short, small voltage pulse, then 0 V, with both encoders watched.
//!
//! # What a correctly wired rig does
//!
//! The pulse is a doublet, `+V` then `−V` for [`PULSE_S`] each, then 0 V for [`WATCH_S`]: the
//! second half brakes the arm. A positive voltage turns the arm the positive θ way (the convention of `rip_core::plant`
//! and `docs/protocol.md`). The hanging pendulum follows the arm by reaction: linearised about
//! hanging (`α = π + δ`), its equation of motion (plant module) reads
//!
//! ```text
//! J_α δ̈ + G δ = −m₁₂ θ̈
//! ```
//!
//! so while the pulse's first half accelerates the arm positively the pendulum first swings
//! **negatively**
//! in δ, as its mass lags behind the arm. The check takes the sign of the first arm excursion
//! beyond [`MIN_ARM_COUNTS`] and of the first pendulum excursion beyond
//! [`MIN_PENDULUM_COUNTS`] (both from the angles at the start of the pulse, with `[device]`'s
//! signs applied), and needs
//!
//! ```text
//! s_arm = sign Δθ = +1                   (the motor and the arm encoder agree)
//! s_pend = sign Δδ = −s_arm              (the pendulum encoder agrees with the arm's)
//! ```
//!
//! # What a failure says
//!
//! Three sign errors are possible (motor leads, arm encoder, pendulum encoder), but only two
//! relative signs can be seen, so each failure has one fix that makes the rig consistent:
//!
//! | arm moved | pendulum reaction | diagnosis | fix |
//! |---|---|---|---|
//! | negative | agrees with the arm | motor reversed | swap the motor leads |
//! | negative | disagrees | arm encoder reversed | flip `device.arm_sign` |
//! | positive | disagrees | pendulum encoder reversed | flip `device.pendulum_sign` |
//! | nothing | counted | arm encoder dead | check the arm encoder's cable |
//! | counted | nothing | pendulum encoder dead | check the pendulum encoder's cable |
//! | nothing | nothing | motor did not turn (or both encoders dead) | driver, supply, motor cable |
//!
//! (A reversed motor with a reversed pendulum encoder shows as a reversed arm encoder: flipping
//! `arm_sign` then makes the measured coordinates those of the mirrored rig, which the model
//! describes equally well.)

use rip_core::swingup::wrap_angle;

use crate::config::Config;

/// Pulse voltage (V) by default, capped at `safety.voltage_limit`: a few times the dead
/// zone of a typical rig (0.65 V on a QUBE-Servo 3), a fraction of its rated voltage.
pub const PULSE_VOLTAGE: f64 = 2.0;
/// Length (s) of each half of the pulse (`+V`, then `−V`): long enough that the hanging
/// pendulum swings measurably by reaction; the second half brakes the arm, so that a light arm
/// ends nearly at rest a short way from its start instead of coasting towards its limit.
pub const PULSE_S: f64 = 0.15;
/// How long (s) both encoders are watched at 0 V after the pulse.
pub const WATCH_S: f64 = 0.3;
/// The arm must move at least this many counts (2048 counts/rev: 25 mrad).
pub const MIN_ARM_COUNTS: f64 = 8.0;
/// The pendulum must move at least this many counts (2048 counts/rev: 12 mrad).
pub const MIN_PENDULUM_COUNTS: f64 = 4.0;

/// Why the check refused the rig (module docs); the message says what to swap.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SignFault {
    /// Neither encoder counted.
    #[error(
        "neither encoder counted during the ±{voltage} V pulse of 2 × {pulse_s} s (arm {arm:.1}, \
         pendulum {pendulum:.1} counts): the motor did not turn (is the driver powered and \
         enabled, the motor connected?) or neither encoder is connected"
    )]
    NoMotion {
        /// Pulse voltage (V).
        voltage: f64,
        /// Pulse length (s).
        pulse_s: f64,
        /// Largest arm movement (counts).
        arm: f64,
        /// Largest pendulum movement (counts).
        pendulum: f64,
    },
    /// The pendulum moved, the arm encoder did not count.
    #[error(
        "the arm encoder did not count ({arm:.1} counts, at least {MIN_ARM_COUNTS} expected) \
         while the pendulum moved {pendulum:.1} counts: check the arm encoder's cable and \
         sensor.encoder_counts[0]"
    )]
    ArmEncoderSilent {
        /// Largest arm movement (counts).
        arm: f64,
        /// Largest pendulum movement (counts).
        pendulum: f64,
    },
    /// The arm moved, the pendulum encoder did not count.
    #[error(
        "the pendulum encoder did not count ({pendulum:.1} counts, at least \
         {MIN_PENDULUM_COUNTS} expected) while the arm moved {arm:.1} counts, which swings a \
         hanging pendulum by reaction: check the pendulum encoder's cable and \
         sensor.encoder_counts[1]"
    )]
    PendulumEncoderSilent {
        /// Largest arm movement (counts).
        arm: f64,
        /// Largest pendulum movement (counts).
        pendulum: f64,
    },
    /// The arm moved the negative way and the pendulum's reaction agrees with it.
    #[error(
        "a positive voltage turned the arm the negative way ({arm:+.1} counts) and the \
         pendulum's reaction agrees with the arm encoder: the motor is reversed; swap the motor \
         leads (or its direction in the firmware)"
    )]
    MotorReversed {
        /// First arm excursion (counts).
        arm: f64,
    },
    /// The arm read the negative way and the pendulum's reaction disagrees with it.
    #[error(
        "the arm encoder counts backwards: a positive voltage read {arm:+.1} counts of arm \
         motion while the pendulum's reaction shows a positive turn; set device.arm_sign = \
         {fix} (or swap the arm encoder's A and B channels)"
    )]
    ArmEncoderReversed {
        /// First arm excursion (counts).
        arm: f64,
        /// The `device.arm_sign` that fixes it.
        fix: i32,
    },
    /// The pendulum's reaction has the wrong sign for the arm's motion.
    #[error(
        "the pendulum encoder counts backwards: the arm turned the positive way ({arm:+.1} \
         counts) but the hanging pendulum first swung {pendulum:+.1} counts, with the arm \
         instead of behind it; set device.pendulum_sign = {fix} (or swap the pendulum \
         encoder's A and B channels)"
    )]
    PendulumEncoderReversed {
        /// First arm excursion (counts).
        arm: f64,
        /// First pendulum excursion (counts).
        pendulum: f64,
        /// The `device.pendulum_sign` that fixes it.
        fix: i32,
    },
}

/// What a passed check measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignReport {
    /// Pulse voltage (V).
    pub voltage: f64,
    /// Largest arm movement from the start (counts).
    pub arm_counts: f64,
    /// Largest pendulum movement from the start (counts).
    pub pendulum_counts: f64,
}

impl std::fmt::Display for SignReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "passed: a ±{} V pulse moved the arm up to {:.0} counts the positive way first, the pendulum \
             up to {:.0} counts, first behind the arm",
            self.voltage, self.arm_counts, self.pendulum_counts
        )
    }
}

/// The check without I/O: [`command`](Self::command) says what to apply, [`push`](Self::push)
/// takes each measurement, [`verdict`](Self::verdict) judges.
#[derive(Debug, Clone)]
pub struct SignCheck {
    voltage: f64,
    counts_per_rad: [f64; 2],
    signs: [f64; 2],
    start: Option<[f64; 2]>,
    first: [Option<f64>; 2],
    largest: [f64; 2],
}

impl SignCheck {
    /// The check for `cfg` with a pulse of `voltage` (V; capped at `safety.voltage_limit`).
    pub fn new(cfg: &Config, voltage: f64) -> Self {
        let tau = std::f64::consts::TAU;
        let d = &cfg.device;
        Self {
            voltage: voltage.min(cfg.safety.voltage_limit),
            counts_per_rad: [
                f64::from(d.arm_counts_per_rev) / tau,
                f64::from(d.pendulum_counts_per_rev) / tau,
            ],
            signs: [d.arm_sign, d.pendulum_sign],
            start: None,
            first: [None, None],
            largest: [0.0, 0.0],
        }
    }

    /// The pulse voltage (V).
    pub fn voltage(&self) -> f64 {
        self.voltage
    }

    /// The voltage to apply `t` seconds after the check started: the pulse (`+V`, then
    /// `−V`), then 0 V; `None` once the check is over.
    pub fn command(&self, t: f64) -> Option<f64> {
        if t < PULSE_S {
            Some(self.voltage)
        } else if t < 2.0 * PULSE_S {
            Some(-self.voltage)
        } else if t < 2.0 * PULSE_S + WATCH_S {
            Some(0.0)
        } else {
            None
        }
    }

    /// Takes a measurement: arm angle θ and pendulum angle α (rad, α wrapped, 0 upright).
    /// The first one is the reference pose.
    pub fn push(&mut self, theta: f64, alpha: f64) {
        let Some([theta0, alpha0]) = self.start else {
            self.start = Some([theta, alpha]);
            return;
        };
        let moved = [
            (theta - theta0) * self.counts_per_rad[0],
            wrap_angle(alpha - alpha0) * self.counts_per_rad[1],
        ];
        let min = [MIN_ARM_COUNTS, MIN_PENDULUM_COUNTS];
        for j in 0..2 {
            self.largest[j] = self.largest[j].max(moved[j].abs());
            if self.first[j].is_none() && moved[j].abs() >= min[j] {
                self.first[j] = Some(moved[j]);
            }
        }
    }

    /// The judgement on what was pushed (module docs).
    pub fn verdict(&self) -> Result<SignReport, SignFault> {
        let [arm, pendulum] = self.largest;
        let flip = |s: f64| if s > 0.0 { -1 } else { 1 };
        match self.first {
            [None, None] => Err(SignFault::NoMotion {
                voltage: self.voltage,
                pulse_s: PULSE_S,
                arm,
                pendulum,
            }),
            [None, Some(_)] => Err(SignFault::ArmEncoderSilent { arm, pendulum }),
            [Some(_), None] => Err(SignFault::PendulumEncoderSilent { arm, pendulum }),
            [Some(a), Some(p)] => {
                let pendulum_agrees = a * p < 0.0;
                match (a > 0.0, pendulum_agrees) {
                    (true, true) => Ok(SignReport {
                        voltage: self.voltage,
                        arm_counts: arm,
                        pendulum_counts: pendulum,
                    }),
                    (false, true) => Err(SignFault::MotorReversed { arm: a }),
                    (false, false) => Err(SignFault::ArmEncoderReversed {
                        arm: a,
                        fix: flip(self.signs[0]),
                    }),
                    (true, false) => Err(SignFault::PendulumEncoderReversed {
                        arm: a,
                        pendulum: p,
                        fix: flip(self.signs[1]),
                    }),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rip_core::plant::{Plant, State};

    /// Runs the check on the simulated hanging pendulum with the given wiring errors.
    fn simulate(motor: f64, arm_enc: f64, pend_enc: f64, frozen: [bool; 2]) -> SignCheck {
        let cfg = Config::default();
        let mut check = SignCheck::new(&cfg, PULSE_VOLTAGE);
        let plant = Plant::qube_servo2();
        let mut x = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
        let quantise =
            |v: f64| (v * 2048.0 / std::f64::consts::TAU).round() * std::f64::consts::TAU / 2048.0;
        let mut t = 0.0;
        while let Some(u) = check.command(t) {
            let theta = if frozen[0] {
                0.0
            } else {
                arm_enc * quantise(x[0])
            };
            // The encoder reads from hanging; the loop's α is π there.
            let from_hanging = if frozen[1] {
                0.0
            } else {
                pend_enc * quantise(x[2] - std::f64::consts::PI)
            };
            check.push(theta, wrap_angle(from_hanging + std::f64::consts::PI));
            plant.advance(&mut x, motor * u, 0.0, 0.01, 10);
            t += 0.01;
        }
        check
    }

    #[test]
    fn a_correct_rig_passes() {
        let report = simulate(1.0, 1.0, 1.0, [false, false]).verdict().unwrap();
        assert!(report.arm_counts >= MIN_ARM_COUNTS);
        assert!(report.pendulum_counts >= MIN_PENDULUM_COUNTS);
    }

    #[test]
    fn each_wiring_error_gets_its_fix() {
        let e = simulate(-1.0, 1.0, 1.0, [false, false])
            .verdict()
            .unwrap_err();
        assert!(matches!(e, SignFault::MotorReversed { .. }), "{e}");
        assert!(e.to_string().contains("swap the motor leads"), "{e}");
        let e = simulate(1.0, -1.0, 1.0, [false, false])
            .verdict()
            .unwrap_err();
        assert!(
            matches!(e, SignFault::ArmEncoderReversed { fix: -1, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("device.arm_sign = -1"), "{e}");
        let e = simulate(1.0, 1.0, -1.0, [false, false])
            .verdict()
            .unwrap_err();
        assert!(
            matches!(e, SignFault::PendulumEncoderReversed { fix: -1, .. }),
            "{e}"
        );
        // Motor and pendulum encoder both reversed look like a reversed arm encoder, whose fix
        // makes the rig consistent (mirrored).
        let e = simulate(-1.0, 1.0, -1.0, [false, false])
            .verdict()
            .unwrap_err();
        assert!(matches!(e, SignFault::ArmEncoderReversed { .. }), "{e}");
        let e = simulate(1.0, 1.0, 1.0, [true, false])
            .verdict()
            .unwrap_err();
        assert!(matches!(e, SignFault::ArmEncoderSilent { .. }), "{e}");
        let e = simulate(1.0, 1.0, 1.0, [false, true])
            .verdict()
            .unwrap_err();
        assert!(matches!(e, SignFault::PendulumEncoderSilent { .. }), "{e}");
        let e = simulate(0.0, 1.0, 1.0, [false, false])
            .verdict()
            .unwrap_err();
        assert!(matches!(e, SignFault::NoMotion { .. }), "{e}");
    }

    #[test]
    fn the_pulse_is_capped_and_ends_at_zero() {
        let mut cfg = Config::default();
        cfg.safety.voltage_limit = 1.5;
        let check = SignCheck::new(&cfg, PULSE_VOLTAGE);
        assert_eq!(check.command(0.0), Some(1.5));
        assert_eq!(check.command(PULSE_S + 0.01), Some(-1.5));
        assert_eq!(check.command(2.0 * PULSE_S + 0.01), Some(0.0));
        assert_eq!(check.command(2.0 * PULSE_S + WATCH_S), None);
    }
}
