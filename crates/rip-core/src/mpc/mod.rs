//! Constrained model predictive control with MATLAB MPC Toolbox semantics (the paper's
//! section 3).
//!
//! # Prediction model
//!
//! The plant `x⁺ = A x + B u`, `y = C x` is augmented with an output-disturbance model
//! `x_od⁺ = A_od x_od + B_od w_od`, `y_od = C_od x_od` (the paper's eq. (1)) and a measurement
//! noise `y_n = D_n w_n` (eq. (2)). Outputs are in scaled units `y/s_y` (scale factors `S_y`),
//! so with `x = [x_p; x_od]`
//!
//! ```text
//! A_aug = [A 0; 0 A_od],   B_u = [B; 0],   C_aug = [S_y⁻¹ C  C_od]          (eq. (3))
//! ```
//!
//! # Estimator
//!
//! A steady-state Kalman filter on the augmented model, with the manipulated variables
//! modelled as unit white noise in scaled units (noise input columns `B S_u`), the disturbance
//! noise `B_od` and the measurement noise `D_n` (default `I`):
//!
//! ```text
//! B_n = [B S_u 0 0; 0 B_od 0],  D_n' = [0 0 D_n],
//! Q = B_n B_nᵀ,  R = D_n' D_n'ᵀ,  N = B_n D_n'ᵀ                              (eqs. (8)–(10))
//! [L, M] = kalman(A_aug, I, C_aug, Q, R, N)                                    (eq. (11))
//! ```
//!
//! run in current form (eqs. (4)–(6)): `e = y/s_y − C_aug x̂[k|k−1]`,
//! `x̂[k|k] = x̂[k|k−1] + M e`, `x̂[k+1|k] = A_aug x̂[k|k−1] + B_u u[k] + L e`.
//!
//! # The move
//!
//! At step `k`, from `x = x̂[k|k]` and the previous move `u(k−1)`:
//!
//! ```text
//! minimise   Σ_{i=1..P} Σ_j ( w^y_j (r_j(k+i) − y_j(k+i|k)) / s^y_j )²
//!          + Σ_{i=0..m−1} Σ_j ( w^Δu_j Δu_j(k+i) / s^u_j )²
//!          + Σ_{i=0..P−1} Σ_j ( w^u_j (u_j(k+i) − u_t,j) / s^u_j )²  +  ρ_ε ε²
//! subject to u_min ≤ u(k+i) ≤ u_max                    (hard, i = 0..P−1)
//!            y_min − ε ≤ y(k+i|k) ≤ y_max + ε          (soft, equal concern, i = 1..P)
//!            ε ≥ 0,   Δu(k+i) = 0 for i ≥ m            (control horizon as move blocking)
//! ```
//!
//! (here `y` is the plant output in engineering units, i.e. `s_y` times the model output, and
//! `ε` is in scaled output units). The problem is condensed over `z = [Δu(k) … Δu(k+m−1), ε]`
//! (see the `condense` module docs for the matrices), all state-independent matrices are built
//! in [`Mpc::new`], and each step only fills two vectors and solves the QP with the selected
//! [`QpSolver`]. The applied input is `u(k) = u(k−1) + Δu(k)`.
//!
//! With [`MpcSettings::prediction_step`] `= s > 1` the sums above run over a grid of `s`
//! periods (the `condense` module docs, "Prediction grid"): `y(k+i|k)` is the output `i·s`
//! periods ahead and each planned move is held for `s` periods, so a fast loop keeps a long
//! horizon in seconds without more QP rows; the estimator and the move stay at `Ts`.
//!
//! # Failures and the fallback
//!
//! Every solve reports a [`QpStatus`]. If it is not usable (maximum iterations, numerical
//! trouble, infeasible, non-finite input), the controller applies the previous plan's next
//! move, `u(k|k−1)` from the last successful solve (shifted once per sample, the last planned
//! move held), clamped to the input bounds, and reports [`StepStatus::Fallback`]. The applied
//! input is therefore always finite and within the bounds.
//!
//! A measurement is discarded, as if it had not arrived (zero innovation, so
//! `x̂[k|k] = x̂[k|k−1]`), when it holds NaN or Inf or when anything computed from it overflows:
//! the innovation, the corrected estimate, or the QP data `f`, `b` built on that estimate. The
//! step then applies the fallback, and the estimator keeps predicting from its last good
//! estimate instead of carrying the overflow into every later sample.
//!
//! # Missing samples
//!
//! [`Controller::hold`] stands for a period without a measurement in which the plant receives
//! a given input: the estimator runs the time update with zero innovation and that input, the
//! plan advances one sample as in a fallback step, and the held input becomes the previous move
//! `u(k−1)` of the next step.
//!
//! # The run-time MPC
//!
//! This is the general MPC (several inputs and outputs, long horizons, Clarabel or the active
//! set) and the design object: [`Mpc::control_design`] is what rip-control runs. The
//! experiment file's MPC, as `rip-rt` and the simulations run it, steps with rip-control's
//! controller of that design whenever it computes the same move
//! ([`Mpc::run_time_controller`], which also says how its fallback differs); this type runs otherwise.
//!
//! # Size limits
//!
//! The condensed matrices are dense, so their size is bounded before anything is built:
//! `P ≤` [`MAX_PREDICTION_HORIZON`] ([`MpcSettings::validate`]) and at most
//! [`MAX_CONDENSED_ENTRIES`] entries in the largest condensed matrix ([`Mpc::new`]).

mod backend;
mod clarabel_backend;
mod condense;
mod estimator;
mod model;
pub mod paper;
mod settings;
#[cfg(test)]
mod tests;

use std::time::Instant;

use nalgebra::DVector;

use crate::controller::{Controller, StepStatus};
use crate::error::{Result, RipError};
use crate::kalman::{CurrentEstimator, KalmanDesign};
use crate::linalg::Mat;
use crate::onboard::OnboardController;

use backend::Backend;
pub use backend::{QpSolver, QpStatus};
use condense::{CondenseInput, Condensed};
pub use estimator::EstimatorDesign;
pub use model::AugmentedModel;
use settings::{fill_bounds, fill_default};
pub use settings::{
    MpcSettings, MpcSettingsBuilder, OutputDisturbance, DEFAULT_CONTROL_HORIZON,
    DEFAULT_ECR_WEIGHT, DEFAULT_MAX_ITERATIONS, DEFAULT_PREDICTION_HORIZON, MAX_CONDENSED_ENTRIES,
    MAX_PREDICTION_HORIZON, MAX_QP_ITERATIONS,
};

/// The result of one MPC solve.
#[derive(Debug, Clone)]
pub struct MpcSolution {
    /// The move `u(k)` (applied input; the fallback when [`fallback`](Self::fallback)).
    pub u: DVector<f64>,
    /// `[Δu(k); …; Δu(k+m−1)]` (m·nu, stacked by step) of the applied plan.
    pub du: DVector<f64>,
    /// The slack `ε ≥ 0` (scaled output units): the largest predicted soft-bound violation of
    /// the plan, which is the optimal `ε` for the computed moves; NaN when the QP failed.
    pub slack: f64,
    /// Solver status.
    pub status: QpStatus,
    /// Whether the fallback move was applied.
    pub fallback: bool,
    /// Solver iterations (interior-point iterations or active-set subproblems).
    pub iterations: usize,
    /// Wall time of the QP setup and solve (s).
    pub solve_time: f64,
}

/// Constrained MPC with a built-in Kalman filter (module docs). `Clone + Send`.
#[derive(Debug, Clone)]
pub struct Mpc {
    settings: MpcSettings,
    ts: f64,
    model: AugmentedModel,
    kalman: KalmanDesign,
    estimator: CurrentEstimator,
    qp: Condensed,
    backend: Backend,
    u_lo: Vec<f64>,
    u_hi: Vec<f64>,
    output_scales: Vec<f64>,
    // Workspace and controller state.
    f: DVector<f64>,
    b: DVector<f64>,
    z: DVector<f64>,
    az: DVector<f64>,
    x: Vec<f64>,
    y_scaled: DVector<f64>,
    /// `x̂[k|k−1]` before the time update, to undo one that overflowed.
    prior_backup: DVector<f64>,
    /// A zero reference, to test the QP data of an estimate when the given reference is bad.
    r_zero: Vec<f64>,
    u_prev: Vec<f64>,
    plan: Vec<f64>,
    solution: MpcSolution,
}

fn check_len(name: &str, v: &[f64], n: usize) -> Result<()> {
    if v.len() != n {
        return Err(RipError::Shape {
            name: name.into(),
            expected: format!("({n},)"),
            rows: v.len(),
            cols: 1,
        });
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(RipError::NonFinite { name: name.into() });
    }
    Ok(())
}

impl Mpc {
    /// Builds the controller for the discrete plant `x⁺ = A x + B u`, `y = C x` sampled at
    /// `ts`: the augmented model, the Kalman gains, the condensed QP and the solver.
    pub fn new(a: &Mat, b: &Mat, c: &Mat, ts: f64, settings: MpcSettings) -> Result<Self> {
        settings.validate()?;
        let estimator = EstimatorDesign::new(a, b, c, &settings)?;
        Self::with_estimator(&estimator, ts, settings)
    }

    /// Builds the controller on an existing Kalman design (the one a controller assembly
    /// shares with an LQG), designed by [`EstimatorDesign::new`] with the same scales,
    /// disturbance and measurement-noise settings as `settings`.
    pub fn with_estimator(
        design: &EstimatorDesign,
        ts: f64,
        settings: MpcSettings,
    ) -> Result<Self> {
        settings.validate()?;
        crate::linalg::check_sample_time("Ts", ts)?;
        design.check_settings(&settings)?;
        let (nu, ny) = (design.n_inputs(), design.n_outputs());
        settings.check_sizes(nu, ny)?;
        let wy = fill_default("output_weights", &settings.output_weights, ny, 1.0)?;
        let wu = fill_default("input_weights", &settings.input_weights, nu, 0.0)?;
        let wdu = fill_default("input_rate_weights", &settings.input_rate_weights, nu, 0.1)?;
        let ut = fill_default("input_target", &settings.input_target, nu, 0.0)?;
        let su = fill_default("input_scales", &settings.input_scales, nu, 1.0)?;
        let sy = fill_default("output_scales", &settings.output_scales, ny, 1.0)?;
        let ub = fill_bounds("input_bounds", &settings.input_bounds, nu)?;
        let yb = fill_bounds("output_bounds", &settings.output_bounds, ny)?;
        let model = design.model().clone();
        let kalman = design.kalman().clone();
        let nx = model.a.nrows();
        settings.check_condensed(nx, nu, ny)?;
        let estimator = CurrentEstimator::new(
            model.a.clone(),
            model.b.clone(),
            model.c.clone(),
            None,
            kalman.l.clone(),
            kalman.m.clone(),
            DVector::zeros(nx),
        )?;

        let qp = Condensed::new(&CondenseInput {
            a: &model.a,
            b: &model.b,
            c: &model.c,
            p: settings.prediction_horizon,
            m: settings.control_horizon,
            step: settings.prediction_step,
            output_weights: &wy,
            input_weights: &wu,
            input_rate_weights: &wdu,
            input_target: &ut,
            input_scales: &su,
            output_scales: &sy,
            input_bounds: &ub,
            output_bounds: &yb,
            ecr_weight: settings.ecr_weight,
        });
        model::check_condensed(&qp, &model, &settings, &wdu, &wu)?;
        let backend = Backend::new(settings.solver, &qp, settings.max_iterations)?;
        let (nz, ncon, m) = (qp.nz, qp.ncon, qp.m);
        Ok(Self {
            ts,
            kalman,
            estimator,
            backend,
            u_lo: ub.iter().map(|b| b.0).collect(),
            u_hi: ub.iter().map(|b| b.1).collect(),
            output_scales: sy,
            f: DVector::zeros(nz),
            b: DVector::zeros(ncon),
            z: DVector::zeros(nz),
            az: DVector::zeros(ncon),
            x: vec![0.0; nx],
            y_scaled: DVector::zeros(ny),
            prior_backup: DVector::zeros(nx),
            r_zero: vec![0.0; ny],
            u_prev: vec![0.0; nu],
            plan: vec![0.0; m * nu],
            solution: MpcSolution {
                u: DVector::zeros(nu),
                du: DVector::zeros(m * nu),
                slack: 0.0,
                status: QpStatus::Solved,
                fallback: false,
                iterations: 0,
                solve_time: 0.0,
            },
            model,
            qp,
            settings,
        })
    }

    /// The settings the controller was built with.
    pub fn settings(&self) -> &MpcSettings {
        &self.settings
    }

    /// Sample time (s).
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// The augmented prediction model.
    pub fn model(&self) -> &AugmentedModel {
        &self.model
    }

    /// The built-in Kalman filter design (`L`, `M`, covariances, poles).
    pub fn kalman_design(&self) -> &KalmanDesign {
        &self.kalman
    }

    /// Number of augmented states.
    pub fn n_states(&self) -> usize {
        self.qp.nx
    }

    /// Prediction horizon `P`.
    pub fn prediction_horizon(&self) -> usize {
        self.qp.p
    }

    /// Control horizon `m`.
    pub fn control_horizon(&self) -> usize {
        self.qp.m
    }

    /// Number of QP variables (`m·nu + 1`) and constraint rows.
    pub fn qp_size(&self) -> (usize, usize) {
        (self.qp.nz, self.qp.ncon)
    }

    /// How many constraint rows are hard input bounds (first) and soft output bounds (next);
    /// the last row is `−ε ≤ 0`.
    pub fn constraint_layout(&self) -> (usize, usize) {
        (self.qp.rows.n_input, self.qp.rows.n_soft)
    }

    /// Input bounds `(u_min, u_max)`, `±∞` where unbounded.
    pub fn input_bounds(&self) -> (&[f64], &[f64]) {
        (&self.u_lo, &self.u_hi)
    }

    /// The previous move `u(k−1)` the next [`step`](Controller::step) starts from.
    pub fn last_input(&self) -> &[f64] {
        &self.u_prev
    }

    /// The result of the last solve or step.
    pub fn last_solution(&self) -> &MpcSolution {
        &self.solution
    }

    /// The condensed QP `(H, f, A_c, b)` for the given data (`½zᵀHz + fᵀz`, `A_c z ≤ b`),
    /// for checking against an independent formulation. Allocates.
    pub fn qp_matrices(
        &self,
        x: &[f64],
        u_prev: &[f64],
        r: &[f64],
    ) -> Result<(Mat, DVector<f64>, Mat, DVector<f64>)> {
        self.check_solve_args(x, u_prev, r)?;
        let mut f = DVector::zeros(self.qp.nz);
        let mut b = DVector::zeros(self.qp.ncon);
        self.qp.fill_linear(x, u_prev, r, &mut f, &mut b);
        Ok((self.qp.h.clone(), f, self.qp.a.clone(), b))
    }

    /// Predicted outputs `y(k+i|k)`, `i = 1..P` (P × ny, engineering units; `i` counts
    /// prediction steps of [`MpcSettings::prediction_step`] periods), for the augmented
    /// state `x`, previous input `u_prev` and moves `du` (m·nu). Allocates.
    pub fn predict_outputs(&self, x: &[f64], u_prev: &[f64], du: &[f64]) -> Result<Mat> {
        check_len("x", x, self.qp.nx)?;
        check_len("u_prev", u_prev, self.qp.nu)?;
        check_len("du", du, self.qp.m * self.qp.nu)?;
        let y = self.qp.predict(x, u_prev, du);
        let ny = self.qp.ny;
        Ok(Mat::from_fn(self.qp.p, ny, |i, j| {
            y[i * ny + j] * self.output_scales[j]
        }))
    }

    fn check_solve_args(&self, x: &[f64], u_prev: &[f64], r: &[f64]) -> Result<()> {
        check_len("x", x, self.qp.nx)?;
        check_len("u_prev", u_prev, self.qp.nu)?;
        self.check_reference(r)
    }

    fn check_reference(&self, r: &[f64]) -> Result<()> {
        let ny = self.qp.ny;
        if r.is_empty() || r.len() % ny != 0 || r.len() / ny > self.qp.p {
            return Err(RipError::Shape {
                name: "r".into(),
                expected: format!("({ny},) or (q, {ny}) with 1 ≤ q ≤ P = {}", self.qp.p),
                rows: r.len() / ny.max(1),
                cols: ny,
            });
        }
        if r.iter().any(|v| !v.is_finite()) {
            return Err(RipError::NonFinite { name: "r".into() });
        }
        Ok(())
    }

    /// Computes the move for the augmented state `x` (plant states, then disturbance
    /// states), the previous input `u_prev` and the reference `r` (`ny` values, or a preview of
    /// `q ≤ P` rows of `ny` values for `r(k+1) … r(k+q)`, the last row held to `k+P`), in
    /// engineering units. Does not touch the estimator; does update the warm start and the plan
    /// the fallback uses. Errors name a wrong-length or non-finite argument.
    pub fn solve(&mut self, x: &[f64], u_prev: &[f64], r: &[f64]) -> Result<&MpcSolution> {
        self.check_solve_args(x, u_prev, r)?;
        self.x.copy_from_slice(x);
        self.solve_buffers(u_prev, r, QpStatus::Solved, false);
        Ok(&self.solution)
    }

    /// One controller sample with a reference preview (see [`solve`](Self::solve) for `r`):
    /// estimator correction with `y`, move, estimator prediction with the applied move.
    /// The written `u` is always finite and within the input bounds. A measurement that is
    /// non-finite or overflows the correction or the QP data is discarded (module docs).
    pub fn step_preview(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        let ny = self.qp.ny;
        let r_ok = self.check_reference(r).is_ok();
        let mut measured = y.len() == ny && y.iter().all(|v| v.is_finite());
        if measured {
            for ((ys, &yi), &s) in self.y_scaled.iter_mut().zip(y).zip(&self.output_scales) {
                *ys = yi / s;
            }
            let posterior = self
                .estimator
                .correct(self.y_scaled.as_slice(), &self.u_prev);
            self.x.copy_from_slice(posterior.as_slice());
            measured = all_finite(&self.x) && all_finite(self.estimator.innovation().as_slice());
        }
        if measured {
            // A finite but huge estimate can still overflow the QP data; kept, it would make
            // every later step fail too. Tested even when this step's reference is unusable.
            let r_fill = if r_ok { r } else { &self.r_zero };
            self.qp
                .fill_linear(&self.x, &self.u_prev, r_fill, &mut self.f, &mut self.b);
            measured = all_finite(self.f.as_slice()) && all_finite(self.b.as_slice());
        }
        if !measured {
            let posterior = self.estimator.correct_without_measurement();
            self.x.copy_from_slice(posterior.as_slice());
        }
        let pre_status = if measured && r_ok {
            QpStatus::Solved
        } else {
            QpStatus::InvalidInput
        };
        let u_prev = std::mem::take(&mut self.u_prev);
        self.solve_buffers(&u_prev, if r_ok { r } else { &[] }, pre_status, true);
        self.u_prev = u_prev;
        self.u_prev.copy_from_slice(self.solution.u.as_slice());
        self.prior_backup.copy_from(self.estimator.prior());
        self.estimator.predict(&self.u_prev);
        if !all_finite(self.estimator.prior().as_slice()) {
            // Same reasoning for the time update: redo it from the last good prior, without
            // the innovation, rather than carry an overflow into every later sample.
            self.estimator.set_prior(self.prior_backup.as_slice());
            self.estimator.predict_without_measurement(&self.u_prev);
        }
        let n = u.len().min(self.u_prev.len());
        u[..n].copy_from_slice(&self.u_prev[..n]);
        if self.solution.fallback {
            StepStatus::Fallback
        } else {
            StepStatus::Nominal
        }
    }

    /// A period without a measurement in which the plant receives `u` (the
    /// [`Controller::hold`] of this controller; module docs): the estimator's time update with
    /// zero innovation, the plan shifted by one sample, and `u` as the next step's `u(k−1)`.
    /// Non-finite entries of `u` keep the previous input. [`last_solution`](Self::last_solution)
    /// is left as it was.
    pub fn hold_input(&mut self, u: &[f64]) {
        for (prev, &held) in self.u_prev.iter_mut().zip(u) {
            if held.is_finite() {
                *prev = held;
            }
        }
        self.estimator.predict_without_measurement(&self.u_prev);
        self.x
            .copy_from_slice(self.estimator.posterior().as_slice());
        let nu = self.qp.nu;
        if self.qp.m > 1 {
            self.plan.copy_within(nu.., 0);
        }
    }

    /// A sample whose input `u` someone else chose ([`Controller::observe`]): the estimator's
    /// correction with `y` (discarded as in a step when unusable), `u` as the next step's
    /// `u(k−1)` and as every move of the plan the fallback would use, then the time update with
    /// `u`. No QP is solved; [`last_solution`](Self::last_solution) is left as it was.
    pub fn observe_input(&mut self, y: &[f64], u: &[f64]) {
        let ny = self.qp.ny;
        let mut measured = y.len() == ny && y.iter().all(|v| v.is_finite());
        if measured {
            for ((ys, &yi), &s) in self.y_scaled.iter_mut().zip(y).zip(&self.output_scales) {
                *ys = yi / s;
            }
            let posterior = self
                .estimator
                .correct(self.y_scaled.as_slice(), &self.u_prev);
            measured = all_finite(posterior.as_slice())
                && all_finite(self.estimator.innovation().as_slice());
        }
        if !measured {
            self.estimator.correct_without_measurement();
        }
        self.x
            .copy_from_slice(self.estimator.posterior().as_slice());
        self.take_applied_input(u);
        self.prior_backup.copy_from(self.estimator.prior());
        self.estimator.predict(&self.u_prev);
        if !all_finite(self.estimator.prior().as_slice()) {
            self.estimator.set_prior(self.prior_backup.as_slice());
            self.estimator.predict_without_measurement(&self.u_prev);
        }
    }

    /// Restarts the estimator at the plant state `x_plant` ([`Controller::seed`]): `x̂[k|k]` is
    /// `x_plant` with the disturbance states at zero, `u` becomes `u(k−1)` and the plan, and
    /// `x̂[k+1|k] = A x̂[k|k] + B u`. A non-finite or short `x_plant` is a held period instead.
    pub fn seed_state(&mut self, x_plant: &[f64], u: &[f64]) {
        let n = self.model.n_plant;
        if x_plant.len() < n || !all_finite(&x_plant[..n]) {
            self.hold_input(u);
            return;
        }
        self.x.fill(0.0);
        self.x[..n].copy_from_slice(&x_plant[..n]);
        self.estimator.set_prior(&self.x);
        self.estimator.correct_without_measurement();
        self.take_applied_input(u);
        self.estimator.predict(&self.u_prev);
    }

    /// `u` (finite entries) as the previous move and as every planned move, clamped.
    fn take_applied_input(&mut self, u: &[f64]) {
        for (prev, &applied) in self.u_prev.iter_mut().zip(u) {
            if applied.is_finite() {
                *prev = applied;
            }
        }
        let nu = self.qp.nu;
        for (j, slot) in self.plan.iter_mut().enumerate() {
            let c = j % nu;
            *slot = self.u_prev[c].max(self.u_lo[c]).min(self.u_hi[c]);
        }
    }

    /// Solves from `self.x`, writes `self.solution`, shifts the plan. `pre_status` other than
    /// `Solved` skips the QP and applies the fallback. `filled`: `f` and `b` already hold the
    /// data for `self.x`, `u_prev` and `r`.
    #[allow(clippy::needless_range_loop)] // input index c runs over several arrays
    fn solve_buffers(&mut self, u_prev: &[f64], r: &[f64], pre_status: QpStatus, filled: bool) {
        let start = Instant::now();
        let (nu, m) = (self.qp.nu, self.qp.m);
        let (status, iterations) = if pre_status == QpStatus::Solved {
            if !filled {
                self.qp
                    .fill_linear(&self.x, u_prev, r, &mut self.f, &mut self.b);
            }
            if !(all_finite(self.f.as_slice()) && all_finite(self.b.as_slice())) {
                (QpStatus::InvalidInput, 0)
            } else {
                self.backend.solve(&self.f, &self.b, &mut self.z)
            }
        } else {
            (pre_status, 0)
        };

        // The previous plan advances one sample whatever happens now.
        if m > 1 {
            self.plan.copy_within(nu.., 0);
        }
        let slack = if status.is_usable() {
            self.exact_slack()
        } else {
            f64::NAN
        };
        let sol = &mut self.solution;
        sol.status = status;
        sol.iterations = iterations;
        if status.is_usable() {
            for c in 0..nu {
                let mut u = u_prev[c];
                for j in 0..m {
                    u += self.z[j * nu + c];
                    self.plan[j * nu + c] = u.max(self.u_lo[c]).min(self.u_hi[c]);
                }
            }
            sol.slack = slack;
            sol.fallback = false;
        } else {
            for c in 0..nu {
                self.plan[c] = self.plan[c].max(self.u_lo[c]).min(self.u_hi[c]);
            }
            sol.slack = slack;
            sol.fallback = true;
        }
        for c in 0..nu {
            let mut prev = if u_prev[c].is_finite() {
                u_prev[c]
            } else {
                self.plan[c]
            };
            for j in 0..m {
                sol.du[j * nu + c] = self.plan[j * nu + c] - prev;
                prev = self.plan[j * nu + c];
            }
            sol.u[c] = self.plan[c];
        }
        sol.solve_time = start.elapsed().as_secs_f64();
    }

    /// The optimal `ε` for the computed moves: given `Δ`, the cost grows with `ε`, so the
    /// optimum is the largest soft-bound violation of the plan, `max(0, max_i a_iᵀΔ − b_i)`.
    /// Recomputing it removes the interior-point error in `ε`, which the objective weighs so
    /// little (`ρ_ε ε²` next to terms of `10⁴`) that a solver leaves it at `~10⁻⁴`.
    fn exact_slack(&mut self) -> f64 {
        let nd = self.qp.nz - 1;
        self.z[nd] = 0.0;
        self.az.gemv(1.0, &self.qp.a, &self.z, 0.0);
        let (start, len) = (self.qp.rows.n_input, self.qp.rows.n_soft);
        let mut eps = 0.0f64;
        for i in start..start + len {
            eps = eps.max(self.az[i] - self.b[i]);
        }
        self.z[nd] = eps;
        eps
    }

    /// Returns to the state right after construction.
    pub fn reset_state(&mut self) {
        self.estimator.reset();
        self.u_prev.fill(0.0);
        self.plan.fill(0.0);
        self.backend.reset();
    }

    /// The run-time controller of this MPC ([`OnboardController`]) when the device's code computes the same move:
    /// the QP solver is [`QpSolver::ActiveSet`] (the default; it is rip-control's dual active
    /// set with its warm start), the iteration bound is within
    /// [`rip_control::MAX_QP_ITERATIONS`], and the design fits rip-control's capacities (one
    /// input, at most two outputs and [`rip_control::MAX_NX`] states, `P ≤ 100`, `m ≤ 4`:
    /// [`control_design`](Self::control_design)). `None` otherwise (Clarabel, MIMO, long horizons), where
    /// this [`Mpc`] itself is the run-time controller.
    ///
    /// This is the one place that choice is made. Both solve the same QP from the same
    /// estimate; they differ only after a failed solve (iteration limit, numerical trouble):
    /// rip-control applies the unconstrained minimiser clamped to the bounds, [`Mpc`] the
    /// previous plan's next move.
    pub fn run_time_controller(&self) -> Option<OnboardController> {
        let settings = self.settings();
        let bounded = u32::try_from(settings.max_iterations)
            .is_ok_and(|n| n <= rip_control::MAX_QP_ITERATIONS);
        if settings.solver != QpSolver::ActiveSet || !bounded {
            return None;
        }
        let design = self.control_design().ok()?;
        OnboardController::new(&design).ok()
    }

    /// The design rip-control runs for this controller ([`crate::onboard`]): the estimator,
    /// the condensed QP for a constant reference, the input bounds and the iteration bound.
    ///
    /// # Errors
    /// A size beyond rip-control's capacities (one input, `P ≤ 100`, `m ≤ 4`, 8 states),
    /// naming it.
    pub fn control_design(&self) -> Result<rip_control::Design> {
        use crate::onboard::put;
        use rip_control::{MAX_NX, MAX_NY};
        let mut d = rip_control::Design {
            kind: rip_control::Kind::Mpc,
            ts: self.ts,
            ..rip_control::Design::default()
        };
        if self.qp.nu != 1 {
            return Err(RipError::invalid("B", "the onboard MPC has one input"));
        }
        d.input_bounds = [self.u_lo[0], self.u_hi[0]];
        let (a, b, c, l, m) = self.estimator.matrices();
        put("A", &mut d.a, a, MAX_NX, MAX_NX)?;
        put("B", &mut d.b, b, MAX_NX, 1)?;
        put("C", &mut d.c, c, MAX_NY, MAX_NX)?;
        put("L", &mut d.l, l, MAX_NX, MAX_NY)?;
        put("M", &mut d.m, m, MAX_NX, MAX_NY)?;
        d.nx = a.nrows();
        d.ny = c.nrows();
        d.output_scales[..d.ny].copy_from_slice(&self.output_scales);
        self.qp.fill_control(&mut d)?;
        d.max_iterations = u32::try_from(self.settings.max_iterations)
            .unwrap_or(u32::MAX)
            .min(rip_control::MAX_QP_ITERATIONS);
        d.validate().map_err(crate::onboard::refused)?;
        Ok(d)
    }

    /// The estimator (its posterior `x̂[k|k]` and prior `x̂[k+1|k]`).
    pub fn estimator(&self) -> &CurrentEstimator {
        &self.estimator
    }
}

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl Controller for Mpc {
    fn n_outputs(&self) -> usize {
        self.qp.ny
    }

    fn n_inputs(&self) -> usize {
        self.qp.nu
    }

    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        self.step_preview(y, r, u)
    }

    fn hold(&mut self, u: &[f64]) {
        self.hold_input(u);
    }

    fn observe(&mut self, y: &[f64], u: &[f64]) {
        self.observe_input(y, u);
    }

    fn seed(&mut self, x: &[f64], u: &[f64]) {
        self.seed_state(x, u);
    }

    fn reset(&mut self) {
        self.reset_state();
    }

    fn sample_time(&self) -> Option<f64> {
        Some(self.ts())
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        Some(self.estimator.posterior().as_slice())
    }
}
