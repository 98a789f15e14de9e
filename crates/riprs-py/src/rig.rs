//! Binding for `rip_core::rig`: `random_rig(seed)` and the `Rig` it returns.

use pyo3::prelude::*;
use pyo3::types::PyDict;
use rip_core::rig::Rig;

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
        let plant = PyDict::new(py);
        plant.set_item("preset", "qube_servo2")?;
        for param in Param::ALL {
            plant.set_item(param.name(), self.inner.params.get(param))?;
        }
        let sensor = PyDict::new(py);
        sensor.set_item("encoder_counts", self.inner.encoder_counts.to_vec())?;
        sensor.set_item("noise_std", self.inner.noise_std.to_vec())?;
        let d = PyDict::new(py);
        d.set_item("plant", plant)?;
        d.set_item("sensor", sensor)?;
        Ok(d)
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

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRig>()?;
    m.add_function(wrap_pyfunction!(random_rig, m)?)?;
    Ok(())
}
