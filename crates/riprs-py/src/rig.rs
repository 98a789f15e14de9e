//! Binding for `rip_core::rig`: `random_rig(seed)` and the `Rig` it returns, `named_rig(name)`
//! and the `NamedRig` it returns.

use pyo3::prelude::*;
use pyo3::types::PyDict;
use rip_core::rig::{NamedRig, Rig};
use rip_core::spec::{PlantSpec, SensorSpec};

use crate::convert::Count;
use crate::plant::PyFurutaParams;
use rip_core::plant::Param;

/// A rig drawn across the envelope riprs must handle (see :func:`random_rig`).
///
/// Attributes
/// ----------
/// seed : int
///     The seed it was drawn from.
/// params : FurutaParams
///     Physical parameters (``km == kt``, ``g = 9.81``).
/// encoder_counts : tuple of int
///     Counts per revolution of the arm and pendulum encoders.
/// noise_std : tuple of float
///     Standard deviation of the arm and pendulum angle noise (rad).
#[pyclass(name = "Rig", module = "riprs._riprs", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyRig {
    inner: Rig,
}

#[pymethods]
impl PyRig {
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.seed
    }

    #[getter]
    fn params(&self) -> PyFurutaParams {
        PyFurutaParams {
            inner: self.inner.params,
        }
    }

    #[getter]
    fn encoder_counts(&self) -> (u32, u32) {
        let [a, p] = self.inner.encoder_counts;
        (a, p)
    }

    #[getter]
    fn noise_std(&self) -> (f64, f64) {
        let [a, p] = self.inner.noise_std;
        (a, p)
    }

    /// The larger angle noise in encoder counts (what ``rip-rt emulate --noise`` takes).
    fn noise_counts(&self) -> f64 {
        self.inner.noise_counts()
    }

    /// The ``[plant]`` and ``[sensor]`` sections as a mapping ready for a configuration file.
    ///
    /// Returns
    /// -------
    /// dict
    ///     ``{"plant": {"preset": "qube_servo2", "mr": ..., ...}, "sensor": {"encoder_counts":
    ///     [...], "noise_std": [...]}}`` with every plant parameter given.
    fn to_config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        config(py, &self.inner.plant_spec(), &self.inner.sensor_spec())
    }

    /// The ``[plant]`` and ``[sensor]`` sections as TOML text, the file ``rip-rt emulate
    /// --config`` and ``riprs compare --config`` read.
    fn to_toml(&self) -> String {
        self.inner.to_toml()
    }

    fn __repr__(&self) -> String {
        format!("random_rig({})", self.inner.seed)
    }
}

/// Draw a rig across the envelope riprs must handle, reproducibly from a seed.
///
/// The envelope (pendulum 0.015-0.08 kg and 0.08-0.30 m, arm 0.05-0.15 kg and 0.06-0.15 m,
/// centroidal inertias within 50 % of a uniform rod's, Rm 2-10 Ohm, kt = km 0.02-0.08, viscous
/// friction Dr 2e-4-3e-3 and Dp 1e-5-2e-4 N m s (log-uniform), dead zone 0-1 V, Coulomb
/// friction up to 0.006 and 5e-5 N m, encoders 512-8192 counts, noise up to 2 mrad) is the one
/// of ``rip_core::rig``; the same seed gives the same rig.
///
/// Parameters
/// ----------
/// seed : int
///     Non-negative seed.
///
/// Returns
/// -------
/// Rig
///     The rig; :meth:`Rig.to_toml` and :meth:`Rig.to_config` give its configuration.
///
/// Raises
/// ------
/// InvalidParameterError
///     ``seed`` is negative or not below 2**63.
#[pyfunction]
fn random_rig(seed: Count) -> PyResult<PyRig> {
    Ok(PyRig {
        inner: Rig::random(seed.get("seed")? as u64),
    })
}

/// `{"plant": {...}, "sensor": {...}}` of the sections: the preset and the parameters given.
fn config<'py>(
    py: Python<'py>,
    plant_spec: &PlantSpec,
    sensor_spec: &SensorSpec,
) -> PyResult<Bound<'py, PyDict>> {
    let plant = PyDict::new(py);
    plant.set_item("preset", plant_spec.preset.name())?;
    for param in Param::ALL {
        if let Some(v) = plant_spec.get(param) {
            plant.set_item(param.name(), v)?;
        }
    }
    let sensor = PyDict::new(py);
    sensor.set_item("encoder_counts", sensor_spec.encoder_counts.to_vec())?;
    sensor.set_item("noise_std", sensor_spec.noise_std.to_vec())?;
    let d = PyDict::new(py);
    d.set_item("plant", plant)?;
    d.set_item("sensor", sensor)?;
    Ok(d)
}

/// A rig of the tables of docs/tuning.md (see :func:`named_rig`).
///
/// Attributes
/// ----------
/// name : str
///     The name :func:`named_rig` takes.
/// label : str
///     The row label of the docs' tables.
/// params : FurutaParams
///     Physical parameters.
#[pyclass(name = "NamedRig", module = "riprs._riprs", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyNamedRig {
    inner: NamedRig,
}

#[pymethods]
impl PyNamedRig {
    #[getter]
    fn name(&self) -> &'static str {
        self.inner.name()
    }

    #[getter]
    fn label(&self) -> &'static str {
        self.inner.label()
    }

    #[getter]
    fn params(&self) -> PyFurutaParams {
        PyFurutaParams {
            inner: self.inner.params(),
        }
    }

    /// The ``[plant]`` and ``[sensor]`` sections as a mapping ready for a configuration file.
    ///
    /// Returns
    /// -------
    /// dict
    ///     ``{"plant": {"preset": ..., ...}, "sensor": {"encoder_counts": [2048, 2048],
    ///     "noise_std": [0.0005, 0.0005]}}``; the paper rig's plant is ``{"preset": "paper"}``
    ///     alone, every other gives every parameter.
    fn to_config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        config(py, &self.inner.plant_spec(), &self.inner.sensor_spec())
    }

    /// The ``[plant]`` and ``[sensor]`` sections as TOML text.
    fn to_toml(&self) -> String {
        self.inner.to_toml()
    }

    fn __repr__(&self) -> String {
        format!("named_rig({:?})", self.inner.name())
    }
}

/// A rig of the tables of docs/tuning.md, by name: the one definition tests, benches and
/// docs use (``rip_core::rig::NamedRig``), read by the table's sensor (2048-count encoders,
/// 0.5 mrad of noise).
///
/// Parameters
/// ----------
/// name : str
///     One of :func:`named_rigs`: ``"paper"`` (the paper preset), ``"qube_like"``,
///     ``"qube_like_dead_zone"`` (Vd 0.4 V, Cr 0.003 N m), ``"qube_servo3"`` (QUBE-Servo 3
///     values, 0.65 V dead band), ``"heavy"`` (mp 0.06, Lp 0.25, Vd 0.6, Cr 0.006).
///
/// Returns
/// -------
/// NamedRig
///
/// Raises
/// ------
/// ValueError
///     ``name`` is not a named rig.
#[pyfunction]
fn named_rig(name: &str) -> PyResult<PyNamedRig> {
    NamedRig::from_name(name)
        .map(|inner| PyNamedRig { inner })
        .ok_or_else(|| {
            let names: Vec<&str> = NamedRig::ALL.iter().map(|r| r.name()).collect();
            pyo3::exceptions::PyValueError::new_err(format!(
                "name: expected one of {}, got {name:?}",
                names.join(", ")
            ))
        })
}

/// The names :func:`named_rig` takes, in the table's order.
///
/// Returns
/// -------
/// list of str
#[pyfunction]
fn named_rigs() -> Vec<&'static str> {
    NamedRig::ALL.iter().map(|r| r.name()).collect()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRig>()?;
    m.add_function(wrap_pyfunction!(random_rig, m)?)?;
    m.add_class::<PyNamedRig>()?;
    m.add_function(wrap_pyfunction!(named_rig, m)?)?;
    m.add_function(wrap_pyfunction!(named_rigs, m)?)?;
    Ok(())
}
