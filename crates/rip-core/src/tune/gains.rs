//! The compensation's gains: how much of the identified dead zone and arm friction the
//! compensation applies, chosen with the identification's error in view.
//!
//! The bar asks for a balance with the compensation 30 % off either way and the arm's
//! stiction on ([`super::Bar`], [`super::off_compensation`]). The two errors are not alike:
//!
//! - **Too little** (`0.7 ×`) leaves a dead zone and a friction the loop does not see, and an
//!   unknown breakaway torque on top. The arm sticks while the pendulum leans, breaks free
//!   late and overshoots: a slow limit cycle (periods of 1–3 s, up to 0.3 rad peak-to-peak on
//!   generated rigs 3 and 4 with the gains at 1).
//! - **Too much** (`1.3 ×`) is a relay of the excess inside the loop: a fast chatter the arm's
//!   inertia filters, typically half the slow cycle's amplitude or less.
//!
//! So compensating a little more than identified trades a smaller fast chatter at `1.3 ×`
//! for a much smaller slow cycle at `0.7 ×`:
//!
//! ```text
//! u = w + g_d V_d σ(w / v_s),   w = v + g_f V_f σ(θ̇̂ / ω_s)     (compensation::Compensation)
//! ```
//!
//! with `g_d` = `compensation.dead_zone_gain` and `g_f` = `compensation.friction_gain`
//! multiplying the identified `V_d` and `V_f = C_r R_m / k_t`. Where the weights the search
//! chose leave a controller short of the bar, [`choose`] assesses every pair of
//! [`DEAD_ZONE_GAINS`] × [`FRICTION_GAINS`] whole (the exact compensation, `0.7 ×` and
//! `1.3 ×` the identified values, each times the gains, with the stiction on) and keeps the
//! pair with which most controllers work, the nearest the shortfall summed on a tie. The
//! bar's "exact" compensation is then the identified values times the gains, as on the rig.

use std::sync::atomic::AtomicBool;

use super::settings::check_cancel;
use super::{assess, off_compensation, Bar, Tuned};
use crate::spec::{Spec, SpecError};

/// The dead-zone gains [`choose`] tries.
pub const DEAD_ZONE_GAINS: [f64; 3] = [1.0, 1.2, 1.4];

/// The friction gains [`choose`] tries.
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
fn rank(assessments: &[super::Assessment], bar: &Bar) -> (usize, f64) {
    let failing = assessments.iter().filter(|a| !a.works(bar)).count();
    let shortfall = assessments.iter().map(|a| a.shortfall(bar)).sum();
    (failing, shortfall)
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
            if key < best.0 {
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
