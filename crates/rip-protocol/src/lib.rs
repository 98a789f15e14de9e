//! # rip-protocol
//!
//! Wire protocol v3 between the PC (host) and the pendulum's microcontroller (device). The PC's
//! control loop (`rip-rt`), its device emulator and the STM32 firmware all use this crate, so
//! both ends of the wire run the same code.
//!
//! Version 2 adds onboard control (the controller runs on the device): a controller design
//! uploaded in chunks and committed with its CRC-32, start and stop of onboard mode, the
//! device's acknowledgements and its telemetry stream. Version 1's frames (measurement,
//! command, sample request) are unchanged and still carry version byte 1, so a v1 peer and a v2
//! peer interoperate on them; a v2 parser accepts them with version byte 1 or 2. The new frames
//! carry version byte 2: a v1 device rejects them as another version, which stops its motor.
//!
//! Version 3 adds two frames, both about the device's own stop (`rip_control::stop`: its
//! braking and hold laws, which a device may drive only once the wiring's sign is checked):
//! an onboard start with a flags byte ([`ONBOARD_WIRING_VERIFIED`]), sent only with a flag set
//! (a start without flags is v2's frame, unchanged), and the [`WatchdogStop`] of host mode,
//! which says what the v1 command watchdog does when the host goes silent. They carry version
//! byte 3; every other frame keeps its version byte, and version byte 3 carries nothing else.
//! A v2 device rejects both as another version, which stops its motor.
//!
//! The byte-level specification lives in `docs/protocol.md`; this crate is its reference
//! implementation and `crates/rip-protocol/vectors.toml` holds the conformance vectors that both
//! refer to. Every frame is
//!
//! ```text
//! offset  size  field
//! 0       1     sync 0xA5
//! 1       1     sync 0x5A
//! 2       1     protocol version (1 for v1's messages, 2 for v2's)
//! 3       1     message type
//! 4       2     sequence number, u16 little-endian (each side counts its own frames)
//! 6       1     payload length n (≤ MAX_PAYLOAD)
//! 7       n     payload
//! 7+n     2     CRC-16/CCITT-FALSE of bytes 2 .. 7+n, u16 little-endian
//! ```
//!
//! All multi-byte fields are little-endian. The crate is `no_std` and never allocates, and the
//! streaming [`Parser`] accepts any byte sequence without panicking.
//!
//! ## Resynchronisation rule
//!
//! The parser skips bytes until `0xA5 0x5A`, then reads a candidate frame. What it discards after
//! a rejection depends on whether the CRC has established where the candidate ends:
//!
//! - a candidate that fails its CRC, or whose header is impossible (length field above
//!   [`MAX_PAYLOAD`]), proves nothing about framing — its sync bytes may have been noise in the
//!   middle of a real frame, or a real frame may have lost a byte — so only its first byte is
//!   dropped and the search for `0xA5 0x5A` restarts one byte later, inside the rejected bytes;
//! - a candidate whose CRC is valid but which this version cannot use (another version byte, an
//!   unknown type, a payload length that does not fit its type) was sent as that frame by the
//!   peer: a random match has probability 2⁻¹⁶. It is discarded whole, because any `0xA5 0x5A`
//!   inside it is payload data, and resynchronising there would decode data as frames.

#![no_std]
#![forbid(unsafe_code)]

/// First sync byte.
pub const SYNC0: u8 = 0xA5;
/// Second sync byte.
pub const SYNC1: u8 = 0x5A;
/// The newest protocol version: the version byte of v3's two new frames, an [`OnboardStart`]
/// with flags ([`ONBOARD_WIRING_VERIFIED`]) and a [`WatchdogStop`].
pub const VERSION: u8 = 3;
/// The version byte of v2's messages (upload, onboard, ack, telemetry), which v3 keeps.
pub const VERSION_2: u8 = 2;
/// The version byte of v1's messages (measurement, command, sample request), which v2 and v3
/// keep.
pub const VERSION_1: u8 = 1;
/// Offset of the version byte.
const VERSION_AT: usize = 2;
/// Bytes before the payload.
pub const HEADER_LEN: usize = 7;
/// Bytes after the payload (the CRC).
pub const TRAILER_LEN: usize = 2;
/// Largest payload a parser accepts; longer length fields are treated as corruption.
pub const MAX_PAYLOAD: usize = 32;
/// Largest frame on the wire.
pub const MAX_FRAME: usize = HEADER_LEN + MAX_PAYLOAD + TRAILER_LEN;

/// Message type of a [`Measurement`] (device → host).
pub const TYPE_MEASUREMENT: u8 = 0x01;
/// Message type of a [`Command`] (host → device).
pub const TYPE_COMMAND: u8 = 0x02;
/// Message type of a sample request (host → device, empty payload).
pub const TYPE_SAMPLE_REQUEST: u8 = 0x03;
/// Message type of an [`UploadBegin`] (host → device, v2).
pub const TYPE_UPLOAD_BEGIN: u8 = 0x10;
/// Message type of an [`UploadChunk`] (host → device, v2).
pub const TYPE_UPLOAD_CHUNK: u8 = 0x11;
/// Message type of an [`UploadCommit`] (host → device, v2).
pub const TYPE_UPLOAD_COMMIT: u8 = 0x12;
/// Message type of an [`OnboardStart`] (host → device, v2).
pub const TYPE_ONBOARD_START: u8 = 0x13;
/// Message type of an onboard stop (host → device, v2): one byte of `COMMAND_*` flags, of
/// which only [`COMMAND_BRAKE`] counts.
pub const TYPE_ONBOARD_STOP: u8 = 0x14;
/// Message type of a [`PilStep`] (host → device, v2).
pub const TYPE_PIL_STEP: u8 = 0x15;
/// Message type of a [`WatchdogStop`] (host → device, v3).
pub const TYPE_WATCHDOG_STOP: u8 = 0x16;
/// Message type of a [`PilMove`] (device → host, v2).
pub const TYPE_PIL_MOVE: u8 = 0x22;
/// Message type of an [`Ack`] (device → host, v2).
pub const TYPE_ACK: u8 = 0x20;
/// Message type of a [`Telemetry`] record (device → host, v2).
pub const TYPE_TELEMETRY: u8 = 0x21;

/// Payload length of a measurement.
pub const MEASUREMENT_LEN: usize = 17;
/// Payload length of a command.
pub const COMMAND_LEN: usize = 3;
/// Payload length of an upload begin.
pub const UPLOAD_BEGIN_LEN: usize = 4;
/// Largest number of design bytes in one [`UploadChunk`]: the payload less its 4-byte offset.
pub const CHUNK_MAX: usize = MAX_PAYLOAD - 4;
/// Payload length of an upload commit.
pub const UPLOAD_COMMIT_LEN: usize = 8;
/// Payload length of an onboard start (v2: no flags).
pub const ONBOARD_START_LEN: usize = 20;
/// Payload length of an onboard start with flags (v3).
pub const ONBOARD_START_V3_LEN: usize = 21;
/// Payload length of a [`WatchdogStop`] (v3).
pub const WATCHDOG_STOP_LEN: usize = 9;
/// Payload length of an onboard stop.
pub const ONBOARD_STOP_LEN: usize = 1;
/// Payload length of a PIL step.
pub const PIL_STEP_LEN: usize = 9;
/// Payload length of a PIL move.
pub const PIL_MOVE_LEN: usize = 19;
/// [`PilStep`] flag: reset the controller (a new run) before this step.
pub const PIL_RESET: u8 = 1 << 0;
/// [`PilStep`] flag (v3): step the device's own stop instead of the controller (with
/// [`PIL_RESET`], begin it, the wiring verified), its clock advancing a design period per
/// step. The [`PilMove`]'s move is the stop's voltage, `+∞` for the short, NaN once the stop is
/// done; refused (`ACK_REFUSED`) when the image has no stop's design.
pub const PIL_STOP: u8 = 1 << 4;
/// [`PilStep`] flags, bits 1–3: which part of the step the answer's `cycles` covers (0, the
/// default, the whole step; `PIL_PHASE_*`, one part), to find where a step's time goes.
pub const PIL_PHASE_MASK: u8 = 0b1110;
/// The first bit of [`PIL_PHASE_MASK`].
pub const PIL_PHASE_SHIFT: u32 = 1;
/// `PIL_PHASE_*` part: the encoder counts to the controller's angles and reference.
pub const PIL_PHASE_CONVERT: u8 = 1;
/// `PIL_PHASE_*` part: the measurement update (rate filter or Kalman correction).
pub const PIL_PHASE_ESTIMATE: u8 = 2;
/// `PIL_PHASE_*` part: the MPC's QP data from the estimate.
pub const PIL_PHASE_LINEAR: u8 = 3;
/// `PIL_PHASE_*` part: the MPC's QP solve.
pub const PIL_PHASE_QP: u8 = 4;
/// `PIL_PHASE_*` part: the rest (the plan, the time update, the compensation).
pub const PIL_PHASE_REST: u8 = 5;
/// Number of `PIL_PHASE_*` parts.
pub const PIL_PHASES: usize = 5;
/// Payload length of an ack.
pub const ACK_LEN: usize = 8;
/// Payload length of a telemetry record.
pub const TELEMETRY_LEN: usize = 28;

/// Device status bit: the motor driver is enabled and applying the commanded voltage.
pub const STATUS_ENABLED: u8 = 1 << 0;
/// Device status bit: the device's own watchdog zeroed the motor because commands stopped.
pub const STATUS_WATCHDOG: u8 = 1 << 1;
/// Device status bit: the device received a corrupt or unknown frame since its last report.
pub const STATUS_RX_ERROR: u8 = 1 << 2;
/// Device status bit: the motor driver reports a fault (over-current, over-temperature, ...).
pub const STATUS_FAULT: u8 = 1 << 3;

/// Device status bit: the bridge is braking, its windings shorted (a [`COMMAND_BRAKE`], or the
/// device's own stop on a watchdog trip or a frame of another version, on a board that can
/// brake). Bit 4 was reserved (sent as 0) before braking was defined: a device without it
/// never sets it, and the host reads its absence as an open, coasting motor.
pub const STATUS_BRAKING: u8 = 1 << 4;

/// Device status bit: the device is an emulator in lockstep (`rip-rt emulate --lockstep`),
/// which advances its plant by exactly one host period per sample request instead of in real
/// time. Bit 5 was reserved (sent as 0) before lockstep was defined; a real device never sets
/// it, and the host refuses to run in lockstep against a device that does not.
pub const STATUS_LOCKSTEP: u8 = 1 << 5;

/// Device status bit: the device runs its onboard controller (v2). Bit 6 was reserved (sent
/// as 0) in v1.
pub const STATUS_ONBOARD: u8 = 1 << 6;

/// Device status bit: this measurement carries no reading, only the news that the period's
/// reply was lost on the way (an injected fault of an emulator in lockstep: dropped, damaged
/// or inside a silence). A lockstep host counts the period as without a measurement at once,
/// as a real-time host does when its reply timeout passes, instead of waiting on a wall-clock
/// timeout for a reply that will not come. Set only together with [`STATUS_LOCKSTEP`]; a real
/// device never sets it (bit 7 was reserved, sent as 0, before).
pub const STATUS_NO_SAMPLE: u8 = 1 << 7;

/// Command flag bit: enable the motor driver. Without it the device applies 0 V.
pub const COMMAND_ENABLE: u8 = 1 << 0;
/// Command flag bit, with [`COMMAND_ENABLE`] clear: brake (short the motor's windings, so that
/// back-EMF stops the arm) instead of leaving them open, where the board can. Bit 1 was
/// reserved before braking was defined; a device without braking ignores it and disables the
/// driver as for any disabled command, and reports no [`STATUS_BRAKING`]. Ignored together
/// with `COMMAND_ENABLE`: an enabled command drives its voltage.
pub const COMMAND_BRAKE: u8 = 1 << 1;

/// Encoder readings and status, sampled by the device when it receives a sample request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Measurement {
    /// Sequence number of the host frame (the sample request) this measurement answers.
    pub ack_seq: u16,
    /// Arm encoder, counts since power-up (multi-turn, signed).
    pub arm_counts: i32,
    /// Pendulum encoder, counts since power-up (multi-turn, signed).
    pub pendulum_counts: i32,
    /// Voltage the device is applying at the sampling instant, millivolts.
    pub applied_mv: i16,
    /// `STATUS_*` bits.
    pub status: u8,
    /// Device clock at the sampling instant, microseconds (wraps around).
    pub device_time_us: u32,
}

/// Motor command from the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Command {
    /// Motor voltage, millivolts.
    pub voltage_mv: i16,
    /// `COMMAND_*` bits.
    pub flags: u8,
}

impl Command {
    /// The stop command: 0 V with the driver disabled.
    pub const STOP: Command = Command {
        voltage_mv: 0,
        flags: 0,
    };

    /// The brake command: 0 V, driver disabled, windings shorted ([`COMMAND_BRAKE`]).
    pub const BRAKE: Command = Command {
        voltage_mv: 0,
        flags: COMMAND_BRAKE,
    };

    /// Whether the enable bit is set.
    pub fn enabled(&self) -> bool {
        self.flags & COMMAND_ENABLE != 0
    }

    /// Whether this command asks for the brake: [`COMMAND_BRAKE`] without [`COMMAND_ENABLE`].
    pub fn brake(&self) -> bool {
        !self.enabled() && self.flags & COMMAND_BRAKE != 0
    }
}

mod onboard;
pub use onboard::*;

/// A decoded message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// Device → host.
    Measurement(Measurement),
    /// Host → device.
    Command(Command),
    /// Host → device: sample the encoders now and answer with a [`Measurement`].
    SampleRequest,
    /// Host → device (v2).
    UploadBegin(UploadBegin),
    /// Host → device (v2).
    UploadChunk(UploadChunk),
    /// Host → device (v2).
    UploadCommit(UploadCommit),
    /// Host → device (v2).
    OnboardStart(OnboardStart),
    /// Host → device (v2): stop onboard mode, 0 V; brake where the flags ask for it.
    OnboardStop {
        /// `COMMAND_*` flags: [`COMMAND_BRAKE`] brakes.
        flags: u8,
    },
    /// Host → device (v2).
    PilStep(PilStep),
    /// Host → device (v3).
    WatchdogStop(WatchdogStop),
    /// Device → host (v2).
    PilMove(PilMove),
    /// Device → host (v2).
    Ack(Ack),
    /// Device → host (v2).
    Telemetry(Telemetry),
}

impl Message {
    /// The version byte this message is sent with: v1's messages keep 1, v2's 2; an onboard
    /// start with flags and a watchdog stop are v3's (module docs).
    pub fn version(&self) -> u8 {
        match self {
            Message::Measurement(_) | Message::Command(_) | Message::SampleRequest => VERSION_1,
            Message::OnboardStart(s) if s.flags != 0 => VERSION,
            Message::WatchdogStop(_) => VERSION,
            _ => VERSION_2,
        }
    }

    /// The message type byte.
    pub fn kind(&self) -> u8 {
        match self {
            Message::Measurement(_) => TYPE_MEASUREMENT,
            Message::Command(_) => TYPE_COMMAND,
            Message::SampleRequest => TYPE_SAMPLE_REQUEST,
            Message::UploadBegin(_) => TYPE_UPLOAD_BEGIN,
            Message::UploadChunk(_) => TYPE_UPLOAD_CHUNK,
            Message::UploadCommit(_) => TYPE_UPLOAD_COMMIT,
            Message::OnboardStart(_) => TYPE_ONBOARD_START,
            Message::OnboardStop { .. } => TYPE_ONBOARD_STOP,
            Message::PilStep(_) => TYPE_PIL_STEP,
            Message::WatchdogStop(_) => TYPE_WATCHDOG_STOP,
            Message::PilMove(_) => TYPE_PIL_MOVE,
            Message::Ack(_) => TYPE_ACK,
            Message::Telemetry(_) => TYPE_TELEMETRY,
        }
    }
}

/// A decoded frame: the sender's sequence number and the message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    /// The sender's sequence number (wraps around).
    pub seq: u16,
    /// The message.
    pub message: Message,
}

/// CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR
/// (check value `crc16(b"123456789") == 0x29B1`).
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &byte in data {
        crc ^= (byte as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// CRC-32/ISO-HDLC (the zlib and Ethernet CRC): reflected polynomial 0xEDB88320, initial value
/// and final XOR 0xFFFFFFFF (check value `crc32(b"123456789") == 0xCBF43926`). It checks a
/// whole uploaded design image ([`UploadCommit`]).
pub fn crc32(data: &[u8]) -> u32 {
    crc32_update(0, data)
}

/// Continues a [`crc32`] over `data`: `crc32_update(crc32(a), b) == crc32(a ++ b)`, so that
/// an image can be checked chunk by chunk.
pub fn crc32_update(crc: u32, data: &[u8]) -> u32 {
    let mut crc = !crc;
    for &byte in data {
        crc ^= byte as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// Writes `frame` into `out` and returns the number of bytes used.
pub fn encode(frame: &Frame, out: &mut [u8; MAX_FRAME]) -> usize {
    let (kind, len) = match frame.message {
        Message::Measurement(m) => {
            let p = &mut out[HEADER_LEN..HEADER_LEN + MEASUREMENT_LEN];
            p[0..2].copy_from_slice(&m.ack_seq.to_le_bytes());
            p[2..6].copy_from_slice(&m.arm_counts.to_le_bytes());
            p[6..10].copy_from_slice(&m.pendulum_counts.to_le_bytes());
            p[10..12].copy_from_slice(&m.applied_mv.to_le_bytes());
            p[12] = m.status;
            p[13..17].copy_from_slice(&m.device_time_us.to_le_bytes());
            (TYPE_MEASUREMENT, MEASUREMENT_LEN)
        }
        Message::Command(c) => {
            let p = &mut out[HEADER_LEN..HEADER_LEN + COMMAND_LEN];
            p[0..2].copy_from_slice(&c.voltage_mv.to_le_bytes());
            p[2] = c.flags;
            (TYPE_COMMAND, COMMAND_LEN)
        }
        Message::SampleRequest => (TYPE_SAMPLE_REQUEST, 0),
        Message::UploadBegin(b) => {
            out[HEADER_LEN..HEADER_LEN + 4].copy_from_slice(&b.total_len.to_le_bytes());
            (TYPE_UPLOAD_BEGIN, UPLOAD_BEGIN_LEN)
        }
        Message::UploadChunk(c) => {
            let data = c.bytes();
            let p = &mut out[HEADER_LEN..HEADER_LEN + 4 + data.len()];
            p[0..4].copy_from_slice(&c.offset.to_le_bytes());
            p[4..].copy_from_slice(data);
            (TYPE_UPLOAD_CHUNK, 4 + data.len())
        }
        Message::UploadCommit(c) => {
            let p = &mut out[HEADER_LEN..HEADER_LEN + UPLOAD_COMMIT_LEN];
            p[0..4].copy_from_slice(&c.len.to_le_bytes());
            p[4..8].copy_from_slice(&c.crc32.to_le_bytes());
            (TYPE_UPLOAD_COMMIT, UPLOAD_COMMIT_LEN)
        }
        Message::OnboardStart(s) => {
            let len = if s.flags != 0 {
                ONBOARD_START_V3_LEN
            } else {
                ONBOARD_START_LEN
            };
            let p = &mut out[HEADER_LEN..HEADER_LEN + len];
            p[0..2].copy_from_slice(&s.decimation.to_le_bytes());
            p[2..4].copy_from_slice(&s.host_timeout_ms.to_le_bytes());
            p[4..8].copy_from_slice(&s.arm_center.to_le_bytes());
            p[8..12].copy_from_slice(&s.arm_limit.to_le_bytes());
            p[12..16].copy_from_slice(&s.pendulum_center.to_le_bytes());
            p[16..20].copy_from_slice(&s.pendulum_limit.to_le_bytes());
            if s.flags != 0 {
                p[20] = s.flags;
            }
            (TYPE_ONBOARD_START, len)
        }
        Message::OnboardStop { flags } => {
            out[HEADER_LEN] = flags;
            (TYPE_ONBOARD_STOP, ONBOARD_STOP_LEN)
        }
        Message::PilStep(s) => {
            let p = &mut out[HEADER_LEN..HEADER_LEN + PIL_STEP_LEN];
            p[0..4].copy_from_slice(&s.arm_counts.to_le_bytes());
            p[4..8].copy_from_slice(&s.pendulum_counts.to_le_bytes());
            p[8] = s.flags;
            (TYPE_PIL_STEP, PIL_STEP_LEN)
        }
        Message::WatchdogStop(w) => {
            let p = &mut out[HEADER_LEN..HEADER_LEN + WATCHDOG_STOP_LEN];
            p[0] = w.flags;
            p[1..5].copy_from_slice(&w.arm_zero.to_le_bytes());
            p[5..9].copy_from_slice(&w.pendulum_down.to_le_bytes());
            (TYPE_WATCHDOG_STOP, WATCHDOG_STOP_LEN)
        }
        Message::PilMove(m) => {
            let p = &mut out[HEADER_LEN..HEADER_LEN + PIL_MOVE_LEN];
            p[0..2].copy_from_slice(&m.ack_seq.to_le_bytes());
            p[2..6].copy_from_slice(&m.step.to_le_bytes());
            p[6..14].copy_from_slice(&m.voltage_bits.to_le_bytes());
            p[14..18].copy_from_slice(&m.cycles.to_le_bytes());
            p[18] = m.code;
            (TYPE_PIL_MOVE, PIL_MOVE_LEN)
        }
        Message::Ack(a) => {
            let p = &mut out[HEADER_LEN..HEADER_LEN + ACK_LEN];
            p[0..2].copy_from_slice(&a.ack_seq.to_le_bytes());
            p[2] = a.request;
            p[3] = a.code;
            p[4..8].copy_from_slice(&a.value.to_le_bytes());
            (TYPE_ACK, ACK_LEN)
        }
        Message::Telemetry(t) => {
            let p = &mut out[HEADER_LEN..HEADER_LEN + TELEMETRY_LEN];
            p[0..4].copy_from_slice(&t.step.to_le_bytes());
            p[4..8].copy_from_slice(&t.device_time_us.to_le_bytes());
            p[8..12].copy_from_slice(&t.arm_counts.to_le_bytes());
            p[12..16].copy_from_slice(&t.pendulum_counts.to_le_bytes());
            p[16..18].copy_from_slice(&t.applied_mv.to_le_bytes());
            p[18] = t.status;
            p[19] = t.onboard;
            p[20..24].copy_from_slice(&t.step_cycles.to_le_bytes());
            p[24..26].copy_from_slice(&t.overruns.to_le_bytes());
            p[26..28].copy_from_slice(&t.fallbacks.to_le_bytes());
            (TYPE_TELEMETRY, TELEMETRY_LEN)
        }
    };
    out[0] = SYNC0;
    out[1] = SYNC1;
    out[2] = frame.message.version();
    out[3] = kind;
    out[4..6].copy_from_slice(&frame.seq.to_le_bytes());
    out[6] = len as u8;
    let end = HEADER_LEN + len;
    let crc = crc16(&out[2..end]);
    out[end..end + TRAILER_LEN].copy_from_slice(&crc.to_le_bytes());
    end + TRAILER_LEN
}

/// Decodes the payload of a CRC-valid frame of version byte `version` (1, 2 or 3); `None` for
/// an unknown type, a wrong length, a v2 message with version byte 1, or anything but an
/// onboard start with flags or a watchdog stop with version byte 3.
fn decode_payload(version: u8, kind: u8, p: &[u8]) -> Option<Message> {
    let u16_at = |i: usize| u16::from_le_bytes([p[i], p[i + 1]]);
    let i16_at = |i: usize| i16::from_le_bytes([p[i], p[i + 1]]);
    let u32_at = |i: usize| u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
    let onboard_start = |flags: u8| {
        Message::OnboardStart(OnboardStart {
            decimation: u16_at(0),
            host_timeout_ms: u16_at(2),
            arm_center: u32_at(4) as i32,
            arm_limit: u32_at(8),
            pendulum_center: u32_at(12) as i32,
            pendulum_limit: u32_at(16),
            flags,
        })
    };
    if version == VERSION {
        // v3 adds two frames, the onboard start with flags and the watchdog stop; a start
        // without flags is v2's (the encoder's rule), and every other frame keeps its own
        // version byte.
        return match (kind, p.len()) {
            (TYPE_ONBOARD_START, ONBOARD_START_V3_LEN) if p[20] != 0 => Some(onboard_start(p[20])),
            (TYPE_WATCHDOG_STOP, WATCHDOG_STOP_LEN) => Some(Message::WatchdogStop(WatchdogStop {
                flags: p[0],
                arm_zero: u32_at(1) as i32,
                pendulum_down: u32_at(5) as i32,
            })),
            _ => None,
        };
    }
    match (kind, p.len()) {
        (TYPE_MEASUREMENT, MEASUREMENT_LEN) => Some(Message::Measurement(Measurement {
            ack_seq: u16_at(0),
            arm_counts: u32_at(2) as i32,
            pendulum_counts: u32_at(6) as i32,
            applied_mv: i16_at(10),
            status: p[12],
            device_time_us: u32_at(13),
        })),
        (TYPE_COMMAND, COMMAND_LEN) => Some(Message::Command(Command {
            voltage_mv: i16_at(0),
            flags: p[2],
        })),
        (TYPE_SAMPLE_REQUEST, 0) => Some(Message::SampleRequest),
        _ if version == VERSION_1 => None,
        (TYPE_UPLOAD_BEGIN, UPLOAD_BEGIN_LEN) => Some(Message::UploadBegin(UploadBegin {
            total_len: u32_at(0),
        })),
        (TYPE_UPLOAD_CHUNK, n) if (5..=MAX_PAYLOAD).contains(&n) => {
            Some(Message::UploadChunk(UploadChunk::new(u32_at(0), &p[4..])))
        }
        (TYPE_UPLOAD_COMMIT, UPLOAD_COMMIT_LEN) => Some(Message::UploadCommit(UploadCommit {
            len: u32_at(0),
            crc32: u32_at(4),
        })),
        (TYPE_ONBOARD_START, ONBOARD_START_LEN) => Some(onboard_start(0)),
        (TYPE_ONBOARD_STOP, ONBOARD_STOP_LEN) => Some(Message::OnboardStop { flags: p[0] }),
        (TYPE_PIL_STEP, PIL_STEP_LEN) => Some(Message::PilStep(PilStep {
            arm_counts: u32_at(0) as i32,
            pendulum_counts: u32_at(4) as i32,
            flags: p[8],
        })),
        (TYPE_PIL_MOVE, PIL_MOVE_LEN) => Some(Message::PilMove(PilMove {
            ack_seq: u16_at(0),
            step: u32_at(2),
            voltage_bits: u32_at(6) as u64 | (u32_at(10) as u64) << 32,
            cycles: u32_at(14),
            code: p[18],
        })),
        (TYPE_ACK, ACK_LEN) => Some(Message::Ack(Ack {
            ack_seq: u16_at(0),
            request: p[2],
            code: p[3],
            value: u32_at(4),
        })),
        (TYPE_TELEMETRY, TELEMETRY_LEN) => Some(Message::Telemetry(Telemetry {
            step: u32_at(0),
            device_time_us: u32_at(4),
            arm_counts: u32_at(8) as i32,
            pendulum_counts: u32_at(12) as i32,
            applied_mv: i16_at(16),
            status: p[18],
            onboard: p[19],
            step_cycles: u32_at(20),
            overruns: u16_at(24),
            fallbacks: u16_at(26),
        })),
        _ => None,
    }
}

/// Counters kept by the [`Parser`], for diagnostics and the run summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ParserStats {
    /// Frames decoded.
    pub frames: u64,
    /// Bytes skipped while looking for a frame start.
    pub skipped_bytes: u64,
    /// Candidate frames whose CRC did not match.
    pub crc_errors: u64,
    /// Candidates with an oversized length field.
    pub bad_headers: u64,
    /// CRC-valid frames of another protocol version.
    pub version_mismatches: u64,
    /// CRC-valid frames with an unknown type or a payload length that does not fit the type.
    pub unknown_frames: u64,
}

impl ParserStats {
    /// All rejected candidates (skipped bytes between frames are not counted).
    pub fn errors(&self) -> u64 {
        self.crc_errors + self.bad_headers + self.version_mismatches + self.unknown_frames
    }
}

/// Why the [`Parser`] rejected a candidate frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// The CRC did not match: corruption on the wire or a false sync.
    Crc,
    /// The length field exceeds [`MAX_PAYLOAD`].
    BadHeader,
    /// A CRC-valid frame of a version other than 1 and 2: the peer speaks another protocol.
    Version(u8),
    /// A CRC-valid frame with an unknown type, a payload length that does not fit its type, or
    /// a v2 message with version byte 1.
    Unknown {
        /// The message type byte.
        kind: u8,
        /// The payload length.
        len: u8,
    },
}

/// What the [`Parser`] found next in the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A good frame.
    Frame(Frame),
    /// A rejected candidate frame.
    Rejected(Rejection),
}

/// A streaming frame parser with a fixed buffer.
///
/// Feed bytes with [`push`](Self::push) and collect frames with [`poll`](Self::poll) (or frames
/// and rejections with [`poll_event`](Self::poll_event)) until it returns `None`, or use
/// [`feed`](Self::feed). After every poll that returns `None` the buffer holds at most one
/// incomplete candidate frame, so it never overflows. The resynchronisation rule is described
/// in the crate documentation.
#[derive(Debug, Clone)]
pub struct Parser {
    buf: [u8; MAX_FRAME],
    len: usize,
    stats: ParserStats,
}

impl Default for Parser {
    fn default() -> Self {
        Self::new()
    }
}

impl Parser {
    /// An empty parser.
    pub fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME],
            len: 0,
            stats: ParserStats::default(),
        }
    }

    /// The counters so far.
    pub fn stats(&self) -> ParserStats {
        self.stats
    }

    /// Forgets any partial frame (the counters are kept).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Appends one byte. Call [`poll`](Self::poll) until it returns `None` before the next push.
    pub fn push(&mut self, byte: u8) {
        if self.len == self.buf.len() {
            // Only reachable when the caller skipped `poll`: keep the newest bytes.
            self.discard(1);
        }
        if self.len == 0 && byte != SYNC0 {
            self.stats.skipped_bytes += 1;
            return;
        }
        self.buf[self.len] = byte;
        self.len += 1;
    }

    /// Pushes every byte of `data`, handing each decoded frame to `sink`.
    pub fn feed(&mut self, data: &[u8], mut sink: impl FnMut(Frame)) {
        for &byte in data {
            self.push(byte);
            while let Some(frame) = self.poll() {
                sink(frame);
            }
        }
    }

    /// Returns the next complete frame in the buffer, if any, passing over rejected candidates
    /// (they are counted in [`stats`](Self::stats)).
    pub fn poll(&mut self) -> Option<Frame> {
        loop {
            match self.poll_event()? {
                Event::Frame(frame) => return Some(frame),
                Event::Rejected(_) => {}
            }
        }
    }

    /// Returns the next complete frame or rejected candidate in the buffer, if any.
    pub fn poll_event(&mut self) -> Option<Event> {
        loop {
            if self.len == 0 {
                return None;
            }
            if self.buf[0] != SYNC0 || (self.len >= 2 && self.buf[1] != SYNC1) {
                self.resync();
                continue;
            }
            if self.len < HEADER_LEN {
                return None;
            }
            let payload_len = self.buf[6] as usize;
            if payload_len > MAX_PAYLOAD {
                // Rejected at once: waiting for up to 255 bytes would hold back the good frames
                // behind a corrupted length field.
                self.stats.bad_headers += 1;
                self.resync();
                return Some(Event::Rejected(Rejection::BadHeader));
            }
            let total = HEADER_LEN + payload_len + TRAILER_LEN;
            if self.len < total {
                return None;
            }
            let end = HEADER_LEN + payload_len;
            let crc = u16::from_le_bytes([self.buf[end], self.buf[end + 1]]);
            if crc16(&self.buf[VERSION_AT..end]) != crc {
                self.stats.crc_errors += 1;
                self.resync();
                return Some(Event::Rejected(Rejection::Crc));
            }
            let version = self.buf[VERSION_AT];
            let kind = self.buf[3];
            let seq = u16::from_le_bytes([self.buf[4], self.buf[5]]);
            let known = version == VERSION_1 || version == VERSION_2 || version == VERSION;
            let decoded = if known {
                decode_payload(version, kind, &self.buf[HEADER_LEN..end])
            } else {
                None
            };
            // The CRC has established the frame's extent: it is consumed whole (crate docs).
            self.discard(total);
            return Some(match decoded {
                Some(message) => {
                    self.stats.frames += 1;
                    Event::Frame(Frame { seq, message })
                }
                None if !known => {
                    self.stats.version_mismatches += 1;
                    Event::Rejected(Rejection::Version(version))
                }
                None => {
                    self.stats.unknown_frames += 1;
                    Event::Rejected(Rejection::Unknown {
                        kind,
                        len: payload_len as u8,
                    })
                }
            });
        }
    }

    /// Drops the first buffered byte and everything up to the next possible frame start.
    fn resync(&mut self) {
        let next = self.buf[1..self.len]
            .iter()
            .position(|&b| b == SYNC0)
            .map_or(self.len, |i| i + 1);
        self.stats.skipped_bytes += next as u64;
        self.discard(next);
    }

    fn discard(&mut self, n: usize) {
        let n = n.min(self.len);
        self.buf.copy_within(n..self.len, 0);
        self.len -= n;
    }
}
