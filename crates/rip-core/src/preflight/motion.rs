//! What a rig file's motions must satisfy before `rip-rt` drives them: every swing-up state
//! and every excitation must leave room for the stop of `safety.arm_limit` (the envelope of
//! `rip-rt`, module docs of [`crate::envelope`]). One definition for `rip-rt`, which refuses a run that
//! fails them, and for `riprs tune`, which writes a file that passes them.
//!
//! # The stop's model of a rig file
//!
//! [`StoppingModel`] on the file's `[plant]`, braked at `safety.voltage_limit` with
//! [`STOP_BRAKE_FRACTION`] of (1), [`LATENCY_PERIODS`] loop periods after the measurement
//! the stop is decided on. The envelope ends [`ENVELOPE_MARGIN`] inside `safety.arm_limit`:
//! a stopping point beyond `L_s = safety.arm_limit − ENVELOPE_MARGIN` stops the run.
//!
//! # The swing-up's reach
//!
//! The swing-up's own envelope lets the arm anywhere within `±L` (`swing_up.arm_limit`) at up
//! to `v(θ) = √(2 a_b (L − θ))` outwards, `a_b = β k_t U_s / (R_m J)` (`β` its
//! `brake_fraction`, `U_s` its `max_voltage`, `J` the arm's largest inertia). A stop decided
//! in any of those states, the swing's full voltage along the motion during the latency,
//! carries the arm at most to
//!
//! ```text
//! R(L) = max_{|θ| ≤ L} θ + D(v(θ), U_s)                                                      (4)
//! ```
//!
//! with `D` of (3). The swing-up passes when `R(L) ≤ L_s`. `R` grows with `L` (a wider swing
//! reaches every state of a narrower one, and faster), so the largest `L` that passes is
//! found by bisection ([`largest_swing_arm_limit`]).
//!
//! # An excitation's clearance
//!
//! An excitation passes when its simulated run on the `[plant]` model
//! ([`crate::envelope::excitation_breach`]) keeps every stopping point within
//! `L_s − PREFLIGHT_HEADROOM · safety.arm_limit`: the rig differs from its model, and an
//! excitation accepted at the edge would be cut short by the envelope's stop. A breach grows
//! with the amplitude; the largest amplitude that passes is found by bisection
//! ([`largest_excitation_amplitude`]).

use crate::error::RipError;
use crate::excitation::{ExcitationSettings, Signal};
use crate::plant::Plant;
use crate::spec::rig_sections::{RigSections, MAX_ARM_LIMIT, MAX_VOLTAGE_LIMIT};
use crate::spec::{Spec, SpecError};

use crate::envelope::{
    envelope_speed, excitation_breach, Breach, StoppingModel, STOP_BRAKE_FRACTION,
};

/// Distance (rad) inside `safety.arm_limit` at which the stop envelope ends, for the rate's
/// quantisation and the arm's travel within the period of the decision.
pub const ENVELOPE_MARGIN: f64 = 0.05;
/// Loop periods between the measurement a stop is decided on and its first braking command
/// (the decision's own period, and the next one, which sends it).
pub const LATENCY_PERIODS: f64 = 2.0;
/// Share of `safety.arm_limit` that an excitation's simulated stopping point keeps clear of
/// the envelope's bound (module docs, "An excitation's clearance").
pub const PREFLIGHT_HEADROOM: f64 = 0.05;
/// Resolution (rad) of the largest swing-up arm limit reported: the value named in a refusal
/// and the one `riprs tune` writes are rounded down to it, so that they pass.
pub const ARM_LIMIT_STEP: f64 = 0.01;
/// Resolution (V) of the largest excitation amplitude reported.
pub const AMPLITUDE_STEP: f64 = 0.01;

/// `x` rounded down to a multiple of `step`, as the decimal a message prints (`k / (1 / step)`
/// is the double nearest `k · step` written in decimal; `k · step` need not be).
fn floor_to(x: f64, step: f64) -> f64 {
    (x / step).floor() / (1.0 / step)
}

/// The control period of the rig's loop (s).
fn period_s(rig: &RigSections) -> f64 {
    rig.loop_.period_ms * 1e-3
}

/// The stop's model of a rig file (module docs).
pub fn stopping_model(spec: &Spec, rig: &RigSections) -> StoppingModel {
    crate::envelope::stopping_model(
        &spec.plant.params(),
        rig.safety.voltage_limit.clamp(0.0, MAX_VOLTAGE_LIMIT),
        STOP_BRAKE_FRACTION,
        LATENCY_PERIODS * period_s(rig),
    )
}

/// The envelope's bound on the stopping point, `L_s = safety.arm_limit − ENVELOPE_MARGIN`.
pub fn envelope_limit(rig: &RigSections) -> f64 {
    rig.safety.arm_limit - ENVELOPE_MARGIN
}

/// `R(L)` of (4): the farthest a stop during a swing-up within `±arm_limit` could carry the
/// arm (rad), with the file's other `[swing_up]` settings.
pub fn swing_stop_reach(spec: &Spec, rig: &RigSections, arm_limit: f64) -> f64 {
    let s = &spec.swing_up;
    let p = spec.plant.params();
    let model = stopping_model(spec, rig);
    let j = p.lumped().arm_axis();
    let a_b = s.brake_fraction * p.kt / p.rm * s.max_voltage / j;
    // With the room `r = L − θ` left to the swing's limit, (4) is `L + max g(r)` over
    // `0 ≤ r ≤ 2L`, `g(r) = D(v(r)) − r`: evaluated on a grid of `r` that does not depend on
    // `L` (and at `r = 2L`), so that `R` grows with `L` exactly, as the bisection needs. The
    // grid's step, π / 400, is far below the envelope's margin.
    let g =
        |room: f64| model.stopping_distance_with(envelope_speed(a_b, room), s.max_voltage) - room;
    let step = std::f64::consts::PI / 400.0;
    let span = 2.0 * arm_limit.max(0.0);
    let steps = (span / step).floor() as usize;
    let worst = (0..=steps)
        .map(|i| g(i as f64 * step))
        .fold(g(span), f64::max);
    arm_limit + worst
}

/// The largest `swing_up.arm_limit` whose reach `R(L)` stays within the envelope's bound, a
/// multiple of [`ARM_LIMIT_STEP`] and at most `π` (the key's own bound); `None` when not even
/// one step does (module docs, "The swing-up's reach").
pub fn largest_swing_arm_limit(spec: &Spec, rig: &RigSections) -> Option<f64> {
    let bound = envelope_limit(rig);
    let passes = |l: f64| swing_stop_reach(spec, rig, l) <= bound;
    let top = std::f64::consts::PI - 1e-9;
    if !passes(ARM_LIMIT_STEP) {
        return None;
    }
    if passes(top) {
        return Some(floor_to(top, ARM_LIMIT_STEP));
    }
    let (mut lo, mut hi) = (ARM_LIMIT_STEP, top);
    while hi - lo > 0.1 * ARM_LIMIT_STEP {
        let mid = 0.5 * (lo + hi);
        if passes(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    // Rounded down, then confirmed: the value reported must pass as written.
    let mut l = floor_to(lo, ARM_LIMIT_STEP);
    while l > ARM_LIMIT_STEP && !passes(l) {
        l = floor_to(l - 0.5 * ARM_LIMIT_STEP, ARM_LIMIT_STEP);
    }
    // The bisection's last interval may straddle a step that passes too.
    loop {
        let next = floor_to(l + 1.5 * ARM_LIMIT_STEP, ARM_LIMIT_STEP);
        if next >= top || !passes(next) {
            break;
        }
        l = next;
    }
    Some(l)
}

/// What the stop makes of a file's swing-up.
enum SwingFit {
    /// It passes as written.
    Passes,
    /// It passes with `swing_up.arm_limit` lowered to the largest value that does.
    Lowered(Box<Spec>),
    /// No `swing_up.arm_limit` passes that the file's other keys allow: what to change.
    Impossible(String),
}

/// The keys that widen what the stop allows, named where the arm limit alone cannot help.
const WIDER_STOP: &str = "lower swing_up.brake_fraction or swing_up.max_voltage, or raise \
                          safety.arm_limit";

/// The file's swing-up against the stop, with its reach `R(L)` at the file's arm limit.
fn fit(spec: &Spec, rig: &RigSections) -> (f64, SwingFit) {
    let reach = swing_stop_reach(spec, rig, spec.swing_up.arm_limit);
    let fitted = if reach <= envelope_limit(rig) {
        SwingFit::Passes
    } else {
        lower(spec, rig)
    };
    (reach, fitted)
}

/// [`fit`] of a swing-up whose own arm limit does not pass.
fn lower(spec: &Spec, rig: &RigSections) -> SwingFit {
    let Some(arm_limit) = largest_swing_arm_limit(spec, rig) else {
        return SwingFit::Impossible(format!("no swing_up.arm_limit passes: {WIDER_STOP}"));
    };
    let mut lowered = spec.clone();
    lowered.swing_up.arm_limit = arm_limit;
    // The catch must still fit inside the lowered limit: the swing-up's own rules decide.
    match lowered.validate() {
        Ok(()) => SwingFit::Lowered(Box::new(lowered)),
        Err(e) => SwingFit::Impossible(format!(
            "at most {arm_limit:.2} rad passes, where {}: {}; {WIDER_STOP}",
            e.key, e.reason
        )),
    }
}

/// Refuses a swing-up whose arm could not be stopped inside `safety.arm_limit` from every
/// state its own envelope lets the arm into (module docs, (4)). The error names
/// `swing_up.arm_limit` and the largest value that passes, or, where none the file allows
/// does, the keys to change. A swing-up left at its default arm limit is refused through
/// `safety.arm_limit` instead (the key such a file narrowed), with the least value that passes
/// (the reach does not depend on it) and the largest `swing_up.arm_limit` as the other way.
pub fn check_swing_up(spec: &Spec, rig: &RigSections) -> Result<(), SpecError> {
    match fit(spec, rig) {
        (_, SwingFit::Passes) => Ok(()),
        (reach, SwingFit::Lowered(lowered)) => {
            Err(refusal(spec, rig, reach, Ok(lowered.swing_up.arm_limit)))
        }
        (reach, SwingFit::Impossible(remedy)) => Err(refusal(spec, rig, reach, Err(remedy))),
    }
}

/// [`check_swing_up`]'s refusal of a swing-up whose stop reaches `reach`, with the largest arm
/// limit that passes or, where none the file allows does, what to change instead.
fn refusal(spec: &Spec, rig: &RigSections, reach: f64, largest: Result<f64, String>) -> SpecError {
    let arm_limit = spec.swing_up.arm_limit;
    let why = format!(
        "a stop during the swing could carry the arm to {reach:.2} rad, past safety.arm_limit \
         ({} rad) less its {ENVELOPE_MARGIN} rad margin, by the stopping model of [plant] \
         (docs/rip-rt.md, \"Stopping\")",
        rig.safety.arm_limit
    );
    if arm_limit == crate::swingup::SwingUpSettings::default().arm_limit {
        let least = (reach + ENVELOPE_MARGIN) / ARM_LIMIT_STEP;
        let least = least.ceil() / (1.0 / ARM_LIMIT_STEP);
        let other = match largest {
            Ok(l) => format!("set swing_up.arm_limit to at most {l:.2} rad"),
            Err(remedy) => remedy,
        };
        let need = if least <= MAX_ARM_LIMIT {
            format!("must be at least {least} rad")
        } else {
            format!("cannot be raised far enough ({least} rad, past its {MAX_ARM_LIMIT} rad)")
        };
        return SpecError::new(
            "safety.arm_limit",
            format!(
                "{need} for a swing-up within swing_up.arm_limit ({arm_limit} rad, its \
                 default), got {}: {why}; or {other}",
                rig.safety.arm_limit
            ),
        );
    }
    let remedy = match largest {
        Ok(l) => format!("at most {l:.2} rad passes (or {WIDER_STOP})"),
        Err(remedy) => remedy,
    };
    SpecError::new(
        "swing_up.arm_limit",
        format!("{arm_limit} rad: {why}; {remedy}"),
    )
}

/// `spec` with `swing_up.arm_limit` lowered, where [`check_swing_up`] refuses it, to the
/// largest value that passes ([`largest_swing_arm_limit`]); unchanged where it passes. What
/// `riprs tune` writes, so that `rip-rt run --swing-up` accepts its file as is.
///
/// # Errors
/// [`check_swing_up`]'s refusal, naming the keys to change, where no arm limit the file's
/// other keys allow passes.
pub fn fit_swing_up(spec: &Spec, rig: &RigSections) -> Result<Spec, SpecError> {
    match fit(spec, rig) {
        (_, SwingFit::Passes) => Ok(spec.clone()),
        (_, SwingFit::Lowered(lowered)) => Ok(*lowered),
        (reach, SwingFit::Impossible(remedy)) => Err(refusal(spec, rig, reach, Err(remedy))),
    }
}

/// The bound an excitation's stopping points must keep within (module docs).
fn excitation_bound(rig: &RigSections) -> f64 {
    envelope_limit(rig) - PREFLIGHT_HEADROOM * rig.safety.arm_limit
}

/// The first breach of an excitation with `settings` at `amplitude` on the file's `[plant]`
/// (module docs, "An excitation's clearance"), `None` when it keeps clear.
fn excitation_breach_at(
    spec: &Spec,
    rig: &RigSections,
    settings: &ExcitationSettings,
    amplitude: f64,
) -> Result<Option<Breach>, RipError> {
    let plant = Plant::new(spec.plant.params())?;
    let s = ExcitationSettings {
        amplitude,
        ..*settings
    };
    excitation_breach(
        s,
        &plant,
        period_s(rig),
        &stopping_model(spec, rig),
        excitation_bound(rig),
        rig.safety.arm_limit,
    )
}

/// The largest amplitude (V) of an excitation with `settings`, at most `settings.amplitude`
/// and a multiple of [`AMPLITUDE_STEP`], that keeps clear of the envelope on the file's
/// `[plant]`; 0 when none does.
pub fn largest_excitation_amplitude(
    spec: &Spec,
    rig: &RigSections,
    settings: &ExcitationSettings,
) -> Result<f64, RipError> {
    if excitation_breach_at(spec, rig, settings, settings.amplitude)?.is_none() {
        return Ok(settings.amplitude);
    }
    largest_below_breach(spec, rig, settings)
}

/// [`largest_excitation_amplitude`] of `settings` whose own amplitude breaches.
fn largest_below_breach(
    spec: &Spec,
    rig: &RigSections,
    settings: &ExcitationSettings,
) -> Result<f64, RipError> {
    let clear = |a: f64| excitation_breach_at(spec, rig, settings, a).map(|b| b.is_none());
    let top = settings.amplitude;
    let (mut lo, mut hi) = (0.0, top);
    while hi - lo > 0.1 * AMPLITUDE_STEP {
        let mid = 0.5 * (lo + hi);
        if clear(mid)? {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let mut a = floor_to(lo, AMPLITUDE_STEP);
    while a > 0.0 && !clear(a)? {
        a = floor_to(a - 0.5 * AMPLITUDE_STEP, AMPLITUDE_STEP);
    }
    loop {
        let next = floor_to(a + 1.5 * AMPLITUDE_STEP, AMPLITUDE_STEP);
        if next >= top || !clear(next)? {
            break;
        }
        a = next;
    }
    Ok(a.max(0.0))
}

/// Refuses an excitation that would come within the headroom of the braking envelope on the
/// file's `[plant]` (module docs): its run would likely be cut short by the envelope's stop.
/// `model` says whose `[plant]` it is in the message (a rig file, or the preset `rip-rt
/// excite` assumes without one). The error names `--amplitude` (and, for free swing,
/// `--kick`) and gives the largest amplitude that passes.
pub fn check_excitation(
    spec: &Spec,
    rig: &RigSections,
    settings: &ExcitationSettings,
    model: &str,
) -> Result<(), SpecError> {
    let rip = |e: RipError| SpecError::new("--amplitude", e.to_string());
    let Some(b) = excitation_breach_at(spec, rig, settings, settings.amplitude).map_err(rip)?
    else {
        return Ok(());
    };
    let largest = largest_below_breach(spec, rig, settings).map_err(rip)?;
    let what = if settings.signal == Signal::FreeSwing {
        format!("{} V with --kick {} s", settings.amplitude, settings.kick)
    } else {
        format!("{} V", settings.amplitude)
    };
    let remedy = if largest > 0.0 {
        format!("at most {largest:.2} V stays inside")
    } else {
        "no amplitude stays inside: raise safety.arm_limit or the arm-centring".to_string()
    };
    let limit = rig.safety.arm_limit;
    Err(SpecError::new(
        "--amplitude",
        format!(
            "{what}: on {model} the arm would reach the braking envelope of safety.arm_limit \
             ({limit} rad, less {PREFLIGHT_HEADROOM} of it as headroom) {:.2} s into the signal \
             (at {:.2} rad and {:.1} rad/s it would stop at {:.2} rad); {remedy}",
            b.t, b.theta, b.rate, b.stop_at
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::rig_sections::parse_file;

    /// Rig files across plants, arm limits, voltages and periods: some whose swing-up passes
    /// as written, some that only a lower `swing_up.arm_limit` lets pass, some none does.
    fn rigs() -> Vec<String> {
        let mut out = Vec::new();
        for preset in ["paper", "qube_servo2"] {
            for (safety_arm, voltage) in [(3.0_f64, 12.0_f64), (2.0, 12.0), (1.7, 6.0), (1.3, 12.0)]
            {
                for (swing_arm, brake, period) in
                    [(1.45, 0.5, 10.0), (1.45, 0.9, 10.0), (1.2, 0.5, 20.0)]
                {
                    if swing_arm >= safety_arm {
                        continue;
                    }
                    let swing_v = voltage.min(10.0);
                    out.push(format!(
                        "[plant]\npreset = \"{preset}\"\n[loop]\nperiod_ms = {period}\n\
                         [safety]\narm_limit = {safety_arm}\nvoltage_limit = {voltage}\n\
                         [swing_up]\narm_limit = {swing_arm}\nbrake_fraction = {brake}\n\
                         max_voltage = {swing_v}\n"
                    ));
                }
            }
        }
        out
    }

    /// "at most X rad passes" in a refusal.
    fn named_limit(message: &str) -> Option<f64> {
        let at = message.find("at most ")? + "at most ".len();
        message[at..].split(" rad").next()?.parse().ok()
    }

    #[test]
    fn the_reach_grows_with_the_arm_limit() {
        for text in rigs() {
            let (spec, rig) = parse_file(&text).unwrap();
            let mut last = f64::NEG_INFINITY;
            for i in 1..=60 {
                let r = swing_stop_reach(&spec, &rig, 0.05 * i as f64);
                assert!(
                    r >= last - 1e-12,
                    "{text}: R({}) = {r} < {last}",
                    0.05 * i as f64
                );
                // A stop never ends inside the swing's own limit's reach of the arm.
                assert!(r >= 0.05 * i as f64, "{text}");
                last = r;
            }
        }
    }

    #[test]
    fn a_refused_swing_up_names_the_largest_arm_limit_that_passes() {
        let (mut refused, mut none) = (0, 0);
        for text in rigs() {
            let (spec, rig) = parse_file(&text).unwrap();
            let largest = largest_swing_arm_limit(&spec, &rig);
            match largest {
                Some(l) => {
                    // The value named passes as written; one step more does not.
                    let mut at = spec.clone();
                    at.swing_up.arm_limit = l;
                    check_swing_up(&at, &rig).unwrap_or_else(|e| panic!("{text}: {l}: {e}"));
                    if l + ARM_LIMIT_STEP < std::f64::consts::PI {
                        at.swing_up.arm_limit = l + ARM_LIMIT_STEP;
                        assert!(check_swing_up(&at, &rig).is_err(), "{text}: {l}");
                    }
                }
                None => {
                    let mut at = spec.clone();
                    at.swing_up.arm_limit = ARM_LIMIT_STEP;
                    assert!(check_swing_up(&at, &rig).is_err(), "{text}");
                }
            }
            match check_swing_up(&spec, &rig) {
                Ok(()) => {
                    assert!(largest.unwrap() >= spec.swing_up.arm_limit, "{text}");
                    assert_eq!(fit_swing_up(&spec, &rig).unwrap(), spec);
                }
                Err(e) => {
                    assert_eq!(e.key, "swing_up.arm_limit");
                    match fit_swing_up(&spec, &rig) {
                        Ok(fitted) => {
                            refused += 1;
                            let l = largest.unwrap();
                            assert!(l < spec.swing_up.arm_limit, "{text}");
                            assert_eq!(named_limit(&e.reason), Some(l), "{e}");
                            assert_eq!(fitted.swing_up.arm_limit, l);
                            check_swing_up(&fitted, &rig).unwrap();
                        }
                        Err(again) => {
                            none += 1;
                            assert_eq!(again, e);
                            assert!(e.reason.contains("raise safety.arm_limit"), "{e}");
                        }
                    }
                }
            }
        }
        // The sweep reaches each kind of file.
        assert!(refused >= 3 && none >= 1, "refused {refused}, none {none}");
    }

    #[test]
    fn a_default_swing_up_is_refused_through_the_safety_limit_the_file_narrowed() {
        let mut refused = 0;
        for preset in ["paper", "qube_servo2"] {
            for i in 0..=30 {
                let limit = 1.55 + 0.05 * f64::from(i);
                let text = |limit: f64| {
                    format!("[plant]\npreset = \"{preset}\"\n[safety]\narm_limit = {limit}\n")
                };
                let (spec, rig) = parse_file(&text(limit)).unwrap();
                let Err(e) = check_swing_up(&spec, &rig) else {
                    continue;
                };
                refused += 1;
                assert_eq!(e.key, "safety.arm_limit", "{e}");
                let least: f64 = e.reason["must be at least ".len()..]
                    .split(' ')
                    .next()
                    .and_then(|n| n.parse().ok())
                    .unwrap_or_else(|| panic!("no least value in {e}"));
                assert!(least > limit, "{e}");
                // The least value passes; a step below it does not.
                let (spec, rig) = parse_file(&text(least)).unwrap();
                check_swing_up(&spec, &rig).unwrap();
                let (spec, rig) = parse_file(&text(least - ARM_LIMIT_STEP)).unwrap();
                assert!(check_swing_up(&spec, &rig).is_err(), "{least}");
                // The other way, a lower swing-up limit, is named with its value.
                let (spec, rig) = parse_file(&text(limit)).unwrap();
                match fit_swing_up(&spec, &rig) {
                    Ok(fitted) => {
                        let other = format!(
                            "or set swing_up.arm_limit to at most {:.2} rad",
                            fitted.swing_up.arm_limit
                        );
                        assert!(e.reason.contains(&other), "{e}");
                    }
                    // Lower than the catch allows: the keys that would widen the stop.
                    Err(_) => assert!(e.reason.ends_with(WIDER_STOP), "{e}"),
                }
            }
        }
        assert!(refused >= 4, "{refused}");
    }

    #[test]
    fn a_refused_excitation_names_the_largest_amplitude_that_passes() {
        let (spec, rig) = parse_file("[plant]\npreset = \"qube_servo2\"\n").unwrap();
        for signal in [Signal::Chirp, Signal::Steps, Signal::FreeSwing] {
            let loud = ExcitationSettings {
                amplitude: 12.0,
                centering: 0.0,
                damping: 0.0,
                kick: 2.0,
                duration: 6.0,
                ..ExcitationSettings::new(signal)
            };
            let a = largest_excitation_amplitude(&spec, &rig, &loud).unwrap();
            assert!(a > 0.0 && a < 12.0, "{signal:?}: {a}");
            let at = |amplitude| ExcitationSettings { amplitude, ..loud };
            check_excitation(&spec, &rig, &at(a), "the preset").unwrap();
            let e = check_excitation(&spec, &rig, &loud, "the preset").unwrap_err();
            assert_eq!(e.key, "--amplitude");
            assert!(e.reason.contains(&format!("at most {a:.2} V")), "{e}");
            assert!(e.reason.contains("on the preset"), "{e}");
            assert!(
                check_excitation(&spec, &rig, &at(a + 2.0 * AMPLITUDE_STEP), "x").is_err(),
                "{signal:?}: {a}"
            );
        }
    }
}
