//! The planned swing-up: a trajectory from hanging to upright at rest on the nominal model,
//! found by iterative LQR, and the time-varying LQR that tracks it
//! ([`rip_control::swing::PlanPoint`], `swing_up.method = "trajectory"`).
//!
//! # The plan
//!
//! On the smooth nominal model (no dead zone, no Coulomb friction: the compensation clears
//! those around the whole supervisor, as it does for the energy law), discretised at the
//! balance period by RK4, `x_{k+1} = f(x_k, u_k)`, the plan minimises
//!
//! ```text
//! J = (x_N − x_up)ᵀ Q_f (x_N − x_up) + Σ_k [ ρ (u_k/U_p)² + w_θ max(0, |θ_k| − θ_s)² ]
//! ```
//!
//! from `x_0 = [0, 0, π, 0]` (hanging at rest) to `x_up = [0, 0, 2πm, 0]` (upright at rest, `m`
//! the turn the first guess arrives in), over `u_k = U_p tanh v_k`, so that `|u_k| < U_p` holds
//! by construction. `U_p = κ (U − V_d − C_r R_m/k_t)`: `U` is the swing-up's voltage bound
//! (`swing_up.max_voltage`, already within what the compensation leaves), `κ`
//! ([`PLAN_VOLTAGE_SHARE`]) the plan's share, and the tracking law keeps the rest and, again,
//! the size of the compensation itself (dead zone `V_d` and Coulomb friction voltage), whose
//! errors it has to absorb: on generated rigs with friction a plan at `κ U` caught on the first
//! arrival in 6 of 9 runs where this one catches in 9 (`examples/swingup_rigs.rs`, rigs 1, 3
//! and 14); `θ_s = max(θ_L − θ_r, θ_L/2)` with `θ_L` = `swing_up.arm_limit` and `θ_r`
//! [`ARM_ROOM`]; `Q_f = diag(100, 10, 1000, 10)`, `ρ = 0.05`, `w_θ = 1000`. iLQR (Li & Todorov
//! 2004) expands `f` to first and the cost to second order about the current trajectory
//! (Gauss–Newton in the input cost), solves the resulting time-varying LQ problem backwards
//! (a Levenberg–Marquardt term `μ` added to `Q_vv`, raised tenfold when a pass fails, lowered
//! threefold when one succeeds) and line-searches the new inputs forwards with the feedback of
//! the expansion (halving the step up to ten times; converged when an accepted step gains less
//! than `10⁻⁹ (1 + J)`). Its work is bounded whatever the rig and period: each horizon gets at
//! most `min(2000, 10⁶/N)` iterations, and no plan is longer than 10 s or
//! `swing_up.max_time` less the tail. The first guess is the energy law's own swing-up on the
//! nominal model: its first arrival within the catch angle sets the horizon `N`, and the
//! horizons of [`HORIZON_FACTORS`] are tried in turn (the plan's smaller voltage often needs a
//! longer one). Where the energy law never arrives, or no plan is found from it, the
//! **resonant** guesses follow, which need no swing to start from: the arm driven at the
//! pendulum's small-swing frequency `ω_p = √(G/J_α)`,
//!
//! ```text
//! u_k = a U_p sin(ω_p k T),    N = (h + ½) π / (ω_p T),    h = 2, 3, …, 10
//! ```
//!
//! (`a` [`RESONANT_SHARE`], `h` [`RESONANT_HALF_SWINGS`]: the horizon ends half a swing after
//! `h` half periods, on a rise), the goal the upright one turn on, `α = 2π`, the first found
//! kept. On generated rigs 0, 4, 8 and 13, where the energy law never arrives on the nominal
//! model within its arm limit, plans of 1.1–2.2 s are found from them (0.1–0.3 s to design),
//! the arm within 1.3 rad.
//!
//! A plan is **found** when its rollout ends within [`UPRIGHT_TOLERANCE`] of upright at rest
//! and never takes the arm beyond `θ_s + 0.02 rad`; otherwise there is none and the energy
//! law swings up alone.
//!
//! # Tracking
//!
//! Along the plan, the time-varying LQR of the linearisation `A_k = ∂f/∂x`, `b_k = ∂f/∂u`
//! (central differences of the RK4 step) with the tracking weights `Q = diag(25, w_v, 50, 0)`,
//! `R = 0.1` (the paper's LQR weights, eq. (13), with `w_v` [`TRACKING_ARM_RATE_WEIGHT`] on the
//! arm's rate, [`tracking_weights`]) and their upright LQR's DARE solution as its terminal
//! cost:
//!
//! ```text
//! P_N = P_∞,   K_k = (R + b_kᵀ P_{k+1} b_k)⁻¹ b_kᵀ P_{k+1} A_k,
//! P_k = Q + A_kᵀ P_{k+1} (A_k − b_k K_k),
//! ```
//!
//! so the tracking law `u = u_k − K_k (x − x_k)` (the pendulum's error wrapped) ends in that
//! upright LQR's gain. The paper's weights leave the arm's rate free, and under ±10 % model
//! error the arm then arrives turning at 5–10 rad/s where the plan's turns at 1–2.6: the
//! catch waits for the next arrival. With `w_v = 5` the tracked `qube_servo2` plan is caught
//! on its first arrival in 93.0 % of 1 000 perturbed runs (LQR, the tuned file, the plan
//! retimed as rip-control's supervisor does; 90.7 % with the paper's weights) and all 1 000
//! are held (998 before); `paper`'s stays within two passes over the top in 99.2 % (99.5 %).
//! Weights from 2 to 40 gave 92.1–94.1 % and 99.1–99.9 %. The plan is
//! extended by [`UPRIGHT_TAIL`] at rest at its own final angles (`u = 0`, the gain the upright
//! LQR's), so that a pendulum a little behind the plan is carried into
//! the catch region rather than left to the energy law. The stored `x_k` are not the planned
//! states themselves but what the supervisor's rate estimate (filtered backward differences
//! at `swing_up.rate_cutoff`) reads along them, so that the error carries no lag of the
//! estimate: at 20 Hz the estimate trails a rate by about 9 ms, several rad/s on the plan's
//! fastest moves. The supervisor follows the plan while the measured state stays near it
//! (rip-control's module docs, "Planned swing-up").

use nalgebra::{SMatrix, SVector};
use rip_control::swing::{PlanPoint, SwingParams};

use crate::linalg::c2d;
use crate::lqr::dlqr;
use crate::plant::{Plant, State};

use super::settings::SwingUpSettings;

/// `κ`: the share of the voltage left by the dead zone and the arm's Coulomb friction that
/// the plan may use; the rest is the tracking law's.
pub const PLAN_VOLTAGE_SHARE: f64 = 0.8;

/// Time (s) the plan holds upright after its end (its points at rest at the plan's final
/// angles, the tracking gain then the upright LQR's), so that a pendulum a little behind the plan is still
/// tracked to upright until the catch region takes it.
pub const UPRIGHT_TAIL: f64 = 0.3;

/// Room (rad) the plan keeps inside `swing_up.arm_limit`.
pub const ARM_ROOM: f64 = 0.2;

/// Largest distance of a found plan's final state from upright at rest, `(|θ|, |θ̇|, |α −
/// 2πm|, |α̇|)` (rad, rad/s, rad, rad/s).
pub const UPRIGHT_TOLERANCE: [f64; 4] = [0.1, 0.5, 0.05, 0.5];

/// iLQR iterations per horizon, at most.
const MAX_ITERATIONS: usize = 2000;

/// Iterations times horizon length per horizon, at most: bounds the design's work (each
/// iteration costs about 20 RK4 periods per point) whatever the rig and period.
const ITERATION_BUDGET: usize = 1_000_000;

/// Horizons tried, as multiples of the energy law's time to its first arrival.
pub const HORIZON_FACTORS: [f64; 4] = [1.0, 0.8, 1.3, 1.7];

/// The resonant first guesses' lengths, in half periods `h` of the pendulum's small swing
/// (module docs); each horizon is `h + ½` of them, a quarter period more, so that the guess
/// ends on a rise.
pub const RESONANT_HALF_SWINGS: std::ops::RangeInclusive<u32> = 2..=10;

/// The resonant first guesses' amplitude, a share of the plan's voltage bound.
pub const RESONANT_SHARE: f64 = 0.5;

/// Longest first guess and plan (s), before the upright tail; a plan is also no longer than
/// `swing_up.max_time` less the tail.
const MAX_PLAN_TIME: f64 = 10.0;

type M4 = SMatrix<f64, 4, 4>;
type V4 = SVector<f64, 4>;

/// The nominal model's period map, `f(x, u)`.
struct Model {
    plant: Plant,
    ts: f64,
    substeps: usize,
}

impl Model {
    fn new(plant: &Plant, ts: f64) -> Option<Self> {
        let smooth = plant.smooth().ok()?;
        let limit = 0.5 * smooth.max_rk4_substep();
        let substeps = ((ts / limit).ceil() as usize).clamp(2, 64);
        Some(Self {
            plant: smooth,
            ts,
            substeps,
        })
    }

    fn step(&self, x: &V4, u: f64) -> V4 {
        let mut next: State = *x;
        self.plant
            .advance(&mut next, u, 0.0, self.ts, self.substeps);
        next
    }

    /// `(∂f/∂x, ∂f/∂u)` at `(x, u)` by central differences.
    fn jacobians(&self, x: &V4, u: f64) -> (M4, V4) {
        let mut a = M4::zeros();
        for i in 0..4 {
            let h = 1e-6 * (1.0 + x[i].abs());
            let mut up = *x;
            let mut down = *x;
            up[i] += h;
            down[i] -= h;
            a.set_column(i, &((self.step(&up, u) - self.step(&down, u)) / (2.0 * h)));
        }
        let h = 1e-6 * (1.0 + u.abs());
        let b = (self.step(x, u + h) - self.step(x, u - h)) / (2.0 * h);
        (a, b)
    }
}

/// The cost of the module docs.
struct Cost {
    u_max: f64,
    terminal: V4,
    /// `x_up`: upright, the pendulum at the multiple of 2π the first guess arrives at.
    goal: V4,
    input: f64,
    arm_soft: f64,
    arm_weight: f64,
}

impl Cost {
    fn stage(&self, x: &V4, v: f64) -> f64 {
        let u = v.tanh();
        let over = (x[0].abs() - self.arm_soft).max(0.0);
        self.input * u * u + self.arm_weight * over * over
    }

    fn terminal(&self, x: &V4) -> f64 {
        (0..4)
            .map(|i| self.terminal[i] * (x[i] - self.goal[i]).powi(2))
            .sum()
    }
}

fn total(cost: &Cost, xs: &[V4], vs: &[f64]) -> f64 {
    let stages: f64 = xs.iter().zip(vs).map(|(x, &v)| cost.stage(x, v)).sum();
    stages + cost.terminal(&xs[xs.len() - 1])
}

/// The `n` periods from `x0` under the inputs `input(k, x_k)`: the states and the inputs, or
/// `None` when the state leaves the finite numbers.
fn rollout(
    model: &Model,
    cost: &Cost,
    x0: &V4,
    n: usize,
    mut input: impl FnMut(usize, &V4) -> f64,
) -> Option<(Vec<V4>, Vec<f64>)> {
    let mut xs = Vec::with_capacity(n + 1);
    let mut vs = Vec::with_capacity(n);
    let mut x = *x0;
    xs.push(x);
    for k in 0..n {
        let v = input(k, &x);
        vs.push(v);
        x = model.step(&x, cost.u_max * v.tanh());
        if !x.iter().all(|c| c.is_finite()) {
            return None;
        }
        xs.push(x);
    }
    Some((xs, vs))
}

/// iLQR from the inputs `vs` (module docs); the converged inputs and their rollout.
fn ilqr(
    model: &Model,
    cost: &Cost,
    x0: &V4,
    mut vs: Vec<f64>,
    iterations: usize,
) -> Option<(Vec<V4>, Vec<f64>)> {
    let n = vs.len();
    let (mut xs, _) = rollout(model, cost, x0, n, |k, _| vs[k])?;
    let mut j = total(cost, &xs, &vs);
    let mut mu = 1e-6;
    let mut ff = vec![0.0; n];
    let mut fb = vec![V4::zeros(); n];
    for _ in 0..iterations {
        // Backward pass.
        let mut vx = V4::from_fn(|i, _| 2.0 * cost.terminal[i] * (xs[n][i] - cost.goal[i]));
        let mut vxx = M4::from_diagonal(&(2.0 * cost.terminal));
        let mut ok = true;
        for k in (0..n).rev() {
            let th = vs[k].tanh();
            let du_dv = cost.u_max * (1.0 - th * th);
            let (a, b) = model.jacobians(&xs[k], cost.u_max * th);
            let fv = b * du_dv;
            // The input cost ρ tanh² v: its gradient and a Gauss–Newton curvature.
            let lv = cost.input * 2.0 * th * (1.0 - th * th);
            let lvv = cost.input * 2.0 * (1.0 - th * th).powi(2);
            let mut lx = V4::zeros();
            let mut lxx = M4::zeros();
            let over = xs[k][0].abs() - cost.arm_soft;
            if over > 0.0 {
                lx[0] = 2.0 * cost.arm_weight * over * xs[k][0].signum();
                lxx[(0, 0)] = 2.0 * cost.arm_weight;
            }
            let qx = lx + a.transpose() * vx;
            let qv = lv + fv.dot(&vx);
            let qxx = lxx + a.transpose() * vxx * a;
            let qvv = lvv + (fv.transpose() * vxx * fv)[0] + mu;
            let qvx = (fv.transpose() * vxx * a).transpose();
            if !(qvv > 0.0 && qvv.is_finite()) {
                ok = false;
                break;
            }
            ff[k] = -qv / qvv;
            fb[k] = -qvx / qvv;
            vx = qx + fb[k] * (qvv * ff[k] + qv) + qvx * ff[k];
            let sym = qxx
                + fb[k] * qvv * fb[k].transpose()
                + fb[k] * qvx.transpose()
                + qvx * fb[k].transpose();
            vxx = 0.5 * (sym + sym.transpose());
        }
        if !ok {
            mu = (mu * 10.0).max(1e-4);
            if mu > 1e8 {
                break;
            }
            continue;
        }
        // Forward line search.
        let mut accepted = false;
        let mut step = 1.0;
        for _ in 0..10 {
            let policy = |k: usize, x: &V4| {
                (vs[k] + step * ff[k] + fb[k].dot(&(x - xs[k]))).clamp(-6.0, 6.0)
            };
            if let Some((new_xs, new_vs)) = rollout(model, cost, x0, n, policy) {
                let new_j = total(cost, &new_xs, &new_vs);
                if new_j < j {
                    let gain = j - new_j;
                    xs = new_xs;
                    vs = new_vs;
                    j = new_j;
                    accepted = true;
                    // A tiny gain of an accepted step, full or halved, ends the search: the
                    // expansion no longer leads anywhere better (stopping only on full steps
                    // found worse plans on 3 of 10 generated rigs).
                    if gain < 1e-9 * (1.0 + j) {
                        return Some((xs, vs));
                    }
                    break;
                }
            }
            step *= 0.5;
        }
        if accepted {
            mu = (mu / 3.0).max(1e-9);
        } else {
            mu = (mu * 10.0).max(1e-4);
            if mu > 1e8 {
                break;
            }
        }
    }
    Some((xs, vs))
}

/// The energy law's swing-up on the nominal model from hanging at rest, on the true state:
/// its voltages until the first arrival within `catch_angle` of upright and the unwrapped
/// pendulum angle there, or `None` when it does not arrive within `max_time`.
fn energy_guess(model: &Model, law: &SwingParams, max_time: f64) -> Option<(Vec<f64>, f64)> {
    let mut x = V4::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    let mut us = Vec::new();
    let steps = (max_time.min(MAX_PLAN_TIME) / model.ts) as usize;
    for _ in 0..steps {
        let mut w: [f64; 4] = x.into();
        w[2] = crate::trig::wrap_angle(w[2]);
        if w[2].abs() <= law.catch_angle {
            return Some((us, x[2]));
        }
        let u = law.voltage(&w, law.acceleration(&w));
        us.push(u);
        x = model.step(&x, u);
    }
    None
}

/// The planned swing-up for the nominal `plant` (module docs): the tracked points, one per
/// period from hanging, or `None` when no plan is found.
pub(crate) fn plan(
    plant: &Plant,
    s: &SwingUpSettings,
    law: &SwingParams,
    ts: f64,
) -> Option<Vec<PlanPoint>> {
    let model = Model::new(plant, ts)?;
    let p = plant.params();
    let u_max = PLAN_VOLTAGE_SHARE * (s.max_voltage - p.vd - p.cr * p.rm / p.kt);
    if u_max.is_nan() || u_max <= 0.0 {
        return None;
    }
    let arm_soft = (s.arm_limit - ARM_ROOM).max(0.5 * s.arm_limit);
    let longest = ((s.max_time - UPRIGHT_TAIL).min(MAX_PLAN_TIME) / ts) as usize;
    let tau = std::f64::consts::TAU;
    // iLQR from the inputs `us` to upright at `goal` (a multiple of 2π): the tracked plan
    // where it is found.
    let attempt = |us: &mut dyn Iterator<Item = f64>, n: usize, goal: f64| {
        if n > longest {
            return None;
        }
        let cost = Cost {
            u_max,
            terminal: V4::new(100.0, 10.0, 1000.0, 10.0),
            goal: V4::new(0.0, 0.0, goal, 0.0),
            input: 0.05,
            arm_soft,
            arm_weight: 1e3,
        };
        let to_v = |u: f64| (u / u_max).clamp(-0.95, 0.95).atanh();
        let vs: Vec<f64> = (0..n).map(|_| us.next().map_or(0.0, to_v)).collect();
        let x0 = V4::new(0.0, 0.0, std::f64::consts::PI, 0.0);
        let iterations = (ITERATION_BUDGET / n).min(MAX_ITERATIONS);
        let (xs, vs) = ilqr(&model, &cost, &x0, vs, iterations)?;
        let end = xs[n];
        let arm = xs.iter().fold(0.0f64, |m, x| m.max(x[0].abs()));
        let off = end - cost.goal;
        let found = (0..4).all(|i| off[i].abs() <= UPRIGHT_TOLERANCE[i]) && arm <= arm_soft + 0.02;
        if !found {
            return None;
        }
        // The tail holds the plan's own final angles at rest, so that the rate estimate
        // along it has no jump.
        let mut us: Vec<f64> = vs.iter().map(|v| u_max * v.tanh()).collect();
        let mut xs = xs;
        let rest = V4::new(end[0], 0.0, end[2], 0.0);
        for _ in 0..((UPRIGHT_TAIL / model.ts).round() as usize) {
            us.push(0.0);
            xs.push(rest);
        }
        tracking(&model, &xs, &us, law.rate_cutoff_hz)
    };
    if let Some((guess, arrival)) = energy_guess(&model, law, s.max_time) {
        let goal = tau * (arrival / tau).round();
        for factor in HORIZON_FACTORS {
            let n = ((guess.len() as f64 * factor).round() as usize).max(10);
            if let Some(plan) = attempt(&mut guess.iter().copied(), n, goal) {
                return Some(plan);
            }
        }
    }
    // The resonant guesses (module docs): the arm driven at the pendulum's own frequency.
    let omega = (law.model.grav / law.model.ja).sqrt();
    RESONANT_HALF_SWINGS.clone().find_map(|halves| {
        let n = (((halves as f64 + 0.5) * std::f64::consts::PI / (omega * ts)).round() as usize)
            .max(10);
        let mut us = (0..).map(|k| RESONANT_SHARE * u_max * (omega * k as f64 * ts).sin());
        attempt(&mut us, n, tau)
    })
}

/// The states the supervisor's rate estimate reads along the planned angles: its filtered
/// backward differences (`rip_control::swing::SwingRates`), starting at rest, so that the
/// tracking error carries no lag of the estimate.
fn as_estimated(xs: &[V4], ts: f64, cutoff_hz: f64) -> Vec<V4> {
    let a = (-(std::f64::consts::TAU * cutoff_hz * ts)).exp();
    let mut out = Vec::with_capacity(xs.len());
    let mut seen = xs[0];
    seen[1] = 0.0;
    seen[3] = 0.0;
    out.push(seen);
    for pair in xs.windows(2) {
        let (before, now) = (pair[0], pair[1]);
        seen[1] = a * seen[1] + (1.0 - a) * (now[0] - before[0]) / ts;
        seen[3] = a * seen[3] + (1.0 - a) * (now[2] - before[2]) / ts;
        seen[0] = now[0];
        seen[2] = now[2];
        out.push(seen);
    }
    out
}

/// How many times the pendulum of `plan` rises into the upper half, `|wrap(α)| < π/2`,
/// counting entries along its points (the last one the rise to upright): 1 for a plan that
/// reaches upright on its first rise (a kick, then one swing up: `qube_servo2`), more for one
/// that pumps over several swings (`paper`: 4).
pub fn rises(plan: &[PlanPoint]) -> u32 {
    let upper = |p: &PlanPoint| crate::trig::wrap_angle(p.x[2]).abs() < std::f64::consts::FRAC_PI_2;
    let mut above = false;
    let mut count = 0;
    for p in plan {
        let now = upper(p);
        count += u32::from(now && !above);
        above = now;
    }
    count
}

/// The weight on the arm's rate added to the paper's LQR weights for the tracking law (module
/// docs, "Tracking").
pub const TRACKING_ARM_RATE_WEIGHT: f64 = 5.0;

/// The tracking law's weights `(Q, R)`: the paper's LQR weights (eq. (13)) with
/// [`TRACKING_ARM_RATE_WEIGHT`] on the arm's rate.
pub fn tracking_weights() -> (crate::linalg::Mat, crate::linalg::Mat) {
    let (mut q, r) = crate::paper::lqr_weights();
    q[(1, 1)] += TRACKING_ARM_RATE_WEIGHT;
    (q, r)
}

/// The time-varying LQR along `(xs, us)` (module docs, "Tracking").
fn tracking(model: &Model, xs: &[V4], us: &[f64], rate_cutoff_hz: f64) -> Option<Vec<PlanPoint>> {
    let (a, b) = model.plant.linearize_upright();
    let (ad, bd) = c2d(&a, &b, model.ts).ok()?;
    let (q, r) = tracking_weights();
    let upright = dlqr(&ad, &bd, &q, &r, None).ok()?;
    let mut p = M4::from_fn(|i, j| upright.s[(i, j)]);
    let q = M4::from_fn(|i, j| q[(i, j)]);
    let r = r[(0, 0)];
    let n = us.len();
    let seen = as_estimated(xs, model.ts, rate_cutoff_hz);
    let mut out = vec![PlanPoint::default(); n];
    for k in (0..n).rev() {
        let (a, b) = model.jacobians(&xs[k], us[k]);
        let pb = p * b;
        let gain = (pb.transpose() * a) / (r + b.dot(&pb));
        let k_row = gain.transpose();
        p = q + a.transpose() * p * (a - b * k_row.transpose());
        p = 0.5 * (p + p.transpose());
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        out[k] = PlanPoint {
            x: seen[k].into(),
            u: us[k],
            k: k_row.into(),
        };
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::MonteCarlo;
    use crate::paper::TS;
    use crate::sim::simulate;
    use crate::spec::study::{arrivals, hanging_config, supervised, Arrivals};
    use crate::spec::{ControllerKind, Param};
    use crate::Spec;

    fn with_method(text: &str, method: &str) -> Spec {
        Spec::parse(&format!("{text}\n[swing_up]\nmethod = \"{method}\"\n")).unwrap()
    }

    fn planned(spec: &Spec) -> Vec<PlanPoint> {
        let plant = spec.plant().unwrap();
        let law = super::super::design::params(&plant, &spec.swing_up, TS).unwrap();
        plan(&plant, &spec.swing_up, &law, TS).expect("a plan")
    }

    /// One LQR swing-up on `plant` (the spec's own plant when `None`), noise seed `seed`.
    fn swing(spec: &Spec, plant: Option<Plant>, seed: u64) -> (Arrivals, bool) {
        let plant = plant.unwrap_or_else(|| spec.plant().unwrap());
        let design = spec.design(TS).unwrap();
        let mut sup = supervised(spec, &design, ControllerKind::Lqr).unwrap();
        let res = simulate(&plant, sup.as_mut(), &hanging_config(spec, TS, seed)).unwrap();
        (
            arrivals(&res, spec.swing_up.catch_angle),
            res.swing_up_succeeded(),
        )
    }

    #[test]
    fn each_preset_has_a_plan_within_its_bounds_that_a_finer_integrator_replays_to_upright() {
        // Generated rig 0's energy law never arrives on its nominal model: its plan comes
        // from a resonant guess.
        let rig0 = crate::rig::Rig::random(0).to_toml();
        let rigs = [
            ("paper", "[plant]\npreset = \"paper\"".to_string()),
            (
                "qube_servo2",
                "[plant]\npreset = \"qube_servo2\"".to_string(),
            ),
            ("generated rig 0", rig0),
        ];
        for (preset, text) in rigs {
            let spec = with_method(&text, "trajectory");
            let points = planned(&spec);
            let s = &spec.swing_up;
            let tail = (UPRIGHT_TAIL / TS).round() as usize;
            let n = points.len() - tail;
            assert!(n > 20, "{preset}: {n} points");
            for p in &points {
                assert!(
                    p.u.abs() < PLAN_VOLTAGE_SHARE * s.max_voltage + 1e-9,
                    "{preset}"
                );
                assert!(
                    p.x[0].abs() <= s.arm_limit - ARM_ROOM + 0.02,
                    "{preset}: {:?}",
                    p.x
                );
            }
            // The planned voltages, held over each period, on the rig's smooth plant (the
            // compensation clears its dead zone and friction) with 8 times the plan's RK4
            // steps: upright at rest where the plan says.
            let plant = spec.plant().unwrap().smooth().unwrap();
            let substeps = 8 * Model::new(&plant, TS).unwrap().substeps;
            let mut x = V4::new(0.0, 0.0, std::f64::consts::PI, 0.0);
            for p in &points[..n] {
                assert!((x[0] - p.x[0]).abs() < 1e-3 && (x[2] - p.x[2]).abs() < 1e-3);
                plant.advance(&mut x, p.u, 0.0, TS, substeps);
            }
            let end = points[n].x;
            assert!((x[0] - end[0]).abs() < 1e-3 && (x[2] - end[2]).abs() < 1e-3);
            let turns = (x[2] / std::f64::consts::TAU).round();
            assert!(turns == 1.0, "{preset}: {x:?}");
            let off = [x[0], x[1], x[2] - turns * std::f64::consts::TAU, x[3]];
            for i in 0..4 {
                assert!(off[i].abs() < UPRIGHT_TOLERANCE[i], "{preset}: {x:?}");
            }
            // The tail rests at the plan's final angles, and its gain is the upright LQR's of
            // the tracking weights (the DARE's, independent of the recursion along the plan).
            for p in &points[n..] {
                assert_eq!((p.x[0], p.x[2], p.u), (end[0], end[2], 0.0));
            }
            let last = points[points.len() - 1];
            assert!(
                last.x[1].abs() < 0.01 && last.x[3].abs() < 0.01,
                "{:?}",
                last.x
            );
            let (a, b) = plant.smooth().unwrap().linearize_upright();
            let (ad, bd) = c2d(&a, &b, TS).unwrap();
            let (q, r) = tracking_weights();
            let k = dlqr(&ad, &bd, &q, &r, None).unwrap().k;
            for i in 0..4 {
                let rel = (last.k[i] - k[(0, i)]).abs() / k[(0, i)].abs().max(1.0);
                assert!(rel < 1e-3, "{preset}: {:?} vs {k}", last.k);
            }
        }
    }

    #[test]
    fn a_planned_swing_up_catches_on_its_first_arrival_where_the_energy_law_goes_over_the_top() {
        // qube_servo2 and a generated rig (seed 5: a dead zone and friction, compensated).
        let rig = crate::rig::Rig::random(5).to_toml();
        for (name, text) in [
            ("qube_servo2", "[plant]\npreset = \"qube_servo2\""),
            ("rig 5", &rig),
        ] {
            let spec = with_method(text, "trajectory");
            for seed in 0..3 {
                let (a, ok) = swing(&spec, None, seed);
                assert!(
                    ok && a.caught_on_first && a.over_tops <= 1,
                    "{name} {seed}: {a:?}"
                );
                assert!(
                    a.peak_arm <= spec.swing_up.arm_limit,
                    "{name} {seed}: {a:?}"
                );
            }
        }
        let (energy, _) = swing(&with_method(&rig, "energy"), None, 0);
        assert!(
            !energy.caught_on_first && energy.over_tops >= 2,
            "{energy:?}"
        );
    }

    #[test]
    fn under_ten_percent_parameter_error_most_planned_swing_ups_catch_on_the_first_arrival() {
        let planned = with_method("[plant]\npreset = \"qube_servo2\"", "trajectory");
        let energy = with_method("[plant]\npreset = \"qube_servo2\"", "energy");
        let study = MonteCarlo {
            base: planned.plant.params(),
            perturbation: 0.1,
            parameters: Param::ALL.to_vec(),
            seed: 2024,
        };
        let (mut first, mut first_energy, mut ok) = (0, 0, 0);
        for i in 0..20 {
            let (plant, seed) = study.run(i).unwrap();
            let (a, success) = swing(&planned, Some(plant), seed);
            first += u32::from(a.caught_on_first);
            ok += u32::from(success);
            first_energy += u32::from(swing(&energy, Some(plant), seed).0.caught_on_first);
        }
        // Measured: 15 and 19 of 20, the energy law 5 first arrivals on the same runs.
        assert!(first >= 13 && ok >= 17, "first {first}, success {ok} of 20");
        assert!(
            first >= first_energy + 6,
            "{first} vs the energy law's {first_energy}"
        );
    }
}
