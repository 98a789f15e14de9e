//! The stop's braking command, period by period, in the mode the stop's cause allows.

use super::*;

/// How a stop brakes the arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrakeMode {
    /// The braking law on the measured rate (the motor and encoders are trusted).
    Active,
    /// The braking law with its sign reversed: the arm was seen to move against the voltage (a
    /// swapped motor lead or a reversed arm encoder), and in both cases a voltage along the
    /// *measured* motion is the one that opposes the true motion. The sign is checked on the
    /// arm's response ([`Brake`]): wrong, the law flips once to [`BrakeMode::Checked`].
    Reversed,
    /// The braking law with the model's sign, checked on the arm's response: the rig's motion
    /// was found unlike the model's, its arm encoder still counting (a wrong scale, a pendulum
    /// that disagrees), so the sign is not known for sure. Wrong, the law flips once to
    /// [`BrakeMode::Reversed`]; a law that fails both ways gives way to the short.
    Checked,
    /// The arm encoder stopped counting; the motor is trusted. From an estimate of the state
    /// at the stop, the braking law on the arm's angular momentum carried by the torque alone
    /// and read against the pendulum ([`Brake::observe_pendulum`]), or without pendulum
    /// readings on the model's arm run open loop, until it is braked out; then the short
    /// (the stop's sequence keeps it until the pendulum rests).
    Modelled,
    /// The brake command only: windings shorted, whatever the wiring's sign.
    Short,
    /// Nothing can be sent (the device is gone), or the motor was never enabled.
    None,
}

/// Periods in a row of a rising arm speed under the saturated braking law with the sign under
/// test after which that sign is taken to be wrong (the sign the arm showed was not the
/// wiring's: a wrong scale, say): the law flips once, then gives way to the short.
pub const WRONG_SIGN_PERIODS: u32 = 4;
/// Periods over which the saturated law with the sign under test must take a tenth off the
/// arm's speed, or the sign is taken to be wrong.
pub const PROGRESS_PERIODS: u32 = 10;

/// What the stop applies for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BrakeCommand<R: Real = f64> {
    /// Drive this voltage (V).
    Volts(R),
    /// Short the windings (the brake command).
    Short,
}

/// The model braked open loop ([`BrakeMode::Modelled`]): its stop, its state, how long its
/// arm has been at rest (periods), and, once the pendulum's readings come in, the arm's
/// angular momentum `H` with the pendulum's last reading (angle, rate).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Modelled<R: Real> {
    stop: SimulatedStop<R>,
    x: [R; 4],
    still: u32,
    momentum: Option<R>,
    pendulum: Option<[R; 2]>,
}

impl<R: Real> Modelled<R> {
    /// The braking law on `rate` (rad/s), 0 V within `dead_band`; counts the periods in a
    /// row within it.
    fn law_beyond_dead_band(&mut self, rate: R, dead_band: R) -> R {
        if rate.abs() <= dead_band {
            self.still += 1;
            R::ZERO
        } else {
            self.still = 0;
            self.stop.law.voltage(rate)
        }
    }
}

/// The stop's command, period by period (module docs): one definition for `rip-rt`'s stops,
/// the device's and the simulations that test them. Allocation-free, `Copy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Brake<R: Real = f64> {
    mode: BrakeMode,
    law: BrakingLaw<R>,
    dead_band: R,
    last_speed: R,
    rising: u32,
    // The speed at the start of the current progress window, and the periods into it.
    window_speed: R,
    window: u32,
    // Whether the checked law may still flip its sign once; the largest saturated speed
    // since its sign was last set, and whether the law has since halved it (its sign shown
    // right on the arm's response).
    may_flip: bool,
    peak_speed: R,
    verified: bool,
    // Whether the arm's equation confirmed the sign under test ([`Brake::drive_sign_found`]).
    drive_confirmed: bool,
    model: Option<Modelled<R>>,
}

impl<R: Real> Brake<R> {
    /// The stop braking with `law` in `mode`; below `dead_band` (rad/s: the rate of one
    /// encoder count and a half per period, the encoder's quantisation) the law applies 0 V
    /// rather than chatter between ± its gain per count.
    pub fn new(law: BrakingLaw<R>, dead_band: R, mode: BrakeMode) -> Self {
        Self {
            mode,
            law,
            dead_band,
            last_speed: c(f64::INFINITY),
            rising: 0,
            window_speed: c(f64::INFINITY),
            window: 0,
            may_flip: matches!(mode, BrakeMode::Reversed | BrakeMode::Checked),
            peak_speed: R::ZERO,
            verified: false,
            drive_confirmed: false,
            model: None,
        }
    }

    /// The stop in [`BrakeMode::Modelled`]: `stop`'s law on its model's arm from the state
    /// `x` at the stop decision, `held` (V) still applied for the period until the stop's
    /// first command (the short when there is no state).
    pub fn modelled(stop: &SimulatedStop<R>, dead_band: R, x: Option<[R; 4]>, held: R) -> Self {
        let mut brake = Self::new(stop.law, dead_band, BrakeMode::Short);
        if let Some(mut x) = x.filter(|x| x.iter().all(|v| v.is_finite())) {
            stop.advance(&mut x, held);
            brake.model = Some(Modelled {
                stop: *stop,
                x,
                still: 0,
                momentum: None,
                pendulum: None,
            });
            brake.mode = BrakeMode::Modelled;
        }
        brake
    }

    /// The pendulum as read this period (`alpha`, rad, 0 upright; `alpha_rate`, rad/s), for
    /// [`BrakeMode::Modelled`]: the model's own pendulum soon parts from the rig's (it fell,
    /// swung, and the law drove the arm blind at the voltage bound for a whole 8 s stop on
    /// generated rig 79), so the stop brakes the arm's angular momentum instead, carried from
    /// the estimate at the stop by the torque alone and read against the pendulum as it is
    /// (momentum module docs); braked out, the short. Other modes ignore it.
    pub fn observe_pendulum(&mut self, alpha: R, alpha_rate: R) {
        if self.mode != BrakeMode::Modelled || !(alpha.is_finite() && alpha_rate.is_finite()) {
            return;
        }
        if let Some(m) = self.model.as_mut() {
            if m.momentum.is_none() {
                // From the estimate's own state: the stop's first rates are no rates (there is
                // no reading before its first), and a pendulum rate of 0 in `H` tripled a heavy
                // pendulum's arm momentum and braked it through zero (generated rig 79).
                m.momentum = Some(m.stop.model.arm_momentum(m.x[1], m.x[2], m.x[3]));
            }
            m.pendulum = Some([alpha, alpha_rate]);
        }
    }

    /// The model's arm angle (rad) in [`BrakeMode::Modelled`].
    pub fn model_arm(&self) -> Option<R> {
        self.model.as_ref().map(|m| m.x[0])
    }

    /// Whether the law's sign is known: trusted ([`BrakeMode::Active`]), or shown on the arm's
    /// response (the saturated law has halved the arm's speed with it).
    pub fn sign_known(&self) -> bool {
        match self.mode {
            BrakeMode::Active => true,
            BrakeMode::Checked | BrakeMode::Reversed => self.verified,
            _ => false,
        }
    }

    /// How it brakes now (a law whose sign proved wrong became [`BrakeMode::Short`]).
    pub fn mode(&self) -> BrakeMode {
        self.mode
    }

    /// Whether arm speed `speed` (rad/s) is within the law's dead band (0 V).
    pub fn below_dead_band(&self, speed: R) -> bool {
        speed <= self.dead_band
    }

    /// Whether the law is saturated at arm speed `speed` (rad/s).
    pub fn saturates(&self, speed: R) -> bool {
        speed > self.law.linear_below
    }

    /// Starts the judging of the sign's progress afresh: the speed it is judged on changed
    /// its meaning (the law moved from the arm's rate to its angular momentum, or back), and
    /// the last speed of the one is no yardstick for the other.
    pub fn restart_judging(&mut self) {
        self.rising = 0;
        self.window = 0;
        self.last_speed = c(f64::INFINITY);
        self.window_speed = c(f64::INFINITY);
        self.peak_speed = R::ZERO;
    }

    /// Gives up the law for the short from now on.
    pub fn short(&mut self) {
        if self.mode != BrakeMode::None {
            self.mode = BrakeMode::Short;
        }
    }

    /// The command for the measured arm rate `rate` (rad/s; `None` without a fresh
    /// measurement, which shorts the windings for that period).
    pub fn command(&mut self, rate: Option<R>) -> BrakeCommand<R> {
        self.command_judged(rate, None)
    }

    /// [`command`](Self::command), the sign's progress judged on `judged` (rad/s) rather than
    /// on `|rate|`: for a law on the arm's angular momentum, the momentum in units of the
    /// arm's largest inertia, which the saturated law takes down every period, where `ω_H`
    /// itself rises and falls with the pendulum's swing (the inertia it is divided by does).
    pub fn command_judged(&mut self, rate: Option<R>, judged: Option<R>) -> BrakeCommand<R> {
        let Some(sign) = self.law_sign() else {
            return match self.mode {
                // A reading that moves after all: the model's arm is not the arm.
                BrakeMode::Modelled if rate.is_some_and(|r| r.abs() > self.dead_band) => {
                    self.mode = BrakeMode::Short;
                    BrakeCommand::Short
                }
                BrakeMode::Modelled => self.modelled_command(),
                _ => BrakeCommand::Short,
            };
        };
        let Some(rate) = rate.filter(|r| r.is_finite()) else {
            return BrakeCommand::Short;
        };
        let speed = judged.filter(|j| j.is_finite()).unwrap_or(rate).abs();
        let mut sign = sign;
        let under_test = matches!(self.mode, BrakeMode::Reversed | BrakeMode::Checked);
        if under_test && !self.drive_confirmed && self.wrong_sign(speed) {
            if !self.flip() {
                return BrakeCommand::Short;
            }
            sign = -sign;
        }
        // Halved from its saturated peak by more than the encoder's quantisation, saturated
        // still or not: the sign is shown right. A law whose sign was shown only while still
        // saturated and that then moved onto the arm's momentum (which restarts the judging)
        // was left unverified, and its stop shorted a heavy pendulum's arm rather than hold
        // it (generated rig 90); a halving within a count or two per period is no evidence (a
        // 616-count encoder read 2 counts a period, then 1, under a wrong sign: generated rig
        // 17, held with that sign and driven to 15 rad).
        if speed > self.law.linear_below {
            self.peak_speed = self.peak_speed.max(speed);
        }
        if self.peak_speed > R::ZERO && speed < c::<R>(0.5) * self.peak_speed - self.dead_band {
            self.verified = true;
        }
        if rate.abs() <= self.dead_band {
            BrakeCommand::Volts(R::ZERO)
        } else {
            BrakeCommand::Volts(sign * self.law.voltage(rate))
        }
    }

    /// The sign under test proved wrong: the law flips to the other one once (the sign the
    /// diagnosis suggested drove the arm on, so the other one brakes it), then gives way to
    /// the short. Whether it still brakes.
    fn flip(&mut self) -> bool {
        if !self.may_flip {
            self.mode = BrakeMode::Short;
            return false;
        }
        self.may_flip = false;
        self.mode = if self.mode == BrakeMode::Reversed {
            BrakeMode::Checked
        } else {
            BrakeMode::Reversed
        };
        self.restart_judging();
        true
    }

    /// The sign the law takes against the measured arm rate: `+1` with the model's (trusted,
    /// or under test), `−1` reversed; `None` where it does not run on the measured rate.
    pub fn law_sign(&self) -> Option<R> {
        match self.mode {
            BrakeMode::Active | BrakeMode::Checked => Some(R::ONE),
            BrakeMode::Reversed => Some(-R::ONE),
            _ => None,
        }
    }

    /// The drive's sign `s_d` as the arm's equation named it ([`CouplingTest::drive_sign`]:
    /// `+1` when a positive voltage moves the arm reading positive): a sign under test that
    /// agrees is shown right; one that disagrees flips as a rising speed would flip it,
    /// periods sooner. A trusted sign, or a stop that does not drive, is left as it is.
    pub fn drive_sign_found(&mut self, s_d: R) {
        let Some(under_test) = self.law_sign().filter(|_| self.mode != BrakeMode::Active) else {
            return;
        };
        if s_d == under_test {
            // The arm's equation outweighs the rising-speed rule, which a heavy pendulum's
            // push on the arm can fool: with the sign confirmed, a speed still rising under
            // that push once shorted a law that was braking (generated rig 90, a swapped lead
            // mid-swing: 17 rad).
            self.verified = true;
            self.drive_confirmed = true;
        } else {
            self.drive_confirmed = false;
            self.flip();
        }
    }

    /// The law on the arm's momentum read against the pendulum (the torque then carries it a
    /// period on), or without a pendulum reading on the model's arm rate (the model then
    /// advances a period under it).
    fn modelled_command(&mut self) -> BrakeCommand<R> {
        let dead_band = self.dead_band;
        let Some(m) = self.model.as_mut() else {
            self.mode = BrakeMode::Short;
            return BrakeCommand::Short;
        };
        let rest_periods = periods_in(REST_S, m.stop.ts.to_f64());
        let stop = m.stop;
        let v = match (m.momentum, m.pendulum.take()) {
            (Some(h), Some([alpha, alpha_rate])) => {
                let model = &stop.model;
                let inertia = model.arm_inertia(alpha);
                let v = m.law_beyond_dead_band(h / inertia, dead_band);
                // Only the motor's torque and the arm's friction change `H` (momentum module
                // docs): `Ḣ = b u − c θ̇`, with `θ̇` from `H` and the pendulum as read.
                let rate = (h + model.m12 * alpha.cos() * alpha_rate) / inertia;
                let applied = v - v.clamp(-stop.dead_zone, stop.dead_zone);
                m.momentum = Some(h + stop.ts * (model.b * applied - model.c_arm * rate));
                m.x[0] += rate * stop.ts;
                m.x[1] = rate;
                v
            }
            _ => {
                let v = m.law_beyond_dead_band(m.x[1], dead_band);
                stop.advance(&mut m.x, v);
                v
            }
        };
        if m.still >= rest_periods {
            self.mode = BrakeMode::Short;
            return BrakeCommand::Short;
        }
        BrakeCommand::Volts(v)
    }

    /// Whether the law with the sign under test proves not to brake: a law that opposes the
    /// motion slows the arm after the latency; one whose sign is wrong speeds it up period
    /// after period, or holds it at the speed where the motor's back-EMF balances it (both
    /// judged while the law is saturated: in its linear range the pendulum's push on the arm
    /// is as large as the law's, and a test there flips a law that was right).
    fn wrong_sign(&mut self, speed: R) -> bool {
        let saturated = speed > self.law.linear_below;
        if saturated && speed > self.last_speed + self.dead_band {
            self.rising += 1;
        } else {
            self.rising = 0;
        }
        self.last_speed = speed;
        if !saturated {
            self.window = 0;
            self.window_speed = c(f64::INFINITY);
            return false;
        }
        if self.window == 0 {
            self.window_speed = speed;
        }
        self.window += 1;
        let stalled = self.window > PROGRESS_PERIODS && speed > c::<R>(0.9) * self.window_speed;
        if self.window > PROGRESS_PERIODS {
            self.window = 0;
        }
        self.rising >= WRONG_SIGN_PERIODS || stalled
    }
}
