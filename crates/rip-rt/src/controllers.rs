//! Builds the selected controller from the configuration. All three are designed on the
//! paper's plant (section 3) discretised at the loop period, with the paper's weights unless
//! the configuration overrides them.

use std::fmt;
use std::str::FromStr;

use rip_core::mpc::{Mpc, MpcSettings, OutputDisturbance, QpSolver};
use rip_core::regulators::{Lqg, Lqr};
use rip_core::{c2d, dlqr, paper, Controller, Mat};

use crate::config::{BoundedOutput, Config};

/// The controllers `rip-rt run --controller` accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerKind {
    /// LQR on measured angles, rates by filtered difference.
    Lqr,
    /// LQR gain on the steady-state Kalman filter's estimate.
    Lqg,
    /// Constrained MPC sharing the Kalman filter.
    Mpc,
}

impl ControllerKind {
    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            ControllerKind::Lqr => "lqr",
            ControllerKind::Lqg => "lqg",
            ControllerKind::Mpc => "mpc",
        }
    }
}

impl fmt::Display for ControllerKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ControllerKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "lqr" => Ok(ControllerKind::Lqr),
            "lqg" => Ok(ControllerKind::Lqg),
            "mpc" => Ok(ControllerKind::Mpc),
            _ => Err(format!("must be lqr, lqg or mpc, got {s:?}")),
        }
    }
}

/// The paper's plant `(A_d, B_d)` at sample time `ts`.
fn plant(ts: f64) -> Result<(Mat, Mat), String> {
    let (ac, bc) = paper::continuous_model();
    c2d(&ac, &bc, ts).map_err(|e| format!("plant discretisation: {e}"))
}

/// Builds the controller `kind` as configured.
pub fn build(kind: ControllerKind, cfg: &Config) -> Result<Box<dyn Controller>, String> {
    let ts = cfg.period_s();
    let (ad, bd) = plant(ts)?;
    let v = cfg.safety.voltage_limit;
    let q = Mat::from_diagonal(&nalgebra::DVector::from_row_slice(&cfg.lqr.q));
    let r = Mat::from_element(1, 1, cfg.lqr.r);
    let design_err = |what: &str, e: rip_core::RipError| format!("{what} design: {e}");
    match kind {
        ControllerKind::Lqr => {
            let lqr = Lqr::design(&ad, &bd, &q, &r, ts, cfg.lqr.rate_cutoff_hz)
                .and_then(|c| c.with_input_bounds(-v, v))
                .map_err(|e| design_err("lqr", e))?;
            Ok(Box::new(lqr))
        }
        ControllerKind::Lqg => {
            let k = dlqr(&ad, &bd, &q, &r, None)
                .map_err(|e| design_err("lqg", e))?
                .k;
            // LQG uses the MPC's estimator, as in the paper: the augmented model of eq. (3) and
            // the Kalman gains of eq. (11), designed once in one place.
            let mpc = mpc(cfg, &ad, &bd, ts)?;
            let (model, kf) = (mpc.model(), mpc.kalman_design());
            let lqg = Lqg::new(&k, &model.a, &model.b, &model.c, &kf.l, &kf.m, ts)
                .and_then(|c| c.with_input_bounds(-v, v))
                .map_err(|e| design_err("lqg", e))?;
            Ok(Box::new(lqg))
        }
        ControllerKind::Mpc => Ok(Box::new(mpc(cfg, &ad, &bd, ts)?)),
    }
}

/// The MPC of section 3 with the configured settings.
fn mpc(cfg: &Config, ad: &Mat, bd: &Mat, ts: f64) -> Result<Mpc, String> {
    let m = &cfg.mpc;
    let v = cfg.safety.voltage_limit;
    let design_err = |e: rip_core::RipError| format!("mpc design: {e}");
    let bound = (-m.soft_bound, m.soft_bound);
    let free = (f64::NEG_INFINITY, f64::INFINITY);
    let output_bounds = match m.bounded_output {
        BoundedOutput::Pendulum => vec![free, bound],
        BoundedOutput::Arm => vec![bound, free],
    };
    let solver = QpSolver::from_name(&m.solver).map_err(design_err)?;
    let settings: MpcSettings = MpcSettings::builder()
        .prediction_horizon(m.horizon)
        .control_horizon(m.control_horizon)
        .output_weights(m.output_weights.to_vec())
        .input_weights(vec![0.0])
        .input_rate_weights(vec![m.rate_weight])
        .input_scales(vec![paper::INPUT_SCALE])
        .output_scales(vec![1.0, 1.0])
        .input_bounds(vec![(-v, v)])
        .output_bounds(output_bounds)
        .ecr_weight(m.slack_weight)
        .output_disturbance(Some(OutputDisturbance::integrated_white_noise(2, 0.01)))
        .solver(solver)
        .build()
        .map_err(design_err)?;
    Mpc::new(ad, bd, &paper::output_matrix(), ts, settings).map_err(design_err)
}
