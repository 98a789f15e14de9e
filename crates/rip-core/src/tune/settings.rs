//! The settings of a tuning checked before its search ([`Settings`], the rig's voltage by the
//! pre-flight's own check), how far the search has got ([`Progress`]) and its cancellation.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use crate::preflight::{self, Verdict};
use crate::spec::rig_sections::PERIOD_MS;
use crate::spec::{ControllerKind, Spec, SpecError};

/// Most robustness runs per controller a tuning takes: a fraction from 1000 runs is known to
/// about ±1.6 %, and more would hold a command for many minutes.
pub const MAX_RUNS: usize = 1000;

/// The settings of a tuning besides the rig, checked: the one rule `riprs tune`, its
/// Python function and the bindings share. Each error names the argument (`Ts`, `runs`,
/// `seed`, `spread`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Sample time (s): a loop period `loop.period_ms` allows ([`PERIOD_MS`]).
    pub ts: f64,
    /// Robustness runs per controller, at most [`MAX_RUNS`].
    pub runs: usize,
    /// Seed of the robustness runs.
    pub seed: u64,
    /// Relative spread of each parameter in the robustness runs, in `[0, 1)`.
    pub spread: f64,
}

impl Settings {
    /// Checks the settings as a front end received them: `runs` and `seed` are `None` when
    /// the value is not an integer (or beyond `i128`), and `shown` gives each value as the
    /// caller wrote it, for the message.
    pub fn new(
        ts: f64,
        runs: Option<i128>,
        seed: Option<i128>,
        spread: f64,
        shown: [&str; 2],
    ) -> Result<Self, SpecError> {
        Ok(Self {
            ts: check_ts(ts)?,
            runs: runs
                .and_then(|r| usize::try_from(r).ok())
                .filter(|r| *r <= MAX_RUNS)
                .ok_or_else(|| {
                    SpecError::new(
                        "runs",
                        format!("must be an integer in 0..={MAX_RUNS}, got {}", shown[0]),
                    )
                })?,
            seed: seed.and_then(|s| u64::try_from(s).ok()).ok_or_else(|| {
                SpecError::new(
                    "seed",
                    format!("must be an integer in 0..={}, got {}", u64::MAX, shown[1]),
                )
            })?,
            spread: check_spread(spread)?,
        })
    }
}

/// `ts` when it is a sample time a rig file allows (`loop.period_ms` in [`PERIOD_MS`]): a
/// tuning at 10 µs would simulate for many minutes.
pub fn check_ts(ts: f64) -> Result<f64, SpecError> {
    if PERIOD_MS.contains(&(ts * 1000.0)) {
        Ok(ts)
    } else {
        Err(SpecError::new(
            "Ts",
            format!(
                "must be in {}..={} s (loop.period_ms {}..={} ms), got {ts}",
                PERIOD_MS.start() / 1000.0,
                PERIOD_MS.end() / 1000.0,
                PERIOD_MS.start(),
                PERIOD_MS.end()
            ),
        ))
    }
}

/// `spread` when it is a relative spread [`Perturbation::Relative`](super::Perturbation::Relative) can draw with: in `[0, 1)`.
pub fn check_spread(spread: f64) -> Result<f64, SpecError> {
    if (0.0..1.0).contains(&spread) {
        Ok(spread)
    } else {
        Err(SpecError::new(
            "spread",
            format!("must be in [0, 1), got {spread}"),
        ))
    }
}

/// How far a tuning has got, for a progress bar on another thread: steps of the search
/// done, of the steps known so far (the search adds its second pass's when it begins it).
#[derive(Debug, Default)]
pub struct Progress {
    /// Steps done.
    pub done: AtomicUsize,
    /// Steps in all, as far as known.
    pub total: AtomicUsize,
}

impl Progress {
    pub(super) fn step(&self) {
        self.done.fetch_add(1, Ordering::Relaxed);
    }

    pub(super) fn add(&self, steps: usize) {
        self.total.fetch_add(steps, Ordering::Relaxed);
    }

    pub(super) fn finish(&self) {
        self.done
            .store(self.total.load(Ordering::Relaxed), Ordering::Relaxed);
    }
}

fn cancelled() -> SpecError {
    SpecError::new("", "cancelled before the tuning finished")
}

pub(super) fn check_cancel(cancel: &AtomicBool) -> Result<(), SpecError> {
    if cancel.load(Ordering::Relaxed) {
        Err(cancelled())
    } else {
        Ok(())
    }
}

/// The pre-flight's voltage check ([`preflight::voltage`]) on `spec` at `ts`, as an error
/// when it refuses: no weights can balance such a rig, so [`tune`](super::tune) does not search.
pub fn check_voltage(spec: &Spec, ts: f64) -> Result<(), SpecError> {
    let design = spec.design(ts)?;
    let finding = preflight::voltage(&preflight::Input {
        design: &design,
        controller: ControllerKind::Lqr,
        rig_file: None,
        arm_limit: None,
        swing_up: false,
    });
    match finding {
        Some(f) if f.verdict == Verdict::Refuse => Err(SpecError::new("", f.message)),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::super::{candidates, tune_with};
    use super::*;

    #[test]
    fn settings_out_of_range_are_refused_naming_the_argument() {
        let ok = Settings::new(0.01, Some(20), Some(0), 0.1, ["20", "0"]).unwrap();
        assert_eq!((ok.runs, ok.seed), (20, 0));
        // (Ts, runs, seed, spread, the argument named)
        type Case = (f64, Option<i128>, Option<i128>, f64, &'static str);
        let cases: [Case; 9] = [
            (1e-5, Some(1), Some(0), 0.1, "Ts"),
            (0.5, Some(1), Some(0), 0.1, "Ts"),
            (f64::NAN, Some(1), Some(0), 0.1, "Ts"),
            (0.01, Some(-3), Some(0), 0.1, "runs"),
            (0.01, Some(MAX_RUNS as i128 + 1), Some(0), 0.1, "runs"),
            (0.01, None, Some(0), 0.1, "runs"),
            (0.01, Some(1), Some(-1), 0.1, "seed"),
            (0.01, Some(1), Some(1i128 << 70), 0.1, "seed"),
            (0.01, Some(1), Some(0), f64::NAN, "spread"),
        ];
        for (ts, runs, seed, spread, key) in cases {
            let e = Settings::new(ts, runs, seed, spread, ["r", "s"]).unwrap_err();
            assert_eq!(e.key, key, "{e}");
        }
        for spread in [1.0, -0.1, f64::INFINITY] {
            assert_eq!(check_spread(spread).unwrap_err().key, "spread");
        }
    }

    #[test]
    fn a_rig_beyond_the_voltage_bound_is_refused_before_any_candidate() {
        let spec =
            Spec::parse("[plant]\npreset = \"qube_servo2\"\nkt = 0.004\nkm = 0.004\nRm = 30.0\n")
                .unwrap();
        let progress = Progress::default();
        let e = tune_with(&spec, 0.01, &progress, &AtomicBool::new(false)).unwrap_err();
        assert!(e.to_string().contains("would need"), "{e}");
        assert_eq!(progress.total.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn the_search_counts_its_steps_and_stops_when_cancelled() {
        let spec = Spec::default();
        let progress = Progress::default();
        let t = tune_with(&spec, crate::paper::TS, &progress, &AtomicBool::new(false)).unwrap();
        assert!(t.works && t.refusal().is_none());
        let total = progress.total.load(Ordering::Relaxed);
        assert!(total > candidates(&spec).len());
        assert_eq!(progress.done.load(Ordering::Relaxed), total);
        let cancelled = tune_with(
            &spec,
            crate::paper::TS,
            &Progress::default(),
            &AtomicBool::new(true),
        );
        assert!(cancelled.is_err());
    }
}
