//! # rip-protocol
//!
//! Wire protocol v1 between the PC (host) and the pendulum's microcontroller (device). The PC's
//! control loop (`rip-rt`), its device emulator and the STM32 firmware all use this crate, so
//! both ends of the wire run the same code.
//!
//! The byte-level specification lives in `docs/protocol.md`; this crate is its reference
//! implementation and `crates/rip-protocol/vectors.toml` holds the conformance vectors that both
//! refer to. Every frame is
//!
//! ```text
//! offset  size  field
//! 0       1     sync 0xA5
//! 1       1     sync 0x5A
//! 2       1     protocol version (1)
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
/// Protocol version carried in every frame.
pub const VERSION: u8 = 1;
/// Offset of the version byte.
const VERSION_AT: usize = 2;
/// Bytes before the payload.
pub const HEADER_LEN: usize = 7;
/// Bytes after the payload (the CRC).
pub const TRAILER_LEN: usize = 2;
/// Largest payload a v1 parser accepts; longer length fields are treated as corruption.
pub const MAX_PAYLOAD: usize = 32;
/// Largest frame on the wire.
pub const MAX_FRAME: usize = HEADER_LEN + MAX_PAYLOAD + TRAILER_LEN;

/// Message type of a [`Measurement`] (device → host).
pub const TYPE_MEASUREMENT: u8 = 0x01;
/// Message type of a [`Command`] (host → device).
pub const TYPE_COMMAND: u8 = 0x02;
/// Message type of a sample request (host → device, empty payload).
pub const TYPE_SAMPLE_REQUEST: u8 = 0x03;

/// Payload length of a measurement.
pub const MEASUREMENT_LEN: usize = 17;
/// Payload length of a command.
pub const COMMAND_LEN: usize = 3;

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

/// A decoded message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// Device → host.
    Measurement(Measurement),
    /// Host → device.
    Command(Command),
    /// Host → device: sample the encoders now and answer with a [`Measurement`].
    SampleRequest,
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
    };
    out[0] = SYNC0;
    out[1] = SYNC1;
    out[2] = VERSION;
    out[3] = kind;
    out[4..6].copy_from_slice(&frame.seq.to_le_bytes());
    out[6] = len as u8;
    let end = HEADER_LEN + len;
    let crc = crc16(&out[2..end]);
    out[end..end + TRAILER_LEN].copy_from_slice(&crc.to_le_bytes());
    end + TRAILER_LEN
}

/// Decodes the payload of a CRC-valid frame; `None` for an unknown type or a wrong length.
fn decode_payload(kind: u8, p: &[u8]) -> Option<Message> {
    let u16_at = |i: usize| u16::from_le_bytes([p[i], p[i + 1]]);
    let i16_at = |i: usize| i16::from_le_bytes([p[i], p[i + 1]]);
    let u32_at = |i: usize| u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
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
    /// A CRC-valid frame of another protocol version: the peer speaks another protocol.
    Version(u8),
    /// A CRC-valid frame with an unknown type, or a payload length that does not fit its type.
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
            let decoded = if version == VERSION {
                decode_payload(kind, &self.buf[HEADER_LEN..end])
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
                None if version != VERSION => {
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
