//! What a device needs to run the stop itself ([`StopDesign`]), and its byte layout.
//!
//! # Byte layout (version 1)
//!
//! Little-endian; every real an IEEE-754 `f64` (a `StopDesign<f32>` rounds them once when it
//! reads them). It travels inside a larger image whose whole checksum the carrier checks (the
//! onboard image of `rip-device`), so it has none of its own.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"RIPS"` |
//! | 4 | 2 | layout version `u16` = 1 |
//! | 6 | 2 | reals that follow `u16` = 15 |
//! | 8 | 16 | braking law `[U, ω_lin]` |
//! | 24 | 8 | dead band (rad/s) |
//! | 32 | 32 | hold law `K` (4) |
//! | 64 | 56 | model `[J₀, J_α, m₁₂, G, b, c, d_p]` |
//! | 120 | 8 | dead zone `V_d` (V) |

use super::*;

/// The first four bytes of an encoded [`StopDesign`].
pub const STOP_MAGIC: [u8; 4] = *b"RIPS";
/// The version of the layout [`StopDesign::write`] writes.
pub const STOP_LAYOUT_VERSION: u16 = 1;
/// Reals in the layout.
const STOP_REALS: usize = 15;
/// Bytes of an encoded [`StopDesign`].
pub const STOP_DESIGN_LEN: usize = 8 + 8 * STOP_REALS;

/// Why bytes are not a [`StopDesign`] (the field named).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopDesignError {
    /// Fewer bytes than the layout.
    Truncated,
    /// Not the magic `"RIPS"`.
    BadMagic,
    /// Another layout version, or another count of reals.
    UnsupportedVersion(u16),
    /// A value out of its range.
    BadValue(&'static str),
}

impl core::fmt::Display for StopDesignError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Truncated => write!(f, "the stop design is truncated"),
            Self::BadMagic => write!(f, "not a stop design (magic)"),
            Self::UnsupportedVersion(v) => write!(f, "stop design layout version {v} unsupported"),
            Self::BadValue(name) => write!(f, "stop design: {name} out of range"),
        }
    }
}

/// The stop's rule for one rig, as a device runs it: the braking law with its dead band, the
/// hold law, the smooth model (the arm's momentum for the braking law, the simulated stop) and
/// the dead zone. rip-core fills it from the plant (`envelope`); [`sequence`](Self::sequence)
/// is the stop a device runs after a fault.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StopDesign<R: Real = f64> {
    /// The braking law.
    pub law: BrakingLaw<R>,
    /// Arm speed (rad/s) below which the braking law applies 0 V ([`Brake::new`]).
    pub dead_band: R,
    /// The hold law (its voltage bound is the braking law's).
    pub hold: HoldLaw<R>,
    /// The smooth model.
    pub model: ArmModel<R>,
    /// The motor's dead zone `V_d` (V).
    pub dead_zone: R,
}

impl<R: Real> StopDesign<R> {
    fn reals(&self) -> [R; STOP_REALS] {
        let (l, k, m) = (self.law, self.hold.k, self.model);
        [
            l.voltage,
            l.linear_below,
            self.dead_band,
            k[0],
            k[1],
            k[2],
            k[3],
            m.j0,
            m.ja,
            m.m12,
            m.grav,
            m.b,
            m.c_arm,
            m.dp,
            self.dead_zone,
        ]
    }

    fn from_reals(v: [R; STOP_REALS]) -> Self {
        Self {
            law: BrakingLaw {
                voltage: v[0],
                linear_below: v[1],
            },
            dead_band: v[2],
            hold: HoldLaw {
                k: [v[3], v[4], v[5], v[6]],
                voltage: v[0],
            },
            model: ArmModel {
                j0: v[7],
                ja: v[8],
                m12: v[9],
                grav: v[10],
                b: v[11],
                c_arm: v[12],
                dp: v[13],
            },
            dead_zone: v[14],
        }
    }

    /// Checks every number for what it must be; the error names the field.
    pub fn validate(&self) -> Result<(), StopDesignError> {
        use StopDesignError::BadValue;
        if !self.reals().iter().all(|v| v.is_finite()) {
            return Err(BadValue("a value is not finite"));
        }
        let positive = |v: R| v > R::ZERO;
        if !(positive(self.law.voltage) && positive(self.law.linear_below)) {
            return Err(BadValue("braking law"));
        }
        if self.hold.voltage != self.law.voltage {
            return Err(BadValue("hold law voltage"));
        }
        if self.dead_band < R::ZERO || self.dead_zone < R::ZERO {
            return Err(BadValue("dead band or dead zone"));
        }
        let m = self.model;
        // The inertia matrix is positive definite: J₀ J_α > m₁₂².
        if !(positive(m.j0) && positive(m.ja) && m.j0 * m.ja > m.m12 * m.m12) {
            return Err(BadValue("model inertias"));
        }
        if !(positive(m.b) && m.c_arm >= R::ZERO && m.dp >= R::ZERO && m.grav >= R::ZERO) {
            return Err(BadValue("model coefficients"));
        }
        Ok(())
    }

    /// Writes the layout (module docs) into `buf`; the length written.
    ///
    /// # Errors
    /// [`StopDesignError::Truncated`] when `buf` is shorter than [`STOP_DESIGN_LEN`]; an
    /// invalid design ([`validate`](Self::validate)) is refused, so only valid ones travel.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, StopDesignError> {
        self.validate()?;
        let out = buf
            .get_mut(..STOP_DESIGN_LEN)
            .ok_or(StopDesignError::Truncated)?;
        out[..4].copy_from_slice(&STOP_MAGIC);
        out[4..6].copy_from_slice(&STOP_LAYOUT_VERSION.to_le_bytes());
        out[6..8].copy_from_slice(&(STOP_REALS as u16).to_le_bytes());
        for (i, v) in self.reals().iter().enumerate() {
            out[8 + 8 * i..16 + 8 * i].copy_from_slice(&v.to_f64().to_le_bytes());
        }
        Ok(STOP_DESIGN_LEN)
    }

    /// Reads the layout from the start of `bytes` (which may go on past it), then
    /// [`validate`](Self::validate)s.
    ///
    /// # Errors
    /// The first check that fails.
    pub fn read(bytes: &[u8]) -> Result<Self, StopDesignError> {
        let b = bytes
            .get(..STOP_DESIGN_LEN)
            .ok_or(StopDesignError::Truncated)?;
        if b[..4] != STOP_MAGIC {
            return Err(StopDesignError::BadMagic);
        }
        let version = u16::from_le_bytes([b[4], b[5]]);
        let count = u16::from_le_bytes([b[6], b[7]]);
        if version != STOP_LAYOUT_VERSION || usize::from(count) != STOP_REALS {
            return Err(StopDesignError::UnsupportedVersion(version));
        }
        let mut v = [R::ZERO; STOP_REALS];
        for (i, x) in v.iter_mut().enumerate() {
            let mut raw = [0u8; 8];
            raw.copy_from_slice(&b[8 + 8 * i..16 + 8 * i]);
            *x = R::from_f64(f64::from_le_bytes(raw));
        }
        let d = Self::from_reals(v);
        d.validate()?;
        Ok(d)
    }

    /// The stop a device runs after a fault at the loop period `period_s` (s): with the
    /// wiring's sign `verified` (a sign check passed), the braking law on the arm's momentum,
    /// then the hold law, then the short; without, the passive short alone (a voltage of the
    /// wrong sign would drive the arm on).
    pub fn sequence(&self, period_s: f64, verified: bool) -> StopSequence<R> {
        if verified {
            StopSequence::new(
                Brake::new(self.law, self.dead_band, BrakeMode::Active),
                Some(self.hold),
                Some(self.model),
                period_s,
                self.law.voltage,
            )
        } else {
            StopSequence::new(
                Brake::new(self.law, self.dead_band, BrakeMode::Short),
                None,
                None,
                period_s,
                self.law.voltage,
            )
        }
    }
}
