//! Statistics of Monte Carlo results: how far a success rate measured over `n` runs can be
//! trusted, and how many successes a controller of a given success probability reaches.
//!
//! # The Wilson score interval
//!
//! Of `k` successes in `n` independent runs, `p̂ = k / n`, the interval of success
//! probabilities `p` that a two-sided score test at the normal quantile `z` does not reject
//! (Wilson, "Probable inference, the law of succession, and statistical inference", JASA 22,
//! 1927; recommended over the normal ("Wald") interval by Brown, Cai & DasGupta, Statistical
//! Science 16, 2001, because it keeps its coverage near 0 and 1, where a swing-up's success
//! rate lives) is
//!
//! ```text
//! c = (p̂ + z²/(2n)) / (1 + z²/n),   h = z / (1 + z²/n) · √(p̂ (1 − p̂)/n + z²/(4n²)),
//! [c − h, c + h]
//! ```
//!
//! (scipy's `binomtest(k, n).proportion_ci(method="wilson")`). With `z = 1.96` it is the 95 %
//! interval: a bar "the lower end of the Wilson interval ≥ 97 %" holds when the runs show,
//! at 95 % confidence, a success probability of at least 97 %.
//!
//! # A regression guard
//!
//! A test over few runs cannot show a high success probability, but it can guard one: a
//! controller that succeeds with probability `p` in each of `n` runs reaches at least
//!
//! ```text
//! k_min = max { k : P(X ≥ k) ≥ c },   X ~ Binomial(n, p)
//! ```
//!
//! successes with probability at least `c` ([`guaranteed_successes`]), so a test that asks
//! for `k_min` of `n` fails such a controller at most `1 − c` of the time, while a controller
//! much worse than `p` fails it almost always. (A 99 % controller passes 198 of 200 only 68 %
//! of the time: a bar of 198 cannot be a test.)

use crate::error::{Result, RipError};

/// The normal quantile of a two-sided 95 % interval, `Φ⁻¹(0.975)`.
pub const Z_95: f64 = 1.959_963_984_540_054;

/// The Wilson score interval (module docs) of `successes` in `runs` at the normal quantile `z`
/// ([`Z_95`] for 95 %): `(low, high)`, within [0, 1].
///
/// # Errors
/// No runs, more successes than runs, or a `z` that is not finite and positive.
pub fn wilson(successes: u64, runs: u64, z: f64) -> Result<(f64, f64)> {
    if runs == 0 {
        return Err(RipError::invalid("runs", "must be at least 1"));
    }
    if successes > runs {
        return Err(RipError::invalid(
            "successes",
            format!("{successes} is more than the {runs} runs"),
        ));
    }
    if !(z.is_finite() && z > 0.0) {
        return Err(RipError::invalid(
            "z",
            format!("must be finite and positive, got {z}"),
        ));
    }
    let n = runs as f64;
    let p = successes as f64 / n;
    let z2 = z * z;
    let scale = 1.0 + z2 / n;
    let centre = (p + z2 / (2.0 * n)) / scale;
    let half = z / scale * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    // At k = 0 or k = n the formula's end is 0 or 1 up to rounding.
    let low = if successes == 0 { 0.0 } else { centre - half };
    let high = if successes == runs {
        1.0
    } else {
        centre + half
    };
    Ok((low.clamp(0.0, 1.0), high.clamp(0.0, 1.0)))
}

/// The most successes of `runs` that a controller succeeding with probability `p` in each
/// run reaches with probability at least `confidence` (module docs, "A regression guard"):
/// the largest `k` with `P(Binomial(runs, p) ≥ k) ≥ confidence`.
///
/// # Errors
/// A `p` outside [0, 1] or a `confidence` outside (0, 1).
pub fn guaranteed_successes(runs: u64, p: f64, confidence: f64) -> Result<u64> {
    if !(0.0..=1.0).contains(&p) {
        return Err(RipError::invalid(
            "p",
            format!("must be in [0, 1], got {p}"),
        ));
    }
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(RipError::invalid(
            "confidence",
            format!("must be in (0, 1), got {confidence}"),
        ));
    }
    if p == 1.0 {
        return Ok(runs);
    }
    if p == 0.0 {
        return Ok(0);
    }
    // The upper tail P(X ≥ k) summed from k = n down, in logarithms: p^n underflows for
    // large n. ln pmf(k − 1) = ln pmf(k) + ln(k / (n − k + 1)) + ln((1 − p) / p).
    let n = runs as f64;
    let odds = (1.0 - p).ln() - p.ln();
    let target = confidence.ln();
    let mut log_pmf = n * p.ln();
    let mut log_tail = log_pmf;
    let mut k = runs;
    while log_tail < target && k > 0 {
        let kf = k as f64;
        log_pmf += (kf / (n - kf + 1.0)).ln() + odds;
        k -= 1;
        log_tail = log_add(log_tail, log_pmf);
    }
    Ok(k)
}

/// `ln(eᵃ + eᵇ)` without overflow.
fn log_add(a: f64, b: f64) -> f64 {
    let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
    hi + (lo - hi).exp().ln_1p()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// scipy 1.17 `binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")`,
    /// computed outside this crate.
    #[test]
    fn the_wilson_interval_is_scipys() {
        let cases = [
            (909, 1000, 0.889_574_415_930_459_9, 0.925_295_295_628_355_8),
            (198, 200, 0.964_278_238_283_823_2, 0.997_253_341_866_455_6),
            (0, 10, 0.0, 0.277_532_799_862_889_26),
            (10, 10, 0.722_467_200_137_110_9, 1.0),
        ];
        for (k, n, lo, hi) in cases {
            let (l, h) = wilson(k, n, Z_95).unwrap();
            assert!(
                (l - lo).abs() < 1e-12 && (h - hi).abs() < 1e-12,
                "{k}/{n}: {l} {h}"
            );
        }
    }

    #[test]
    fn the_interval_holds_its_estimate_and_mirrors_failures() {
        for n in [1u64, 7, 200, 1000] {
            for k in 0..=n {
                let (l, h) = wilson(k, n, Z_95).unwrap();
                let p = k as f64 / n as f64;
                assert!(l <= p && p <= h, "{k}/{n}");
                let (l2, h2) = wilson(n - k, n, Z_95).unwrap();
                assert!((l - (1.0 - h2)).abs() < 1e-12 && (h - (1.0 - l2)).abs() < 1e-12);
            }
        }
        // More runs at the same rate: a narrower interval.
        let (l1, h1) = wilson(90, 100, Z_95).unwrap();
        let (l2, h2) = wilson(900, 1000, Z_95).unwrap();
        assert!(l2 > l1 && h2 < h1);
    }

    /// scipy's `binom.sf(k − 1, n, 0.985)`: the largest `k` at which it is still ≥ 0.999.
    #[test]
    fn the_guard_is_the_binomial_quantile() {
        for (n, k) in [(20, 17), (100, 94), (200, 191), (1000, 972)] {
            assert_eq!(
                guaranteed_successes(n, 0.985, 0.999).unwrap(),
                k,
                "{n} runs"
            );
        }
        assert_eq!(guaranteed_successes(50, 1.0, 0.999).unwrap(), 50);
        assert_eq!(guaranteed_successes(50, 0.0, 0.999).unwrap(), 0);
        // A million runs: no underflow of p^n (scipy: 984 623).
        assert_eq!(
            guaranteed_successes(1_000_000, 0.985, 0.999).unwrap(),
            984_623
        );
    }

    #[test]
    fn bad_arguments_name_themselves() {
        let msg = |e: RipError| e.to_string();
        assert!(msg(wilson(1, 0, Z_95).unwrap_err()).contains("runs"));
        assert!(msg(wilson(3, 2, Z_95).unwrap_err()).contains("successes"));
        assert!(msg(wilson(1, 2, f64::NAN).unwrap_err()).contains('z'));
        assert!(msg(guaranteed_successes(10, 1.5, 0.9).unwrap_err()).contains('p'));
        assert!(msg(guaranteed_successes(10, 0.5, 1.0).unwrap_err()).contains("confidence"));
    }
}
