//! Bindings for `rip_core::plant` and `rip_core::fit`: `FurutaParams` and `Plant`, plus the
//! array-like coercion the controller and simulator bindings share.

use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rip_core::fit::{fit_params, FitOptions};
use rip_core::plant::Param;
use rip_core::{FurutaParams, Mat, Plant, RipError, State};

use crate::convert::{array_like, mat_to_py, matrix_arg, vector_arg, Count, Real};
use crate::errors::{to_py, IntoPyResult};

type Py1<'py> = Bound<'py, PyArray1<f64>>;
type Py2<'py> = Bound<'py, PyArray2<f64>>;

fn finite_scalar(v: f64, name: &str) -> PyResult<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(to_py(RipError::NonFinite { name: name.into() }))
    }
}

fn state_arg(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<State> {
    Ok(match obj {
        Some(o) if !o.is_none() => State::from(vector_arg::<4>(o, name)?),
        _ => State::zeros(),
    })
}

fn state_to_py<'py>(py: Python<'py>, x: &State) -> Py1<'py> {
    Array1::from_iter(x.iter().copied()).into_pyarray(py)
}

/// Physical parameters of a rotary inverted pendulum and its DC motor (SI units).
///
/// Both links are uniform rods pivoted at an end; ``Jr`` and ``Jp`` are inertias about each
/// link's own centre of mass (the parallel-axis terms are added by the model). Keywords not
/// given take the QUBE-Servo 2 values.
///
/// Parameters
/// ----------
/// Rm : float
///     Motor resistance (Ohm), > 0.
/// kt : float
///     Motor torque constant (N m/A), > 0.
/// km : float
///     Back-EMF constant (V s/rad), >= 0.
/// mr, Lr, Jr : float
///     Arm mass (kg), length from the motor axis to the pendulum joint (m) and centroidal
///     inertia (kg m^2), all > 0.
/// mp, Lp, Jp : float
///     Pendulum mass, length (centre of mass at ``Lp/2``) and centroidal inertia, all > 0.
/// Dr, Dp : float
///     Viscous friction of the arm and pendulum joints (N m s/rad), >= 0.
/// g : float
///     Gravitational acceleration (m/s^2), > 0.
/// Cr, Cp : float
///     Coulomb friction torque of the arm and pendulum joints (N m), >= 0; 0 by default. The
///     sign of the joint rate is smoothed, ``tanh(rate / 0.05 rad/s)``.
/// Vd : float
///     Voltage dead zone of the motor drive (V), >= 0; 0 by default: the applied voltage is
///     ``u - clip(u, -Vd, Vd)``.
/// Kc : float
///     Stiffness of the cable on the arm (N m/rad), >= 0; 0 by default: a torque
///     ``-Kc * theta`` about the arm's zero.
///
/// Raises
/// ------
/// InvalidParameterError
///     A value is out of range; the message names the parameter.
#[pyclass(name = "FurutaParams", module = "riprs._riprs", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyFurutaParams {
    pub(crate) inner: FurutaParams,
}

fn params_from_kwargs(
    base: &FurutaParams,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<FurutaParams> {
    let mut values = base.to_array();
    if let Some(kw) = kwargs {
        for (key, value) in kw.iter() {
            let key: String = key.extract()?;
            let Some(param) = Param::from_field_name(&key) else {
                return Err(PyTypeError::new_err(format!(
                    "unknown parameter {key:?}; expected one of {}",
                    Param::FIELDS.map(Param::name).join(", ")
                )));
            };
            values[param.index()] = value
                .extract::<Real>()
                .map_err(|_| PyTypeError::new_err(format!("{key} must be a real number")))?
                .0;
        }
    }
    let params = FurutaParams::from_array(values);
    params.validate().map_err(to_py)?;
    Ok(params)
}

#[pymethods]
impl PyFurutaParams {
    #[new]
    #[pyo3(signature = (**kwargs))]
    fn new(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        Ok(Self {
            inner: params_from_kwargs(&FurutaParams::qube_servo2(), kwargs)?,
        })
    }

    /// Quanser QUBE-Servo 2 (published values; see the ``riprs.plant`` module docs).
    #[staticmethod]
    fn qube_servo2() -> Self {
        Self {
            inner: FurutaParams::qube_servo2(),
        }
    }

    /// Parameters fitted so that the upright linearisation, discretised at 0.01 s, reproduces the
    /// paper's ``A_d``, ``B_d`` to their printed precision.
    #[staticmethod]
    fn paper() -> Self {
        Self {
            inner: FurutaParams::paper(),
        }
    }

    /// A copy with some parameters replaced, e.g. ``p.replace(mp=0.03)``.
    #[pyo3(signature = (**changes))]
    fn replace(&self, changes: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        Ok(Self {
            inner: params_from_kwargs(&self.inner, changes)?,
        })
    }

    /// The parameters as a ``dict`` keyed by their Python names.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (param, value) in Param::FIELDS.into_iter().zip(self.inner.to_array()) {
            d.set_item(param.name(), value)?;
        }
        Ok(d)
    }

    /// Fit physical parameters to a discrete linear model.
    ///
    /// Finds the parameters whose linearisation about upright, discretised by zero-order hold at
    /// ``Ts``, best reproduces ``(Ad, Bd)`` in the weighted least-squares sense
    /// :math:`\min \sum_{ij} (W_{ij} (F(p) - [A_d\ B_d])_{ij})^2` (Levenberg-Marquardt on the
    /// logarithms of the free parameters). A linear model determines only six combinations of the
    /// parameters, so ``Rm``, ``kt``, ``km``, ``mr``, ``mp`` and ``g`` are held at the values of
    /// ``base`` and ``Lr``, ``Lp``, ``Jr``, ``Jp``, ``Dr``, ``Dp`` are fitted.
    ///
    /// Parameters
    /// ----------
    /// Ad : array_like, shape (4, 4)
    /// Bd : array_like, shape (4, 1) or (4,)
    /// Ts : float
    ///     Sample time of ``(Ad, Bd)`` (s).
    /// base : FurutaParams, optional
    ///     Fixed parameters and initial guess; QUBE-Servo 2 by default.
    /// weights : array_like, shape (4, 5), optional
    ///     Weight of each entry of ``[Ad Bd]``; by default the inverse magnitude of each entry of
    ///     ``[Ad - I, Bd]`` (relative errors, floored at 1e-3 of the largest).
    /// max_iter : int
    ///     Iteration limit.
    ///
    /// Returns
    /// -------
    /// params : FurutaParams
    ///     The fitted parameters.
    /// report : dict
    ///     ``Ad``, ``Bd`` of the fit, ``max_weighted_residual``, ``max_abs_residual``,
    ///     ``rms_weighted_residual``, ``iterations``, ``converged``.
    #[staticmethod]
    #[pyo3(signature = (Ad, Bd, Ts, *, base=None, weights=None, max_iter=Count::of(200)))]
    #[pyo3(text_signature = "(Ad, Bd, Ts, *, base=None, weights=None, max_iter=200)")]
    #[allow(non_snake_case)]
    fn fit<'py>(
        py: Python<'py>,
        Ad: &Bound<'py, PyAny>,
        Bd: &Bound<'py, PyAny>,
        Ts: Real,
        base: Option<PyFurutaParams>,
        weights: Option<&Bound<'py, PyAny>>,
        max_iter: Count,
    ) -> PyResult<(Self, Bound<'py, PyDict>)> {
        let (Ts, max_iter) = (Ts.0, max_iter.get("max_iter")?);
        let ad = matrix_arg(Ad, "Ad", Some(4), Some(4))?;
        let bd = match matrix_arg(Bd, "Bd", Some(4), Some(1)) {
            Ok(b) => b,
            Err(_) => Mat::from_column_slice(4, 1, &vector_arg::<4>(Bd, "Bd")?),
        };
        let weights = match weights {
            Some(w) if !w.is_none() => Some(matrix_arg(w, "weights", Some(4), Some(5))?),
            _ => None,
        };
        let options = FitOptions {
            base: base.map_or_else(FurutaParams::qube_servo2, |b| b.inner),
            weights,
            max_iterations: max_iter,
            ..Default::default()
        };
        let report = py
            .allow_threads(|| fit_params(&ad, &bd, Ts, &options))
            .map_err(to_py)?;
        let d = PyDict::new(py);
        d.set_item("Ad", mat_to_py(py, &report.ad))?;
        d.set_item("Bd", mat_to_py(py, &report.bd))?;
        d.set_item("max_weighted_residual", report.max_weighted_residual)?;
        d.set_item("max_abs_residual", report.max_abs_residual)?;
        d.set_item("rms_weighted_residual", report.rms_weighted_residual)?;
        d.set_item("iterations", report.iterations)?;
        d.set_item("converged", report.converged)?;
        Ok((
            Self {
                inner: report.params,
            },
            d,
        ))
    }

    #[getter(Rm)]
    fn rm(&self) -> f64 {
        self.inner.rm
    }
    #[getter]
    fn kt(&self) -> f64 {
        self.inner.kt
    }
    #[getter]
    fn km(&self) -> f64 {
        self.inner.km
    }
    #[getter]
    fn mr(&self) -> f64 {
        self.inner.mr
    }
    #[getter(Lr)]
    fn lr(&self) -> f64 {
        self.inner.lr
    }
    #[getter(Jr)]
    fn jr(&self) -> f64 {
        self.inner.jr
    }
    #[getter]
    fn mp(&self) -> f64 {
        self.inner.mp
    }
    #[getter(Lp)]
    fn lp(&self) -> f64 {
        self.inner.lp
    }
    #[getter(Jp)]
    fn jp(&self) -> f64 {
        self.inner.jp
    }
    #[getter(Dr)]
    fn dr(&self) -> f64 {
        self.inner.dr
    }
    #[getter(Dp)]
    fn dp(&self) -> f64 {
        self.inner.dp
    }
    #[getter]
    fn g(&self) -> f64 {
        self.inner.g
    }
    #[getter(Cr)]
    fn cr(&self) -> f64 {
        self.inner.cr
    }
    #[getter(Cp)]
    fn cp(&self) -> f64 {
        self.inner.cp
    }
    #[getter(Vd)]
    fn vd(&self) -> f64 {
        self.inner.vd
    }
    #[getter(Kc)]
    fn kc(&self) -> f64 {
        self.inner.kc
    }

    fn __repr__(&self) -> String {
        let body: Vec<String> = Param::FIELDS
            .map(Param::name)
            .into_iter()
            .zip(self.inner.to_array())
            .map(|(n, v)| format!("{n}={v}"))
            .collect();
        format!("FurutaParams({})", body.join(", "))
    }
}

/// The nonlinear Furuta pendulum driven by motor voltage.
///
/// State ``x = [theta, theta_dot, alpha, alpha_dot]``: arm angle, arm rate, pendulum angle
/// (0 = upright, positive when leaning against positive arm rotation), pendulum rate; input:
/// voltage ``u``; outputs ``[theta, alpha]``. The equations of motion are
///
/// .. math::
///
///     (J_0 + J_\alpha \sin^2\alpha)\ddot\theta - m_{12}\cos\alpha\,\ddot\alpha
///       + 2J_\alpha\sin\alpha\cos\alpha\,\dot\theta\dot\alpha + m_{12}\sin\alpha\,\dot\alpha^2
///       = \tau - D_r\dot\theta - K_c\theta + \tau_d
///
///     -m_{12}\cos\alpha\,\ddot\theta + J_\alpha\ddot\alpha
///       - J_\alpha\sin\alpha\cos\alpha\,\dot\theta^2 - G\sin\alpha = -D_p\dot\alpha
///
/// with :math:`J_0 = J_r + m_r L_r^2/4 + m_p L_r^2`, :math:`J_\alpha = J_p + m_p L_p^2/4`,
/// :math:`m_{12} = m_p L_r L_p/2`, :math:`G = m_p g L_p/2` and the motor torque
/// :math:`\tau = k_t (u - k_m\dot\theta)/R_m`. Coulomb friction adds
/// :math:`-C_r \tanh(\dot\theta/v_c)` and :math:`-C_p \tanh(\dot\alpha/v_c)`
/// (:math:`v_c` = 0.05 rad/s) to the right-hand sides, and the dead zone replaces ``u`` by
/// ``u - clip(u, -Vd, Vd)``; :meth:`linearize` leaves both out (they are not differentiable at
/// rest), as the controller designs do. The cable's torque :math:`-K_c\theta`
/// is smooth: :meth:`linearize` and the designs include it.
///
/// Parameters
/// ----------
/// params : FurutaParams, optional
///     QUBE-Servo 2 by default.
#[pyclass(name = "Plant", module = "riprs._riprs", frozen)]
#[derive(Clone)]
pub struct PyPlant {
    pub(crate) inner: Plant,
}

#[pymethods]
impl PyPlant {
    #[new]
    #[pyo3(signature = (params=None))]
    fn new(params: Option<PyFurutaParams>) -> PyResult<Self> {
        let p = params.map_or_else(FurutaParams::qube_servo2, |p| p.inner);
        Ok(Self {
            inner: Plant::new(p).map_err(to_py)?,
        })
    }

    /// The QUBE-Servo 2 plant.
    #[staticmethod]
    fn qube_servo2() -> Self {
        Self {
            inner: Plant::qube_servo2(),
        }
    }

    /// The plant fitted to the paper's model (``FurutaParams.paper()``).
    #[staticmethod]
    fn paper() -> Self {
        Self {
            inner: Plant::paper(),
        }
    }

    /// The arm's breakaway torque (N m) of its stiction (``plant.arm_breakaway``), 0 for none.
    #[getter]
    fn arm_breakaway(&self) -> f64 {
        self.inner.arm_breakaway()
    }

    /// The physical parameters.
    #[getter]
    fn params(&self) -> PyFurutaParams {
        PyFurutaParams {
            inner: *self.inner.params(),
        }
    }

    /// State derivative ``dx/dt = f(x, u, torque)``.
    ///
    /// Parameters
    /// ----------
    /// x : array_like, shape (4,)
    /// u : float
    ///     Motor voltage (V).
    /// torque : float
    ///     External torque on the arm (N m).
    ///
    /// Returns
    /// -------
    /// ndarray, shape (4,)
    #[pyo3(signature = (x, u=Real(0.0), torque=Real(0.0)))]
    #[pyo3(text_signature = "(self, x, u=0.0, torque=0.0)")]
    fn derivative<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: Real,
        torque: Real,
    ) -> PyResult<Py1<'py>> {
        let x = state_arg(Some(x), "x")?;
        let (u, torque) = (finite_scalar(u.0, "u")?, finite_scalar(torque.0, "torque")?);
        Ok(state_to_py(py, &self.inner.derivative(&x, u, torque)))
    }

    /// Advance the state by ``dt`` with ``substeps`` classical RK4 steps, ``u`` held.
    ///
    /// ``substeps`` is at most 100 000.
    ///
    /// Returns
    /// -------
    /// ndarray, shape (4,)
    ///     The state at ``t + dt``.
    ///
    /// Raises
    /// ------
    /// InvalidParameterError
    ///     ``dt`` not positive and finite, or ``substeps`` out of range.
    /// DivergedError
    ///     The state overflowed (a step or an input far too large for the dynamics).
    #[pyo3(signature = (x, u, dt, substeps=Count::of(1), torque=Real(0.0)))]
    #[pyo3(text_signature = "(self, x, u, dt, substeps=1, torque=0.0)")]
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: Real,
        dt: Real,
        substeps: Count,
        torque: Real,
    ) -> PyResult<Py1<'py>> {
        let x = state_arg(Some(x), "x")?;
        let substeps = substeps.get("substeps")?;
        let x = self
            .inner
            .step_checked(&x, u.0, torque.0, dt.0, substeps)
            .py()?;
        Ok(state_to_py(py, &x))
    }

    /// Open-loop trajectory under a zero-order-held input sequence (RK4).
    ///
    /// Parameters
    /// ----------
    /// x0 : array_like, shape (4,)
    /// u : array_like, shape (N,)
    ///     Voltage held over each interval of length ``dt``.
    /// dt : float
    /// substeps : int
    ///     RK4 steps per interval.
    ///
    /// Returns
    /// -------
    /// ndarray, shape (N + 1, 4)
    ///     States at ``0, dt, ..., N dt``.
    ///
    /// Raises
    /// ------
    /// InvalidParameterError
    ///     ``dt`` not positive and finite, ``substeps`` above 100 000, or more than 10 million
    ///     RK4 steps in all (``N * substeps``).
    /// DivergedError
    ///     The state overflowed (a step or an input far too large for the dynamics).
    #[pyo3(signature = (x0, u, dt, substeps=Count::of(1)))]
    #[pyo3(text_signature = "(self, x0, u, dt, substeps=1)")]
    fn integrate<'py>(
        &self,
        py: Python<'py>,
        x0: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        dt: Real,
        substeps: Count,
    ) -> PyResult<Py2<'py>> {
        let (dt, substeps) = (dt.0, substeps.get("substeps")?);
        let x0 = state_arg(Some(x0), "x0")?;
        let (shape, u) = array_like(u, "u")?;
        if shape.len() > 1 {
            return Err(to_py(RipError::Shape {
                name: "u".into(),
                expected: "(N,)".into(),
                rows: shape[0],
                cols: shape[1..].iter().product(),
            }));
        }
        let plant = self.inner;
        let traj = py
            .allow_threads(|| plant.integrate(&x0, &u, dt, substeps))
            .py()?;
        let flat: Vec<f64> = traj.iter().flat_map(|x| x.iter().copied()).collect();
        let out = Array2::from_shape_vec((traj.len(), 4), flat).expect("one row of four per state");
        Ok(out.into_pyarray(py))
    }

    /// Total mechanical energy ``T + V`` (J), with ``V = G cos(alpha)``.
    fn energy(&self, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        Ok(self.inner.energy(&state_arg(Some(x), "x")?))
    }

    /// Analytic Jacobians of ``f`` at ``(x, u)``: ``(A, B)`` with ``A = df/dx`` (4x4) and
    /// ``B = df/du`` (4x1). ``x`` defaults to upright at rest.
    #[pyo3(signature = (x=None, u=Real(0.0)))]
    #[pyo3(text_signature = "(self, x=None, u=0.0)")]
    fn linearize<'py>(
        &self,
        py: Python<'py>,
        x: Option<&Bound<'py, PyAny>>,
        u: Real,
    ) -> PyResult<(Py2<'py>, Py2<'py>)> {
        let x = state_arg(x, "x")?;
        let (a, b) = self.inner.linearize(&x, finite_scalar(u.0, "u")?);
        Ok((
            mat_to_py(py, &Mat::from_fn(4, 4, |i, j| a[(i, j)])),
            mat_to_py(py, &Mat::from_fn(4, 1, |i, _| b[i])),
        ))
    }

    /// Zero-order-hold discretisation (period ``Ts``) of :meth:`linearize`: ``(Ad, Bd)``.
    #[pyo3(signature = (Ts, x=None, u=Real(0.0)))]
    #[pyo3(text_signature = "(self, Ts, x=None, u=0.0)")]
    #[allow(non_snake_case)]
    fn linearize_discrete<'py>(
        &self,
        py: Python<'py>,
        Ts: Real,
        x: Option<&Bound<'py, PyAny>>,
        u: Real,
    ) -> PyResult<(Py2<'py>, Py2<'py>)> {
        let x = state_arg(x, "x")?;
        let (ad, bd) = self
            .inner
            .linearize_discrete(&x, finite_scalar(u.0, "u")?, Ts.0)
            .py()?;
        Ok((mat_to_py(py, &ad), mat_to_py(py, &bd)))
    }

    fn __repr__(&self) -> String {
        format!("Plant({})", self.params().__repr__())
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyFurutaParams>()?;
    m.add_class::<PyPlant>()?;
    Ok(())
}
