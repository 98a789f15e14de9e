//! The protocol v2 payloads of onboard mode: the design upload, start and stop, the
//! device's acknowledgements and telemetry, and the processor-in-the-loop step (crate docs).

// The frame constants and helpers the payloads are built from.
use super::*;

/// Host → device (v2): a design upload of `total_len` bytes begins; the device forgets any
/// earlier upload and expects the chunk at offset 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct UploadBegin {
    /// Length of the whole design image, bytes.
    pub total_len: u32,
}

/// Host → device (v2): `len` bytes of the design image at byte `offset`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UploadChunk {
    /// Offset of the first byte in the design image.
    pub offset: u32,
    /// Number of valid bytes in `data`, `1 ..= CHUNK_MAX`.
    pub len: u8,
    /// The bytes; those past `len` are not sent and decode as 0.
    pub data: [u8; CHUNK_MAX],
}

impl UploadChunk {
    /// The chunk carrying `bytes` (at most [`CHUNK_MAX`]; more are cut off) at `offset`.
    pub fn new(offset: u32, bytes: &[u8]) -> Self {
        let n = bytes.len().min(CHUNK_MAX);
        let mut data = [0u8; CHUNK_MAX];
        data[..n].copy_from_slice(&bytes[..n]);
        Self {
            offset,
            len: n as u8,
            data,
        }
    }

    /// The chunk's bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.data[..(self.len as usize).min(CHUNK_MAX)]
    }
}

/// Host → device (v2): the upload is complete; the device checks that it received exactly
/// `len` bytes whose [`crc32`] is `crc32`, then loads the design.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct UploadCommit {
    /// Length of the design image, bytes.
    pub len: u32,
    /// CRC-32 (ISO-HDLC) of the image.
    pub crc32: u32,
}

/// Host → device (v2): run the loaded design onboard, with the device's own safety limits.
///
/// Positions are encoder counts as in a [`Measurement`]; the device stops (0 V, driver
/// disabled, brake where it can) as soon as `|arm − arm_center| > arm_limit` or
/// `|pendulum − pendulum_center| > pendulum_limit`, or no valid host frame arrived for
/// `host_timeout_ms`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct OnboardStart {
    /// Send one [`Telemetry`] record every this many controller steps (≥ 1).
    pub decimation: u16,
    /// Host-silence watchdog, milliseconds (≥ 1).
    pub host_timeout_ms: u16,
    /// Arm position of the arm limit's centre, counts.
    pub arm_center: i32,
    /// Arm limit, counts from `arm_center`.
    pub arm_limit: u32,
    /// Pendulum position of the pendulum limit's centre (upright), counts.
    pub pendulum_center: i32,
    /// Pendulum limit, counts from `pendulum_center`.
    pub pendulum_limit: u32,
    /// `ONBOARD_*` flags (v3; 0 for a v2 start): [`ONBOARD_WIRING_VERIFIED`].
    pub flags: u8,
}

/// [`OnboardStart`] and [`WatchdogStop`] flag (v3): the host's sign check passed on this rig
/// since the device's power-up, so the wiring's sign is known and the device may stop the arm
/// with the braking and hold laws of the onboard image's stop design; without it the device's
/// stop is the passive short.
pub const ONBOARD_WIRING_VERIFIED: u8 = 1 << 0;

/// Host → device (v3): what the device does when its v1 command watchdog trips in host mode
/// (the host went silent while the motor was enabled).
///
/// With [`ONBOARD_WIRING_VERIFIED`] (the host's sign check passed on this rig since the
/// device's power-up) and a loaded onboard image that has a stop's design, the device stops
/// the arm itself with that design's braking and hold laws, as it does in onboard mode, on
/// angles zeroed here: θ = 0 at arm count `arm_zero`, α = π (hanging) at pendulum count
/// `pendulum_down` (the host's calibration, which replaces the image's offsets for this stop).
/// Without the flag the watchdog's stop is the passive short (v1's). It holds until the next
/// watchdog stop, the plain stop command (the end of the host's run), an upload or an onboard
/// start. The device acks it: code [`ACK_OK`] with the
/// value 1 when its watchdog will run the laws and 0 for the short; [`ACK_NO_DESIGN`] without a
/// loaded image, [`ACK_BUSY`] while onboard mode runs, [`ACK_BAD_SETTINGS`] for a flag it does
/// not know (each changing nothing).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WatchdogStop {
    /// `ONBOARD_*` flags: [`ONBOARD_WIRING_VERIFIED`].
    pub flags: u8,
    /// Arm count at θ = 0.
    pub arm_zero: i32,
    /// Pendulum count with the pendulum hanging (α = π).
    pub pendulum_down: i32,
}

/// Host → device (v2): processor-in-the-loop. Step the loaded controller once on these
/// encoder positions (in place of the device's own) and answer with a [`PilMove`]. The motor
/// is not driven: the move is only reported. Refused while onboard mode runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PilStep {
    /// Arm position, counts.
    pub arm_counts: i32,
    /// Pendulum position, counts.
    pub pendulum_counts: i32,
    /// `PIL_*` flags.
    pub flags: u8,
}

/// Device → host (v2): the move of a [`PilStep`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PilMove {
    /// Sequence number of the step request answered.
    pub ack_seq: u16,
    /// Controller steps since the last reset (this one included).
    pub step: u32,
    /// The move (V) as the bits of an `f64` ([`voltage`](Self::voltage)), exactly as the
    /// controller computed it (an `f32` controller's value is exact in `f64`); NaN when
    /// refused. Bits, so that frames compare exactly.
    pub voltage_bits: u64,
    /// The step's duration in the device's cycle counter's units (0 without one).
    pub cycles: u32,
    /// `ACK_*` result code.
    pub code: u8,
}

impl PilMove {
    /// The move (V).
    pub fn voltage(&self) -> f64 {
        f64::from_bits(self.voltage_bits)
    }
}

/// Device → host (v2): the answer to an upload, commit, start, stop or watchdog stop frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ack {
    /// Sequence number of the host frame answered.
    pub ack_seq: u16,
    /// Message type of the host frame answered.
    pub request: u8,
    /// `ACK_*` result code.
    pub code: u8,
    /// For a chunk or a begin: the offset the device expects next. For a commit: the CRC-32
    /// the device computed over what it received. For a start or a stop: the
    /// `ONBOARD_*` state after it. For a watchdog stop: 1 when the device's watchdog will run
    /// the braking and hold laws, 0 for the short.
    pub value: u32,
}

/// Ack code: accepted.
pub const ACK_OK: u8 = 0;
/// Ack code: a chunk whose offset is not the next expected one (out of order or a duplicate);
/// the ack's value is the expected offset.
pub const ACK_OUT_OF_ORDER: u8 = 1;
/// Ack code: the image does not fit the device's design buffer, or a chunk runs past the
/// length announced by the begin.
pub const ACK_TOO_LARGE: u8 = 2;
/// Ack code: a chunk or commit without an upload begun.
pub const ACK_NO_UPLOAD: u8 = 3;
/// Ack code: the commit's length is not the number of bytes received.
pub const ACK_LENGTH_MISMATCH: u8 = 4;
/// Ack code: the commit's CRC-32 is not that of the bytes received.
pub const ACK_CRC_MISMATCH: u8 = 5;
/// Ack code: the image is intact but the device's controller refused it (another design
/// format version, a dimension it cannot hold, a value out of range).
pub const ACK_DESIGN_REFUSED: u8 = 6;
/// Ack code: onboard start without a committed design.
pub const ACK_NO_DESIGN: u8 = 7;
/// Ack code: an upload while onboard mode runs (stop it first).
pub const ACK_BUSY: u8 = 8;
/// Ack code: onboard start refused because the driver reports a fault, or a limit is already
/// exceeded.
pub const ACK_REFUSED: u8 = 9;
/// Ack code: onboard start with a zero decimation or host timeout, or a start or watchdog
/// stop with a flag the device does not know.
pub const ACK_BAD_SETTINGS: u8 = 10;

/// Onboard state: no onboard run since power-up or the last upload.
pub const ONBOARD_IDLE: u8 = 0;
/// Onboard state: the controller runs.
pub const ONBOARD_RUNNING: u8 = 1;
/// Onboard state: stopped by the host (an onboard stop or a command frame).
pub const ONBOARD_STOPPED: u8 = 2;
/// Onboard state: stopped on the arm limit.
pub const ONBOARD_ARM_LIMIT: u8 = 3;
/// Onboard state: stopped on the pendulum limit.
pub const ONBOARD_PENDULUM_LIMIT: u8 = 4;
/// Onboard state: stopped because the host went silent.
pub const ONBOARD_HOST_SILENT: u8 = 5;
/// Onboard state: stopped because a controller step overran its period.
pub const ONBOARD_OVERRUN: u8 = 6;
/// Onboard state: stopped because the driver reported a fault.
pub const ONBOARD_DRIVER_FAULT: u8 = 7;
/// Onboard state: stopped because the controller returned a non-finite move.
pub const ONBOARD_BAD_MOVE: u8 = 8;
/// Onboard state: stopped on a frame of another protocol version.
pub const ONBOARD_PROTOCOL: u8 = 9;

/// Device → host (v2): one onboard controller step, streamed every `decimation` steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Telemetry {
    /// Controller steps since the onboard start (wraps).
    pub step: u32,
    /// Device clock at the step's sampling instant, microseconds (wraps).
    pub device_time_us: u32,
    /// Arm encoder position the step used, counts.
    pub arm_counts: i32,
    /// Pendulum encoder position the step used, counts.
    pub pendulum_counts: i32,
    /// The voltage applied from this step on, millivolts (0 once stopped).
    pub applied_mv: i16,
    /// `STATUS_*` bits.
    pub status: u8,
    /// `ONBOARD_*` state.
    pub onboard: u8,
    /// Duration of the previous step, processor cycles (0 where the device cannot count).
    pub step_cycles: u32,
    /// Steps that overran their period since the start.
    pub overruns: u16,
    /// Steps since the start that applied the controller's fallback law (an MPC whose QP hit
    /// its iteration bound or failed; saturates).
    pub fallbacks: u16,
}
