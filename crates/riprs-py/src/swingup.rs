//! Binding for `rip_core::swingup`: `riprs.SwingUp`, the swing-up supervisor around any of the
//! balance controllers.

use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rip_core::{Controller, Lqg, Lqr, Mpc, Phase, Plant, StepStatus, SwingUp, SwingUpSettings};

use crate::control::{PyLqg, PyLqr};
use crate::convert::vector_arg;
use crate::errors::IntoPyResult;
use crate::mpc::PyMpc;
use crate::plant::{PyFurutaParams, PyPlant};
use crate::shared::Shared;
use rip_core::Compensation;

/// The balance controllers a supervisor can hold, as one cloneable type.
#[derive(Clone)]
pub enum Balance {
    Lqr(Lqr),
    Lqg(Box<Lqg>),
    Mpc(Box<Mpc>),
}

impl Balance {
    /// The balance controller and its compensation, which the supervisor takes over and
    /// applies around itself (to the swing-up law's voltage as to the balance controller's).
    fn extract(obj: &Bound<'_, PyAny>) -> PyResult<(Self, Option<Compensation>)> {
        let py = obj.py();
        if let Ok(c) = obj.downcast::<PyLqr>() {
            let c = c.get();
            return Ok((Self::Lqr(c.inner.lock(py).clone()), c.compensation));
        }
        if let Ok(c) = obj.downcast::<PyLqg>() {
            let c = c.get();
            return Ok((
                Self::Lqg(Box::new(c.inner.lock(py).clone())),
                c.compensation,
            ));
        }
        if let Ok(c) = obj.downcast::<PyMpc>() {
            let c = c.get();
            return Ok((
                Self::Mpc(Box::new(c.inner.lock(py).clone())),
                c.compensation,
            ));
        }
        Err(PyTypeError::new_err(format!(
            "balance must be a riprs balance controller (Lqr, Lqg, Mpc), got {}",
            obj.get_type().name()?
        )))
    }

    fn get(&self) -> &dyn Controller {
        match self {
            Self::Lqr(c) => c,
            Self::Lqg(c) => c.as_ref(),
            Self::Mpc(c) => c.as_ref(),
        }
    }

    fn get_mut(&mut self) -> &mut dyn Controller {
        match self {
            Self::Lqr(c) => c,
            Self::Lqg(c) => c.as_mut(),
            Self::Mpc(c) => c.as_mut(),
        }
    }

    fn name(&self) -> &'static str {
        match self {
            Self::Lqr(_) => "Lqr",
            Self::Lqg(_) => "Lqg",
            Self::Mpc(_) => "Mpc",
        }
    }
}

impl Controller for Balance {
    fn n_outputs(&self) -> usize {
        self.get().n_outputs()
    }

    fn n_inputs(&self) -> usize {
        self.get().n_inputs()
    }

    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        self.get_mut().step(y, r, u)
    }

    fn hold(&mut self, u: &[f64]) {
        self.get_mut().hold(u);
    }

    fn observe(&mut self, y: &[f64], u: &[f64]) {
        self.get_mut().observe(y, u);
    }

    fn seed(&mut self, x: &[f64], u: &[f64]) {
        self.get_mut().seed(x, u);
    }

    fn reset(&mut self) {
        self.get_mut().reset();
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        self.get().state_estimate()
    }

    fn sample_time(&self) -> Option<f64> {
        self.get().sample_time()
    }
}

/// Swing-up from rest and catch: energy pumping (Åström & Furuta, Automatica 36(2), 2000) with
/// the arm kept inside ``arm_limit`` by a braking envelope, and a supervisor that hands over to
/// ``balance`` (the paper's LQR, LQG or MPC, unchanged) inside a catch region.
///
/// The pendulum energy relative to upright rest,
///
/// .. math::
///
///     E = \tfrac12 J_\alpha \dot\alpha^2 + G(\cos\alpha - 1),
///
/// is driven to :math:`E_t = \delta G` by the arm acceleration
/// :math:`a = a_p\,\mathrm{sat}(k_E (E_t - E)/G)\,\mathrm{sat}(\dot\alpha\cos\alpha / w)`
/// plus a centring spring, clipped to the braking envelope
/// :math:`|\dot\theta| \le \sqrt{2 a_b(\theta_L \mp \theta)}` that keeps :math:`|\theta| \le
/// \theta_L`, and turned into a voltage (at most ``max_voltage``) by inverting the nominal
/// model. The target energy adds the viscous loss still to come on the way up,
/// :math:`E_t(\alpha) = \delta G + 4 d_p \sqrt{G/J_\alpha}\,(1 - \cos(\alpha/2))`. Inside the
/// catch region (``catch_angle``, ``catch_rate``, ``catch_arm_rate``, ``catch_arm_angle``,
/// ``catch_lookahead``, and ``catch_mode_fraction``: the upright's unstable mode small enough for
/// the voltage bound to stop it) the balance controller takes over: its estimator
/// has run on the measurements and the swing-up's voltage (``estimator_window``) and is
/// restarted from the swing-up's estimate every sample for ``handover_time`` s after the catch,
/// the MPC's previous move is the swing-up's last voltage, and the arm reference starts where the arm
/// was caught and returns to the external one at ``reference_return_rate`` until the external
/// arm reference changes. Leaving the balance region
/// (``balance_angle``, ``arm_limit``) swings up again (``on_fall="retry"``) or stops with 0 V
/// (``"stop"``); after ``max_time`` s of swinging it stops with 0 V. The full derivation is in
/// the ``rip_core::swingup`` documentation.
///
/// Parameters
/// ----------
/// balance : Lqr, Lqg or Mpc
///     The balance controller (copied).
/// plant : Plant or FurutaParams, optional
///     The nominal model the swing-up is designed on; the paper's fitted plant by default.
/// **settings
///     Any of the settings (keyword only; omitted ones take their defaults, listed in
///     :attr:`settings`): ``max_voltage`` (V), ``arm_limit`` (rad), ``brake_fraction``,
///     ``pump_fraction``, ``pump_width`` (rad/s), ``energy_gain``, ``energy_margin``,
///     ``arm_centering`` (rad/s), ``rise_damping`` (1/s), ``barrier_rate`` (1/s),
///     ``rate_cutoff`` (Hz),
///     ``catch_angle`` (rad), ``catch_lookahead`` (s), ``catch_mode_fraction``,
///     ``catch_rate`` (rad/s),
///     ``catch_arm_rate`` (rad/s), ``catch_arm_angle`` (rad), ``catch_prediction`` (s),
///     ``catch_margin`` (rad), ``reference_return_rate`` (rad/s), ``balance_angle`` (rad),
///     ``estimator_window`` (rad), ``handover_time`` (s), ``max_time`` (s), ``on_fall`` (``"retry"`` or ``"stop"``),
///     ``method`` (``"energy"``, the default, or ``"trajectory"``: a swing-up planned on the
///     nominal model by iterative LQR and tracked by time-varying LQR, see :attr:`plan`; its
///     design takes up to a few seconds).
///
/// Raises
/// ------
/// InvalidParameterError
///     A setting is out of range; the message names it as ``swing_up.<key>``.
/// TypeError
///     ``balance`` or ``plant`` is not a riprs object, or a setting is unknown.
#[pyclass(name = "SwingUp", module = "riprs._riprs", frozen)]
pub struct PySwingUp {
    pub(crate) inner: Shared<SwingUp<Balance>>,
    balance_kind: &'static str,
    /// The balance controller's compensation, applied around the whole supervisor.
    pub(crate) compensation: Option<Compensation>,
}

/// `s` with the keyword arguments `settings` applied: the keys and their kinds are those of
/// [`SwingUpSettings`]'s serde form (the `[swing_up]` section), so there is no list of names
/// here. An unknown key or a value of the wrong kind is a `TypeError`, a bad value of the
/// right kind the settings' own error (`swing_up.KEY`).
fn apply_settings(s: &SwingUpSettings, settings: &Bound<'_, PyDict>) -> PyResult<SwingUpSettings> {
    let Ok(toml::Value::Table(mut table)) = toml::Value::try_from(s) else {
        unreachable!("the swing-up settings serialise to a table")
    };
    for (key, value) in settings.iter() {
        let key: String = key.extract()?;
        let Some(old) = table.get(&key) else {
            return Err(PyTypeError::new_err(format!(
                "SwingUp got an unexpected keyword argument {key:?}"
            )));
        };
        let new = crate::spec::to_toml(&value, &key)?;
        let number = |v: &toml::Value| matches!(v, toml::Value::Float(_) | toml::Value::Integer(_));
        let same_kind = std::mem::discriminant(old) == std::mem::discriminant(&new)
            || (number(old) && number(&new));
        if !same_kind {
            return Err(PyTypeError::new_err(format!(
                "{key} must be {}, got {}",
                old.type_str(),
                value.get_type().name()?
            )));
        }
        table.insert(key, new);
    }
    rip_core::spec::from_value(toml::Value::Table(table), "swing_up")
        .map_err(|e| crate::errors::InvalidParameterError::new_err(e.to_string()))
}

/// The settings as a dict of their `[swing_up]` keys.
pub(crate) fn settings_dict<'py>(
    py: Python<'py>,
    s: &SwingUpSettings,
) -> PyResult<Bound<'py, PyDict>> {
    let Ok(table @ toml::Value::Table(_)) = toml::Value::try_from(s) else {
        unreachable!("the swing-up settings serialise to a table")
    };
    Ok(crate::spec::from_toml(py, &table)?
        .into_bound(py)
        .downcast_into::<PyDict>()?)
}

fn phase_name(p: Phase) -> &'static str {
    p.name()
}

#[pymethods]
impl PySwingUp {
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
    #[pyo3(signature = (balance, plant=None, **settings))]
    fn new(
        py: Python<'_>,
        balance: &Bound<'_, PyAny>,
        plant: Option<&Bound<'_, PyAny>>,
        settings: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let (balance, compensation) = Balance::extract(balance)?;
        let plant = match plant {
            None => Plant::paper(),
            Some(p) if p.is_none() => Plant::paper(),
            Some(p) => {
                if let Ok(p) = p.downcast::<PyPlant>() {
                    p.get().inner
                } else if let Ok(p) = p.downcast::<PyFurutaParams>() {
                    Plant::new(p.get().inner).py()?
                } else {
                    return Err(PyTypeError::new_err(format!(
                        "plant must be a riprs.Plant or riprs.FurutaParams, got {}",
                        p.get_type().name()?
                    )));
                }
            }
        };
        let mut s = match settings {
            Some(kw) => apply_settings(&SwingUpSettings::default(), kw)?,
            None => SwingUpSettings::default(),
        };
        if let Some(c) = compensation {
            // The law plans within the bounds the compensation leaves, as the balance does.
            s.max_voltage = c.planned_limit(s.max_voltage);
        }
        let balance_kind = balance.name();
        // A planned swing-up is designed here (up to seconds): without the GIL.
        let inner = py.allow_threads(|| SwingUp::new(balance, &plant, s)).py()?;
        Ok(Self {
            inner: Shared::new(inner),
            balance_kind,
            compensation,
        })
    }

    /// Compute the input for measured angles ``y = [theta, alpha]`` (alpha 0 upright, +-pi
    /// hanging; wrapped or not) and reference ``r``.
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
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let y = vector_arg::<2>(y, "y")?;
        let r = match r {
            Some(r) if !r.is_none() => vector_arg::<2>(r, "r")?,
            _ => [0.0; 2],
        };
        let mut u = [0.0];
        let mut guard = self.inner.lock(py);
        let inner: &mut SwingUp<Balance> = &mut guard;
        py.allow_threads(|| inner.step(&y, &r, &mut u));
        drop(guard);
        Ok(Array1::from_vec(u.to_vec()).into_pyarray(py))
    }

    /// Start over: swing-up phase, estimators and clock reset.
    fn reset(&self, py: Python<'_>) {
        self.inner.lock(py).reset();
    }

    /// ``"swing_up"``, ``"balance"`` or ``"stopped"``.
    #[getter]
    fn phase(&self, py: Python<'_>) -> &'static str {
        phase_name(self.inner.lock(py).phase())
    }

    /// Why the supervisor stopped (``"swing_up_timeout"`` or ``"left_balance_region"``), or
    /// ``None``.
    #[getter]
    fn stop_cause(&self, py: Python<'_>) -> Option<&'static str> {
        match self.inner.lock(py).phase() {
            Phase::Stopped(cause) => Some(cause.name()),
            _ => None,
        }
    }

    /// The settings in use, every default filled in.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.lock(py).settings().clone();
        settings_dict(py, &s)
    }

    /// Sample time (s), the balance controller's.
    #[getter(Ts)]
    fn ts(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).ts()
    }

    /// The pendulum energy ``E`` (J, 0 upright at rest) of the swing-up's own estimate.
    #[getter]
    fn energy(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).energy()
    }

    /// The balance controller's estimate (``None`` for one without).
    #[getter]
    fn x_hat<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        let estimate = self.inner.lock(py).state_estimate().map(<[f64]>::to_vec);
        estimate.map(|s| Array1::from_vec(s).into_pyarray(py))
    }

    /// The planned swing-up (``method="trajectory"``): one row per period from hanging, the
    /// plan's end held upright for its tail.
    ///
    /// Returns
    /// -------
    /// x : ndarray, shape (N, 4)
    ///     ``[theta, theta_dot, alpha, alpha_dot]`` as the swing-up's rate estimate reads them
    ///     along the plan (alpha unwrapped from pi).
    /// u : ndarray, shape (N,)
    ///     The planned voltage (V), before the compensation.
    /// K : ndarray, shape (N, 4)
    ///     The time-varying LQR gain: the swing-up writes ``u[k] - K[k] @ (x - x[k])``.
    ///
    /// ``N`` is 0 with ``method="energy"`` or when no plan was found.
    #[getter]
    #[allow(clippy::type_complexity)]
    fn plan<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray2<f64>>,
    )> {
        let guard = self.inner.lock(py);
        let plan = guard.plan();
        let n = plan.len();
        let rows = |f: &dyn Fn(&rip_core::swingup::PlanPoint) -> [f64; 4]| {
            Array2::from_shape_vec((n, 4), plan.iter().flat_map(f).collect())
        };
        let x = rows(&|p| p.x).map_err(|e| PyTypeError::new_err(e.to_string()))?;
        let k = rows(&|p| p.k).map_err(|e| PyTypeError::new_err(e.to_string()))?;
        let u = Array1::from_vec(plan.iter().map(|p| p.u).collect());
        drop(guard);
        Ok((x.into_pyarray(py), u.into_pyarray(py), k.into_pyarray(py)))
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let s = self.inner.lock(py).settings().clone();
        format!(
            "SwingUp(balance={}, max_voltage={}, arm_limit={}, max_time={}, on_fall={:?})",
            self.balance_kind,
            s.max_voltage,
            s.arm_limit,
            s.max_time,
            s.on_fall.name()
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySwingUp>()?;
    Ok(())
}
