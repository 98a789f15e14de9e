//! The loop's logic without I/O or clocks: frame decoding, angle conversion, the safety
//! checks on every measurement, the controller step, clamping, and the command frames, with
//! the hard bound on driving without a measurement.

use std::fmt;

use rip_core::{Controller, Phase, StepStatus, StopCause};

use crate::calibrate::Calibration;
use crate::config::{Config, PendulumZero, MAX_BLIND_MS, MAX_VOLTAGE_LIMIT};
use crate::protocol::{
    encode, Command, Frame, Measurement, Message, Parser, ParserStats, COMMAND_ENABLE, MAX_FRAME,
    STATUS_FAULT,
};
use crate::stop::{next_seq, SetupError, StopReason};
use crate::witness::{Witness, WitnessLimits};

/// Log status bit (above the device's 8 status bits): no measurement arrived this period; the
/// previous command was repeated and the controller, instead of being stepped, was told that
/// the period passed with that command ([`LoopCore::hold`]).
pub const FLAG_NO_REPLY: u32 = 1 << 8;
/// Log status bit: the controller used its fallback (e.g. the MPC solver failed).
pub const FLAG_FALLBACK: u32 = 1 << 9;
/// Log status bit: the command is at `±safety.voltage_limit`, saturated by the controller (LQR and
/// LQG saturate, the MPC bounds its moves, at that limit) or clamped by the loop.
pub const FLAG_CLAMPED: u32 = 1 << 10;
/// Log status bit: deadlines were missed (skipped) right before this period.
pub const FLAG_DEADLINE_MISS: u32 = 1 << 11;

/// What one control step produced (see [`LoopCore::control`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutput {
    /// Measured arm angle (rad).
    pub theta: f64,
    /// Measured pendulum angle (rad from upright).
    pub alpha: f64,
    /// Arm reference (rad).
    pub reference: f64,
    /// Commanded voltage after clamping (V).
    pub voltage: f64,
    /// Device status bits and `FLAG_*` bits.
    pub flags: u32,
    /// Bytes of the encoded command frame.
    pub len: usize,
    /// The controller's phase after the step: [`Phase::Balance`] for a balance controller;
    /// a swing-up supervisor reports [`Phase::SwingUp`] until its catch.
    pub phase: Phase,
}

/// The loop's logic without I/O or clocks: frame decoding, angle conversion, safety checks,
/// the controller step, clamping and command encoding. Allocation-free after construction.
pub struct LoopCore {
    controller: Box<dyn Controller>,
    parser: Parser,
    arm_rad_per_count: f64,
    pendulum_rad_per_count: f64,
    // Subtracted from the scaled counts: θ = 0 and α = 0 (upright).
    arm_offset: f64,
    pendulum_offset: f64,
    pendulum_limit: f64,
    arm_limit: f64,
    start_tolerance: f64,
    voltage_limit: f64,
    step_height: f64,
    step_time: f64,
    // Where, on the loop's time axis, the reference's own time starts (the step comes
    // `step_time` after it): 0 for a balancing run, the catch for a swing-up (+∞ before).
    reference_origin: f64,
    // The controller supervises a swing-up: it owns the pendulum-angle rule (module docs).
    supervised: bool,
    balance_angle: f64,
    swing_arm_limit: f64,
    max_swing_s: f64,
    y: [f64; 2],
    r: [f64; 2],
    u: [f64; 1],
    last_command: Command,
    // Periods since the last command computed from a measurement, and the most of them an
    // enabling command may be repeated for.
    blind_periods: u32,
    blind_limit: u32,
    // The model's check that the rig moves as commanded (crate::witness); `None` for
    // open-loop drives and controllers without the pendulum's model.
    witness: Option<Witness>,
    // The previous measurement's device clock (µs) and the voltage it reported applied.
    last_sample: Option<(u32, f64)>,
    // Request to reply (s) of the latest exchange: about when the command reaches the device.
    latency_s: f64,
    // `safety.arm_limit` for the arm's stopping point (crate::envelope).
    envelope: crate::envelope::ArmEnvelope,
}

impl fmt::Debug for LoopCore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LoopCore")
            .field("y", &self.y)
            .field("u", &self.u)
            .finish_non_exhaustive()
    }
}

fn wrap_angle(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let w = a - tau * (a / tau).round();
    if w <= -std::f64::consts::PI {
        w + tau
    } else {
        w
    }
}

impl LoopCore {
    /// Wraps `controller` (2 outputs: arm, pendulum angle; 1 input: voltage) with the settings
    /// of `cfg`.
    ///
    /// The hard bounds of the loop hold whatever `cfg` says (it may not have been validated):
    /// commands never exceed [`MAX_VOLTAGE_LIMIT`], and an enabling command is repeated
    /// without a new measurement for at most [`MAX_BLIND_MS`] (see [`encode_held`]).
    ///
    /// [`encode_held`]: Self::encode_held
    pub fn new(controller: Box<dyn Controller>, cfg: &Config) -> Result<Self, SetupError> {
        if controller.n_outputs() != 2 || controller.n_inputs() != 1 {
            return Err(SetupError::ControllerShape {
                outputs: controller.n_outputs(),
                inputs: controller.n_inputs(),
            });
        }
        // At least one period: the command of a step is always sent once.
        let blind_limit = if cfg.loop_.period_ms > 0.0 {
            (MAX_BLIND_MS / cfg.loop_.period_ms).floor().clamp(1.0, 1e3) as u32
        } else {
            1
        };
        let tau = std::f64::consts::TAU;
        let d = &cfg.device;
        // Only a controller that itself starts in the swing-up (rip-core's supervisor) is
        // trusted with the pendulum's fall rule.
        let supervised = controller.phase() == Phase::SwingUp;
        Ok(Self {
            controller,
            parser: Parser::new(),
            arm_rad_per_count: d.arm_sign * tau / d.arm_counts_per_rev as f64,
            pendulum_rad_per_count: d.pendulum_sign * tau / d.pendulum_counts_per_rev as f64,
            arm_offset: 0.0,
            pendulum_offset: match d.pendulum_zero {
                PendulumZero::Down => std::f64::consts::PI,
                PendulumZero::Up => 0.0,
            },
            pendulum_limit: cfg.safety.pendulum_limit,
            arm_limit: cfg.safety.arm_limit,
            start_tolerance: cfg.safety.start_tolerance,
            voltage_limit: cfg.safety.voltage_limit.clamp(0.0, MAX_VOLTAGE_LIMIT),
            step_height: cfg.spec.reference.arm_step,
            step_time: cfg.spec.reference.step_time,
            reference_origin: if supervised { f64::INFINITY } else { 0.0 },
            supervised,
            balance_angle: cfg.spec.swing_up.balance_angle,
            swing_arm_limit: cfg.spec.swing_up.arm_limit,
            max_swing_s: cfg.spec.swing_up.max_time,
            y: [0.0; 2],
            r: [0.0; 2],
            u: [0.0],
            last_command: Command::STOP,
            blind_periods: 0,
            blind_limit,
            witness: Witness::new(cfg, WitnessLimits::default()).ok(),
            last_sample: None,
            latency_s: 0.0,
            envelope: crate::envelope::ArmEnvelope::new(cfg),
        })
    }

    /// The parser's counters.
    pub fn parser_stats(&self) -> ParserStats {
        self.parser.stats()
    }

    /// The controller's state estimate, if it has one.
    pub fn state_estimate(&self) -> Option<&[f64]> {
        self.controller.state_estimate()
    }

    /// Restarts the controller (estimator, previous input) and forgets any partial frame.
    pub fn reset(&mut self) {
        self.controller.reset();
        self.u = [0.0];
        self.last_command = Command::STOP;
        self.blind_periods = 0;
        self.envelope.reset();
        if let Some(w) = self.witness.as_mut() {
            w.reset();
        }
        self.last_sample = None;
    }

    /// Notes the request-to-reply time of the latest exchange (ns): the witness takes the
    /// next command to reach the device about that long after the sample.
    pub fn note_latency(&mut self, ns: u64) {
        self.latency_s = ns as f64 * 1e-9;
    }

    /// Turns the witness off (open-loop drives, tests of other rules).
    pub fn without_witness(mut self) -> Self {
        self.witness = None;
        self
    }

    /// The witness's largest statistics so far ([`Witness::peak`]).
    pub fn witness_peak(&self) -> Option<[f64; 3]> {
        self.witness.as_ref().map(Witness::peak)
    }

    /// The voltage the device applies under the last command: its value when the driver is
    /// enabled, else 0 V.
    pub fn held_voltage(&self) -> f64 {
        if self.last_command.enabled() {
            f64::from(self.last_command.voltage_mv) / 1000.0
        } else {
            0.0
        }
    }

    /// A period without a measurement, in which the device keeps applying the last command:
    /// passes its voltage to [`Controller::hold`], so that rate filters and estimators account
    /// for the period (and for the input actually applied, after clamping and rounding to mV)
    /// before the next step. Returns that voltage.
    pub fn hold(&mut self) -> f64 {
        let held = [self.held_voltage()];
        self.controller.hold(&held);
        held[0]
    }

    /// Encodes a sample request; returns its sequence number and length.
    pub fn encode_request(&mut self, out: &mut [u8; MAX_FRAME]) -> (u16, usize) {
        let seq = next_seq();
        let n = encode(
            &Frame {
                seq,
                message: Message::SampleRequest,
            },
            out,
        );
        (seq, n)
    }

    /// A period without a measurement: encodes the last command again, so that the device's
    /// command watchdog stays fed with what it already applies. Refuses (without encoding) once
    /// the last enabling command is [`MAX_BLIND_MS`] (at least one period) old, whatever the
    /// configured watchdog: the loop never drives longer than that on a stale measurement.
    pub fn encode_held(&mut self, out: &mut [u8; MAX_FRAME]) -> Result<usize, StopReason> {
        self.blind_periods = self.blind_periods.saturating_add(1);
        if self.last_command.enabled() && self.blind_periods > self.blind_limit {
            return Err(StopReason::Watchdog(self.blind_periods));
        }
        Ok(self.encode_repeat(out))
    }

    /// Encodes the last command again.
    fn encode_repeat(&mut self, out: &mut [u8; MAX_FRAME]) -> usize {
        encode(
            &Frame {
                seq: next_seq(),
                message: Message::Command(self.last_command),
            },
            out,
        )
    }

    /// Encodes the stop command and makes it the last command.
    pub fn encode_stop(&mut self, out: &mut [u8; MAX_FRAME]) -> usize {
        self.last_command = Command::STOP;
        self.encode_repeat(out)
    }

    /// Feeds received bytes to the parser; returns the newest measurement answering `seq`.
    /// Anything else (stale answers, host-type frames echoed back) is ignored.
    pub fn receive(&mut self, bytes: &[u8], seq: u16) -> Option<Measurement> {
        let mut found = None;
        self.parser.feed(bytes, |frame| {
            if let Message::Measurement(m) = frame.message {
                if m.ack_seq == seq {
                    found = Some(m);
                }
            }
        });
        found
    }

    /// Takes the encoder zeros from `cal` (a rest window hanging down, [`crate::calibrate`])
    /// instead of `[device]`: the arm's rest count is θ = 0, the pendulum's is α = π.
    pub fn calibrate(&mut self, cal: &Calibration) {
        self.arm_offset = cal.arm_zero_counts * self.arm_rad_per_count;
        self.pendulum_offset =
            cal.pendulum_hanging_counts * self.pendulum_rad_per_count - std::f64::consts::PI;
    }

    /// Arm and pendulum angles (rad; pendulum wrapped to (−π, π], 0 upright) of a measurement.
    pub fn angles(&self, m: &Measurement) -> (f64, f64) {
        let theta = m.arm_counts as f64 * self.arm_rad_per_count - self.arm_offset;
        let alpha = wrap_angle(
            m.pendulum_counts as f64 * self.pendulum_rad_per_count - self.pendulum_offset,
        );
        (theta, alpha)
    }

    /// `Ok` when the pendulum is close enough to upright (and the arm inside its limit) to
    /// start balancing.
    pub fn check_start(&self, m: &Measurement) -> Result<(), StopReason> {
        let (theta, alpha) = self.angles(m);
        if alpha.abs() > self.start_tolerance {
            return Err(StopReason::NotUpright {
                angle: alpha,
                tolerance: self.start_tolerance,
            });
        }
        if theta.abs() > self.arm_limit {
            return Err(StopReason::AngleLimit {
                which: "arm",
                angle: theta,
                limit: self.arm_limit,
            });
        }
        Ok(())
    }

    /// Whether the controller supervises a swing-up (it started in [`Phase::SwingUp`]): the
    /// pendulum-angle limit is then its balance region's, applied by it after the catch.
    pub fn supervises_swing_up(&self) -> bool {
        self.supervised
    }

    /// The controller's phase.
    pub fn phase(&self) -> Phase {
        self.controller.phase()
    }

    /// Starts the reference's clock at `t` (the catch of a swing-up): the arm step comes
    /// `reference.step_time` later. Before it (a swing-up that has not caught, or
    /// `t = +∞` after a fall) the reference is 0.
    pub fn start_reference_at(&mut self, t: f64) {
        self.reference_origin = t;
    }

    /// The arm reference at `t` seconds on the loop's time axis (from the start of balancing;
    /// from the start of the swing for a swing-up, whose reference starts at the catch).
    pub fn reference_at(&self, t: f64) -> f64 {
        if t - self.reference_origin >= self.step_time {
            self.step_height
        } else {
            0.0
        }
    }

    /// One control step on measurement `m` at `t` seconds after balancing started: checks the
    /// device status and the angle limits, steps the controller, clamps the voltage and encodes
    /// the enabling command into `out`. A failed check returns the stop reason and encodes
    /// nothing.
    pub fn control(
        &mut self,
        m: &Measurement,
        t: f64,
        out: &mut [u8; MAX_FRAME],
    ) -> Result<StepOutput, StopReason> {
        if m.status & STATUS_FAULT != 0 {
            return Err(StopReason::DeviceFault(m.status));
        }
        let (theta, alpha) = self.angles(m);
        // A hanging or swinging pendulum is no fall during a swing-up, and after its catch the
        // supervisor's balance region decides (retry or stop, below).
        if !self.supervised && alpha.abs() > self.pendulum_limit {
            return Err(StopReason::AngleLimit {
                which: "pendulum",
                angle: alpha,
                limit: self.pendulum_limit,
            });
        }
        if theta.abs() > self.arm_limit {
            return Err(StopReason::AngleLimit {
                which: "arm",
                angle: theta,
                limit: self.arm_limit,
            });
        }
        // Since the previous sample (on the device's clock, so skipped periods and late
        // wake-ups count as they were) the device applied what it reported then, until the
        // last command arrived.
        let reported = f64::from(m.applied_mv) / 1000.0;
        let previous = self.last_sample.replace((m.device_time_us, reported));
        let commanded = self.held_voltage();
        if let Some(w) = self.witness.as_mut() {
            let (dt, before) = previous.map_or((0.0, 0.0), |(us, v)| {
                (f64::from(m.device_time_us.wrapping_sub(us)) * 1e-6, v)
            });
            let volts = (before, commanded);
            w.observe(theta, alpha, volts, dt, self.latency_s)
                .map_err(StopReason::Witness)?;
        }
        self.envelope
            .check(theta, m.device_time_us, m.applied_mv as f64 * 1e-3)?;
        let reference = self.reference_at(t);
        self.y = [theta, alpha];
        self.r = [reference, 0.0];
        let status = self.controller.step(&self.y, &self.r, &mut self.u);
        let phase = self.controller.phase();
        if let Phase::Stopped(cause) = phase {
            return Err(match cause {
                StopCause::SwingUpTimeout => StopReason::SwingUpFailed {
                    max_time: self.max_swing_s,
                    report: self.controller.swing_up_report(),
                },
                // The balance region bounds both joints: name the one that left it (the arm
                // when it is past its bound, else the pendulum).
                StopCause::LeftBalanceRegion if theta.abs() > self.swing_arm_limit => {
                    StopReason::Fell {
                        part: "arm",
                        key: "swing_up.arm_limit",
                        angle: theta,
                        limit: self.swing_arm_limit,
                    }
                }
                StopCause::LeftBalanceRegion => StopReason::Fell {
                    part: "pendulum",
                    key: "swing_up.balance_angle",
                    angle: alpha,
                    limit: self.balance_angle,
                },
            });
        }
        let mut flags = m.status as u32;
        if status == StepStatus::Fallback {
            flags |= FLAG_FALLBACK;
        }
        let raw = self.u[0];
        if !raw.is_finite() {
            return Err(StopReason::ControllerFault { voltage: raw, t });
        }
        let voltage = raw.clamp(-self.voltage_limit, self.voltage_limit);
        // LQR/LQG saturate and the MPC bounds its moves at the same limit, so a saturated
        // command usually arrives already at the limit rather than beyond it.
        if voltage.abs() >= self.voltage_limit {
            flags |= FLAG_CLAMPED;
        }
        self.last_command = Command {
            voltage_mv: (voltage * 1000.0).round() as i16,
            flags: COMMAND_ENABLE,
        };
        self.blind_periods = 0;
        let len = self.encode_repeat(out);
        Ok(StepOutput {
            theta,
            alpha,
            reference,
            voltage,
            flags,
            len,
            phase,
        })
    }

    /// Steps the controller on a synthetic output `y` with reference `r`, for timing it before
    /// the motor is enabled; encodes nothing. Call [`reset`](Self::reset) afterwards.
    pub fn probe_step(&mut self, y: [f64; 2], r: [f64; 2]) -> f64 {
        self.y = y;
        self.r = r;
        self.controller.step(&self.y, &self.r, &mut self.u);
        self.u[0]
    }

    /// A loop core for open-loop runs (`rip-rt excite`): no controller; its enabling
    /// commands come from [`drive`](Self::drive), with the same hard bounds as
    /// [`new`](Self::new)'s.
    pub fn open_loop(cfg: &Config) -> Self {
        Self::new(Box::new(OpenLoop), cfg)
            .expect("OpenLoop has the pendulum's shape")
            .without_witness()
    }

    /// One open-loop command on measurement `m` at `t` seconds: checks the device status and
    /// the arm limit (not the pendulum's: an open-loop run starts hanging, where it swings
    /// freely), refuses a non-finite `voltage`, clamps it to `±safety.voltage_limit` and
    /// encodes the enabling command into `out`. A failed check returns the stop reason and
    /// encodes nothing.
    pub fn drive(
        &mut self,
        m: &Measurement,
        voltage: f64,
        t: f64,
        out: &mut [u8; MAX_FRAME],
    ) -> Result<StepOutput, StopReason> {
        if m.status & STATUS_FAULT != 0 {
            return Err(StopReason::DeviceFault(m.status));
        }
        let (theta, alpha) = self.angles(m);
        if theta.abs() > self.arm_limit {
            return Err(StopReason::AngleLimit {
                which: "arm",
                angle: theta,
                limit: self.arm_limit,
            });
        }
        self.envelope
            .check(theta, m.device_time_us, m.applied_mv as f64 * 1e-3)?;
        if !voltage.is_finite() {
            return Err(StopReason::ControllerFault { voltage, t });
        }
        let clamped = voltage.clamp(-self.voltage_limit, self.voltage_limit);
        let mut flags = m.status as u32;
        if clamped.abs() >= self.voltage_limit {
            flags |= FLAG_CLAMPED;
        }
        self.last_command = Command {
            voltage_mv: (clamped * 1000.0).round() as i16,
            flags: COMMAND_ENABLE,
        };
        self.blind_periods = 0;
        let len = self.encode_repeat(out);
        Ok(StepOutput {
            theta,
            alpha,
            reference: 0.0,
            voltage: clamped,
            flags,
            len,
            phase: self.controller.phase(),
        })
    }

    /// One loop iteration without I/O: decodes `rx`, and for a measurement answering `seq`
    /// runs [`control`](Self::control). `Ok(None)` when no such measurement was in `rx`.
    pub fn iterate(
        &mut self,
        rx: &[u8],
        seq: u16,
        t: f64,
        out: &mut [u8; MAX_FRAME],
    ) -> Result<Option<StepOutput>, StopReason> {
        match self.receive(rx, seq) {
            Some(m) => self.control(&m, t, out).map(Some),
            None => Ok(None),
        }
    }
}

/// The controller of an open-loop core: never stepped (commands come from
/// [`LoopCore::drive`]); 0 V if it were.
struct OpenLoop;

impl Controller for OpenLoop {
    fn n_outputs(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn step(&mut self, _y: &[f64], _r: &[f64], u: &mut [f64]) -> StepStatus {
        u[0] = 0.0;
        StepStatus::Nominal
    }
    fn reset(&mut self) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::Parser;
    use crate::stop::exit_code;

    /// A controller whose output is a fixed function of y, to check the plumbing.
    struct Affine {
        gain: f64,
    }

    impl Controller for Affine {
        fn n_outputs(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
            u[0] = self.gain * (r[0] - y[0]) + 100.0 * y[1];
            StepStatus::Nominal
        }
        fn reset(&mut self) {}
    }

    /// Records what the loop tells it about held periods.
    struct Recorder {
        held: std::sync::Arc<std::sync::Mutex<Vec<f64>>>,
    }

    impl Controller for Recorder {
        fn n_outputs(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn step(&mut self, _y: &[f64], _r: &[f64], u: &mut [f64]) -> StepStatus {
            u[0] = 3.21049;
            StepStatus::Nominal
        }
        fn hold(&mut self, u: &[f64]) {
            self.held.lock().unwrap().push(u[0]);
        }
        fn reset(&mut self) {}
    }

    fn core(gain: f64) -> LoopCore {
        LoopCore::new(Box::new(Affine { gain }), &Config::default()).unwrap()
    }

    fn measurement(ack: u16, arm: i32, pend: i32) -> Measurement {
        Measurement {
            ack_seq: ack,
            arm_counts: arm,
            pendulum_counts: pend,
            ..Default::default()
        }
    }

    fn decode_one(bytes: &[u8]) -> Frame {
        let mut p = Parser::new();
        let mut out = None;
        p.feed(bytes, |f| out = Some(f));
        out.expect("one frame")
    }

    #[test]
    fn hold_passes_the_command_the_device_applies() {
        let held = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let rec = Recorder { held: held.clone() };
        let mut c = LoopCore::new(Box::new(rec), &Config::default()).unwrap();
        let mut out = [0u8; MAX_FRAME];
        // Before any command the driver is disabled: 0 V.
        assert_eq!(c.hold(), 0.0);
        c.control(&measurement(1, 0, 1024), 0.0, &mut out).unwrap();
        // The command is rounded to millivolts; the controller hears the rounded value.
        assert_eq!(c.hold(), 3.21);
        c.encode_stop(&mut out);
        assert_eq!(c.hold(), 0.0);
        assert_eq!(*held.lock().unwrap(), vec![0.0, 3.21, 0.0]);
    }

    #[test]
    fn counts_map_to_angles_with_upright_zero() {
        let c = core(1.0);
        // 2048 counts/rev; pendulum zero hanging down: 1024 counts = upright.
        let (theta, alpha) = c.angles(&measurement(0, 512, 1024));
        assert!((theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(alpha.abs() < 1e-12);
        let (_, alpha) = c.angles(&measurement(0, 0, 1024 + 2048 * 3 + 10));
        assert!((alpha - 10.0 * std::f64::consts::TAU / 2048.0).abs() < 1e-9);
        let (_, alpha) = c.angles(&measurement(0, 0, 0));
        assert!((alpha - std::f64::consts::PI).abs() < 1e-12);
    }

    /// A stand-in for the swing-up supervisor: starts swinging, and its phase after each step is
    /// the next of `script`.
    struct Scripted {
        phase: Phase,
        script: Vec<Phase>,
    }

    impl Controller for Scripted {
        fn n_outputs(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn step(&mut self, _y: &[f64], _r: &[f64], u: &mut [f64]) -> StepStatus {
            if !self.script.is_empty() {
                self.phase = self.script.remove(0);
            }
            u[0] = 2.0;
            StepStatus::Nominal
        }
        fn phase(&self) -> Phase {
            self.phase
        }
        fn reset(&mut self) {}
    }

    fn supervised(script: Vec<Phase>) -> LoopCore {
        let c = Scripted {
            phase: Phase::SwingUp,
            script,
        };
        // Scripted measurements no plant makes: the witness would stop them.
        LoopCore::new(Box::new(c), &Config::default())
            .unwrap()
            .without_witness()
    }

    #[test]
    fn a_swing_up_owns_the_pendulum_rule_but_not_the_arm_limit() {
        let mut c = supervised(vec![Phase::SwingUp, Phase::Balance]);
        assert!(c.supervises_swing_up());
        assert!(!core(1.0).supervises_swing_up());
        let mut out = [0u8; MAX_FRAME];
        // Hanging (0 counts, α = π): no fall while swinging; the command goes out.
        let s = c.control(&measurement(1, 0, 0), 0.0, &mut out).unwrap();
        assert_eq!((s.voltage, s.phase), (2.0, Phase::SwingUp));
        // Nor after the catch: 0.7 rad is past safety.pendulum_limit (0.6), and it is the
        // supervisor's balance region that decides.
        let pend = 1024 + (0.7 / std::f64::consts::TAU * 2048.0) as i32;
        let s = c.control(&measurement(2, 0, pend), 0.01, &mut out).unwrap();
        assert_eq!(s.phase, Phase::Balance);
        // The arm limit (3 rad) stays a stop.
        let e = c
            .control(&measurement(3, 1000, 0), 0.02, &mut out)
            .unwrap_err();
        assert!(
            matches!(e, StopReason::AngleLimit { which: "arm", .. }),
            "{e}"
        );
    }

    #[test]
    fn a_supervisor_that_gives_up_stops_the_loop_without_a_command() {
        for (cause, code) in [
            (StopCause::SwingUpTimeout, exit_code::SWING_UP_FAILED),
            (StopCause::LeftBalanceRegion, exit_code::ANGLE_LIMIT),
        ] {
            let mut c = supervised(vec![Phase::SwingUp, Phase::Stopped(cause)]);
            let mut out = [0u8; MAX_FRAME];
            c.control(&measurement(1, 0, 0), 0.0, &mut out).unwrap();
            assert_eq!(c.held_voltage(), 2.0);
            out.fill(0);
            let e = c
                .control(&measurement(2, 0, 0), 0.01, &mut out)
                .unwrap_err();
            assert_eq!(e.exit_code(), code, "{e}");
            assert!(e.to_string().contains("swing_up."), "{e}");
            // Nothing encoded; the loop's stop guard sends the stop frame.
            assert!(out.iter().all(|&b| b == 0));
        }
    }

    #[test]
    fn a_fall_names_the_part_that_left_the_balance_region() {
        let fell = |arm: i32, pend: i32| {
            let mut c = supervised(vec![
                Phase::Balance,
                Phase::Stopped(StopCause::LeftBalanceRegion),
            ]);
            let mut out = [0u8; MAX_FRAME];
            c.control(&measurement(1, 0, 1024), 0.0, &mut out).unwrap();
            c.control(&measurement(2, arm, pend), 0.01, &mut out)
                .unwrap_err()
        };
        // The arm at 1.53 rad (500 counts) is past swing_up.arm_limit (1.5 rad) while the
        // pendulum (0.3 rad) is well inside swing_up.balance_angle (0.6 rad).
        let pend = 1024 + (0.3 / std::f64::consts::TAU * 2048.0) as i32;
        let e = fell(500, pend);
        assert_eq!(e.exit_code(), exit_code::ANGLE_LIMIT);
        let text = e.to_string();
        assert!(
            text.contains("arm") && text.contains("swing_up.arm_limit"),
            "{text}"
        );
        assert!(!text.contains("balance_angle"), "{text}");
        // The pendulum at 0.7 rad with the arm at 0: the pendulum's bound.
        let pend = 1024 + (0.7 / std::f64::consts::TAU * 2048.0) as i32;
        let text = fell(0, pend).to_string();
        assert!(
            text.contains("pendulum") && text.contains("swing_up.balance_angle"),
            "{text}"
        );
        assert!(!text.contains("arm_limit"), "{text}");
    }

    #[test]
    fn a_swing_ups_reference_starts_at_the_catch() {
        let mut c = supervised(vec![]);
        // Before the catch the arm reference is 0 however long the swing takes.
        assert_eq!(c.reference_at(100.0), 0.0);
        c.start_reference_at(4.0);
        // The step (1 rad) comes reference.step_time (1 s) after the catch.
        assert_eq!(c.reference_at(4.99), 0.0);
        assert_eq!(c.reference_at(5.0), 1.0);
        // A balancing run's reference starts with it.
        assert_eq!(core(1.0).reference_at(1.0), 1.0);
    }

    #[test]
    fn calibration_moves_both_zeros() {
        let mut c = core(1.0);
        let cal = Calibration {
            arm_zero_counts: 100.0,
            pendulum_hanging_counts: -7.5,
            pendulum_offset: 0.0,
            spread_counts: [0, 0],
            max_rates: [0.0, 0.0],
            after_s: 1.0,
        };
        c.calibrate(&cal);
        let count = std::f64::consts::TAU / 2048.0;
        // The rest pose reads θ = 0, α = π (hanging); half a turn on is upright.
        let (theta, alpha) = c.angles(&measurement(0, 100, -7));
        assert!(theta.abs() < 1e-12);
        assert!((alpha.abs() - (std::f64::consts::PI - 0.5 * count)).abs() < 1e-12);
        let (theta, alpha) = c.angles(&measurement(0, 612, -7 + 1024));
        assert!((theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((alpha - 0.5 * count).abs() < 1e-12);
    }

    #[test]
    fn control_encodes_clamped_enabling_command() {
        let mut c = core(-100.0);
        let mut out = [0u8; MAX_FRAME];
        // theta = π/2 > step 0, so u = -100·(0 − π/2) = 157 V → clamped to 12 V.
        let s = c
            .control(&measurement(3, 512, 1024), 0.0, &mut out)
            .unwrap();
        assert_eq!(s.voltage, 12.0);
        assert!(s.flags & FLAG_CLAMPED != 0);
        match decode_one(&out[..s.len]).message {
            Message::Command(cmd) => {
                assert_eq!(cmd.voltage_mv, 12000);
                assert!(cmd.enabled());
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn limits_and_faults_stop_without_a_command() {
        let mut c = core(1.0);
        let mut out = [0u8; MAX_FRAME];
        // Pendulum 0.7 rad from upright > 0.6 limit.
        let pend = 1024 + (0.7 / std::f64::consts::TAU * 2048.0) as i32;
        let e = c
            .control(&measurement(0, 0, pend), 0.0, &mut out)
            .unwrap_err();
        assert!(
            matches!(
                e,
                StopReason::AngleLimit {
                    which: "pendulum",
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(e.exit_code(), exit_code::ANGLE_LIMIT);
        let e = c
            .control(&measurement(0, 1100, 1024), 0.0, &mut out)
            .unwrap_err();
        assert!(
            matches!(e, StopReason::AngleLimit { which: "arm", .. }),
            "{e}"
        );
        let mut m = measurement(0, 0, 1024);
        m.status = STATUS_FAULT;
        let e = c.control(&m, 0.0, &mut out).unwrap_err();
        assert_eq!(e.exit_code(), exit_code::DEVICE_FAULT);
    }

    #[test]
    fn start_requires_upright() {
        let c = core(1.0);
        assert!(c.check_start(&measurement(0, 0, 1030)).is_ok());
        let e = c.check_start(&measurement(0, 0, 0)).unwrap_err();
        assert_eq!(e.exit_code(), exit_code::NOT_UPRIGHT);
        assert!(e.to_string().contains("refusing"), "{e}");
    }

    #[test]
    fn non_finite_output_is_a_controller_fault() {
        let mut c = core(f64::NAN);
        let mut out = [0u8; MAX_FRAME];
        let e = c
            .control(&measurement(0, 0, 1024), 0.0, &mut out)
            .unwrap_err();
        assert_eq!(e.exit_code(), exit_code::CONTROLLER_FAULT);
    }

    #[test]
    fn a_held_command_goes_stale_whatever_the_watchdog() {
        // A configuration that was never validated: a watchdog of u32::MAX periods.
        let mut cfg = Config::default();
        cfg.loop_.watchdog_periods = u32::MAX;
        let mut c = LoopCore::new(Box::new(Affine { gain: 1.0 }), &cfg).unwrap();
        let mut out = [0u8; MAX_FRAME];
        c.control(&measurement(1, 0, 1024), 0.0, &mut out).unwrap();
        // 100 ms at 10 ms: ten repeats of the enabling command, then no more.
        for k in 1..=10 {
            let n = c.encode_held(&mut out).unwrap();
            match decode_one(&out[..n]).message {
                Message::Command(cmd) => assert!(cmd.enabled(), "repeat {k}"),
                other => panic!("{other:?}"),
            }
        }
        let e = c.encode_held(&mut out).unwrap_err();
        assert_eq!(e.exit_code(), crate::stop::exit_code::WATCHDOG, "{e}");
        // A fresh measurement starts the count again.
        c.control(&measurement(2, 0, 1024), 0.01, &mut out).unwrap();
        assert!(c.encode_held(&mut out).is_ok());
        // The stop command may be repeated for ever.
        c.encode_stop(&mut out);
        for _ in 0..100 {
            c.encode_held(&mut out).unwrap();
        }
    }

    #[test]
    fn an_unvalidated_voltage_limit_is_capped() {
        let mut cfg = Config::default();
        cfg.safety.voltage_limit = 1e9;
        let mut c = LoopCore::new(Box::new(Affine { gain: -1e6 }), &cfg).unwrap();
        let mut out = [0u8; MAX_FRAME];
        let s = c
            .control(&measurement(3, 512, 1024), 0.0, &mut out)
            .unwrap();
        assert_eq!(s.voltage, MAX_VOLTAGE_LIMIT);
    }

    #[test]
    fn drive_checks_the_arm_but_not_the_hanging_pendulum() {
        let mut c = LoopCore::open_loop(&Config::default());
        let mut out = [0u8; MAX_FRAME];
        // Hanging down (0 counts): far outside the pendulum limit, which does not apply.
        let s = c.drive(&measurement(1, 0, 0), 30.0, 0.0, &mut out).unwrap();
        assert_eq!(s.voltage, 12.0);
        assert!(s.flags & FLAG_CLAMPED != 0);
        match decode_one(&out[..s.len]).message {
            Message::Command(cmd) => assert_eq!((cmd.voltage_mv, cmd.enabled()), (12000, true)),
            other => panic!("{other:?}"),
        }
        let e = c
            .drive(&measurement(2, 1100, 0), 1.0, 0.0, &mut out)
            .unwrap_err();
        assert!(
            matches!(e, StopReason::AngleLimit { which: "arm", .. }),
            "{e}"
        );
        let e = c
            .drive(&measurement(3, 0, 0), f64::NAN, 0.0, &mut out)
            .unwrap_err();
        assert_eq!(e.exit_code(), exit_code::CONTROLLER_FAULT);
        let mut m = measurement(4, 0, 0);
        m.status = STATUS_FAULT;
        let e = c.drive(&m, 1.0, 0.0, &mut out).unwrap_err();
        assert_eq!(e.exit_code(), exit_code::DEVICE_FAULT);
    }

    #[test]
    fn receive_ignores_stale_answers() {
        let mut c = core(1.0);
        let mut bytes = Vec::new();
        let mut buf = [0u8; MAX_FRAME];
        for ack in [4u16, 5] {
            let n = encode(
                &Frame {
                    seq: 0,
                    message: Message::Measurement(measurement(ack, ack as i32, 1024)),
                },
                &mut buf,
            );
            bytes.extend_from_slice(&buf[..n]);
        }
        assert_eq!(c.receive(&bytes, 4).map(|m| m.arm_counts), Some(4));
        assert_eq!(c.receive(&bytes, 9), None);
    }
}
