//! The compensation's gains: how much of the identified dead zone and arm friction the
//! compensation applies, chosen with the identification's error in view.
//!
//! The bar asks for a balance with the compensation 30 % off either way and the arm's
//! stiction on ([`super::Bar`], [`super::off_compensation`]). The two errors are not alike:
//!
//! - **Too little** (`0.7 ×`) leaves a dead zone and a friction the loop does not see, and an
//!   unknown breakaway torque on top. The arm sticks while the pendulum leans, breaks free
//!   late and overshoots: a slow limit cycle (on generated rig 4, tuned with the gains at 1,
//!   the LQR's period is about 2.5 s and its arm peak-to-peak 0.264 rad).
//! - **Too much** (`1.3 ×`) is a relay of the excess inside the loop. On generated rigs 3, 4,
//!   5, 8, 11, 12, 13, 15 and 16 it left the tuned LQR 0.3–0.7 times the arm peak-to-peak of
//!   the `0.7 ×` case.
//!
//! So compensating a little more than identified trades a larger error at `1.3 ×` for a
//! smaller one at `0.7 ×`:
//!
//! ```text
//! u = w + g_d V_d σ(w / v_s),   w = v + g_f V_f σ(θ̇̂ / ω_s)     (compensation::Compensation)
//! ```
//!
//! with `g_d` = `compensation.dead_zone_gain` and `g_f` = `compensation.friction_gain`
//! multiplying the identified `V_d` and `V_f = C_r R_m / k_t`. Where the weights the search
//! chose leave a controller short of the bar, the tuning assesses every pair of
//! [`DEAD_ZONE_GAINS`] × [`FRICTION_GAINS`] whole (the exact compensation, `0.7 ×` and
//! `1.3 ×` the identified values, each times the gains, with the stiction on) and keeps the
//! pair with which most controllers work, the nearest the shortfall summed on a tie, among
//! the pairs with which every controller that worked still works. The
//! bar's "exact" compensation is then the identified values times the gains, as on the rig.

use std::sync::atomic::AtomicBool;

use super::settings::check_cancel;
use super::{assess, off_compensation, Assessment, Bar, Tuned};
use crate::spec::{Spec, SpecError};

/// The dead-zone gains the tuning tries.
pub const DEAD_ZONE_GAINS: [f64; 3] = [1.0, 1.2, 1.4];

/// The friction gains the tuning tries.
pub const FRICTION_GAINS: [f64; 4] = [1.0, 1.3, 1.6, 2.0];

/// `spec` with the compensation's gains `(g_d, g_f)`.
pub fn with_gains(spec: &Spec, gains: (f64, f64)) -> Spec {
    let mut s = spec.clone();
    s.compensation.dead_zone_gain = gains.0;
    s.compensation.friction_gain = gains.1;
    s
}

/// The gains of `spec`'s compensation `(g_d, g_f)`.
pub fn gains(spec: &Spec) -> (f64, f64) {
    (
        spec.compensation.dead_zone_gain,
        spec.compensation.friction_gain,
    )
}

/// `(failing controllers, summed shortfall)` of `tuned`'s assessments against `bar`: the
/// order the search ranks candidates in.
fn rank(assessments: &[Assessment], bar: &Bar) -> (usize, f64) {
    let failing = assessments.iter().filter(|a| !a.works(bar)).count();
    let shortfall = assessments.iter().map(|a| a.shortfall(bar)).sum();
    (failing, shortfall)
}

/// Whether every controller that works in `before` still works in `after`: gains that fix one
/// controller by breaking another trade a warning for another, and the one broken may be the
/// one a lab runs (an over-compensated dead zone shakes the pendulum).
fn keeps_every_working(before: &[Assessment], after: &[Assessment], bar: &Bar) -> bool {
    before
        .iter()
        .filter(|a| a.works(bar))
        .all(|a| after.iter().any(|b| b.kind == a.kind && b.works(bar)))
}

/// Keeps in `tuned` the compensation's gains with which most controllers work (module docs),
/// when `tuned` has a controller short of `bar` and a compensation to scale; returns whether
/// they changed.
pub(crate) fn choose(
    tuned: &mut Tuned,
    ts: f64,
    bar: &Bar,
    cancel: &AtomicBool,
) -> Result<bool, SpecError> {
    if tuned.works || off_compensation(&tuned.spec, 0.0).is_none() {
        return Ok(false);
    }
    let start = gains(&tuned.spec);
    let mut best = (rank(&tuned.assessments, bar), start, None);
    for gd in DEAD_ZONE_GAINS {
        for gf in FRICTION_GAINS {
            if (gd, gf) == start {
                continue;
            }
            check_cancel(cancel)?;
            let candidate = with_gains(&tuned.spec, (gd, gf));
            let Ok(assessments) = assess(&candidate, ts, bar) else {
                continue;
            };
            let key = rank(&assessments, bar);
            if key < best.0 && keeps_every_working(&tuned.assessments, &assessments, bar) {
                best = (key, (gd, gf), Some((candidate, assessments)));
            }
        }
    }
    let Some((spec, assessments)) = best.2 else {
        return Ok(false);
    };
    tuned.spec = spec;
    tuned.works = assessments.iter().all(|a| a.works(bar));
    tuned.assessments = assessments;
    Ok(true)
}
