//! The witness's verdicts: what each stop names as the likely fault (the parent module's
//! "What the stop says").

use super::{Reversal, Witness, FROZEN_PERIODS, REVERSED_SIGMAS};

/// Why the witness stopped the run: the likely fault.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum WitnessFault {
    /// The arm encoder's reading stayed constant while the voltage must have turned the arm.
    #[error(
        "the arm encoder has read a constant {theta:+.3} rad for {still_s:.2} s while the \
         applied voltage must have turned the arm by {predicted:+.3} rad: the arm encoder \
         stopped counting (check its cable and connector)"
    )]
    ArmFrozen {
        /// The constant reading (rad).
        theta: f64,
        /// The arm motion the model predicted meanwhile (rad).
        predicted: f64,
        /// How long the reading has been constant (s).
        still_s: f64,
    },
    /// The arm moved against the motion the voltage must produce.
    #[error(
        "the arm moved {measured:+.3} rad over the last {window_s:.2} s where the applied \
         voltage must have turned it {predicted:+.3} rad (statistic {stat:.0} > {limit}): the \
         motor leads are swapped, the arm encoder counts backwards, or device.arm_sign is wrong \
         (rip-rt excite's sign check tells which)"
    )]
    ArmWrongWay {
        /// The measured arm motion since the disagreement began (rad).
        measured: f64,
        /// The arm motion the model predicted meanwhile (rad).
        predicted: f64,
        /// How long ago the disagreement began (s).
        window_s: f64,
        /// The statistic at the trip.
        stat: f64,
        /// Its threshold.
        limit: f64,
    },
    /// The arm moved the predicted way, but not as far as the model says.
    #[error(
        "the arm's motion disagrees with what the applied voltage must produce: it moved \
         {measured:+.3} rad over the last {window_s:.2} s where [plant] predicts \
         {predicted:+.3} rad (statistic {stat:.0} > {limit}): swapped motor leads, a reversed \
         arm encoder or device.arm_sign (rip-rt excite's sign check tells which), a wrong \
         sensor.encoder_counts[0], a slipping arm, or a rig unlike [plant] (riprs identify)"
    )]
    ArmDisagrees {
        /// The measured arm motion since the disagreement began (rad).
        measured: f64,
        /// The arm motion the model predicted meanwhile (rad).
        predicted: f64,
        /// How long ago the disagreement began (s).
        window_s: f64,
        /// The statistic at the trip.
        stat: f64,
        /// Its threshold.
        limit: f64,
        /// The evidence of a reversal at the trip ([`super::Witness::reversal_evidence`]).
        reversal: f64,
    },
    /// The model of a reversed wiring followed the arm's readings better than the model as
    /// wired ([`Reversal`]).
    #[error(
        "the arm's readings over the last {window_s:.2} s follow [plant] with {wiring} better \
         than as wired (statistic {stat:.0} > {limit}): the motor leads are swapped, the arm \
         encoder counts backwards, or device.arm_sign is wrong (rip-rt excite's sign check \
         tells which)"
    )]
    ArmFollowsReversed {
        /// The wiring whose model fitted best.
        wiring: Reversal,
        /// How long ago the statistic last left 0 (s).
        window_s: f64,
        /// The statistic at the trip.
        stat: f64,
        /// Its threshold.
        limit: f64,
    },
    /// The pendulum's motion disagrees with the model.
    #[error(
        "the pendulum's motion disagrees with what the arm's motion must produce (statistic \
         {stat:.0} > {limit}): check the pendulum encoder (cable, device.pendulum_sign, \
         sensor.encoder_counts[1]) and the motor leads"
    )]
    PendulumDisagrees {
        /// The statistic at the trip.
        stat: f64,
        /// Its threshold.
        limit: f64,
        /// The evidence of a reversal at the trip ([`super::Witness::reversal_evidence`]).
        reversal: f64,
    },
}

impl WitnessFault {
    /// Whether the stop takes the fault for a reversed motor lead or arm encoder: named so,
    /// or found on another statistic with the evidence of a reversal at
    /// [`super::REVERSAL_EVIDENCE`] or more.
    pub fn reversed(&self) -> bool {
        match *self {
            Self::ArmWrongWay { .. } | Self::ArmFollowsReversed { .. } => true,
            Self::ArmDisagrees { reversal, .. } | Self::PendulumDisagrees { reversal, .. } => {
                reversal >= super::REVERSAL_EVIDENCE
            }
            Self::ArmFrozen { .. } => false,
        }
    }
}

/// Naming the fault from the response ([`Witness::response_gain`]) and the CUSUMs.
impl Witness {
    /// The voltage's gain on the arm that the measurements since the sign statistic left 0
    /// show, relative to the model's (1 as modelled, −1 reversed); `None` without a response.
    pub fn response_gain(&self) -> Option<f64> {
        super::response::gain(&self.response).map(|(g, _)| g)
    }

    pub(super) fn classify(&self, theta: f64, stat: f64, limit: f64) -> WitnessFault {
        let (predicted, measured) = (self.predicted, self.measured);
        let window_s = f64::from(self.disagreeing) * self.ts;
        // No motion at all since the disagreement began, against the model's.
        if self.unchanged >= self.disagreeing.min(FROZEN_PERIODS)
            && self.unchanged > 0
            && measured.abs() < 0.5 * self.arm_count
            && predicted.abs() > 2.0 * self.arm_count
        {
            WitnessFault::ArmFrozen {
                theta,
                predicted,
                still_s: f64::from(self.unchanged) * self.ts,
            }
        } else if predicted * measured < 0.0 {
            WitnessFault::ArmWrongWay {
                measured,
                predicted,
                window_s,
                stat,
                limit,
            }
        } else {
            WitnessFault::ArmDisagrees {
                measured,
                predicted,
                window_s,
                stat,
                limit,
                reversal: self.reversal_evidence(),
            }
        }
    }

    /// The evidence (a log-likelihood ratio, as the sign statistic) that the voltage moves
    /// the arm reversed: the sign statistic where the arm's response since it left 0 has the
    /// wrong sign too, else 0. A trip on another statistic while this stands at
    /// [`REVERSAL_EVIDENCE`](super::REVERSAL_EVIDENCE) or more is stopped as a reversal is ([`WitnessFault::reversed`]):
    /// a swapped motor lead under a hard-driving balance can spin the pendulum past its own
    /// threshold before the sign statistic reaches its own, and a stop with the model's sign
    /// then drove the arm 2.6 rad before it learnt the sign (generated rig 54, statistic
    /// 7.5–13 at the trip).
    pub fn reversal_evidence(&self) -> f64 {
        if self.response_reversed() {
            self.sign
        } else {
            0.0
        }
    }

    /// The standard error of [`Witness::response_gain`] (the weighted regression's); `None`
    /// without a response.
    pub fn response_gain_error(&self) -> Option<f64> {
        super::response::gain(&self.response).map(|(_, se)| se)
    }

    /// Whether the arm's response since the sign statistic left 0 has the wrong sign: the
    /// gain ([`Witness::response_gain`]) nearer a reversal's −1 than 0, or below 0 by more
    /// than [`REVERSED_SIGMAS`] of its standard error, over the whole window or over its
    /// periods after the first (below). A gain of −0.09 from three periods of a coarse
    /// reading at a quarter of the arm's motion, a count from 0, once named a wrong arm scale
    /// a reversal 0.03 s into a swing-up, and the stop braked with the sign that drove the arm
    /// on (generated rig 54, 524 counts set as 2096: 6.6 rad); a swapped lead's −0.55, within
    /// its noise of 0 a tenth of a second into a heavy pendulum's swing, is a reversal still
    /// (generated rig 90: named a disagreement, the model's sign drove the arm 0.9 rad before
    /// the arm's equation turned it). A trip of the reversed observers is named by their own
    /// response ([`Reversal`](super::Reversal)): a reversal unless it is forward beyond its
    /// noise.
    ///
    /// Each period's response is the change of the arm's mean rate between its interval and
    /// the one before, so the period the statistic left 0 in reaches back into an interval
    /// before it, which may lie in the fault or not: the statistic's clamp at 0 hides where
    /// the fault began (one that leaps from 0 past its threshold in one period has only that
    /// sample to name it by), and noise lifts it off 0 by a hair before the fault as well.
    /// So the response is judged with that period and without it, and a reversal either way
    /// is a reversal. With it alone, a healthy interval outweighed a swapped lead's:
    /// generated rig 54, MPC, the lead swapped 1 s into the swing-up (noise seed 5), whose
    /// statistic left 0 by a hair in the last healthy period (a gain of +0.93 there) and
    /// tripped two periods later at 20 rad/s with a gain of −0.13; braked as a disagreement,
    /// with the model's sign for 6 periods before the arm's equation turned it, the arm went
    /// on to 3.74 rad against a limit of 3. After that period the gain is −0.59 (standard
    /// error 0.17), and the stop with the reversed sign keeps the arm within 1.63 rad.
    /// Without it alone, a reversal whose window began in the fault lost that period's
    /// evidence and was braked as a disagreement (generated rig 79, a swapped lead mid-swing:
    /// 1.54 → 2.75 rad). Over the every-stop sweep of `witness_sim` the second judgement
    /// turns 50 stops of a swapped lead into a reversal's (45 trips named
    /// [`WitnessFault::ArmWrongWay`], 5 pendulum trips given its evidence) and no stop of any
    /// other fault, a wrong arm scale's included.
    pub(super) fn response_reversed(&self) -> bool {
        let reversed = |regression: &[f64; 2]| {
            super::response::gain(regression)
                .is_some_and(|(g, se)| g < -0.5 || g + REVERSED_SIGMAS * se < 0.0)
        };
        reversed(&self.response) || reversed(&self.response_inside)
    }

    /// The fault of an arm encoder that stopped counting at `theta` (rad): the free-running
    /// arm's motion from it, and how long the reading has been constant.
    pub(super) fn frozen_fault(&self, theta: f64) -> WitnessFault {
        WitnessFault::ArmFrozen {
            theta,
            predicted: self.free[0] - theta,
            still_s: f64::from(self.unchanged) * self.ts,
        }
    }
}
