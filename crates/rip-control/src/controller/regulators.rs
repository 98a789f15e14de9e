//! The regulators' steps (crate docs, "LQR" and "Estimator"): LQR's rate filter and its
//! input-disturbance observer, LQG's law on the filter's estimate, and the feedback both share.

use super::{gemv_acc, Controller, Measurement, Phase, Status};
use crate::design::{MAX_NY, NX_PLANT};
use crate::real::Real;

impl<R: Real> Controller<R> {
    pub(super) fn sync_lqr_estimate(&mut self) {
        let ([t, a], [tr, ar]) = (self.filter.angles(), self.filter.rates());
        self.x_hat = [t, tr, a, ar];
    }

    pub(super) fn update_lqr_estimate(&mut self, y: &[R; MAX_NY]) -> bool {
        if !self.filter.update([y[0], y[1]]) {
            return false;
        }
        self.sync_lqr_estimate();
        true
    }

    /// `sat(−K (x − x_ref) − k_i x_i)` (and `− d̂` where the design cancels an input
    /// disturbance), then the integrator's update with the arm error (conditional
    /// integration) when `integrate`; a non-finite value becomes 0 (clamped).
    pub(super) fn feedback(&mut self, r: &[R; MAX_NY], arm: R, integrate: bool) -> (R, bool) {
        let x = self.x_hat;
        let k = self.design.k;
        let err = [x[0] - r[0], x[1], x[2] - r[1], x[3]];
        let mut acc = k[0] * err[0];
        for j in 1..NX_PLANT {
            acc += k[j] * err[j];
        }
        let mut v = -acc - self.input_disturbance();
        let ki = self.design.integral_gain;
        if ki != R::ZERO {
            v -= ki * self.integral;
        }
        let [lo, hi] = self.plan_bounds;
        if !v.is_finite() {
            return (R::ZERO.clamp(lo, hi), false);
        }
        let u = v.clamp(lo, hi);
        if integrate && ki != R::ZERO {
            let ts = self.design.ts;
            let error = r[0] - arm;
            let push = -ki * ts * error;
            let deepens = (v > u && push > R::ZERO) || (v < u && push < R::ZERO);
            if !deepens {
                let next = self.integral + ts * error;
                if next.is_finite() {
                    self.integral = next;
                }
            }
        }
        (u, true)
    }

    /// With [`Design::cancels_input_disturbance`], after a fresh `x̂`:
    /// `d̂ ← d̂ + g (x̂ − x̂⁻)` (crate docs, "LQR"); a non-finite update is not kept.
    pub(super) fn observe_disturbance(&mut self) {
        if let Some(predicted) = self.x_predicted {
            let g = self.design.disturbance_gain;
            let mut next = self.disturbance;
            for i in 0..NX_PLANT {
                next += g[i] * (self.x_hat[i] - predicted[i]);
            }
            if next.is_finite() {
                self.disturbance = next;
            }
        }
    }

    /// `x̂⁻ = A x + B (v + d̂)` from `x`, the planned `v` applied over the period.
    pub(super) fn lqr_prediction(&self, x: &[R; NX_PLANT], v: R) -> Option<[R; NX_PLANT]> {
        let d = &self.design;
        let w = v + self.disturbance;
        let mut next = [R::ZERO; NX_PLANT];
        for i in 0..NX_PLANT {
            next[i] = d.b[i] * w;
        }
        gemv_acc(&mut next, &d.a, x, NX_PLANT, NX_PLANT, R::ONE);
        next.iter().all(|x| x.is_finite()).then_some(next)
    }

    /// The prediction from the fresh `x̂` and the planned `v` (LQR cancelling an input
    /// disturbance; nothing otherwise).
    pub(super) fn predict_lqr(&mut self, v: R) {
        if self.design.cancels_input_disturbance {
            self.x_predicted = self.lqr_prediction(&self.x_hat, v);
        }
    }

    /// The prediction carried over a period without a fresh `x̂`.
    pub(super) fn predict_lqr_over_held(&mut self, v: R) {
        if let Some(x) = self.x_predicted {
            self.x_predicted = self.lqr_prediction(&x, v);
        }
    }

    pub(super) fn step_lqr(
        &mut self,
        m: &Measurement<R>,
        probe: &mut impl FnMut(Phase),
    ) -> (R, Status, u32) {
        let fresh = self.update_lqr_estimate(&m.angles);
        if fresh && self.design.cancels_input_disturbance {
            self.observe_disturbance();
        }
        probe(Phase::Estimate);
        if !fresh {
            self.filter.hold();
            let (u, _) = self.feedback(&m.reference, self.x_hat[0], false);
            self.predict_lqr_over_held(u);
            return (u, Status::InvalidMeasurement, 0);
        }
        let arm = self.x_hat[0];
        let (u, ok) = self.feedback(&m.reference, arm, true);
        self.predict_lqr(u);
        (
            u,
            if ok {
                Status::Nominal
            } else {
                Status::InvalidMeasurement
            },
            0,
        )
    }

    /// [`Design::regulates_outputs`]: `θ̂ += s_θ Σ_{j≥4} C[0,j] x̂_j`, `α̂ += s_α Σ_{j≥4}
    /// C[1,j] x̂_j` (crate docs, "Estimator"); the estimate's angles are states 0 and 2.
    ///
    /// [`Design::regulates_outputs`]: crate::Design::regulates_outputs
    fn add_output_disturbance(&mut self) {
        let (n, d) = (self.design.nx, &self.design);
        for (i, state) in [0, 2].into_iter().enumerate() {
            let mut share = R::ZERO;
            for j in NX_PLANT..n {
                share += d.c[i * n + j] * self.est.posterior[j];
            }
            self.x_hat[state] += d.output_scales[i] * share;
        }
    }

    pub(super) fn step_lqg(
        &mut self,
        m: &Measurement<R>,
        probe: &mut impl FnMut(Phase),
    ) -> (R, Status, u32) {
        let usable = self.correct(&m.angles);
        if !usable {
            self.correct_without_measurement();
        }
        probe(Phase::Estimate);
        self.sync_plant_estimate();
        if self.design.regulates_outputs {
            self.add_output_disturbance();
        }
        let (u, ok) = self.feedback(&m.reference, m.angles[0], usable);
        self.u_prev = u;
        self.predict();
        let status = if usable && ok {
            Status::Nominal
        } else {
            Status::InvalidMeasurement
        };
        (u, status, 0)
    }
}
