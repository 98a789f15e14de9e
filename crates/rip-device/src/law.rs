//! The onboard controller of the rig: rip-control's [`Controller`] behind the device's
//! [`Onboard`] interface, with the conversion from encoder counts to the controller's angles
//! and the reference step, which the host uploads ahead of the design.
//!
//! # Onboard image (version 2)
//!
//! The bytes the host uploads are a header, the stop's design where the host sends one
//! ([`StopDesign::write`], magic `"RIPS"`; version 1 images have none), and the design in
//! rip-control's layout ([`Design::to_bytes`], which has its own magic, length and CRC-32):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"RIPO"` |
//! | 4 | 8 | arm radians per count `s_θ` (`f64`, signed: the encoder's direction) |
//! | 12 | 8 | pendulum radians per count `s_α` |
//! | 20 | 8 | arm offset `o_θ` (rad) |
//! | 28 | 8 | pendulum offset `o_α` (rad) |
//! | 36 | 8 | reference step height `r_θ` (rad) |
//! | 44 | 8 | reference step time `t_r` (s after the start) |
//! | 52 | 128 | the stop's design, when the next four bytes are `"RIPS"` |
//! | 52 or 180 | … | the design |
//!
//! At step `k` of a run (time `t = k T_s`), from positions `(n_θ, n_α)`:
//!
//! ```text
//! θ = n_θ s_θ − o_θ,   α = wrap(n_α s_α − o_α) ∈ (−π, π],   r = [r_θ if t ≥ t_r else 0, 0]
//! ```
//!
//! the same conversion as rip-rt's loop on the host ([`rip_control::stop::angles`]).
//!
//! # The device's stop
//!
//! When a run stops on the device's own account (its limits, a silent host, a non-finite move)
//! and the start said the wiring was verified, the law runs the stop of the image's stop
//! design ([`StopDesign::sequence`]: the braking law, then the hold law, then the short, the
//! rule of `rip_control::stop` that rip-rt runs on the host) on the angles and the rates over
//! the device's clock ([`rip_control::stop::sample_rates`]), at most every
//! [`STOP_PERIOD_S`](rip_control::stop::STOP_PERIOD_S)
//! (a faster design holds the stop's command in between); otherwise the device shorts the
//! windings at once.

use rip_control::stop::{
    sample_rates, steps_per_stop_period, BrakeCommand, StopDesign, StopSequence, STOP_MAGIC,
};
use rip_control::{Controller, Design, Measurement, Phase, Real};
use rip_protocol::{PIL_PHASE_CONVERT, PIL_PHASE_ESTIMATE, PIL_PHASE_LINEAR, PIL_PHASE_QP};

use crate::{DesignRefused, Onboard};

/// Magic of an onboard image.
pub const IMAGE_MAGIC: [u8; 4] = *b"RIPO";
/// Length of the onboard image's header (module docs).
pub const IMAGE_HEADER_LEN: usize = 52;

/// Counts → angles and the reference: the onboard image's header (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sensor {
    /// Arm radians per count (signed).
    pub arm_rad_per_count: f64,
    /// Pendulum radians per count (signed).
    pub pendulum_rad_per_count: f64,
    /// Subtracted from the arm's scaled counts: θ = 0.
    pub arm_offset: f64,
    /// Subtracted from the pendulum's scaled counts: α = 0 upright.
    pub pendulum_offset: f64,
    /// Arm reference step (rad).
    pub arm_step: f64,
    /// When the step comes, s after the start.
    pub step_time: f64,
}

impl Sensor {
    fn fields(&self) -> [f64; 6] {
        [
            self.arm_rad_per_count,
            self.pendulum_rad_per_count,
            self.arm_offset,
            self.pendulum_offset,
            self.arm_step,
            self.step_time,
        ]
    }

    /// Writes the header into `out[..IMAGE_HEADER_LEN]`; `false` if `out` is shorter.
    pub fn write(&self, out: &mut [u8]) -> bool {
        let Some(h) = out.get_mut(..IMAGE_HEADER_LEN) else {
            return false;
        };
        h[..4].copy_from_slice(&IMAGE_MAGIC);
        for (i, v) in self.fields().iter().enumerate() {
            h[4 + 8 * i..12 + 8 * i].copy_from_slice(&v.to_le_bytes());
        }
        true
    }

    /// Reads a header; `None` for another magic, a short input or a non-finite field (a zero
    /// scale is refused too: it would hide the encoder).
    pub fn read(bytes: &[u8]) -> Option<Sensor> {
        let h = bytes.get(..IMAGE_HEADER_LEN)?;
        if h[..4] != IMAGE_MAGIC {
            return None;
        }
        let f = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&h[4 + 8 * i..12 + 8 * i]);
            f64::from_le_bytes(b)
        };
        let s = Sensor {
            arm_rad_per_count: f(0),
            pendulum_rad_per_count: f(1),
            arm_offset: f(2),
            pendulum_offset: f(3),
            arm_step: f(4),
            step_time: f(5),
        };
        let ok = s.fields().iter().all(|v| v.is_finite())
            && s.arm_rad_per_count != 0.0
            && s.pendulum_rad_per_count != 0.0;
        ok.then_some(s)
    }

    /// The same conversion with its zeros at the counts `[arm_zero, pendulum_down]`: θ = 0 at
    /// the first, α = π (hanging) at the second (a host's calibration from a rest hanging
    /// down, as rip-rt's loop takes it).
    pub fn zeroed_at(&self, [arm_zero, pendulum_down]: [i32; 2]) -> Sensor {
        Sensor {
            arm_offset: f64::from(arm_zero) * self.arm_rad_per_count,
            pendulum_offset: f64::from(pendulum_down) * self.pendulum_rad_per_count
                - core::f64::consts::PI,
            ..*self
        }
    }

    /// The angles `[θ, α]` of the positions (module docs; [`rip_control::stop::angles`]).
    pub fn angles(&self, positions: [i32; 2]) -> [f64; 2] {
        rip_control::stop::angles(
            positions,
            [self.arm_rad_per_count, self.pendulum_rad_per_count],
            [self.arm_offset, self.pendulum_offset],
        )
    }
}

/// An onboard image assembled on the host: `sensor`'s header, `stop`'s design where there is
/// one, then `design`'s bytes, into `out`; returns the length, or `None` if `out` is too short
/// or a design is invalid.
pub fn write_image<R: Real>(
    sensor: &Sensor,
    stop: Option<&StopDesign<R>>,
    design: &Design<R>,
    out: &mut [u8],
) -> Option<usize> {
    if !sensor.write(out) {
        return None;
    }
    let mut at = IMAGE_HEADER_LEN;
    if let Some(stop) = stop {
        at += stop.write(out.get_mut(at..)?).ok()?;
    }
    let n = design.to_bytes(out.get_mut(at..)?).ok()?;
    Some(at + n)
}

/// The device's own stop in progress (module docs): its sequence, run every `every` steps
/// (at least [`STOP_PERIOD_S`](rip_control::stop::STOP_PERIOD_S) apart) on the angles of `sensor`, the last of those samples'
/// angles and device clock for the rates, the steps so far, and the command held between the
/// sequence's periods.
#[derive(Debug, Clone, Copy)]
struct Stopping<R: Real> {
    sequence: StopSequence<R>,
    sensor: Sensor,
    last: Option<(R, R, u32)>,
    every: u32,
    steps: u32,
    held: BrakeCommand<R>,
}

/// rip-control's controller in scalar `R` as the device's [`Onboard`] law, with a design
/// buffer of `N` bytes.
#[derive(Debug, Clone)]
pub struct ControlLaw<R: Real, const N: usize> {
    buf: [u8; N],
    sensor: Sensor,
    // Loaded in place (`Controller::load`): a design or a controller built as a temporary
    // would take tens of kilobytes of a firmware's stack, which overflows into the statics.
    controller: Controller<R>,
    loaded: bool,
    step: u32,
    last: Option<rip_control::Move<R>>,
    stop: Option<StopDesign<R>>,
    stopping: Option<Stopping<R>>,
}

impl<R: Real, const N: usize> Default for ControlLaw<R, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<R: Real, const N: usize> ControlLaw<R, N> {
    /// No design loaded (`const`, for a firmware's static).
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            sensor: Sensor {
                arm_rad_per_count: 0.0,
                pendulum_rad_per_count: 0.0,
                arm_offset: 0.0,
                pendulum_offset: 0.0,
                arm_step: 0.0,
                step_time: 0.0,
            },
            controller: Controller::unloaded(),
            loaded: false,
            step: 0,
            last: None,
            stop: None,
            stopping: None,
        }
    }

    /// The loaded controller, if any.
    pub fn controller(&self) -> Option<&Controller<R>> {
        self.loaded.then_some(&self.controller)
    }

    /// The loaded image's counts → angles conversion and reference.
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// The loaded image's stop design, if it has one.
    pub fn stop_design(&self) -> Option<&StopDesign<R>> {
        self.loaded.then_some(self.stop.as_ref()).flatten()
    }

    /// The device's own stop in progress, if any (module docs, "The device's stop").
    pub fn stop_sequence(&self) -> Option<&StopSequence<R>> {
        self.stopping.as_ref().map(|s| &s.sequence)
    }

    /// The last step's move (its status and QP iterations).
    pub fn last_move(&self) -> Option<rip_control::Move<R>> {
        self.last
    }

    /// The controller's measurement at step `k` from the positions (module docs).
    pub fn measurement(&self, k: u32, positions: [i32; 2]) -> Measurement<R> {
        let [theta, alpha] = self.sensor.angles(positions);
        let ts = self.controller().map_or(0.0, |c| c.design().ts.to_f64());
        let r = if k as f64 * ts >= self.sensor.step_time {
            self.sensor.arm_step
        } else {
            0.0
        };
        Measurement {
            angles: [R::from_f64(theta), R::from_f64(alpha)],
            reference: [R::from_f64(r), R::ZERO],
        }
    }
}

impl<R: Real, const N: usize> Onboard for ControlLaw<R, N> {
    fn buffer(&mut self) -> &mut [u8] {
        &mut self.buf
    }

    fn load(&mut self, len: usize) -> Result<(), DesignRefused> {
        self.loaded = false;
        self.stopping = None;
        let bytes = self.buf.get(..len).ok_or(DesignRefused)?;
        let sensor = Sensor::read(bytes).ok_or(DesignRefused)?;
        if len <= IMAGE_HEADER_LEN {
            return Err(DesignRefused);
        }
        let rest = &bytes[IMAGE_HEADER_LEN..];
        let (stop, at) = if rest.starts_with(&STOP_MAGIC) {
            let stop = StopDesign::read(rest).map_err(|_| DesignRefused)?;
            (
                Some(stop),
                IMAGE_HEADER_LEN + rip_control::stop::STOP_DESIGN_LEN,
            )
        } else {
            (None, IMAGE_HEADER_LEN)
        };
        if len <= at {
            return Err(DesignRefused);
        }
        self.controller
            .load(&self.buf[at..len])
            .map_err(|_| DesignRefused)?;
        let design = self.controller.design();
        let ts = design.ts.to_f64();
        if !(1e-4..=1.0).contains(&ts) {
            return Err(DesignRefused);
        }
        // A step that overruns its period stops the run: a design whose worst step does not
        // fit (an MPC's iteration bound too high for its rate) is refused before it starts.
        design.check_step_budget().map_err(|_| DesignRefused)?;
        self.sensor = sensor;
        self.stop = stop;
        self.loaded = true;
        Ok(())
    }

    fn period_us(&self) -> u32 {
        self.controller()
            .map_or(0, |c| libm::round(c.design().ts.to_f64() * 1e6) as u32)
    }

    fn reset(&mut self, _positions: [i32; 2]) {
        self.step = 0;
        self.stopping = None;
        if self.loaded {
            self.controller.reset();
        }
    }

    fn has_stop(&self) -> bool {
        self.stop_design().is_some()
    }

    fn begin_stop(&mut self, verified: bool, zero: Option<[i32; 2]>) -> bool {
        let period_s = f64::from(self.period_us()) * 1e-6;
        let every = steps_per_stop_period(period_s);
        let sensor = zero.map_or(self.sensor, |z| self.sensor.zeroed_at(z));
        self.stopping = self
            .stop_design()
            .filter(|_| verified && period_s > 0.0)
            .map(|d| Stopping {
                sequence: d.sequence(period_s * f64::from(every), true),
                sensor,
                last: None,
                every,
                steps: 0,
                held: BrakeCommand::Short,
            });
        self.stopping.is_some()
    }

    fn stop_step(&mut self, positions: [i32; 2], now_us: u32) -> Option<BrakeCommand<f64>> {
        let stopping = self.stopping.as_mut()?;
        let [theta, alpha] = stopping.sensor.angles(positions);
        let (theta, alpha) = (R::from_f64(theta), R::from_f64(alpha));
        if stopping.steps % stopping.every == 0 {
            let before = stopping.last.replace((theta, alpha, now_us));
            let (rate, alpha_rate) = sample_rates(before, theta, alpha, now_us);
            match stopping.sequence.step(theta, rate, alpha, alpha_rate) {
                Some(command) => stopping.held = command,
                None => {
                    self.stopping = None;
                    return None;
                }
            }
        }
        stopping.steps = stopping.steps.wrapping_add(1);
        Some(match stopping.held {
            BrakeCommand::Volts(v) => BrakeCommand::Volts(v.to_f64()),
            BrakeCommand::Short => BrakeCommand::Short,
        })
    }

    fn step(&mut self, positions: [i32; 2]) -> f64 {
        self.step_with(positions, |_| {})
    }

    fn step_probed(&mut self, positions: [i32; 2], probe: &mut dyn FnMut(u8)) -> f64 {
        self.step_with(positions, probe)
    }

    /// The controller's iteration-bound and solver-failure steps ([`Stats`](rip_control::Stats)),
    /// both of which apply its fallback law.
    fn fallbacks(&self) -> u32 {
        self.controller().map_or(0, |c| {
            let s = c.stats();
            s.iteration_limits.saturating_add(s.solver_failures)
        })
    }
}

impl<R: Real, const N: usize> ControlLaw<R, N> {
    fn step_with(&mut self, positions: [i32; 2], mut probe: impl FnMut(u8)) -> f64 {
        let m = self.measurement(self.step, positions);
        self.step = self.step.wrapping_add(1);
        probe(PIL_PHASE_CONVERT);
        match self.loaded.then_some(&mut self.controller) {
            Some(c) => {
                let mv = c.step_probed(m, |p| {
                    probe(match p {
                        Phase::Estimate => PIL_PHASE_ESTIMATE,
                        Phase::Linear => PIL_PHASE_LINEAR,
                        Phase::Qp => PIL_PHASE_QP,
                    })
                });
                self.last = Some(mv);
                mv.voltage.to_f64()
            }
            None => f64::NAN,
        }
    }
}
