//! The scalar the controllers compute in: `f64` on the host, `f64` or `f32` on the chip.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A floating-point scalar: [`f64`] or [`f32`]. Every transcendental goes through `libm`, so
/// the host and the chip evaluate the same functions.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialEq
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// The unit round-off `ε` of the format.
    const EPSILON: Self;
    /// The nearest value to `v`.
    fn from_f64(v: f64) -> Self;
    /// The value as `f64` (exact).
    fn to_f64(self) -> f64;
    /// Whether neither NaN nor infinite.
    fn is_finite(self) -> bool;
    /// Square root (`libm`).
    fn sqrt(self) -> Self;
    /// Exponential (`libm`).
    fn exp(self) -> Self;
    /// `self^n` (`libm`'s `pow`).
    fn powu(self, n: u32) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Sine (`libm`).
    fn sin(self) -> Self;
    /// Cosine (`libm`).
    fn cos(self) -> Self;
    /// The nearest integer, halves away from zero (`libm`'s `round`, exact).
    fn round(self) -> Self;
    /// `ln(1 + self)`, accurate near 0 (`libm`'s `log1p`).
    fn ln_1p(self) -> Self;
    /// `1` for `+0` and positive values, `−1` for `−0` and negative ones, NaN for NaN: the
    /// semantics of `f64::signum`.
    fn signum(self) -> Self;
    /// The larger of the two; `self` when `other` is NaN.
    #[inline]
    fn max(self, other: Self) -> Self {
        if other > self {
            other
        } else {
            self
        }
    }
    /// The smaller of the two; `self` when `other` is NaN.
    #[inline]
    fn min(self, other: Self) -> Self {
        if other < self {
            other
        } else {
            self
        }
    }
    /// `self` clamped to `[lo, hi]` (`lo ≤ hi`), with the semantics of `f64::clamp`.
    #[inline]
    fn clamp(self, lo: Self, hi: Self) -> Self {
        let mut v = self;
        if v < lo {
            v = lo;
        }
        if v > hi {
            v = hi;
        }
        v
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f64::EPSILON;
    #[inline]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::exp(self)
    }
    #[inline]
    fn powu(self, n: u32) -> Self {
        libm::pow(self, f64::from(n))
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline]
    fn sin(self) -> Self {
        libm::sin(self)
    }
    #[inline]
    fn cos(self) -> Self {
        libm::cos(self)
    }
    #[inline]
    fn round(self) -> Self {
        libm::round(self)
    }
    #[inline]
    fn ln_1p(self) -> Self {
        libm::log1p(self)
    }
    #[inline]
    fn signum(self) -> Self {
        if self.is_nan() {
            self
        } else {
            libm::copysign(1.0, self)
        }
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f32::EPSILON;
    #[inline]
    fn from_f64(v: f64) -> Self {
        #[allow(clippy::cast_possible_truncation)] // rounding to f32 is the point
        let r = v as f32;
        r
    }
    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrtf(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::expf(self)
    }
    #[inline]
    fn powu(self, n: u32) -> Self {
        #[allow(clippy::cast_precision_loss)] // held-period counts are small
        let e = n as f32;
        libm::powf(self, e)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    #[inline]
    fn sin(self) -> Self {
        libm::sinf(self)
    }
    #[inline]
    fn cos(self) -> Self {
        libm::cosf(self)
    }
    #[inline]
    fn round(self) -> Self {
        libm::roundf(self)
    }
    #[inline]
    fn ln_1p(self) -> Self {
        libm::log1pf(self)
    }
    #[inline]
    fn signum(self) -> Self {
        if self.is_nan() {
            self
        } else {
            libm::copysignf(1.0, self)
        }
    }
}
