//! The loop's logic without I/O or clocks: frame decoding, angle conversion, the safety
//! checks on every measurement, the controller step, clamping, and the command frames, with
//! the hard bound on driving without a measurement.

use std::fmt;

use rip_core::{Controller, Phase, StepStatus, StopCause};

use crate::config::{Config, PendulumZero, MAX_BLIND_MS, MAX_VOLTAGE_LIMIT};
use crate::protocol::{
    encode, Command, Frame, Measurement, Message, Parser, ParserStats, COMMAND_ENABLE, MAX_FRAME,
    STATUS_FAULT,
};
use crate::rest::Calibration;
use crate::stop::{next_seq, SetupError, StopReason};
use crate::witness::{Witness, WitnessLimits, LATE_S};

pub use crate::step::{StepOutput, FLAG_CLAMPED, FLAG_DEADLINE_MISS, FLAG_FALLBACK, FLAG_NO_REPLY};

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
    // The last command's voltage before the clamp, for the live stream.
    planned: f64,
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
    // Request to reply (s) of the latest exchange; request to command (s) of the last command
    // sent (about when it reached the device after its sample); whether this period woke
    // late or skipped deadlines; whether the loop runs in lockstep (crate::witness, "Timing").
    latency_s: f64,
    sent_s: f64,
    woke_late: bool,
    // When the last sample request was written (host clock, ns) and the interval before it.
    last_request_ns: Option<u64>,
    host_interval_s: Option<f64>,
    lockstep: bool,
    // `safety.arm_limit` for the arm's stopping point (crate::envelope).
    envelope: crate::envelope::ArmEnvelope,
    // The gentle end's law for this rig, designed before the motor is enabled (the search
    // takes tens of milliseconds, too long for the period the run ends in).
    lowering: Option<rip_core::envelope::Lowering>,
    // The stop's parts, designed once for the run (the envelope's simulated stop, and the
    // stop at its end, which would otherwise design them before its first command).
    stop_parts: Option<crate::envelope::StopParts>,
    // The witness's next measurement follows a gap (`witness_restart`).
    witness_gap: bool,
}

impl fmt::Debug for LoopCore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LoopCore")
            .field("y", &self.y)
            .field("u", &self.u)
            .finish_non_exhaustive()
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
        Self::build(controller, cfg, crate::envelope::lowering(cfg))
    }

    /// [`new`](Self::new) with the gentle end's law given (`None`: no lowering).
    fn build(
        controller: Box<dyn Controller>,
        cfg: &Config,
        lowering: Option<rip_core::envelope::Lowering>,
    ) -> Result<Self, SetupError> {
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
        let stop_parts = crate::envelope::stop_parts(cfg);
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
            planned: f64::NAN,
            last_command: Command::STOP,
            blind_periods: 0,
            blind_limit,
            witness: Witness::new(cfg, WitnessLimits::default()).ok(),
            last_sample: None,
            latency_s: 0.0,
            sent_s: 0.0,
            woke_late: false,
            last_request_ns: None,
            host_interval_s: None,
            lockstep: false,
            envelope: crate::envelope::arm_envelope(cfg, stop_parts.as_ref()),
            lowering,
            stop_parts,
            witness_gap: false,
        })
    }

    /// The last measured arm and pendulum angles (rad) the loop judged, if any.
    pub fn last_angles(&self) -> Option<(f64, f64)> {
        self.last_sample.map(|_| (self.y[0], self.y[1]))
    }

    /// The gentle end's law for this rig ([`rip_core::envelope::Lowering`]), if one settles
    /// on its model.
    pub fn lowering(&self) -> Option<&rip_core::envelope::Lowering> {
        self.lowering.as_ref()
    }

    /// The run's stop, designed once ([`crate::envelope::stop_parts`]).
    pub fn stop_parts(&self) -> Option<&crate::envelope::StopParts> {
        self.stop_parts.as_ref()
    }

    /// The parser's counters.
    pub fn parser_stats(&self) -> ParserStats {
        self.parser.stats()
    }

    /// The last enabling command's voltage before the clamp (V): the controller's, or the
    /// open-loop drive's; NaN before the first.
    pub fn planned_voltage(&self) -> f64 {
        self.planned
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

    /// Notes the request-to-reply time of the latest exchange (ns): a slow reply leaves the
    /// period's timing unknown to the witness (crate::witness, "Timing").
    pub fn note_latency(&mut self, ns: u64) {
        self.latency_s = ns as f64 * 1e-9;
    }

    /// Notes this period's timing before its measurement is judged: how late the loop woke
    /// (ns), the deadlines it skipped, and whether it runs in lockstep (the device's plant
    /// waiting for the host, so that timing is always known).
    ///
    /// `request_ns` is when its sample request was written (host clock): the interval between
    /// two requests and the device's between the samples answering them differ when the
    /// device was late to answer (an emulator starved of the CPU catching up on its clock).
    pub fn note_period(&mut self, lateness_ns: u64, skipped: u64, lockstep: bool, request_ns: u64) {
        self.woke_late = skipped > 0 || lateness_ns as f64 * 1e-9 > LATE_S;
        self.lockstep = lockstep;
        self.host_interval_s = self
            .last_request_ns
            .replace(request_ns)
            .map(|before| request_ns.saturating_sub(before) as f64 * 1e-9);
    }

    /// Notes that this period's command was written `ns` after its sample request.
    pub fn note_sent(&mut self, ns: u64) {
        self.sent_s = ns as f64 * 1e-9;
    }

    /// Turns the witness off (open-loop drives, tests of other rules).
    pub fn without_witness(mut self) -> Self {
        self.witness = None;
        self
    }

    /// The witness's estimate of the rig's state ([`Witness::estimate`]).
    pub fn witness_estimate(&self) -> Option<rip_core::plant::State> {
        self.witness.as_ref().and_then(Witness::estimate)
    }

    /// The witness's largest statistics so far ([`Witness::peak`]).
    pub fn witness_peak(&self) -> Option<[f64; 5]> {
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
        let [theta, alpha] = rip_control::stop::angles(
            [m.arm_counts, m.pendulum_counts],
            [self.arm_rad_per_count, self.pendulum_rad_per_count],
            [self.arm_offset, self.pendulum_offset],
        );
        (theta, alpha)
    }

    /// The position rule ([`rip_control::stop::past_limit`]): the run's stop when the arm at
    /// `theta` is past `safety.arm_limit`.
    fn check_arm_limit(&self, theta: f64) -> Result<(), StopReason> {
        if rip_control::stop::past_limit(theta, self.arm_limit) {
            return Err(StopReason::AngleLimit {
                which: "arm",
                angle: theta,
                limit: self.arm_limit,
            });
        }
        Ok(())
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
        self.check_arm_limit(theta)?;
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
        if !self.supervised && rip_control::stop::past_limit(alpha, self.pendulum_limit) {
            return Err(StopReason::AngleLimit {
                which: "pendulum",
                angle: alpha,
                limit: self.pendulum_limit,
            });
        }
        self.check_arm_limit(theta)?;
        let commanded = self.held_voltage();
        self.witness_observe(m, theta, alpha, commanded)?;
        self.envelope
            .check(theta, alpha, m.device_time_us, m.applied_mv as f64 * 1e-3)?;
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
                StopCause::LeftBalanceRegion
                    if rip_control::stop::past_limit(theta, self.swing_arm_limit) =>
                {
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
        self.planned = raw;
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

    /// The witness's judgement of measurement `m` (its angles `theta`, `alpha`) after the
    /// device applied what it reported at the previous sample until `commanded` (V) arrived.
    fn witness_observe(
        &mut self,
        m: &Measurement,
        theta: f64,
        alpha: f64,
        commanded: f64,
    ) -> Result<(), StopReason> {
        // Since the previous sample (on the device's clock, so skipped periods and late
        // wake-ups count as they were) the device applied what it reported then, until the
        // last command arrived.
        let reported = f64::from(m.applied_mv) / 1000.0;
        let previous = self.last_sample.replace((m.device_time_us, reported));
        if let Some(w) = self.witness.as_mut() {
            let (dt, before) = previous.map_or((0.0, 0.0), |(us, v)| {
                (f64::from(m.device_time_us.wrapping_sub(us)) * 1e-6, v)
            });
            let dt = if std::mem::take(&mut self.witness_gap) {
                f64::INFINITY
            } else {
                dt
            };
            let volts = (before, commanded);
            // The last command reached the device about when it was written after its sample
            // (at once in lockstep); a period the loop cannot time is held (crate::witness).
            let delay = if self.lockstep { 0.0 } else { self.sent_s };
            let device_late = self
                .host_interval_s
                .is_some_and(|host| previous.is_some() && (host - dt).abs() > LATE_S);
            if !self.lockstep
                && (self.woke_late
                    || device_late
                    || self.latency_s > LATE_S
                    || self.sent_s > LATE_S)
            {
                w.timing_unknown();
            }
            w.observe(theta, alpha, volts, dt, delay)
                .map_err(StopReason::Witness)?;
        }
        Ok(())
    }

    /// The witness on a period of the gentle end's lowering (`crate::braking`), which drives
    /// the rig as hard as a swing: measurement `m` with its angles `theta`, `alpha`, the
    /// lowering's last command `commanded` (V), against the lowering's thresholds
    /// ([`WitnessLimits::lowering`]). A wrong `arm_counts_per_rev` that balancing never showed,
    /// or an encoder that failed unseen, would otherwise steer the lowering.
    pub fn witness_stop_period(
        &mut self,
        m: &Measurement,
        theta: f64,
        alpha: f64,
        commanded: f64,
    ) -> Result<(), StopReason> {
        if let Some(w) = self.witness.as_mut() {
            let lowering = WitnessLimits::default().lowering();
            if w.limits() != lowering {
                w.set_limits(lowering);
            }
        }
        self.witness_observe(m, theta, alpha, commanded)
    }

    /// Has the witness take its next measurement as one after a gap: the rig moving as it was,
    /// its rates acquired from the measurement after it (`Witness::observe`), as after
    /// periods the stop went without a reply. Restarted at rest instead, the observer of a
    /// lowering swinging the arm at several rad/s tripped on its first prediction.
    pub fn witness_restart(&mut self) {
        self.witness_gap = true;
    }

    /// A loop core for open-loop runs (`rip-rt excite`): no controller; its enabling
    /// commands come from [`drive`](Self::drive), with the same hard bounds as
    /// [`new`](Self::new)'s.
    pub fn open_loop(cfg: &Config) -> Self {
        // No controller balances: nothing to lower at the end (and no law to design).
        Self::build(Box::new(OpenLoop), cfg, None)
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
        self.check_arm_limit(theta)?;
        self.envelope
            .check(theta, alpha, m.device_time_us, m.applied_mv as f64 * 1e-3)?;
        if !voltage.is_finite() {
            return Err(StopReason::ControllerFault { voltage, t });
        }
        self.planned = voltage;
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
mod tests;
