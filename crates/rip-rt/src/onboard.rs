//! `rip-rt run --onboard`: the controller runs on the device (protocol v2 and v3, `rip-device`'s
//! onboard mode). The host makes the design from the experiment file with the same assembly
//! as the host loop ([`crate::controllers`]) and puts it through the same pre-flight check
//! (`rip_rt::cli` prepares both modes), uploads it as an onboard image
//! ([`rip_device::law`]: the counts → angles conversion and the reference step, the stop's
//! design, then rip-control's design bytes) in acknowledged chunks, commits it with its CRC-32
//! and checks the CRC the device computed. With the pendulum hanging it checks the wiring's
//! sign and waits for the pendulum to be raised ([`wiring`]); it starts onboard mode with the
//! device's own limits in counts, saying whether the wiring was verified (the device's own stop
//! then brakes and holds the arm, `rip_control::stop`; otherwise it shorts the windings), and
//! then only supervises: every period it sends a sample request (the heartbeat the device's
//! host-silence watchdog waits for), logs the telemetry the device streams, and on any end —
//! `--duration`, a signal, a device stop, a silent device — sends the onboard stop and the v1
//! stop frame (0 V, disabled).

pub mod watchdog;
pub mod wiring;

use std::time::{Duration, Instant};

use rip_control::Design as OnboardDesign;
use rip_device::law::{write_image, Sensor};
use rip_protocol::{
    crc32, encode, Command, Frame, Measurement, Message, OnboardStart, Parser, Telemetry,
    UploadBegin, UploadChunk, UploadCommit, ACK_OK, ACK_OUT_OF_ORDER, CHUNK_MAX, COMMAND_BRAKE,
    MAX_FRAME, ONBOARD_RUNNING, STATUS_LOCKSTEP, STATUS_NO_SAMPLE, STATUS_ONBOARD,
};

use crate::config::Config;
use crate::controllers::{self, ControllerKind};
use crate::live::{Bounds, Kind, Live};
use crate::log::{LogWriter, Row};
use crate::serial::{Fd, Readiness};
use crate::step::{StepOutput, FLAG_FALLBACK};

/// Largest onboard image the host builds (the emulator's buffer holds it).
pub const MAX_IMAGE: usize = crate::emulator::ONBOARD_BUFFER;

/// How long the host waits for an ack before repeating the request.
pub const ACK_TIMEOUT: Duration = Duration::from_millis(300);
/// Repeats of one request before the upload is given up.
pub const RETRIES: u32 = 5;
/// Host periods without a reply after which the device counts as gone.
pub const MISSING_LIMIT: u32 = 10;

/// rip-control's design of `kind` as `rip-rt run` would build it: the one assembly at the
/// loop period inside `±safety.voltage_limit` ([`crate::controllers`]), converted by rip-core
/// ([`rip_core::onboard`]), with the `[compensation]` law where there is one.
///
/// # Errors
/// The design's error, naming the controller.
pub fn design(kind: ControllerKind, cfg: &Config) -> Result<OnboardDesign, String> {
    let d = controllers::design(kind, cfg)?;
    let err = |e: &dyn std::fmt::Display| format!("{kind} design for the device: {e}");
    let out = match kind {
        ControllerKind::Lqr => d.lqr().map_err(|e| err(&e))?.control_design(),
        ControllerKind::Lqg => d
            .lqg()
            .map_err(|e| err(&e))?
            .control_design()
            .map_err(|e| err(&e))?,
        ControllerKind::Mpc => d
            .mpc()
            .map_err(|e| err(&e))?
            .control_design()
            .map_err(|e| err(&e))?,
    };
    let mut out = match d.compensation() {
        Some(law) => rip_core::onboard::with_compensation(out, law),
        None => out,
    };
    // A step that overruns its period stops the onboard run, and the device refuses at the
    // commit a design whose worst step does not fit (rip-control's `check_step_budget`, in the
    // image's load), so the host sends one that fits: the QP's iteration bound is the
    // configured one or the largest that fits, whichever is smaller (at the bound the step
    // applies the fallback law, rip-control's crate docs), and a design that does not fit even
    // one iteration is refused here, with the reason the device's refusal cannot give.
    out.max_iterations = out.max_iterations.min(out.fitting_iterations().max(1));
    out.check_step_budget().map_err(|e| err(&e))?;
    Ok(out)
}

/// The counts → angles conversion of `cfg`'s `[device]` and its `[reference]` step: the
/// onboard image's header.
pub fn sensor(cfg: &Config) -> Sensor {
    let tau = std::f64::consts::TAU;
    let d = &cfg.device;
    Sensor {
        arm_rad_per_count: d.arm_sign * tau / d.arm_counts_per_rev as f64,
        pendulum_rad_per_count: d.pendulum_sign * tau / d.pendulum_counts_per_rev as f64,
        arm_offset: 0.0,
        pendulum_offset: match d.pendulum_zero {
            crate::config::PendulumZero::Down => std::f64::consts::PI,
            crate::config::PendulumZero::Up => 0.0,
        },
        arm_step: cfg.spec.reference.arm_step,
        step_time: cfg.spec.reference.step_time,
    }
}

/// The onboard image of `design` with the conversion of `cfg`'s `[device]`, the `[reference]`
/// step and the stop's design of `cfg` ([`crate::envelope::stop_design`]) for the device's own
/// stop.
///
/// # Errors
/// A design the layout refuses, or an image beyond [`MAX_IMAGE`].
pub fn image(design: &OnboardDesign, cfg: &Config) -> Result<Vec<u8>, String> {
    let stop = crate::envelope::stop_design(cfg);
    let mut buf = vec![0u8; MAX_IMAGE];
    let n = write_image(&sensor(cfg), stop.as_ref(), design, &mut buf)
        .ok_or_else(|| format!("--onboard: the design does not fit {MAX_IMAGE} bytes"))?;
    buf.truncate(n);
    Ok(buf)
}

/// The device's limits in counts around the pendulum's upright position nearest to the
/// measurement `m` (the host's `safety.arm_limit` and `safety.pendulum_limit`), and whether the
/// wiring's sign was `verified` ([`ONBOARD_WIRING_VERIFIED`](rip_protocol::ONBOARD_WIRING_VERIFIED)).
pub fn start_settings(
    cfg: &Config,
    m: &Measurement,
    decimation: u16,
    verified: bool,
) -> OnboardStart {
    // The device's own conversion (the image's header): the upright nearest the measurement.
    let sensor = sensor(cfg);
    let s_arm = sensor.arm_rad_per_count.abs();
    let s_pend = sensor.pendulum_rad_per_count;
    let [_, alpha] = sensor.angles([m.arm_counts, m.pendulum_counts]);
    let center = m.pendulum_counts as f64 - alpha / s_pend;
    OnboardStart {
        decimation: decimation.max(1),
        host_timeout_ms: host_timeout_ms(cfg),
        arm_center: 0,
        arm_limit: (cfg.safety.arm_limit / s_arm).floor() as u32,
        pendulum_center: center.round() as i32,
        pendulum_limit: (cfg.safety.pendulum_limit / s_pend.abs()).floor() as u32,
        flags: if verified {
            rip_protocol::ONBOARD_WIRING_VERIFIED
        } else {
            0
        },
    }
}

/// The device's host-silence watchdog: v1's command watchdog (`rip-device`'s
/// [`Config::DEFAULT`](rip_device::Config::DEFAULT), 50 ms), or five host periods where those
/// are longer, so that a heartbeat may be lost without a stop.
pub fn host_timeout_ms(cfg: &Config) -> u16 {
    let v1 = rip_device::Config::DEFAULT.command_timeout_us as f64 / 1000.0;
    (5.0 * cfg.loop_.period_ms)
        .max(v1)
        .min(u16::MAX as f64)
        .round() as u16
}

/// Why an onboard run ended.
#[derive(Debug)]
pub enum OnboardEnd {
    /// `--duration` elapsed.
    Duration,
    /// A stop signal.
    Signal(crate::stop::StopReason),
    /// The host stopped before the start ([`wiring`]): a failed sign check, a pendulum not
    /// raised in time.
    Host(crate::stop::StopReason),
    /// The device stopped on its own, with this `ONBOARD_*` state.
    Device(u8),
    /// No reply for [`MISSING_LIMIT`] periods.
    Silent,
    /// The upload, commit or start failed.
    Setup(String),
    /// The port failed.
    Io(String),
    /// The log could not be written.
    Log(String),
}

impl OnboardEnd {
    /// The process exit code (rip-rt's one table, [`crate::stop::exit_code`]).
    pub fn exit_code(&self) -> i32 {
        use crate::stop::exit_code as x;
        use rip_protocol as p;
        match self {
            OnboardEnd::Duration => x::FINISHED,
            OnboardEnd::Signal(r) | OnboardEnd::Host(r) => r.exit_code(),
            OnboardEnd::Device(p::ONBOARD_ARM_LIMIT | p::ONBOARD_PENDULUM_LIMIT) => x::ANGLE_LIMIT,
            OnboardEnd::Device(p::ONBOARD_HOST_SILENT) => x::WATCHDOG,
            OnboardEnd::Device(p::ONBOARD_OVERRUN) => x::OVERRUN,
            OnboardEnd::Device(p::ONBOARD_BAD_MOVE) => x::CONTROLLER_FAULT,
            OnboardEnd::Device(_) => x::DEVICE_FAULT,
            OnboardEnd::Silent | OnboardEnd::Io(_) => x::DEVICE_LOST,
            OnboardEnd::Setup(_) => x::SETUP,
            OnboardEnd::Log(_) => x::LOG_ERROR,
        }
    }
}

impl std::fmt::Display for OnboardEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use rip_protocol as p;
        match self {
            OnboardEnd::Duration => f.write_str("finished (--duration)"),
            OnboardEnd::Signal(r) | OnboardEnd::Host(r) => write!(f, "{r}"),
            OnboardEnd::Device(s) => f.write_str(match *s {
                p::ONBOARD_ARM_LIMIT => "the device stopped: arm limit (safety.arm_limit)",
                p::ONBOARD_PENDULUM_LIMIT => {
                    "the device stopped: pendulum limit (safety.pendulum_limit)"
                }
                p::ONBOARD_HOST_SILENT => "the device stopped: the host went silent",
                p::ONBOARD_OVERRUN => "the device stopped: a controller step overran its period",
                p::ONBOARD_DRIVER_FAULT => "the device stopped: the motor driver reports a fault",
                p::ONBOARD_BAD_MOVE => "the device stopped: the controller's move was not finite",
                p::ONBOARD_PROTOCOL => "the device stopped: a frame of another protocol version",
                _ => "the device left onboard mode",
            }),
            OnboardEnd::Silent => write!(f, "no reply from the device for {MISSING_LIMIT} periods"),
            OnboardEnd::Setup(e) => write!(f, "refusing to start onboard mode: {e}"),
            OnboardEnd::Io(e) => write!(f, "the port failed: {e}"),
            OnboardEnd::Log(e) => write!(f, "{e}"),
        }
    }
}

/// The host side of the wire: frames out with the host's sequence numbers, frames in.
pub struct Link<'a> {
    io: &'a Fd,
    parser: Parser,
    seq: u16,
    rx: [u8; 256],
    /// Telemetry received, in order.
    pub telemetry: Vec<Telemetry>,
    /// The latest measurement received.
    pub last_measurement: Option<Measurement>,
}

impl<'a> Link<'a> {
    /// A link on `io`.
    pub fn new(io: &'a Fd) -> Self {
        Self {
            io,
            parser: Parser::new(),
            seq: 0,
            rx: [0; 256],
            telemetry: Vec::new(),
            last_measurement: None,
        }
    }

    /// Sends `message`; returns its sequence number.
    pub fn send(&mut self, message: Message) -> std::io::Result<u16> {
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        let mut out = [0u8; MAX_FRAME];
        let n = encode(&Frame { seq, message }, &mut out);
        self.io.write_all(&out[..n])?;
        Ok(seq)
    }

    /// Reads until `want` accepts a frame or `timeout` passes, keeping telemetry and
    /// measurements as they come.
    pub fn wait(
        &mut self,
        timeout: Duration,
        mut want: impl FnMut(&Message) -> bool,
    ) -> std::io::Result<Option<Message>> {
        let deadline = Instant::now() + timeout;
        loop {
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let left = (deadline - now).as_nanos() as u64;
            match self.io.wait_readable(left)? {
                Readiness::Readable => {}
                Readiness::Timeout | Readiness::Interrupted => continue,
            }
            let n = self.io.read_available(&mut self.rx)?;
            let mut found = None;
            for i in 0..n {
                self.parser.push(self.rx[i]);
                while let Some(f) = self.parser.poll() {
                    match f.message {
                        Message::Telemetry(t) => self.telemetry.push(t),
                        Message::Measurement(m) => self.last_measurement = Some(m),
                        _ => {}
                    }
                    if found.is_none() && want(&f.message) {
                        found = Some(f.message);
                    }
                }
            }
            if found.is_some() {
                return Ok(found);
            }
        }
    }

    /// Sends `message` and waits for its ack, repeating it on silence: `(code, value)`.
    pub fn request(&mut self, message: Message) -> Result<(u8, u32), String> {
        for _ in 0..RETRIES {
            let seq = self.send(message).map_err(|e| e.to_string())?;
            let got = self
                .wait(
                    ACK_TIMEOUT,
                    |m| matches!(m, Message::Ack(a) if a.ack_seq == seq),
                )
                .map_err(|e| e.to_string())?;
            if let Some(Message::Ack(a)) = got {
                return Ok((a.code, a.value));
            }
        }
        Err(format!(
            "the device did not acknowledge a {:#04x} frame after {RETRIES} tries (a firmware of \
             protocol v1 does not know v2's onboard frames, nor one of v2 v3's)",
            message.kind()
        ))
    }

    /// A sample request and its measurement.
    pub fn sample(&mut self, timeout: Duration) -> std::io::Result<Option<Measurement>> {
        let seq = self.send(Message::SampleRequest)?;
        Ok(
            match self.wait(
                timeout,
                |m| matches!(m, Message::Measurement(x) if x.ack_seq == seq),
            )? {
                // A lockstep emulator's marker of a lost reply: a period without one.
                Some(Message::Measurement(m)) if m.status & STATUS_NO_SAMPLE == 0 => Some(m),
                _ => None,
            },
        )
    }

    /// Uploads `image` in chunks, resuming where an out-of-order ack says (at most
    /// [`RETRIES`] times in a row), and commits it;
    /// checks the CRC-32 the device computed against the image's.
    ///
    /// # Errors
    /// A refusal (named by its ack code) or silence.
    pub fn upload(&mut self, image: &[u8]) -> Result<(), String> {
        let total = u32::try_from(image.len()).map_err(|_| "image too large".to_string())?;
        let (code, _) = self.request(Message::UploadBegin(UploadBegin { total_len: total }))?;
        if code != ACK_OK {
            return Err(format!(
                "the device refused the upload of {total} bytes (ack code {code})"
            ));
        }
        let mut offset = 0u32;
        let mut refusals = 0;
        while offset < total {
            let end = (offset as usize + CHUNK_MAX).min(image.len());
            let chunk = UploadChunk::new(offset, &image[offset as usize..end]);
            let (code, next) = self.request(Message::UploadChunk(chunk))?;
            match code {
                ACK_OK => {
                    offset = next;
                    refusals = 0;
                }
                // A repeated chunk whose first ack was lost (or a chunk that arrived
                // damaged): continue where the device is, up to RETRIES times in a row.
                ACK_OUT_OF_ORDER if next <= total && refusals < RETRIES => {
                    refusals += 1;
                    offset = next;
                }
                _ => {
                    return Err(format!(
                        "the device refused the chunk at {offset} (ack code {code})"
                    ))
                }
            }
        }
        let crc = crc32(image);
        let (code, device_crc) = self.request(Message::UploadCommit(UploadCommit {
            len: total,
            crc32: crc,
        }))?;
        if code != ACK_OK || device_crc != crc {
            return Err(format!(
                "the device refused the design (ack code {code}; its CRC-32 {device_crc:#010x}, \
                 the image's {crc:#010x})"
            ));
        }
        Ok(())
    }

    /// The stop: the onboard stop (braking) and v1's stop frame, 0 V and disabled.
    pub fn stop(&mut self) -> bool {
        let a = self.send(Message::OnboardStop {
            flags: COMMAND_BRAKE,
        });
        let b = self.send(Message::Command(Command::STOP));
        a.is_ok() && b.is_ok()
    }
}

/// What an onboard run returns.
#[derive(Debug)]
pub struct OnboardReport {
    /// Why it ended.
    pub end: OnboardEnd,
    /// Whether the stop frames were written.
    pub stop_sent: bool,
    /// Telemetry records received.
    pub telemetry: Vec<Telemetry>,
    /// Bytes uploaded.
    pub image_len: usize,
}

/// Uploads, starts and supervises an onboard run on `io` (module docs). `lockstep`: the
/// device is `rip-rt emulate --lockstep` (one period per sample request, no wall-clock waits).
pub fn run(
    io: &Fd,
    cfg: &Config,
    image: &[u8],
    duration_s: Option<f64>,
    lockstep: bool,
    decimation: u16,
    mut log: Option<&mut LogWriter>,
) -> OnboardReport {
    let mut link = Link::new(io);
    let mut report = OnboardReport {
        end: OnboardEnd::Duration,
        stop_sent: false,
        telemetry: Vec::new(),
        image_len: image.len(),
    };
    let mut logged = 0;
    let mut live = Live::for_port(cfg.loop_.live_port, Bounds::of(cfg));
    let mut published = 0;
    let mut end = supervise(
        &mut link,
        cfg,
        image,
        duration_s,
        lockstep,
        decimation,
        &mut |link: &Link<'_>| {
            if let Some(live) = live.as_mut() {
                publish(live, cfg, image, &link.telemetry, published);
                published = link.telemetry.len();
            }
            let Some(log) = log.as_deref_mut() else {
                return Ok(());
            };
            log_rows(log, cfg, image, &link.telemetry, logged)?;
            logged = link.telemetry.len();
            Ok(())
        },
    );
    // Every exit path: stop frames, then the last telemetry the device sends.
    report.stop_sent = link.stop();
    let _ = link.wait(Duration::from_millis(50), |_| false);
    if let Some(log) = log {
        if let Err(e) = log_rows(log, cfg, image, &link.telemetry, logged) {
            if matches!(end, OnboardEnd::Duration) {
                end = OnboardEnd::Log(e);
            }
        }
    }
    if let Some(live) = live.as_mut() {
        publish(live, cfg, image, &link.telemetry, published);
        let t = link
            .telemetry
            .last()
            .map_or(f64::NAN, |r| r.step as f64 * cfg.period_s());
        live.stop(t, end.exit_code(), "onboard");
    }
    report.end = end;
    report.telemetry = std::mem::take(&mut link.telemetry);
    report
}

/// Log rows of the telemetry records from `first` on, in the usual columns: the angles
/// converted as the device converts them, the applied voltage, the status bits, and the step's
/// time at 168 MHz as the compute time. A record whose fallback count rose since the record
/// before it carries `FLAG_FALLBACK`: one or more of the steps between them (the decimation)
/// applied the controller's fallback law.
fn log_rows(
    log: &mut LogWriter,
    cfg: &Config,
    image: &[u8],
    records: &[Telemetry],
    first: usize,
) -> Result<(), String> {
    let Some(sensor) = Sensor::read(image) else {
        return Ok(());
    };
    for i in first..records.len() {
        let row = telemetry_row(&sensor, cfg, records, i);
        // A burst beyond the queue waits for the writer rather than failing the run.
        let mut tries = 0;
        loop {
            match log.push(row) {
                Ok(()) => break,
                Err(crate::log::LogError::Behind(_)) if tries < 100 => {
                    tries += 1;
                    std::thread::sleep(Duration::from_millis(2));
                }
                Err(e) => return Err(e.to_string()),
            }
        }
    }
    Ok(())
}

/// The log row of telemetry record `i` (see [`log_rows`]).
fn telemetry_row(sensor: &Sensor, cfg: &Config, records: &[Telemetry], i: usize) -> Row {
    let t = &records[i];
    let previous_fallbacks = i.checked_sub(1).map_or(0, |p| records[p].fallbacks);
    let fell_back = t.fallbacks > previous_fallbacks;
    let [theta, alpha] = sensor.angles([t.arm_counts, t.pendulum_counts]);
    let time = t.step as f64 * cfg.period_s();
    Row {
        t: time,
        seq: t.step as u16,
        step: StepOutput {
            theta,
            alpha,
            reference: if time >= sensor.step_time {
                sensor.arm_step
            } else {
                0.0
            },
            voltage: t.applied_mv as f64 / 1000.0,
            flags: t.status as u32 | if fell_back { FLAG_FALLBACK } else { 0 },
            len: 0,
            phase: rip_core::Phase::Balance,
        },
        estimate: None,
        compute_us: t.step_cycles as f64 / 168.0,
        jitter_us: 0.0,
        phase: "onboard",
    }
}

/// Publishes telemetry records from `first` on to the live stream, as their log rows.
fn publish(live: &mut Live, cfg: &Config, image: &[u8], records: &[Telemetry], first: usize) {
    let Some(sensor) = Sensor::read(image) else {
        return;
    };
    for i in first..records.len() {
        let row = telemetry_row(&sensor, cfg, records, i);
        let mut f = live.frame(Kind::Period).with_phase(row.phase);
        f.t = row.t;
        f.seq = records[i].step;
        f.theta = row.step.theta;
        f.alpha = row.step.alpha;
        f.theta_ref = row.step.reference;
        f.u_written = row.step.voltage;
        f.status = row.step.flags;
        f.compute_us = row.compute_us;
        live.send(f);
    }
}

#[allow(clippy::too_many_arguments)]
fn supervise(
    link: &mut Link<'_>,
    cfg: &Config,
    image: &[u8],
    duration_s: Option<f64>,
    lockstep: bool,
    decimation: u16,
    log: &mut dyn FnMut(&Link<'_>) -> Result<(), String>,
) -> OnboardEnd {
    // The heartbeat: every period in lockstep (each sample request is one period of the
    // emulator's plant), else at most every 10 ms, which any link sustains.
    let period = if lockstep {
        Duration::from_secs_f64(cfg.period_s())
    } else {
        Duration::from_secs_f64(cfg.period_s().max(0.01))
    };
    if let Err(e) = link.upload(image) {
        return OnboardEnd::Setup(e);
    }
    let first = match link.sample(ACK_TIMEOUT) {
        Ok(Some(m)) => m,
        Ok(None) => return OnboardEnd::Setup("no measurement before the start".into()),
        Err(e) => return OnboardEnd::Io(e.to_string()),
    };
    if lockstep && first.status & STATUS_LOCKSTEP == 0 {
        return OnboardEnd::Setup("--lockstep: the device is not an emulator in lockstep".into());
    }
    let (first, verified) = match wiring::prepare(link, cfg, first, period, lockstep) {
        Ok(prepared) => prepared,
        Err(end) => return end,
    };
    let settings = start_settings(cfg, &first, decimation, verified);
    match link.request(Message::OnboardStart(settings)) {
        Ok((ACK_OK, _)) => {}
        Ok((code, _)) => {
            return OnboardEnd::Setup(format!(
                "the device refused to start (ack code {code}: the pendulum must be upright \
                 and the arm inside safety.arm_limit)"
            ))
        }
        Err(e) => return OnboardEnd::Setup(e),
    }
    let periods = duration_s.map(|d| (d / period.as_secs_f64()).round() as u64);
    let mut pace = Pace::new(period, lockstep);
    let mut k = 0u64;
    // The period at which the device began a stop of its own, if it has.
    let mut device_stop: Option<u64> = None;
    loop {
        if let Some(reason) = crate::stop::requested_stop() {
            return OnboardEnd::Signal(reason);
        }
        if device_stop.is_none() && periods.is_some_and(|n| k >= n) {
            return OnboardEnd::Duration;
        }
        if let Err(end) = pace.period(link, None) {
            return end;
        }
        if let Err(e) = log(link) {
            return OnboardEnd::Log(e);
        }
        if let Some(t) = link.telemetry.last() {
            if t.onboard != ONBOARD_RUNNING {
                // Still in onboard mode after the stop: the device stops the arm itself
                // (rip_control::stop). The host keeps the link alive and lets it finish, up
                // to its bound: its stop frames would cut that stop short.
                let since = *device_stop.get_or_insert_with(|| {
                    if t.status & STATUS_ONBOARD != 0 {
                        crate::say!(
                            "rip-rt: {}; the device is stopping the arm itself (at most {} s)",
                            OnboardEnd::Device(t.onboard),
                            rip_control::stop::MAX_STOP_S
                        );
                    }
                    k
                });
                let waited = (k - since) as f64 * period.as_secs_f64();
                if t.status & STATUS_ONBOARD == 0 || waited > rip_control::stop::MAX_STOP_S + 1.0 {
                    return OnboardEnd::Device(t.onboard);
                }
            }
        }
        k += 1;
    }
}

/// The host's periods: a command (if any) and a sample request each, on the wall clock or, in
/// lockstep, one emulated period per sample; [`MISSING_LIMIT`] periods in a row without a
/// reply end the run as [`OnboardEnd::Silent`].
pub(crate) struct Pace {
    period: Duration,
    lockstep: bool,
    next: Instant,
    missing: u32,
}

impl Pace {
    pub(crate) fn new(period: Duration, lockstep: bool) -> Self {
        Self {
            period,
            lockstep,
            next: Instant::now() + period,
            missing: 0,
        }
    }

    /// One period: `command` sent, the wait for the period's time, then its measurement, if
    /// one came.
    pub(crate) fn period(
        &mut self,
        link: &mut Link<'_>,
        command: Option<Command>,
    ) -> Result<Option<Measurement>, OnboardEnd> {
        if let Some(c) = command {
            link.send(Message::Command(c))
                .map_err(|e| OnboardEnd::Io(e.to_string()))?;
        }
        if !self.lockstep {
            let now = Instant::now();
            if self.next > now {
                std::thread::sleep(self.next - now);
            }
            self.next += self.period;
        }
        let timeout = if self.lockstep {
            ACK_TIMEOUT
        } else {
            self.period
        };
        match link.sample(timeout) {
            Ok(Some(m)) => {
                self.missing = 0;
                Ok(Some(m))
            }
            Ok(None) => {
                self.missing += 1;
                if self.missing >= MISSING_LIMIT {
                    return Err(OnboardEnd::Silent);
                }
                Ok(None)
            }
            Err(e) => Err(OnboardEnd::Io(e.to_string())),
        }
    }

    /// Periods, `command` sent in each, until one brings a measurement (a stop signal ends
    /// the wait).
    pub(crate) fn next(
        &mut self,
        link: &mut Link<'_>,
        command: Option<Command>,
    ) -> Result<Measurement, OnboardEnd> {
        loop {
            if let Some(reason) = crate::stop::requested_stop() {
                return Err(OnboardEnd::Signal(reason));
            }
            if let Some(m) = self.period(link, command)? {
                return Ok(m);
            }
        }
    }
}

/// Telemetry every this many steps: at most 100 records a second, which a 115 200-baud link
/// carries with room to spare (a record is a 37-byte frame: about 310 a second fit).
pub fn telemetry_decimation(cfg: &Config) -> u16 {
    (0.01 / cfg.period_s()).round().clamp(1.0, u16::MAX as f64) as u16
}

/// `rip-rt run --onboard`'s settings (from the command line).
#[derive(Debug, Clone)]
pub struct OnboardArgs<'a> {
    /// The device, for the messages.
    pub port: &'a std::path::Path,
    /// The controller.
    pub controller: ControllerKind,
    /// Stop after this many seconds.
    pub duration: Option<f64>,
    /// Only the summary.
    pub quiet: bool,
    /// Against `rip-rt emulate --lockstep`.
    pub lockstep: bool,
}

/// Runs `rip-rt run --onboard` from the point where the motor may be enabled: uploads `img`
/// to the device on `port`, starts and supervises it ([`run`]), completes `log` and prints the
/// summary; returns the exit code.
///
/// Everything before that point is the caller's, shared with the host loop so that it cannot
/// differ between the two: the configuration `cfg`, the design `img` holds, the
/// pre-flight check with its `--force`, the signal dispositions, `port` opened and `log`
/// created with its header (`rip_rt::cli`).
pub fn command(
    a: &OnboardArgs<'_>,
    cfg: &Config,
    img: &[u8],
    port: &crate::serial::SerialPort,
    mut log: Option<LogWriter>,
) -> i32 {
    use crate::stop::exit_code;
    crate::stop::install_panic_hook();
    if !a.quiet {
        crate::say!(
            "rip-rt: {} onboard on {} every {} ms ({} bytes of design); Ctrl-C stops",
            a.controller,
            a.port.display(),
            cfg.loop_.period_ms,
            img.len()
        );
    }
    let guard = crate::stop::StopGuard::new(port.io().raw());
    let report = run(
        port.io(),
        cfg,
        img,
        a.duration,
        a.lockstep,
        telemetry_decimation(cfg),
        log.as_mut(),
    );
    drop(guard);
    let mut end = report.end;
    // The device counts from the start, so the last record holds the run's total.
    let fallbacks = report.telemetry.last().map_or(0, |t| t.fallbacks);
    if let Some(log) = log.as_mut() {
        let footer = [
            ("stop", end.to_string()),
            ("telemetry", report.telemetry.len().to_string()),
            ("fallbacks", fallbacks.to_string()),
        ];
        if let Err(e) = log.finish(&footer) {
            if matches!(end, OnboardEnd::Duration) {
                end = OnboardEnd::Log(e.to_string());
            }
        }
    }
    let steps = report.telemetry.last().map_or(0, |t| t.step as u64 + 1);
    let max_cycles = report
        .telemetry
        .iter()
        .map(|t| t.step_cycles)
        .max()
        .unwrap_or(0);
    let code = end.exit_code();
    crate::say!(
        "rip-rt: {}: {end}; {} (0 V, disabled)",
        if code == exit_code::FINISHED {
            "stop"
        } else {
            "FAULT"
        },
        if report.stop_sent {
            "stop frames sent"
        } else {
            "stop frames could not be written (the device's watchdog stops the motor)"
        }
    );
    crate::say!(
        "rip-rt: onboard: image={} bytes steps={steps} telemetry={} max_step_cycles={max_cycles} \
         fallbacks={fallbacks}",
        report.image_len,
        report.telemetry.len()
    );
    code
}
