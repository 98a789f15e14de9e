//! A device emulator: the device side of protocol v1 over a pseudo-terminal, with the pendulum
//! simulated in real time at 1 kHz and injectable faults.
//!
//! The emulated firmware behaves as `docs/protocol.md` asks of a real one: it samples the
//! encoders when a sample request arrives and answers at once; it applies the last command's
//! voltage only while the command enables the driver and is fresh (its own watchdog zeroes the
//! motor when commands stop); and it reports what it applies.
//!
//! Until the first enabling command arrives the pendulum is held still at its initial pose, the
//! way an operator holds it upright before the loop takes over; `hold_until_enabled = false`
//! lets it fall from the start.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use crate::plant::{Model, PlantSim};
use crate::protocol::{
    encode, Command, Frame, Measurement, Message, Parser, MAX_FRAME, STATUS_ENABLED,
    STATUS_RX_ERROR, STATUS_WATCHDOG,
};
use crate::serial::{Fd, Pty, Readiness};
use crate::timing::now_ns;

/// Settings of the emulated device and of the faults it injects.
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorConfig {
    /// Physical parameters of the simulated pendulum.
    pub model: Model,
    /// Simulation step rate (Hz).
    pub sim_rate_hz: f64,
    /// Arm encoder counts per revolution.
    pub arm_counts_per_rev: u32,
    /// Pendulum encoder counts per revolution (zero hanging down).
    pub pendulum_counts_per_rev: u32,
    /// Initial arm angle (rad).
    pub initial_arm: f64,
    /// Initial pendulum angle from upright (rad).
    pub initial_pendulum: f64,
    /// Hold the pendulum still until the first enabling command.
    pub hold_until_enabled: bool,
    /// The device watchdog: zero the motor when no command arrived for this long (s).
    pub command_timeout_s: f64,
    /// Standard deviation of Gaussian noise added to each encoder reading (counts).
    pub noise_counts: f64,
    /// Probability that a measurement is not sent.
    pub drop_rate: f64,
    /// Probability that a measurement is corrupted on the wire (a flipped byte, or garbage
    /// bytes inserted before it).
    pub corrupt_rate: f64,
    /// Close the device this long after the first command (s): a vanished USB device.
    pub vanish_after_s: Option<f64>,
    /// Seed of the fault and noise generator.
    pub seed: u64,
    /// Stop after this long (s).
    pub duration_s: Option<f64>,
    /// CSV file receiving every command the device accepted (`t_s,seq,voltage_mv,flags`).
    pub record: Option<PathBuf>,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        Self {
            model: Model::Paper,
            sim_rate_hz: 1000.0,
            arm_counts_per_rev: 2048,
            pendulum_counts_per_rev: 2048,
            initial_arm: 0.0,
            initial_pendulum: 0.05,
            hold_until_enabled: true,
            command_timeout_s: 0.05,
            noise_counts: 0.0,
            drop_rate: 0.0,
            corrupt_rate: 0.0,
            vanish_after_s: None,
            seed: 1,
            duration_s: None,
            record: None,
        }
    }
}

impl EmulatorConfig {
    /// Checks the values; the error names the command-line flag.
    pub fn validate(&self) -> Result<(), String> {
        let prob = |name: &str, p: f64| {
            if (0.0..=1.0).contains(&p) {
                Ok(())
            } else {
                Err(format!("{name}: must be a probability in [0, 1], got {p}"))
            }
        };
        prob("--drop-rate", self.drop_rate)?;
        prob("--corrupt-rate", self.corrupt_rate)?;
        if !(self.noise_counts.is_finite() && self.noise_counts >= 0.0) {
            return Err(format!(
                "--noise: must be a non-negative number of counts, got {}",
                self.noise_counts
            ));
        }
        if !(self.sim_rate_hz.is_finite() && (100.0..=100_000.0).contains(&self.sim_rate_hz)) {
            return Err(format!(
                "--sim-rate: must be in [100, 100000] Hz, got {}",
                self.sim_rate_hz
            ));
        }
        if !(self.command_timeout_s.is_finite() && self.command_timeout_s > 0.0) {
            return Err(format!(
                "--command-timeout: must be positive, got {}",
                self.command_timeout_s
            ));
        }
        for (name, v) in [
            ("--initial-arm", self.initial_arm),
            ("--initial-pendulum", self.initial_pendulum),
        ] {
            if !v.is_finite() {
                return Err(format!("{name}: must be finite, got {v}"));
            }
        }
        for (name, v) in [
            ("--vanish-after", self.vanish_after_s),
            ("--duration", self.duration_s),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!(
                        "{name}: must be a non-negative number of seconds, got {v}"
                    ));
                }
            }
        }
        if self.arm_counts_per_rev == 0 || self.pendulum_counts_per_rev == 0 {
            return Err("--counts-per-rev: must be positive".into());
        }
        Ok(())
    }
}

/// The emulated firmware: protocol handling, the motor driver and the encoders, without I/O.
#[derive(Debug)]
pub struct Device {
    cfg: EmulatorConfig,
    plant: PlantSim,
    rng: StdRng,
    noise: Normal<f64>,
    seq: u16,
    command: Command,
    last_command_s: Option<f64>,
    released: bool,
    watchdog_tripped: bool,
    rx_error: bool,
    seen_errors: u64,
    time_s: f64,
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
    /// A device with the plant at its initial pose, at rest.
    pub fn new(cfg: EmulatorConfig) -> Self {
        let plant = PlantSim::new(cfg.model, cfg.initial_arm, cfg.initial_pendulum);
        let released = !cfg.hold_until_enabled;
        Self {
            rng: StdRng::seed_from_u64(cfg.seed),
            noise: Normal::new(0.0, cfg.noise_counts.max(0.0)).expect("validated"),
            plant,
            seq: 0,
            command: Command::STOP,
            last_command_s: None,
            released,
            watchdog_tripped: false,
            rx_error: false,
            seen_errors: 0,
            time_s: 0.0,
            cfg,
        }
    }

    /// Simulated time (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Plant state `[θ, θ̇, α, α̇]`.
    pub fn state(&self) -> [f64; 4] {
        self.plant.state()
    }

    /// Whether any command has arrived.
    pub fn first_command_seen(&self) -> bool {
        self.last_command_s.is_some()
    }

    /// The voltage the driver applies now: the last command's while it enables the driver and
    /// is fresh, else zero.
    pub fn applied_voltage(&self) -> f64 {
        match self.last_command_s {
            Some(t) if self.command.enabled() && self.time_s - t <= self.cfg.command_timeout_s => {
                self.command.voltage_mv as f64 / 1000.0
            }
            _ => 0.0,
        }
    }

    /// Advances the simulation by `dt` seconds.
    pub fn advance(&mut self, dt: f64) {
        if self.command.enabled()
            && self
                .last_command_s
                .is_some_and(|t| self.time_s - t > self.cfg.command_timeout_s)
        {
            self.watchdog_tripped = true;
        }
        let u = self.applied_voltage();
        if self.released {
            self.plant.step(u, dt);
        }
        self.time_s += dt;
    }

    /// Notes that a corrupt frame was received (reported in the next measurement's status).
    pub fn note_rx_errors(&mut self, total_errors: u64) {
        if total_errors > self.seen_errors {
            self.seen_errors = total_errors;
            self.rx_error = true;
        }
    }

    fn encoder(&mut self, angle: f64, cpr: u32) -> i32 {
        let mut counts = angle * cpr as f64 / std::f64::consts::TAU;
        if self.cfg.noise_counts > 0.0 {
            counts += self.noise.sample(&mut self.rng);
        }
        counts.round().clamp(i32::MIN as f64, i32::MAX as f64) as i32
    }

    /// Handles one frame from the host; a sample request writes the measurement into `out`.
    pub fn handle(&mut self, frame: &Frame, out: &mut [u8; MAX_FRAME]) -> Reply {
        match frame.message {
            Message::Command(c) => {
                self.command = c;
                self.last_command_s = Some(self.time_s);
                self.watchdog_tripped = false;
                if c.enabled() {
                    self.released = true;
                }
                Reply::None
            }
            Message::SampleRequest => {
                let [theta, _, alpha, _] = self.plant.state();
                let arm_counts = self.encoder(theta, self.cfg.arm_counts_per_rev);
                let pendulum_counts = self.encoder(
                    alpha + std::f64::consts::PI,
                    self.cfg.pendulum_counts_per_rev,
                );
                let u = self.applied_voltage();
                let mut status = 0;
                if u != 0.0 || (self.command.enabled() && !self.watchdog_tripped) {
                    status |= STATUS_ENABLED;
                }
                if self.watchdog_tripped {
                    status |= STATUS_WATCHDOG;
                }
                if self.rx_error {
                    status |= STATUS_RX_ERROR;
                    self.rx_error = false;
                }
                let m = Measurement {
                    ack_seq: frame.seq,
                    arm_counts,
                    pendulum_counts,
                    applied_mv: (u * 1000.0).round() as i16,
                    status,
                    device_time_us: (self.time_s * 1e6) as u64 as u32,
                };
                let seq = self.seq;
                self.seq = self.seq.wrapping_add(1);
                Reply::Bytes(encode(
                    &Frame {
                        seq,
                        message: Message::Measurement(m),
                    },
                    out,
                ))
            }
            Message::Measurement(_) => Reply::None,
        }
    }

    /// Applies the configured faults to an outgoing frame and writes what remains into `wire`
    /// (which is cleared first).
    pub fn inject_faults(&mut self, frame: &[u8], wire: &mut Vec<u8>) {
        wire.clear();
        if self.cfg.drop_rate > 0.0 && self.rng.gen_bool(self.cfg.drop_rate) {
            return;
        }
        if self.cfg.corrupt_rate > 0.0 && self.rng.gen_bool(self.cfg.corrupt_rate) {
            if self.rng.gen_bool(0.5) {
                // Garbage before an intact frame: the parser must skip it and still decode it.
                let n = self.rng.gen_range(1..=8);
                for _ in 0..n {
                    let b = if self.rng.gen_bool(0.3) {
                        crate::protocol::SYNC0
                    } else {
                        self.rng.gen()
                    };
                    wire.push(b);
                }
                wire.extend_from_slice(frame);
            } else {
                wire.extend_from_slice(frame);
                let i = self.rng.gen_range(0..wire.len());
                let flip: u8 = self.rng.gen_range(1..=255);
                wire[i] ^= flip;
            }
            return;
        }
        wire.extend_from_slice(frame);
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
/// answered as soon as they arrive.
pub fn run(cfg: EmulatorConfig, pty: Pty, stop: &AtomicBool) -> io::Result<EmulatorExit> {
    let mut record = match &cfg.record {
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
    let dt = dt_ns as f64 * 1e-9;
    let duration = cfg.duration_s;
    let vanish_after = cfg.vanish_after_s;
    let mut device = Device::new(cfg);
    let mut parser = Parser::new();
    let mut rx = [0u8; 256];
    let mut out = [0u8; MAX_FRAME];
    let mut wire = Vec::with_capacity(MAX_FRAME + 16);
    let start = now_ns();
    let mut next_tick = start + dt_ns;
    let mut first_command_at: Option<f64> = None;
    let io: &Fd = pty.io();
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(EmulatorExit::Stopped);
        }
        let now = now_ns();
        if now >= next_tick {
            device.advance(dt);
            next_tick += dt_ns;
            if now > next_tick + 100 * dt_ns {
                // Far behind (the machine stalled): resume from now rather than fast-forward.
                next_tick = now + dt_ns;
            }
            let t = device.time_s();
            if duration.is_some_and(|d| t >= d) {
                return Ok(EmulatorExit::Finished);
            }
            if let (Some(v), Some(t0)) = (vanish_after, first_command_at) {
                if t - t0 >= v {
                    drop(pty);
                    return Ok(EmulatorExit::Vanished);
                }
            }
            continue;
        }
        match io.wait_readable(next_tick - now)? {
            Readiness::Readable => {}
            Readiness::Timeout | Readiness::Interrupted => continue,
        }
        let n = io.read_available(&mut rx)?;
        let mut error = None;
        let t = device.time_s();
        for &byte in &rx[..n] {
            parser.push(byte);
            while let Some(frame) = parser.poll() {
                // A bad frame ahead of this one in the same read is reported in this reply,
                // the next measurement, as protocol.md asks.
                device.note_rx_errors(parser.stats().errors());
                if first_command_at.is_none() && matches!(frame.message, Message::Command(_)) {
                    first_command_at = Some(t);
                }
                if let Err(e) = write_record(&mut record, t, &frame) {
                    error.get_or_insert(e);
                }
                if let Reply::Bytes(len) = device.handle(&frame, &mut out) {
                    device.inject_faults(&out[..len], &mut wire);
                    if !wire.is_empty() {
                        if let Err(e) = io.write_all(&wire) {
                            error.get_or_insert(e);
                        }
                    }
                }
            }
        }
        device.note_rx_errors(parser.stats().errors());
        if let Some(e) = error {
            return Err(e);
        }
    }
}
