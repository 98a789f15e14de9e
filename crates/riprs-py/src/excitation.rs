//! Binding for `rip_core::excitation`: `riprs.excitation`, the excitation signals of
//! `rip-rt excite` as numpy arrays.

use numpy::ndarray::Array1;
use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rip_core::excitation::{Excitation, ExcitationSettings, Signal, Sweep};
use rip_core::RipError;

use crate::convert::{array_like, Count, Real, Seed};
use crate::errors::ShapeError;
use crate::errors::{to_py, IntoPyResult};

/// Most samples one call returns (800 MB of float64).
const MAX_SAMPLES: f64 = 1e8;

fn signal_arg(name: &str) -> PyResult<Signal> {
    Signal::from_name(name).ok_or_else(|| {
        to_py(RipError::invalid(
            "signal",
            format!("must be 'chirp', 'prbs', 'steps' or 'free-swing', got {name:?}"),
        ))
    })
}

/// The excitation `signal` sampled at `t` (default: every `dt` seconds over its duration).
#[pyfunction]
#[pyo3(signature = (
    signal, *, dt=Real(0.01), t=None, duration=None, amplitude=None, f_start=None, f_end=None,
    sweep=None, prbs_bits=None, prbs_clock=None, seed=None, step_hold=None, kick=None
))]
#[allow(clippy::too_many_arguments)]
fn excitation<'py>(
    py: Python<'py>,
    signal: &str,
    dt: Real,
    t: Option<&Bound<'py, PyAny>>,
    duration: Option<Real>,
    amplitude: Option<Real>,
    f_start: Option<Real>,
    f_end: Option<Real>,
    sweep: Option<&str>,
    prbs_bits: Option<Count>,
    prbs_clock: Option<Real>,
    seed: Option<Seed>,
    step_hold: Option<Real>,
    kick: Option<Real>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let mut s = ExcitationSettings::new(signal_arg(signal)?);
    let set = |field: &mut f64, v: Option<Real>| {
        if let Some(Real(v)) = v {
            *field = v;
        }
    };
    set(&mut s.duration, duration);
    set(&mut s.amplitude, amplitude);
    set(&mut s.f_start, f_start);
    set(&mut s.f_end, f_end);
    set(&mut s.prbs_clock, prbs_clock);
    set(&mut s.step_hold, step_hold);
    set(&mut s.kick, kick);
    if let Some(name) = sweep {
        s.sweep = Sweep::from_name(name).ok_or_else(|| {
            to_py(RipError::invalid(
                "sweep",
                format!("must be 'linear' or 'log', got {name:?}"),
            ))
        })?;
    }
    if let Some(bits) = prbs_bits {
        s.prbs_bits = u32::try_from(bits.get("prbs_bits")?).unwrap_or(u32::MAX);
    }
    if let Some(Seed(seed)) = seed {
        s.seed = seed;
    }
    let mut x = Excitation::new(s, dt.0).py()?;
    let times: Vec<f64> = match t {
        Some(obj) => {
            let (shape, values) = array_like(obj, "t")?;
            if shape.len() > 1 {
                return Err(ShapeError::new_err(format!(
                    "t: expected a 1-D array of times, got shape {shape:?}"
                )));
            }
            values
        }
        None => {
            let n = (s.duration / dt.0).round();
            if n > MAX_SAMPLES {
                return Err(to_py(RipError::invalid(
                    "dt",
                    format!(
                        "{} s in steps of {} s are {n} samples; at most {MAX_SAMPLES} are \
                         returned",
                        s.duration, dt.0
                    ),
                )));
            }
            let n = n as usize;
            (0..n).map(|k| k as f64 * dt.0).collect()
        }
    };
    let u: Vec<f64> = py.allow_threads(|| times.iter().map(|&t| x.value(t)).collect());
    Ok(Array1::from_vec(u).into_pyarray(py))
}

/// The defaults of `signal` as a dict of the keyword arguments of `excitation`.
#[pyfunction]
fn excitation_defaults<'py>(py: Python<'py>, signal: &str) -> PyResult<Bound<'py, PyDict>> {
    let s = ExcitationSettings::new(signal_arg(signal)?);
    let d = PyDict::new(py);
    d.set_item("duration", s.duration)?;
    d.set_item("amplitude", s.amplitude)?;
    d.set_item("f_start", s.f_start)?;
    d.set_item("f_end", s.f_end)?;
    d.set_item("sweep", s.sweep.name())?;
    d.set_item("prbs_bits", s.prbs_bits)?;
    d.set_item("prbs_clock", s.prbs_clock)?;
    d.set_item("seed", s.seed)?;
    d.set_item("step_hold", s.step_hold)?;
    d.set_item("kick", s.kick)?;
    d.set_item("centering", s.centering)?;
    d.set_item("damping", s.damping)?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(excitation, m)?)?;
    m.add_function(wrap_pyfunction!(excitation_defaults, m)?)?;
    Ok(())
}
