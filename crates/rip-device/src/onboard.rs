//! Onboard mode (protocol v2): the controller interface, the upload state machine, the
//! controller steps and their telemetry (crate docs, "Onboard mode").

// The device's private state and the protocol names it uses.
use super::*;

/// The design image was intact but the controller cannot run it ([`Onboard::load`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DesignRefused;

/// An onboard controller as the device sees it: a buffer for the uploaded design image, and a
/// law from encoder positions to a voltage (module docs, "Onboard mode").
pub trait Onboard {
    /// The buffer the design image is uploaded into; its length is the largest image the
    /// device accepts.
    fn buffer(&mut self) -> &mut [u8];
    /// Loads the image in `buffer()[..len]`, whose length and CRC-32 the device has checked.
    fn load(&mut self, len: usize) -> Result<(), DesignRefused>;
    /// The loaded design's step period, µs (the firmware's timer period).
    fn period_us(&self) -> u32;
    /// Prepares a run from the encoder positions (arm, pendulum) at the start: the estimator's
    /// initial state, no previous move.
    fn reset(&mut self, positions: [i32; 2]);
    /// One step from the encoder positions (arm, pendulum, counts): the move, volts.
    fn step(&mut self, positions: [i32; 2]) -> f64;
    /// [`step`](Self::step), calling `probe(p)` at the end of each part `p` it goes through
    /// (`PIL_PHASE_*`, in increasing order; the last part needs no call). The default marks
    /// none.
    fn step_probed(&mut self, positions: [i32; 2], probe: &mut dyn FnMut(u8)) -> f64 {
        let _ = probe;
        self.step(positions)
    }
    /// Steps since the last [`reset`](Self::reset) that applied the controller's fallback law
    /// (telemetry's `fallbacks`). The default: a law without one, 0.
    fn fallbacks(&self) -> u32 {
        0
    }
    /// Whether the loaded design has a stop of its own to run ([`begin_stop`](Self::begin_stop)
    /// with the wiring verified). The default: none.
    fn has_stop(&self) -> bool {
        false
    }
    /// Begins the device's own stop of the run (`rip_control::stop`, the rule rip-rt runs):
    /// with the wiring `verified`, the braking and hold laws of the law's stop design, on
    /// angles zeroed at `zero` (arm count at θ = 0, pendulum count hanging) where given
    /// (host mode's [`WatchdogStop`](rip_protocol::WatchdogStop)), else the design's own;
    /// whether there is such a stop to run (otherwise the device shorts the windings at once).
    /// The default: none.
    fn begin_stop(&mut self, verified: bool, zero: Option<[i32; 2]>) -> bool {
        let _ = (verified, zero);
        false
    }
    /// One period of that stop on the positions sampled at the device's clock `now_us`: the
    /// command, or `None` once the stop is done (or none runs).
    fn stop_step(&mut self, positions: [i32; 2], now_us: u32) -> Option<BrakeCommand<f64>> {
        let _ = (positions, now_us);
        None
    }
}

/// The device without an onboard controller (the v1 device): every upload is refused as too
/// large, and onboard mode cannot start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NoOnboard;

impl Onboard for NoOnboard {
    fn buffer(&mut self) -> &mut [u8] {
        &mut []
    }
    fn load(&mut self, _len: usize) -> Result<(), DesignRefused> {
        Err(DesignRefused)
    }
    fn period_us(&self) -> u32 {
        0
    }
    fn reset(&mut self, _positions: [i32; 2]) {}
    fn step(&mut self, _positions: [i32; 2]) -> f64 {
        0.0
    }
}

/// An upload in progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Upload {
    pub(crate) total: u32,
    pub(crate) next: u32,
}

/// An onboard run in progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Run {
    pub(crate) settings: OnboardStart,
    // Device time at which the next step is due (used by `onboard_tick`).
    pub(crate) due_us: u32,
    pub(crate) step: u32,
    pub(crate) last_host_us: u32,
    pub(crate) last_cycles: u32,
    pub(crate) overruns: u16,
    /// The device's own stop in progress (crate docs): the state the run
    /// stopped with, and the periods the stop has run.
    pub(crate) stopping: Option<(u8, u32)>,
    /// A driver fault was read since the run's last step, even if it has cleared since (a
    /// bridge's auto-retry pulse between two steps stops the run as a fault that lasted).
    pub(crate) faulted: bool,
}

/// The states whose stop the device makes itself with the law's stop (crate docs): the run's
/// own limits, a silent host, a non-finite move. A driver fault cannot drive, an overrun's
/// timing cannot be trusted to close a loop, and the host's stops are the host's.
fn stops_itself(state: u8) -> bool {
    matches!(
        state,
        ONBOARD_ARM_LIMIT | ONBOARD_PENDULUM_LIMIT | ONBOARD_HOST_SILENT | ONBOARD_BAD_MOVE
    )
}

impl<C: Onboard> Device<C> {
    /// A processor-in-the-loop step (protocol docs of `PilStep`): the controller's move on
    /// the given positions, timed, without driving the motor.
    pub(crate) fn pil_step(&mut self, seq: u16, p: PilStep) -> Frame {
        let code = if self.run.is_some() {
            ACK_BUSY
        } else if !self.design_loaded {
            ACK_NO_DESIGN
        } else {
            ACK_OK
        };
        let mut out = PilMove {
            ack_seq: seq,
            step: self.pil_steps,
            voltage_bits: f64::NAN.to_bits(),
            cycles: 0,
            code,
        };
        if code == ACK_OK && p.flags & PIL_STOP != 0 {
            return self.pil_stop_step(out, p);
        }
        if code == ACK_OK {
            let positions = [p.arm_counts, p.pendulum_counts];
            if p.flags & PIL_RESET != 0 {
                self.onboard.reset(positions);
                self.pil_steps = 0;
            }
            let phase = (p.flags & PIL_PHASE_MASK) >> PIL_PHASE_SHIFT;
            let u = match self.cycle_counter {
                None => self.onboard.step(positions),
                Some((c, shift)) if phase == 0 => {
                    let t0 = c();
                    let u = self.onboard.step(positions);
                    out.cycles = c().wrapping_sub(t0) >> shift;
                    u
                }
                Some((c, shift)) => {
                    // The counter at the end of each part; a part the step skipped ends
                    // where the one before it did.
                    let mut ends = [None::<u32>; PIL_PHASES + 1];
                    ends[0] = Some(c());
                    let u = self.onboard.step_probed(positions, &mut |q| {
                        if let Some(e) = ends.get_mut(usize::from(q)) {
                            *e = Some(c());
                        }
                    });
                    ends[PIL_PHASES] = Some(c());
                    let mut last = ends[0].unwrap_or(0);
                    let mut at = [0u32; PIL_PHASES + 1];
                    for (a, e) in at.iter_mut().zip(ends) {
                        last = e.unwrap_or(last);
                        *a = last;
                    }
                    let k = usize::from(phase).min(PIL_PHASES);
                    out.cycles = at[k].wrapping_sub(at[k - 1]) >> shift;
                    u
                }
            };
            self.pil_steps = self.pil_steps.wrapping_add(1);
            out.step = self.pil_steps;
            out.voltage_bits = u.to_bits();
        }
        self.next_frame(Message::PilMove(out))
    }

    /// Handles a v2 host request: the ack's code and value.
    pub(crate) fn onboard_request(&mut self, message: Message, inputs: &Inputs) -> (u8, u32) {
        match message {
            Message::UploadBegin(_) | Message::UploadChunk(_) | Message::UploadCommit(_)
                if self.run.is_some() =>
            {
                (ACK_BUSY, 0)
            }
            Message::UploadBegin(b) => {
                // A new upload overwrites the buffer: the loaded design is gone, and with it
                // the wiring it was verified for.
                self.design_loaded = false;
                self.watchdog_stop = None;
                self.onboard_state = ONBOARD_IDLE;
                if b.total_len as usize > self.onboard.buffer().len() || b.total_len == 0 {
                    self.upload = None;
                    return (ACK_TOO_LARGE, 0);
                }
                self.upload = Some(Upload {
                    total: b.total_len,
                    next: 0,
                });
                (ACK_OK, 0)
            }
            Message::UploadChunk(c) => self.chunk(&c),
            Message::UploadCommit(c) => self.commit(&c),
            Message::OnboardStart(s) => self.start(s, inputs),
            Message::WatchdogStop(w) => self.arm_watchdog_stop(w),
            Message::OnboardStop { flags } => {
                if self.run.is_some() {
                    self.stop_onboard(ONBOARD_STOPPED, flags & COMMAND_BRAKE != 0);
                } else {
                    self.command = Command::STOP;
                    self.brake = flags & COMMAND_BRAKE != 0 && !self.fault;
                }
                (ACK_OK, self.onboard_state as u32)
            }
            _ => (ACK_REFUSED, 0),
        }
    }

    pub(crate) fn chunk(&mut self, c: &UploadChunk) -> (u8, u32) {
        let Some(up) = self.upload.as_mut() else {
            return (ACK_NO_UPLOAD, 0);
        };
        if c.offset != up.next {
            return (ACK_OUT_OF_ORDER, up.next);
        }
        let bytes = c.bytes();
        let end = up.next as u64 + bytes.len() as u64;
        if end > up.total as u64 {
            return (ACK_TOO_LARGE, up.next);
        }
        let at = up.next as usize;
        up.next = end as u32;
        let next = up.next;
        // `total` was checked against the buffer's length at the begin.
        if let Some(dst) = self.onboard.buffer().get_mut(at..at + bytes.len()) {
            dst.copy_from_slice(bytes);
        }
        (ACK_OK, next)
    }

    pub(crate) fn commit(&mut self, c: &UploadCommit) -> (u8, u32) {
        let Some(up) = self.upload else {
            return (ACK_NO_UPLOAD, 0);
        };
        if c.len != up.next || c.len != up.total {
            return (ACK_LENGTH_MISMATCH, up.next);
        }
        let len = up.next as usize;
        let crc = self.onboard.buffer().get(..len).map_or(!c.crc32, crc32);
        self.upload = None;
        if crc != c.crc32 {
            return (ACK_CRC_MISMATCH, crc);
        }
        match self.onboard.load(len) {
            Ok(()) => {
                self.design_loaded = true;
                (ACK_OK, crc)
            }
            Err(DesignRefused) => (ACK_DESIGN_REFUSED, crc),
        }
    }

    pub(crate) fn start(&mut self, s: OnboardStart, inputs: &Inputs) -> (u8, u32) {
        if !self.design_loaded || self.onboard.period_us() == 0 {
            return (ACK_NO_DESIGN, self.onboard_state as u32);
        }
        if self.run.is_some_and(|r| r.stopping.is_some()) {
            // The device's own stop runs to its end (a start resent on a lost ack would
            // otherwise cancel it).
            return (ACK_BUSY, self.onboard_state as u32);
        }
        if s.decimation == 0 || s.host_timeout_ms == 0 || s.flags & !ONBOARD_WIRING_VERIFIED != 0 {
            // A flag this device does not know is refused rather than ignored.
            return (ACK_BAD_SETTINGS, self.onboard_state as u32);
        }
        let positions = self.positions();
        if self.fault || Self::outside_limits(&s, positions).is_some() {
            return (ACK_REFUSED, self.onboard_state as u32);
        }
        self.onboard.reset(positions);
        self.run = Some(Run {
            settings: s,
            due_us: inputs.now_us,
            step: 0,
            last_host_us: inputs.now_us,
            last_cycles: 0,
            overruns: 0,
            stopping: None,
            faulted: false,
        });
        self.watchdog = false;
        // The start's own flags say how this run stops.
        self.watchdog_stop = None;
        self.onboard_state = ONBOARD_RUNNING;
        (ACK_OK, ONBOARD_RUNNING as u32)
    }

    /// Host mode's [`WatchdogStop`] (crate docs, "The watchdog's stop"): the ack's code, and 1
    /// when the watchdog will run the law's stop, 0 for the short.
    pub(crate) fn arm_watchdog_stop(&mut self, w: WatchdogStop) -> (u8, u32) {
        if self.run.is_some() {
            return (ACK_BUSY, 0);
        }
        if w.flags & !ONBOARD_WIRING_VERIFIED != 0 {
            return (ACK_BAD_SETTINGS, 0);
        }
        if !self.design_loaded {
            return (ACK_NO_DESIGN, 0);
        }
        // A stop the device would not step (a period outside its timer's range) is the short.
        let [shortest, longest] = self.cfg.onboard_period_us;
        let steps = (shortest..=longest).contains(&self.onboard.period_us());
        let laws = w.flags & ONBOARD_WIRING_VERIFIED != 0 && self.onboard.has_stop() && steps;
        self.watchdog_stop = laws.then_some(w);
        (ACK_OK, u32::from(laws))
    }

    /// The command watchdog tripped in host mode at `now_us`: with a [`WatchdogStop`] in
    /// force, the law's stop begins as an onboard run already stopping on the host's
    /// silence, so that it is stepped and reported as in onboard mode; otherwise the short
    /// the caller set stays.
    pub(crate) fn begin_watchdog_stop(&mut self, now_us: u32) {
        let Some(w) = self.watchdog_stop else {
            return;
        };
        let zero = [w.arm_zero, w.pendulum_down];
        if self.run.is_some()
            || self.fault
            || !self.design_loaded
            || !self.onboard.begin_stop(true, Some(zero))
        {
            return;
        }
        // Telemetry at the stop's own rate: a record per period of its sequence.
        let period_s = f64::from(self.onboard.period_us().max(1)) * 1e-6;
        let decimation = rip_control::stop::steps_per_stop_period(period_s);
        self.run = Some(Run {
            settings: OnboardStart {
                decimation: u16::try_from(decimation).unwrap_or(u16::MAX),
                host_timeout_ms: u16::MAX,
                arm_center: 0,
                arm_limit: u32::MAX,
                pendulum_center: 0,
                pendulum_limit: u32::MAX,
                flags: ONBOARD_WIRING_VERIFIED,
            },
            due_us: now_us,
            step: 0,
            last_host_us: now_us,
            last_cycles: 0,
            overruns: 0,
            stopping: Some((ONBOARD_HOST_SILENT, 0)),
            faulted: false,
        });
        self.onboard_state = ONBOARD_HOST_SILENT;
    }

    /// The limit the positions exceed, if any, arm first: the position rule
    /// ([`rip_control::stop::past_limit`], rip-rt's) in counts from each limit's centre, exact
    /// in `f64` for any `i32` position and `u32` limit.
    pub(crate) fn outside_limits(s: &OnboardStart, [arm, pendulum]: [i32; 2]) -> Option<u8> {
        let past = |p: i32, c: i32, limit: u32| {
            rip_control::stop::past_limit(f64::from(p) - f64::from(c), f64::from(limit))
        };
        if past(arm, s.arm_center, s.arm_limit) {
            Some(ONBOARD_ARM_LIMIT)
        } else if past(pendulum, s.pendulum_center, s.pendulum_limit) {
            Some(ONBOARD_PENDULUM_LIMIT)
        } else {
            None
        }
    }

    /// A processor-in-the-loop step of the device's own stop ([`PIL_STOP`]): begun on
    /// [`PIL_RESET`], its clock a design period per step, timed as a whole.
    fn pil_stop_step(&mut self, mut out: PilMove, p: PilStep) -> Frame {
        let positions = [p.arm_counts, p.pendulum_counts];
        if p.flags & PIL_RESET != 0 {
            self.onboard.reset(positions);
            self.pil_steps = 0;
            if !self.onboard.begin_stop(true, None) {
                out.code = ACK_REFUSED;
                return self.next_frame(Message::PilMove(out));
            }
        }
        let now_us = self.pil_steps.wrapping_mul(self.onboard.period_us());
        let t0 = self.cycle_counter.map(|(c, _)| c());
        let command = self.onboard.stop_step(positions, now_us);
        if let (Some(t0), Some((c, shift))) = (t0, self.cycle_counter) {
            out.cycles = c().wrapping_sub(t0) >> shift;
        }
        self.pil_steps = self.pil_steps.wrapping_add(1);
        out.step = self.pil_steps;
        out.voltage_bits = match command {
            Some(BrakeCommand::Volts(v)) => v,
            Some(BrakeCommand::Short) => f64::INFINITY,
            None => f64::NAN,
        }
        .to_bits();
        self.next_frame(Message::PilMove(out))
    }

    /// Ends onboard mode with `state`: 0 V, driver disabled, braking if `brake` (and no fault).
    pub(crate) fn stop_onboard(&mut self, state: u8, brake: bool) {
        self.run = None;
        self.onboard_state = state;
        self.command = Command::STOP;
        self.brake = brake && !self.fault;
        if state == ONBOARD_HOST_SILENT {
            self.watchdog = true;
        }
    }

    /// Steps the onboard controller if a step is due at `inputs.now_us` (one
    /// [`Onboard::period_us`] after the previous one): for a main loop or a simulation that
    /// calls the device more often than the controller's period. Returns what
    /// [`onboard_step`](Self::onboard_step) returns, or `None` when no step was due.
    pub fn onboard_tick(&mut self, inputs: &Inputs) -> Option<Frame> {
        let due = self.run?.due_us;
        if (inputs.now_us.wrapping_sub(due) as i32) < 0 {
            self.tick(inputs);
            return None;
        }
        self.onboard_step(inputs)
    }

    /// One onboard controller step at the instant `inputs` was read (the firmware's timer
    /// interrupt): the checks of the module docs, the controller's move applied, and a
    /// telemetry frame to send every `decimation` steps and on the step that stops the run.
    /// Without a run in progress it only ticks and returns `None`.
    pub fn onboard_step(&mut self, inputs: &Inputs) -> Option<Frame> {
        self.tick(inputs);
        let mut run = self.run?;
        let positions = self.positions();
        let mut stop = if run.stopping.is_some() {
            self.stop_period(&mut run, positions, inputs.now_us)
        } else {
            self.control_period(&run, positions, inputs.now_us)
        };
        let period = self.onboard.period_us().max(1);
        run.due_us = run.due_us.wrapping_add(period);
        if (inputs.now_us.wrapping_sub(run.due_us) as i32) > 0 {
            // Far behind: resume from now rather than catch up with a burst of steps.
            run.due_us = inputs.now_us.wrapping_add(period);
        }
        let step = run.step;
        run.step = run.step.wrapping_add(1);
        if let Some((state, true)) = stop.filter(|_| run.stopping.is_none()) {
            let verified = run.settings.flags & ONBOARD_WIRING_VERIFIED != 0;
            if stops_itself(state) && self.onboard.begin_stop(verified, None) {
                run.stopping = Some((state, 0));
                self.onboard_state = state;
                stop = self.stop_period(&mut run, positions, inputs.now_us);
            }
        }
        self.run = Some(run);
        if let Some((state, brake)) = stop {
            self.stop_onboard(state, brake);
        }
        let report = stop.is_some() || step % run.settings.decimation.max(1) as u32 == 0;
        report.then(|| self.telemetry(&run, step, positions, inputs.now_us))
    }

    /// A period of the controller: the checks of the module docs, then its move applied; the
    /// state and brake to stop with, if it stops.
    fn control_period(
        &mut self,
        run: &Run,
        positions: [i32; 2],
        now_us: u32,
    ) -> Option<(u8, bool)> {
        let silent =
            now_us.wrapping_sub(run.last_host_us) > run.settings.host_timeout_ms as u32 * 1000;
        let stop = if self.fault || run.faulted {
            Some((ONBOARD_DRIVER_FAULT, false))
        } else if silent {
            Some((ONBOARD_HOST_SILENT, true))
        } else {
            Self::outside_limits(&run.settings, positions).map(|s| (s, true))
        };
        stop.or_else(|| {
            let u = self.onboard.step(positions);
            if !u.is_finite() {
                return Some((ONBOARD_BAD_MOVE, true));
            }
            self.drive(u, now_us);
            None
        })
    }

    /// Drives `u` (V), clamped to the device's limit; each such period is the command the v1
    /// watchdog waits for (module docs).
    fn drive(&mut self, u: f64, now_us: u32) {
        let limit = self.cfg.voltage_limit_mv.min(i16::MAX as u16) as f64;
        let mv = (u * 1000.0).clamp(-limit, limit);
        self.command = Command {
            voltage_mv: libm_round(mv) as i16,
            flags: COMMAND_ENABLE,
        };
        self.brake = false;
        self.last_command_us = now_us;
    }

    /// A period of the device's own stop (crate docs): the law's command
    /// for it, at most [`MAX_STOP_S`] of them; the state and brake to end the run with once it
    /// is done, or at once on a driver fault.
    fn stop_period(
        &mut self,
        run: &mut Run,
        positions: [i32; 2],
        now_us: u32,
    ) -> Option<(u8, bool)> {
        let (state, periods) = run.stopping?;
        if self.fault || run.faulted {
            return Some((ONBOARD_DRIVER_FAULT, false));
        }
        run.stopping = Some((state, periods.saturating_add(1)));
        let period_s = f64::from(self.onboard.period_us().max(1)) * 1e-6;
        let command = if f64::from(periods) * period_s >= MAX_STOP_S {
            None
        } else {
            self.onboard.stop_step(positions, now_us)
        };
        match command {
            Some(BrakeCommand::Volts(v)) if v.is_finite() => {
                self.drive(v, now_us);
                None
            }
            Some(_) => {
                // The short: not driven, the windings shorted.
                self.command = Command::STOP;
                self.brake = true;
                self.last_command_us = now_us;
                None
            }
            None => Some((state, true)),
        }
    }

    pub(crate) fn telemetry(
        &mut self,
        run: &Run,
        step: u32,
        positions: [i32; 2],
        now_us: u32,
    ) -> Frame {
        let t = Telemetry {
            step,
            device_time_us: now_us,
            arm_counts: positions[0],
            pendulum_counts: positions[1],
            applied_mv: self.voltage_mv(),
            status: self.status(),
            onboard: self.onboard_state,
            step_cycles: run.last_cycles,
            overruns: run.overruns,
            fallbacks: u16::try_from(self.onboard.fallbacks()).unwrap_or(u16::MAX),
        };
        self.next_frame(Message::Telemetry(t))
    }

    /// Records how long the last controller step took, `cycles` processor cycles, against
    /// its `budget` (the period's cycles): a step over budget is an overrun, which stops
    /// onboard mode (module docs). On an overrun it returns the run's final telemetry record,
    /// stamped `now_us` and numbered as the step that overran, so that the host learns why the
    /// run ended as it does for every other stop; otherwise `None`.
    pub fn record_step_cycles(&mut self, cycles: u32, budget: u32, now_us: u32) -> Option<Frame> {
        let run = self.run.as_mut()?;
        run.last_cycles = cycles;
        if cycles <= budget {
            return None;
        }
        run.overruns = run.overruns.saturating_add(1);
        let run = *run;
        self.stop_onboard(ONBOARD_OVERRUN, true);
        let positions = self.positions();
        Some(self.telemetry(&run, run.step.wrapping_sub(1), positions, now_us))
    }

    /// The `ONBOARD_*` state: running, idle, or why the last run stopped.
    pub fn onboard_state(&self) -> u8 {
        self.onboard_state
    }

    /// Whether onboard mode runs.
    pub fn onboard_running(&self) -> bool {
        self.run.is_some()
    }

    /// Whether a committed design is loaded.
    pub fn design_loaded(&self) -> bool {
        self.design_loaded
    }

    /// The onboard controller.
    pub fn onboard(&self) -> &C {
        &self.onboard
    }

    /// The onboard controller, mutable (to read or replace its design outside the protocol).
    pub fn onboard_mut(&mut self) -> &mut C {
        &mut self.onboard
    }
}
