//! Bindings for `rip_core::sim::vec_env`: the native vectorised environment behind
//! `riprs.envs`, the observer a trained policy runs on, and the replay of a log. Only
//! conversion: the Python wrappers (`riprs.envs`) own the Gymnasium API, this module fills
//! their numpy buffers in place with the GIL released.

use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1, PyReadwriteArray1, PyReadwriteArray2};
use pyo3::exceptions::{PyKeyError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyInt};
use rip_core::sim::vec_env::{
    replay, EnvConfig, Observer, ParamCovariance, Randomisation, Task, VecEnv, MAX_DELAY,
    MAX_OBS_RATE, OBS_DIM,
};
use rip_core::spec::Param;

use crate::convert::{matrix_arg, pair_arg, vector_arg, Count, Real};
use crate::errors::IntoPyResult;
use crate::plant::{PyFurutaParams, PyPlant};
use crate::shared::Shared;
use crate::spec::PySpec;

fn opt<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Option<Bound<'py, PyAny>>> {
    Ok(d.get_item(key)?.filter(|v| !v.is_none()))
}

fn real(v: &Bound<'_, PyAny>, key: &str) -> PyResult<f64> {
    v.extract::<Real>()
        .map(|r| r.0)
        .map_err(|e| PyTypeError::new_err(format!("{key}: {e}")))
}

fn count(v: &Bound<'_, PyAny>, key: &str) -> PyResult<u64> {
    v.extract::<Count>()
        .map_err(|e| PyTypeError::new_err(format!("{key}: {e}")))?
        .get_u64(key)
}

fn param_named(name: &str, key: &str) -> PyResult<Param> {
    Param::from_name(name).ok_or_else(|| {
        PyKeyError::new_err(format!(
            "{key}: unknown parameter {name:?}; expected one of {}",
            Param::ALL.map(|p| p.name()).join(", ")
        ))
    })
}

fn delay_range(v: &Bound<'_, PyAny>, key: &str) -> PyResult<[usize; 2]> {
    let (lo, hi): (Bound<'_, PyAny>, Bound<'_, PyAny>) = v
        .extract()
        .map_err(|_| PyTypeError::new_err(format!("{key} must be a pair (lo, hi) of periods")))?;
    let bound = |b: &Bound<'_, PyAny>| -> PyResult<usize> {
        Ok(usize::try_from(count(b, key)?).unwrap_or(usize::MAX))
    };
    Ok([bound(&lo)?, bound(&hi)?])
}

fn randomisation(d: &Bound<'_, PyDict>) -> PyResult<Randomisation> {
    let mut r = Randomisation::default();
    for (key, value) in d.iter() {
        let key: String = key.extract()?;
        let full = format!("randomize.{key}");
        match key.as_str() {
            "relative" => {
                let rel = value.downcast::<PyDict>().map_err(|_| {
                    PyTypeError::new_err(
                        "randomize.relative must be a dict {parameter: half-width}",
                    )
                })?;
                for (name, half) in rel.iter() {
                    let name: String = name.extract()?;
                    let p = param_named(&name, &full)?;
                    r.relative
                        .push((p, real(&half, &format!("{full}.{name}"))?));
                }
            }
            "covariance" => {
                let (names, matrix): (Vec<String>, Bound<'_, PyAny>) =
                    value.extract().map_err(|_| {
                        PyTypeError::new_err(
                            "randomize.covariance must be (parameter names, matrix)",
                        )
                    })?;
                let params = names
                    .iter()
                    .map(|n| param_named(n, &full))
                    .collect::<PyResult<Vec<_>>>()?;
                let n = params.len();
                let m = matrix_arg(&matrix, "randomize.covariance", Some(n), Some(n))?;
                r.covariance = Some(ParamCovariance {
                    params,
                    matrix: (0..n * n).map(|k| m[(k / n, k % n)]).collect(),
                });
            }
            "Vd" => r.dead_zone = Some(pair_arg(&value, &full)?),
            "Cr" => r.arm_friction = Some(pair_arg(&value, &full)?),
            "Cp" => r.pendulum_friction = Some(pair_arg(&value, &full)?),
            "noise_std" => r.noise_std = Some(pair_arg(&value, &full)?),
            "action_delay" => r.action_delay = Some(delay_range(&value, &full)?),
            _ => {
                return Err(PyKeyError::new_err(format!(
                    "unknown randomize key {key:?}; expected relative, covariance, Vd, Cr, Cp, \
                     noise_std or action_delay"
                )))
            }
        }
    }
    Ok(r)
}

/// The core configuration: the spec's environment at period `Ts`, then the given overrides.
fn env_config(spec: &PySpec, task: &str, d: &Bound<'_, PyDict>) -> PyResult<EnvConfig> {
    let task = match task {
        "balance" => Task::Balance,
        "swing_up" => Task::SwingUp,
        other => {
            return Err(PyKeyError::new_err(format!(
                "task must be 'balance' or 'swing_up', got {other:?}"
            )))
        }
    };
    let ts = match opt(d, "Ts")? {
        Some(v) => real(&v, "Ts")?,
        None => rip_core::paper::TS,
    };
    let mut c = EnvConfig::from_spec(&spec.inner, task, ts);
    for (key, value) in d.iter() {
        let key: String = key.extract()?;
        if value.is_none() {
            continue;
        }
        match key.as_str() {
            "Ts" => {}
            "params" => {
                c.params = value
                    .extract::<PyFurutaParams>()
                    .map_err(|_| PyTypeError::new_err("params must be a riprs.FurutaParams"))?
                    .inner
            }
            "substeps" => c.substeps = usize::try_from(count(&value, &key)?).unwrap_or(usize::MAX),
            "u_limit" => c.u_limit = real(&value, &key)?,
            "encoder_counts" => c.sensor.counts_per_rev = Some(pair_arg(&value, &key)?),
            "exact_angles" => {
                if value.is_truthy()? {
                    c.sensor.counts_per_rev = None;
                }
            }
            "noise_std" => c.sensor.noise_std = pair_arg(&value, &key)?,
            "encoder_offsets" => c.sensor.offsets = pair_arg(&value, &key)?,
            "rate_cutoff" => c.rate_cutoff_hz = real(&value, &key)?,
            "max_episode_steps" => {
                let steps = count(&value, &key)?;
                c.max_steps = u32::try_from(steps).map_err(|_| {
                    crate::errors::to_py(rip_core::RipError::invalid(
                        "max_episode_steps",
                        format!("must be at most {}, got {steps}", u32::MAX),
                    ))
                })?
            }
            "fall_limit" => c.fall_limit = real(&value, &key)?,
            "arm_limit" => c.arm_limit = real(&value, &key)?,
            "action_delay" | "observation_latency" => {
                let v = usize::try_from(count(&value, &key)?).unwrap_or(usize::MAX);
                if key == "action_delay" {
                    c.action_delay = v;
                } else {
                    c.observation_latency = v;
                }
            }
            "init_spread" => c.init_spread = real(&value, &key)?,
            "action_cost" => c.action_cost = real(&value, &key)?,
            "randomize" => {
                let r = value.downcast::<PyDict>().map_err(|_| {
                    PyTypeError::new_err("randomize must be a dict (see riprs.envs)")
                })?;
                c.randomisation = randomisation(r)?;
            }
            _ => {
                return Err(PyTypeError::new_err(format!(
                    "unknown environment setting {key:?}"
                )))
            }
        }
    }
    Ok(c)
}

/// `N` pendulum environments stepped in one native call (``rip_core::sim::vec_env``).
///
/// Thread-safe: the class is `frozen` with its environments in a [`Shared`] mutex, so calls
/// from several Python threads queue and each runs whole (a step releases the GIL while it
/// integrates; with PyO3's borrow flag a second thread's call would fail "Already borrowed").
/// The buffers passed to `reset` and `step` are the caller's to guard (`riprs.envs` does).
#[pyclass(name = "NativeVecEnv", module = "riprs._riprs", frozen)]
pub struct PyVecEnv {
    inner: Shared<VecEnv>,
}

impl PyVecEnv {
    fn wrap(inner: VecEnv) -> Self {
        Self {
            inner: Shared::new(inner),
        }
    }
}

#[pymethods]
impl PyVecEnv {
    #[new]
    fn new(
        num_envs: &Bound<'_, PyAny>,
        spec: PyRef<'_, PySpec>,
        task: &str,
        settings: &Bound<'_, PyDict>,
    ) -> PyResult<Self> {
        let n = usize::try_from(count(num_envs, "num_envs")?).unwrap_or(usize::MAX);
        let config = env_config(&spec, task, settings)?;
        Ok(Self::wrap(VecEnv::new(config, n).py()?))
    }

    /// The environment that ``state`` (``__reduce__``'s bytes) describes.
    #[staticmethod]
    fn _from_state(state: &[u8]) -> PyResult<Self> {
        Ok(Self::wrap(VecEnv::from_bytes(state).py()?))
    }

    /// Pickles as the whole native state: the unpickled environment continues exactly as
    /// this one would.
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyBytes>,))> {
        let bytes = slf.get().inner.lock(py).to_bytes();
        let rebuild = slf.get_type().getattr("_from_state")?;
        Ok((rebuild, (PyBytes::new(py, &bytes),)))
    }

    /// An independent copy: nothing mutable is shared.
    fn __copy__(&self, py: Python<'_>) -> Self {
        Self::wrap(self.inner.lock(py).clone())
    }

    /// An independent copy (as ``__copy__``: the object holds no Python references).
    fn __deepcopy__(&self, py: Python<'_>, _memo: &Bound<'_, PyAny>) -> Self {
        self.__copy__(py)
    }

    /// Number of environments.
    #[getter]
    fn num_envs(&self, py: Python<'_>) -> usize {
        self.inner.lock(py).len()
    }

    /// Control period (s).
    #[getter]
    #[allow(non_snake_case)]
    fn Ts(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).config().ts
    }

    /// Voltage of the action 1 (V).
    #[getter]
    fn u_limit(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).config().u_limit
    }

    /// Episode length (steps).
    #[getter]
    fn max_episode_steps(&self, py: Python<'_>) -> u32 {
        self.inner.lock(py).config().max_steps
    }

    /// Rate-filter cut-off (Hz).
    #[getter]
    fn rate_cutoff(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).config().rate_cutoff_hz
    }

    /// The nominal plant parameters.
    #[getter]
    fn params(&self, py: Python<'_>) -> PyFurutaParams {
        PyFurutaParams {
            inner: self.inner.lock(py).config().params,
        }
    }

    /// Resets the environments where ``mask`` is true (all without a mask), writing their
    /// observations into ``obs``. ``seeds``: one per environment, or one int ``s`` that seeds
    /// environment ``i`` with ``s + i`` (an error if that would not fit 64 bits).
    #[pyo3(signature = (obs, seeds=None, mask=None))]
    fn reset(
        &self,
        py: Python<'_>,
        mut obs: PyReadwriteArray2<'_, f32>,
        seeds: Option<&Bound<'_, PyAny>>,
        mask: Option<PyReadonlyArray1<'_, bool>>,
    ) -> PyResult<()> {
        let mask: Vec<bool> = match mask {
            Some(m) => m.as_slice()?.to_vec(),
            None => Vec::new(),
        };
        let obs = obs.as_slice_mut()?;
        let mut guard = self.inner.lock(py);
        let seeds = match seeds {
            None => Vec::new(),
            Some(s) if s.is_instance_of::<PyInt>() => guard.seeds_from(s.extract()?).py()?,
            Some(s) => s.extract()?,
        };
        let inner: &mut VecEnv = &mut guard;
        py.allow_threads(|| inner.reset(&seeds, &mask, obs)).py()
    }

    /// Steps every environment (autoreset in next-step mode when ``autoreset``), writing into
    /// the given buffers.
    #[allow(clippy::too_many_arguments)]
    fn step(
        &self,
        py: Python<'_>,
        actions: PyReadonlyArray1<'_, f32>,
        autoreset: bool,
        mut obs: PyReadwriteArray2<'_, f32>,
        mut reward: PyReadwriteArray1<'_, f64>,
        mut terminated: PyReadwriteArray1<'_, bool>,
        mut truncated: PyReadwriteArray1<'_, bool>,
    ) -> PyResult<()> {
        let actions = actions.as_slice()?;
        let (obs, reward) = (obs.as_slice_mut()?, reward.as_slice_mut()?);
        let (terminated, truncated) = (terminated.as_slice_mut()?, truncated.as_slice_mut()?);
        let mut guard = self.inner.lock(py);
        let inner: &mut VecEnv = &mut guard;
        py.allow_threads(|| inner.step(actions, autoreset, obs, reward, terminated, truncated))
            .py()
    }

    /// True state ``[theta, theta_dot, alpha, alpha_dot]`` of environment ``i``.
    fn state<'py>(&self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let inner = self.inner.lock(py);
        check(&inner, i)?;
        Ok(Array1::from_vec(inner.env(i).state().to_vec()).into_pyarray(py))
    }

    /// The drawn plant parameters of environment ``i``'s episode.
    fn episode_params(&self, py: Python<'_>, i: usize) -> PyResult<PyFurutaParams> {
        let inner = self.inner.lock(py);
        check(&inner, i)?;
        Ok(PyFurutaParams {
            inner: *inner.env(i).plant().params(),
        })
    }

    /// The drawn action delay (periods) and noise levels (rad) of environment ``i``'s episode.
    fn episode_sensor(&self, py: Python<'_>, i: usize) -> PyResult<(usize, [f64; 2])> {
        let inner = self.inner.lock(py);
        check(&inner, i)?;
        let e = inner.env(i);
        Ok((e.action_delay(), e.noise_std()))
    }
}

fn check(env: &VecEnv, i: usize) -> PyResult<()> {
    if i >= env.len() {
        return Err(pyo3::exceptions::PyIndexError::new_err(format!(
            "environment {i} out of range for {} environments",
            env.len()
        )));
    }
    Ok(())
}

/// The environments' observation of measured angles (rate filter, cos/sin), for running a
/// trained policy on measurements.
#[pyclass(name = "EnvObserver", module = "riprs._riprs")]
pub struct PyObserver {
    inner: Observer,
}

#[pymethods]
impl PyObserver {
    #[new]
    #[allow(non_snake_case)]
    fn new(Ts: f64, rate_cutoff: f64) -> PyResult<Self> {
        rip_core::linalg::check_sample_time("Ts", Ts).py()?;
        if rate_cutoff.is_nan() || rate_cutoff <= 0.0 {
            return Err(crate::errors::to_py(rip_core::RipError::invalid(
                "rate_cutoff",
                format!("must be positive (Hz) or inf, got {rate_cutoff}"),
            )));
        }
        Ok(Self {
            inner: Observer::new(Ts, rate_cutoff),
        })
    }

    /// The observation of the measured angles ``y = [theta, alpha]``.
    fn observe<'py>(
        &mut self,
        py: Python<'py>,
        y: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let y = vector_arg::<2>(y, "y")?;
        let o = self.inner.observe(y);
        Ok(Array1::from_iter(o.iter().map(|v| *v as f32)).into_pyarray(py))
    }

    /// Forgets the previous angles.
    fn reset(&mut self) {
        self.inner.reset();
    }
}

/// Replays logged voltages through ``plant``; returns ``(y_sim, nrmse)``.
#[pyfunction]
#[allow(non_snake_case)]
fn env_replay<'py>(
    py: Python<'py>,
    plant: PyRef<'py, PyPlant>,
    y: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    Ts: f64,
    substeps: u64,
) -> PyResult<(Bound<'py, numpy::PyArray2<f64>>, [f64; 2])> {
    let ym = matrix_arg(y, "y", None, Some(2))?;
    let um = matrix_arg(u, "u", None, None)?;
    let yv: Vec<[f64; 2]> = (0..ym.nrows()).map(|i| [ym[(i, 0)], ym[(i, 1)]]).collect();
    let uv: Vec<f64> = um.iter().copied().collect();
    let plant = plant.inner;
    let substeps = usize::try_from(substeps).unwrap_or(usize::MAX);
    let fit = py
        .allow_threads(|| replay(&plant, &yv, &uv, Ts, substeps))
        .py()?;
    let sim = Array2::from_shape_fn((fit.y.len(), 2), |(i, j)| fit.y[i][j]);
    Ok((sim.into_pyarray(py), fit.nrmse))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyVecEnv>()?;
    m.add_class::<PyObserver>()?;
    m.add("ENV_OBS_DIM", OBS_DIM)?;
    m.add("ENV_MAX_DELAY", MAX_DELAY)?;
    m.add("ENV_MAX_OBS_RATE", MAX_OBS_RATE)?;
    m.add_function(wrap_pyfunction!(env_replay, m)?)?;
    Ok(())
}
