//! The optimisation's values and their map onto [`FurutaParams`] (module docs of
//! [`super`], "Model and parameters").

use super::NP;
use crate::plant::FurutaParams;

/// The arm's inertia about the motor axis, `J₀ = jr + mr lr²/4 + mp lr²`.
pub(super) fn arm_inertia(p: &FurutaParams) -> f64 {
    p.jr + p.mr * p.lr * p.lr / 4.0 + p.mp * p.lr * p.lr
}

/// The pendulum's inertia about its joint, `Jα = jp + mp lp²/4`.
pub(super) fn pendulum_inertia(p: &FurutaParams) -> f64 {
    p.jp + p.mp * p.lp * p.lp / 4.0
}

/// The values the optimisation works on: [`FREE`] with `jr` replaced by `J₀` and `jp` by `Jα`,
/// on which the dynamics depend (their split into centroidal inertia, mass and length does
/// not matter to them).
pub(super) fn get(p: &FurutaParams, k: usize) -> f64 {
    [
        p.lr,
        arm_inertia(p),
        pendulum_inertia(p),
        p.kt,
        p.dr,
        p.dp,
        p.cr,
        p.cp,
        p.vd,
    ][k]
}

/// The start set with the optimisation's values in place.
///
/// `Jα` is split as `jp = Jα − mp lp²/4` with the start's `mp`, `lp` while that is positive;
/// otherwise the pendulum is taken as a uniform rod with the same `mp lp` (so `G` and `m₁₂`
/// keep their values): `lp = 3 Jα/(mp lp)`, `mp = (mp lp)/lp`, `jp = mp lp²/12`. Then `J₀` is
/// split as `jr = J₀ − mr lr²/4 − mp lr²` with the start's `mr` while that is positive;
/// otherwise the arm is taken as a uniform rod (`mr = 3 (J₀ − mp lr²)/lr²`, `jr = mr lr²/12`).
/// `J₀ ≤ mp lr²` gives an invalid set (no arm can have it), which [`Plant::new`] refuses.
pub(super) fn with(mut p: FurutaParams, v: &[f64; NP]) -> FurutaParams {
    let [lr, j0, ja, kt, dr, dp, cr, cp, vd] = *v;
    [p.lr, p.kt, p.dr, p.dp, p.cr, p.cp, p.vd] = [lr, kt, dr, dp, cr, cp, vd];
    let jp = ja - p.mp * p.lp * p.lp / 4.0;
    if jp > 0.0 {
        p.jp = jp;
    } else {
        let product = p.mp * p.lp;
        p.lp = 3.0 * ja / product;
        p.mp = product / p.lp;
        p.jp = FurutaParams::rod_inertia(p.mp, p.lp);
    }
    let rest = j0 - p.mp * lr * lr;
    let jr = rest - p.mr * lr * lr / 4.0;
    if jr > 0.0 {
        p.jr = jr;
    } else if rest > 0.0 {
        p.mr = 3.0 * rest / (lr * lr);
        p.jr = FurutaParams::rod_inertia(p.mr, lr);
    } else {
        p.jr = -1.0;
    }
    p
}

/// Upper bounds of the optimisation values beyond any bench-top rig (ten times the envelope of
/// shared rigs and more): a fit that reaches one is inconsistent with the rig (the verdict says
/// so), and the stiff friction law of a huge Coulomb term would stall the simulation.
pub(super) const CEILING: [f64; NP] = [1.0, 1.0, 1.0, 10.0, 0.1, 0.01, 0.1, 0.002, 5.0];

/// Initial values of the free parameters: the start set's, or small positive values for those
/// that may be zero and are.
pub(super) fn initial(start: &FurutaParams) -> [f64; NP] {
    let floors = [0.0, 0.0, 0.0, 0.0, 1e-4, 1e-5, 1e-3, 1e-5, 0.1];
    std::array::from_fn(|k| get(start, k).max(floors[k]))
}
