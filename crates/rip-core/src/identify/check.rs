//! What is refused before the fit (bad logs and options) and the verdict after it.

use super::params::get;
use super::*;
use crate::plant::FurutaParams;

pub(super) fn check(logs: &[LogData], o: &IdentifyOptions) -> Result<()> {
    o.start.validate()?;
    if logs.is_empty() {
        return Err(RipError::invalid("logs", "at least one log is needed"));
    }
    let ts = logs[0].ts;
    let mut total = 0usize;
    for (i, log) in logs.iter().enumerate() {
        let name = o
            .names
            .get(i)
            .cloned()
            .unwrap_or_else(|| format!("logs[{i}]"));
        if !(log.ts.is_finite() && log.ts > 0.0) || (log.ts - ts).abs() > 1e-9 * ts {
            return Err(RipError::invalid(
                name,
                format!(
                    "sample time {} s differs from the first log's {ts} s",
                    log.ts
                ),
            ));
        }
        if log.u.len() != log.y.len() {
            return Err(RipError::invalid(
                name,
                format!("{} voltages but {} measurements", log.u.len(), log.y.len()),
            ));
        }
        if let Some(k) = (0..log.u.len())
            .find(|&k| !(log.u[k].is_finite() && log.y[k].iter().all(|v| v.is_finite())))
        {
            return Err(RipError::invalid(
                name,
                format!("sample {k} is not finite (NaN or infinite voltage or angle)"),
            ));
        }
        let train = ((1.0 - o.holdout) * log.u.len() as f64).floor() as usize;
        if train < MIN_SAMPLES {
            return Err(RipError::invalid(
                name,
                format!(
                    "too short: {} samples, {train} for the fit after the held-out part; at \
                     least {MIN_SAMPLES} are needed",
                    log.u.len()
                ),
            ));
        }
        total += log.u.len();
        if total > MAX_SAMPLES {
            return Err(RipError::invalid(
                name,
                format!(
                    "the logs hold {total} samples up to this one, more than the {MAX_SAMPLES} \
                     one identification takes; cut the logs (a few minutes of excitation suffice)"
                ),
            ));
        }
    }
    if !(o.segment.is_finite() && o.segment >= 20.0 * ts) {
        return Err(RipError::invalid(
            "segment",
            format!(
                "must be at least 20 samples of the logs' sample time {ts} s ({} s), got {}{}",
                20.0 * ts,
                o.segment,
                if ts >= 0.5 {
                    "; a sample time this long means the logs' time is not in seconds \
                     (milliseconds?)"
                } else {
                    ""
                }
            ),
        ));
    }
    if !(o.holdout.is_finite() && (0.0..=0.9).contains(&o.holdout)) {
        return Err(RipError::invalid(
            "holdout",
            format!("must be in [0, 0.9], got {}", o.holdout),
        ));
    }
    if o.max_iterations == 0 || o.max_iterations > MAX_ITERATIONS {
        return Err(RipError::invalid(
            "max_iterations",
            format!("must be in 1..={MAX_ITERATIONS}, got {}", o.max_iterations),
        ));
    }
    if let Some(name) = o
        .fixed
        .iter()
        .find(|n| !FREE.iter().any(|p| p.name() == *n))
    {
        return Err(RipError::invalid(
            "fixed",
            format!(
                "{name:?} is not one of the estimated parameters {:?}",
                FREE.map(Param::name)
            ),
        ));
    }
    crate::plant::check_substeps(o.substeps)?;
    if !(o.tolerance.is_finite() && o.tolerance > 0.0) {
        return Err(RipError::invalid(
            "tolerance",
            "must be positive and finite",
        ));
    }
    Ok(())
}

/// The logs' names, comma-separated (`logs[i]` where a name is missing).
pub(super) fn log_names(logs: &[LogData], names: &[String]) -> String {
    (0..logs.len())
        .map(|l| {
            names
                .get(l)
                .cloned()
                .unwrap_or_else(|| format!("logs[{l}]"))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The logs whose held-out fit could not be scored (module docs, "Held-out fit"): none of
/// their outputs moves [`MIN_HELDOUT_MOTION`] over the held-out part, or there is none. Each
/// sentence names the log, what it held out and the recording that would let the check be
/// done.
pub(super) fn not_done(
    logs: &[LogData],
    names: &[String],
    fit: &[[f64; 2]],
    motion: &[[f64; 2]],
    holdout: f64,
) -> Vec<String> {
    let mut out = Vec::new();
    for (l, log) in logs.iter().enumerate() {
        if fit[l].iter().any(|f| !f.is_nan()) {
            continue;
        }
        let name = names
            .get(l)
            .cloned()
            .unwrap_or_else(|| format!("logs[{l}]"));
        let train = ((1.0 - holdout) * log.u.len() as f64).floor() as usize;
        let seconds = (log.u.len() - train) as f64 * log.ts;
        let percent = 100.0 * holdout;
        if holdout == 0.0 || log.u.len() - train < 20 {
            out.push(format!(
                "{name}: held-out fit not done: nothing of the log is held out (holdout \
                 {holdout}); identify with a held-out part (holdout 0.25: the last quarter of \
                 each log)"
            ));
            continue;
        }
        out.push(format!(
            "{name}: held-out fit not done: its held-out part (the last {percent:.0} %, \
             {seconds:.1} s) moves the arm {:.3} rad and the pendulum {:.4} rad (RMS), less \
             than the {MIN_HELDOUT_MOTION} rad a fit is scored on; record it with the \
             excitation running to its end (a chirp or PRBS run, or a free swing that still \
             swings), so that its last {percent:.0} % moves the arm or the pendulum by at \
             least {MIN_HELDOUT_MOTION} rad RMS, or add such a log",
            motion[l][0], motion[l][1]
        ));
    }
    out
}

/// What [`verdict`] judges.
pub(super) struct Verdict<'a> {
    pub(super) logs: &'a [LogData],
    pub(super) names: &'a [String],
    pub(super) start: &'a FurutaParams,
    pub(super) params: &'a FurutaParams,
    pub(super) fit: &'a [[f64; 2]],
    pub(super) rse: &'a [f64; NP],
    pub(super) at_bounds: &'a [&'static str],
    pub(super) at_upper: &'a [bool; NP],
    pub(super) rank: usize,
    /// Relative standard errors of [`LINEAR_ENTRIES`] and the unstable eigenvalue.
    pub(super) linear_rse: &'a [f64; 9],
    pub(super) condition_number: f64,
}

/// The checks of the module docs' "Verdict", each failure a sentence for the user. (The
/// upright eigenvalue is tied to the logs by the pendulum's held-out fit: a model whose
/// pendulum frequency is wrong does not predict a swing.) With them, whether a restart from
/// another start may mend them: not when the only problems are standard errors, which more or
/// other logs mend, not another start.
pub(super) fn verdict(v: &Verdict<'_>) -> (Vec<String>, bool) {
    let mut out = Vec::new();
    let mut uncertain = 0;
    let name = |l: usize| {
        v.names
            .get(l)
            .cloned()
            .unwrap_or_else(|| format!("logs[{l}]"))
    };
    for (l, f) in v.fit.iter().enumerate() {
        for (j, output) in ["theta", "alpha"].iter().enumerate() {
            if f[j] < MIN_FIT_PERCENT {
                out.push(format!(
                    "{}: held-out fit of {output} is {:.1} %, below {MIN_FIT_PERCENT} %: the \
                     model does not predict this log; weigh and measure the rig (a lab file: \
                     mp, Lp, mr, Lr, Rm) so that the fit starts near it",
                    name(l),
                    f[j]
                ));
            }
        }
    }
    if v.rank < NP || v.condition_number.is_nan() || v.condition_number > MAX_CONDITION {
        out.push(format!(
            "the information matrix has rank {}/{NP} and condition number {:.3e} (at most \
             {MAX_CONDITION:.0e}): the logs do not determine the parameters; add a chirp and a \
             PRBS run (motor and arm) and a free swing (pendulum)",
            v.rank, v.condition_number
        ));
    }
    for (k, &param) in FREE.iter().enumerate() {
        let name = param.name();
        if LINEAR.contains(&param) && (v.rse[k].is_nan() || v.rse[k] > MAX_RSE) {
            uncertain += 1;
            out.push(format!(
                "{name} has a relative standard error of {:.1} % (at most {} %): the upright \
                 model is not determined; {}",
                100.0 * v.rse[k],
                100.0 * MAX_RSE,
                if param == Param::Dp || param == Param::Jp {
                    "add a free-swing log (rip-rt excite --signal free-swing)"
                } else {
                    "add a chirp or PRBS run with more amplitude"
                }
            ));
        }
        // A bound on one of these (all of LINEAR but the pendulum's damping) contradicts the
        // start set's measured values.
        let structural = LINEAR[..5].contains(&param);
        if v.at_upper[k] || (structural && v.at_bounds.contains(&name)) {
            out.push(format!(
                "{name} ended on its bound ({:.4e}): the start set is inconsistent with the rig; \
                 {}",
                get(v.params, k),
                match param {
                    Param::Dr => "measure the motor's km (back-EMF) and Rm",
                    Param::Lr | Param::Jr => "measure mr and Lr",
                    Param::Jp => "measure mp and Lp",
                    _ => "measure Rm with a multimeter",
                }
            ));
        }
    }
    let swing = widest_free_swing(v.logs, v.names);
    for (e, entry) in LINEAR_ENTRIES.iter().enumerate() {
        let rse = v.linear_rse[e];
        if rse.is_nan() || rse > MAX_ENTRY_RSE {
            uncertain += 1;
            let advice = match e {
                2 | 6 => match &swing {
                    Some((name, peak, ..)) if *peak > std::f64::consts::PI => format!(
                        "the pendulum's damping is not determined: the free swing {name} goes \
                         over the top (the pendulum turns {peak:.1} rad from hanging); record \
                         one with a smaller --kick or --amplitude that swings to about \
                         {MIN_DAMPING_SWING} rad without going over"
                    ),
                    Some((name, peak, kick, volts)) => format!(
                        "the pendulum's damping is not determined: the free swing {name} (a kick \
                         of {volts:.1} V for {kick:.2} s) peaks at {peak:.2} rad from hanging; \
                         record one that swings wider, to about {MIN_DAMPING_SWING} rad without \
                         going over the top: rip-rt excite --signal free-swing --amplitude \
                         {volts:.1} --kick {:.2} --duration 60 (the swing grows about as the \
                         kick). A longer swing does not help as much: the decay is read against \
                         the encoders' quantum",
                        kick * (MIN_DAMPING_SWING / peak).clamp(1.2, 2.0)
                    ),
                    None => format!(
                        "the pendulum's damping is not determined: add a free swing that swings \
                         to about {MIN_DAMPING_SWING} rad from hanging (rip-rt excite --signal \
                         free-swing --amplitude 6 --kick 0.3 --duration 60)"
                    ),
                },
                1 | 5 => "add a free-swing log (the pendulum's frequency)".to_string(),
                _ => "add a chirp or PRBS run with more amplitude (motor and arm)".to_string(),
            };
            out.push(format!(
                "{entry} of the upright linearisation has a relative standard error of {:.2} % \
                 (at most {} %, so that it is known within {} % at two standard errors): \
                 {advice}",
                100.0 * rse,
                100.0 * MAX_ENTRY_RSE,
                200.0 * MAX_ENTRY_RSE,
            ));
        }
    }
    if v.linear_rse[8].is_nan() || v.linear_rse[8] > MAX_EIGENVALUE_RSE {
        uncertain += 1;
        out.push(format!(
            "the unstable eigenvalue of the upright linearisation has a relative standard error \
             of {:.2} % (at most {} %): weigh and measure the pendulum (lab file: mp, Lp) and \
             add a free swing",
            100.0 * v.linear_rse[8],
            100.0 * MAX_EIGENVALUE_RSE
        ));
    }
    for (what, a, b) in [
        ("mr", v.start.mr, v.params.mr),
        ("mp", v.start.mp, v.params.mp),
        ("Lp", v.start.lp, v.params.lp),
    ] {
        if !(b <= a * MAX_FIXED_CHANGE && b >= a / MAX_FIXED_CHANGE) {
            out.push(format!(
                "{what} had to change from {a:.4} to {b:.4} to fit (more than a factor \
                 {MAX_FIXED_CHANGE}): the start set's masses and lengths are not the rig's; \
                 weigh and measure it (lab file: {what})"
            ));
        }
    }
    let mut drive: Vec<f64> = v
        .logs
        .iter()
        .flat_map(|l| l.u.iter().map(|u| u.abs()))
        .collect();
    if !drive.is_empty() {
        let k = ((drive.len() - 1) as f64 * 0.95) as usize;
        let (_, p95, _) = drive.select_nth_unstable_by(k, f64::total_cmp);
        let p95 = *p95;
        if p95 > 0.0 && v.params.vd > MAX_DEAD_ZONE_FRACTION * p95 {
            out.push(format!(
                "the identified dead zone {:.3} V is more than {} % of the logs' voltage (95th \
                 percentile {p95:.3} V): the motor would barely move; repeat the excitation \
                 with a larger amplitude",
                v.params.vd,
                100.0 * MAX_DEAD_ZONE_FRACTION
            ));
        }
    }
    let restartable = out.len() > uncertain;
    (out, restartable)
}

/// The log with the widest free swing: its name, its peak (rad from hanging, over its coast:
/// the largest deviation of the pendulum angle from its median there, the rest position), and
/// its kick's half length (s) and voltage (from the voltage before the coast); `None` without
/// a coast.
fn widest_free_swing(logs: &[LogData], names: &[String]) -> Option<(String, f64, f64, f64)> {
    let mut best: Option<(String, f64, f64, f64)> = None;
    for (l, log) in logs.iter().enumerate() {
        let end = log.u.len();
        let c = super::coast_start(log, end);
        if c >= end {
            continue;
        }
        let mut alpha: Vec<f64> = log.y[c..].iter().map(|y| y[1]).collect();
        let mid = alpha.len() / 2;
        let (_, rest, _) = alpha.select_nth_unstable_by(mid, f64::total_cmp);
        let rest = *rest;
        let peak = log.y[c..]
            .iter()
            .map(|y| (y[1] - rest).abs())
            .fold(0.0, f64::max);
        let driven = log.u[..c].iter().filter(|u| **u != 0.0).count();
        let kick = 0.5 * driven as f64 * log.ts;
        let volts = log.u[..c].iter().map(|u| u.abs()).fold(0.0, f64::max);
        if best.as_ref().map_or(true, |b| peak > b.1) {
            let name = names
                .get(l)
                .cloned()
                .unwrap_or_else(|| format!("logs[{l}]"));
            best = Some((name, peak, kick, volts));
        }
    }
    best
}
