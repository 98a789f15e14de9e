//! Bindings for `rip_core::spec`: the experiment file as a typed, read-only object, the one
//! controller assembly, and the one Tab. 1 RMSE. Parsing, defaults, validation and design all
//! happen in the core; this module converts.

use std::path::PathBuf;

use numpy::PyReadonlyArray1;
use pyo3::create_exception;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use rip_core::metrics::table1_rmse_of;
use rip_core::spec::{rig_sections, ControllerKind, Param, Spec, SpecError};

use crate::control::{PyLqg, PyLqr};
use crate::errors::RiprsError;
use crate::mpc::PyMpc;
use crate::plant::{PyFurutaParams, PyPlant};
use crate::shared::Shared;

create_exception!(
    _riprs,
    ConfigError,
    RiprsError,
    "A configuration file, key or value is invalid; the message names the file and the key."
);

fn config_err(e: SpecError) -> PyErr {
    ConfigError::new_err(e.to_string())
}

/// A TOML value as the Python object of the same shape (arrays as lists, tables as dicts).
pub(crate) fn from_toml(py: Python<'_>, value: &toml::Value) -> PyResult<PyObject> {
    Ok(match value {
        toml::Value::Float(v) => v.into_pyobject(py)?.into_any().unbind(),
        toml::Value::Integer(v) => v.into_pyobject(py)?.into_any().unbind(),
        toml::Value::String(v) => v.into_pyobject(py)?.into_any().unbind(),
        toml::Value::Boolean(v) => PyBool::new(py, *v).to_owned().into_any().unbind(),
        toml::Value::Datetime(v) => v.to_string().into_pyobject(py)?.into_any().unbind(),
        toml::Value::Array(items) => {
            let items: PyResult<Vec<PyObject>> = items.iter().map(|v| from_toml(py, v)).collect();
            PyList::new(py, items?)?.into_any().unbind()
        }
        toml::Value::Table(table) => {
            let d = PyDict::new(py);
            for (k, v) in table {
                d.set_item(k, from_toml(py, v)?)?;
            }
            d.into_any().unbind()
        }
    })
}

/// Converts nested Python dicts, lists and scalars into a TOML value; `key` is the key path
/// of `obj`, named by the error of a value no TOML value holds.
pub(crate) fn to_toml(obj: &Bound<'_, PyAny>, key: &str) -> PyResult<toml::Value> {
    if obj.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(obj.extract()?));
    }
    if obj.is_instance_of::<PyInt>() {
        return match obj.extract::<i64>() {
            Ok(v) => Ok(toml::Value::Integer(v)),
            Err(_) => Err(ConfigError::new_err(format!(
                "{key}: the integer {obj} is out of range"
            ))),
        };
    }
    if obj.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(obj.extract()?));
    }
    if obj.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(obj.extract()?));
    }
    if let Ok(d) = obj.downcast::<PyDict>() {
        let mut table = toml::Table::new();
        for (k, v) in d.iter() {
            let name: String = k
                .extract()
                .map_err(|_| ConfigError::new_err(format!("{key}: keys must be strings")))?;
            let path = if key.is_empty() {
                name.clone()
            } else {
                format!("{key}.{name}")
            };
            table.insert(name, to_toml(&v, &path)?);
        }
        return Ok(toml::Value::Table(table));
    }
    if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        let mut out = Vec::new();
        for (i, v) in obj.try_iter()?.enumerate() {
            out.push(to_toml(&v?, &format!("{key}[{i}]"))?);
        }
        return Ok(toml::Value::Array(out));
    }
    if let Ok(v) = obj.extract::<f64>() {
        // numpy scalars and other numbers.
        return Ok(toml::Value::Float(v));
    }
    Err(ConfigError::new_err(format!(
        "{}: cannot be {} in a configuration",
        if key.is_empty() { "configuration" } else { key },
        obj.get_type().name()?
    )))
}

/// `[plant]` (read-only; ``params`` holds every parameter, resolved from the preset).
#[pyclass(name = "PlantSpec", module = "riprs._riprs", frozen, get_all)]
pub struct PyPlantSpec {
    preset: String,
    params: PyFurutaParams,
    arm_breakaway: Option<f64>,
    substeps: usize,
    initial_state: Vec<f64>,
    fall_limit: f64,
}

#[pymethods]
impl PyPlantSpec {
    /// A ``[plant]`` parameter by its key (``spec.plant.Jr``), resolved from the preset.
    fn __getattr__(&self, name: &str) -> PyResult<f64> {
        match rip_core::plant::Param::from_name(name) {
            Some(p) => Ok(self.params.inner.get(p)),
            None => Err(pyo3::exceptions::PyAttributeError::new_err(format!(
                "PlantSpec has no attribute {name:?}"
            ))),
        }
    }
}

/// `[sensor]` (read-only).
#[pyclass(name = "SensorSpec", module = "riprs._riprs", frozen, get_all)]
pub struct PySensorSpec {
    encoder_counts: Vec<u32>,
    noise_std: Vec<f64>,
    encoder_offsets: Vec<f64>,
}

/// `[reference]` (read-only).
#[pyclass(name = "ReferenceSpec", module = "riprs._riprs", frozen, get_all)]
pub struct PyReferenceSpec {
    arm_step: f64,
    step_time: f64,
    duration: f64,
}

/// `[lqr]` (read-only): ``disturbance_bandwidth`` is LQR's own (Hz; 0: no input-disturbance
/// observer).
#[pyclass(name = "LqrSpec", module = "riprs._riprs", frozen, get_all)]
#[allow(non_snake_case)]
pub struct PyLqrSpec {
    Q: Vec<f64>,
    R: f64,
    rate_cutoff: f64,
    integral_weight: f64,
    disturbance_bandwidth: f64,
}

/// `[kalman]` (read-only): ``input_disturbance`` and ``regulate_outputs`` are LQG's own (0 and
/// ``False``: the paper's LQG on the shared filter).
#[pyclass(name = "KalmanSpec", module = "riprs._riprs", frozen, get_all)]
pub struct PyKalmanSpec {
    disturbance_gain: f64,
    measurement_noise: Vec<f64>,
    input_disturbance: f64,
    regulate_outputs: bool,
}

/// `[compensation]` (read-only): ``dead_zone`` and ``arm_friction`` are ``None`` when they
/// follow the ``[plant]``'s ``Vd`` and ``Cr``; ``dead_zone_gain`` and ``friction_gain`` are
/// the multiples of them the compensation applies (``riprs tune`` chooses them).
#[pyclass(name = "CompensationSpec", module = "riprs._riprs", frozen, get_all)]
pub struct PyCompensationSpec {
    enabled: bool,
    dead_zone: Option<f64>,
    arm_friction: Option<f64>,
    voltage_scale: f64,
    velocity_scale: f64,
    dead_zone_gain: f64,
    friction_gain: f64,
}

/// `[mpc]` (read-only): the core's ``MpcSettings`` in its serde form, one attribute per key of
/// the section (the settings type is the section's schema, so the names and values are its).
#[pyclass(name = "MpcSpec", module = "riprs._riprs", frozen)]
pub struct PyMpcSpec {
    table: toml::Table,
}

#[pymethods]
impl PyMpcSpec {
    fn __getattr__(&self, py: Python<'_>, name: &str) -> PyResult<PyObject> {
        match self.table.get(name) {
            Some(value) => from_toml(py, value),
            None => Err(pyo3::exceptions::PyAttributeError::new_err(format!(
                "MpcSpec has no attribute {name:?}; the [mpc] keys are {}",
                self.table.keys().cloned().collect::<Vec<_>>().join(", ")
            ))),
        }
    }

    /// The section's keys.
    fn __dir__(&self) -> Vec<String> {
        self.table.keys().cloned().collect()
    }
}

/// `[monte_carlo]` (read-only).
#[pyclass(name = "MonteCarloSpec", module = "riprs._riprs", frozen, get_all)]
pub struct PyMonteCarloSpec {
    runs: usize,
    perturbation: f64,
    parameters: Vec<String>,
}

/// The experiment file: every setting of ``riprs compare``, ``rip-rt run`` and
/// ``rip-rt emulate``, with the paper's defaults.
///
/// Read a file with :func:`riprs.load_config`; ``Spec()`` is the default. The sections are
/// read-only attributes; :meth:`updated` returns a changed copy, checked like a file.
/// See ``docs/configuration.md`` for every key.
#[pyclass(name = "Spec", module = "riprs._riprs", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PySpec {
    // Always resolved (every plant parameter written out), so equal files compare equal.
    pub(crate) inner: Spec,
    // rip-rt's sections ([loop], [device], [safety], [calibration]) as the file gave them,
    // checked: written back by `to_toml`, so a file riprs writes describes the same rig.
    pub(crate) rig: toml::Table,
}

impl PySpec {
    /// A spec without rip-rt sections (the defaults).
    pub(crate) fn of(spec: Spec) -> Self {
        Self {
            inner: spec.resolved(),
            rig: toml::Table::new(),
        }
    }
}

impl PySpec {
    fn design(&self, py: Python<'_>, ts: f64) -> PyResult<rip_core::spec::Design> {
        let spec = self.inner.clone();
        py.allow_threads(move || spec.design(ts))
            .map_err(config_err)
    }
}

#[pymethods]
impl PySpec {
    #[new]
    fn new() -> Self {
        Self::of(Spec::default())
    }

    /// Parse and check TOML text.
    ///
    /// Parameters
    /// ----------
    /// text : str
    ///     The file's contents.
    ///
    /// Raises
    /// ------
    /// ConfigError
    ///     Unknown key, wrong type or out-of-range value; the message names the key.
    #[staticmethod]
    fn from_toml(text: &str) -> PyResult<Self> {
        let (spec, rig) = rig_sections::parse_file_as_given(text).map_err(config_err)?;
        Ok(Self {
            inner: spec.resolved(),
            rig,
        })
    }

    /// Build from nested dicts as a parsed TOML document would hold them.
    #[staticmethod]
    fn from_dict(data: &Bound<'_, PyDict>) -> PyResult<Self> {
        let toml::Value::Table(table) = to_toml(data.as_any(), "")? else {
            unreachable!("a dict converts to a table")
        };
        Ok(Self::of(Spec::from_table(table).map_err(config_err)?))
    }

    /// A copy with ``changes`` (nested dicts, e.g. ``{"monte_carlo": {"runs": 10}}``)
    /// merged in (``Spec::updated``: a dict changes only the keys it holds, any other value
    /// replaces the old one; a new ``plant.preset`` brings its own parameters) and checked as
    /// in a file.
    ///
    /// Raises
    /// ------
    /// ConfigError
    ///     An unknown key, a value of the wrong type or out of range; the message names the
    ///     key path.
    fn updated(&self, changes: &Bound<'_, PyDict>) -> PyResult<Self> {
        let toml::Value::Table(changes) = to_toml(changes.as_any(), "")? else {
            unreachable!("a dict converts to a table")
        };
        let inner = self.inner.updated(changes).map_err(config_err)?.resolved();
        // The rig sections' relations to the experiment (limits, counts) are checked again.
        rig_sections::resolve(&inner, &self.rig).map_err(config_err)?;
        Ok(Self {
            inner,
            rig: self.rig.clone(),
        })
    }

    /// The resolved configuration as TOML, every default filled in (what ``riprs config``
    /// prints), then rip-rt's sections (``[loop]``, ``[device]``, ``[safety]``,
    /// ``[calibration]``) as the file gave them: the text describes the same rig.
    fn to_toml(&self) -> String {
        rig_sections::file_toml(&self.inner, &self.rig)
    }

    /// The keyword arguments of :func:`riprs.simulate` (and ``simulate_metrics``) for a run
    /// of this file: rip-core's one mapping of ``[plant]``, ``[sensor]`` and ``[reference]``
    /// onto a simulation (``Spec::simulation``), ``duration`` included.
    ///
    /// Parameters
    /// ----------
    /// start : {"up", "down"}
    ///     ``"up"``: at ``plant.initial_state``, the step at ``reference.step_time``;
    ///     ``"down"``: hanging at rest, ``reference.duration + SWING_UP_ALLOWANCE`` long, the
    ///     step ``reference.step_time`` after the catch (as ``rip-rt run --swing-up``).
    /// Ts : float
    ///     Control period (s).
    #[pyo3(signature = (start = "up", Ts = rip_core::paper::TS))]
    #[allow(non_snake_case)]
    fn simulation_options<'py>(
        &self,
        py: Python<'py>,
        start: &str,
        Ts: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        use rip_core::sim::Reference;
        use rip_core::spec::Start;
        let start = match start {
            "up" => Start::Upright,
            "down" => Start::Hanging,
            other => {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "start must be \"up\" or \"down\", got {other:?}"
                )))
            }
        };
        let c = self.inner.simulation(Ts, 0, start);
        let d = PyDict::new(py);
        d.set_item("duration", c.duration)?;
        d.set_item("Ts", c.ts)?;
        d.set_item("substeps", c.substeps)?;
        d.set_item("x0", c.x0.to_vec())?;
        match c.reference {
            Reference::Step { time, value } => {
                d.set_item("reference", value[0])?;
                d.set_item("reference_time", time)?;
            }
            Reference::StepAfterCatch { delay, value } => {
                d.set_item("reference", value[0])?;
                d.set_item("step_after_catch", delay)?;
            }
            Reference::Sequence(_) => unreachable!("a spec's reference is a step"),
        }
        d.set_item(
            "encoder_counts",
            c.sensor.counts_per_rev.map(|v| v.to_vec()),
        )?;
        d.set_item("noise_std", c.sensor.noise_std.to_vec())?;
        d.set_item("encoder_offsets", c.sensor.offsets.to_vec())?;
        d.set_item("u_limit", c.u_limit)?;
        d.set_item("fall_limit", c.fall_limit)?;
        Ok(d)
    }

    /// Check that every controller can be designed at sample time ``Ts`` (s).
    ///
    /// Raises
    /// ------
    /// ConfigError
    ///     Naming the key whose value makes a design fail.
    #[pyo3(signature = (Ts = rip_core::paper::TS))]
    #[allow(non_snake_case)]
    fn check(&self, py: Python<'_>, Ts: f64) -> PyResult<()> {
        py.allow_threads(|| self.inner.check(Ts))
            .map_err(config_err)
    }

    /// A copy whose swing-up ``rip-rt run --swing-up`` accepts: ``swing_up.arm_limit``
    /// lowered, where a stop during the swing could carry the arm past
    /// ``safety.arm_limit``, to the largest value from which it cannot (a multiple of
    /// 0.01 rad); the same spec where it already passes.
    ///
    /// The reach of a stop from every state the swing's envelope allows,
    /// ``R(L) = max_{|θ| ≤ L} θ + D(√(2 a_b (L − θ)), U_s)``, must stay within
    /// ``safety.arm_limit − 0.05`` (``rip_core::preflight::motion``, equation (4); ``D`` is the
    /// stopping distance of equation (3)).
    ///
    /// Returns
    /// -------
    /// Spec
    ///
    /// Raises
    /// ------
    /// ConfigError
    ///     No arm limit the file's other ``[swing_up]`` keys allow passes; the message names
    ///     the keys to change.
    fn with_stoppable_swing_up(&self, py: Python<'_>) -> PyResult<Self> {
        let rig = rig_sections::resolve(&self.inner, &self.rig).map_err(config_err)?;
        let inner = py
            .allow_threads(|| rip_core::preflight::fit_swing_up(&self.inner, &rig))
            .map_err(config_err)?;
        Ok(Self {
            inner,
            rig: self.rig.clone(),
        })
    }

    /// The configured controllers (``controllers``), designed at ``Ts`` by the one assembly
    /// (LQR and LQG share the gain, LQG and MPC share one Kalman design), by name in the
    /// file's order.
    ///
    /// Raises
    /// ------
    /// ConfigError
    ///     Naming the key whose value makes a design fail.
    #[pyo3(signature = (Ts = rip_core::paper::TS))]
    #[allow(non_snake_case)]
    fn build_controllers<'py>(&self, py: Python<'py>, Ts: f64) -> PyResult<Bound<'py, PyDict>> {
        let d = self.design(py, Ts)?;
        let out = PyDict::new(py);
        for &kind in &self.inner.controllers {
            let obj: Bound<'py, PyAny> = match kind {
                ControllerKind::Lqr => {
                    let c = py.allow_threads(|| d.lqr()).map_err(config_err)?;
                    Bound::new(py, PyLqr::from_core(c, d.compensation().copied()))?.into_any()
                }
                ControllerKind::Lqg => {
                    let c = py.allow_threads(|| d.lqg()).map_err(config_err)?;
                    Bound::new(py, PyLqg::from_core(c, d.compensation().copied()))?.into_any()
                }
                ControllerKind::Mpc => {
                    let c = py.allow_threads(|| d.mpc()).map_err(config_err)?;
                    let inner = Shared::new(c);
                    let compensation = d.compensation().copied();
                    Bound::new(
                        py,
                        PyMpc {
                            inner,
                            compensation,
                        },
                    )?
                    .into_any()
                }
            };
            out.set_item(kind.name(), obj)?;
        }
        Ok(out)
    }

    /// The nonlinear plant of ``[plant]``.
    fn build_plant(&self) -> PyResult<PyPlant> {
        Ok(PyPlant {
            inner: self.inner.plant().map_err(config_err)?,
        })
    }

    /// The controllers ``riprs compare`` runs (``"LQR"``, ``"LQG"``, ``"MPC"``).
    #[getter]
    fn controllers(&self) -> Vec<&'static str> {
        self.inner.controllers.iter().map(|k| k.name()).collect()
    }

    /// ``[plant]``.
    #[getter]
    fn plant(&self) -> PyPlantSpec {
        let p = &self.inner.plant;
        PyPlantSpec {
            preset: p.preset.name().into(),
            params: PyFurutaParams { inner: p.params() },
            arm_breakaway: p.arm_breakaway,
            substeps: p.substeps,
            initial_state: p.initial_state.to_vec(),
            fall_limit: p.fall_limit,
        }
    }

    /// The physical parameters of ``[plant]``.
    #[getter]
    fn params(&self) -> PyFurutaParams {
        PyFurutaParams {
            inner: self.inner.plant.params(),
        }
    }

    /// ``[sensor]``.
    #[getter]
    fn sensor(&self) -> PySensorSpec {
        let s = &self.inner.sensor;
        PySensorSpec {
            encoder_counts: s.encoder_counts.to_vec(),
            noise_std: s.noise_std.to_vec(),
            encoder_offsets: s.encoder_offsets.to_vec(),
        }
    }

    /// ``[reference]``.
    #[getter]
    fn reference(&self) -> PyReferenceSpec {
        let r = &self.inner.reference;
        PyReferenceSpec {
            arm_step: r.arm_step,
            step_time: r.step_time,
            duration: r.duration,
        }
    }

    /// ``[lqr]``.
    #[getter]
    fn lqr(&self) -> PyLqrSpec {
        let l = &self.inner.lqr;
        PyLqrSpec {
            Q: l.Q.to_vec(),
            R: l.R,
            rate_cutoff: l.rate_cutoff,
            integral_weight: l.integral_weight,
            disturbance_bandwidth: l.disturbance_bandwidth,
        }
    }

    /// ``[kalman]``.
    #[getter]
    fn kalman(&self) -> PyKalmanSpec {
        let k = &self.inner.kalman;
        PyKalmanSpec {
            disturbance_gain: k.disturbance_gain,
            measurement_noise: k.measurement_noise.to_vec(),
            input_disturbance: k.input_disturbance,
            regulate_outputs: k.regulate_outputs,
        }
    }

    /// ``[compensation]``.
    #[getter]
    fn compensation(&self) -> PyCompensationSpec {
        let c = &self.inner.compensation;
        PyCompensationSpec {
            enabled: c.enabled,
            dead_zone: c.dead_zone,
            arm_friction: c.arm_friction,
            voltage_scale: c.voltage_scale,
            velocity_scale: c.velocity_scale,
            dead_zone_gain: c.dead_zone_gain,
            friction_gain: c.friction_gain,
        }
    }

    /// ``[mpc]``.
    #[getter]
    fn mpc(&self) -> PyMpcSpec {
        let Ok(toml::Value::Table(table)) = toml::Value::try_from(&self.inner.mpc) else {
            unreachable!("the MPC settings serialise to a table")
        };
        PyMpcSpec { table }
    }

    /// ``[monte_carlo]``.
    #[getter]
    fn monte_carlo(&self) -> PyMonteCarloSpec {
        let m = &self.inner.monte_carlo;
        PyMonteCarloSpec {
            runs: m.runs,
            perturbation: m.perturbation,
            parameters: m.parameters.iter().map(|p| p.name().into()).collect(),
        }
    }

    /// ``[swing_up]`` as a dict of every setting (the keywords of :class:`riprs.SwingUp`).
    #[getter]
    fn swing_up<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        crate::swingup::settings_dict(py, &self.inner.swing_up)
    }

    fn __repr__(&self) -> String {
        format!("Spec.from_toml('''\n{}''')", self.inner.to_toml())
    }
}

/// Read, parse and check a configuration file, including that every controller can be
/// designed at the paper's sample time.
///
/// Parameters
/// ----------
/// path : str or os.PathLike
///     The TOML file. ``[loop]``, ``[device]``, ``[safety]`` and ``[calibration]`` belong to
///     ``rip-rt``; they are checked here with the same function as ``rip-rt config`` runs.
///
/// Returns
/// -------
/// Spec
///
/// Raises
/// ------
/// ConfigError
///     Unreadable file, TOML syntax, unknown key, wrong type, out-of-range value, or values
///     that fail together in a design; the message names the file and the key.
#[pyfunction]
fn load_config(py: Python<'_>, path: PathBuf) -> PyResult<PySpec> {
    let (spec, rig) = py
        .allow_threads(|| {
            let (spec, rig) = rig_sections::load_file_as_given(&path)?;
            spec.check(rip_core::paper::TS)
                .map_err(|e| e.in_file(&path))?;
            Ok::<_, rip_core::spec::SpecError>((spec, rig))
        })
        .map_err(config_err)?;
    Ok(PySpec {
        inner: spec.resolved(),
        rig,
    })
}

/// The paper's Tab. 1 indices ``(arm, pendulum, voltage)`` of recorded signals: RMSE of the
/// measured arm angle against its reference, RMS of the measured pendulum angle and of the
/// voltage, over every sample (samples with NaN left out). The same definition as
/// ``SimResult.rmse`` (``rip_core::metrics::table1_rmse``).
#[pyfunction]
fn table1_rmse(
    arm: PyReadonlyArray1<'_, f64>,
    pendulum: PyReadonlyArray1<'_, f64>,
    voltage: PyReadonlyArray1<'_, f64>,
    arm_reference: PyReadonlyArray1<'_, f64>,
) -> PyResult<(f64, f64, f64)> {
    let (a, p, u, r) = (
        arm.as_slice()?,
        pendulum.as_slice()?,
        voltage.as_slice()?,
        arm_reference.as_slice()?,
    );
    if p.len() != a.len() || u.len() != a.len() || r.len() != a.len() {
        return Err(PyTypeError::new_err(format!(
            "arm, pendulum, voltage and arm_reference must have equal lengths, got {}, {}, {}, {}",
            a.len(),
            p.len(),
            u.len(),
            r.len()
        )));
    }
    let [x, y, z] = table1_rmse_of(a, p, u, r);
    Ok((x, y, z))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add(
        "PRESETS",
        rip_core::spec::Preset::ALL.map(|p| p.name()).to_vec(),
    )?;
    m.add("PARAMETERS", Param::ALL.map(|p| p.name()).to_vec())?;
    m.add("TS", rip_core::paper::TS)?;
    m.add_class::<PySpec>()?;
    m.add_class::<PyPlantSpec>()?;
    m.add_class::<PySensorSpec>()?;
    m.add_class::<PyReferenceSpec>()?;
    m.add_class::<PyLqrSpec>()?;
    m.add_class::<PyKalmanSpec>()?;
    m.add_class::<PyMpcSpec>()?;
    m.add_class::<PyCompensationSpec>()?;
    m.add_class::<PyMonteCarloSpec>()?;
    m.add_function(wrap_pyfunction!(load_config, m)?)?;
    m.add_function(wrap_pyfunction!(table1_rmse, m)?)?;
    Ok(())
}
