//! The live telemetry stream: one UDP datagram per period on loopback, for `riprs watch`.
//!
//! `rip-rt run`, `excite` and `emulate` publish what each period measured and decided when
//! `--live PORT` (or `[loop] live_port`) is given. The stream is off the hot path's critical
//! rules: the frame is encoded on the stack and sent with a non-blocking socket, so a viewer
//! that is slow, stopped (SIGSTOP) or absent loses frames (the kernel drops datagrams its
//! receive buffer has no room for, and `send` never waits), never the loop's timing. Unlike
//! the log, whose full queue stops the run, a full stream is not an error.
//!
//! The datagram is [`Frame`], a fixed little-endian layout of [`SIZE`] bytes defined once by
//! [`FIELDS`]: the Python viewer reads that table through the binding
//! (`riprs._riprs.live_frame_fields`) and builds its `struct` format from it, so the encoder
//! and the decoder cannot disagree. `docs/live.md` documents it.

use std::io;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};

/// The first four bytes of every frame.
pub const MAGIC: [u8; 4] = *b"RIPL";
/// The layout's version: a change of [`FIELDS`] increments it.
pub const VERSION: u16 = 1;

/// What a frame reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum Kind {
    /// One period of the loop: the measured angles, the estimate, the planned and written
    /// voltage, the reference, the phase and the status bits.
    Period = 1,
    /// The emulator's true plant state: `theta` and `alpha` the true angles, `estimate`
    /// `[θ, θ̇, α, α̇]`, `u_written` the voltage across the motor.
    Truth = 2,
    /// The run stopped: `exit_code` is rip-rt's exit code, `phase` the stop's kind.
    Stop = 3,
}

/// A field's wire type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ty {
    /// Little-endian `u16`.
    U16,
    /// Little-endian `u32`.
    U32,
    /// Little-endian `i32`.
    I32,
    /// Little-endian `u64`.
    U64,
    /// Little-endian IEEE 754 `f64`.
    F64,
    /// Bytes (ASCII, NUL-padded).
    Bytes,
}

impl Ty {
    /// Bytes of one element.
    pub const fn size(self) -> usize {
        match self {
            Ty::U16 => 2,
            Ty::U32 | Ty::I32 => 4,
            Ty::U64 | Ty::F64 => 8,
            Ty::Bytes => 1,
        }
    }

    /// Python `struct` code of `count` elements (`count` values, or one `bytes` for
    /// [`Ty::Bytes`]).
    pub fn struct_code(self, count: usize) -> String {
        let c = match self {
            Ty::U16 => 'H',
            Ty::U32 => 'I',
            Ty::I32 => 'i',
            Ty::U64 => 'Q',
            Ty::F64 => 'd',
            Ty::Bytes => 's',
        };
        if count == 1 {
            c.to_string()
        } else {
            format!("{count}{c}")
        }
    }
}

/// One field of the layout.
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// Its name (the Python decoder's key).
    pub name: &'static str,
    /// Its wire type.
    pub ty: Ty,
    /// Elements.
    pub count: usize,
    /// What it holds.
    pub doc: &'static str,
}

/// Entries of [`Frame::estimate`].
pub const ESTIMATES: usize = 4;
/// Bytes of [`Frame::phase`].
pub const PHASE_BYTES: usize = 16;

trait Wire: Sized {
    const TY: Ty;
    const COUNT: usize;
    fn put(&self, out: &mut [u8], at: &mut usize);
    fn get(buf: &[u8], at: &mut usize) -> Self;
}

macro_rules! scalar_wire {
    ($t:ty, $ty:expr) => {
        impl Wire for $t {
            const TY: Ty = $ty;
            const COUNT: usize = 1;
            fn put(&self, out: &mut [u8], at: &mut usize) {
                let b = self.to_le_bytes();
                out[*at..*at + b.len()].copy_from_slice(&b);
                *at += b.len();
            }
            fn get(buf: &[u8], at: &mut usize) -> Self {
                const N: usize = std::mem::size_of::<$t>();
                let mut b = [0u8; N];
                b.copy_from_slice(&buf[*at..*at + N]);
                *at += N;
                <$t>::from_le_bytes(b)
            }
        }
    };
}
scalar_wire!(u16, Ty::U16);
scalar_wire!(u32, Ty::U32);
scalar_wire!(i32, Ty::I32);
scalar_wire!(u64, Ty::U64);
scalar_wire!(f64, Ty::F64);

impl<const N: usize> Wire for [f64; N] {
    const TY: Ty = Ty::F64;
    const COUNT: usize = N;
    fn put(&self, out: &mut [u8], at: &mut usize) {
        for x in self {
            x.put(out, at);
        }
    }
    fn get(buf: &[u8], at: &mut usize) -> Self {
        std::array::from_fn(|_| f64::get(buf, at))
    }
}

impl<const N: usize> Wire for [u8; N] {
    const TY: Ty = Ty::Bytes;
    const COUNT: usize = N;
    fn put(&self, out: &mut [u8], at: &mut usize) {
        out[*at..*at + N].copy_from_slice(self);
        *at += N;
    }
    fn get(buf: &[u8], at: &mut usize) -> Self {
        let mut b = [0u8; N];
        b.copy_from_slice(&buf[*at..*at + N]);
        *at += N;
        b
    }
}

// The one definition of the layout: the struct, its field table, the encoder and the decoder
// all come from this list, in this order.
macro_rules! frame {
    ($( #[doc = $doc:literal] $name:ident : $t:ty ),* $(,)?) => {
        /// One datagram of the stream (module docs); `NaN` where a value does not apply.
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct Frame {
            $( #[doc = $doc] pub $name: $t, )*
        }

        /// The layout, in wire order.
        pub const FIELDS: &[Field] = &[
            $( Field {
                name: stringify!($name),
                ty: <$t as Wire>::TY,
                count: <$t as Wire>::COUNT,
                doc: $doc.trim_ascii(),
            }, )*
        ];

        /// Bytes of a frame.
        pub const SIZE: usize = 0 $( + <$t as Wire>::COUNT * <$t as Wire>::TY.size() )*;

        impl Frame {
            /// The frame's bytes.
            pub fn encode(&self) -> [u8; SIZE] {
                let mut out = [0u8; SIZE];
                let mut at = 0;
                $( self.$name.put(&mut out, &mut at); )*
                out
            }

            /// A frame from its bytes: `None` for a datagram of another size, magic or
            /// version.
            pub fn decode(buf: &[u8]) -> Option<Self> {
                if buf.len() != SIZE {
                    return None;
                }
                let mut at = 0;
                let frame = Frame { $( $name: <$t as Wire>::get(buf, &mut at), )* };
                (frame.magic == MAGIC && frame.version == VERSION).then_some(frame)
            }
        }
    };
}

frame! {
    /// `RIPL`.
    magic: [u8; 4],
    /// The layout's version.
    version: u16,
    /// What the frame reports: 1 a period, 2 the emulator's true state, 3 the run's stop.
    kind: u16,
    /// The sender's frame counter, from 0: a gap is frames lost on the way.
    counter: u32,
    /// The sender's `CLOCK_MONOTONIC` when sent (ns), for the viewer's lag.
    sent_ns: u64,
    /// Time (s): the log's `t` for a period, simulated time for the emulator.
    t: f64,
    /// The sample request's sequence number (the log's `seq`).
    seq: u32,
    /// Measured arm angle θ (rad).
    theta: f64,
    /// Measured pendulum angle α (rad from upright).
    alpha: f64,
    /// Arm reference (rad).
    theta_ref: f64,
    /// The controller's voltage before the clamp (V).
    u_planned: f64,
    /// The voltage written to the device (V, clamped).
    u_written: f64,
    /// The controller's state estimate `[θ, θ̇, α, α̇]` (NaN without one).
    estimate: [f64; 4],
    /// The log's status bits (device status, no reply, fallback, clamped, deadline miss).
    status: u32,
    /// rip-rt's exit code in a stop frame, else 0.
    exit_code: i32,
    /// `safety.voltage_limit` (V).
    voltage_limit: f64,
    /// `safety.arm_limit` (rad).
    arm_limit: f64,
    /// `safety.pendulum_limit` (rad).
    pendulum_limit: f64,
    /// Compute time (µs).
    compute_us: f64,
    /// Wake-up lateness (µs).
    jitter_us: f64,
    /// The log's `phase` (ASCII, NUL-padded), or the stop's kind.
    phase: [u8; 16],
}

impl Frame {
    /// An empty frame of `kind` (every value NaN or 0) with the bounds of the run.
    pub fn new(kind: Kind, bounds: Bounds) -> Self {
        Frame {
            magic: MAGIC,
            version: VERSION,
            kind: kind as u16,
            counter: 0,
            sent_ns: 0,
            t: f64::NAN,
            seq: 0,
            theta: f64::NAN,
            alpha: f64::NAN,
            theta_ref: f64::NAN,
            u_planned: f64::NAN,
            u_written: f64::NAN,
            estimate: [f64::NAN; ESTIMATES],
            status: 0,
            exit_code: 0,
            voltage_limit: bounds.voltage_limit,
            arm_limit: bounds.arm_limit,
            pendulum_limit: bounds.pendulum_limit,
            compute_us: f64::NAN,
            jitter_us: f64::NAN,
            phase: [0; PHASE_BYTES],
        }
    }

    /// Sets the phase, cut to [`PHASE_BYTES`].
    pub fn with_phase(mut self, phase: &str) -> Self {
        let n = phase.len().min(PHASE_BYTES);
        self.phase = [0; PHASE_BYTES];
        self.phase[..n].copy_from_slice(&phase.as_bytes()[..n]);
        self
    }

    /// Copies the first [`ESTIMATES`] entries of `x`.
    pub fn with_estimate(mut self, x: Option<&[f64]>) -> Self {
        if let Some(x) = x {
            for (e, v) in self.estimate.iter_mut().zip(x) {
                *e = *v;
            }
        }
        self
    }
}

/// The limits the viewer draws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// `safety.voltage_limit` (V).
    pub voltage_limit: f64,
    /// `safety.arm_limit` (rad).
    pub arm_limit: f64,
    /// `safety.pendulum_limit` (rad).
    pub pendulum_limit: f64,
}

impl Bounds {
    /// The bounds of `cfg`'s `[safety]`.
    pub fn of(cfg: &crate::config::Config) -> Self {
        Bounds {
            voltage_limit: cfg.safety.voltage_limit,
            arm_limit: cfg.safety.arm_limit,
            pendulum_limit: cfg.safety.pendulum_limit,
        }
    }
}

/// The sending end: a non-blocking UDP socket connected to `127.0.0.1:port`.
#[derive(Debug)]
pub struct Live {
    socket: UdpSocket,
    bounds: Bounds,
    counter: u32,
    /// Frames the socket did not take (a full send buffer; no viewer is not counted: on
    /// loopback the kernel drops those datagrams after `send`).
    pub dropped: u64,
}

impl Live {
    /// A stream to `127.0.0.1:port` with the run's `bounds`; an error names the port.
    pub fn open(port: u16, bounds: Bounds) -> io::Result<Self> {
        let named = |e: io::Error| io::Error::new(e.kind(), format!("--live {port}: {e}"));
        let socket = UdpSocket::bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0)).map_err(named)?;
        socket.set_nonblocking(true).map_err(named)?;
        socket
            .connect(SocketAddrV4::new(Ipv4Addr::LOCALHOST, port))
            .map_err(named)?;
        Ok(Live {
            socket,
            bounds,
            counter: 0,
            dropped: 0,
        })
    }

    /// A stream for `port`, `None` for 0 (off); a socket that cannot be made is a warning,
    /// not a reason to refuse a run.
    pub fn for_port(port: u16, bounds: Bounds) -> Option<Self> {
        if port == 0 {
            return None;
        }
        match Self::open(port, bounds) {
            Ok(live) => Some(live),
            Err(e) => {
                crate::say!("rip-rt: warning: no live stream: {e}");
                None
            }
        }
    }

    /// An empty frame of `kind` with this stream's bounds.
    pub fn frame(&self, kind: Kind) -> Frame {
        Frame::new(kind, self.bounds)
    }

    /// Sends `frame` with the next counter and the send time. Never waits and never fails:
    /// a viewer that is not there, or not reading, loses the frame.
    pub fn send(&mut self, mut frame: Frame) {
        frame.counter = self.counter;
        self.counter = self.counter.wrapping_add(1);
        frame.sent_ns = crate::timing::now_ns();
        let bytes = frame.encode();
        // ECONNREFUSED (no viewer bound: the kernel's answer to an earlier datagram) and
        // EAGAIN (the buffer is full) alike drop this frame.
        if self.socket.send(&bytes).is_err() {
            self.dropped += 1;
        }
    }

    /// Sends the stop frame of a run that ended with `exit_code` for `why`.
    pub fn stop(&mut self, t: f64, exit_code: i32, why: &str) {
        let mut f = self.frame(Kind::Stop).with_phase(why);
        f.t = t;
        f.exit_code = exit_code;
        self.send(f);
    }
}

/// The `struct` format of a frame for Python's `struct` module (little-endian, no padding).
pub fn struct_format() -> String {
    let mut s = String::from("<");
    for f in FIELDS {
        s.push_str(&f.ty.struct_code(f.count));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bounds() -> Bounds {
        Bounds {
            voltage_limit: 12.0,
            arm_limit: 3.0,
            pendulum_limit: 0.5,
        }
    }

    #[test]
    fn a_frame_decodes_to_itself_and_its_size_follows_the_table() {
        let mut f = Frame::new(Kind::Period, bounds())
            .with_phase("balance")
            .with_estimate(Some(&[1.0, 2.0, 3.0, 4.0, 5.0]));
        f.theta = 0.25;
        f.status = 1 << 10;
        let b = f.encode();
        assert_eq!(b.len(), SIZE);
        assert_eq!(
            SIZE,
            FIELDS.iter().map(|f| f.ty.size() * f.count).sum::<usize>()
        );
        let back = Frame::decode(&b).unwrap();
        assert_eq!(back.theta, 0.25);
        assert_eq!(back.estimate, [1.0, 2.0, 3.0, 4.0]);
        assert_eq!(&back.phase[..8], b"balance\0");
        assert!(back.alpha.is_nan());
        assert_eq!(&b[..4], b"RIPL");
    }

    #[test]
    fn a_datagram_of_another_size_or_version_is_refused() {
        let b = Frame::new(Kind::Stop, bounds()).encode();
        assert!(Frame::decode(&b[..SIZE - 1]).is_none());
        let mut other = b;
        other[4] = 9;
        assert!(Frame::decode(&other).is_none());
    }

    #[test]
    fn the_struct_format_has_one_code_per_field() {
        let f = struct_format();
        assert!(f.starts_with("<4sHHIQdIddddd4dIiddddd16s"), "{f}");
    }

    #[test]
    fn frames_reach_a_reader_and_a_missing_one_costs_nothing() {
        let reader = UdpSocket::bind("127.0.0.1:0").unwrap();
        let port = reader.local_addr().unwrap().port();
        let mut live = Live::open(port, bounds()).unwrap();
        for _ in 0..3 {
            live.send(live.frame(Kind::Period));
        }
        let mut buf = [0u8; 2 * SIZE];
        for k in 0..3 {
            let n = reader.recv(&mut buf).unwrap();
            assert_eq!(Frame::decode(&buf[..n]).unwrap().counter, k);
        }
        drop(reader);
        // Nobody listens now: sending still returns at once.
        for _ in 0..100 {
            live.send(live.frame(Kind::Period));
        }
    }
}
