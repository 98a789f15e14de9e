//! Bindings for `rip_core::sim` and `rip_core::batch`: one closed-loop run, a parallel batch of
//! records, and a parallel batch of per-run metrics. All run on a worker thread with the GIL
//! released while the calling thread stays responsive to Ctrl-C (`crate::interrupt`). The public
//! wrappers (`riprs.simulate`, `riprs.simulate_batch`, `riprs.simulate_metrics`) coerce the
//! arguments and pass them here as a configuration dict.

use std::sync::atomic::{AtomicU64, Ordering};

use numpy::ndarray::{Array1, Array2};
use numpy::IntoPyArray;
use pyo3::exceptions::{PyKeyError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rip_core::batch::{run_range, simulate_metrics, MetricsOptions, MonteCarlo, RunMetrics};
use rip_core::metrics::table1_rmse;
use rip_core::sim::{batch_runs, Pairing, Reference, SensorModel, StepDisturbance};
use rip_core::{Controller, Plant, SimConfig, SimResult};

use crate::control::{controller_factory, extract_controller};
use crate::convert::{matrix_arg, pair_arg, vector_arg, Count, Real};
use crate::errors::IntoPyResult;
use crate::interrupt::interruptible;
use crate::plant::PyPlant;

fn item<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?
        .ok_or_else(|| PyKeyError::new_err(format!("simulation config is missing {key:?}")))
}

fn opt_item<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Option<Bound<'py, PyAny>>> {
    Ok(d.get_item(key)?.filter(|v| !v.is_none()))
}

fn scalar<T: for<'a> FromPyObject<'a>>(d: &Bound<'_, PyDict>, key: &str) -> PyResult<T> {
    item(d, key)?
        .extract()
        .map_err(|e| PyTypeError::new_err(format!("{key}: {e}")))
}

/// A real-number setting (the coercion policy of `crate::convert`).
fn real(d: &Bound<'_, PyDict>, key: &str) -> PyResult<f64> {
    scalar::<Real>(d, key).map(|r| r.0)
}

/// A count setting, named in the error when negative or huge.
fn count(d: &Bound<'_, PyDict>, key: &str) -> PyResult<u64> {
    scalar::<Count>(d, key)?.get_u64(key)
}

/// Builds the core configuration from the wrapper's dict.
fn config_from_dict(d: &Bound<'_, PyDict>) -> PyResult<SimConfig> {
    let after_catch = match opt_item(d, "reference_after_catch")? {
        Some(v) => Some(v.extract::<Real>()?.0),
        None => None,
    };
    let reference = match opt_item(d, "reference_sequence")? {
        Some(_) if after_catch.is_some() => {
            return Err(PyTypeError::new_err(
                "step_after_catch needs a scalar reference (a step), not a sequence",
            ))
        }
        Some(seq) => {
            let m = matrix_arg(&seq, "reference", None, Some(2))?;
            Reference::Sequence((0..m.nrows()).map(|i| [m[(i, 0)], m[(i, 1)]]).collect())
        }
        None => match after_catch {
            Some(delay) => Reference::StepAfterCatch {
                delay,
                value: vector_arg::<2>(&item(d, "reference_value")?, "reference")?,
            },
            None => Reference::Step {
                time: real(d, "reference_time")?,
                value: vector_arg::<2>(&item(d, "reference_value")?, "reference")?,
            },
        },
    };
    let counts_per_rev = match opt_item(d, "encoder_counts")? {
        Some(c) => Some(pair_arg(&c, "encoder_counts")?),
        None => None,
    };
    let output_disturbance = match opt_item(d, "output_disturbance")? {
        Some(v) => {
            let (time, value): (Real, Bound<'_, PyAny>) = v.extract()?;
            Some(StepDisturbance {
                time: time.0,
                value: pair_arg(&value, "output_disturbance")?,
            })
        }
        None => None,
    };
    let torque_disturbance = match opt_item(d, "torque_disturbance")? {
        Some(v) => {
            let (time, value): (Real, Real) = v.extract()?;
            Some(StepDisturbance {
                time: time.0,
                value: value.0,
            })
        }
        None => None,
    };
    Ok(SimConfig {
        duration: real(d, "duration")?,
        ts: real(d, "Ts")?,
        substeps: count(d, "substeps")? as usize,
        x0: vector_arg::<4>(&item(d, "x0")?, "x0")?,
        reference,
        sensor: SensorModel {
            counts_per_rev,
            noise_std: pair_arg(&item(d, "noise_std")?, "noise_std")?,
            offsets: match opt_item(d, "encoder_offsets")? {
                Some(o) => pair_arg(&o, "encoder_offsets")?,
                None => [0.0; 2],
            },
        },
        output_disturbance,
        torque_disturbance,
        u_limit: real(d, "u_limit")?,
        fall_limit: real(d, "fall_limit")?,
        seed: count(d, "seed")?,
        end_after_catch: None,
    })
}

fn rows<const N: usize>(v: &[[f64; N]]) -> Array2<f64> {
    Array2::from_shape_fn((v.len(), N), |(i, j)| v[i][j])
}

fn result_to_dict<'py>(py: Python<'py>, res: SimResult) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let n = res.len();
    d.set_item("time_to_upright", res.time_to_upright())?;
    d.set_item("swing_up_succeeded", res.swing_up_succeeded())?;
    d.set_item("rmse", table1_rmse(&res).to_vec())?;
    d.set_item("t", Array1::from_vec(res.t).into_pyarray(py))?;
    d.set_item("x", rows(&res.x).into_pyarray(py))?;
    d.set_item("y", rows(&res.y).into_pyarray(py))?;
    d.set_item("u", Array1::from_vec(res.u).into_pyarray(py))?;
    d.set_item("r", rows(&res.r).into_pyarray(py))?;
    if res.n_estimate > 0 {
        let xh = Array2::from_shape_vec((n, res.n_estimate), res.x_hat)
            .map_err(|e| PyTypeError::new_err(e.to_string()))?;
        d.set_item("x_hat", xh.into_pyarray(py))?;
    } else {
        d.set_item("x_hat", py.None())?;
    }
    d.set_item(
        "compute_time",
        Array1::from_vec(res.compute_time).into_pyarray(py),
    )?;
    let phase: Vec<i8> = res
        .phase
        .iter()
        .map(|p| match p {
            rip_core::Phase::SwingUp => 0,
            rip_core::Phase::Balance => 1,
            rip_core::Phase::Stopped(_) => 2,
        })
        .collect();
    d.set_item("phase", Array1::from_vec(phase).into_pyarray(py))?;
    d.set_item("catch_time", res.catch_time)?;
    d.set_item("stop_cause", res.stop_cause.map(|c| c.name()))?;
    d.set_item("fell", res.fell)?;
    d.set_item("diverged", res.diverged)?;
    d.set_item("fall_time", res.fall_time)?;
    d.set_item("fallbacks", res.fallbacks)?;
    d.set_item(
        "x_final",
        Array1::from_vec(res.x_final.to_vec()).into_pyarray(py),
    )?;
    Ok(d)
}

/// A Python callable as the controller: `u = f(y)`, `y` the measured `[θ, α]` as a numpy
/// array, `u` a real number (V). The first exception it raises (or a result that is not a
/// finite number) is kept, the controller reports itself stopped so that the run ends at that
/// sample, and the run's caller raises it.
struct CallableController {
    func: Py<PyAny>,
    error: Option<PyErr>,
}

impl CallableController {
    fn call(&self, py: Python<'_>, y: &[f64]) -> PyResult<f64> {
        let arr = numpy::PyArray1::from_slice(py, y);
        let out = self.func.call1(py, (arr,))?;
        let out = out.bind(py);
        let u = match out.extract::<Real>() {
            Ok(r) => r.0,
            Err(_) => vector_arg::<1>(out, "controller's return value")?[0],
        };
        if !u.is_finite() {
            return Err(crate::errors::NonFiniteError::new_err(format!(
                "the controller returned {u}, not a finite voltage"
            )));
        }
        Ok(u)
    }
}

impl Controller for CallableController {
    fn n_outputs(&self) -> usize {
        2
    }

    fn n_inputs(&self) -> usize {
        1
    }

    fn step(&mut self, y: &[f64], _r: &[f64], u: &mut [f64]) -> rip_core::StepStatus {
        if self.error.is_none() {
            match Python::with_gil(|py| self.call(py, y)) {
                Ok(v) => {
                    u[0] = v;
                    return rip_core::StepStatus::Nominal;
                }
                Err(e) => self.error = Some(e),
            }
        }
        u[0] = 0.0;
        rip_core::StepStatus::Fallback
    }

    fn phase(&self) -> rip_core::Phase {
        // After an exception the run has no controller left: end it at this sample.
        if self.error.is_some() {
            rip_core::Phase::Stopped(rip_core::StopCause::LeftBalanceRegion)
        } else {
            rip_core::Phase::Balance
        }
    }

    fn reset(&mut self) {}
}

/// One closed-loop run; returns the record as a dict of numpy arrays.
#[pyfunction]
fn sim_run<'py>(
    py: Python<'py>,
    plant: PyRef<'py, PyPlant>,
    controller: &Bound<'py, PyAny>,
    config: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let cfg = config_from_dict(config)?;
    let plant: Plant = plant.inner;
    let native = extract_controller(controller);
    if native.is_err() && controller.is_callable() {
        // Every step calls back into Python: the run stays on this thread with the GIL held
        // (Ctrl-C reaches the callable as KeyboardInterrupt, which ends the run).
        let mut c = CallableController {
            func: controller.clone().unbind(),
            error: None,
        };
        let res = rip_core::sim::simulate(&plant, &mut c, &cfg).py()?;
        if let Some(e) = c.error {
            return Err(e);
        }
        return result_to_dict(py, res);
    }
    let mut c = native?;
    let res = interruptible(
        py,
        |cancel| rip_core::sim::simulate_cancellable(&plant, c.as_mut(), &cfg, cancel),
        |_| Ok(()),
    )?
    .py()?;
    result_to_dict(py, res)
}

/// Every (plant, seed) pair in parallel, plant-major; or, with `paired`, plant `i` with seed `i`.
#[pyfunction]
fn sim_batch<'py>(
    py: Python<'py>,
    plants: Vec<PyRef<'py, PyPlant>>,
    controller: &Bound<'py, PyAny>,
    seeds: Vec<u64>,
    config: &Bound<'py, PyDict>,
    paired: bool,
) -> PyResult<Bound<'py, PyList>> {
    let cfg = config_from_dict(config)?;
    let plants: Vec<Plant> = plants.iter().map(|p| p.inner).collect();
    let pairing = if paired {
        Pairing::OneToOne
    } else {
        Pairing::Product
    };
    let runs = batch_runs(plants.len(), &seeds, pairing).py()?;
    let controllers = (0..runs.len())
        .map(|_| extract_controller(controller))
        .collect::<PyResult<Vec<Box<dyn Controller>>>>()?;
    let results = interruptible(
        py,
        |cancel| {
            rip_core::sim::simulate_runs_cancellable(&plants, &runs, &cfg, controllers, cancel)
        },
        |_| Ok(()),
    )?
    .py()?;
    let list = PyList::empty(py);
    for res in results {
        list.append(result_to_dict(py, res)?)?;
    }
    Ok(list)
}

/// Per-run metrics of runs `first_run .. first_run + runs` of a Monte Carlo study around
/// `plant` (`rip_core::batch`); a dict of numpy arrays, one entry per run.
///
/// `cancel` (anything with `is_set()`, e.g. `threading.Event`) lets another thread stop the
/// batch: signal handlers run on Python's main thread only, so a batch called from a pool
/// thread would otherwise not see Ctrl-C. It is polled like a signal, with the same effect.
#[pyfunction]
#[pyo3(signature = (plant, controller, config, runs, first_run, perturbation, parameters, settle_band, progress=None, cancel=None))]
#[allow(clippy::too_many_arguments)]
fn sim_metrics<'py>(
    py: Python<'py>,
    plant: PyRef<'py, PyPlant>,
    controller: &Bound<'py, PyAny>,
    config: &Bound<'py, PyDict>,
    runs: u64,
    first_run: u64,
    perturbation: f64,
    parameters: Vec<String>,
    settle_band: f64,
    progress: Option<Bound<'py, PyAny>>,
    cancel: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let cfg = config_from_dict(config)?;
    let study = MonteCarlo {
        base: *plant.inner.params(),
        perturbation,
        parameters: MonteCarlo::parameters_named(&parameters).py()?,
        seed: cfg.seed,
    };
    study.validate().py()?;
    let range = run_range(first_run, runs).py()?;
    let options = MetricsOptions { settle_band };
    let make = controller_factory(controller)?;
    let done = AtomicU64::new(0);
    let mut reported = 0;
    let metrics = interruptible(
        py,
        |cancel| {
            simulate_metrics(
                range.clone(),
                &cfg,
                &options,
                &|i| study.run(i),
                &make,
                &done,
                cancel,
            )
        },
        |_| {
            if let Some(token) = cancel.as_ref() {
                if token.call_method0("is_set")?.is_truthy()? {
                    return Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(
                        "the batch was cancelled",
                    ));
                }
            }
            let now = done.load(Ordering::Relaxed);
            if let Some(callback) = progress.as_ref().filter(|_| now != reported) {
                callback.call1((now, runs))?;
                reported = now;
            }
            Ok(())
        },
    )?
    .py()?;
    metrics_to_dict(py, &metrics)
}

fn metrics_to_dict<'py>(py: Python<'py>, m: &[RunMetrics]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let col = |f: fn(&RunMetrics) -> f64| Array1::from_iter(m.iter().map(f)).into_pyarray(py);
    d.set_item(
        "run",
        Array1::from_iter(m.iter().map(|r| r.run)).into_pyarray(py),
    )?;
    d.set_item(
        "seed",
        Array1::from_iter(m.iter().map(|r| r.seed)).into_pyarray(py),
    )?;
    d.set_item(
        "rmse",
        Array2::from_shape_fn((m.len(), 3), |(i, j)| m[i].rmse[j]).into_pyarray(py),
    )?;
    d.set_item(
        "fell",
        Array1::from_iter(m.iter().map(|r| r.fell)).into_pyarray(py),
    )?;
    d.set_item(
        "diverged",
        Array1::from_iter(m.iter().map(|r| r.diverged)).into_pyarray(py),
    )?;
    d.set_item("fall_time", col(|r| r.fall_time))?;
    d.set_item("peak_voltage", col(|r| r.peak_voltage))?;
    d.set_item("settle_time", col(|r| r.settle_time))?;
    d.set_item("peak_arm", col(|r| r.peak_arm))?;
    d.set_item("time_to_upright", col(|r| r.time_to_upright))?;
    d.set_item(
        "swing_up_succeeded",
        Array1::from_iter(m.iter().map(|r| r.swing_up_succeeded)).into_pyarray(py),
    )?;
    d.set_item(
        "samples",
        Array1::from_iter(m.iter().map(|r| i64::from(r.samples))).into_pyarray(py),
    )?;
    d.set_item(
        "fallbacks",
        Array1::from_iter(m.iter().map(|r| i64::from(r.fallbacks))).into_pyarray(py),
    )?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("DEFAULT_DURATION", rip_core::sim::DEFAULT_DURATION)?;
    m.add("DEFAULT_SUBSTEPS", rip_core::sim::DEFAULT_SUBSTEPS)?;
    m.add("DEFAULT_U_LIMIT", rip_core::paper::INPUT_LIMIT)?;
    m.add("DEFAULT_FALL_LIMIT", rip_core::sim::DEFAULT_FALL_LIMIT)?;
    m.add("SWING_UP_ALLOWANCE", rip_core::spec::SWING_UP_ALLOWANCE)?;
    m.add_function(wrap_pyfunction!(sim_run, m)?)?;
    m.add_function(wrap_pyfunction!(sim_batch, m)?)?;
    m.add_function(wrap_pyfunction!(sim_metrics, m)?)?;
    Ok(())
}
