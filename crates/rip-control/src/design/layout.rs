//! The byte layout of a [`Design`] (crate docs, "Byte layout"): its encoding, its decoding and
//! their checks.

use super::{CompensationDesign, Design, DesignError, Kind, HEADER_LEN, LAYOUT_VERSION, MAGIC};
use super::{MAX_CONTROL_HORIZON, MAX_NCON, MAX_NX, MAX_NY, NX_PLANT};
use crate::real::Real;
use rip_protocol::crc32;

impl<R: Real> Design<R> {
    /// Bytes [`to_bytes`](Self::to_bytes) writes for this design.
    pub fn encoded_len(&self) -> usize {
        let mut w = Sizer(0);
        self.write_body(&mut w);
        HEADER_LEN + w.0 + 4
    }

    /// Writes the design in the documented layout (crate docs) into `buf`; returns the length.
    ///
    /// # Errors
    /// [`DesignError::BufferTooSmall`] with the length needed; an invalid design (see
    /// [`validate`](Self::validate)) is refused as well, so only valid designs travel.
    pub fn to_bytes(&self, buf: &mut [u8]) -> Result<usize, DesignError> {
        self.validate()?;
        let needed = self.encoded_len();
        if buf.len() < needed {
            return Err(DesignError::BufferTooSmall { needed });
        }
        buf[..4].copy_from_slice(&MAGIC);
        buf[4..6].copy_from_slice(&LAYOUT_VERSION.to_le_bytes());
        buf[6] = self.kind.code();
        buf[7] = u8::from(self.cancels_input_disturbance) | (u8::from(self.regulates_outputs) << 1);
        let total = u32::try_from(needed).map_err(|_| DesignError::BadSize("length"))?;
        buf[8..12].copy_from_slice(&total.to_le_bytes());
        let mut w = Writer {
            buf: &mut buf[HEADER_LEN..needed - 4],
            pos: 0,
        };
        self.write_body(&mut w);
        let crc = crc32(&buf[..needed - 4]);
        buf[needed - 4..needed].copy_from_slice(&crc.to_le_bytes());
        Ok(needed)
    }

    /// Reads a design written by [`to_bytes`](Self::to_bytes) (the numbers travel as `f64`
    /// and are rounded to `R`), checking magic, version, length, CRC-32 and then
    /// [`validate`](Self::validate).
    ///
    /// # Errors
    /// The first check that fails.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, DesignError> {
        let mut d = Self::default();
        d.read_from(bytes)?;
        Ok(d)
    }

    /// [`from_bytes`](Self::from_bytes) into an existing design, for a device that keeps its
    /// one design in a static rather than on the stack. On error `self` is unspecified but
    /// valid to overwrite; do not run it.
    ///
    /// # Errors
    /// As [`from_bytes`](Self::from_bytes).
    pub fn read_from(&mut self, bytes: &[u8]) -> Result<(), DesignError> {
        if bytes.len() < HEADER_LEN + 4 {
            return Err(DesignError::Truncated);
        }
        if bytes[..4] != MAGIC {
            return Err(DesignError::BadMagic);
        }
        let version = u16::from_le_bytes([bytes[4], bytes[5]]);
        if version != LAYOUT_VERSION {
            return Err(DesignError::UnsupportedVersion(version));
        }
        let total = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize;
        if total != bytes.len() {
            return Err(DesignError::LengthMismatch);
        }
        let crc = u32::from_le_bytes([
            bytes[total - 4],
            bytes[total - 3],
            bytes[total - 2],
            bytes[total - 1],
        ]);
        if crc != crc32(&bytes[..total - 4]) {
            return Err(DesignError::BadChecksum);
        }
        let kind = Kind::from_code(bytes[6]).ok_or(DesignError::UnknownKind(bytes[6]))?;
        let flags = bytes[7];
        if flags & !0b11 != 0 {
            return Err(DesignError::BadValue("flags"));
        }
        self.clear(kind);
        self.cancels_input_disturbance = flags & 1 != 0;
        self.regulates_outputs = flags & 0b10 != 0;
        let mut r = Reader {
            buf: &bytes[HEADER_LEN..total - 4],
            pos: 0,
        };
        self.read_body(&mut r)?;
        if r.pos != r.buf.len() {
            return Err(DesignError::LengthMismatch);
        }
        self.validate()
    }

    fn write_body(&self, w: &mut impl Sink) {
        w.real(self.ts);
        w.reals(&self.input_bounds);
        let c = self.compensation;
        w.reals(&[
            c.dead_zone,
            c.friction_voltage,
            c.voltage_scale,
            c.velocity_scale,
        ]);
        w.reals(&self.k);
        w.real(self.integral_gain);
        if self.kind == Kind::Lqr {
            w.real(self.rate_cutoff_hz);
            if self.cancels_input_disturbance {
                w.reals(&self.a[..NX_PLANT * NX_PLANT]);
                w.reals(&self.b[..NX_PLANT]);
                w.reals(&self.disturbance_gain);
            }
            return;
        }
        let (n, ny) = (self.nx, self.ny);
        w.u16(n as u16);
        w.u16(ny as u16);
        w.reals(&self.a[..n * n]);
        w.reals(&self.b[..n]);
        w.reals(&self.c[..ny * n]);
        w.reals(&self.l[..n * ny]);
        w.reals(&self.m[..n * ny]);
        w.reals(&self.output_scales[..ny]);
        if self.kind != Kind::Mpc {
            return;
        }
        w.u16(self.horizon as u16);
        w.u16(self.control_horizon as u16);
        w.u16(self.n_input_rows as u16);
        w.u16(self.n_soft_rows as u16);
        w.u16(u16::try_from(self.max_iterations).unwrap_or(u16::MAX));
        let nz = self.nz();
        w.reals(&self.h[..nz * nz]);
        w.reals(&self.f0[..nz]);
        w.reals(&self.fx[..nz * n]);
        w.reals(&self.fu[..nz]);
        w.reals(&self.fr[..nz * ny]);
        w.reals(&self.ac[..self.ncon * nz]);
        w.reals(&self.b0[..self.ncon]);
        w.reals(&self.bx[..self.ncon * n]);
        w.reals(&self.bu[..self.ncon]);
    }

    fn read_body(&mut self, r: &mut Reader<'_>) -> Result<(), DesignError> {
        use DesignError::BadSize;
        self.ts = r.real()?;
        r.reals(&mut self.input_bounds)?;
        let mut comp = [R::ZERO; 4];
        r.reals(&mut comp)?;
        self.compensation = CompensationDesign {
            dead_zone: comp[0],
            friction_voltage: comp[1],
            voltage_scale: comp[2],
            velocity_scale: comp[3],
        };
        r.reals(&mut self.k)?;
        self.integral_gain = r.real()?;
        if self.kind == Kind::Lqr {
            self.rate_cutoff_hz = r.real()?;
            if self.cancels_input_disturbance {
                self.nx = NX_PLANT;
                r.reals(&mut self.a[..NX_PLANT * NX_PLANT])?;
                r.reals(&mut self.b[..NX_PLANT])?;
                r.reals(&mut self.disturbance_gain)?;
            }
            return Ok(());
        }
        let n = usize::from(r.u16()?);
        let ny = usize::from(r.u16()?);
        if n == 0 || n > MAX_NX {
            return Err(BadSize("nx"));
        }
        if ny == 0 || ny > MAX_NY {
            return Err(BadSize("ny"));
        }
        self.nx = n;
        self.ny = ny;
        r.reals(&mut self.a[..n * n])?;
        r.reals(&mut self.b[..n])?;
        r.reals(&mut self.c[..ny * n])?;
        r.reals(&mut self.l[..n * ny])?;
        r.reals(&mut self.m[..n * ny])?;
        r.reals(&mut self.output_scales[..ny])?;
        if self.kind != Kind::Mpc {
            return Ok(());
        }
        self.horizon = usize::from(r.u16()?);
        self.control_horizon = usize::from(r.u16()?);
        self.n_input_rows = usize::from(r.u16()?);
        self.n_soft_rows = usize::from(r.u16()?);
        self.max_iterations = u32::from(r.u16()?);
        if self.control_horizon == 0 || self.control_horizon > MAX_CONTROL_HORIZON {
            return Err(BadSize("control_horizon"));
        }
        self.ncon = self.n_input_rows + self.n_soft_rows + 1;
        if self.ncon > MAX_NCON {
            return Err(BadSize("ncon"));
        }
        let nz = self.nz();
        let ncon = self.ncon;
        r.reals(&mut self.h[..nz * nz])?;
        r.reals(&mut self.f0[..nz])?;
        r.reals(&mut self.fx[..nz * n])?;
        r.reals(&mut self.fu[..nz])?;
        r.reals(&mut self.fr[..nz * ny])?;
        r.reals(&mut self.ac[..ncon * nz])?;
        r.reals(&mut self.b0[..ncon])?;
        r.reals(&mut self.bx[..ncon * n])?;
        r.reals(&mut self.bu[..ncon])?;
        Ok(())
    }
}

trait Sink {
    fn bytes(&mut self, b: &[u8]);
    fn real<R: Real>(&mut self, v: R) {
        self.bytes(&v.to_f64().to_le_bytes());
    }
    fn reals<R: Real>(&mut self, v: &[R]) {
        for &x in v {
            self.real(x);
        }
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
}

struct Sizer(usize);

impl Sink for Sizer {
    fn bytes(&mut self, b: &[u8]) {
        self.0 += b.len();
    }
}

struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl Sink for Writer<'_> {
    fn bytes(&mut self, b: &[u8]) {
        // The caller sized the buffer with `encoded_len`.
        self.buf[self.pos..self.pos + b.len()].copy_from_slice(b);
        self.pos += b.len();
    }
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], DesignError> {
        let end = self.pos + N;
        let s = self.buf.get(self.pos..end).ok_or(DesignError::Truncated)?;
        self.pos = end;
        let mut out = [0u8; N];
        out.copy_from_slice(s);
        Ok(out)
    }
    fn real<R: Real>(&mut self) -> Result<R, DesignError> {
        Ok(R::from_f64(f64::from_le_bytes(self.take::<8>()?)))
    }
    fn reals<R: Real>(&mut self, out: &mut [R]) -> Result<(), DesignError> {
        for v in out {
            *v = self.real()?;
        }
        Ok(())
    }
    fn u16(&mut self) -> Result<u16, DesignError> {
        Ok(u16::from_le_bytes(self.take::<2>()?))
    }
}
