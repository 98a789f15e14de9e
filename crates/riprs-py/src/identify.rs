//! Binding for `rip_core::identify`: the output-error fit of the nonlinear model to logs.

use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rip_core::identify::header::rig_settings;
use rip_core::identify::lab::Lab;
use rip_core::identify::{identify, IdentifyOptions, LogData, FREE};
use rip_core::RipError;

use crate::convert::{mat_to_py, Count, Real};
use crate::errors::{to_py, IntoPyResult};
use crate::interrupt::interruptible;
use crate::plant::PyFurutaParams;

/// Output-error identification of the nonlinear model (``rip_core::identify``).
///
/// ``logs`` is a list of ``(Ts, u, y)``: sample time (s), voltage (N,) and measured angles
/// ``[theta, alpha]`` (N, 2; alpha continuous, 0 upright). Returns a dict with ``params``
/// (FurutaParams), ``free`` (Python names of the estimated parameters), ``std_errors``,
/// ``fit_percent`` and ``training_fit_percent`` (per log, ``[theta, alpha]``),
/// ``not_identifiable``, ``at_bounds``, ``condition_number``, ``rank``, ``cost``,
/// ``rms_residual``, ``iterations``, ``converged``, ``simulations``, ``starts`` (fits run by
/// the multi-start), ``segments``, ``Ad``,
/// ``Bd``, ``held_out_motion`` (per log, rad), ``covariance`` (9 x 9, of the log of the
/// ``free`` values), ``plant_covariance`` (9 x 9, of the ``free`` plant parameters in SI
/// units), ``values`` (those values: ``Jr``, ``Jp`` as the joint-axis inertias), ``linear_entries``
/// and ``linear_rse`` (relative standard errors of those entries of the continuous upright
/// ``[A B]`` and, last, of its unstable eigenvalue) and ``problems`` (the verdict: why not to trust the result, empty when
/// trusted; ``names`` name the logs in it), ``not_done`` (checks not done, naming the log and
/// the recording that would do them), ``held`` (``(name, value, prior_rse)`` of the start's
/// values held at a preset's, their priors in ``std_errors``) and ``km_tied`` (``km`` held
/// equal to ``kt``). ``fixed`` (Python names of ``free``) are held at the start's values;
/// ``measured`` names the start's held values that were measured (``km`` among them: else
/// ``km = kt``), and ``preset`` is the preset the start is based on (a held value differing
/// from its is measured). Ctrl-C stops it (``KeyboardInterrupt``).
#[pyfunction]
#[pyo3(signature = (logs, start, *, segment=Real(2.0), holdout=Real(0.25), max_iter=Count::of(60), substeps=Count::of(4), names=Vec::new(), fixed=Vec::new(), measured=Vec::new(), preset=None))]
#[pyo3(
    text_signature = "(logs, start, *, segment=2.0, holdout=0.25, max_iter=60, substeps=4, names=[], fixed=[], measured=[], preset=None)"
)]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn identify_logs<'py>(
    py: Python<'py>,
    logs: Vec<(Real, PyReadonlyArray1<'py, f64>, PyReadonlyArray2<'py, f64>)>,
    start: PyFurutaParams,
    segment: Real,
    holdout: Real,
    max_iter: Count,
    substeps: Count,
    names: Vec<String>,
    fixed: Vec<String>,
    measured: Vec<String>,
    preset: Option<PyFurutaParams>,
) -> PyResult<Bound<'py, PyDict>> {
    let mut data = Vec::with_capacity(logs.len());
    for (i, (ts, u, y)) in logs.iter().enumerate() {
        let (u, y) = (u.as_array(), y.as_array());
        if y.ncols() != 2 || y.nrows() != u.len() {
            return Err(to_py(RipError::Shape {
                name: format!("logs[{i}].y"),
                expected: format!("({}, 2)", u.len()),
                rows: y.nrows(),
                cols: y.ncols(),
            }));
        }
        data.push(LogData {
            ts: ts.0,
            u: u.iter().copied().collect(),
            y: y.rows().into_iter().map(|r| [r[0], r[1]]).collect(),
        });
    }
    let options = IdentifyOptions {
        start: start.inner,
        segment: segment.0,
        holdout: holdout.0,
        max_iterations: max_iter.get("max_iter")?,
        substeps: substeps.get("substeps")?,
        names,
        fixed,
        measured,
        preset: preset.map(|p| p.inner),
        ..Default::default()
    };
    let result = interruptible(py, |cancel| identify(&data, &options, cancel), |_| Ok(()))?.py()?;
    let d = PyDict::new(py);
    d.set_item(
        "params",
        PyFurutaParams {
            inner: result.params,
        },
    )?;
    d.set_item("free", FREE.map(|p| p.name()).to_vec())?;
    d.set_item("std_errors", result.std_errors.to_vec())?;
    d.set_item(
        "fit_percent",
        result
            .fit_percent
            .iter()
            .map(|f| f.to_vec())
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "training_fit_percent",
        result
            .training_fit_percent
            .iter()
            .map(|f| f.to_vec())
            .collect::<Vec<_>>(),
    )?;
    d.set_item("not_identifiable", result.not_identifiable.clone())?;
    d.set_item("at_bounds", result.at_bounds.clone())?;
    d.set_item("condition_number", result.condition_number)?;
    d.set_item("rank", result.rank)?;
    d.set_item("cost", result.cost)?;
    d.set_item("rms_residual", result.rms_residual)?;
    d.set_item("iterations", result.iterations)?;
    d.set_item("converged", result.converged)?;
    d.set_item("simulations", result.simulations)?;
    d.set_item("starts", result.starts)?;
    d.set_item("segments", result.segments)?;
    d.set_item("Ad", mat_to_py(py, &result.ad))?;
    d.set_item("Bd", mat_to_py(py, &result.bd))?;
    d.set_item(
        "held_out_motion",
        result
            .held_out_motion
            .iter()
            .map(|f| f.to_vec())
            .collect::<Vec<_>>(),
    )?;
    let n = FREE.len();
    d.set_item(
        "covariance",
        result
            .covariance
            .chunks(n)
            .map(<[f64]>::to_vec)
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "plant_covariance",
        result
            .plant_covariance
            .chunks(n)
            .map(<[f64]>::to_vec)
            .collect::<Vec<_>>(),
    )?;
    d.set_item("problems", result.problems)?;
    d.set_item("not_done", result.not_done)?;
    d.set_item(
        "held",
        result
            .held
            .iter()
            .map(|h| (h.name, h.value, h.prior_rse))
            .collect::<Vec<_>>(),
    )?;
    d.set_item("km_tied", result.km_tied)?;
    d.set_item("values", result.values.to_vec())?;
    d.set_item(
        "linear_entries",
        rip_core::identify::LINEAR_ENTRIES.to_vec(),
    )?;
    d.set_item("linear_rse", result.linear_rse.to_vec())?;
    Ok(d)
}

/// The lab file at ``path`` (``rip_core::identify::lab``): a dict of its measured values
/// (counts as int), only those given. Raises ``ConfigError`` naming the file and the key.
#[pyfunction]
fn read_lab_file<'py>(py: Python<'py>, path: std::path::PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let lab = Lab::load(&path).map_err(|e| crate::spec::ConfigError::new_err(e.to_string()))?;
    let d = PyDict::new(py);
    for (k, v) in lab.values {
        if k.ends_with("_counts") {
            d.set_item(k, v as i64)?;
        } else {
            d.set_item(k, v)?;
        }
    }
    Ok(d)
}

/// The identification's start set: ``start`` with the lab's measured values in place
/// (``rip_core::identify::lab::Lab::start``: a measured link restarts as a uniform rod,
/// ``km = kt`` when only one is given). ``lab`` maps :data:`LAB_KEYS` names to values,
/// checked like a lab file's; raises ``ConfigError`` naming ``lab.KEY``.
#[pyfunction]
fn lab_start(start: PyFurutaParams, lab: Vec<(String, f64)>) -> PyResult<PyFurutaParams> {
    let lab = Lab::from_values(lab.iter().map(|(k, v)| (k.as_str(), *v)))
        .map_err(|e| crate::spec::ConfigError::new_err(e.to_string()))?;
    Ok(PyFurutaParams {
        inner: lab.start(&start.inner),
    })
}

/// The identified rig file's ``[loop]``, ``[sensor]``, ``[device]`` and ``[safety]`` tables
/// (a dict of dicts) of the logs' header settings (``rip_core::identify::header``): ``given``
/// is ``(log, header key, text)`` per setting, the log that recorded it. Checked as the rig
/// file is; raises ``ConfigError`` naming the log and ``header KEY``.
#[pyfunction]
fn header_rig_settings(py: Python<'_>, given: Vec<(String, String, String)>) -> PyResult<PyObject> {
    let table = rig_settings(
        given
            .iter()
            .map(|(log, k, v)| (log.as_str(), k.as_str(), v.as_str())),
    )
    .map_err(|e| crate::spec::ConfigError::new_err(e.to_string()))?;
    crate::spec::from_toml(py, &toml::Value::Table(table))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(header_rig_settings, m)?)?;
    m.add(
        "HEADER_SETTINGS",
        rip_core::identify::header::HEADER_SETTINGS.to_vec(),
    )?;
    m.add_function(wrap_pyfunction!(lab_start, m)?)?;
    m.add_function(wrap_pyfunction!(identify_logs, m)?)?;
    m.add_function(wrap_pyfunction!(read_lab_file, m)?)?;
    m.add("LAB_KEYS", rip_core::identify::lab::LAB_KEYS.to_vec())?;
    m.add("IDENTIFY_MAX_SAMPLES", rip_core::identify::MAX_SAMPLES)?;
    m.add(
        "IDENTIFY_MIN_HELDOUT_MOTION",
        rip_core::identify::MIN_HELDOUT_MOTION,
    )?;
    m.add("IDENTIFY_PRIOR_RSE", rip_core::identify::PRIOR_RSE)?;
    Ok(())
}
