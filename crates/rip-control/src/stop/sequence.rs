//! The stop's sequence, period by period: the gentle end's lowering, the braking law, the hold
//! law, the short (module docs).

use super::*;

/// The longest the hold law runs (s) before the windings are shorted regardless.
pub const MAX_HOLD_S: f64 = 5.0;
/// Swing of the pendulum (rad, its range over [`REST_S`]) below which the hold law has
/// taken out what it needs to.
pub const PENDULUM_REST_RAD: f64 = 0.05;
/// Distance (rad) from its hold point past which a hold law whose sign was learnt on the arm's
/// response alone is given up for the short (a sign learnt wrong, a reading that is not the
/// arm's). A trusted sign holds on, and so does one whose arm reading the coupling test has
/// matched to the pendulum ([`CouplingTest`]): the arm swings with a pendulum still falling
/// past its hold point by more than this (0.56 rad on generated rig 1, 0.5 rad within 0.1 s
/// of a heavy pendulum's swing on generated rig 90), and the short in its place let the
/// pendulum walk the arm 3.7 rad (7.7 rad on rig 90).
pub const HOLD_GIVE_UP_RAD: f64 = 0.5;

/// Periods in a row in which the hold law drives with at least a quarter of the voltage bound
/// while the arm's reading does not change, after which the law is given up for the short:
/// the reading is not the arm's (an arm encoder that stopped counting unseen), and the
/// pendulum's terms would drive the arm blind.
pub const HOLD_BLIND_PERIODS: u32 = 5;

/// Pendulum angle from upright (rad) within which an orderly stop lowers it
/// ([`StopSequence::lowering`]): a balanced pendulum. Farther out (an excitation, a swing) the
/// stop brakes as it always did.
pub const LOWER_FROM_RAD: f64 = 0.3;

/// Pendulum angle from hanging (rad) within which the gentle end may count it lowered (with arm
/// and pendulum at rest): the bar the end of a run is judged by.
pub const LOWERED_HANGING_RAD: f64 = 0.1;

/// The longest a lowering may take (s), on the model in its design and on the rig: past it
/// the stop brakes and holds as after a fault.
pub const MAX_LOWER_S: f64 = 6.0;

/// The arm's distance from the centre (rad) past which the gentle end tips the pendulum the
/// way the arm's term pushes it; nearer, the way it leans.
pub const LOWER_SIDE_FROM_RAD: f64 = 0.05;

/// Share of the pendulum's swing energy (`2 G`) that the rig may gain under the braking law on
/// [`momentum_rate`] before that law gives way to the arm's rate.
pub const MOMENTUM_ENERGY_GAIN: f64 = 1.0;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage<R: Real> {
    /// The gentle end: the pendulum lowered to hanging and the arm brought to its hold point
    /// `at` (the centre; NaN until the first measurement).
    Lowering {
        at: R,
        periods: u32,
        last: R,
        unmoved: u32,
    },
    Braking,
    Holding {
        at: R,
        periods: u32,
        last: R,
        unmoved: u32,
    },
    /// `blind`: the arm's reading was found not to be the arm's (it did not change while the
    /// hold law drove), so the short lasts until the pendulum rests instead.
    Shorted {
        blind: bool,
    },
}

/// A stop, period by period, after the run ended: the braking law of the stop's mode
/// ([`Brake`]; with the wiring trusted, on the arm's angular momentum, [`momentum_rate`])
/// until the arm rests or that momentum is braked out; then, where the wiring's sign is known,
/// the hold law ([`HoldLaw`]: the arm held where it stopped, the pendulum's energy taken out
/// through it; the arm's terms alone when only the arm's sign was learnt) until arm and
/// pendulum rest, at most [`MAX_HOLD_S`]; then the windings shorted until the arm rests once
/// more. One definition for `rip-rt`'s stops, the device's and the simulations that test
/// them. Allocation-free, `Copy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopSequence<R: Real = f64> {
    brake: Brake<R>,
    hold: Option<HoldLaw<R>>,
    arm_rest: RestTest<R>,
    pendulum_rest: RestTest<R>,
    stage: Stage<R>,
    period_s: f64,
    voltage: R,
    // The smooth model, for the arm's angular momentum; the periods in a row the saturated
    // law on it has seen its speed rise (`None` once it gave way), that speed, and the rig's
    // energy (measured) when the law began.
    model: Option<ArmModel<R>>,
    momentum_rising: Option<u32>,
    momentum_speed: R,
    momentum_energy: Option<R>,
    // The momentum's mean over blocks (which tells it braked out); whether the law ran on it
    // last period.
    momentum_block: MomentumBlock<R>,
    on_momentum: bool,
    // Whether the hold law has run (it runs once); whether the stop has commanded a period.
    held: bool,
    commanded: bool,
    // The last command's voltage (0 for the short).
    last_volts: R,
    // The gentle end's law while it may still run, the loop's braking envelope that watches
    // it, and the side the pendulum is lowered on.
    lower: Option<HoldLaw<R>>,
    lower_envelope: Option<ArmEnvelope<R>>,
    lower_side: R,
    // Whether the gentle end brought the pendulum down.
    lowered: bool,
    // Which way the arm reading turns relative to the arm the pendulum feels, where the
    // wiring's sign was learnt rather than trusted.
    coupling: Option<CouplingTest<R>>,
}

impl<R: Real> StopSequence<R> {
    /// The stop with `brake`, the hold law `hold` (none: the short after the braking), the
    /// smooth `model` for the arm's momentum (none: the braking law on the arm's rate), at a
    /// loop period of `period_s` (s) and a voltage bound `voltage` (V).
    pub fn new(
        brake: Brake<R>,
        hold: Option<HoldLaw<R>>,
        model: Option<ArmModel<R>>,
        period_s: f64,
        voltage: R,
    ) -> Self {
        Self {
            model,
            momentum_rising: Some(0),
            momentum_speed: c(f64::INFINITY),
            momentum_energy: None,
            momentum_block: MomentumBlock::new(period_s),
            held: false,
            commanded: false,
            on_momentum: false,
            brake,
            hold,
            arm_rest: RestTest::new(period_s),
            pendulum_rest: RestTest::new(period_s),
            stage: Stage::Braking,
            period_s,
            voltage,
            last_volts: R::ZERO,
            lower: None,
            lower_envelope: None,
            lower_side: R::ZERO,
            lowered: false,
            coupling: None,
        }
    }

    /// The same stop with `test` run on its readings ([`CouplingTest`]): once it knows the arm
    /// encoder's sign, a stop that learnt its sign on the arm's response
    /// ([`BrakeMode::Reversed`]) brakes the arm's angular momentum and holds with the
    /// pendulum's terms, as a stop whose wiring is trusted does.
    pub fn coupling_test(mut self, test: CouplingTest<R>) -> Self {
        self.coupling = Some(test);
        self
    }

    /// The coupling test the stop runs, if any (for its statistic in a log).
    pub fn coupling(&self) -> Option<&CouplingTest<R>> {
        self.coupling.as_ref()
    }

    /// The arm encoder's sign `s_e` relative to the pendulum (±1) where the stop may use the
    /// pendulum's terms: trusted with the wiring, else the coupling test's verdict for a
    /// sign learnt as a reversal.
    fn encoder_sign(&self) -> Option<R> {
        match self.brake.mode() {
            BrakeMode::Active => Some(R::ONE),
            BrakeMode::Reversed => self.coupling.as_ref().and_then(CouplingTest::sign),
            _ => None,
        }
    }

    /// The same stop beginning with the gentle end of an orderly stop: the lowering `law`
    /// brings a balanced pendulum (within [`LOWER_FROM_RAD`] of upright at the first
    /// measurement) down to hanging at rest with the arm brought to the centre, at most
    /// [`MAX_LOWER_S`]; then the stop ends. Past that time, or where the loop's braking
    /// `envelope` finds the arm's stopping point past its bound, the stop brakes and holds as
    /// after a fault; a reading that does not change while the law drives shorts the windings
    /// as the hold's blind rule does. Only for a brake whose sign is trusted
    /// ([`BrakeMode::Active`]). `held` (V): the run's last command, which acts until the
    /// stop's first.
    pub fn lowering(mut self, law: HoldLaw<R>, envelope: ArmEnvelope<R>, held: R) -> Self {
        if self.brake.mode() == BrakeMode::Active {
            self.last_volts = held;
            self.lower = Some(law);
            self.lower_envelope = Some(envelope);
            self.stage = Stage::Lowering {
                at: c(f64::NAN),
                periods: 0,
                last: c(f64::NAN),
                unmoved: 0,
            };
        }
        self
    }

    /// Whether the gentle end is running.
    pub fn is_lowering(&self) -> bool {
        matches!(self.stage, Stage::Lowering { .. })
    }

    /// Whether the gentle end brought the pendulum down (the stop then ended without braking).
    pub fn lowered(&self) -> bool {
        self.lowered
    }

    /// The blind rule's count ([`HOLD_BLIND_PERIODS`]) after a period whose arm reading is
    /// `theta`, the last one `last`, `unmoved` periods in a row so far: one more when the last
    /// command drove with at least a quarter of the voltage bound and the reading did not
    /// change, else 0.
    fn unmoved_while_driven(&self, theta: R, last: R, unmoved: u32) -> u32 {
        let driven = self.last_volts.abs() >= c::<R>(0.25) * self.voltage;
        if driven && theta == last {
            unmoved + 1
        } else {
            0
        }
    }

    /// A period without a measurement, which the stop shorted: 0 V across the motor.
    pub fn note_short(&mut self) {
        self.last_volts = R::ZERO;
        self.momentum_block.restart();
        if let Some(test) = self.coupling.as_mut() {
            test.gap();
        }
    }

    /// Ends the gentle end for the stop of a fault found during it: `brake` from this period
    /// on, then the hold as after that fault.
    pub fn lowering_faulted(&mut self, brake: Brake<R>) {
        if self.is_lowering() {
            self.brake = brake;
            self.give_up_lowering();
        }
    }

    /// Ends the gentle end for the fault's stop (braking, then holding) from this period on.
    pub fn give_up_lowering(&mut self) {
        if self.is_lowering() {
            self.stage = Stage::Braking;
            self.arm_rest = RestTest::new(self.period_s);
            self.pendulum_rest = RestTest::new(self.period_s);
        }
    }

    /// The last command's voltage (V; 0 for the short).
    pub fn last_volts(&self) -> R {
        self.last_volts
    }

    /// How it brakes now.
    pub fn mode(&self) -> BrakeMode {
        self.brake.mode()
    }

    /// Whether the hold law is running.
    pub fn holding(&self) -> bool {
        matches!(self.stage, Stage::Holding { .. })
    }

    /// Without a fresh measurement: the short from now on.
    pub fn short(&mut self) {
        self.brake.short();
        if self.holding() {
            self.stage = Stage::Shorted { blind: false };
            self.arm_rest = RestTest::new(self.period_s);
        }
    }

    /// Seconds in `periods` periods.
    fn seconds(&self, periods: u32) -> f64 {
        f64::from(periods) * self.period_s
    }

    /// The command for this period from the measured arm angle `theta` (rad) and rate `rate`
    /// (rad/s), pendulum angle `alpha` (rad, 0 upright) and rate `alpha_rate` (rad/s);
    /// `None` once the stop is done (the arm at rest with the windings shorted, or with the
    /// short its only brake).
    pub fn step(&mut self, theta: R, rate: R, alpha: R, alpha_rate: R) -> Option<BrakeCommand<R>> {
        // The voltage over the period that ended with these readings: the stop's last
        // command, from its second period on (its first follows the run's).
        let volts = core::mem::replace(&mut self.commanded, true).then_some(self.last_volts);
        self.brake.observe_pendulum(alpha, alpha_rate);
        if let Some(test) = self.coupling.as_mut() {
            test.observe(theta, alpha, volts);
            if let Some(s_d) = test.drive_sign() {
                self.brake.drive_sign_found(s_d);
            }
        }
        // The model's arm while the stop runs on it: the reading is not the arm's.
        let arm_rests = self
            .arm_rest
            .observe(self.brake.model_arm().unwrap_or(theta));
        let hold_ready = self.hold.is_some() && self.hold_sign().is_some();
        if let Some(command) = self.lowering_step(arm_rests, theta, rate, alpha, alpha_rate) {
            return command;
        }
        let pi: R = c(core::f64::consts::PI);
        let pendulum_rest: R = c(PENDULUM_REST_RAD);
        match self.stage {
            // The arm at rest, or what the law brakes braked out (its mean over a block within
            // the law's dead band): under a pendulum still swinging the arm swings with it and
            // never rests, and the hold law is what takes the pendulum's energy out.
            Stage::Braking if arm_rests || self.braked_out(hold_ready) => {
                if self.brake.mode() == BrakeMode::Short && self.brake.model_arm().is_some() {
                    // The model's arm rests, the arm encoder stopped: the reading is not the
                    // arm's, and a pendulum still swinging drives the arm through the coupling
                    // (the hold's blind rule). The windings open at once walked an arm whose
                    // momentum was braked out to 4.5 rad under a heavy pendulum's swing
                    // (generated rig 79, arm encoder stopped mid-swing).
                    self.stage = Stage::Shorted { blind: true };
                    self.pendulum_rest = RestTest::new(self.period_s);
                    self.last_volts = R::ZERO;
                    return Some(BrakeCommand::Short);
                }
                if self.brake.mode() == BrakeMode::Short {
                    return None;
                }
                if hold_ready && !self.held {
                    self.stage = Stage::Holding {
                        at: theta,
                        periods: 0,
                        last: theta,
                        unmoved: 0,
                    };
                    self.pendulum_rest = RestTest::new(self.period_s);
                } else {
                    self.brake.short();
                    self.stage = Stage::Shorted { blind: false };
                }
                self.arm_rest = RestTest::new(self.period_s);
            }
            Stage::Holding {
                at,
                periods,
                last,
                unmoved,
            } => {
                let unmoved = self.unmoved_while_driven(theta, last, unmoved);
                let phi = wrap_angle(alpha - pi);
                let pendulum_rests = self.pendulum_rest.observe_within(phi, pendulum_rest);
                let expired = self.seconds(periods + 1) >= MAX_HOLD_S;
                let done = (arm_rests && pendulum_rests)
                    || expired
                    || ((theta - at).abs() > c(HOLD_GIVE_UP_RAD) && self.encoder_sign().is_none())
                    || unmoved >= HOLD_BLIND_PERIODS
                    || !theta.is_finite();
                if expired && !(arm_rests && pendulum_rests) && self.may_brake_momentum() {
                    // The hold ran out with the pendulum still swinging: the arm's momentum
                    // braked out once more, so that the swing cannot walk the arm once the
                    // windings open.
                    self.held = true;
                    self.stage = Stage::Braking;
                    self.judge_afresh();
                    self.arm_rest = RestTest::new(self.period_s);
                } else if done {
                    self.brake.short();
                    self.stage = Stage::Shorted {
                        blind: unmoved >= HOLD_BLIND_PERIODS,
                    };
                    self.arm_rest = RestTest::new(self.period_s);
                    self.pendulum_rest = RestTest::new(self.period_s);
                } else {
                    self.stage = Stage::Holding {
                        at,
                        periods: periods + 1,
                        last: theta,
                        unmoved,
                    };
                }
            }
            Stage::Shorted { blind: false } if arm_rests => return None,
            // The arm's reading is not the arm's, and the pendulum's swing still drives the
            // arm through the coupling: a swinging pendulum left with the windings open walked
            // an arm that read at rest to 5.1 rad (generated rig 33, MPC, arm encoder stopped).
            Stage::Shorted { blind: true } => {
                let phi = wrap_angle(alpha - pi);
                if self.pendulum_rest.observe_within(phi, pendulum_rest) {
                    return None;
                }
            }
            _ => {}
        }
        let command = match (self.stage, self.hold, self.hold_sign()) {
            (Stage::Braking, ..) => {
                let (rate, judged) = self.braked_rate(theta, rate, alpha, alpha_rate);
                if judged.is_some() != self.on_momentum {
                    self.on_momentum = judged.is_some();
                    self.judge_afresh();
                }
                self.brake.command_judged(Some(rate), judged)
            }
            (Stage::Holding { at, .. }, Some(law), Some((sign, encoder))) => {
                // The pendulum's terms are the linearisation's about hanging: in the upper
                // half (a pendulum still falling from upright) they would drive the arm hard
                // on a state they do not describe.
                let lower = alpha.cos() < R::ZERO;
                let v = if let Some(s_e) = encoder.filter(|_| lower) {
                    // In the reading's frame the pendulum's terms carry the encoder's sign
                    // (coupling module docs).
                    let phi = wrap_angle(alpha - c(core::f64::consts::PI));
                    law.voltage_from_hanging(theta - at, rate, s_e * phi, s_e * alpha_rate)
                } else {
                    law.arm_voltage(theta - at, rate)
                };
                BrakeCommand::Volts(sign * v)
            }
            _ => BrakeCommand::Short,
        };
        self.last_volts = match command {
            BrakeCommand::Volts(v) => v,
            BrakeCommand::Short => R::ZERO,
        };
        Some(command)
    }

    /// The gentle end's period (`Stage::Lowering`): `None` when the stop is not lowering (or
    /// gives the lowering up this period), else the period's command, `Some(None)` once the
    /// pendulum hangs at rest and the arm rests (the stop is done).
    fn lowering_step(
        &mut self,
        arm_rests: bool,
        theta: R,
        rate: R,
        alpha: R,
        alpha_rate: R,
    ) -> Option<Option<BrakeCommand<R>>> {
        let (
            Stage::Lowering {
                at,
                periods,
                last,
                unmoved,
            },
            Some(law),
        ) = (self.stage, self.lower)
        else {
            return None;
        };
        // The centre: about a hold point where the run left the arm (out by its reference
        // step) the law's swing came within 0.26 rad of the limit (paper preset, MPC).
        let at = if at.is_finite() {
            at
        } else {
            // An arm out from the centre (a run that ends after its reference step): the
            // pendulum tipped so that its term first opposes the arm's, which softens the
            // first command and lets the fall's reaction carry the arm back. Tipped the
            // other way, the arm's term and the pendulum's added up and the arm swung to
            // 2.47 rad against 2.10 (paper preset, 1 rad step, LQR and LQG).
            let push = law.k[0] * theta * law.k[2];
            if theta.abs() > c(LOWER_SIDE_FROM_RAD) && push != R::ZERO {
                self.lower_side = -push.signum();
            }
            R::ZERO
        };
        let phi = wrap_angle(alpha - c(core::f64::consts::PI));
        let pendulum_rests = self.pendulum_rest.observe_within(phi, c(PENDULUM_REST_RAD));
        let upright = wrap_angle(alpha).abs() <= c(LOWER_FROM_RAD);
        let expired = self.seconds(periods) >= MAX_LOWER_S;
        let breach = self.lower_envelope.as_ref().is_some_and(|envelope| {
            envelope
                .check_state(theta, rate, alpha, alpha_rate, self.last_volts)
                .is_err()
        });
        // The hold law's rule: a reading that does not change while the law drives is not
        // the arm's (an arm encoder that stopped counting unseen), and the law would drive
        // the arm blind (217 rad in simulation, generated rig 33, MPC).
        let unmoved = self.unmoved_while_driven(theta, last, unmoved);
        if unmoved >= HOLD_BLIND_PERIODS || !theta.is_finite() {
            // As the hold's blind rule: the reading is not the arm's, and a law on it (the
            // braking law's included) would drive the arm blind; the short until the
            // pendulum rests.
            self.brake.short();
            self.stage = Stage::Shorted { blind: true };
            self.arm_rest = RestTest::new(self.period_s);
            self.pendulum_rest = RestTest::new(self.period_s);
            self.last_volts = R::ZERO;
            return Some(Some(BrakeCommand::Short));
        }
        if (periods == 0 && !upright) || expired || breach {
            self.give_up_lowering();
            return None;
        }
        if arm_rests && pendulum_rests && phi.abs() <= c(LOWERED_HANGING_RAD) {
            self.lowered = true;
            self.last_volts = R::ZERO;
            return Some(None);
        }
        self.stage = Stage::Lowering {
            at,
            periods: periods + 1,
            last: theta,
            unmoved,
        };
        let phi = pendulum_angle(alpha, &mut self.lower_side);
        let v = law.voltage_from_hanging(theta - at, rate, phi, alpha_rate);
        self.last_volts = v;
        Some(Some(BrakeCommand::Volts(v)))
    }

    /// The rate the braking law takes, and the speed its sign's progress is judged on (none:
    /// the rate's): [`momentum_rate`] in the reading's frame while the arm encoder's sign
    /// against the pendulum is known (the wiring trusted, or [`CouplingTest`] after a
    /// reversal) and the law on it makes progress, judged on the momentum over the largest
    /// inertia; else the measured arm rate. A law on `ω_H` mixes the two
    /// readings, and a wrong `arm_counts_per_rev` (the arm's rate read at a quarter) turns it
    /// into one that drives the arm on: once its saturated speed has risen for
    /// [`WRONG_SIGN_PERIODS`] periods in a row it gives way to the arm rate for the rest of
    /// the stop (without that guard, 14 more generated rigs' LQR balances with the wrong
    /// scale ended past the limit). A brake takes energy out; a law on `ω_H` whose rig gained
    /// [`MOMENTUM_ENERGY_GAIN`] of the pendulum's swing energy (`2 G`) since it began is
    /// pumping the pendulum (that wrong scale spun one to 115 rad/s, generated rig 71) and
    /// gives way too.
    fn braked_rate(&mut self, theta: R, rate: R, alpha: R, alpha_rate: R) -> (R, Option<R>) {
        let Some(model) = self.model else {
            return (rate, None);
        };
        let on_rate = |stop: &mut Self| {
            // The law on the arm's rate: the block's mean is the arm's (`s_e` = 0 drops the
            // coupling's term).
            stop.momentum_block.observe(&model, theta, alpha, R::ZERO);
            (rate, None)
        };
        let Some(s_e) = self.encoder_sign() else {
            return on_rate(self);
        };
        let Some(rising) = self.momentum_rising.as_mut() else {
            return on_rate(self);
        };
        // In the reading's frame the coupling carries the encoder's sign (coupling module
        // docs): `ω_H` of the reading, which the brake's sign maps onto the true one.
        let omega = momentum_rate(&model, rate, alpha, s_e * alpha_rate);
        let speed = omega.abs();
        *rising = if self.brake.saturates(speed) && speed > self.momentum_speed {
            *rising + 1
        } else {
            0
        };
        self.momentum_speed = speed;
        let energy = energy(&model, s_e * rate, alpha, alpha_rate);
        let start = *self.momentum_energy.get_or_insert(energy);
        let swing_energy = c::<R>(2.0) * model.grav;
        if *rising >= WRONG_SIGN_PERIODS
            || energy > start + c::<R>(MOMENTUM_ENERGY_GAIN) * swing_energy
        {
            self.momentum_rising = None;
            return on_rate(self);
        }
        self.momentum_block.observe(&model, theta, alpha, s_e);
        let judged = speed * model.arm_inertia(alpha) / (model.j0 + model.ja);
        (omega, Some(judged))
    }

    /// Starts the braking law's judging afresh, its sign's progress and its block mean: the
    /// speed it brakes changed its meaning (it moved between the arm's rate and momentum, or
    /// came back after the hold).
    fn judge_afresh(&mut self) {
        self.brake.restart_judging();
        self.momentum_block.restart();
    }

    /// Whether the braking law may run on the arm's momentum: the model known, the arm
    /// encoder's sign against the pendulum known, and the law not given up.
    fn may_brake_momentum(&self) -> bool {
        self.model.is_some() && self.encoder_sign().is_some() && self.momentum_rising.is_some()
    }

    /// Whether the braking law has braked out what it brakes: its mean over the last block
    /// ([`MomentumBlock`]) within the law's dead band. On the arm's momentum that ends the
    /// braking; on the arm's rate, only where the hold is `hold_ready` to take over with the
    /// pendulum's terms (the arm encoder's sign known): under a pendulum still swinging the
    /// law on the rate keeps the arm near still but never at rest, and the hold is what takes
    /// the pendulum's energy out (generated rig 46, a heavy pendulum, `m₁₂/J₀` = 1.14, arm
    /// encoder reversed mid-swing: held 1.2 s on the rate while the coupling test gathered its
    /// evidence, the arm then swung out with the pendulum 1.2 rad under the law on the
    /// momentum, which a hold begun there avoids). A hold with the arm's terms alone keeps the
    /// arm still and leaves the pendulum swinging (generated rig 6: the coupling test, with no
    /// arm motion to read, never decided, and the short after the hold let the pendulum walk
    /// the arm past the limit); the short in its place would leave the arm to the pendulum.
    fn braked_out(&self, hold_ready: bool) -> bool {
        (self.on_momentum || (hold_ready && self.encoder_sign().is_some()))
            && self
                .momentum_block
                .mean()
                .is_some_and(|mean| self.brake.below_dead_band(mean.abs()))
    }

    /// The hold law's sign and, where it may use the pendulum's terms, the arm encoder's sign
    /// they take ([`CouplingTest`]), by the brake's mode: the model's sign with both angles
    /// when the wiring is trusted; the sign the arm showed once the braking law proved it on
    /// the arm's response, with the pendulum's terms where the coupling test knows the
    /// encoder's sign; none otherwise (an unproven sign could drive the arm off its hold
    /// point).
    fn hold_sign(&self) -> Option<(R, Option<R>)> {
        if !self.brake.sign_known() {
            return None;
        }
        Some((self.brake.law_sign()?, self.encoder_sign()))
    }
}
