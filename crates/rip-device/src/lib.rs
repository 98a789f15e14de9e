//! # rip-device
//!
//! What the pendulum's microcontroller does, independent of its hardware: protocol v1 command
//! handling (`docs/protocol.md`, "What the device must do"), enabling and disabling the motor
//! driver, the command watchdog, clamping to the device's own voltage limit, sequence numbers,
//! status flags, multi-turn encoder positions from 16-bit timer counters, the voltage →
//! PWM duty and direction mapping, and what the bridge does to a motor it does not drive.
//!
//! # A motor that is not driven: open or braked
//!
//! An H-bridge whose driver is disabled leaves the motor's windings **open**: no current flows,
//! back-EMF produces no torque, and a moving arm coasts until friction stops it. A bridge
//! that **brakes** shorts the windings through its low-side switches: the back-EMF drives the
//! current `i = −k_m ω / R_m` and the torque `−k_t k_m ω / R_m` opposes the motion (the same
//! as driving 0 V). [`Pwm`] says which of the three the bridge does; a board that cannot
//! brake sets [`Config::can_brake`] false and its motor is open whenever it is not driven.
//! The device brakes on [`COMMAND_BRAKE`], and on its own when
//! it stops the motor itself (the command watchdog, a frame of another version), so that a
//! host that went silent while the arm moved does not leave it to coast; a plain disabled
//! command (the stop frame, power-up) leaves the windings open; a driver fault opens them.
//!
//! The STM32 firmware (`firmware/`) and `rip-rt emulate` both run this crate, so every
//! end-to-end test of the PC loop against the emulator exercises the firmware's logic with only
//! the hardware replaced by a simulated plant. It is `no_std`, allocation-free and never panics.
//!
//! A main loop reads the hardware into [`Inputs`], calls [`Device::tick`] at least every
//! millisecond or so (and in any case more often than every 2³¹ µs, half the wrap of the
//! microsecond clock), feeds received bytes through [`Device::receive`], and drives the
//! H-bridge from [`Device::pwm`].
//!
//! # Onboard mode (protocol v2)
//!
//! A device built with an [`Onboard`] controller also runs the control law itself. The host
//! uploads a design image in chunks into the controller's buffer ([`Onboard::buffer`]):
//! `UploadBegin` announces its length (refused beyond the buffer), each `UploadChunk` must
//! start exactly where the previous one ended (an out-of-order or repeated chunk is refused and
//! the ack names the expected offset, so the host resumes there), a chunk running past the
//! announced length is refused, and `UploadCommit` carries the image's length and CRC-32: the
//! device recomputes the CRC over what it holds and only then hands the image to
//! [`Onboard::load`]. `OnboardStart` starts the loop with the device's own limits.
//!
//! Each controller step ([`Device::onboard_step`], from a timer interrupt on the firmware)
//! works from the device's own encoder positions and checks, in this order, that the driver
//! reports no fault, that a valid host frame arrived within the host timeout, that the arm and
//! the pendulum are inside their limits, and that the move is finite; it then applies the move
//! clamped to the device's voltage limit. Any failed check stops onboard mode: 0 V, the driver
//! disabled, and the brake where the board has one (not on a driver fault, as for v1), and the
//! stop's reason is sent in a final telemetry record. When the start said the wiring is
//! verified (protocol v3) and the law has a stop of its own ([`Onboard::begin_stop`]: the
//! image's stop's design, [`law`]'s "The device's stop"), a stop on the device's own account
//! (a limit, a silent host, a non-finite move) first runs that stop, at most
//! `rip_control::stop::MAX_STOP_S`, telemetry carrying its reason from its first step; a
//! driver fault during it disables the driver at once, a host command or onboard stop ends it,
//! and an onboard start meanwhile is refused as busy. A command frame from the host also ends
//! onboard mode (so v1's stop frame stops it), and so does a frame of another version. A step
//! that overruns its period ([`Device::record_step_cycles`]) is a fault too. Should the steps
//! themselves stop (a hung interrupt), the v1 command watchdog stops the motor, since each step
//! counts as the command that the watchdog waits for.
//!
//! # The watchdog's stop (protocol v3)
//!
//! In host mode the command watchdog shorts the windings, unless the host armed the device's
//! own stop for it with a [`WatchdogStop`]: the wiring verified, a loaded image with a stop's
//! design whose period the board's timer runs ([`Config::onboard_period_us`]), and the
//! encoder zeros of the host's calibration. Then a watchdog trip starts that
//! stop as an onboard run already stopping on the host's silence (`ONBOARD_HOST_SILENT`), on
//! angles from those zeros, stepped by [`Device::onboard_step`] like every onboard run (the
//! firmware's timer runs while [`Device::onboard_running`]) and reported by telemetry every
//! [`STOP_PERIOD_S`](rip_control::stop::STOP_PERIOD_S); a host command ends it (the host takes
//! over). An upload, an onboard start or the plain stop frame (the end of the host's run)
//! disarms it. A driver fault read between two steps of an onboard run, even one that has
//! cleared by the next step, stops the run as a fault.

#![no_std]
#![forbid(unsafe_code)]

pub mod law;
mod onboard;

pub use onboard::{DesignRefused, NoOnboard, Onboard};
use onboard::{Run, Upload};
use rip_control::stop::{BrakeCommand, MAX_STOP_S};

use rip_protocol::{
    crc32, encode, Ack, Command, Event, Frame, Measurement, Message, OnboardStart, Parser, PilMove,
    PilStep, Rejection, Telemetry, UploadChunk, UploadCommit, WatchdogStop, ACK_BAD_SETTINGS,
    ACK_BUSY, ACK_CRC_MISMATCH, ACK_DESIGN_REFUSED, ACK_LENGTH_MISMATCH, ACK_NO_DESIGN,
    ACK_NO_UPLOAD, ACK_OK, ACK_OUT_OF_ORDER, ACK_REFUSED, ACK_TOO_LARGE, COMMAND_BRAKE,
    COMMAND_ENABLE, MAX_FRAME, ONBOARD_ARM_LIMIT, ONBOARD_BAD_MOVE, ONBOARD_DRIVER_FAULT,
    ONBOARD_HOST_SILENT, ONBOARD_IDLE, ONBOARD_OVERRUN, ONBOARD_PENDULUM_LIMIT, ONBOARD_PROTOCOL,
    ONBOARD_RUNNING, ONBOARD_STOPPED, ONBOARD_WIRING_VERIFIED, PIL_PHASES, PIL_PHASE_MASK,
    PIL_PHASE_SHIFT, PIL_RESET, PIL_STOP, STATUS_BRAKING, STATUS_ENABLED, STATUS_FAULT,
    STATUS_ONBOARD, STATUS_RX_ERROR, STATUS_WATCHDOG,
};

/// The device's fixed settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// Command watchdog: with no valid command for longer than this (µs) the motor gets 0 V and
    /// the driver is disabled. `docs/protocol.md` asks for 50 ms (5 periods of 10 ms).
    pub command_timeout_us: u32,
    /// The device's own voltage limit (mV): commands beyond ±limit are clamped. At most
    /// `supply_mv`, since the bridge cannot apply more than its supply.
    pub voltage_limit_mv: u16,
    /// H-bridge supply voltage (mV): the voltage at 100 % duty.
    pub supply_mv: u16,
    /// The bridge can brake (short the motor's windings) while not driving it (module docs).
    pub can_brake: bool,
    /// The shortest and longest onboard step period (µs) the board's timer runs: outside it
    /// the device's own stop on the command watchdog is the short (crate docs, "The
    /// watchdog's stop").
    pub onboard_period_us: [u32; 2],
}

impl Config {
    /// 50 ms watchdog, a bridge that brakes, any onboard period, and the motor's rated voltage
    /// ([`rip_control::INPUT_LIMIT_MV`], 12 V) as both the limit and the supply: the reference
    /// rig feeds its bridge at the motor's rating, so full duty is the rated voltage.
    pub const DEFAULT: Config = Config {
        command_timeout_us: 50_000,
        voltage_limit_mv: rip_control::INPUT_LIMIT_MV,
        supply_mv: rip_control::INPUT_LIMIT_MV,
        can_brake: true,
        onboard_period_us: [1, u32::MAX],
    };

    /// The same settings with the limit reduced to the supply where it exceeds it, and a zero
    /// watchdog time raised to 1 µs, so that every `Config` a [`Device`] holds is usable.
    pub const fn sanitized(self) -> Config {
        Config {
            command_timeout_us: if self.command_timeout_us == 0 {
                1
            } else {
                self.command_timeout_us
            },
            voltage_limit_mv: if self.voltage_limit_mv > self.supply_mv {
                self.supply_mv
            } else {
                self.voltage_limit_mv
            },
            supply_mv: self.supply_mv,
            can_brake: self.can_brake,
            onboard_period_us: self.onboard_period_us,
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A 32-bit multi-turn position from a 16-bit hardware counter (a timer in encoder mode).
///
/// The counter wraps every 65 536 counts; the position accumulates the signed difference
/// between successive readings, `Δ = (raw − last) mod 2¹⁶` read as an `i16`, which is the true
/// movement as long as the shaft moves fewer than 32 768 counts between two readings (16
/// revolutions of a 2048-count encoder: far more than a pendulum does in a millisecond). The
/// position itself wraps at ±2³¹ counts (a million revolutions at 2048 counts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EncoderCounter {
    last: u16,
    position: i32,
}

impl EncoderCounter {
    /// A counter whose current raw reading `raw` stands for `position`.
    pub const fn new(raw: u16, position: i32) -> Self {
        Self {
            last: raw,
            position,
        }
    }

    /// Takes a new raw reading and returns the position.
    pub fn update(&mut self, raw: u16) -> i32 {
        let delta = raw.wrapping_sub(self.last) as i16;
        self.last = raw;
        self.position = self.position.wrapping_add(delta as i32);
        self.position
    }

    /// The position at the last reading.
    pub const fn position(&self) -> i32 {
        self.position
    }
}

/// The hardware readings a device step works from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Inputs {
    /// Free-running microsecond clock (wraps around).
    pub now_us: u32,
    /// Raw 16-bit counters of the arm and the pendulum encoder.
    pub encoders: [u16; 2],
    /// The motor driver's fault line is asserted.
    pub driver_fault: bool,
}

/// Which way the H-bridge drives the motor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Positive voltage: the arm turns in the positive θ direction.
    Forward,
    /// Negative voltage.
    Reverse,
}

/// The H-bridge drive: duty cycle, direction, whether it drives the motor, and whether it
/// brakes a motor it does not drive (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pwm {
    /// Compare value, `0 ..= max_duty`.
    pub duty: u16,
    /// Direction pin level.
    pub direction: Direction,
    /// The bridge drives the motor at `duty`. When false, `duty` is 0.
    pub enable: bool,
    /// Not driving, the bridge shorts the windings (brake) rather than leaving them open.
    /// Only with `enable` false.
    pub brake: bool,
}

impl Pwm {
    /// The safe state: driver disabled, duty 0, windings open.
    pub const OFF: Pwm = Pwm {
        duty: 0,
        direction: Direction::Forward,
        enable: false,
        brake: false,
    };

    /// Not driving, windings shorted: duty 0.
    pub const BRAKE: Pwm = Pwm {
        duty: 0,
        direction: Direction::Forward,
        enable: false,
        brake: true,
    };
}

/// The device: command state, watchdog, status and encoder positions, and with an [`Onboard`]
/// controller `C` the design upload and the onboard loop.
#[derive(Debug, Clone)]
pub struct Device<C = NoOnboard> {
    cfg: Config,
    seq: u16,
    command: Command,
    last_command_us: u32,
    watchdog: bool,
    rx_error: bool,
    fault: bool,
    // Not driving, short the windings (module docs); cleared by a fault or any command that is
    // not a brake command.
    brake: bool,
    arm: EncoderCounter,
    pendulum: EncoderCounter,
    commands: u32,
    onboard: C,
    upload: Option<Upload>,
    design_loaded: bool,
    run: Option<Run>,
    onboard_state: u8,
    // Host mode's stop on the command watchdog (`WatchdogStop`): `None` is the short.
    watchdog_stop: Option<WatchdogStop>,
    pil_steps: u32,
    // A free-running up-counter and the shift that turns its differences into cycles.
    cycle_counter: Option<(fn() -> u32, u8)>,
}

impl Device {
    /// A device at power-up: driver disabled, encoder positions zero at the current readings.
    pub fn new(cfg: Config, inputs: &Inputs) -> Self {
        Self::with_positions(cfg, inputs, [0, 0])
    }

    /// A device whose current encoder readings stand for `positions` (arm, pendulum).
    pub fn with_positions(cfg: Config, inputs: &Inputs, positions: [i32; 2]) -> Self {
        Device::with_onboard(cfg, inputs, positions, NoOnboard)
    }
}

impl<C: Onboard> Device<C> {
    /// A device with the onboard controller `onboard`, whose current encoder readings stand
    /// for `positions` (arm, pendulum).
    pub fn with_onboard(cfg: Config, inputs: &Inputs, positions: [i32; 2], onboard: C) -> Self {
        Self {
            cfg: cfg.sanitized(),
            seq: 0,
            command: Command::STOP,
            last_command_us: inputs.now_us,
            watchdog: false,
            rx_error: false,
            fault: inputs.driver_fault,
            brake: false,
            arm: EncoderCounter::new(inputs.encoders[0], positions[0]),
            pendulum: EncoderCounter::new(inputs.encoders[1], positions[1]),
            commands: 0,
            onboard,
            upload: None,
            design_loaded: false,
            run: None,
            onboard_state: ONBOARD_IDLE,
            watchdog_stop: None,
            pil_steps: 0,
            cycle_counter: None,
        }
    }

    /// The device at power-up with encoder readings and positions 0 at time 0 (a `const`
    /// constructor, so that a firmware can hold a large controller in a static without a
    /// copy on its stack).
    pub const fn at_power_up(cfg: Config, onboard: C) -> Self {
        Self {
            cfg: cfg.sanitized(),
            seq: 0,
            command: Command::STOP,
            last_command_us: 0,
            watchdog: false,
            rx_error: false,
            fault: false,
            brake: false,
            arm: EncoderCounter::new(0, 0),
            pendulum: EncoderCounter::new(0, 0),
            commands: 0,
            onboard,
            upload: None,
            design_loaded: false,
            run: None,
            onboard_state: ONBOARD_IDLE,
            watchdog_stop: None,
            pil_steps: 0,
            cycle_counter: None,
        }
    }

    /// Takes the hardware readings `inputs` as the power-up state: the encoder readings stand
    /// for positions 0, the watchdog counts from `inputs.now_us` (for a device made by
    /// [`at_power_up`](Self::at_power_up) before the hardware could be read).
    pub fn rebase(&mut self, inputs: &Inputs) {
        self.arm = EncoderCounter::new(inputs.encoders[0], 0);
        self.pendulum = EncoderCounter::new(inputs.encoders[1], 0);
        self.last_command_us = inputs.now_us;
        self.fault = inputs.driver_fault;
    }

    /// Gives the device a cycle counter for the [`PilStep`]'s
    /// timing: `counter` counts up and wraps at 2³², and `(b − a) >> shift` is the cycles
    /// between two readings `a`, `b` (a 24-bit down-counter such as SysTick is read as
    /// `(0xFF_FFFF − value) << 8` with `shift` 8).
    pub fn set_cycle_counter(&mut self, counter: fn() -> u32, shift: u8) {
        self.cycle_counter = Some((counter, shift.min(31)));
    }

    /// The settings in force.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Updates the encoder positions, the fault state and the watchdog from `inputs`.
    pub fn tick(&mut self, inputs: &Inputs) {
        self.arm.update(inputs.encoders[0]);
        self.pendulum.update(inputs.encoders[1]);
        self.fault = inputs.driver_fault;
        if self.fault {
            // A driver fault drops the command: after it clears the host must enable again.
            // A faulted bridge is not trusted to switch: open.
            self.command = Command::STOP;
            self.brake = false;
            if let Some(run) = self.run.as_mut() {
                run.faulted = true;
            }
        }
        if self.command.enabled()
            && inputs.now_us.wrapping_sub(self.last_command_us) > self.cfg.command_timeout_us
        {
            // The host went silent while driving: stop the arm rather than let it coast, with
            // the law's stop where the host armed it.
            self.command = Command::STOP;
            self.watchdog = true;
            self.brake = true;
            self.begin_watchdog_stop(inputs.now_us);
        }
    }

    /// Handles one parser event at the instant `inputs` was read; a sample request returns the
    /// measurement frame to send.
    pub fn handle(&mut self, event: Event, inputs: &Inputs) -> Option<Frame> {
        self.tick(inputs);
        if let (Event::Frame(_), Some(run)) = (event, self.run.as_mut()) {
            // Any valid frame shows the host is there (the host-silence watchdog).
            run.last_host_us = inputs.now_us;
        }
        match event {
            Event::Frame(Frame {
                message: Message::Command(c),
                ..
            }) => {
                if self.run.is_some() {
                    // The host takes over: its stop frame stops onboard mode too.
                    self.run = None;
                    self.onboard_state = ONBOARD_STOPPED;
                }
                self.commands = self.commands.wrapping_add(1);
                self.last_command_us = inputs.now_us;
                self.watchdog = false;
                self.command = if self.fault { Command::STOP } else { c };
                self.brake = c.brake() && !self.fault;
                if !c.enabled() && !c.brake() {
                    // The plain stop frame ends the host's run: the watchdog's stop it armed
                    // (and the wiring it checked) ends with it.
                    self.watchdog_stop = None;
                }
                None
            }
            Event::Frame(Frame {
                seq,
                message: Message::SampleRequest,
            }) => {
                let m = Measurement {
                    ack_seq: seq,
                    arm_counts: self.arm.position(),
                    pendulum_counts: self.pendulum.position(),
                    applied_mv: self.voltage_mv(),
                    status: self.take_status(),
                    device_time_us: inputs.now_us,
                };
                Some(self.next_frame(Message::Measurement(m)))
            }
            Event::Frame(Frame {
                seq,
                message: Message::PilStep(p),
            }) => Some(self.pil_step(seq, p)),
            // Device frames: from the host they are a protocol error.
            Event::Frame(Frame {
                message:
                    Message::Measurement(_)
                    | Message::Ack(_)
                    | Message::Telemetry(_)
                    | Message::PilMove(_),
                ..
            }) => {
                self.rx_error = true;
                None
            }
            Event::Frame(Frame { seq, message }) => {
                let (code, value) = self.onboard_request(message, inputs);
                Some(self.next_frame(Message::Ack(Ack {
                    ack_seq: seq,
                    request: message.kind(),
                    code,
                    value,
                })))
            }
            Event::Rejected(Rejection::Version(_)) => {
                if self.run.is_some() {
                    self.run = None;
                    self.onboard_state = ONBOARD_PROTOCOL;
                }
                // The peer speaks another protocol: none of its frames can be trusted. Stop
                // the arm as on a watchdog trip.
                if self.command.enabled() {
                    self.brake = true;
                }
                self.command = Command::STOP;
                self.rx_error = true;
                None
            }
            Event::Rejected(_) => {
                self.rx_error = true;
                None
            }
        }
    }

    /// The device's next frame: its own sequence number and `message`.
    fn next_frame(&mut self, message: Message) -> Frame {
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        Frame { seq, message }
    }

    /// Feeds received bytes through `parser`, handles every event and passes each encoded reply
    /// to `send`.
    pub fn receive(
        &mut self,
        parser: &mut Parser,
        data: &[u8],
        inputs: &Inputs,
        mut send: impl FnMut(&[u8]),
    ) {
        let mut out = [0u8; MAX_FRAME];
        for &byte in data {
            parser.push(byte);
            while let Some(event) = parser.poll_event() {
                if let Some(reply) = self.handle(event, inputs) {
                    let n = encode(&reply, &mut out);
                    send(&out[..n]);
                }
            }
        }
    }

    /// Whether the motor driver is enabled.
    pub fn enabled(&self) -> bool {
        self.command.enabled() && !self.fault
    }

    /// Whether the bridge brakes now: not driving, on a board that can brake, after a brake
    /// command or the device's own stop (module docs).
    pub fn braking(&self) -> bool {
        self.brake && self.cfg.can_brake && !self.enabled() && !self.fault
    }

    /// The voltage applied now (mV): the last command's, clamped to the device's limit, while
    /// the driver is enabled; else 0.
    pub fn voltage_mv(&self) -> i16 {
        if !self.enabled() {
            return 0;
        }
        let limit = self.cfg.voltage_limit_mv.min(i16::MAX as u16) as i16;
        self.command.voltage_mv.clamp(-limit, limit)
    }

    /// The H-bridge drive for a PWM timer whose compare range is `0 ..= max_duty`:
    /// `duty = round(|V| · max_duty / supply)`; not driving, [`Pwm::BRAKE`] while
    /// [`braking`](Self::braking), else [`Pwm::OFF`].
    pub fn pwm(&self, max_duty: u16) -> Pwm {
        if !self.enabled() || self.cfg.supply_mv == 0 {
            return if self.braking() { Pwm::BRAKE } else { Pwm::OFF };
        }
        let v = self.voltage_mv();
        let supply = self.cfg.supply_mv as u32;
        let duty = (v.unsigned_abs() as u32 * max_duty as u32 + supply / 2) / supply;
        Pwm {
            duty: duty.min(max_duty as u32) as u16,
            direction: if v < 0 {
                Direction::Reverse
            } else {
                Direction::Forward
            },
            enable: true,
            brake: false,
        }
    }

    /// The status bits now, without clearing the one-shot `RX_ERROR`.
    pub fn status(&self) -> u8 {
        let mut s = 0;
        if self.enabled() {
            s |= STATUS_ENABLED;
        }
        if self.watchdog {
            s |= STATUS_WATCHDOG;
        }
        if self.rx_error {
            s |= STATUS_RX_ERROR;
        }
        if self.fault {
            s |= STATUS_FAULT;
        }
        if self.braking() {
            s |= STATUS_BRAKING;
        }
        if self.run.is_some() {
            s |= STATUS_ONBOARD;
        }
        s
    }

    fn take_status(&mut self) -> u8 {
        let s = self.status();
        self.rx_error = false;
        s
    }

    /// Encoder positions (arm, pendulum) at the last reading, counts since power-up.
    pub fn positions(&self) -> [i32; 2] {
        [self.arm.position(), self.pendulum.position()]
    }

    /// Commands received since power-up (wraps).
    pub fn commands_received(&self) -> u32 {
        self.commands
    }

    /// The sequence number of the next measurement.
    pub fn next_seq(&self) -> u16 {
        self.seq
    }
}

/// `x` rounded half away from zero, without `std` (`f64::round` needs it); exact for the
/// millivolt range.
fn libm_round(x: f64) -> f64 {
    let t = x as i32 as f64;
    let d = x - t;
    if d >= 0.5 {
        t + 1.0
    } else if d <= -0.5 {
        t - 1.0
    } else {
        t
    }
}
