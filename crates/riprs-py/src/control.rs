//! Bindings for `rip_core::regulators`: `Lqr` and `Lqg`, and [`controller_factory`], which turns
//! any controller object from Python into owned copies (`Box<dyn Controller>`) for the simulator.
//! The classes are `frozen` with their controller in a [`Shared`] mutex, so several Python
//! threads may use one object at once (see `crate::shared`).

use std::sync::{Mutex, PoisonError};

use numpy::ndarray::Array1;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use rip_core::paper::INPUT_LIMIT;
use rip_core::paper::TS;
use rip_core::regulators::DEFAULT_RATE_CUTOFF_HZ;
use rip_core::{Compensated, Compensation, Controller, Lqg, Lqr};

use crate::convert::mat_to_py;
use crate::convert::{matrix_arg, vector_arg, Real};
use crate::errors::IntoPyResult;
use crate::shared::Shared;

type Py1<'py> = Bound<'py, PyArray1<f64>>;
type Py2<'py> = Bound<'py, PyArray2<f64>>;

/// Makes fresh copies of one controller, for a simulation or one per run of a batch.
pub type ControllerFactory = Box<dyn Fn() -> Box<dyn Controller> + Send + Sync>;

fn factory_of<C: Controller + Clone + 'static>(template: C) -> ControllerFactory {
    // Behind a mutex so controllers that are `Send` but not `Sync` can be cloned from any
    // worker thread.
    let template = Mutex::new(template);
    Box::new(move || {
        let c = template
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        Box::new(c)
    })
}

/// A factory of copies of the Rust controller inside a Python controller object, taken at this
/// moment: the simulator runs on its own copies, never on the object itself, so it neither
/// changes the caller's controller nor races with another thread stepping it.
///
/// Each arm downcasts one controller pyclass. New controller classes add an arm.
pub fn controller_factory(obj: &Bound<'_, PyAny>) -> PyResult<ControllerFactory> {
    let py = obj.py();
    if let Ok(c) = obj.downcast::<PyLqr>() {
        let c = c.get();
        return Ok(compensated_factory(
            c.inner.lock(py).clone(),
            c.compensation,
        ));
    }
    if let Ok(c) = obj.downcast::<PyLqg>() {
        let c = c.get();
        return Ok(compensated_factory(
            c.inner.lock(py).clone(),
            c.compensation,
        ));
    }
    if let Ok(c) = obj.downcast::<crate::mpc::PyMpc>() {
        let c = c.get();
        return Ok(compensated_factory(
            c.inner.lock(py).clone(),
            c.compensation,
        ));
    }
    if let Ok(c) = obj.downcast::<crate::swingup::PySwingUp>() {
        let c = c.get();
        return Ok(compensated_factory(
            c.inner.lock(py).clone(),
            c.compensation,
        ));
    }
    Err(PyTypeError::new_err(format!(
        "controller must be a riprs controller (Lqr, Lqg, Mpc, SwingUp), got {}",
        obj.get_type().name()?
    )))
}

/// Copies of `template`, inside the compensation (rip-core's `Compensated`) when there is one.
fn compensated_factory<C: Controller + Clone + 'static>(
    template: C,
    compensation: Option<Compensation>,
) -> ControllerFactory {
    match compensation {
        Some(law) => factory_of(Compensated::new(template, law)),
        None => factory_of(template),
    }
}

/// The compensation as a dict (``dead_zone``, ``friction_voltage`` in V; ``u_min``,
/// ``u_max``: the bounds of the written voltage; ``voltage_scale`` (V), ``velocity_scale``
/// (rad/s): the widths of its sign ramps), or ``None``.
pub(crate) fn compensation_dict<'py>(
    py: Python<'py>,
    c: Option<Compensation>,
) -> PyResult<Option<Bound<'py, pyo3::types::PyDict>>> {
    let Some(c) = c else { return Ok(None) };
    let d = pyo3::types::PyDict::new(py);
    let (lo, hi) = c.bounds();
    d.set_item("dead_zone", c.dead_zone())?;
    d.set_item("friction_voltage", c.friction_voltage())?;
    d.set_item("u_min", lo)?;
    d.set_item("u_max", hi)?;
    let (voltage_scale, velocity_scale) = c.scales();
    d.set_item("voltage_scale", voltage_scale)?;
    d.set_item("velocity_scale", velocity_scale)?;
    Ok(Some(d))
}

/// An owned copy of the Rust controller inside a Python controller object (see
/// [`controller_factory`]).
pub fn extract_controller(obj: &Bound<'_, PyAny>) -> PyResult<Box<dyn Controller>> {
    Ok(controller_factory(obj)?())
}

/// Runs one `Controller::step` on array-like `y`, `r` and returns `u` as an array. The step
/// itself runs with the GIL released.
fn step_py<'py, C: Controller>(
    py: Python<'py>,
    c: &Shared<C>,
    y: &Bound<'py, PyAny>,
    r: Option<&Bound<'py, PyAny>>,
) -> PyResult<Py1<'py>> {
    let y = vector_arg::<2>(y, "y")?;
    let r = match r {
        Some(r) if !r.is_none() => vector_arg::<2>(r, "r")?,
        _ => [0.0; 2],
    };
    let mut u = [0.0];
    let mut guard = c.lock(py);
    let inner: &mut C = &mut guard;
    py.allow_threads(|| inner.step(&y, &r, &mut u));
    drop(guard);
    Ok(Array1::from_vec(u.to_vec()).into_pyarray(py))
}

fn estimate_py<'py, C: Controller>(py: Python<'py>, c: &Shared<C>) -> Option<Py1<'py>> {
    let estimate = c.lock(py).state_estimate().map(<[f64]>::to_vec);
    estimate.map(|s| Array1::from_vec(s).into_pyarray(py))
}

/// LQR as the paper uses it: measured angles, rates from a filtered difference, no estimator.
///
/// Each sample, with :math:`a = e^{-2\pi f_c T_s}`, the rate of each angle :math:`q` is
///
/// .. math::
///
///     \hat{\dot q}[k] = a\,\hat{\dot q}[k-1] + (1 - a)\,\frac{q[k] - q[k-1]}{T_s}
///
/// (zero on the first sample), :math:`\hat x = [\theta, \hat{\dot\theta}, \alpha,
/// \hat{\dot\alpha}]` and
///
/// .. math::
///
///     u = \mathrm{sat}\big(-K(\hat x - x_{ref})\big), \qquad
///     x_{ref} = [r_\theta, 0, r_\alpha, 0].
///
/// Parameters
/// ----------
/// K : array_like, shape (1, 4)
///     State-feedback gain (``u = -K x``), e.g. from :func:`riprs.dlqr`.
/// Ts : float
///     Sample time (s).
/// rate_cutoff : float
///     Cut-off frequency of the rate filter (Hz); ``inf`` for the plain difference.
/// u_min, u_max : float
///     Input bounds (V).
#[pyclass(name = "Lqr", module = "riprs._riprs", frozen)]
pub struct PyLqr {
    pub(crate) inner: Shared<Lqr>,
    /// Applied around the regulator wherever it runs (`riprs.simulate`, campaigns).
    pub(crate) compensation: Option<Compensation>,
}

impl PyLqr {
    /// Wraps a core regulator (from the controller assembly).
    pub(crate) fn from_core(inner: Lqr, compensation: Option<Compensation>) -> Self {
        Self {
            inner: Shared::new(inner),
            compensation,
        }
    }
}

#[pymethods]
impl PyLqr {
    /// The dead-zone and friction compensation applied around this controller wherever it
    /// runs (:func:`riprs.simulate`, campaigns, ``rip-rt``), as a dict (``dead_zone``,
    /// ``friction_voltage``, ``u_min``, ``u_max``, all in V), or ``None``. :meth:`step`
    /// returns the voltage before it.
    #[getter]
    fn compensation<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, pyo3::types::PyDict>>> {
        crate::control::compensation_dict(py, self.compensation)
    }

    #[new]
    #[pyo3(signature = (K, Ts=Real(TS), *, rate_cutoff=Real(DEFAULT_RATE_CUTOFF_HZ), u_min=Real(-INPUT_LIMIT), u_max=Real(INPUT_LIMIT)))]
    #[allow(non_snake_case)]
    fn new(
        K: &Bound<'_, PyAny>,
        Ts: Real,
        rate_cutoff: Real,
        u_min: Real,
        u_max: Real,
    ) -> PyResult<Self> {
        let (Ts, rate_cutoff, u_min, u_max) = (Ts.0, rate_cutoff.0, u_min.0, u_max.0);
        let k = matrix_arg(K, "K", Some(1), Some(4))?;
        let inner = Lqr::new(&k, Ts, rate_cutoff)
            .and_then(|c| c.with_input_bounds(u_min, u_max))
            .py()?;
        Ok(Self {
            inner: Shared::new(inner),
            compensation: None,
        })
    }

    /// Design ``K = dlqr(A, B, Q, R)`` and build the regulator.
    ///
    /// Parameters
    /// ----------
    /// A : array_like, shape (4, 4)
    /// B : array_like, shape (4, 1)
    /// Q : array_like, shape (4, 4)
    /// R : array_like, shape (1, 1)
    /// Ts, rate_cutoff, u_min, u_max
    ///     As for the constructor.
    #[staticmethod]
    #[pyo3(signature = (A, B, Q, R, Ts=Real(TS), *, rate_cutoff=Real(DEFAULT_RATE_CUTOFF_HZ), u_min=Real(-INPUT_LIMIT), u_max=Real(INPUT_LIMIT)))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn design(
        py: Python<'_>,
        A: &Bound<'_, PyAny>,
        B: &Bound<'_, PyAny>,
        Q: &Bound<'_, PyAny>,
        R: &Bound<'_, PyAny>,
        Ts: Real,
        rate_cutoff: Real,
        u_min: Real,
        u_max: Real,
    ) -> PyResult<Self> {
        let (Ts, rate_cutoff, u_min, u_max) = (Ts.0, rate_cutoff.0, u_min.0, u_max.0);
        let a = matrix_arg(A, "A", Some(4), Some(4))?;
        let b = matrix_arg(B, "B", Some(4), Some(1))?;
        let q = matrix_arg(Q, "Q", Some(4), Some(4))?;
        let r = matrix_arg(R, "R", Some(1), Some(1))?;
        let inner = py
            .allow_threads(|| Lqr::design(&a, &b, &q, &r, Ts, rate_cutoff))
            .and_then(|c| c.with_input_bounds(u_min, u_max))
            .py()?;
        Ok(Self {
            inner: Shared::new(inner),
            compensation: None,
        })
    }

    /// The paper's LQR: eq. (13) weights on its model, ``Ts = 0.01``, default filter, +-12 V.
    #[staticmethod]
    fn paper() -> PyResult<Self> {
        Ok(Self {
            inner: Shared::new(Lqr::paper().py()?),
            compensation: None,
        })
    }

    /// Compute the input for measured angles ``y = [theta, alpha]`` and reference ``r``.
    ///
    /// Parameters
    /// ----------
    /// y : array_like, shape (2,)
    /// r : array_like, shape (2,), optional
    ///     Reference ``[theta_ref, alpha_ref]``; zero by default.
    ///
    /// Returns
    /// -------
    /// u : ndarray, shape (1,)
    #[pyo3(signature = (y, r=None))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        y: &Bound<'py, PyAny>,
        r: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Py1<'py>> {
        step_py(py, &self.inner, y, r)
    }

    /// Forget the previous measurement and the filtered rates.
    fn reset(&self, py: Python<'_>) {
        self.inner.lock(py).reset();
    }

    /// State-feedback gain (1x4).
    #[getter(K)]
    fn k<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, &self.inner.lock(py).gain())
    }

    /// Sample time (s).
    #[getter(Ts)]
    fn ts(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).ts()
    }

    /// Rate-filter cut-off (Hz).
    #[getter]
    fn rate_cutoff(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).rate_cutoff_hz()
    }

    /// Lower input bound (V).
    #[getter]
    fn u_min(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).input_bounds().0
    }

    /// Gain ``k_i`` on the integrated arm error (integral action, ``lqr.integral_weight``), or
    /// ``None`` without integral action.
    #[getter]
    fn integral_gain(&self, py: Python<'_>) -> Option<f64> {
        self.inner.lock(py).integral_gain()
    }

    /// Upper input bound (V).
    #[getter]
    fn u_max(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).input_bounds().1
    }

    /// The state used by the last step, ``[theta, rate, alpha, rate]``.
    #[getter]
    fn x_hat<'py>(&self, py: Python<'py>) -> Option<Py1<'py>> {
        estimate_py(py, &self.inner)
    }

    /// The input disturbance (V) the law cancels now (``lqr.disturbance_bandwidth``), or
    /// ``None`` without the observer.
    #[getter]
    fn input_disturbance(&self, py: Python<'_>) -> Option<f64> {
        let c = self.inner.lock(py);
        c.cancels_input_disturbance().then(|| c.input_disturbance())
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let c = self.inner.lock(py);
        let k = c.gain();
        format!(
            "Lqr(K=[{:.4}, {:.4}, {:.4}, {:.4}], Ts={}, rate_cutoff={})",
            k[0],
            k[1],
            k[2],
            k[3],
            c.ts(),
            c.rate_cutoff_hz()
        )
    }
}

/// LQG: the LQR gain on the steady-state Kalman filter's current estimate (paper eqs. (3)-(12)).
///
/// Each sample
///
/// .. math::
///
///     e[k] = y[k] - C\hat x[k|k-1], \quad \hat x[k|k] = \hat x[k|k-1] + M e[k],
///
///     u[k] = \mathrm{sat}\big(-K(\hat x_p[k|k] - x_{ref})\big), \quad
///     \hat x[k+1|k] = A\hat x[k|k-1] + B u[k] + L e[k],
///
/// where :math:`\hat x_p` are the first four (plant) states; further states (the paper's output
/// disturbance) are estimated but not fed back.
///
/// Parameters
/// ----------
/// K : array_like, shape (1, 4)
/// A : array_like, shape (n, n)
///     Estimator model, ``n >= 4``, plant states first.
/// B : array_like, shape (n, 1)
///     Input column used for prediction (unscaled).
/// C : array_like, shape (2, n)
/// L, M : array_like, shape (n, 2)
///     Predictor and innovation gains, e.g. from :func:`riprs.kalman`.
/// Ts : float
/// u_min, u_max : float
#[pyclass(name = "Lqg", module = "riprs._riprs", frozen)]
pub struct PyLqg {
    pub(crate) inner: Shared<Lqg>,
    /// Applied around the regulator wherever it runs (`riprs.simulate`, campaigns).
    pub(crate) compensation: Option<Compensation>,
}

impl PyLqg {
    /// Wraps a core regulator (from the controller assembly).
    pub(crate) fn from_core(inner: Lqg, compensation: Option<Compensation>) -> Self {
        Self {
            inner: Shared::new(inner),
            compensation,
        }
    }
}

#[pymethods]
impl PyLqg {
    /// The dead-zone and friction compensation applied around this controller wherever it
    /// runs (:func:`riprs.simulate`, campaigns, ``rip-rt``), as a dict (``dead_zone``,
    /// ``friction_voltage``, ``u_min``, ``u_max``, all in V), or ``None``. :meth:`step`
    /// returns the voltage before it.
    #[getter]
    fn compensation<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, pyo3::types::PyDict>>> {
        crate::control::compensation_dict(py, self.compensation)
    }

    #[new]
    #[pyo3(signature = (K, A, B, C, L, M, Ts=Real(TS), *, u_min=Real(-INPUT_LIMIT), u_max=Real(INPUT_LIMIT)))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn new(
        K: &Bound<'_, PyAny>,
        A: &Bound<'_, PyAny>,
        B: &Bound<'_, PyAny>,
        C: &Bound<'_, PyAny>,
        L: &Bound<'_, PyAny>,
        M: &Bound<'_, PyAny>,
        Ts: Real,
        u_min: Real,
        u_max: Real,
    ) -> PyResult<Self> {
        let k = matrix_arg(K, "K", Some(1), Some(4))?;
        let (Ts, u_min, u_max) = (Ts.0, u_min.0, u_max.0);
        // Shapes are checked by the core, which names the argument that disagrees with the rest.
        let a = matrix_arg(A, "A", None, None)?;
        let b = matrix_arg(B, "B", None, None)?;
        let c = matrix_arg(C, "C", None, None)?;
        let l = matrix_arg(L, "L", None, None)?;
        let m = matrix_arg(M, "M", None, None)?;
        let inner = Lqg::new(&k, &a, &b, &c, &l, &m, Ts)
            .and_then(|c| c.with_input_bounds(u_min, u_max))
            .py()?;
        Ok(Self {
            inner: Shared::new(inner),
            compensation: None,
        })
    }

    /// The paper's LQG: eq. (13) gain and the eq. (11) Kalman filter on the augmented model.
    #[staticmethod]
    fn paper() -> PyResult<Self> {
        Ok(Self {
            inner: Shared::new(Lqg::paper().py()?),
            compensation: None,
        })
    }

    /// Compute the input for measured angles ``y`` and reference ``r`` (see :class:`Lqr`).
    #[pyo3(signature = (y, r=None))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        y: &Bound<'py, PyAny>,
        r: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Py1<'py>> {
        step_py(py, &self.inner, y, r)
    }

    /// Restart the estimator from zero.
    fn reset(&self, py: Python<'_>) {
        self.inner.lock(py).reset();
    }

    /// State-feedback gain (1x4).
    #[getter(K)]
    fn k<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, &self.inner.lock(py).gain())
    }

    /// Predictor gain L (n x 2).
    #[getter(L)]
    fn l<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, self.inner.lock(py).predictor_gain())
    }

    /// Innovation gain M (n x 2).
    #[getter(M)]
    fn m<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, self.inner.lock(py).innovation_gain())
    }

    /// Sample time (s).
    #[getter(Ts)]
    fn ts(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).ts()
    }

    /// Lower input bound (V).
    #[getter]
    fn u_min(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).input_bounds().0
    }

    /// Gain ``k_i`` on the integrated arm error (integral action, ``lqr.integral_weight``), or
    /// ``None`` without integral action.
    #[getter]
    fn integral_gain(&self, py: Python<'_>) -> Option<f64> {
        self.inner.lock(py).integral_gain()
    }

    /// Upper input bound (V).
    #[getter]
    fn u_max(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).input_bounds().1
    }

    /// The current estimate x[k|k] (n,).
    #[getter]
    fn x_hat<'py>(&self, py: Python<'py>) -> Option<Py1<'py>> {
        estimate_py(py, &self.inner)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let c = self.inner.lock(py);
        format!("Lqg(states={}, Ts={})", c.n_states(), c.ts())
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyLqr>()?;
    m.add_class::<PyLqg>()?;
    Ok(())
}
