//! A device emulator: the device side of protocol v1 over a pseudo-terminal, with the pendulum
//! simulated in real time at 1 kHz and injectable faults.
//!
//! The emulated firmware is the firmware's own logic, `rip-device`: command handling, the
//! command watchdog, clamping to the device's voltage limit, status flags, the 16-bit encoder
//! counters and the PWM duty. Only the hardware is replaced: the encoder counters are the
//! simulated angles truncated to 16 bits, and the motor receives the voltage that the PWM duty
//! and direction produce from the bridge supply, or, not driven, has its windings open (the
//! driver disabled: the arm coasts) or shorted (the bridge brakes: back-EMF stops the arm),
//! as `rip-device` says (its "A motor that is not driven"). So every end-to-end test of `rip-rt run`
//! against the emulator runs the code that the STM32 runs.
//!
//! Until the first enabling command arrives the pendulum is held still at its initial pose, the
//! way an operator holds it upright before the loop takes over; `hold_until_enabled = false`
//! lets it fall from the start. `raise_at_s` has the operator raise it later and hold it
//! again until the next enabling command.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rip_device::{Direction, Inputs};

use crate::plant::{Model, PlantSim, Windings};
use crate::protocol::{
    encode, Event, Frame, Measurement, Message, Parser, MAX_FRAME, STATUS_LOCKSTEP,
    STATUS_NO_SAMPLE, SYNC0,
};
use crate::serial::{Fd, Pty, Readiness};
use crate::timing::now_ns;

/// Full-scale compare value of the firmware's PWM timer (TIM1 at 168 MHz, 20 kHz PWM: 8400
/// steps); the emulated bridge applies the same quantised voltage as the real one.
pub const PWM_MAX_DUTY: u16 = 8400;

mod config;
mod true_state;
pub use config::{EmulatorConfig, EmulatorConfigError, Wiring};
use true_state::TrueState;
pub use true_state::TRUE_STATE_HEADER;

/// After its host hung up, the emulator (in lockstep or real time) runs its plant on, unpaced,
/// until it has rested ([`RUN_ON_REST_RATE`], the motor not driven) for this long (s of
/// simulated time):
/// what happens after a run (the arm coasting, the device's watchdog, the pendulum settling)
/// plays out as on the rig, in a fraction of the wall time, and a test reads it from the
/// true-state record at once.
pub const RUN_ON_REST_S: f64 = 1.0;

/// The rates `|θ̇|`, `|α̇|` (rad/s) below which the plant counts as resting for
/// [`RUN_ON_REST_S`].
pub const RUN_ON_REST_RATE: [f64; 2] = [1e-3, 1e-2];

/// The longest the emulator runs on after its host hung up (s of simulated time), for a plant
/// that never rests (a lightly damped pendulum, a motor the device still drives); then it
/// paces its plant again (in real time, or by the next host's requests in lockstep).
pub const RUN_ON_MAX_S: f64 = 60.0;

/// The emulated device: the firmware's logic (`rip-device`) on a simulated pendulum.
#[derive(Debug)]
pub struct Device {
    cfg: EmulatorConfig,
    plant: PlantSim,
    rng: StdRng,
    firmware: Box<rip_device::Device<OnboardLaw>>,
    // Frames the firmware sent on its own (onboard telemetry), waiting to be written.
    outgoing: Vec<Frame>,
    // The last hardware readings taken (their reading noise drawn).
    last_inputs: Option<Inputs>,
    released: bool,
    // Whether the operator of `raise_at_s` has raised the pendulum.
    raised: bool,
    commands_seen: bool,
    time_ns: u64,
    // When the first enabling command arrived (simulated time).
    enabled_at_ns: Option<u64>,
    // The wiring faults' onset: the true counts then (before noise and rounding), from which
    // a reversed encoder counts backwards and at which a frozen one stays. `None` before it.
    fault_onset: Option<[f64; 2]>,
}

/// The emulated firmware's onboard controller: rip-control's in `f64`, with room for the
/// largest design rip-control can hold.
pub type OnboardLaw = rip_device::law::ControlLaw<f64, ONBOARD_BUFFER>;

/// Bytes of the emulated firmware's design buffer.
pub const ONBOARD_BUFFER: usize = 96 * 1024;

fn firmware(
    cfg: rip_device::Config,
    inputs: &Inputs,
    positions: [i32; 2],
) -> Box<rip_device::Device<OnboardLaw>> {
    Box::new(rip_device::Device::with_onboard(
        cfg,
        inputs,
        positions,
        OnboardLaw::new(),
    ))
}

/// What the device did with a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply {
    /// Nothing to send.
    None,
    /// Send these many bytes from the output buffer.
    Bytes(usize),
}

impl Device {
    /// A device with the plant at its initial pose, at rest, and the firmware at power-up.
    pub fn new(cfg: EmulatorConfig) -> Self {
        let plant = PlantSim::new(cfg.model, cfg.initial_arm, cfg.initial_pendulum);
        let firmware_cfg = rip_device::Config {
            command_timeout_us: (cfg.command_timeout_s * 1e6).round().min(u32::MAX as f64) as u32,
            voltage_limit_mv: (cfg.voltage_limit * 1000.0).round() as u16,
            supply_mv: (cfg.supply * 1000.0).round() as u16,
            can_brake: cfg.can_brake,
            ..rip_device::Config::DEFAULT
        };
        let mut dev = Self {
            rng: StdRng::seed_from_u64(cfg.seed),
            plant,
            firmware: firmware(firmware_cfg, &Inputs::default(), [0, 0]),
            outgoing: Vec::with_capacity(64),
            last_inputs: None,
            released: !cfg.hold_until_enabled,
            raised: false,
            commands_seen: false,
            time_ns: 0,
            enabled_at_ns: None,
            fault_onset: None,
            cfg,
        };
        if dev.cfg.fault_at_s.is_none() {
            dev.fault_onset = Some(dev.true_counts());
        }
        let [arm, pendulum] = dev.counts(false);
        let inputs = Inputs {
            now_us: 0,
            encoders: [arm as u16, pendulum as u16],
            driver_fault: false,
        };
        dev.firmware = firmware(firmware_cfg, &inputs, [arm, pendulum]);
        dev
    }

    /// Simulated time (s).
    pub fn time_s(&self) -> f64 {
        self.time_ns as f64 * 1e-9
    }

    /// Plant state `[θ, θ̇, α, α̇]`.
    pub fn state(&self) -> [f64; 4] {
        self.plant.state()
    }

    /// Whether any command has arrived.
    pub fn first_command_seen(&self) -> bool {
        self.commands_seen
    }

    /// The firmware's state.
    pub fn firmware(&self) -> &rip_device::Device<OnboardLaw> {
        &self.firmware
    }

    /// The voltage the bridge applies now: the firmware's PWM duty and direction on the supply.
    pub fn applied_voltage(&self) -> f64 {
        let pwm = self.firmware.pwm(PWM_MAX_DUTY);
        if !pwm.enable {
            return 0.0;
        }
        let v = self.cfg.supply * pwm.duty as f64 / PWM_MAX_DUTY as f64;
        match pwm.direction {
            Direction::Forward => v,
            Direction::Reverse => -v,
        }
    }

    /// The voltage across the motor's windings in the plant's sign convention (a positive
    /// voltage turns the arm the positive way): [`applied_voltage`](Self::applied_voltage),
    /// negated when the leads are swapped.
    pub fn motor_voltage(&self) -> f64 {
        if self.wiring().motor_reversed {
            -self.applied_voltage()
        } else {
            self.applied_voltage()
        }
    }

    /// What the bridge connects to the motor's windings now (the plant's sign convention).
    pub fn windings(&self) -> Windings {
        let pwm = self.firmware.pwm(PWM_MAX_DUTY);
        if pwm.enable {
            Windings::Driven(self.motor_voltage())
        } else if pwm.brake {
            Windings::Shorted
        } else {
            Windings::Open
        }
    }

    /// What the bridge does to the motor now: `"drive"` (a voltage across the windings),
    /// `"brake"` (windings shorted) or `"open"` (driver disabled, windings disconnected).
    pub fn driver_state(&self) -> &'static str {
        match self.windings() {
            Windings::Driven(_) => "drive",
            Windings::Shorted => "brake",
            Windings::Open => "open",
        }
    }

    /// Motor current (A) now, in the plant's sign convention.
    pub fn motor_current(&self) -> f64 {
        self.plant.motor_current(self.windings())
    }

    /// One row of the true-state record ([`TRUE_STATE_HEADER`]).
    fn write_true_state(&self, w: &mut impl Write) -> io::Result<()> {
        let [theta, theta_dot, alpha, alpha_dot] = self.state();
        writeln!(
            w,
            "{:.6},{theta:.6},{theta_dot:.6},{alpha:.6},{alpha_dot:.6},{:.4},{:.5},{}",
            self.time_s(),
            self.motor_voltage(),
            self.motor_current(),
            self.driver_state()
        )
    }

    /// The wiring in effect now: the configured faults once they began, else a correct rig.
    pub fn wiring(&self) -> Wiring {
        if self.fault_onset.is_some() {
            self.cfg.wiring
        } else {
            Wiring::default()
        }
    }

    fn counts_per_rev(&self) -> [f64; 2] {
        [
            self.cfg.arm_counts_per_rev,
            self.cfg.pendulum_counts_per_rev,
        ]
        .map(f64::from)
    }

    /// The counts a correctly wired, noiseless encoder pair would read now (unrounded).
    fn true_counts(&self) -> [f64; 2] {
        let [theta, _, alpha, _] = self.plant.state();
        let [o_arm, o_pendulum] = self.cfg.encoder_offsets;
        let tau = std::f64::consts::TAU;
        [
            (theta + o_arm) * self.cfg.arm_counts_per_rev as f64 / tau,
            (alpha + std::f64::consts::PI + o_pendulum) * self.cfg.pendulum_counts_per_rev as f64
                / tau,
        ]
    }

    /// Encoder counts of the plant's angles (pendulum zero hanging down), with reading noise
    /// and the wiring faults in effect.
    fn counts(&mut self, noisy: bool) -> [i32; 2] {
        let mut c = self.true_counts();
        let w = self.wiring();
        let onset = self.fault_onset.unwrap_or_default();
        for (j, v) in c.iter_mut().enumerate() {
            if w.encoder_frozen[j] {
                *v = onset[j];
                continue;
            }
            if w.encoder_reversed[j] {
                *v = 2.0 * onset[j] - *v;
            }
            *v = v.round();
            let sigma = self.cfg.noise_std[j] * self.counts_per_rev()[j] / std::f64::consts::TAU;
            if noisy && sigma > 0.0 {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                *v += (sigma * z).round();
            }
        }
        c.map(|v| v.round().clamp(i32::MIN as f64, i32::MAX as f64) as i32)
    }

    /// The hardware readings now: the microsecond clock and the 16-bit encoder counters.
    fn inputs(&mut self) -> Inputs {
        let [arm, pendulum] = self.counts(true);
        let inputs = Inputs {
            // The firmware's clock is a wrapping 32-bit microsecond counter.
            now_us: (self.time_ns / 1000) as u32,
            encoders: [arm as u16, pendulum as u16],
            driver_fault: false,
        };
        self.last_inputs = Some(inputs);
        inputs
    }

    /// Advances the simulation by `dt_ns` nanoseconds: the firmware's tick (encoders,
    /// watchdog), then the plant under the voltage the bridge applies.
    pub fn advance(&mut self, dt_ns: u64) {
        if let (None, Some(at), Some(t0)) =
            (self.fault_onset, self.cfg.fault_at_s, self.enabled_at_ns)
        {
            if self.time_ns >= t0 + (at * 1e9).round() as u64 {
                self.fault_onset = Some(self.true_counts());
            }
        }
        if let (false, Some(at), Some(t0)) = (self.raised, self.cfg.raise_at_s, self.enabled_at_ns)
        {
            if self.time_ns >= t0 + (at * 1e9).round() as u64 && !self.firmware.enabled() {
                let x = self.plant.state();
                self.plant.set_state([x[0], 0.0, 0.05, 0.0]);
                self.raised = true;
                self.released = false;
            }
        }
        let inputs = self.inputs();
        if self.firmware.onboard_running() {
            if let Some(frame) = self.firmware.onboard_tick(&inputs) {
                self.outgoing.push(frame);
            }
            if self.firmware.enabled() {
                self.released = true;
                self.enabled_at_ns.get_or_insert(self.time_ns);
            }
        } else {
            self.firmware.tick(&inputs);
        }
        let w = self.windings();
        if self.released {
            self.plant.step_windings(w, dt_ns as f64 * 1e-9);
        }
        self.time_ns += dt_ns;
    }

    /// Hands one parser event to the firmware; a sample request writes the measurement into
    /// `out`.
    pub fn handle(&mut self, event: Event, out: &mut [u8; MAX_FRAME]) -> Reply {
        if let Event::Frame(Frame {
            message: Message::Command(_),
            ..
        }) = event
        {
            self.commands_seen = true;
        }
        // A request that does not read the encoders (an upload, the watchdog stop's arming)
        // takes the last readings at the current clock, so that the reading noise is drawn
        // per reading the rig's behaviour depends on, not per frame the host happens to send.
        let reads = !matches!(
            event,
            Event::Frame(Frame {
                message: Message::UploadBegin(_)
                    | Message::UploadChunk(_)
                    | Message::UploadCommit(_)
                    | Message::WatchdogStop(_),
                ..
            })
        );
        let inputs = match self.last_inputs {
            Some(last) if !reads => Inputs {
                now_us: (self.time_ns / 1000) as u32,
                ..last
            },
            _ => self.inputs(),
        };
        let reply = self.firmware.handle(event, &inputs);
        if self.firmware.enabled() {
            self.released = true;
            self.enabled_at_ns.get_or_insert(self.time_ns);
        }
        match reply {
            Some(mut frame) => {
                if let (Message::Measurement(m), Some(_)) =
                    (&mut frame.message, self.cfg.lockstep_period_s)
                {
                    m.status |= STATUS_LOCKSTEP;
                }
                Reply::Bytes(encode(&frame, out))
            }
            None => Reply::None,
        }
    }

    /// The next frame the firmware sent on its own (onboard telemetry), encoded into `out`.
    pub fn take_outgoing(&mut self, out: &mut [u8; MAX_FRAME]) -> Option<usize> {
        if self.outgoing.is_empty() {
            return None;
        }
        let frame = self.outgoing.remove(0);
        Some(encode(&frame, out))
    }

    /// Whether the device is inside its configured silence (`EmulatorConfig::silence`).
    fn silent(&self) -> bool {
        match (self.cfg.silence, self.enabled_at_ns) {
            (Some((at, len)), Some(t0)) => {
                let t = self.time_ns.saturating_sub(t0) as f64 * 1e-9;
                t >= at && t < at + len
            }
            _ => false,
        }
    }

    /// Applies the configured faults to an outgoing frame and writes what remains into `wire`
    /// (which is cleared first); `false` when the frame cannot reach the host intact
    /// (dropped, silenced, or a byte flipped).
    pub fn inject_faults(&mut self, frame: &[u8], wire: &mut Vec<u8>) -> bool {
        wire.clear();
        if self.silent() {
            return false;
        }
        if self.cfg.drop_rate > 0.0 && self.rng.gen_bool(self.cfg.drop_rate) {
            return false;
        }
        if self.cfg.corrupt_rate > 0.0 && self.rng.gen_bool(self.cfg.corrupt_rate) {
            if self.rng.gen_bool(0.5) {
                // Garbage before an intact frame: the parser must skip it and still decode it.
                let n = self.rng.gen_range(1..=8);
                for _ in 0..n {
                    let b = if self.rng.gen_bool(0.3) {
                        SYNC0
                    } else {
                        self.rng.gen()
                    };
                    wire.push(b);
                }
                wire.extend_from_slice(frame);
                return true;
            }
            wire.extend_from_slice(frame);
            let i = self.rng.gen_range(0..wire.len());
            let flip: u8 = self.rng.gen_range(1..=255);
            wire[i] ^= flip;
            return false;
        }
        wire.extend_from_slice(frame);
        true
    }

    /// The lockstep marker that stands in for a lost reply to the sample request `ack_seq`
    /// ([`STATUS_NO_SAMPLE`]), encoded into `out`: its length. A lockstep host then counts the
    /// period as without a measurement at once; a real-time host would have waited out its
    /// reply timeout for the same verdict, which costs the lockstep run no wall time.
    pub fn lost_reply_marker(&self, ack_seq: u16, out: &mut [u8; MAX_FRAME]) -> usize {
        let frame = Frame {
            seq: ack_seq,
            message: Message::Measurement(Measurement {
                ack_seq,
                status: STATUS_LOCKSTEP | STATUS_NO_SAMPLE,
                device_time_us: (self.time_ns / 1000) as u32,
                ..Measurement::default()
            }),
        };
        encode(&frame, out)
    }

    /// Whether the plant is at rest with the motor not driven: what a lockstep emulator runs
    /// on to after its host hung up.
    fn resting(&self) -> bool {
        let [_, theta_dot, _, alpha_dot] = self.state();
        theta_dot.abs() < RUN_ON_REST_RATE[0]
            && alpha_dot.abs() < RUN_ON_REST_RATE[1]
            && !matches!(self.windings(), Windings::Driven(_))
    }
}

/// Why [`run`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EmulatorExit {
    /// A stop signal arrived.
    Stopped,
    /// `duration_s` elapsed.
    Finished,
    /// The injected vanish fault closed the device.
    Vanished,
}

fn write_record(rec: &mut Option<BufWriter<File>>, t: f64, frame: &Frame) -> io::Result<()> {
    if let (Some(w), Message::Command(c)) = (rec.as_mut(), frame.message) {
        writeln!(w, "{t:.6},{},{},{}", frame.seq, c.voltage_mv, c.flags)?;
        // Flushed per line: the file is the evidence of what the device last received.
        w.flush()?;
    }
    Ok(())
}

/// Runs the emulator on `pty` until `stop` is set, the duration passes or the device vanishes.
/// The simulation advances on a 1 kHz (configurable) grid of absolute deadlines; host frames are
/// answered as soon as they arrive. With `cfg.true_state`, the plant's state is recorded
/// throughout, and once more on every way out (including an error).
pub fn run(cfg: EmulatorConfig, pty: Pty, stop: &AtomicBool) -> io::Result<EmulatorExit> {
    let mut truth = TrueState::create(&cfg)?;
    let mut device = Device::new(cfg.clone());
    if let Some(t) = truth.as_mut() {
        t.sample(&device)?;
    }
    let result = serve(cfg, &mut device, &mut truth, pty, stop);
    let last = match truth.as_mut() {
        Some(t) => t.row(&device),
        None => Ok(()),
    };
    let exit = result?;
    last.map(|()| exit)
}

fn serve(
    cfg: EmulatorConfig,
    device: &mut Device,
    truth: &mut Option<TrueState>,
    mut pty: Pty,
    stop: &AtomicBool,
) -> io::Result<EmulatorExit> {
    let record = match &cfg.record {
        Some(path) => {
            let mut w = BufWriter::new(File::create(path).map_err(|e| {
                io::Error::new(e.kind(), format!("--record {}: {e}", path.display()))
            })?);
            writeln!(w, "t_s,seq,voltage_mv,flags")?;
            w.flush()?;
            Some(w)
        }
        None => None,
    };
    let dt_ns = (1e9 / cfg.sim_rate_hz).round() as u64;
    let mut server = Server {
        device,
        truth,
        clock: SimClock {
            dt_ns,
            duration: cfg.duration_s,
            vanish_after: cfg.vanish_after_s,
            first_command_at: None,
        },
        // Simulation steps per host period in lockstep.
        lockstep_steps: cfg
            .lockstep_period_s
            .map(|p| ((p * 1e9 / dt_ns as f64).round() as u64).max(1)),
        pause_at_arm: cfg.pause_at_arm,
        parser: Parser::new(),
        record,
        out: [0u8; MAX_FRAME],
        wire: Vec::with_capacity(2 * MAX_FRAME + 16),
    };
    let mut rx = [0u8; 256];
    let mut next_tick = now_ns() + dt_ns;
    let mut host = Host::Awaited;
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(EmulatorExit::Stopped);
        }
        let now = now_ns();
        let wait_ns = match (server.lockstep_steps, host) {
            // After the host hung up, in either mode: the plant runs on, unpaced, to rest.
            (_, Host::RunningOn { since_ns, rest_ns }) => {
                let (exit, next) = server.run_on(since_ns, rest_ns)?;
                if let Some(exit) = exit {
                    return Ok(exit);
                }
                host = next;
                0
            }
            // Real time: the plant steps on its own grid of deadlines.
            (None, _) => {
                if now >= next_tick {
                    if let Some(exit) = server.step()? {
                        return Ok(exit);
                    }
                    server.send_outgoing(pty.io())?;
                    next_tick += dt_ns;
                    if now > next_tick + 100 * dt_ns {
                        // Far behind (the machine stalled): resume from now rather than
                        // fast-forward.
                        next_tick = now + dt_ns;
                    }
                    continue;
                }
                next_tick - now
            }
            // Lockstep, waiting for the host's frames (the plant waits too) or, once it has
            // gone and the plant has settled, for the next host.
            (Some(_), _) => HOST_POLL_NS,
        };
        let read = match pty.io().wait_readable(wait_ns) {
            Ok(Readiness::Readable) => pty.io().read_available(&mut rx),
            Ok(Readiness::Timeout | Readiness::Interrupted) => continue,
            Err(e) => Err(e),
        };
        let n = match read {
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::BrokenPipe && pty.slave_released() => {
                host = host.hung_up(server.device.time_ns);
                if host == Host::Gone {
                    // The hang-up stays readable while no client holds the slave: wait
                    // between looks instead of spinning on it (in real time, until the
                    // plant's next step at most).
                    let pause = match server.lockstep_steps {
                        Some(_) => HOST_POLL_NS,
                        None => next_tick.saturating_sub(now_ns()).min(HOST_POLL_NS),
                    };
                    std::thread::sleep(std::time::Duration::from_nanos(pause));
                }
                continue;
            }
            Err(e) => return Err(e),
        };
        if n == 0 {
            continue;
        }
        // The host holds the slave now: from here on its close is a hang-up the master sees,
        // which releases the plant to run on.
        pty.release_slave();
        if host != Host::Connected {
            server.parser = Parser::new();
        }
        host = Host::Connected;
        if let Some(exit) = server.answer(pty.io(), &rx[..n])? {
            return Ok(exit);
        }
    }
}

/// What [`serve`] keeps between the host's frames.
struct Server<'a> {
    device: &'a mut Device,
    truth: &'a mut Option<TrueState>,
    clock: SimClock,
    lockstep_steps: Option<u64>,
    // The breakpoint's arm angle until it fires (`EmulatorConfig::pause_at_arm`).
    pause_at_arm: Option<f64>,
    parser: Parser,
    record: Option<BufWriter<File>>,
    out: [u8; MAX_FRAME],
    wire: Vec<u8>,
}

impl Server<'_> {
    /// One simulation step; `Some` when the emulator must end.
    fn step(&mut self) -> io::Result<Option<EmulatorExit>> {
        self.clock.step(self.device, self.truth)
    }

    /// Stops the process (SIGSTOP) the first time the true arm is past the breakpoint's angle
    /// and moving outwards, after a true-state row of that state (`EmulatorConfig::
    /// pause_at_arm`); it goes on when resumed (SIGCONT).
    fn pause_at_breakpoint(&mut self) -> io::Result<()> {
        let Some(angle) = self.pause_at_arm else {
            return Ok(());
        };
        let [theta, rate, _, _] = self.device.state();
        if theta.abs() > angle && theta * rate > 0.0 {
            self.pause_at_arm = None;
            if let Some(truth) = self.truth.as_mut() {
                truth.row(self.device)?;
            }
            // SAFETY: raise only sends a signal to this process.
            unsafe { libc::raise(libc::SIGSTOP) };
        }
        Ok(())
    }

    /// Writes the frames the firmware sent on its own, through the configured faults.
    fn send_outgoing(&mut self, io: &Fd) -> io::Result<()> {
        while let Some(len) = self.device.take_outgoing(&mut self.out) {
            self.device.inject_faults(&self.out[..len], &mut self.wire);
            if !self.wire.is_empty() {
                io.write_all(&self.wire)?;
            }
        }
        Ok(())
    }

    /// A batch of the plant run on, unpaced, after the host hung up at simulated time
    /// `since_ns`, the plant having rested for `rest_ns`: the host's state after it (still
    /// running on, or gone once the plant rested for [`RUN_ON_REST_S`] or ran on for
    /// [`RUN_ON_MAX_S`]), or the emulator's end.
    fn run_on(&mut self, since_ns: u64, rest_ns: u64) -> io::Result<(Option<EmulatorExit>, Host)> {
        let mut rest_ns = rest_ns;
        for _ in 0..RUN_ON_BATCH {
            if let Some(exit) = self.step()? {
                return Ok((Some(exit), Host::Gone));
            }
            rest_ns = if self.device.resting() {
                rest_ns + self.clock.dt_ns
            } else {
                0
            };
            let ran_s = (self.device.time_ns - since_ns) as f64 * 1e-9;
            if rest_ns as f64 * 1e-9 >= RUN_ON_REST_S || ran_s >= RUN_ON_MAX_S {
                return Ok((None, Host::Gone));
            }
        }
        // Frames the firmware sent on its own have no reader: dropped, as the host's close
        // drops them on a rig.
        while self.device.take_outgoing(&mut self.out).is_some() {}
        Ok((None, Host::RunningOn { since_ns, rest_ns }))
    }

    /// Hands the host's `bytes` to the firmware and answers them: in lockstep a sample request
    /// first advances the plant by one host period, and a reply the faults lose is followed
    /// by its [`STATUS_NO_SAMPLE`] marker. `Some` when the emulator must end.
    fn answer(&mut self, io: &Fd, bytes: &[u8]) -> io::Result<Option<EmulatorExit>> {
        let mut error = None;
        for &byte in bytes {
            self.parser.push(byte);
            // Rejected candidates go to the firmware too: it reports them with RX_ERROR in the
            // next measurement and disables the motor on a frame of another version.
            while let Some(event) = self.parser.poll_event() {
                let mut lockstep_request = None;
                if let Event::Frame(frame) = event {
                    if let (Some(steps), Message::SampleRequest) =
                        (self.lockstep_steps, frame.message)
                    {
                        // One host period of the plant under the command in force, then the
                        // answer: the measurement a sampled loop sees at its next deadline.
                        for _ in 0..steps {
                            if let Some(exit) = self.step()? {
                                return Ok(Some(exit));
                            }
                        }
                        self.pause_at_breakpoint()?;
                        if let Err(e) = self.send_outgoing(io) {
                            error.get_or_insert(e);
                        }
                        lockstep_request = Some(frame.seq);
                    }
                    let t = self.device.time_s();
                    if self.clock.first_command_at.is_none()
                        && matches!(frame.message, Message::Command(_))
                    {
                        self.clock.first_command_at = Some(t);
                    }
                    if let Err(e) = write_record(&mut self.record, t, &frame) {
                        error.get_or_insert(e);
                    }
                }
                if let Reply::Bytes(len) = self.device.handle(event, &mut self.out) {
                    let intact = self.device.inject_faults(&self.out[..len], &mut self.wire);
                    if let (false, Some(seq)) = (intact, lockstep_request) {
                        // The lost reply's marker follows whatever of it went out.
                        let m = self.device.lost_reply_marker(seq, &mut self.out);
                        self.wire.extend_from_slice(&self.out[..m]);
                    }
                    if !self.wire.is_empty() {
                        if let Err(e) = io.write_all(&self.wire) {
                            error.get_or_insert(e);
                        }
                    }
                }
            }
        }
        match error {
            Some(e) => Err(e),
            None => Ok(None),
        }
    }
}

/// Where the emulator's host is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Host {
    /// No frame yet. In lockstep the plant waits for the host's first frame, so that a
    /// lockstep run is the same sequence of plant steps and noise draws however long the host
    /// took to start.
    Awaited,
    /// A host holds the port (in lockstep it paces the plant, one period per sample request).
    Connected,
    /// The host hung up at simulated time `since_ns`; the plant runs on, unpaced, and has
    /// rested for `rest_ns`.
    RunningOn { since_ns: u64, rest_ns: u64 },
    /// The host hung up and the plant has run on to rest: it waits for the next host.
    Gone,
}

impl Host {
    /// The state after the port reported a hang-up at simulated time `now_ns`.
    fn hung_up(self, now_ns: u64) -> Self {
        match self {
            Self::Connected => Self::RunningOn {
                since_ns: now_ns,
                rest_ns: 0,
            },
            // Before any host (the slave still held, so never), while running on, or gone.
            other => other,
        }
    }
}

/// Plant steps between looks at the port while a lockstep emulator runs on.
const RUN_ON_BATCH: usize = 200;

/// How often (ns) a lockstep emulator without a host looks for one.
const HOST_POLL_NS: u64 = 5_000_000;

/// The simulation's own clock: one step of the plant and the ends it can bring (the
/// emulator's `--duration`, the vanish fault).
struct SimClock {
    dt_ns: u64,
    duration: Option<f64>,
    vanish_after: Option<f64>,
    first_command_at: Option<f64>,
}

impl SimClock {
    /// Advances the plant by one simulation step and records it; `Some` when the emulator
    /// must end.
    fn step(
        &self,
        device: &mut Device,
        truth: &mut Option<TrueState>,
    ) -> io::Result<Option<EmulatorExit>> {
        device.advance(self.dt_ns);
        if let Some(t) = truth.as_mut() {
            t.sample(device)?;
        }
        let t = device.time_s();
        if self.duration.is_some_and(|d| t >= d) {
            return Ok(Some(EmulatorExit::Finished));
        }
        if let (Some(v), Some(t0)) = (self.vanish_after, self.first_command_at) {
            if t - t0 >= v {
                return Ok(Some(EmulatorExit::Vanished));
            }
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests;
