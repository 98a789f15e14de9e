//! The optimisation's values and their map onto [`FurutaParams`] (module docs of
//! [`super`], "Model and parameters").

use super::NP;
use crate::plant::{FurutaParams, Param};

/// The arm's inertia about the motor axis, `J₀` ([`crate::plant::Lumped`]).
pub(super) fn arm_inertia(p: &FurutaParams) -> f64 {
    p.lumped().j0
}

/// The pendulum's inertia about its joint, `Jα` ([`crate::plant::Lumped`]).
pub(super) fn pendulum_inertia(p: &FurutaParams) -> f64 {
    p.lumped().ja
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
/// With `tie_km`, `km = kt` (one motor constant, SI units; module docs).
pub(super) fn with(mut p: FurutaParams, v: &[f64; NP], tie_km: bool) -> FurutaParams {
    let [lr, j0, ja, kt, dr, dp, cr, cp, vd] = *v;
    [p.lr, p.kt, p.dr, p.dp, p.cr, p.cp, p.vd] = [lr, kt, dr, dp, cr, cp, vd];
    if tie_km {
        p.km = kt;
    }
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

/// How the optimisation's values of `p` move with a held parameter at the same dynamics:
/// `∂ log v / ∂ log h` with the lumped quantities (module docs of [`super`]) held up to their
/// common factor. `mp` and `lp` set that factor (`G = mp g lp/2`): `J₀`, `Jα`, `b`, `c`, `dp`,
/// `cr`, `cp` scale with it, `lr = 2 m₁₂/(mp lp)` and `vd` do not; so `kt = b rm` scales, and
/// `dr = c − kt km/rm` as `1 − kt km/(rm dr)` when `km = kt` (`dr = c − b² rm`), else as
/// `c`. `rm` moves `kt = b rm` and, with `km = kt`, `dr` by `−kt²/(rm dr)`. `mr` moves none
/// of them (only the split of `J₀` into `jr`). The prior of a held parameter reaches the
/// estimates' standard errors through these (module docs, "Uncertainty and identifiability").
pub(super) fn held_sensitivity(p: &FurutaParams, held: Param, tie_km: bool) -> [f64; NP] {
    let emf = if tie_km {
        p.kt * p.km / (p.rm * p.dr)
    } else {
        0.0
    };
    match held {
        Param::Mp | Param::Lp => [0.0, 1.0, 1.0, 1.0, 1.0 - emf, 1.0, 1.0, 1.0, 0.0],
        Param::Rm => [0.0, 0.0, 0.0, 1.0, -emf, 0.0, 0.0, 0.0, 0.0],
        // km held at a value: dr = c − b km takes its change.
        Param::Km => {
            let mut s = [0.0; NP];
            s[4] = -p.kt * p.km / (p.rm * p.dr);
            s
        }
        _ => [0.0; NP],
    }
}
