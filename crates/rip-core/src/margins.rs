//! Robustness margins of a controller's linearised loop, broken at the plant input.
//!
//! The loop is the controller (any [`Controller`]: LQR, LQG, MPC, without the compensation,
//! whose dead-zone inverse cancels the rig's dead zone) around the discrete design model
//! `x[k+1] = A_d x + B_d u_a`, `y = C x`. Breaking it at the plant input, the plant receives
//! `u_a = u_c + d` while the controller believes it applied its own `u_c`, so that
//!
//! ```text
//! u_c(z) = −L(z) u_a(z),      L(z) = −K(z) P(z),   P(z) = C (zI − A_d)⁻¹ B_d
//! ```
//!
//! with `K(z)` the controller from `y` to `u_c` (negative feedback: `L = K_lqr (zI − A)⁻¹ B`
//! for a state feedback `u = −K_lqr x`). The response is measured without looking inside the
//! controller: a small impulse `d` (1 mV, so no bound of the controller is reached and it acts
//! linearly) enters the closed loop at rest, and `L(e^{jω}) = −U_c(ω) / U_a(ω)` from the
//! transforms `U(ω) = Σ_k u[k] e^{−jωk}` of the two recorded responses, which decay when the
//! loop is stable.
//!
//! From `L` on `0 < ω < π` (rad/sample):
//!
//! - **gain margins**, at the phase crossovers (`L` real and negative): `1/|L|`. Crossovers
//!   with `|L| < 1` bound how much the loop gain may grow (`gain_margin_db > 0`); with the
//!   unstable pendulum, crossovers with `|L| > 1` bound how much it may shrink
//!   (`gain_reduction_db < 0`).
//! - **phase margin**, at the gain crossovers (`|L| = 1`): the angle `|180° + ∠L|` (wrapped
//!   into `[0°, 180°]`) between `L` and `−1`, the smallest.
//! - **disk margin** as MATLAB's `diskmargin` (balanced, skew σ = 0) at the plant input:
//!
//!   ```text
//!   α = 1 / max_ω |S(e^{jω}) − 1/2|,     S = 1 / (1 + L)
//!   ```
//!
//!   the loop stays stable for every gain `f` in the disk `(1 + α/2·δ)/(1 − α/2·δ)`, `|δ| < 1`,
//!   i.e. simultaneous gain variations in `[(2 − α)/(2 + α), (2 + α)/(2 − α)]`
//!   (`disk_gain_margin_db`) or phase variations of `±2 atan(α/2)` (`disk_phase_margin_deg`).
//!
//! For the MPC this is the loop of its **unconstrained** law: with a 1 mV impulse no input or
//! output bound is active, the QP's solution is `Δu = −(H⁻¹ f)₀` with `f` linear in the
//! estimate `x̂[k|k]` and the previous move `u[k−1]`, and the MPC acts as the linear controller
//! `u = u[k−1] + k_x x̂[k|k] + k_u u[k−1]` on its Kalman filter, with `u[k−1]` (what it
//! believes it applied) one of its states. `tests/test_tune.py` rebuilds that controller from
//! the condensed QP's data and checks these margins against python-control's `disk_margins`.
//!
//! A loop whose impulse response grows, or has not fallen below 1e-4 of its peak after 65 536
//! samples, is unstable; its margins are all zero.

use nalgebra::Complex;
use nalgebra::DVector;

use crate::controller::Controller;
use crate::error::{Result, RipError};
use crate::linalg::Mat;

/// Amplitude (V) of the impulse the response is measured with.
const IMPULSE: f64 = 1e-3;
/// Samples the response may take to decay.
const MAX_SAMPLES: usize = 1 << 16;
/// Frequencies of the sweep (log-spaced on `(0, π)` rad/sample).
const GRID: usize = 800;

/// The robustness margins of a loop (module docs). Frequencies are in rad/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Margins {
    /// Whether the closed loop is stable (its impulse response decays).
    pub stable: bool,
    /// The smallest factor (dB, > 0) by which the loop gain may grow; `inf` when it may grow
    /// without bound.
    pub gain_margin_db: f64,
    /// The largest factor (dB, < 0) by which the loop gain may shrink; `-inf` when it may
    /// shrink to zero (a stable plant).
    pub gain_reduction_db: f64,
    /// The smallest phase margin (degrees) over the gain crossovers; `inf` without one.
    pub phase_margin_deg: f64,
    /// The frequency of that gain crossover (rad/s), `NaN` without one.
    pub crossover_rad_s: f64,
    /// The balanced disk margin `α` (MATLAB's `DiskMargin`).
    pub disk_margin: f64,
    /// The disk's gain margin (dB): `20 log10((2 + α)/(2 − α))`, `inf` for `α ≥ 2`.
    pub disk_gain_margin_db: f64,
    /// The disk's phase margin (degrees): `2 atan(α/2)`.
    pub disk_phase_margin_deg: f64,
}

impl Margins {
    /// All zero: an unstable loop (or one not measured).
    pub(crate) fn unstable() -> Self {
        Self {
            stable: false,
            gain_margin_db: 0.0,
            gain_reduction_db: 0.0,
            phase_margin_deg: 0.0,
            crossover_rad_s: f64::NAN,
            disk_margin: 0.0,
            disk_gain_margin_db: 0.0,
            disk_phase_margin_deg: 0.0,
        }
    }

    /// Whether the loop meets the classical requirement: stable, at least `gain_db` of gain
    /// margin both ways and `phase_deg` of phase margin (the tuning asks 6 dB and 30°).
    pub fn meets(&self, gain_db: f64, phase_deg: f64) -> bool {
        self.stable
            && self.gain_margin_db >= gain_db
            && self.gain_reduction_db <= -gain_db
            && self.phase_margin_deg >= phase_deg
    }
}

/// The loop's impulse responses `(u_a, u_c)` (module docs); `None` when they do not decay.
fn impulse_responses(
    controller: &mut dyn Controller,
    a: &Mat,
    b: &Mat,
    c: &Mat,
) -> Result<Option<(Vec<f64>, Vec<f64>)>> {
    let n = a.nrows();
    if a.ncols() != n || b.shape() != (n, 1) || c.shape() != (2, n) {
        return Err(RipError::invalid(
            "model",
            format!(
                "need A n×n, B n×1, C 2×n, got {:?}, {:?}, {:?}",
                a.shape(),
                b.shape(),
                c.shape()
            ),
        ));
    }
    controller.reset();
    let r = [0.0, 0.0];
    let mut u = [0.0];
    // Rest samples first, so that rate filters and estimators have started.
    for _ in 0..3 {
        controller.step(&[0.0, 0.0], &r, &mut u);
    }
    let mut x = DVector::<f64>::zeros(n);
    let (mut ua, mut uc) = (Vec::new(), Vec::new());
    let mut peak = 0.0f64;
    let mut quiet = 0usize;
    let mut last = f64::INFINITY;
    for k in 0..MAX_SAMPLES {
        let y = c * &x;
        controller.step(&[y[0], y[1]], &r, &mut u);
        let d = if k == 0 { IMPULSE } else { 0.0 };
        let applied = u[0] + d;
        ua.push(applied);
        uc.push(u[0]);
        x = a * &x + b * applied;
        let size = x.amax().max(applied.abs());
        if !size.is_finite() || size > 1e6 * IMPULSE {
            return Ok(None);
        }
        peak = peak.max(size);
        quiet = if size < 1e-13 * peak { quiet + 1 } else { 0 };
        if quiet > 50 {
            return Ok(Some((ua, uc)));
        }
        last = size;
    }
    // Not decayed to rounding within MAX_SAMPLES: a slow but decaying loop (a slow
    // disturbance estimator) is measured on what was recorded, whose missing tail only
    // affects frequencies far below the crossovers; one that has not decayed is unstable.
    Ok((last < 1e-4 * peak).then_some((ua, uc)))
}

/// Frequencies evaluated in one pass over the responses. Horner's recursion is a chain of
/// dependent multiplications, so one frequency at a time waits on each; this many independent
/// chains side by side keep the vector units busy instead.
const LANES: usize = 8;

/// `L(e^{jω})` (module docs) at each `ω` of `w` (rad/sample), [`LANES`] at a time:
/// `U(ω) = Σ_k u[k] z^{−k}` by Horner in `z^{−1} = e^{−jω}` for both responses at once,
/// `L = −U_c / U_a`.
fn loop_at(ua: &[f64], uc: &[f64], w: &[f64]) -> Vec<Complex<f64>> {
    use rayon::prelude::*;
    if w.len() <= LANES {
        return loop_at_lanes(ua, uc, w);
    }
    w.par_chunks(LANES)
        .flat_map_iter(|chunk| loop_at_lanes(ua, uc, chunk))
        .collect()
}

/// [`loop_at`] at up to [`LANES`] frequencies, in one pass.
fn loop_at_lanes(ua: &[f64], uc: &[f64], w: &[f64]) -> Vec<Complex<f64>> {
    debug_assert!(w.len() <= LANES);
    let (mut zr, mut zi) = ([0.0; LANES], [0.0; LANES]);
    for (j, &wj) in w.iter().enumerate() {
        let z = Complex::from_polar(1.0, -wj);
        (zr[j], zi[j]) = (z.re, z.im);
    }
    let (mut ar, mut ai) = ([0.0; LANES], [0.0; LANES]);
    let (mut cr, mut ci) = ([0.0; LANES], [0.0; LANES]);
    for (&va, &vc) in ua.iter().rev().zip(uc.iter().rev()) {
        for j in 0..LANES {
            // `acc · z⁻¹ + v`, written out as the complex product is.
            let (r, i) = (
                ar[j] * zr[j] - ai[j] * zi[j] + va,
                ar[j] * zi[j] + ai[j] * zr[j],
            );
            (ar[j], ai[j]) = (r, i);
            let (r, i) = (
                cr[j] * zr[j] - ci[j] * zi[j] + vc,
                cr[j] * zi[j] + ci[j] * zr[j],
            );
            (cr[j], ci[j]) = (r, i);
        }
    }
    (0..w.len())
        .map(|j| -Complex::new(cr[j], ci[j]) / Complex::new(ar[j], ai[j]))
        .collect()
}

/// Refines a sign change of `f(L(ω))` on `[lo, hi]`, where `f(L(lo)) > 0` is `positive`:
/// [`LANES`] − 1 inner points per pass narrow the bracket [`LANES`]-fold, until it is within
/// rounding of `ω`.
fn bisect(
    l: &(dyn Fn(&[f64]) -> Vec<Complex<f64>> + Sync),
    f: fn(Complex<f64>) -> f64,
    positive: bool,
    mut lo: f64,
    mut hi: f64,
) -> f64 {
    while hi - lo > 4.0 * f64::EPSILON * hi {
        let step = (hi - lo) / LANES as f64;
        let inner: Vec<f64> = (1..LANES).map(|i| lo + step * i as f64).collect();
        let values = l(&inner);
        // The first inner point past the sign change closes the bracket; none: it is in the last.
        let (mut new_lo, mut new_hi) = (inner[LANES - 2], hi);
        for (i, v) in values.iter().enumerate() {
            if (f(*v) > 0.0) != positive {
                new_hi = inner[i];
                new_lo = if i == 0 { lo } else { inner[i - 1] };
                break;
            }
        }
        if new_hi - new_lo >= hi - lo {
            break;
        }
        (lo, hi) = (new_lo, new_hi);
    }
    0.5 * (lo + hi)
}

/// The frequency response `L(e^{jωTs})` of `controller`'s loop at the plant input (module
/// docs) at the frequencies `w` (rad/s); `None` when the closed loop is unstable.
pub fn loop_response(
    controller: &mut dyn Controller,
    a: &Mat,
    b: &Mat,
    c: &Mat,
    ts: f64,
    w: &[f64],
) -> Result<Option<Vec<Complex<f64>>>> {
    Ok(impulse_responses(controller, a, b, c)?.map(|(ua, uc)| {
        let w: Vec<f64> = w.iter().map(|wi| wi * ts).collect();
        loop_at(&ua, &uc, &w)
    }))
}

/// `max_ω |S − 1/2|`, `S = 1/(1 + L)`, of the disk margin: the grid's largest, refined
/// between its neighbours by [`LANES`] points per pass, each pass keeping the two intervals
/// around the largest (the peak is taken as unimodal there, as a golden section would).
fn sensitivity_peak(
    l: &(dyn Fn(&[f64]) -> Vec<Complex<f64>> + Sync),
    grid: &[f64],
    values: &[Complex<f64>],
) -> f64 {
    let dist = |v: Complex<f64>| (Complex::new(1.0, 0.0) / (v + 1.0) - 0.5).norm();
    let (i_peak, mut peak) =
        values
            .iter()
            .map(|&v| dist(v))
            .enumerate()
            .fold((0, f64::NEG_INFINITY), |best, (i, v)| {
                if v > best.1 {
                    (i, v)
                } else {
                    best
                }
            });
    let (mut lo, mut hi) = (
        grid[i_peak.saturating_sub(1)],
        grid[(i_peak + 1).min(grid.len() - 1)],
    );
    while hi - lo > 1e-12 * hi {
        let step = (hi - lo) / (LANES + 1) as f64;
        let points: Vec<f64> = (1..=LANES).map(|i| lo + step * i as f64).collect();
        let (best, value) = l(&points).into_iter().map(dist).enumerate().fold(
            (0, f64::NEG_INFINITY),
            |b, (i, v)| if v > b.1 { (i, v) } else { b },
        );
        peak = peak.max(value);
        (lo, hi) = (points[best] - step, points[best] + step);
    }
    peak
}

/// The margins of `controller`'s loop at the plant input with the discrete model
/// `(a, b, c)` at sample time `ts` (module docs).
pub fn margins(
    controller: &mut dyn Controller,
    a: &Mat,
    b: &Mat,
    c: &Mat,
    ts: f64,
) -> Result<Margins> {
    let Some((ua, uc)) = impulse_responses(controller, a, b, c)? else {
        return Ok(Margins::unstable());
    };
    let l = |w: &[f64]| loop_at(&ua, &uc, w);
    let (w_lo, w_hi) = (1e-4f64, std::f64::consts::PI * (1.0 - 1e-9));
    let grid: Vec<f64> = (0..GRID)
        .map(|i| w_lo * (w_hi / w_lo).powf(i as f64 / (GRID - 1) as f64))
        .collect();
    let values = l(&grid);

    // The grid's sign changes, refined side by side, each independent of the others.
    let phase_crossings: Vec<usize> = (1..GRID)
        .filter(|&i| (values[i - 1].im > 0.0) != (values[i].im > 0.0))
        .collect();
    let gain_crossings: Vec<usize> = (1..GRID)
        .filter(|&i| (values[i - 1].norm() > 1.0) != (values[i].norm() > 1.0))
        .collect();
    let refine = |crossings: &[usize], f: fn(Complex<f64>) -> f64| -> Vec<(f64, Complex<f64>)> {
        use rayon::prelude::*;
        crossings
            .par_iter()
            .map(|&i| {
                // The grid's value at the bracket's low end gives its sign.
                let positive = f(values[i - 1]) > 0.0;
                let w = bisect(&l, f, positive, grid[i - 1], grid[i]);
                (w, l(&[w])[0])
            })
            .collect()
    };
    let ((phase, gain), peak) = rayon::join(
        || {
            rayon::join(
                || refine(&phase_crossings, |v| v.im),
                || refine(&gain_crossings, |v| v.norm() - 1.0),
            )
        },
        || sensitivity_peak(&l, &grid, &values),
    );
    let mut gm = f64::INFINITY;
    let mut gr = f64::NEG_INFINITY;
    // At a phase crossover L is real; where it is negative, 1/|L| is a gain margin.
    for (_, lw) in phase.into_iter().filter(|(_, lw)| lw.re < 0.0) {
        let g = -20.0 * lw.norm().log10();
        if g > 0.0 {
            gm = gm.min(g);
        } else {
            gr = gr.max(g);
        }
    }
    let mut pm = f64::INFINITY;
    let mut wc = f64::NAN;
    for (w, lw) in gain {
        // The angle between L and −1: |180° + ∠L| wrapped into [0°, 180°].
        let mut m = 180.0 + lw.arg().to_degrees();
        if m > 180.0 {
            m -= 360.0;
        }
        let m = m.abs();
        if m < pm {
            pm = m;
            wc = w / ts;
        }
    }
    let alpha: f64 = 1.0 / peak;
    let disk_gain_margin_db = if alpha >= 2.0 {
        f64::INFINITY
    } else {
        20.0 * ((2.0 + alpha) / (2.0 - alpha)).log10()
    };
    Ok(Margins {
        stable: true,
        gain_margin_db: gm,
        gain_reduction_db: gr,
        phase_margin_deg: pm,
        crossover_rad_s: wc,
        disk_margin: alpha,
        disk_gain_margin_db,
        disk_phase_margin_deg: (2.0 * (alpha / 2.0).atan()).to_degrees(),
    })
}

impl crate::spec::Design {
    /// The margins of the balance controller `kind` of this design (without its
    /// compensation) on the design model (module docs of [`crate::margins`]).
    pub fn margins(
        &self,
        kind: crate::spec::ControllerKind,
    ) -> std::result::Result<Margins, crate::spec::SpecError> {
        let mut controller = self.balance(kind)?;
        margins(controller.as_mut(), &self.a, &self.b, &self.c, self.ts())
            .map_err(|e| crate::spec::SpecError::new("plant", e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use crate::spec::{ControllerKind, Spec};

    #[test]
    fn a_state_feedback_loop_has_the_lqr_guarantees() {
        // LQR with the plain difference of exact angles is close to state feedback, whose
        // loop at the input keeps |1 + L| ≥ 1 in continuous time: phase margin ≥ 60° and
        // gain reduction to 1/2. The discrete loop loses a little of both.
        let design = Spec::default().design(crate::paper::TS).unwrap();
        let m = design.margins(ControllerKind::Lqr).unwrap();
        assert!(m.stable);
        assert!(m.phase_margin_deg > 30.0, "{m:?}");
        assert!(m.gain_reduction_db < -3.0, "{m:?}");
        for kind in ControllerKind::ALL {
            let m = design.margins(kind).unwrap();
            println!("{kind:?}: {m:?}");
            assert!(m.stable && m.disk_margin > 0.0, "{kind:?}: {m:?}");
        }
    }
}
