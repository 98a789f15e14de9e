//! Keys of one controller's own, where the shared cost leaves it short of the bar.
//!
//! The shared cost is the paper's thesis, and [`super::tune`] looks for it first. Where it
//! leaves a controller short, what that controller uses alone is changed on top of it, in an
//! order that leaves every controller already judged as it was:
//!
//! 1. LQG: its filter. First a filter of its own with a disturbance at the plant input that
//!    its law cancels (`kalman.input_disturbance`: what the compensation leaves of a dead
//!    zone, friction or breakaway torque), then the shared filter's noise model
//!    (`kalman.measurement_noise`, `kalman.disturbance_gain`; [`KalmanWeights`],
//!    [`search_lqg`]), with LQG's law on the estimated outputs (`kalman.regulate_outputs`) tried
//!    on the shared filter before any change to it and again with each. LQR does not use the
//!    filter; the MPC uses the shared one, and is judged again on the filter chosen.
//! 2. The MPC: its weights (`mpc.output_weights`, `mpc.input_rate_weights`,
//!    `mpc.input_weights`; [`MpcWeights`], [`search`]). Its loop differs from LQR's: it
//!    weights the input's rate, not the input, which adds an integrator's phase lag at the
//!    plant input and costs disk margin.
//!
//! 0. LQR: an observer of a disturbance at the plant input whose estimate its law cancels
//!    (`lqr.disturbance_bandwidth`; [`LqrWeights`], [`search_lqr`]), the same disturbance
//!    LQG's own filter estimates. Its `[lqr]` weights are LQG's too, and stay as they are.
//!
//! The report says what changed (`Tuned::own`).

use crate::spec::{ControllerKind, Spec, SpecError};

use std::sync::atomic::AtomicBool;

use super::{check_cancel, screen_then_confirm, Assessment, Bar};

/// A change to the MPC's own weights on top of the shared ones: its output weights scaled by
/// `√arm` and `√pendulum`, its input-rate weight by `√rate`, and an input weight added of
/// `input` times the input-rate weight (the MPC's weights enter its cost squared).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcWeights {
    /// Factor on the arm's output weight, squared.
    pub arm: f64,
    /// Factor on the pendulum's output weight, squared.
    pub pendulum: f64,
    /// Factor on the input-rate weight, squared.
    pub rate: f64,
    /// The input weight set, relative to the (scaled) input-rate weight.
    pub input: f64,
}

impl MpcWeights {
    /// No change: the shared weights.
    pub const SHARED: MpcWeights = MpcWeights {
        arm: 1.0,
        pendulum: 1.0,
        rate: 1.0,
        input: 0.0,
    };

    /// `spec` with this change to its `[mpc]` weights.
    pub fn apply(&self, spec: &Spec) -> Spec {
        let mut s = spec.clone();
        s.mpc.output_weights[0] *= self.arm.sqrt();
        s.mpc.output_weights[1] *= self.pendulum.sqrt();
        s.mpc.input_rate_weights[0] *= self.rate.sqrt();
        if self.input > 0.0 {
            s.mpc.input_weights[0] = self.input * s.mpc.input_rate_weights[0];
        }
        s
    }
}

/// The changes tried, the gentlest (nearest the shared weights) first: the input-rate weight
/// raised (a slower, better-margined loop) or lowered, an input weight added (a loop nearer
/// LQR's, whose margins the rate weight costs), then the arm and pendulum reweighted.
pub fn candidates() -> Vec<MpcWeights> {
    let mut out = Vec::new();
    for arm in [1.0, 4.0, 0.25, 16.0] {
        for pendulum in [1.0, 0.25, 4.0] {
            for input in [0.0, 1.0] {
                for rate in [1.0, 3.0, 0.3, 10.0, 0.1, 30.0] {
                    let w = MpcWeights {
                        arm,
                        pendulum,
                        rate,
                        input,
                    };
                    if w != MpcWeights::SHARED {
                        out.push(w);
                    }
                }
            }
        }
    }
    out
}

/// The first of [`candidates`] with which the MPC of `spec` meets `bar`: its margins first
/// (no simulation), then [`SCREEN`](super::SCREEN) noise seeds, then all of [`SEEDS`](super::SEEDS). `None` when none
/// does.
pub fn search(
    spec: &Spec,
    ts: f64,
    bar: &Bar,
    cancel: &AtomicBool,
) -> Result<Option<(MpcWeights, Spec, Assessment)>, SpecError> {
    first_that_works(
        candidates(),
        |w| w.apply(spec),
        ControllerKind::Mpc,
        ts,
        bar,
        cancel,
    )
}

/// A change to LQR's own keys on top of the shared weights ([`search_lqr`]): an observer of
/// a disturbance at the plant input of bandwidth `disturbance_bandwidth` (Hz, when positive;
/// `Lqr::with_input_disturbance_cancelled`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LqrWeights {
    /// `lqr.disturbance_bandwidth` set (Hz; 0: the paper's LQR without the observer).
    pub disturbance_bandwidth: f64,
}

impl LqrWeights {
    /// No change: the file's LQR.
    pub const SHARED: LqrWeights = LqrWeights {
        disturbance_bandwidth: 0.0,
    };

    /// `spec` with this change to its `[lqr]` keys.
    pub fn apply(&self, spec: &Spec) -> Spec {
        let mut s = spec.clone();
        s.lqr.disturbance_bandwidth = self.disturbance_bandwidth;
        s
    }
}

/// The observer bandwidths (Hz) [`search_lqr`] tries, the widest first. A wider observer
/// cancels the stick-slip cycle better and costs more phase margin, measured with it in the
/// loop (generated rig 13: 41° without it, 36° at 1 Hz, 32° at 2 Hz, 29° at 3 Hz, 25° at
/// 5 Hz), and its first moves after the reference step grow (generated rig 11 reaches its
/// voltage clamp from 2 Hz up). So the grid is fine where both bind: rig 13 meets the bar at
/// 2.5 Hz only, rig 11 at 1.5 Hz only. Those failing the margins are skipped unsimulated.
pub const DISTURBANCE_BANDWIDTHS: [f64; 9] = [5.0, 4.0, 3.0, 2.5, 2.0, 1.5, 1.0, 0.7, 0.5];

/// The first LQR observer ([`DISTURBANCE_BANDWIDTHS`]) with which the LQR of `spec` meets
/// `bar` (margins, then [`SCREEN`](super::SCREEN) seeds, then all of [`SEEDS`](super::SEEDS)).
/// LQG and the MPC do not use it, and keep what they had.
pub fn search_lqr(
    spec: &Spec,
    ts: f64,
    bar: &Bar,
    cancel: &AtomicBool,
) -> Result<Option<(LqrWeights, Spec, Assessment)>, SpecError> {
    first_that_works(
        DISTURBANCE_BANDWIDTHS
            .into_iter()
            .map(|disturbance_bandwidth| LqrWeights {
                disturbance_bandwidth,
            })
            .collect(),
        |w| w.apply(spec),
        ControllerKind::Lqr,
        ts,
        bar,
        cancel,
    )
}

/// A change to LQG's filter on top of the shared weights ([`search_lqg`]): its own filter with
/// an input disturbance it cancels, `kalman.input_disturbance` = `input_disturbance` (when
/// positive; `Design::lqg`), or the shared filter's noise model, `kalman.measurement_noise`
/// times `measurement_noise` and `kalman.disturbance_gain` times `disturbance`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalmanWeights {
    /// Factor on `kalman.measurement_noise`.
    pub measurement_noise: f64,
    /// Factor on `kalman.disturbance_gain`.
    pub disturbance: f64,
    /// `kalman.input_disturbance` set (0: LQG on the shared filter).
    pub input_disturbance: f64,
    /// `kalman.regulate_outputs` set: LQG's law on the estimated outputs (shared filter only).
    pub regulate_outputs: bool,
}

impl KalmanWeights {
    /// No change: the shared filter.
    pub const SHARED: KalmanWeights = KalmanWeights {
        measurement_noise: 1.0,
        disturbance: 1.0,
        input_disturbance: 0.0,
        regulate_outputs: false,
    };

    /// `spec` with this change to its `[kalman]` noise model.
    pub fn apply(&self, spec: &Spec) -> Spec {
        let mut s = spec.clone();
        for v in s.kalman.measurement_noise.iter_mut() {
            *v *= self.measurement_noise;
        }
        s.kalman.disturbance_gain *= self.disturbance;
        s.kalman.input_disturbance = self.input_disturbance;
        s.kalman.regulate_outputs = self.regulate_outputs;
        s
    }
}

/// The input-disturbance variances (V² per period) [`search_lqg`] tries first: LQG's own
/// filter cancelling what the compensation leaves, whose gain grows with the variance.
pub const INPUT_DISTURBANCES: [f64; 3] = [0.1, 0.01, 1.0];

/// The filters [`search_lqg`] tries: an input disturbance cancelled
/// ([`INPUT_DISTURBANCES`]); the shared filter with LQG's law on the estimated outputs
/// (`kalman.regulate_outputs`; the paper's law on the plant part of the estimate drifts with
/// the estimate of eq. (1)'s output disturbance, which the filter cannot tell from a slow arm
/// motion: rip-control's crate docs, "Estimator"); then the shared filter's noise model
/// changed, nearest the shared one first, with the paper's law and then with the law on the
/// outputs. The first two change LQG alone; the rest change the filter the MPC shares too.
pub fn kalman_candidates() -> Vec<KalmanWeights> {
    let mut out: Vec<KalmanWeights> = INPUT_DISTURBANCES
        .into_iter()
        .map(|input_disturbance| KalmanWeights {
            input_disturbance,
            ..KalmanWeights::SHARED
        })
        .collect();
    // The law on the estimated outputs with the shared filter changes LQG alone, so it comes
    // before every change to the filter the MPC shares.
    out.push(KalmanWeights {
        regulate_outputs: true,
        ..KalmanWeights::SHARED
    });
    for regulate_outputs in [false, true] {
        for disturbance in [1.0, 0.3, 3.0, 0.1, 10.0, 0.01, 100.0] {
            for measurement_noise in [1.0, 0.3, 3.0, 0.1, 10.0, 0.03, 0.01, 0.001] {
                let w = KalmanWeights {
                    measurement_noise,
                    disturbance,
                    input_disturbance: 0.0,
                    regulate_outputs,
                };
                if !out.contains(&w) && w != KalmanWeights::SHARED {
                    out.push(w);
                }
            }
        }
    }
    out
}

/// The first of [`kalman_candidates`] with which the LQG of `spec` meets `bar` (margins,
/// then [`SCREEN`](super::SCREEN) seeds, then all of [`SEEDS`](super::SEEDS)). LQR does not use the filter, so it keeps
/// what it had; the MPC does, and is to be assessed again on the filter returned.
pub fn search_lqg(
    spec: &Spec,
    ts: f64,
    bar: &Bar,
    cancel: &AtomicBool,
) -> Result<Option<(KalmanWeights, Spec, Assessment)>, SpecError> {
    first_that_works(
        kalman_candidates(),
        |w| w.apply(spec),
        ControllerKind::Lqg,
        ts,
        bar,
        cancel,
    )
}

/// The first of `candidates` whose spec (`apply`) gives `kind` a loop that meets `bar`;
/// cancelled (`cancel`) between any two candidates.
fn first_that_works<W: Copy>(
    candidates: Vec<W>,
    apply: impl Fn(&W) -> Spec,
    kind: ControllerKind,
    ts: f64,
    bar: &Bar,
    cancel: &AtomicBool,
) -> Result<Option<(W, Spec, Assessment)>, SpecError> {
    for w in candidates {
        check_cancel(cancel)?;
        let candidate = apply(&w);
        let Ok(design) = candidate.design(ts) else {
            continue;
        };
        let Ok(margins) = design.margins(kind) else {
            continue;
        };
        if !bar.margins_ok(kind, &margins) {
            continue;
        }
        let Ok((mut assessed, _)) = screen_then_confirm(&candidate, ts, bar, &[kind]) else {
            continue;
        };
        if let Some(a) = assessed.pop().filter(|a| a.works(bar)) {
            return Ok(Some((w, candidate, a)));
        }
    }
    Ok(None)
}
