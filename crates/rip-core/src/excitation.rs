//! Excitation signals for identification experiments, and the arm-centring law that keeps an
//! open-loop excitation inside the arm's travel.
//!
//! One definition serves the rig (`rip-rt excite` evaluates them every period) and simulation
//! (`riprs.excitation` returns them as arrays), so a simulated log and a rig log of the same
//! settings carry the same input. Every signal is a voltage `e(t)` (V) defined for
//! `0 ≤ t < duration` and zero from `duration` on; evaluation ([`Excitation::value`]) is
//! allocation-free.
//!
//! # Signals
//!
//! **Chirp** (swept sine) `e(t) = A sin φ(t)` from `f_start` to `f_end` (Hz) over `T = duration`,
//! with instantaneous frequency `f(t) = φ'(t)/2π`:
//!
//! ```text
//! linear:       f(t) = f₀ + (f₁ − f₀) t/T,      φ(t) = 2π (f₀ t + (f₁ − f₀) t²/(2T))
//! logarithmic:  f(t) = f₀ (f₁/f₀)^(t/T),        φ(t) = 2π f₀ T (( f₁/f₀)^(t/T) − 1) / ln(f₁/f₀)
//! ```
//!
//! The logarithmic sweep (the default) spends equal time per decade, so the low frequencies of
//! the arm and the pendulum's resonance get as many periods as the fast motor pole.
//!
//! **PRBS**: a maximum-length sequence from an `n`-bit Fibonacci linear-feedback shift register
//! (`prbs_bits`, taps of Xilinx XAPP052, table 3), one bit per `prbs_clock` seconds,
//! `e = +A` for a 1 and `−A` for a 0. Its period is `2ⁿ − 1` clocks, in which it holds
//! `2ⁿ⁻¹` ones and `2ⁿ⁻¹ − 1` zeros (so the mean over a period is `A/(2ⁿ − 1)`), and its
//! circular autocorrelation is `−A²/(2ⁿ − 1)` at every non-zero lag: a flat spectrum up to about
//! `1/(3 prbs_clock)` Hz. `seed` sets the register's initial state
//! (`1 + seed mod (2ⁿ − 1)`): the same seed gives the same sequence, different seeds shifted
//! copies of the one m-sequence.
//!
//! **Steps**: the levels [`STEP_LEVELS`] × `A` (`+A, 0, −A, 0, +A/2, 0, −A/2, 0`), each held for
//! `step_hold` seconds, repeated: step responses of both signs and two sizes (Coulomb friction
//! and a dead zone show as a size-dependent response), each followed by a coast at 0 V.
//!
//! **Free swing**: a kick, `e = +A` for `kick` seconds then `−A` for `kick` seconds, then 0 V:
//! the pendulum, set swinging by the arm's reaction, coasts (its frequency and damping). The
//! kick is a doublet so that the arm, pushed and then braked, coasts from nearly at rest a
//! short way from its start (about `b A kick²/J` rad): a single pulse would leave it turning,
//! with nothing but friction to stop it before the arm limit.
//!
//! # Arm centring ([`ArmCentering`])
//!
//! With the pendulum hanging, the motor integrates voltage into arm angle (≈ 3 rad/s per volt
//! on a QUBE-Servo 2), so an open-loop excitation with any low-frequency content walks the arm
//! into its limit. The rig adds a weak, damped pull towards the arm's start and scales down any
//! excitation that pushes the arm further out near the limit `θ_L`:
//!
//! ```text
//! u = g(θ, e) e − k_c θ − k_d θ̇,   g = 1 if e θ ≤ 0,
//!                                  else clamp((θ_hi − |θ|)/(θ_hi − θ_lo), 0, 1),
//!                                  θ_lo = GUARD_START θ_L,  θ_hi = GUARD_END θ_L
//! ```
//!
//! (`θ̇` from the difference of the last two measurements). `k_c` (`centering`, V/rad) is weak:
//! the closed arm loop `J θ̈ + (c + b k_d) θ̇ = b (e − k_c θ)` has its natural frequency
//! `√(b k_c / J)` near 0.3–0.6 Hz for `k_c = 1 V/rad` on the presets, so the excitation above it
//! passes almost unchanged, and a constant `e` leaves the arm `e/k_c` rad from its start.
//! `k_d` (`damping`, V·s/rad) damps that loop (on a QUBE-Servo 2 `k_d = 0.2` raises its damping
//! ratio from about 0.4 to 0.8), so that a light arm does not overshoot its guard band into the
//! limit. The identification needs no knowledge of this law: it fits the model to the
//! applied voltage `u`, which the log records. Free swing is left alone (the kick and the coast
//! are the experiment); the loop's arm limit still stops it.

use crate::error::{Result, RipError};

/// The excitation signals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Signal {
    /// Swept sine.
    Chirp,
    /// Pseudo-random binary sequence (maximum-length).
    Prbs,
    /// A staircase of voltage steps ([`STEP_LEVELS`]).
    Steps,
    /// A short kick (a doublet), then 0 V.
    FreeSwing,
}

impl Signal {
    /// Every signal, in documentation order.
    pub const ALL: [Signal; 4] = [
        Signal::Chirp,
        Signal::Prbs,
        Signal::Steps,
        Signal::FreeSwing,
    ];

    /// The name used on command lines, in Python and in logs (`"chirp"`, `"prbs"`, `"steps"`,
    /// `"free-swing"`).
    pub fn name(self) -> &'static str {
        match self {
            Signal::Chirp => "chirp",
            Signal::Prbs => "prbs",
            Signal::Steps => "steps",
            Signal::FreeSwing => "free-swing",
        }
    }

    /// The signal called `name` ([`Signal::name`]; `free_swing` is accepted too).
    pub fn from_name(name: &str) -> Option<Signal> {
        match name {
            "chirp" => Some(Signal::Chirp),
            "prbs" => Some(Signal::Prbs),
            "steps" => Some(Signal::Steps),
            "free-swing" | "free_swing" => Some(Signal::FreeSwing),
            _ => None,
        }
    }
}

impl std::fmt::Display for Signal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How a chirp's frequency moves from `f_start` to `f_end` (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Sweep {
    /// Frequency linear in time.
    Linear,
    /// Frequency exponential in time (equal time per decade).
    #[default]
    Logarithmic,
}

impl Sweep {
    /// `"linear"` or `"log"`.
    pub fn name(self) -> &'static str {
        match self {
            Sweep::Linear => "linear",
            Sweep::Logarithmic => "log",
        }
    }

    /// The sweep called `name` ([`Sweep::name`]; `"logarithmic"` is accepted too).
    pub fn from_name(name: &str) -> Option<Sweep> {
        match name {
            "linear" => Some(Sweep::Linear),
            "log" | "logarithmic" => Some(Sweep::Logarithmic),
            _ => None,
        }
    }
}

/// Step levels, as fractions of the amplitude, each held for `step_hold` seconds in turn.
pub const STEP_LEVELS: [f64; 8] = [1.0, 0.0, -1.0, 0.0, 0.5, 0.0, -0.5, 0.0];

/// Register lengths a PRBS may use.
pub const PRBS_BITS: std::ops::RangeInclusive<u32> = 2..=20;

/// Feedback taps (1-based register positions) of maximum-length LFSRs, Xilinx XAPP052
/// ("Efficient shift registers, LFSR counters, and long pseudo-random sequence generators",
/// 1996), table 3, for 2 to 20 bits.
const PRBS_TAPS: [&[u32]; 19] = [
    &[2, 1],
    &[3, 2],
    &[4, 3],
    &[5, 3],
    &[6, 5],
    &[7, 6],
    &[8, 6, 5, 4],
    &[9, 5],
    &[10, 7],
    &[11, 9],
    &[12, 6, 4, 1],
    &[13, 4, 3, 1],
    &[14, 5, 3, 1],
    &[15, 14],
    &[16, 15, 13, 4],
    &[17, 14],
    &[18, 11],
    &[19, 6, 2, 1],
    &[20, 17],
];

/// Longest excitation (s): an hour at 100 Hz is already 360 000 log rows.
pub const MAX_DURATION: f64 = 3600.0;
/// Largest amplitude (V): the largest voltage limit any rig of rip-rt may set.
pub const MAX_AMPLITUDE: f64 = 24.0;
/// Largest arm-centring gain (V/rad); beyond it the "weak" pull would dominate the excitation.
pub const MAX_CENTERING: f64 = 10.0;
/// Largest arm-centring damping (V·s/rad): beyond it the rate's quantisation noise (one count
/// per period is 0.3 rad/s at 2048 counts per revolution and 100 Hz) would dominate.
pub const MAX_DAMPING: f64 = 2.0;
/// Fraction of the arm limit at which [`ArmCentering`] starts scaling down outward excitation.
pub const GUARD_START: f64 = 0.5;
/// Fraction of the arm limit at which outward excitation is fully suppressed.
pub const GUARD_END: f64 = 0.8;

/// Settings of one excitation; [`ExcitationSettings::new`] gives each signal's documented
/// defaults. Names of fields are the option names of `rip-rt excite` (`--f-start`, ...) and of
/// `riprs.excitation` (`f_start=`, ...), and errors name them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExcitationSettings {
    /// Which signal.
    pub signal: Signal,
    /// Amplitude `A` (V), in (0, [`MAX_AMPLITUDE`]].
    pub amplitude: f64,
    /// Length of the signal (s), in (0, [`MAX_DURATION`]]; 0 V afterwards.
    pub duration: f64,
    /// Chirp start frequency (Hz), positive.
    pub f_start: f64,
    /// Chirp end frequency (Hz), above `f_start` and below the Nyquist frequency `1/(2 dt)`.
    pub f_end: f64,
    /// Chirp sweep law.
    pub sweep: Sweep,
    /// PRBS register length, in [`PRBS_BITS`].
    pub prbs_bits: u32,
    /// PRBS clock period (s): how long each bit is held, at least one sample.
    pub prbs_clock: f64,
    /// PRBS seed (module docs).
    pub seed: u64,
    /// Steps: how long each level is held (s), at least one sample.
    pub step_hold: f64,
    /// Free swing: length of each half of the kick (s), at least one sample; the whole kick
    /// (`2 kick`) is shorter than `duration`.
    pub kick: f64,
    /// Arm-centring gain `k_c` (V/rad), in [0, [`MAX_CENTERING`]] ([`ArmCentering`]).
    pub centering: f64,
    /// Arm-centring damping `k_d` (V·s/rad), in [0, [`MAX_DAMPING`]] ([`ArmCentering`]).
    pub damping: f64,
}

impl ExcitationSettings {
    /// The defaults of `signal`:
    ///
    /// | signal | amplitude | duration | signal settings |
    /// |---|---|---|---|
    /// | chirp | 2 V | 30 s | 0.2 → 10 Hz, logarithmic |
    /// | prbs | 1.5 V | 30 s | 9 bits (511 clocks), 0.03 s clock (15.33 s period), seed 1 |
    /// | steps | 1.5 V | 24 s | 1.5 s per level (two rounds of [`STEP_LEVELS`]) |
    /// | free-swing | 6 V | 30 s | kick of 0.15 s at +6 V, 0.15 s at −6 V |
    ///
    /// and a centring gain of 1 V/rad with a damping of 0.2 V·s/rad.
    pub fn new(signal: Signal) -> Self {
        let (amplitude, duration) = match signal {
            Signal::Chirp => (2.0, 30.0),
            Signal::Prbs => (1.5, 30.0),
            Signal::Steps => (1.5, 24.0),
            // A free swing determines the pendulum's damping only when it swings wide, so it
            // kicks hard; `rip-rt excite` lowers a default amplitude to what the rig's arm
            // can be stopped from.
            Signal::FreeSwing => (6.0, 30.0),
        };
        Self {
            signal,
            amplitude,
            duration,
            f_start: 0.2,
            f_end: 10.0,
            sweep: Sweep::Logarithmic,
            prbs_bits: 9,
            prbs_clock: 0.03,
            seed: 1,
            step_hold: 1.5,
            kick: 0.15,
            centering: 1.0,
            damping: 0.2,
        }
    }

    /// Checks every setting the signal uses for sampling every `dt` seconds; the error names
    /// the first bad one.
    pub fn validate(&self, dt: f64) -> Result<()> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(RipError::invalid(
                "dt",
                format!("must be positive, got {dt}"),
            ));
        }
        if !(self.amplitude > 0.0 && self.amplitude <= MAX_AMPLITUDE) {
            return Err(RipError::invalid(
                "amplitude",
                format!("must be in (0, {MAX_AMPLITUDE}] V, got {}", self.amplitude),
            ));
        }
        if !(self.duration >= dt && self.duration <= MAX_DURATION) {
            return Err(RipError::invalid(
                "duration",
                format!(
                    "must be in [{dt}, {MAX_DURATION}] s (at least one sample), got {}",
                    self.duration
                ),
            ));
        }
        if !(self.damping >= 0.0 && self.damping <= MAX_DAMPING) {
            return Err(RipError::invalid(
                "damping",
                format!(
                    "must be in [0, {MAX_DAMPING}] V·s/rad, got {}",
                    self.damping
                ),
            ));
        }
        if !(self.centering >= 0.0 && self.centering <= MAX_CENTERING) {
            return Err(RipError::invalid(
                "centering",
                format!(
                    "must be in [0, {MAX_CENTERING}] V/rad, got {}",
                    self.centering
                ),
            ));
        }
        let at_least_a_sample = |name: &str, v: f64| {
            if v >= dt && v.is_finite() {
                Ok(())
            } else {
                Err(RipError::invalid(
                    name,
                    format!("must be at least one sample ({dt} s), got {v}"),
                ))
            }
        };
        match self.signal {
            Signal::Chirp => {
                if !(self.f_start.is_finite() && self.f_start > 0.0) {
                    return Err(RipError::invalid(
                        "f_start",
                        format!("must be a positive frequency (Hz), got {}", self.f_start),
                    ));
                }
                let nyquist = 0.5 / dt;
                if !(self.f_end > self.f_start && self.f_end < nyquist) {
                    return Err(RipError::invalid(
                        "f_end",
                        format!(
                            "must be above f_start ({} Hz) and below the Nyquist frequency \
                             ({nyquist} Hz), got {}",
                            self.f_start, self.f_end
                        ),
                    ));
                }
            }
            Signal::Prbs => {
                if !PRBS_BITS.contains(&self.prbs_bits) {
                    return Err(RipError::invalid(
                        "prbs_bits",
                        format!(
                            "must be in {}..={}, got {}",
                            PRBS_BITS.start(),
                            PRBS_BITS.end(),
                            self.prbs_bits
                        ),
                    ));
                }
                at_least_a_sample("prbs_clock", self.prbs_clock)?;
            }
            Signal::Steps => at_least_a_sample("step_hold", self.step_hold)?,
            Signal::FreeSwing => {
                at_least_a_sample("kick", self.kick)?;
                if 2.0 * self.kick >= self.duration {
                    return Err(RipError::invalid(
                        "kick",
                        format!(
                            "must be shorter than half the duration ({} s), got {}",
                            self.duration, self.kick
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Which part of an excitation a time falls in (logged per row by `rip-rt excite`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// The signal itself (for free swing: the kick, both halves).
    Signal,
    /// Free swing after the kick: 0 V.
    Coast,
    /// After `duration`: 0 V.
    Done,
}

/// A maximum-length LFSR and the clock index its state belongs to.
#[derive(Debug, Clone, Copy)]
struct Lfsr {
    bits: u32,
    mask: u32,
    start: u32,
    state: u32,
    clock: u64,
}

impl Lfsr {
    fn new(bits: u32, seed: u64) -> Self {
        let taps = PRBS_TAPS[(bits - 2) as usize];
        // Tap t feeds back the bit that left the register t − 1 clocks before the newest
        // one; tap n (present in every row) is the output bit 0.
        let mask = taps.iter().fold(0u32, |m, &t| m | 1 << (bits - t));
        let period = (1u64 << bits) - 1;
        let start = (1 + seed % period) as u32;
        Self {
            bits,
            mask,
            start,
            state: start,
            clock: 0,
        }
    }

    fn step(&mut self) {
        let feedback = (self.state & self.mask).count_ones() & 1;
        self.state = (self.state >> 1) | (feedback << (self.bits - 1));
        self.clock += 1;
    }

    /// The output bit at `clock`: steps forward from the current state, or from the start
    /// when `clock` lies behind it (a period at most, since the sequence repeats).
    fn bit_at(&mut self, clock: u64) -> bool {
        let target = clock % ((1u64 << self.bits) - 1);
        if target < self.clock {
            self.state = self.start;
            self.clock = 0;
        }
        while self.clock < target {
            self.step();
        }
        self.state & 1 == 1
    }
}

/// An excitation signal ready to evaluate (module docs).
#[derive(Debug, Clone)]
pub struct Excitation {
    settings: ExcitationSettings,
    lfsr: Option<Lfsr>,
}

impl Excitation {
    /// Validates `settings` for a sample time of `dt` seconds ([`ExcitationSettings::validate`]).
    pub fn new(settings: ExcitationSettings, dt: f64) -> Result<Self> {
        settings.validate(dt)?;
        let lfsr =
            (settings.signal == Signal::Prbs).then(|| Lfsr::new(settings.prbs_bits, settings.seed));
        Ok(Self { settings, lfsr })
    }

    /// The settings.
    pub fn settings(&self) -> &ExcitationSettings {
        &self.settings
    }

    /// The stage at `t` seconds.
    pub fn stage(&self, t: f64) -> Stage {
        let s = &self.settings;
        if t >= s.duration {
            Stage::Done
        } else if s.signal == Signal::FreeSwing && t >= 2.0 * s.kick {
            Stage::Coast
        } else {
            Stage::Signal
        }
    }

    /// The excitation voltage `e(t)` (V) at `t ≥ 0` seconds (0 V for `t < 0` and from
    /// `duration` on). Allocation-free; a PRBS steps its register forward from the last call,
    /// so evaluating at increasing times costs O(1) per clock.
    pub fn value(&mut self, t: f64) -> f64 {
        let s = self.settings;
        if !(t >= 0.0 && t < s.duration) {
            return 0.0;
        }
        let a = s.amplitude;
        match s.signal {
            Signal::Chirp => a * chirp_phase(&s, t).sin(),
            Signal::Prbs => {
                let clock = (t / s.prbs_clock + 1e-9).floor() as u64;
                let lfsr = self.lfsr.as_mut().expect("a PRBS has its register");
                if lfsr.bit_at(clock) {
                    a
                } else {
                    -a
                }
            }
            Signal::Steps => {
                let k = (t / s.step_hold + 1e-9).floor() as u64;
                a * STEP_LEVELS[(k % STEP_LEVELS.len() as u64) as usize]
            }
            Signal::FreeSwing => {
                if t < s.kick {
                    a
                } else if t < 2.0 * s.kick {
                    -a
                } else {
                    0.0
                }
            }
        }
    }

    /// The voltage to apply for excitation `e` at measured arm angle `theta` (rad from its
    /// start) and rate `theta_rate` (rad/s) with arm limit `arm_limit`: `e` through
    /// [`ArmCentering`] with this excitation's gains, except for free swing, whose kick and
    /// coast go out unchanged.
    pub fn command(&self, e: f64, theta: f64, theta_rate: f64, arm_limit: f64) -> f64 {
        if self.settings.signal == Signal::FreeSwing {
            return e;
        }
        ArmCentering {
            gain: self.settings.centering,
            damping: self.settings.damping,
        }
        .command(e, theta, theta_rate, arm_limit)
    }
}

/// The chirp's phase φ(t) (module docs).
fn chirp_phase(s: &ExcitationSettings, t: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let (f0, f1, big_t) = (s.f_start, s.f_end, s.duration);
    match s.sweep {
        Sweep::Linear => tau * (f0 * t + (f1 - f0) * t * t / (2.0 * big_t)),
        Sweep::Logarithmic => {
            let r = (f1 / f0).ln();
            tau * f0 * big_t * ((r * t / big_t).exp_m1()) / r
        }
    }
}

/// The weak arm-centring law of the module docs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmCentering {
    /// `k_c` (V/rad).
    pub gain: f64,
    /// `k_d` (V·s/rad).
    pub damping: f64,
}

impl ArmCentering {
    /// `u = g(θ, e) e − k_c θ − k_d θ̇` (module docs) for excitation `e`, arm angle `theta`,
    /// arm rate `theta_rate` and arm limit `arm_limit` (rad).
    pub fn command(&self, e: f64, theta: f64, theta_rate: f64, arm_limit: f64) -> f64 {
        let lo = GUARD_START * arm_limit;
        let hi = GUARD_END * arm_limit;
        let g = if e * theta <= 0.0 {
            1.0
        } else {
            ((hi - theta.abs()) / (hi - lo)).clamp(0.0, 1.0)
        };
        g * e - self.gain * theta - self.damping * theta_rate
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.01;

    fn sampled(settings: ExcitationSettings, n: usize) -> Vec<f64> {
        let mut x = Excitation::new(settings, DT).unwrap();
        (0..n).map(|k| x.value(k as f64 * DT)).collect()
    }

    fn prbs(bits: u32, clock: f64, seed: u64) -> ExcitationSettings {
        ExcitationSettings {
            prbs_bits: bits,
            prbs_clock: clock,
            seed,
            duration: MAX_DURATION,
            amplitude: 1.0,
            ..ExcitationSettings::new(Signal::Prbs)
        }
    }

    #[test]
    fn prbs_has_the_maximum_period_for_every_register_length() {
        for bits in PRBS_BITS {
            let mut r = Lfsr::new(bits, 0);
            let start = r.state;
            let period = (1u64 << bits) - 1;
            let mut ones = 0u64;
            for k in 1..=period {
                ones += u64::from(r.state & 1);
                r.step();
                if k < period {
                    assert_ne!(r.state, start, "{bits} bits: period {k} < {period}");
                }
            }
            assert_eq!(r.state, start, "{bits} bits: not periodic at {period}");
            // An m-sequence has one more 1 than 0 per period.
            assert_eq!(ones, 1u64 << (bits - 1), "{bits} bits");
        }
    }

    #[test]
    fn prbs_is_balanced_with_a_two_valued_autocorrelation() {
        let bits = 7;
        let n = 127;
        let u = sampled(prbs(bits, DT, 5), 2 * n);
        assert!(u.iter().all(|&v| v == 1.0 || v == -1.0));
        assert_eq!(u[..n], u[n..], "periodic with period 2^7 - 1");
        assert_eq!(u[..n].iter().sum::<f64>(), 1.0);
        for lag in 1..n {
            let r: f64 = (0..n).map(|k| u[k] * u[(k + lag) % n]).sum();
            assert_eq!(r, -1.0, "lag {lag}");
        }
    }

    #[test]
    fn prbs_holds_each_bit_for_its_clock_and_is_reproducible() {
        let u = sampled(prbs(9, 0.03, 3), 600);
        for chunk in u.chunks(3) {
            assert!(chunk.iter().all(|&v| v == chunk[0]), "{chunk:?}");
        }
        assert_eq!(u, sampled(prbs(9, 0.03, 3), 600));
        assert_ne!(u, sampled(prbs(9, 0.03, 4), 600));
        // Going back in time gives the same values as the first pass.
        let mut x = Excitation::new(prbs(9, 0.03, 3), DT).unwrap();
        let late = x.value(5.0);
        let early = x.value(0.5);
        assert_eq!((early, late), (u[50], u[500]));
    }

    /// Frequency from zero crossings of `u` in a window centred on sample `k`.
    fn crossing_frequency(u: &[f64], dt: f64, k: usize, half: usize) -> f64 {
        let w = &u[k - half..k + half];
        let n = w.windows(2).filter(|p| p[0] * p[1] < 0.0).count();
        n as f64 / 2.0 / (2 * half) as f64 / dt
    }

    #[test]
    fn chirp_instantaneous_frequency_follows_the_sweep_law() {
        // 1 kHz sampling resolves the zero crossings well.
        let dt = 1e-3;
        for sweep in [Sweep::Linear, Sweep::Logarithmic] {
            let s = ExcitationSettings {
                sweep,
                f_start: 1.0,
                f_end: 20.0,
                duration: 10.0,
                ..ExcitationSettings::new(Signal::Chirp)
            };
            let mut x = Excitation::new(s, dt).unwrap();
            let u: Vec<f64> = (0..10_000).map(|k| x.value(k as f64 * dt)).collect();
            for t in [1.5, 3.0, 5.0, 7.0, 9.0] {
                let expected = match sweep {
                    Sweep::Linear => 1.0 + 19.0 * t / 10.0,
                    Sweep::Logarithmic => 20f64.powf(t / 10.0),
                };
                // A one-second window: the count is exact to ±1 crossing, the frequency moves
                // by at most 2 Hz across it (checked to 10 % plus a crossing's worth).
                let got = crossing_frequency(&u, dt, (t / dt) as usize, 500);
                assert!(
                    (got - expected).abs() <= 0.1 * expected + 0.5,
                    "{sweep:?} at {t} s: {got} Hz, expected {expected}"
                );
            }
            assert!(u.iter().all(|v| v.abs() <= 2.0));
            assert_eq!(u[0], 0.0, "starts at 0 V, no jump");
        }
    }

    #[test]
    fn steps_and_kick_follow_their_definition() {
        let s = ExcitationSettings {
            step_hold: 0.5,
            amplitude: 2.0,
            duration: 5.0,
            ..ExcitationSettings::new(Signal::Steps)
        };
        let u = sampled(s, 600);
        for (k, &v) in u.iter().enumerate() {
            let level = if k < 500 {
                [2.0, 0.0, -2.0, 0.0, 1.0, 0.0, -1.0, 0.0][(k / 50) % 8]
            } else {
                0.0
            };
            assert_eq!(v, level, "sample {k}");
        }
        let s = ExcitationSettings {
            kick: 0.2,
            duration: 1.0,
            amplitude: 3.0,
            ..ExcitationSettings::new(Signal::FreeSwing)
        };
        let mut x = Excitation::new(s, DT).unwrap();
        let u: Vec<f64> = (0..150).map(|k| x.value(k as f64 * DT)).collect();
        assert!(u[..20].iter().all(|&v| v == 3.0));
        assert!(u[20..40].iter().all(|&v| v == -3.0));
        assert!(u[40..].iter().all(|&v| v == 0.0));
        assert_eq!(x.stage(0.1), Stage::Signal);
        assert_eq!(x.stage(0.3), Stage::Signal);
        assert_eq!(x.stage(0.5), Stage::Coast);
        assert_eq!(x.stage(1.0), Stage::Done);
        // Free swing goes out unchanged, whatever the arm does.
        assert_eq!(x.command(3.0, 2.9, 5.0, 3.0), 3.0);
    }

    #[test]
    fn every_signal_stays_within_its_amplitude_and_ends_at_zero() {
        for signal in Signal::ALL {
            let s = ExcitationSettings {
                duration: 4.0,
                ..ExcitationSettings::new(signal)
            };
            let u = sampled(s, 500);
            assert!(
                u.iter().all(|v| v.abs() <= s.amplitude),
                "{signal}: beyond ±{}",
                s.amplitude
            );
            assert!(
                u[..400].iter().any(|v| v.abs() > 0.9 * s.amplitude),
                "{signal}"
            );
            assert!(u[400..].iter().all(|&v| v == 0.0), "{signal}");
        }
    }

    #[test]
    fn centering_pulls_back_and_the_guard_stops_outward_pushes() {
        let c = ArmCentering {
            gain: 1.0,
            damping: 0.5,
        };
        let limit = 2.0;
        // Inside the guard: excitation plus the pull, and the damping against the rate.
        assert_eq!(c.command(1.5, 0.5, 0.0, limit), 1.5 - 0.5);
        assert_eq!(c.command(1.5, 0.5, 2.0, limit), 1.5 - 0.5 - 1.0);
        // Inward excitation is never scaled.
        assert_eq!(c.command(-1.5, 1.8, 0.0, limit), -1.5 - 1.8);
        // Halfway through the guard band (θ_lo = 1, θ_hi = 1.6): half the outward push.
        assert!((c.command(2.0, 1.3, 0.0, limit) - (1.0 - 1.3)).abs() < 1e-12);
        // Past θ_hi: only the pull.
        assert_eq!(c.command(-2.0, -1.7, 0.0, limit), 1.7);
    }

    #[test]
    fn bad_settings_are_named() {
        let base = ExcitationSettings::new(Signal::Chirp);
        let cases = [
            (
                ExcitationSettings {
                    amplitude: 0.0,
                    ..base
                },
                "amplitude",
            ),
            (
                ExcitationSettings {
                    amplitude: f64::NAN,
                    ..base
                },
                "amplitude",
            ),
            (
                ExcitationSettings {
                    duration: -1.0,
                    ..base
                },
                "duration",
            ),
            (
                ExcitationSettings {
                    duration: 1e9,
                    ..base
                },
                "duration",
            ),
            (
                ExcitationSettings {
                    f_start: 0.0,
                    ..base
                },
                "f_start",
            ),
            (ExcitationSettings { f_end: 0.1, ..base }, "f_end"),
            (
                ExcitationSettings {
                    f_end: 50.0,
                    ..base
                },
                "f_end",
            ),
            (
                ExcitationSettings {
                    damping: 10.0,
                    ..base
                },
                "damping",
            ),
            (
                ExcitationSettings {
                    centering: -1.0,
                    ..base
                },
                "centering",
            ),
            (
                ExcitationSettings {
                    prbs_bits: 1,
                    ..ExcitationSettings::new(Signal::Prbs)
                },
                "prbs_bits",
            ),
            (
                ExcitationSettings {
                    prbs_clock: 0.001,
                    ..ExcitationSettings::new(Signal::Prbs)
                },
                "prbs_clock",
            ),
            (
                ExcitationSettings {
                    step_hold: f64::INFINITY,
                    ..ExcitationSettings::new(Signal::Steps)
                },
                "step_hold",
            ),
            (
                ExcitationSettings {
                    kick: 30.0,
                    ..ExcitationSettings::new(Signal::FreeSwing)
                },
                "kick",
            ),
        ];
        for (s, name) in cases {
            match Excitation::new(s, DT) {
                Err(RipError::InvalidParameter { name: got, .. }) => assert_eq!(got, name),
                other => panic!("{name}: {other:?}"),
            }
        }
        // Settings a signal does not use are not checked.
        let s = ExcitationSettings {
            f_end: -1.0,
            ..ExcitationSettings::new(Signal::Steps)
        };
        assert!(Excitation::new(s, DT).is_ok());
    }
}
