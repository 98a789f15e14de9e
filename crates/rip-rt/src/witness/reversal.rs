//! The reversed observers ([`Reversal`]): the witness's observer again, twice, each on the
//! model of one wiring that reverses the arm's response, and the log-likelihood ratio of each
//! against the observer as wired.

use rip_core::plant::State;
use rip_core::swingup::wrap_angle;

use super::{Witness, WitnessFault, GAIN_POSITION, GAIN_RATE};

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
/// a reversal ([`ArmWrongWay`](super::WitnessFault::ArmWrongWay)) when either `S_w` exceeds
/// [`REVERSAL_THRESHOLD`](super::REVERSAL_THRESHOLD). The observer whose model is the rig's
/// has white innovations while the others carry the model's error every period, so the evidence grows at the rate of the
/// difference of their innovations' energies, which no correction hides. ε bounds one
/// period's evidence at `1/(2ε²)` ≈ 5.6 where the innovations are far larger than the noise
/// and neither model need fit (an encoder that stopped counting mid-swing). A wrong scale
/// or a weak motor moves the arm the modelled way, nearer the wired prediction than the
/// reversed one: negative evidence.
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
    // Since the larger statistic last left 0: the arm's motion as read and as the wired
    // observer predicted it, and the periods.
    motion: [f64; 2],
    periods: u32,
    peak: f64,
}

impl Reversals {
    /// Forgets the observers and the statistics (the peak is kept).
    pub(super) fn reset(&mut self) {
        self.observers = [None; 2];
        self.statistic = [0.0; 2];
        self.motion = [0.0; 2];
        self.periods = 0;
    }

    /// Starts the observers afresh from the wired observer's next state (its rates were
    /// acquired anew); the statistics are kept.
    pub(super) fn restart(&mut self) {
        self.observers = [None; 2];
    }

    /// One period: each observer predicts the readings `theta`, `alpha` from its state under
    /// its wiring (`predict` advances a state over the period under the voltages given), is
    /// corrected by its innovation as the wired observer is, and, when `counted`, its
    /// log-likelihood ratio `(e² − e_w²) / (2 var)` against the wired observer's arm
    /// innovation `(e, var)` enters its CUSUM. `prior` is the wired observer's state before
    /// the period, from which a new observer starts; `(moved, predicted)` the arm's motion
    /// over the period as read and as the wired observer predicted it.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn observe(
        &mut self,
        prior: &State,
        (theta, alpha): (f64, f64),
        volts: (f64, f64),
        predict: impl Fn(&mut State, (f64, f64)),
        (e, var): (f64, f64),
        (moved, predicted): (f64, f64),
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
            let read = wiring.frame(x)[0];
            let e_wiring = theta - read;
            let e_alpha = wrap_angle(alpha - x[2]);
            // The correction in the observer's own frame.
            let e_own = wiring.frame(State::new(e_wiring, 0.0, 0.0, 0.0))[0];
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
        if statistic > 0.0 {
            self.motion[0] += moved;
            self.motion[1] += predicted;
            self.periods += 1;
        } else {
            self.motion = [0.0; 2];
            self.periods = 0;
        }
        self.peak = self.peak.max(statistic);
    }

    /// The arm's motion since the larger statistic last left 0: as read, and as the wired
    /// observer predicted it (rad).
    pub(super) fn motion(&self) -> [f64; 2] {
        self.motion
    }

    /// Periods since the larger statistic last left 0.
    pub(super) fn periods(&self) -> u32 {
        self.periods
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
    /// A state of the arm as read in this wiring's observer's frame, and back (the map is its
    /// own inverse): the arm's angle and rate negated for a reversed reading.
    fn frame(self, mut x: State) -> State {
        if self == Reversal::Reading {
            x[0] = -x[0];
            x[1] = -x[1];
        }
        x
    }
}

impl Witness {
    /// The fault a trip of the reversed observers' statistic `stat` names: a reversal, with
    /// the arm's motion since the statistic last left 0.
    pub(super) fn reversal_fault(&self, stat: f64) -> WitnessFault {
        let [measured, predicted] = self.reversals.motion();
        WitnessFault::ArmWrongWay {
            measured,
            predicted,
            window_s: f64::from(self.reversals.periods()) * self.ts,
            stat,
            limit: self.limits.reversal,
        }
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
