//! The reversed observers ([`Reversal`]): the witness's observer again, twice, each on the
//! model of one wiring that reverses the arm's response, and the log-likelihood ratio of each
//! against the observer as wired.

use rip_core::plant::State;
use rip_core::swingup::wrap_angle;

use super::{Response, Witness, WitnessFault, FROZEN_PERIODS, GAIN_POSITION, GAIN_RATE};

/// A wiring that reverses the arm's response to the voltage, and the reversed observers'
/// statistic.
///
/// The sign statistic predicts each period from the observer's state, and the observer's
/// correction follows the readings within a few periods. While balancing, where the voltage's
/// share of one period's motion is a fraction of the noise, a reversed arm then hides in the
/// observer itself: an arm encoder reversed while the paper preset's LQR balanced ran away
/// for 2.2 s and 0.41 rad before the sign statistic saw it. So the witness runs its observer
/// twice more, each on the model of one wiring that reverses the arm's
/// response — the voltage reversed (a swapped motor lead), and the arm read reversed (an arm
/// encoder counting backwards or a wrong `device.arm_sign`: the true arm, `−θ` as read,
/// follows the model driven by `u`, the pendulum's coupling included) — each corrected by
/// its own innovation `e_w` as the observer is by `e`. Each counted period adds
///
/// ```text
/// λ_w = (e² − e_w²) / (2 (σ_s² + ε² max(e², e_w²)))        S_w[k] = max(0, S_w[k−1] + λ_w)
/// ```
///
/// (`σ_s²` the sign statistic's variance, ε = [`REVERSAL_MODEL_ERROR`]), and the run stops as
/// a reversal ([`ArmFollowsReversed`](super::WitnessFault::ArmFollowsReversed)) when either `S_w` exceeds
/// [`REVERSAL_THRESHOLD`](super::REVERSAL_THRESHOLD). The observer whose model is the rig's
/// has white innovations while the others carry the model's error every period, so the evidence grows at the rate of the
/// difference of their innovations' energies, which no correction hides. ε bounds one
/// period's evidence at `1/(2ε²)` ≈ 5.6 where the innovations are far larger than the noise
/// and neither model need fit (an encoder that stopped counting mid-swing). A wrong scale
/// or a weak motor moves the arm the modelled way, nearer the wired prediction than the
/// reversed one: negative evidence. The observers start again from the wired one after a
/// period of unknown timing (whose arrival it fitted to the readings), and a trip is named
/// by the arm's response to the voltage since the statistic left 0
/// ([`Witness`]'s `reversal_fault`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reversal {
    /// The voltage acts reversed (swapped motor leads): the arm as read follows the model
    /// driven by `−u`.
    Drive,
    /// The arm is read reversed (an arm encoder counting backwards, a wrong
    /// `device.arm_sign`): the true arm, `−θ` as read, follows the model driven by `u`, the
    /// pendulum's coupling included.
    Reading,
}

impl core::fmt::Display for Reversal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Reversal::Drive => "the motor leads swapped",
            Reversal::Reading => "the arm encoder reversed",
        })
    }
}

const WIRINGS: [Reversal; 2] = [Reversal::Drive, Reversal::Reading];

/// The share of the larger innovation (the wired observer's or a reversed one's) counted as
/// the model's error: one period's evidence is at most `1 / (2 · 0.3²)` ≈ 5.6, so that no
/// single reading trips the witness.
pub const REVERSAL_MODEL_ERROR: f64 = 0.3;

/// The two reversed observers and their statistics. Allocation-free, `Copy`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Reversals {
    // Each wiring's observer, in its own frame (the drive's in the reading's, the reading's
    // in the true arm's); `None` until the next period starts it from the wired observer.
    observers: [Option<State>; 2],
    // Each wiring's CUSUM of its log-likelihood ratio against the observer as wired.
    statistic: [f64; 2],
    // Since the larger statistic last left 0: the regression of the arm's response on the
    // voltage's share of its motion (as the sign statistic's), and the periods.
    response: [f64; 2],
    periods: u32,
    peak: f64,
}

impl Reversals {
    /// Forgets the observers and the statistics (the peak is kept).
    pub(super) fn reset(&mut self) {
        self.observers = [None; 2];
        self.statistic = [0.0; 2];
        self.forget_response();
    }

    fn forget_response(&mut self) {
        self.response = [0.0; 2];
        self.periods = 0;
    }

    /// Starts the observers afresh from the wired observer's next state (its rates acquired
    /// anew, or a period's arrival fitted to the readings); their statistics stand.
    pub(super) fn restart(&mut self) {
        self.observers = [None; 2];
    }

    /// One period: each observer predicts the readings `theta`, `alpha` from its state under
    /// its wiring (`predict` advances a state over the period under the voltages given), is
    /// corrected by its innovation as the wired observer is, and, when `counted`, its
    /// log-likelihood ratio `(e² − e_w²) / (2 var)` against the wired observer's arm
    /// innovation `(e, var)` enters its CUSUM. `prior` is the wired observer's state before
    /// the period, from which a new observer starts.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn observe(
        &mut self,
        prior: &State,
        (theta, alpha): (f64, f64),
        volts: (f64, f64),
        predict: impl Fn(&mut State, (f64, f64)),
        (e, var): (f64, f64),
        ts: f64,
        counted: bool,
    ) {
        for (i, wiring) in WIRINGS.into_iter().enumerate() {
            let mut x = self.observers[i].unwrap_or_else(|| wiring.frame(*prior));
            let drive = match wiring {
                Reversal::Drive => (-volts.0, -volts.1),
                Reversal::Reading => volts,
            };
            predict(&mut x, drive);
            let e_wiring = theta - wiring.arm_sign() * x[0];
            let e_alpha = wrap_angle(alpha - x[2]);
            // The correction in the observer's own frame.
            let e_own = wiring.arm_sign() * e_wiring;
            x[0] += GAIN_POSITION * e_own;
            x[1] += GAIN_RATE * e_own / ts;
            x[2] = wrap_angle(x[2] + GAIN_POSITION * e_alpha);
            x[3] += GAIN_RATE * e_alpha / ts;
            self.observers[i] = Some(x);
            // Where the innovations are far larger than the noise, neither model need fit (an
            // encoder that stopped counting mid-swing fits no wiring): a share of the larger
            // counts as the model's error, which bounds one period's evidence.
            let model = REVERSAL_MODEL_ERROR * e.abs().max(e_wiring.abs());
            let var = var + model * model;
            if counted && var > 0.0 {
                let llr = (e * e - e_wiring * e_wiring) / (2.0 * var);
                if llr.is_finite() {
                    self.statistic[i] = (self.statistic[i] + llr).max(0.0);
                }
            }
        }
        let (statistic, _) = self.statistic();
        if statistic == 0.0 {
            self.forget_response();
        }
        self.peak = self.peak.max(statistic);
    }

    /// One period's response of the arm to the voltage (the witness's response test), taken
    /// while the larger statistic stands above 0.
    pub(super) fn respond(&mut self, sample: &Response) {
        if self.statistic().0 > 0.0 {
            sample.regress(&mut self.response);
            self.periods += 1;
        }
    }

    /// The larger statistic and its wiring.
    pub(super) fn statistic(&self) -> (f64, Reversal) {
        if self.statistic[1] > self.statistic[0] {
            (self.statistic[1], Reversal::Reading)
        } else {
            (self.statistic[0], Reversal::Drive)
        }
    }

    /// The largest statistic since construction.
    pub(super) fn peak(&self) -> f64 {
        self.peak
    }
}

impl Reversal {
    /// The sign of the arm as read against the arm in this wiring's observer's frame: −1 for
    /// a reversed reading.
    fn arm_sign(self) -> f64 {
        match self {
            Reversal::Drive => 1.0,
            Reversal::Reading => -1.0,
        }
    }

    /// A state of the arm as read in this wiring's observer's frame, and back (the map is its
    /// own inverse).
    fn frame(self, mut x: State) -> State {
        x[0] *= self.arm_sign();
        x[1] *= self.arm_sign();
        x
    }
}

impl Witness {
    /// The arm reading's variance for the sign statistic and the reversed observers: the
    /// noise, the sampling instant at the arm's `rate`, the command's arrival (`switch`, rad)
    /// and the friction's sign (`friction`, rad).
    pub(super) fn sign_variance(&self, rate: f64, switch: f64, friction: f64) -> f64 {
        let timing = super::TIMING_S * rate;
        self.sigma[0] * self.sigma[0] + timing * timing + switch * switch + friction * friction
    }

    /// The reversed observers' period (the wired observer's state `prior` before it, the
    /// readings, the voltages, the interval and the command's delay, the wired arm
    /// innovation and its variance), `counted` into their statistics or not; after a period
    /// of `unknown` timing they start again from the wired observer, which took the arrival
    /// the readings showed (`fit_arrival`), rather than carry the nominal arrival's error.
    pub(super) fn observe_reversals(
        &mut self,
        prior: &State,
        readings: (f64, f64),
        volts: (f64, f64),
        (dt, delay): (f64, f64),
        innovation: (f64, f64),
        (counted, unknown): (bool, bool),
    ) {
        let mut reversals = self.reversals;
        let predict = |x: &mut State, v: (f64, f64)| self.predict(x, v, dt, delay);
        reversals.observe(
            prior, readings, volts, predict, innovation, self.ts, counted,
        );
        if unknown {
            reversals.restart();
        }
        self.reversals = reversals;
    }

    /// The fault a trip of the reversed observers' statistic `stat` names at the arm reading
    /// `theta`, with the sign statistic's guards: a reading that stood still while the model
    /// moved the arm by half of what the frozen rule needs is a dead encoder; a response to
    /// the voltage in the modelled direction beyond its noise is no reversal (a reading at a
    /// quarter of the arm's motion fits a reversed voltage better where the pendulum's pull
    /// and the voltage push the arm the same way) and is named as the CUSUM names it; any
    /// other is a reversal, named with the wiring that fitted best.
    pub(super) fn reversal_fault(&self, theta: f64, stat: f64) -> WitnessFault {
        let r = &self.reversals;
        let still = self.unchanged >= FROZEN_PERIODS.max(r.periods.min(2 * FROZEN_PERIODS));
        if still && (self.free[0] - theta).abs() > 0.5 * self.frozen_rad {
            return self.frozen_fault(theta);
        }
        let forward = super::response::gain(&r.response)
            .is_some_and(|(g, se)| g - super::REVERSED_SIGMAS * se > 0.0);
        if forward {
            return self.classify(theta, stat, self.limits.reversal);
        }
        WitnessFault::ArmFollowsReversed {
            wiring: r.statistic().1,
            window_s: f64::from(r.periods) * self.ts,
            stat,
            limit: self.limits.reversal,
        }
    }
}
