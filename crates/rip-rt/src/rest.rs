//! The rest check and the hanging-down calibration: before a run that starts with the
//! pendulum hanging (`rip-rt run --swing-up`, excitation runs), the loop samples the rig with
//! the motor disabled (0 V, driver off, every period) until both joints have been still for
//! `calibration.rest_window_s`, and then takes its encoder zeros from that window:
//!
//! - the **pendulum**: hanging at rest it is exactly π from upright, so its mean count over the
//!   window becomes the count of α = π (the configured `device.pendulum_zero` is only used to
//!   check that the rest pose is near hanging, within `calibration.max_pendulum_offset`: a
//!   pendulum held still at another angle, or a wrong `device.pendulum_zero`, is refused; a
//!   flipped `device.pendulum_sign` reads the same at ±π and is not detected here, but by the
//!   sign check, [`crate::sign_check`]). The tolerance is a few degrees, not more: whatever
//!   offset is accepted shifts the upright by as much, and Coulomb friction in the pendulum's
//!   bearing lets a free pendulum come to rest within about a degree of hanging;
//! - the **arm**: its mean count over the window becomes θ = 0, so `safety.arm_limit` and
//!   `swing_up.arm_limit` count from where the arm was at start.
//!
//! # When the rig counts as at rest
//!
//! Over the last `rest_window_s` of measurements (the last `round(rest_window_s / Ts)` that
//! arrived, rounded to whole spans), split from the newest into spans of `n` samples,
//! [`RATE_SPAN_S`] (0.1 s), with
//! the means `c̄ᵢ` and mean times `t̄ᵢ` of their counts, for each joint:
//!
//! ```text
//! max c̄ − min c̄ ≤ rest_counts
//! |c̄ᵢ − c̄ᵢ₊₁| · 2π / (N_rev (t̄ᵢ − t̄ᵢ₊₁)) ≤ rest_<joint>_rate   for neighbouring spans
//! ```
//!
//! The first criterion catches a small swing or a creeping arm, the second a motion that the
//! spread of the window would only show later; a difference over a tenth of a second resolves
//! a rate of one count per 0.1 s (0.031 rad/s at 2048 counts per revolution), which a
//! difference over one period (one count per 10 ms: 0.31 rad/s) could not. Means over a
//! span, not single readings: an encoder whose reading jitters by a count or two (noise, a
//! flickering edge) has a single-reading spread over a 1 s window of about five times that
//! jitter's standard deviation, which a still rig would fail for good, while the span means
//! take it down by `√n` and keep a swing (a pendulum's period is ten spans or more) whole.
//! A window that fails is slid on by one sample; the check refuses ([`RestFault`]) when no
//! window has passed `rest_timeout_s` after it started. The rate thresholds must exceed two
//! counts per span, or quantisation alone could fail them.
//!
//! This module is the logic without I/O ([`RestCheck`]); [`crate::calibrate`] runs it on the
//! device with the loop's safety rules.

use crate::config::{Config, PendulumZero};

pub use rip_core::spec::rig_sections::{
    CalibrationConfig, MAX_PENDULUM_OFFSET, MAX_REST_RATE, MAX_REST_TIMEOUT_S, RATE_SPAN_S,
    REST_COUNTS, REST_WINDOW_S,
};

/// The encoder zeros taken from a window at rest, and what that window measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Mean arm count over the window: θ = 0 from now on.
    pub arm_zero_counts: f64,
    /// Mean pendulum count over the window: α = π (hanging) from now on.
    pub pendulum_hanging_counts: f64,
    /// How far (rad) the rest pose was from hanging as `[device]` reads it.
    pub pendulum_offset: f64,
    /// Spread (max − min, counts) of the arm and pendulum counts over the window.
    pub spread_counts: [f64; 2],
    /// Largest arm and pendulum rates (rad/s) over the window.
    pub max_rates: [f64; 2],
    /// Seconds from the start of the check to the end of the window.
    pub after_s: f64,
}

impl std::fmt::Display for Calibration {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "arm_zero_counts={:.2} pendulum_hanging_counts={:.2} pendulum_offset_rad={:.4} \
             spread_counts={:.1}/{:.1} max_rate_rad_s={:.3}/{:.3} after_s={:.2}",
            self.arm_zero_counts,
            self.pendulum_hanging_counts,
            self.pendulum_offset,
            self.spread_counts[0],
            self.spread_counts[1],
            self.max_rates[0],
            self.max_rates[1],
            self.after_s
        )
    }
}

/// Why the rig was not found at rest hanging down ([`StopReason::NotAtRest`](crate::stop::StopReason::NotAtRest)).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RestFault {
    /// A joint moved in every window up to the timeout; the figures are the last window's.
    #[error(
        "the {joint} is moving: over the last {window_s} s its 0.1 s means spanned {spread:.1} \
         counts (calibration.rest_counts = {max_spread}) at up to {rate:.3} rad/s \
         (calibration.rest_{joint}_rate = {max_rate}); still not at rest after {timeout_s} s \
         ({timeout_key})"
    )]
    Moving {
        /// `"arm"` or `"pendulum"`.
        joint: &'static str,
        /// The spread of its span means over the window (counts).
        spread: f64,
        /// `calibration.rest_counts`.
        max_spread: u32,
        /// Its largest rate over the window (rad/s).
        rate: f64,
        /// The rate threshold (rad/s).
        max_rate: f64,
        /// `calibration.rest_window_s`.
        window_s: f64,
        /// The timeout (s).
        timeout_s: f64,
        /// Its key: `calibration.rest_timeout_s`, or `calibration.settle_timeout_s` after the
        /// sign check's pulse.
        timeout_key: &'static str,
    },
    /// Too few measurements arrived to fill a window before the timeout.
    #[error(
        "only {got} of the {needed} measurements of a {window_s} s window arrived within \
         {timeout_s} s ({timeout_key})"
    )]
    NoWindow {
        /// Measurements received.
        got: usize,
        /// Measurements a window needs.
        needed: usize,
        /// `calibration.rest_window_s`.
        window_s: f64,
        /// The timeout (s).
        timeout_s: f64,
        /// Its key: `calibration.rest_timeout_s`, or `calibration.settle_timeout_s` after the
        /// sign check's pulse.
        timeout_key: &'static str,
    },
    /// The pendulum rests away from hanging: held, or `[device]` does not describe its encoder.
    #[error(
        "the pendulum rests {offset:.3} rad from hanging down as [device] reads it, more than \
         calibration.max_pendulum_offset ({max:.3} rad): is it held or leaning on its cable, or \
         is device.pendulum_zero right?"
    )]
    NotHanging {
        /// Distance from hanging (rad).
        offset: f64,
        /// `calibration.max_pendulum_offset`.
        max: f64,
    },
}

/// What [`RestCheck::push`] concluded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RestVerdict {
    /// No still window yet; keep sampling.
    Waiting,
    /// A still window, hanging: the calibration.
    AtRest(Calibration),
}

/// One sample of the window: time (s since the check started) and the two counts.
#[derive(Debug, Clone, Copy, Default)]
struct Sample {
    t: f64,
    counts: [i32; 2],
}

/// The rest check without I/O (module docs): fed one measurement per period, it finds the
/// first still window. Allocation-free after construction.
#[derive(Debug, Clone)]
pub struct RestCheck {
    pub(crate) cfg: CalibrationConfig,
    pub(crate) timeout_key: &'static str,
    rad_per_count: [f64; 2],
    // The α (rad, 0 upright) that `[device]` reads at zero counts, before calibration.
    configured_offset: f64,
    ring: Vec<Sample>,
    // Samples received (the newest is at (received − 1) % len).
    received: usize,
    span: usize,
    last_window: Option<Stats>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Stats {
    spread: [f64; 2],
    rate: [f64; 2],
    mean: [f64; 2],
}

impl RestCheck {
    /// The check for `cfg` (assumed valid) at the loop period `period_s`.
    pub fn new(cfg: &Config) -> Self {
        let c = &cfg.calibration;
        let period_s = cfg.period_s();
        let window = (c.rest_window_s / period_s).round().max(2.0) as usize;
        // At least two spans to a window, so that it has a rate.
        let span = ((RATE_SPAN_S / period_s).round() as usize).clamp(1, window / 2);
        // Whole spans, so that every sample of the calibration's mean is judged.
        let window = ((window as f64 / span as f64).round() as usize).max(2) * span;
        let tau = std::f64::consts::TAU;
        let d = &cfg.device;
        Self {
            cfg: c.clone(),
            timeout_key: "calibration.rest_timeout_s",
            rad_per_count: [
                d.arm_sign * tau / f64::from(d.arm_counts_per_rev),
                d.pendulum_sign * tau / f64::from(d.pendulum_counts_per_rev),
            ],
            configured_offset: match d.pendulum_zero {
                PendulumZero::Down => std::f64::consts::PI,
                PendulumZero::Up => 0.0,
            },
            ring: vec![Sample::default(); window],
            received: 0,
            span,
            last_window: None,
        }
    }

    /// Measurements a window holds.
    pub fn window_len(&self) -> usize {
        self.ring.len()
    }

    fn at(&self, back: usize) -> &Sample {
        let n = self.ring.len();
        &self.ring[(self.received - 1 - back) % n]
    }

    fn window_stats(&self) -> Stats {
        let n = self.ring.len();
        let span = self.span;
        let mut sum = [0i64; 2];
        for back in 0..n {
            let s = self.at(back);
            for (j, total) in sum.iter_mut().enumerate() {
                *total += i64::from(s.counts[j]);
            }
        }
        // The means of consecutive spans, newest first (module docs): their spread and the
        // rates between neighbours.
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut rate = [0.0f64; 2];
        let mut newer: Option<([f64; 2], f64)> = None;
        for block in 0..n / span {
            let mut counts = [0.0f64; 2];
            let mut t = 0.0;
            for back in block * span..(block + 1) * span {
                let s = self.at(back);
                counts[0] += f64::from(s.counts[0]);
                counts[1] += f64::from(s.counts[1]);
                t += s.t;
            }
            let k = span as f64;
            let (counts, t) = ([counts[0] / k, counts[1] / k], t / k);
            for j in 0..2 {
                lo[j] = lo[j].min(counts[j]);
                hi[j] = hi[j].max(counts[j]);
            }
            if let Some((later, t_later)) = newer {
                let dt = t_later - t;
                if dt > 0.0 {
                    for (j, r) in rate.iter_mut().enumerate() {
                        *r = r.max(((later[j] - counts[j]) * self.rad_per_count[j] / dt).abs());
                    }
                }
            }
            newer = Some((counts, t));
        }
        Stats {
            spread: [hi[0] - lo[0], hi[1] - lo[1]],
            rate,
            mean: [sum[0] as f64 / n as f64, sum[1] as f64 / n as f64],
        }
    }

    fn still(&self, s: &Stats) -> bool {
        let max_spread = f64::from(self.cfg.rest_counts);
        s.spread[0] <= max_spread
            && s.spread[1] <= max_spread
            && s.rate[0] <= self.cfg.rest_arm_rate
            && s.rate[1] <= self.cfg.rest_pendulum_rate
    }

    /// Takes the counts measured `t` seconds after the check started; a still window ends the
    /// check, hanging ([`RestVerdict::AtRest`]) or not ([`RestFault::NotHanging`]).
    pub fn push(
        &mut self,
        t: f64,
        arm_counts: i32,
        pendulum_counts: i32,
    ) -> Result<RestVerdict, RestFault> {
        let n = self.ring.len();
        self.ring[self.received % n] = Sample {
            t,
            counts: [arm_counts, pendulum_counts],
        };
        self.received += 1;
        if self.received < n {
            return Ok(RestVerdict::Waiting);
        }
        let stats = self.window_stats();
        self.last_window = Some(stats);
        if !self.still(&stats) {
            return Ok(RestVerdict::Waiting);
        }
        let pi = std::f64::consts::PI;
        let alpha = wrap_angle(rip_control::stop::angle_of(
            stats.mean[1],
            self.rad_per_count[1],
            self.configured_offset,
        ));
        let offset = pi - alpha.abs();
        if offset > self.cfg.max_pendulum_offset {
            return Err(RestFault::NotHanging {
                offset,
                max: self.cfg.max_pendulum_offset,
            });
        }
        Ok(RestVerdict::AtRest(Calibration {
            arm_zero_counts: stats.mean[0],
            pendulum_hanging_counts: stats.mean[1],
            pendulum_offset: offset,
            spread_counts: stats.spread,
            max_rates: stats.rate,
            after_s: t,
        }))
    }

    /// The refusal at the timeout: the joint that failed the last window (the one furthest
    /// over its limits), or too few measurements for a window.
    pub fn timeout_fault(&self) -> RestFault {
        let c = &self.cfg;
        let Some(s) = self.last_window else {
            return RestFault::NoWindow {
                got: self.received,
                needed: self.ring.len(),
                window_s: c.rest_window_s,
                timeout_s: c.rest_timeout_s,
                timeout_key: self.timeout_key,
            };
        };
        let max_rate = [c.rest_arm_rate, c.rest_pendulum_rate];
        let excess =
            |j: usize| (s.spread[j] / f64::from(c.rest_counts)).max(s.rate[j] / max_rate[j]);
        let j = if excess(1) >= excess(0) { 1 } else { 0 };
        RestFault::Moving {
            joint: ["arm", "pendulum"][j],
            spread: s.spread[j],
            max_spread: c.rest_counts,
            rate: s.rate[j],
            max_rate: max_rate[j],
            window_s: c.rest_window_s,
            timeout_s: c.rest_timeout_s,
            timeout_key: self.timeout_key,
        }
    }
}

use rip_core::trig::wrap_angle;

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{PI, TAU};

    fn cfg() -> Config {
        Config::default()
    }

    /// Feeds `f(t) = (arm counts, pendulum counts)` every 10 ms for up to `secs`.
    fn feed(
        check: &mut RestCheck,
        secs: f64,
        mut f: impl FnMut(f64) -> (i32, i32),
    ) -> Result<RestVerdict, RestFault> {
        let n = (secs / 0.01).round() as usize;
        for k in 0..n {
            let t = k as f64 * 0.01;
            let (a, p) = f(t);
            match check.push(t, a, p)? {
                RestVerdict::Waiting => {}
                done => return Ok(done),
            }
        }
        Ok(RestVerdict::Waiting)
    }

    fn counts(rad: f64) -> f64 {
        rad * 2048.0 / TAU
    }

    #[test]
    fn a_still_rig_calibrates_to_the_window_means() {
        let mut check = RestCheck::new(&cfg());
        assert_eq!(check.window_len(), 100);
        // Arm parked 37 counts off the encoder's zero; the pendulum hangs 5 counts off the
        // configured zero and one count of dither alternates on both.
        let v = feed(&mut check, 3.0, |t| {
            let k = (t / 0.01).round() as i32;
            (37 + (k % 2), 5 + (k % 2))
        })
        .unwrap();
        let RestVerdict::AtRest(cal) = v else {
            panic!("{v:?}")
        };
        assert_eq!(cal.arm_zero_counts, 37.5);
        assert_eq!(cal.pendulum_hanging_counts, 5.5);
        assert!((cal.pendulum_offset - 5.5 * TAU / 2048.0).abs() < 1e-12);
        // The dither averages out in every 0.1 s span.
        assert_eq!(cal.spread_counts, [0.0, 0.0]);
        // The first full window: samples 0 to 99.
        assert!((cal.after_s - 0.99).abs() < 1e-9, "{}", cal.after_s);
        assert!(cal.max_rates[0] <= TAU / 2048.0 / 0.1 + 1e-12);
    }

    #[test]
    fn a_swinging_pendulum_is_refused_naming_it() {
        let c = cfg();
        let mut check = RestCheck::new(&c);
        // 0.05 rad of swing at the hanging pendulum's few rad/s: far more than 6 counts.
        let v = feed(&mut check, c.calibration.rest_timeout_s, |t| {
            (0, counts(0.05 * (6.0 * t).sin()).round() as i32)
        })
        .unwrap();
        assert_eq!(v, RestVerdict::Waiting);
        let fault = check.timeout_fault();
        let RestFault::Moving {
            joint,
            spread,
            rate,
            ..
        } = fault
        else {
            panic!("{fault:?}")
        };
        assert_eq!(joint, "pendulum");
        // 0.1 rad peak to peak is 32.6 counts, 0.985 of it in 0.1 s means; the rate up to
        // 0.3 rad/s.
        assert!((29.0..=33.0).contains(&spread), "{spread}");
        assert!(rate > 0.2 && rate < 0.31, "{rate}");
        assert!(
            fault.to_string().contains("calibration.rest_counts"),
            "{fault}"
        );
    }

    #[test]
    fn a_creeping_arm_fails_the_rate_before_the_spread() {
        let mut c = cfg();
        c.calibration.rest_counts = 64;
        c.calibration.rest_arm_rate = 0.1;
        let mut check = RestCheck::new(&c);
        // 0.15 rad/s of drift: 4.9 counts per 0.1 s, 48 counts over the window (inside 64).
        feed(&mut check, 3.0, |t| (counts(0.15 * t).round() as i32, 0)).unwrap();
        let RestFault::Moving {
            joint,
            spread,
            rate,
            ..
        } = check.timeout_fault()
        else {
            panic!()
        };
        assert_eq!(joint, "arm");
        assert!(spread <= 64.0);
        assert!((rate - 0.15).abs() < 0.04, "{rate}");
    }

    /// Gaussian jitter of `sigma` counts, the same sequence every run (an LCG and
    /// Box–Muller), for sample `k` of joint `j`.
    fn jitter(sigma: f64, k: usize, j: usize) -> f64 {
        let uniform = |i: u64| {
            let x = (i + 1)
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let i = 4 * k as u64 + 2 * j as u64;
        sigma * (-2.0 * uniform(i).ln()).sqrt() * (TAU * uniform(i + 1)).cos()
    }

    #[test]
    fn a_still_rig_whose_readings_jitter_rests_and_a_small_swing_through_it_does_not() {
        // 1.7 counts of jitter (a generated rig's arm: 1.8 mrad on 5 696 counts): a 1 s
        // window of single readings spans about 8 counts, the 0.1 s means about 1.6.
        let sigma = 1.7;
        let mut check = RestCheck::new(&cfg());
        let mut k = 0;
        let v = feed(&mut check, 3.0, |_| {
            k += 1;
            let n = |j| jitter(sigma, k, j).round() as i32;
            (40 + n(0), 7 + n(1))
        })
        .unwrap();
        let RestVerdict::AtRest(cal) = v else {
            panic!("{v:?}, {:?}", check.timeout_fault())
        };
        assert!((cal.arm_zero_counts - 40.0).abs() < 0.6, "{cal}");
        assert!(cal.spread_counts[0] <= 6.0, "{cal}");
        // A swing of ±5 counts (a tenth of a degree at 2048 counts) through the same jitter.
        let mut check = RestCheck::new(&cfg());
        let mut k = 0;
        let v = feed(&mut check, 3.0, |t| {
            k += 1;
            let swing = 5.0 * (6.0 * t).sin();
            (
                jitter(sigma, k, 0).round() as i32,
                (swing + jitter(sigma, k, 1)).round() as i32,
            )
        })
        .unwrap();
        assert_eq!(v, RestVerdict::Waiting);
        assert!(matches!(
            check.timeout_fault(),
            RestFault::Moving {
                joint: "pendulum",
                ..
            }
        ));
    }

    #[test]
    fn a_rig_that_comes_to_rest_is_calibrated_after_its_last_motion() {
        let mut check = RestCheck::new(&cfg());
        // Moving for 1.5 s, then still at pendulum count 3.
        let v = feed(&mut check, 3.0, |t| {
            if t < 1.5 {
                (0, counts(0.2 * (6.0 * t).sin()).round() as i32 + 3)
            } else {
                (0, 3)
            }
        })
        .unwrap();
        let RestVerdict::AtRest(cal) = v else {
            panic!("{v:?}")
        };
        // A window 1 s after the motion, less the share of one reading that a span's mean
        // dilutes below the spread's bound (one reading 30 counts off moves its mean by 3).
        assert!(cal.after_s >= 2.45 && cal.after_s < 2.6, "{}", cal.after_s);
        assert!((cal.pendulum_hanging_counts - 3.0).abs() < 0.5, "{cal}");
    }

    #[test]
    fn a_pendulum_resting_away_from_hanging_is_refused() {
        let mut check = RestCheck::new(&cfg());
        // Held still 0.6 rad from hanging (0.5 allowed).
        let e = feed(&mut check, 2.0, |_| (0, counts(0.6).round() as i32)).unwrap_err();
        let RestFault::NotHanging { offset, .. } = e else {
            panic!("{e:?}")
        };
        assert!((offset - 0.6).abs() < 0.01, "{offset}");
        // The same rest with the encoder's zero upright: far from hanging.
        let mut c = cfg();
        c.device.pendulum_zero = PendulumZero::Up;
        let mut check = RestCheck::new(&c);
        let e = feed(&mut check, 2.0, |_| (0, 0)).unwrap_err();
        assert!(matches!(e, RestFault::NotHanging { offset, .. } if (offset - PI).abs() < 1e-9));
        // ... and hanging is half a turn on.
        let mut check = RestCheck::new(&c);
        let v = feed(&mut check, 2.0, |_| (0, 1024)).unwrap();
        assert!(matches!(v, RestVerdict::AtRest(cal) if cal.pendulum_offset.abs() < 1e-12));
    }

    #[test]
    fn too_few_measurements_for_a_window_are_reported() {
        let mut check = RestCheck::new(&cfg());
        for k in 0..50 {
            assert_eq!(check.push(k as f64 * 0.01, 0, 0), Ok(RestVerdict::Waiting));
        }
        let e = check.timeout_fault();
        assert!(
            matches!(
                e,
                RestFault::NoWindow {
                    got: 50,
                    needed: 100,
                    ..
                }
            ),
            "{e:?}"
        );
    }

    #[test]
    fn bad_settings_are_named() {
        for (text, key) in [
            (
                "[calibration]\nrest_window_s = 0.05\n",
                "calibration.rest_window_s",
            ),
            (
                "[calibration]\nrest_window_s = nan\n",
                "calibration.rest_window_s",
            ),
            (
                "[calibration]\nrest_timeout_s = 0.5\n",
                "calibration.rest_timeout_s",
            ),
            (
                "[calibration]\nrest_timeout_s = 1e9\n",
                "calibration.rest_timeout_s",
            ),
            // Below two counts per 0.1 s at 2048 counts/rev (0.061 rad/s).
            (
                "[calibration]\nrest_arm_rate = 0.05\n",
                "calibration.rest_arm_rate",
            ),
            (
                "[calibration]\nrest_pendulum_rate = 2\n",
                "calibration.rest_pendulum_rate",
            ),
            (
                "[sensor]\nencoder_counts = [2048, 512]\n[calibration]\nrest_pendulum_rate = 0.2\n",
                "calibration.rest_pendulum_rate",
            ),
            (
                "[calibration]\nrest_counts = 0\n",
                "calibration.rest_counts",
            ),
            (
                "[calibration]\nmax_pendulum_offset = 0.3\n",
                "calibration.max_pendulum_offset",
            ),
            (
                "[calibration]\nrest_windw_s = 1\n",
                "calibration.rest_windw_s",
            ),
        ] {
            let e = Config::from_toml(text).unwrap_err();
            assert!(e.to_string().contains(key), "{text}: {e}");
        }
        let c =
            Config::from_toml("[calibration]\nrest_window_s = 0.5\nrest_timeout_s = 2\n").unwrap();
        assert_eq!(c.calibration.rest_window_s, 0.5);
        assert_eq!(
            c.calibration.rest_counts,
            CalibrationConfig::default().rest_counts
        );
    }
}
