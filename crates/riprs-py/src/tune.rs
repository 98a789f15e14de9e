//! Bindings for `rip_core::{margins, tune, preflight}`: the loop's robustness margins, the
//! per-rig tuning of the shared weights, its robustness runs and the pre-flight check. The
//! Python package (`riprs.tune`) shapes the results into typed objects.

use std::path::PathBuf;
use std::sync::atomic::Ordering;

use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rip_core::margins::Margins;
use rip_core::preflight;
use rip_core::spec::{ControllerKind, SpecError};
use rip_core::tune::{self, Assessment, Bar, Perturbation, Progress, Settings, Weights};

use crate::interrupt::interruptible;
use crate::spec::{ConfigError, PySpec};

fn config_err(e: SpecError) -> PyErr {
    ConfigError::new_err(e.to_string())
}

fn kind(name: &str) -> PyResult<ControllerKind> {
    ControllerKind::from_name(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "controller: expected one of 'LQR', 'LQG', 'MPC', got {name:?}"
        ))
    })
}

fn check_ts(ts: f64) -> PyResult<()> {
    if ts.is_finite() && ts > 0.0 {
        Ok(())
    } else {
        Err(PyValueError::new_err(format!(
            "Ts: must be positive and finite, got {ts}"
        )))
    }
}

fn margins_dict<'py>(py: Python<'py>, m: &Margins) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("stable", m.stable)?;
    d.set_item("gain_margin_db", m.gain_margin_db)?;
    d.set_item("gain_reduction_db", m.gain_reduction_db)?;
    d.set_item("phase_margin_deg", m.phase_margin_deg)?;
    d.set_item("crossover_rad_s", m.crossover_rad_s)?;
    d.set_item("disk_margin", m.disk_margin)?;
    d.set_item("disk_gain_margin_db", m.disk_gain_margin_db)?;
    d.set_item("disk_phase_margin_deg", m.disk_phase_margin_deg)?;
    Ok(d)
}

fn assessment_dict<'py>(
    py: Python<'py>,
    a: &Assessment,
    bar: &Bar,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("controller", a.kind.name())?;
    d.set_item("margins", margins_dict(py, &a.margins)?)?;
    d.set_item("rmse", a.rmse.to_vec())?;
    d.set_item("peak_voltage", a.peak_voltage)?;
    d.set_item("saturated", a.saturated)?;
    d.set_item("fell", a.fell)?;
    d.set_item("arm_peak_to_peak", a.arm_peak_to_peak)?;
    d.set_item("pendulum", a.pendulum)?;
    d.set_item("offset", a.offset)?;
    d.set_item(
        "off_compensation_peak_to_peak",
        a.off_compensation.map(|o| o.arm_peak_to_peak),
    )?;
    d.set_item(
        "off_compensation_fell",
        a.off_compensation.map(|o| o.fell || o.fall_check.0 > 0),
    )?;
    d.set_item("margins_ok", a.margins_ok(bar))?;
    d.set_item("works", a.works(bar))?;
    d.set_item("misses", a.misses(bar))?;
    Ok(d)
}

fn bar_dict<'py>(py: Python<'py>, t: &tune::Tuned) -> PyResult<Bound<'py, PyDict>> {
    let b = &t.bar;
    let d = PyDict::new(py);
    d.set_item("arm_peak_to_peak", b.arm_peak_to_peak)?;
    d.set_item("floor", b.floor)?;
    d.set_item("pendulum", b.pendulum)?;
    d.set_item("offset", b.offset)?;
    d.set_item("gain_margin_db", b.gain_margin_db)?;
    d.set_item("phase_margin_deg", b.phase_margin_deg)?;
    d.set_item("disk_margin", b.disk_margin)?;
    d.set_item("off_compensation", tune::OFF_COMPENSATION)?;
    d.set_item(
        "off_peak_to_peak",
        b.off_limit(rip_core::spec::ControllerKind::Lqr),
    )?;
    d.set_item(
        "off_peak_to_peak_mpc",
        b.off_limit(rip_core::spec::ControllerKind::Mpc),
    )?;
    d.set_item("summary", t.bar_summary())?;
    Ok(d)
}

/// The robustness margins of the loop of ``controller`` (without compensation) at the plant
/// input, on the spec's design model at sample time ``Ts`` (``rip_core::margins``).
#[pyfunction]
#[pyo3(signature = (spec, controller, Ts = rip_core::paper::TS))]
#[allow(non_snake_case)]
fn loop_margins<'py>(
    py: Python<'py>,
    spec: PyRef<'py, PySpec>,
    controller: &str,
    Ts: f64,
) -> PyResult<Bound<'py, PyDict>> {
    check_ts(Ts)?;
    let kind = kind(controller)?;
    let s = spec.inner.clone();
    let m = py
        .allow_threads(|| s.design(Ts).and_then(|d| d.margins(kind)))
        .map_err(config_err)?;
    margins_dict(py, &m)
}

/// ``L(e^{j w Ts})`` of the loop of ``controller`` at the plant input at the frequencies
/// ``w`` (rad/s); ``None`` when the closed loop is unstable.
#[pyfunction]
#[pyo3(signature = (spec, controller, w, Ts = rip_core::paper::TS))]
#[allow(non_snake_case)]
fn loop_response<'py>(
    py: Python<'py>,
    spec: PyRef<'py, PySpec>,
    controller: &str,
    w: PyReadonlyArray1<'py, f64>,
    Ts: f64,
) -> PyResult<Option<Bound<'py, PyArray1<numpy::Complex64>>>> {
    check_ts(Ts)?;
    let kind = kind(controller)?;
    let w = w.as_slice()?.to_vec();
    if !w.iter().all(|v| v.is_finite() && *v > 0.0) {
        return Err(PyValueError::new_err(
            "w: frequencies must be positive and finite",
        ));
    }
    let s = spec.inner.clone();
    let out = py
        .allow_threads(|| -> Result<_, SpecError> {
            let d = s.design(Ts)?;
            let mut c = d.balance(kind)?;
            rip_core::margins::loop_response(c.as_mut(), &d.a, &d.b, &d.c, Ts, &w)
                .map_err(|e| SpecError::new("plant", e.to_string()))
        })
        .map_err(config_err)?;
    Ok(out.map(|v| {
        let v: Vec<numpy::Complex64> = v
            .iter()
            .map(|c| numpy::Complex64::new(c.re, c.im))
            .collect();
        PyArray1::from_vec(py, v)
    }))
}

/// An integer argument as the core's checks take it: `None` for a value that is no integer
/// (a bool, a float: anything without `__index__`) or beyond `i128`, with the value as the
/// caller wrote it. A NumPy integer is one.
fn integer(value: &Bound<'_, PyAny>) -> PyResult<(Option<i128>, String)> {
    let shown = value.repr()?.to_string();
    if value.is_instance_of::<pyo3::types::PyBool>() {
        return Ok((None, shown));
    }
    Ok((value.extract::<i128>().ok(), shown))
}

/// What a tuning checks before its search: the settings (``rip_core::tune::Settings``, a
/// ``ConfigError`` naming the argument: ``Ts``, ``runs``, ``seed``, ``spread``), then the
/// pre-flight's voltage check on the spec's rig (``rip_core::tune::check_voltage``, a
/// ``ConfigError`` giving the voltage it would need).
#[pyfunction]
#[pyo3(signature = (spec, Ts, runs, seed, spread))]
#[allow(non_snake_case)]
fn tune_check(
    py: Python<'_>,
    spec: PyRef<'_, PySpec>,
    Ts: f64,
    runs: &Bound<'_, PyAny>,
    seed: &Bound<'_, PyAny>,
    spread: f64,
) -> PyResult<()> {
    let (runs, runs_shown) = integer(runs)?;
    let (seed, seed_shown) = integer(seed)?;
    Settings::new(Ts, runs, seed, spread, [&runs_shown, &seed_shown]).map_err(config_err)?;
    let s = spec.inner.clone();
    py.allow_threads(|| tune::check_voltage(&s, Ts))
        .map_err(config_err)
}

/// Why the rig file is not trusted by its identification, if it is not
/// (``rip_core::preflight::untrusted_reason``: its header, the identification file or the
/// tuning record beside it).
#[pyfunction]
fn identification_untrusted(rig_file: PathBuf) -> Option<String> {
    preflight::untrusted_reason(&rig_file)
}

/// Chooses shared weights for the spec's rig (``rip_core::tune::tune_with``: a rig the
/// pre-flight's voltage check refuses is a ``ConfigError`` before any search). Returns
/// ``(tuned spec, weights, works, assessments, tried, record, refusal)``: the record the TOML
/// text of ``rip_core::preflight::TuneRecord`` that the pre-flight reads beside the tuned
/// file, followed by the swing-up feasibility verdict's ``[swing_up]`` table
/// (``rip_core::swingup::StoredFeasibility``) that ``rip-rt run --swing-up`` reads and, with
/// ``untrusted`` (why the rig's identification is not trusted), its ``[identification]``
/// verdict; ``refusal`` says why the tuning failed outright (``Tuned::refusal``), or is None;
/// ``shortfalls`` maps each controller short of the bar (``Tuned::shortfalls``) to what it
/// misses; ``bar``
/// is the rig's bar (``rip_core::tune::Bar::for_rig``) with its one-line ``summary``.
/// ``progress(done, total)`` is called as the search advances; Ctrl-C (or an exception from
/// ``progress``) stops it.
#[pyfunction]
#[pyo3(signature = (spec, Ts = rip_core::paper::TS, untrusted = None, progress = None, swing_up = false))]
#[allow(non_snake_case)]
#[allow(clippy::type_complexity)]
fn tune_weights<'py>(
    py: Python<'py>,
    spec: PyRef<'py, PySpec>,
    Ts: f64,
    untrusted: Option<String>,
    progress: Option<Bound<'py, PyAny>>,
    swing_up: bool,
) -> PyResult<(
    PySpec,
    Bound<'py, PyDict>,
    bool,
    Vec<Bound<'py, PyDict>>,
    usize,
    String,
    Option<String>,
    Bound<'py, PyDict>,
    Bound<'py, PyDict>,
    Option<Bound<'py, PyDict>>,
)> {
    tune::check_ts(Ts).map_err(config_err)?;
    let s = spec.inner.clone();
    let steps = Progress::default();
    let mut reported = (0, 0);
    let (t, record, searched) = interruptible(
        py,
        |cancel| {
            let f = tune::tune_file(&s, Ts, swing_up, untrusted.as_deref(), &steps, cancel)?;
            Ok::<_, rip_core::spec::SpecError>((f.tuned, f.record, f.swing_up))
        },
        |_| {
            let now = (
                steps.done.load(Ordering::Relaxed),
                steps.total.load(Ordering::Relaxed),
            );
            if let Some(callback) = progress.as_ref().filter(|_| now != reported) {
                callback.call1(now)?;
                reported = now;
            }
            Ok(())
        },
    )?
    .map_err(config_err)?;
    let refusal = t.refusal();
    let w = PyDict::new(py);
    let Weights {
        arm,
        pendulum,
        input,
        integral_weight,
        measurement_noise,
        recovery,
    } = t.weights;
    w.set_item("arm", arm)?;
    w.set_item("pendulum", pendulum)?;
    w.set_item("input", input)?;
    w.set_item("integral_weight", integral_weight)?;
    w.set_item("measurement_noise", measurement_noise)?;
    w.set_item("recovery", recovery)?;
    let m = t.own.mpc;
    w.set_item("lqr_disturbance_bandwidth", t.own.lqr.disturbance_bandwidth)?;
    w.set_item("lqg_measurement_noise", t.own.kalman.measurement_noise)?;
    w.set_item("lqg_disturbance", t.own.kalman.disturbance)?;
    w.set_item("lqg_input_disturbance", t.own.kalman.input_disturbance)?;
    w.set_item("lqg_regulate_outputs", t.own.kalman.regulate_outputs)?;
    w.set_item("mpc_arm", m.arm)?;
    w.set_item("mpc_pendulum", m.pendulum)?;
    w.set_item("mpc_rate", m.rate)?;
    w.set_item("mpc_input", m.input)?;
    let list = t
        .assessments
        .iter()
        .map(|a| assessment_dict(py, a, &t.bar.guarded()))
        .collect::<PyResult<Vec<_>>>()?;
    let shortfalls = PyDict::new(py);
    for (kind, why) in t.shortfalls() {
        shortfalls.set_item(kind.name(), why)?;
    }
    Ok((
        PySpec {
            inner: t.spec.resolved(),
            rig: spec.rig.clone(),
        },
        w,
        t.works,
        list,
        t.tried,
        record,
        refusal,
        shortfalls,
        bar_dict(py, &t)?,
        searched.map(|f| swing_search_dict(py, &f)).transpose()?,
    ))
}

/// A swing-up search as the Python package reads it (``riprs.SwingUpTuning``).
fn swing_search_dict<'py>(
    py: Python<'py>,
    found: &tune::swing::SwingSearch,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("verdict", found.verdict.name())?;
    d.set_item("tried", found.tried)?;
    d.set_item("summary", found.summary())?;
    let s = &found.settings;
    d.set_item("method", s.method.name())?;
    match &found.plan {
        Some(plan) => {
            let p = PyDict::new(py);
            p.set_item("duration_s", plan.duration_s)?;
            p.set_item("voltage_left", plan.voltage_left)?;
            p.set_item("arm_left", plan.arm_left)?;
            p.set_item("rises", plan.rises)?;
            d.set_item("plan", p)?;
        }
        None => d.set_item("plan", py.None())?,
    }
    let settings = PyDict::new(py);
    settings.set_item("catch_prediction", s.catch_prediction)?;
    settings.set_item("catch_margin", s.catch_margin)?;
    settings.set_item("energy_margin", s.energy_margin)?;
    settings.set_item("rise_damping", s.rise_damping)?;
    settings.set_item("reference_return_rate", s.reference_return_rate)?;
    d.set_item("settings", settings)?;
    let studies = found
        .confirmed
        .iter()
        .map(|m| swing_study_dict(py, m))
        .collect::<PyResult<Vec<_>>>()?;
    d.set_item("confirmed", studies)?;
    Ok(d)
}

/// The swing-up Monte Carlo of ``controller`` on the spec's rig
/// (``rip_core::spec::study::swing_monte_carlo``): ``runs`` draws from ``seed``, each
/// physical parameter within ``1 ± spread``. Ctrl-C stops it.
#[pyfunction]
#[pyo3(signature = (spec, controller, runs = 200, seed = 2024, spread = 0.1, Ts = rip_core::paper::TS))]
#[allow(non_snake_case)]
fn swing_up_monte_carlo<'py>(
    py: Python<'py>,
    spec: PyRef<'py, PySpec>,
    controller: &str,
    runs: u64,
    seed: u64,
    spread: f64,
    Ts: f64,
) -> PyResult<Bound<'py, PyDict>> {
    check_ts(Ts)?;
    let kind = kind(controller)?;
    let study = rip_core::spec::study::SwingStudy {
        runs,
        seed,
        spread,
        horizon: None,
    };
    study.validate().map_err(config_err)?;
    let s = spec.inner.clone();
    let m = interruptible(
        py,
        |cancel| rip_core::spec::study::swing_monte_carlo(&s, kind, Ts, &study, cancel),
        |_| Ok(()),
    )?
    .map_err(config_err)?;
    swing_study_dict(py, &m)
}

/// One controller's swing-up Monte Carlo as the Python package reads it
/// (``riprs.SwingUpStudy``).
fn swing_study_dict<'py>(
    py: Python<'py>,
    m: &rip_core::spec::study::SwingMonteCarlo,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let (lo, hi) = m.success_interval().unwrap_or((f64::NAN, f64::NAN));
    d.set_item("controller", m.controller.name())?;
    d.set_item("runs", m.runs)?;
    d.set_item("excluded", m.excluded)?;
    d.set_item("caught", m.caught)?;
    d.set_item("held", m.held)?;
    d.set_item("step_tracked", m.step_tracked)?;
    d.set_item("caught_on_first", m.caught_on_first)?;
    d.set_item("at_most_two_over_tops", m.at_most_two_over_tops)?;
    d.set_item("most_over_tops", m.most_over_tops)?;
    d.set_item("interval", (lo, hi))?;
    Ok(d)
}

/// For each controller, the fraction of ``runs`` rigs drawn around the spec's on which it
/// balances (``rip_core::tune::robustness``): each parameter within ``1 ± spread``, or
/// log-normal with ``log_covariance`` over the parameters ``names``.
#[pyfunction]
#[pyo3(signature = (spec, runs, seed, Ts = rip_core::paper::TS, spread = 0.1, names = None, log_covariance = None))]
#[allow(non_snake_case)]
#[allow(clippy::too_many_arguments)]
fn tune_robustness(
    py: Python<'_>,
    spec: PyRef<'_, PySpec>,
    runs: usize,
    seed: u64,
    Ts: f64,
    spread: f64,
    names: Option<Vec<String>>,
    log_covariance: Option<PyReadonlyArray2<'_, f64>>,
) -> PyResult<Vec<(String, f64)>> {
    tune::check_ts(Ts).map_err(config_err)?;
    tune::check_spread(spread).map_err(config_err)?;
    let perturbation = match (names, log_covariance) {
        (Some(names), Some(cov)) => {
            let n = names.len();
            let view = cov.as_array();
            let shape = view.shape().to_vec();
            if shape != [n, n] {
                return Err(PyValueError::new_err(format!(
                    "log_covariance: must be {n} x {n} (one row per name), got {shape:?}"
                )));
            }
            Perturbation::LogNormal {
                names,
                log_covariance: view.iter().copied().collect(),
            }
        }
        (None, None) => Perturbation::Relative(spread),
        _ => {
            return Err(PyValueError::new_err(
                "names and log_covariance: give both or neither",
            ))
        }
    };
    let s = spec.inner.clone();
    let out = interruptible(
        py,
        |cancel| tune::robustness_with(&s, Ts, &perturbation, runs, seed, cancel),
        |_| Ok(()),
    )?
    .map_err(config_err)?;
    Ok(out
        .into_iter()
        .map(|(k, f)| (k.name().to_string(), f))
        .collect())
}

/// The pre-flight check of ``controller`` on the spec's rig (``rip_core::preflight``) for a run
/// that starts balanced: ``(check, verdict, message)`` per check that applied. The swing_up
/// check, which only ``rip-rt run --swing-up`` makes, does not apply.
#[pyfunction]
#[pyo3(signature = (spec, controller, Ts = rip_core::paper::TS, rig_file = None, arm_limit = None))]
#[allow(non_snake_case)]
fn preflight_check(
    py: Python<'_>,
    spec: PyRef<'_, PySpec>,
    controller: &str,
    Ts: f64,
    rig_file: Option<PathBuf>,
    arm_limit: Option<f64>,
) -> PyResult<Vec<(String, String, String)>> {
    check_ts(Ts)?;
    let kind = kind(controller)?;
    let s = spec.inner.clone();
    let report = py
        .allow_threads(|| {
            s.design(Ts).map(|design| {
                preflight::run(&preflight::Input {
                    design: &design,
                    controller: kind,
                    rig_file: rig_file.as_deref(),
                    arm_limit,
                    swing_up: false,
                })
            })
        })
        .map_err(config_err)?;
    Ok(report
        .findings
        .into_iter()
        .map(|f| (f.check.to_string(), f.verdict.name().to_string(), f.message))
        .collect())
}

/// The tuning record beside a tuned file (``rip_core::preflight::tune_record_path``):
/// ``tuned.toml`` -> ``tuned.tune.toml``, where ``rip-rt run`` looks for it.
#[pyfunction]
fn tune_record_path(tuned: PathBuf) -> PathBuf {
    preflight::tune_record_path(&tuned)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(loop_margins, m)?)?;
    m.add_function(wrap_pyfunction!(loop_response, m)?)?;
    m.add_function(wrap_pyfunction!(tune_weights, m)?)?;
    m.add_function(wrap_pyfunction!(swing_up_monte_carlo, m)?)?;
    m.add_function(wrap_pyfunction!(tune_robustness, m)?)?;
    m.add_function(wrap_pyfunction!(preflight_check, m)?)?;
    m.add_function(wrap_pyfunction!(tune_record_path, m)?)?;
    m.add_function(wrap_pyfunction!(tune_check, m)?)?;
    m.add_function(wrap_pyfunction!(identification_untrusted, m)?)?;
    Ok(())
}
