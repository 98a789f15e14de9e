//! The sine and cosine of the plant's equations of motion, evaluated together, without
//! branches, so that a batch of pendulums evaluates them in SIMD lanes with the same bits as
//! one pendulum.
//!
//! # Method
//!
//! Cody–Waite reduction by `π/2` in four parts, then fdlibm's minimax polynomials on
//! `[−π/4, π/4]` (Sun's `__kernel_sin` / `__kernel_cos`, error below 1 ulp of the reduced
//! argument):
//!
//! ```text
//! k = round(x · 2/π),   r = (((x − k P₁) − k P₂) − k P₃) − k P₄,   P₁ + P₂ + P₃ + P₄ ≈ π/2
//! z = r²
//! sin r = r + z r (S₁ + z (S₂ + z (S₃ + z (S₄ + z (S₅ + z S₆)))))
//! cos r = w + (((1 − w) − z/2) + z² (C₁ + z (C₂ + … + z C₆))),   w = 1 − z/2
//! (sin x, cos x) = (sin r, cos r), (cos r, −sin r), (−sin r, −cos r), (−cos r, sin r)  for k mod 4 = 0…3
//! ```
//!
//! `P₁`, `P₂` and `P₃` carry 33 significant bits, so their products with `k` are exact for
//! `|k| < 2²⁰`, and near a multiple of `π/2` (where `r` is small) each subtraction is exact
//! (Sterbenz); `P₄` is the 53-bit tail, and `π/2 − ΣPᵢ ≈ 10⁻⁴⁸`. The reduced argument is then
//! within about half an ulp of `x − k π/2` up to `|x| ≤` [`FAST_RANGE`]. Beyond it (and for non-finite
//! arguments) the platform's `sin` and `cos` are used. The rounding `k = round(x · 2/π)` adds
//! and subtracts `1.5 · 2⁵²`, whose low mantissa bits are then `k mod 4`: no float-to-integer
//! conversion, no branch, so the loop over a batch vectorises.
//!
//! Accuracy (tested against the platform's `sin`/`cos`, glibc's being correctly rounded in
//! practice): at most 2 ulp (relative error `≤ 2.3·10⁻¹⁶`) on `|x| ≤ FAST_RANGE`, the
//! correctly rounded value for most arguments; far below the RK4 truncation error of any
//! step the plant takes.

// The constants are written as fdlibm prints them (21 significant digits), each of which rounds
// to the intended double.
#![allow(clippy::excessive_precision)]

/// Largest `|x|` (rad) reduced here; beyond it [`sin_cos`] calls the platform's functions.
/// `|x| ≤ 10⁶` keeps `|k| ≤ 636 620 < 2²⁰` (module docs).
pub const FAST_RANGE: f64 = 1.0e6;

const FRAC_2_PI: f64 = std::f64::consts::FRAC_2_PI;
/// `1.5 · 2⁵²`: adding it rounds to an integer (round to nearest, ties to even).
const ROUND_SHIFT: f64 = 6_755_399_441_055_744.0;
/// `π/2` in four parts (fdlibm's `pio2_1`, `pio2_2`, `pio2_3`, `pio2_3t`); the first three have
/// 33 bits.
const PIO2_1: f64 = 1.570_796_326_734_125_614_17e0;
const PIO2_2: f64 = 6.077_100_506_303_965_976_60e-11;
const PIO2_3: f64 = 2.022_266_248_711_166_455_80e-21;
const PIO2_4: f64 = 8.478_427_660_368_899_569_97e-32;

const S1: f64 = -1.666_666_666_666_663_243_48e-1;
const S2: f64 = 8.333_333_333_322_489_461_24e-3;
const S3: f64 = -1.984_126_982_985_794_931_34e-4;
const S4: f64 = 2.755_731_370_707_006_767_89e-6;
const S5: f64 = -2.505_076_025_340_686_341_95e-8;
const S6: f64 = 1.589_690_995_211_550_102_21e-10;

const C1: f64 = 4.166_666_666_666_660_190_37e-2;
const C2: f64 = -1.388_888_888_887_410_957_49e-3;
const C3: f64 = 2.480_158_728_947_672_941_78e-5;
const C4: f64 = -2.755_731_435_139_066_330_35e-7;
const C5: f64 = 2.087_572_321_298_174_827_90e-9;
const C6: f64 = -1.135_964_755_778_819_482_65e-11;

/// The reduction and polynomials of the module docs, for any `x` (meaningful for
/// `|x| ≤` [`FAST_RANGE`]).
#[inline(always)]
fn reduced(x: f64) -> (f64, f64) {
    let t = x * FRAC_2_PI + ROUND_SHIFT;
    let quadrant = t.to_bits();
    let k = t - ROUND_SHIFT;
    let r = (((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3) - k * PIO2_4;
    let z = r * r;
    let sin_r = r + z * r * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    let cos_poly = z * z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))));
    let cos_r = w + (((1.0 - w) - hz) + cos_poly);
    // Odd quadrants swap sine and cosine; quadrants 2, 3 negate the sine, 1, 2 the cosine.
    let swap = 0u64.wrapping_sub(quadrant & 1);
    let (sb, cb) = (sin_r.to_bits(), cos_r.to_bits());
    let sin_bits = (cb & swap) | (sb & !swap);
    let cos_bits = (sb & swap) | (cb & !swap);
    let sin_sign = (quadrant & 2) << 62;
    let cos_sign = (quadrant.wrapping_add(1) & 2) << 62;
    (
        f64::from_bits(sin_bits ^ sin_sign),
        f64::from_bits(cos_bits ^ cos_sign),
    )
}

/// `|x| ≤` [`FAST_RANGE`] (false for NaN).
#[inline(always)]
fn in_fast_range(x: f64) -> bool {
    x.abs() <= FAST_RANGE
}

/// `(sin x, cos x)` (module docs).
#[inline(always)]
pub fn sin_cos(x: f64) -> (f64, f64) {
    if in_fast_range(x) {
        reduced(x)
    } else {
        x.sin_cos()
    }
}

/// [`sin_cos`] of every lane: the same bits as `L` calls, computed without branches (the
/// lanes beyond [`FAST_RANGE`] are redone by the platform's functions afterwards).
#[inline(always)]
pub fn sin_cos_lanes<const L: usize>(x: &[f64; L]) -> ([f64; L], [f64; L]) {
    let mut s = [0.0; L];
    let mut c = [0.0; L];
    for l in 0..L {
        (s[l], c[l]) = reduced(x[l]);
    }
    if !x.iter().all(|v| in_fast_range(*v)) {
        for l in 0..L {
            if !in_fast_range(x[l]) {
                (s[l], c[l]) = x[l].sin_cos();
            }
        }
    }
    (s, c)
}

/// `a` wrapped to (−π, π]: the one angle wrap of the plant, the simulation, the swing-up and
/// `rip-rt`, the `no_std` code's ([`rip_control::swing::wrap_angle`]) that the firmware runs.
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    rip_control::swing::wrap_angle(a)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two finite doubles of the same sign or zero.
    fn ulps(a: f64, b: f64) -> u64 {
        let key = |v: f64| {
            let bits = v.to_bits() as i64;
            if bits < 0 {
                i64::MIN - bits
            } else {
                bits
            }
        };
        key(a).abs_diff(key(b))
    }

    #[test]
    fn within_two_ulp_of_the_platform_over_the_fast_range() {
        // A deterministic spread: dense near zero and near multiples of π/2 (where the
        // reduction cancels), then logarithmically out to the end of the fast range.
        let mut xs: Vec<f64> = (-200_000..=200_000).map(|i| i as f64 * 1e-4).collect();
        for k in -2000i32..=2000 {
            let m = f64::from(k) * std::f64::consts::FRAC_PI_2;
            for d in [-1e-9, -1e-13, 0.0, 1e-13, 1e-9] {
                xs.push(m + d);
            }
        }
        let mut v = 1e-300f64;
        while v <= FAST_RANGE {
            xs.extend([v, -v]);
            v *= 1.0 + 1e-4;
        }
        let mut worst = 0;
        let (mut n_off, mut n_two) = (0, 0);
        for &x in &xs {
            let (s, c) = sin_cos(x);
            let (s_ref, c_ref) = (x.sin(), x.cos());
            // At exact zeros of the reference the ulp distance is meaningless: compare absolutely.
            for (got, want) in [(s, s_ref), (c, c_ref)] {
                if want.abs() < 1e-300 {
                    assert!(got.abs() < 1e-300, "{x}: {got} vs {want}");
                } else {
                    let d = ulps(got, want);
                    assert!(d <= 2, "x = {x:e}: {got:e} vs {want:e} ({d} ulp)");
                    n_off += usize::from(d > 0);
                    n_two += usize::from(d > 1);
                    worst = worst.max(d);
                }
            }
        }
        eprintln!(
            "{n_off} off by 1 or 2 ulp, {n_two} by 2, of {}",
            2 * xs.len()
        );
        // Mostly the correctly rounded value; off by 2 ulp only where two roundings of the
        // reduction and one of the polynomial add up.
        assert!(n_off * 20 < 2 * xs.len() && n_two * 1000 < 2 * xs.len());
    }

    #[test]
    fn the_first_parts_of_half_pi_have_33_bits() {
        for p in [PIO2_1, PIO2_2, PIO2_3] {
            assert_eq!(p.to_bits() & ((1 << 20) - 1), 0, "{p:e}");
        }
        // Their sum is π/2 to 10⁻⁴⁸: the test above finds sin and cos within 2 ulp right next
        // to multiples of π/2, where any error of the sum would show first.
    }

    #[test]
    fn known_values_symmetries_and_the_fallback() {
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
        let (s, c) = sin_cos(std::f64::consts::FRAC_PI_6);
        assert!((s - 0.5).abs() <= f64::EPSILON / 2.0 && (c - 0.75f64.sqrt()).abs() <= 1e-16);
        for x in [0.3, 1.7, 2.9, 4.4, 1e3, 12345.678] {
            let (s, c) = sin_cos(x);
            let (sm, cm) = sin_cos(-x);
            assert_eq!((sm, cm), (-s, c), "{x}");
            assert!((s * s + c * c - 1.0).abs() <= 4.0 * f64::EPSILON);
        }
        for x in [2e6, -3.3e10, 1e300, f64::INFINITY, f64::NAN] {
            let (s, c) = sin_cos(x);
            let (sr, cr) = x.sin_cos();
            assert!(s.to_bits() == sr.to_bits() || (s.is_nan() && sr.is_nan()));
            assert!(c.to_bits() == cr.to_bits() || (c.is_nan() && cr.is_nan()));
        }
    }

    #[test]
    fn lanes_give_the_bits_of_single_calls() {
        let x = [0.1, -2.5, 3e6, 1e-8, f64::NAN, 7.0, -1e5, 0.0];
        let (s, c) = sin_cos_lanes(&x);
        for l in 0..x.len() {
            let (s1, c1) = sin_cos(x[l]);
            assert!(s[l].to_bits() == s1.to_bits() || (s[l].is_nan() && s1.is_nan()));
            assert!(c[l].to_bits() == c1.to_bits() || (c[l].is_nan() && c1.is_nan()));
        }
    }
}
