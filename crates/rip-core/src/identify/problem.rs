//! The segments of the criterion, their simulation and the normal equations.

use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{DMatrix, DVector};

use super::{LogData, NP};
use crate::plant::{FurutaParams, Plant, State};

pub(super) struct Segment {
    pub(super) log: usize,
    pub(super) k0: usize,
    pub(super) n: usize,
    pub(super) x0: State,
    pub(super) r: Vec<f64>,
    pub(super) trial: Vec<f64>,
    /// Column-major `2n × (NP + 4)`.
    pub(super) jac: Vec<f64>,
}

pub(super) struct Problem<'a> {
    pub(super) logs: &'a [LogData],
    pub(super) w: [f64; 2],
    pub(super) substeps: usize,
    pub(super) sims: AtomicUsize,
}

impl Problem<'_> {
    pub(super) fn plant(&self, p: &FurutaParams) -> Option<(Plant, usize)> {
        let plant = Plant::new(*p).ok()?;
        let ts = self.logs[0].ts;
        let n = (ts / (0.9 * plant.max_rk4_substep())).ceil();
        (n.is_finite() && n <= 1e4).then(|| (plant, self.substeps.max(n as usize)))
    }

    /// Simulates samples `k0 .. k0 + n` of `log` from `x0`, writing the normalised residuals;
    /// false when the state left the finite numbers.
    pub(super) fn simulate(
        &self,
        (plant, sub): &(Plant, usize),
        log: usize,
        k0: usize,
        x0: &State,
        out: &mut [f64],
    ) -> bool {
        self.sims.fetch_add(1, Ordering::Relaxed);
        let data = &self.logs[log];
        let n = out.len() / 2;
        let mut x = *x0;
        for i in 0..n {
            let y = data.y[k0 + i];
            out[2 * i] = self.w[0] * (x[0] - y[0]);
            out[2 * i + 1] = self.w[1] * (x[2] - y[1]);
            if i + 1 < n {
                plant.advance(&mut x, data.u[k0 + i], 0.0, data.ts, *sub);
            }
        }
        out.iter().all(|v| v.is_finite())
    }
}

/// The state at sample `k` estimated from the measured angles (central-difference rates).
pub(super) fn state_at(log: &LogData, k: usize) -> State {
    let (a, b) = (k.saturating_sub(1), (k + 1).min(log.y.len() - 1));
    let dt = (b - a) as f64 * log.ts;
    let rate = |j: usize| (log.y[b][j] - log.y[a][j]) / dt;
    State::new(log.y[k][0], rate(0), log.y[k][1], rate(1))
}

/// MATLAB's fit `100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖)` of each output, from normalised residuals
/// `r = w (ŷ − y)` and the measurements.
pub(super) fn fit_percent(r: &[f64], y: &[[f64; 2]], w: [f64; 2]) -> [f64; 2] {
    std::array::from_fn(|j| {
        let n = y.len() as f64;
        let mean = y.iter().map(|v| v[j]).sum::<f64>() / n;
        let dev: f64 = y.iter().map(|v| (v[j] - mean).powi(2)).sum();
        let err: f64 = r
            .iter()
            .skip(j)
            .step_by(2)
            .map(|v| (v / w[j]).powi(2))
            .sum();
        100.0 * (1.0 - (err / dev).sqrt())
    })
}

/// Root-mean-square deviation from the mean of each output.
pub(super) fn rms_deviation(y: &[[f64; 2]]) -> [f64; 2] {
    let n = y.len().max(1) as f64;
    std::array::from_fn(|j| {
        let mean = y.iter().map(|v| v[j]).sum::<f64>() / n;
        (y.iter().map(|v| (v[j] - mean).powi(2)).sum::<f64>() / n).sqrt()
    })
}

/// `JᵀJ` and `Jᵀr` of all segments into `normal`, `grad` (global block first, then four
/// initial-state unknowns per segment).
pub(super) fn assemble(segments: &[Segment], normal: &mut DMatrix<f64>, grad: &mut DVector<f64>) {
    normal.fill(0.0);
    grad.fill(0.0);
    for (si, s) in segments.iter().enumerate() {
        let rows = 2 * s.n;
        let col = |c: usize| &s.jac[c * rows..(c + 1) * rows];
        let index = |c: usize| if c < NP { c } else { NP + 4 * si + (c - NP) };
        for a in 0..NP + 4 {
            let ca = col(a);
            grad[index(a)] += ca.iter().zip(&s.r).map(|(x, y)| x * y).sum::<f64>();
            for b in 0..=a {
                let v: f64 = ca.iter().zip(col(b)).map(|(x, y)| x * y).sum();
                let (ia, ib) = (index(a), index(b));
                normal[(ia, ib)] += v;
                if ia != ib {
                    normal[(ib, ia)] += v;
                }
            }
        }
    }
}

/// Residuals of samples `k0 .. k0 + n` of log `l` simulated in one piece from the initial state
/// that fits them best (a few Gauss–Newton steps on `x₀` from the measured one).
pub(super) fn fit_initial_state(
    problem: &Problem<'_>,
    plant: &(Plant, usize),
    l: usize,
    k0: usize,
    n: usize,
) -> Vec<f64> {
    let log = &problem.logs[l];
    let mut x0 = state_at(log, k0);
    let mut r = vec![0.0; 2 * n];
    let mut trial = vec![0.0; 2 * n];
    let mut jac = vec![0.0; 2 * n * 4];
    if !problem.simulate(plant, l, k0, &x0, &mut r) {
        return r;
    }
    let mut cost: f64 = r.iter().map(|v| v * v).sum();
    let mut lambda = 1e-3;
    for _ in 0..20 {
        for c in 0..4 {
            let hx = 1e-6 * (1.0 + x0[c].abs());
            let mut x = x0;
            x[c] += hx;
            problem.simulate(plant, l, k0, &x, &mut trial);
            for i in 0..2 * n {
                jac[c * 2 * n + i] = (trial[i] - r[i]) / hx;
            }
        }
        let jm = DMatrix::from_column_slice(2 * n, 4, &jac);
        let jtj = jm.transpose() * &jm;
        let g = jm.transpose() * DVector::from_column_slice(&r);
        let mut improved = false;
        for _ in 0..8 {
            let mut lhs = jtj.clone();
            for k in 0..4 {
                lhs[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let Some(step) = lhs.cholesky().map(|c| c.solve(&(-&g))) else {
                lambda *= 10.0;
                continue;
            };
            let x = x0 + State::from_column_slice(step.as_slice());
            if problem.simulate(plant, l, k0, &x, &mut trial) {
                let c: f64 = trial.iter().map(|v| v * v).sum();
                if c < cost {
                    let small = cost - c < 1e-10 * cost;
                    x0 = x;
                    cost = c;
                    std::mem::swap(&mut r, &mut trial);
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = !small;
                    break;
                }
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    r
}
