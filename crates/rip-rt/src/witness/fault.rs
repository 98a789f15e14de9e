//! The witness's verdicts: what each stop names as the likely fault (the parent module's
//! "What the stop says").

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
            Self::ArmWrongWay { .. } => true,
            Self::ArmDisagrees { reversal, .. } | Self::PendulumDisagrees { reversal, .. } => {
                reversal >= super::REVERSAL_EVIDENCE
            }
            Self::ArmFrozen { .. } => false,
        }
    }
}
