//! Bindings for `rip_core::mpc`: the `Mpc` controller and its `MpcSolution`.

use numpy::ndarray::Array1;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use rip_core::mpc::{paper, Mpc, MpcSettings, MpcSolution, OutputDisturbance, QpSolver};
use rip_core::{Controller, Mat, RipError};

use crate::convert::mat_to_py;
use crate::convert::{matrix_arg, real_array, Count, Real};
use crate::errors::{to_py, IntoPyResult, ShapeError};
use crate::shared::Shared;

type Py1<'py> = Bound<'py, PyArray1<f64>>;
type Py2<'py> = Bound<'py, PyArray2<f64>>;

fn shape_err(name: &str, expected: &str, shape: &[usize]) -> PyErr {
    // `RipError::Shape` holds two dimensions, which would misreport a 3-D or higher array;
    // the message keeps its wording but shows the array's whole shape, as numpy writes it.
    ShapeError::new_err(format!(
        "{name}: expected shape {expected}, got {}",
        numpy_shape(shape)
    ))
}

/// `shape` as numpy prints it: `()`, `(3,)`, `(1, 1, 2)`.
fn numpy_shape(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        dims => {
            let parts: Vec<String> = dims.iter().map(usize::to_string).collect();
            format!("({})", parts.join(", "))
        }
    }
}

/// A scalar or 1-D array-like as a vector; `None` gives an empty vector (the core's default).
/// An explicitly empty sequence is an error: it is not a request for the default.
fn vec_arg(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Vec<f64>> {
    match obj {
        Some(o) if !o.is_none() => {
            let (shape, values) = real_array(o, name)?;
            if shape.len() > 1 {
                return Err(shape_err(name, "a 1-D array", &shape));
            }
            if values.is_empty() {
                return Err(shape_err(
                    name,
                    "one entry per input or output (None for the default)",
                    &shape,
                ));
            }
            Ok(values)
        }
        _ => Ok(Vec::new()),
    }
}

/// Fails unless every value is finite.
fn finite(values: Vec<f64>, name: &str) -> PyResult<Vec<f64>> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(values)
    } else {
        Err(to_py(RipError::NonFinite { name: name.into() }))
    }
}

/// A 1-D vector of exactly `n` finite entries.
fn vec_exact(obj: &Bound<'_, PyAny>, name: &str, n: usize) -> PyResult<Vec<f64>> {
    let (shape, values) = real_array(obj, name)?;
    if shape.len() > 1 || values.len() != n {
        return Err(shape_err(name, &format!("({n},)"), &shape));
    }
    finite(values, name)
}

/// A reference: `(ny,)` constant or `(q, ny)` preview, flattened row by row.
fn reference_arg(obj: Option<&Bound<'_, PyAny>>, ny: usize, p: usize) -> PyResult<Vec<f64>> {
    match obj {
        Some(o) if !o.is_none() => {
            let (shape, values) = real_array(o, "r")?;
            let ok = match shape.as_slice() {
                [] => ny == 1,
                [n] => *n == ny,
                [q, n] => *n == ny && (1..=p).contains(q),
                _ => false,
            };
            if !ok {
                return Err(shape_err(
                    "r",
                    &format!("({ny},) or (q, {ny}) with 1 <= q <= P = {p}"),
                    &shape,
                ));
            }
            finite(values, "r")
        }
        _ => Ok(vec![0.0; ny]),
    }
}

/// `None`, or a sequence whose items are `None` (unbounded) or `(lo, hi)` with `None` for a
/// missing side.
fn bounds_arg(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Vec<(f64, f64)>> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(Vec::new());
    };
    let type_err = || {
        PyTypeError::new_err(format!(
            "{name} must be a sequence of None or (lower, upper) pairs"
        ))
    };
    let mut out = Vec::new();
    let mut given = 0usize;
    for item in obj.try_iter().map_err(|_| type_err())? {
        given += 1;
        let item = item?;
        if item.is_none() {
            out.push((f64::NEG_INFINITY, f64::INFINITY));
            continue;
        }
        let pair: Vec<Option<f64>> = item.extract().map_err(|_| type_err())?;
        if pair.len() != 2 {
            return Err(to_py(RipError::Shape {
                name: format!("{name}[{}]", out.len()),
                expected: "(lower, upper)".into(),
                rows: pair.len(),
                cols: 1,
            }));
        }
        out.push((
            pair[0].unwrap_or(f64::NEG_INFINITY),
            pair[1].unwrap_or(f64::INFINITY),
        ));
    }
    if given == 0 {
        return Err(shape_err(
            name,
            "one item per input or output (None for no bounds)",
            &[0],
        ));
    }
    Ok(out)
}

fn disturbance_arg(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Option<OutputDisturbance>> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(None);
    };
    let parts: Vec<Bound<'_, PyAny>> = obj
        .try_iter()
        .and_then(|it| it.collect::<PyResult<Vec<_>>>())
        .map_err(|_| {
            PyTypeError::new_err("output_disturbance must be None or a tuple (A_od, B_od, C_od)")
        })?;
    if parts.len() != 3 {
        return Err(to_py(RipError::invalid(
            "output_disturbance",
            format!("expected (A_od, B_od, C_od), got {} items", parts.len()),
        )));
    }
    Ok(Some(OutputDisturbance {
        a: matrix_arg(&parts[0], "A_od", None, None)?,
        b: matrix_arg(&parts[1], "B_od", None, None)?,
        c: matrix_arg(&parts[2], "C_od", None, None)?,
    }))
}

fn vec_to_py<'py>(py: Python<'py>, v: &[f64]) -> Py1<'py> {
    Array1::from_vec(v.to_vec()).into_pyarray(py)
}

/// The result of one MPC solve.
///
/// Attributes
/// ----------
/// u : ndarray, shape (nu,)
///     The move :math:`u(k)`; the fallback move when ``fallback`` is true.
/// du : ndarray, shape (m, nu)
///     Moves :math:`\Delta u(k), \dots, \Delta u(k+m-1)` of the applied plan.
/// slack : float or None
///     :math:`\varepsilon \ge 0` in scaled output units; ``None`` when the QP was not solved
///     (``fallback`` is true): there is no optimal slack to report.
/// status : str
///     ``"solved"``, ``"almost_solved"``, ``"max_iterations"``, ``"numerical_trouble"``,
///     ``"infeasible"`` or ``"invalid_input"``.
/// fallback : bool
///     Whether the fallback move (previous plan's next move, clamped) was applied.
/// iterations : int
///     Interior-point iterations (Clarabel) or active-set subproblems.
/// solve_time : float
///     Wall time of the QP update and solve (s).
/// y_pred : ndarray, shape (P, ny) or None
///     Predicted outputs :math:`y(k+i|k)`, :math:`i = 1..P` (engineering units) along the
///     plan, from :meth:`Mpc.solve` only (``None`` after :meth:`Mpc.step`).
#[pyclass(name = "MpcSolution", module = "riprs._riprs", frozen)]
pub struct PyMpcSolution {
    sol: MpcSolution,
    nu: usize,
    y_pred: Option<Mat>,
}

#[pymethods]
impl PyMpcSolution {
    #[getter]
    fn u<'py>(&self, py: Python<'py>) -> Py1<'py> {
        vec_to_py(py, self.sol.u.as_slice())
    }

    #[getter]
    fn du<'py>(&self, py: Python<'py>) -> Py2<'py> {
        let m = self.sol.du.len() / self.nu;
        mat_to_py(py, &Mat::from_row_slice(m, self.nu, self.sol.du.as_slice()))
    }

    #[getter]
    fn slack(&self) -> Option<f64> {
        (!self.sol.fallback && self.sol.slack.is_finite()).then_some(self.sol.slack)
    }

    #[getter]
    fn status(&self) -> &'static str {
        self.sol.status.name()
    }

    #[getter]
    fn fallback(&self) -> bool {
        self.sol.fallback
    }

    #[getter]
    fn iterations(&self) -> usize {
        self.sol.iterations
    }

    #[getter]
    fn solve_time(&self) -> f64 {
        self.sol.solve_time
    }

    #[getter]
    fn y_pred<'py>(&self, py: Python<'py>) -> Option<Py2<'py>> {
        self.y_pred.as_ref().map(|y| mat_to_py(py, y))
    }

    fn __repr__(&self) -> String {
        format!(
            "MpcSolution(u={:?}, slack={:?}, status={:?}, iterations={}, solve_time={:.1e})",
            self.sol.u.as_slice(),
            self.slack(),
            self.sol.status.name(),
            self.sol.iterations,
            self.sol.solve_time
        )
    }
}

/// Constrained MPC with soft output bounds and a built-in Kalman filter (MATLAB MPC Toolbox
/// semantics; the paper's section 3).
///
/// Prediction model: the plant :math:`x^+ = Ax + Bu`, :math:`y = Cx` augmented with the
/// output disturbance :math:`x_{od}^+ = A_{od}x_{od} + B_{od}w_{od}`,
/// :math:`y_{od} = C_{od}x_{od}` (eq. (1)) on scaled outputs:
///
/// .. math::
///
///     A_{aug} = \begin{bmatrix} A & 0 \\ 0 & A_{od} \end{bmatrix}, \quad
///     B_u = \begin{bmatrix} B \\ 0 \end{bmatrix}, \quad
///     C_{aug} = \begin{bmatrix} S_y^{-1} C & C_{od} \end{bmatrix}.
///
/// Estimator: the steady-state Kalman filter ``kalman(A_aug, I, C_aug, Q, R, N)`` with
/// :math:`Q = B_n B_n^T`, :math:`R = D_n D_n^T`, :math:`N = B_n D^T` (eqs. (7)-(11)), the inputs
/// modelled as unit white noise in scaled units (:math:`B_n = [B S_u, 0; 0, B_{od}]`), run in
/// current form (eqs. (4)-(6)). Each step minimises over
/// :math:`z = [\Delta u(k), \dots, \Delta u(k+m-1), \varepsilon]`
///
/// .. math::
///
///     \sum_{i=1}^{P}\sum_j \Big(\frac{w^y_j (r_j(k+i) - y_j(k+i|k))}{s^y_j}\Big)^2
///     + \sum_{i=0}^{m-1}\sum_j \Big(\frac{w^{\Delta u}_j \Delta u_j(k+i)}{s^u_j}\Big)^2
///     + \sum_{i=0}^{P-1}\sum_j \Big(\frac{w^u_j (u_j(k+i) - u_{t,j})}{s^u_j}\Big)^2
///     + \rho_\varepsilon \varepsilon^2
///
/// subject to :math:`u_{min} \le u(k+i) \le u_{max}` (hard), :math:`y_{min} - \varepsilon \le
/// y(k+i|k) \le y_{max} + \varepsilon` (soft, equal concern), :math:`\varepsilon \ge 0` and
/// :math:`\Delta u(k+i) = 0` for :math:`i \ge m`; it applies :math:`u(k) = u(k-1) + \Delta u(k)`.
/// If the QP fails, the previous plan's next move clamped to the bounds is applied and the
/// solution says so (``fallback``); the input is never NaN.
///
/// The keyword defaults are MATLAB's ``mpc`` defaults (``P = 10``, ``m = 2``, weights 1 / 0.1 / 0,
/// ``ECR = 1e5``, no bounds, no disturbance model), as in ``rip_core::mpc::MpcSettings::default``,
/// so that a MATLAB design ports keyword for keyword; :meth:`paper` is the paper's MPC, equal
/// to the experiment file's ``[mpc]`` defaults (``MpcSettings::paper``), solver included.
///
/// Parameters
/// ----------
/// A, B, C : array_like, shapes (n, n), (n, nu), (ny, n)
///     Discrete-time plant.
/// Ts : float
///     Sample time (s).
/// prediction_horizon : int
///     :math:`P` (default 10), at most 10 000; larger horizons, or a condensed problem of more
///     than 10 million entries per matrix, raise :class:`riprs.InvalidParameterError`.
/// control_horizon : int
///     :math:`m \le P` (default 2).
/// prediction_step : int
///     Sample periods per prediction step (default 1): the prediction, its cost and its soft
///     bounds on a grid of ``prediction_step * Ts``, each move held for one grid step, so the
///     horizon spans ``P * prediction_step`` periods (at most 10 000).
/// output_weights, input_rate_weights, input_weights : array_like or None
///     :math:`w^y` (ny,), :math:`w^{\Delta u}` (nu,), :math:`w^u` (nu,); MATLAB defaults 1,
///     0.1, 0.
/// input_target : array_like or None
///     :math:`u_t` (nu,), default 0.
/// input_bounds, output_bounds : sequence or None
///     One item per input / output: ``None`` (unbounded) or ``(lower, upper)``, either side
///     ``None`` or infinite for none. Input bounds are hard, output bounds soft.
/// ecr_weight : float
///     :math:`\rho_\varepsilon > 0` (default 1e5).
/// input_scales, output_scales : array_like or None
///     Scale factors :math:`s^u`, :math:`s^y` (default 1).
/// output_disturbance : tuple or None
///     ``(A_od, B_od, C_od)``; ``None`` for no disturbance model.
/// measurement_noise : array_like or None
///     :math:`D_n` (ny, nv) on the scaled outputs; ``None`` for the identity.
/// solver : {"active_set", "clarabel"}
///     QP backend: the dense active-set method with warm start (default, allocation-free, the
///     solver of the experiment file and ``rip-rt``) or Clarabel (interior point). Both solve
///     the same QP, to different accuracies (measured against the exact QP solution on the
///     design page): the active set to rounding, Clarabel to its stopping tolerances, about
///     1e-6 V in the first move and farther later in the plan on some problems.
/// max_iterations : int
///     Iteration limit of the QP solver, at most 10 000.
///
/// Raises
/// ------
/// ValueError
///     (a :class:`riprs.RiprsError` subclass) naming the argument, for wrong shapes, NaN,
///     negative weights, ``m > P``, empty or inverted bounds, or an undetectable model.
#[pyclass(name = "Mpc", module = "riprs._riprs", frozen)]
pub struct PyMpc {
    // Shared by the Python threads that use this object (see `crate::shared`).
    pub(crate) inner: Shared<Mpc>,
    /// Applied around the MPC wherever it runs (`riprs.simulate`, campaigns).
    pub(crate) compensation: Option<rip_core::Compensation>,
}

#[pymethods]
impl PyMpc {
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
    #[pyo3(signature = (
        A, B, C, Ts, *, prediction_horizon=Count::of(rip_core::mpc::DEFAULT_PREDICTION_HORIZON as i64),
        control_horizon=Count::of(rip_core::mpc::DEFAULT_CONTROL_HORIZON as i64),
        prediction_step=Count::of(1), output_weights=None,
        input_rate_weights=None, input_weights=None, input_target=None, input_bounds=None,
        output_bounds=None, ecr_weight=Real(rip_core::mpc::DEFAULT_ECR_WEIGHT), input_scales=None,
        output_scales=None, output_disturbance=None, measurement_noise=None, solver="active_set",
        max_iterations=Count::of(rip_core::mpc::DEFAULT_MAX_ITERATIONS as i64)
    ))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        A: &Bound<'_, PyAny>,
        B: &Bound<'_, PyAny>,
        C: &Bound<'_, PyAny>,
        Ts: Real,
        prediction_horizon: Count,
        control_horizon: Count,
        prediction_step: Count,
        output_weights: Option<&Bound<'_, PyAny>>,
        input_rate_weights: Option<&Bound<'_, PyAny>>,
        input_weights: Option<&Bound<'_, PyAny>>,
        input_target: Option<&Bound<'_, PyAny>>,
        input_bounds: Option<&Bound<'_, PyAny>>,
        output_bounds: Option<&Bound<'_, PyAny>>,
        ecr_weight: Real,
        input_scales: Option<&Bound<'_, PyAny>>,
        output_scales: Option<&Bound<'_, PyAny>>,
        output_disturbance: Option<&Bound<'_, PyAny>>,
        measurement_noise: Option<&Bound<'_, PyAny>>,
        solver: &str,
        max_iterations: Count,
    ) -> PyResult<Self> {
        let (Ts, ecr_weight) = (Ts.0, ecr_weight.0);
        let a = matrix_arg(A, "A", None, None)?;
        let b = matrix_arg(B, "B", None, None)?;
        let c = matrix_arg(C, "C", None, None)?;
        let settings = MpcSettings {
            prediction_horizon: prediction_horizon.get("prediction_horizon")?,
            control_horizon: control_horizon.get("control_horizon")?,
            prediction_step: prediction_step.get("prediction_step")?,
            output_weights: vec_arg(output_weights, "output_weights")?,
            input_weights: vec_arg(input_weights, "input_weights")?,
            input_rate_weights: vec_arg(input_rate_weights, "input_rate_weights")?,
            input_target: vec_arg(input_target, "input_target")?,
            input_scales: vec_arg(input_scales, "input_scales")?,
            output_scales: vec_arg(output_scales, "output_scales")?,
            input_bounds: bounds_arg(input_bounds, "input_bounds")?,
            output_bounds: bounds_arg(output_bounds, "output_bounds")?,
            ecr_weight,
            output_disturbance: disturbance_arg(output_disturbance)?,
            measurement_noise: match measurement_noise.filter(|o| !o.is_none()) {
                Some(o) => Some(matrix_arg(o, "measurement_noise", None, None)?),
                None => None,
            },
            solver: QpSolver::from_name(solver).py()?,
            max_iterations: max_iterations.get("max_iterations")?,
        };
        let inner = py
            .allow_threads(|| Mpc::new(&a, &b, &c, Ts, settings))
            .py()?;
        Ok(Self {
            inner: Shared::new(inner),
            compensation: None,
        })
    }

    /// The paper's MPC (section 3) on its model; see :func:`riprs.paper.mpc`. The same
    /// controller (settings and solver) as ``riprs.Spec().build_controllers()["MPC"]`` and
    /// ``rip-rt``'s default MPC.
    #[staticmethod]
    #[pyo3(signature = (solver="active_set"))]
    fn paper(py: Python<'_>, solver: &str) -> PyResult<Self> {
        let solver = QpSolver::from_name(solver).py()?;
        let inner = py.allow_threads(|| paper::controller(solver)).py()?;
        Ok(Self {
            inner: Shared::new(inner),
            compensation: None,
        })
    }

    /// Solve the QP for a given augmented state.
    ///
    /// Parameters
    /// ----------
    /// x : array_like, shape (nx,)
    ///     Augmented state: plant states, then disturbance states.
    /// u_prev : array_like, shape (nu,)
    ///     The previous move :math:`u(k-1)`.
    /// r : array_like, shape (ny,) or (q, ny), optional
    ///     Constant reference, or a preview of rows :math:`r(k+1), \dots, r(k+q)`,
    ///     :math:`q \le P`, the last row held to :math:`k+P`. Zero by default.
    ///
    /// Returns
    /// -------
    /// MpcSolution
    ///
    /// Does not touch the estimator; it updates the solver's warm start and the plan used by
    /// the fallback.
    #[pyo3(signature = (x, u_prev, r=None))]
    fn solve(
        &self,
        py: Python<'_>,
        x: &Bound<'_, PyAny>,
        u_prev: &Bound<'_, PyAny>,
        r: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyMpcSolution> {
        let mut guard = self.inner.lock(py);
        let x = vec_exact(x, "x", guard.n_states())?;
        let u_prev = vec_exact(u_prev, "u_prev", guard.n_inputs())?;
        let r = reference_arg(r, guard.n_outputs(), guard.prediction_horizon())?;
        let nu = guard.n_inputs();
        let inner: &mut Mpc = &mut guard;
        let (sol, y_pred) = py
            .allow_threads(|| {
                let sol = inner.solve(&x, &u_prev, &r)?.clone();
                let y = if sol.fallback {
                    None
                } else {
                    Some(inner.predict_outputs(&x, &u_prev, sol.du.as_slice())?)
                };
                Ok::<_, RipError>((sol, y))
            })
            .py()?;
        Ok(PyMpcSolution { sol, nu, y_pred })
    }

    /// One controller sample with the built-in estimator.
    ///
    /// Corrects the estimate with ``y`` (eqs. (5)-(6)), solves for the move from
    /// :math:`\hat x[k|k]` and :math:`u(k-1)`, predicts with the applied move (eq. (4)).
    ///
    /// Parameters
    /// ----------
    /// y : array_like, shape (ny,)
    ///     Measured outputs.
    /// r : array_like, shape (ny,) or (q, ny), optional
    ///     Reference (see :meth:`solve`); zero by default.
    ///
    /// Returns
    /// -------
    /// u : ndarray, shape (nu,)
    ///     Always finite and within the input bounds; see :attr:`last_solution` for the status.
    #[pyo3(signature = (y, r=None))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        y: &Bound<'py, PyAny>,
        r: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Py1<'py>> {
        let mut guard = self.inner.lock(py);
        let y = vec_exact(y, "y", guard.n_outputs())?;
        let r = reference_arg(r, guard.n_outputs(), guard.prediction_horizon())?;
        let mut u = vec![0.0; guard.n_inputs()];
        let inner: &mut Mpc = &mut guard;
        py.allow_threads(|| inner.step_preview(&y, &r, &mut u));
        drop(guard);
        Ok(Array1::from_vec(u).into_pyarray(py))
    }

    /// Restart: zero estimate, zero previous move, no warm start.
    fn reset(&self, py: Python<'_>) {
        self.inner.lock(py).reset_state();
    }

    /// The result of the last :meth:`solve` or :meth:`step`.
    #[getter]
    fn last_solution(&self, py: Python<'_>) -> PyMpcSolution {
        let c = self.inner.lock(py);
        PyMpcSolution {
            sol: c.last_solution().clone(),
            nu: c.n_inputs(),
            y_pred: None,
        }
    }

    /// The augmented prediction model ``(A, B, C)`` (``C`` on scaled outputs).
    #[getter]
    fn model<'py>(&self, py: Python<'py>) -> (Py2<'py>, Py2<'py>, Py2<'py>) {
        let c = self.inner.lock(py);
        let m = c.model();
        (
            mat_to_py(py, &m.a),
            mat_to_py(py, &m.b),
            mat_to_py(py, &m.c),
        )
    }

    /// Predictor gain L of the built-in Kalman filter (nx, ny).
    #[getter(L)]
    fn l<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, &self.inner.lock(py).kalman_design().l)
    }

    /// Innovation gain M of the built-in Kalman filter (nx, ny).
    #[getter(M)]
    fn m<'py>(&self, py: Python<'py>) -> Py2<'py> {
        mat_to_py(py, &self.inner.lock(py).kalman_design().m)
    }

    /// The condensed QP ``(H, f, A, b)`` for given data: minimise
    /// ``0.5 z^T H z + f^T z`` subject to ``A z <= b`` over ``z = [du(k..k+m-1), eps]``.
    ///
    /// Rows of ``A``: hard input bounds for ``u(k..k+m-1)``, then soft output bounds for
    /// ``y(k+1..k+P)``, then ``-eps <= 0``.
    #[pyo3(signature = (x, u_prev, r=None))]
    #[allow(clippy::type_complexity)]
    fn qp_matrices<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u_prev: &Bound<'py, PyAny>,
        r: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<(Py2<'py>, Py1<'py>, Py2<'py>, Py1<'py>)> {
        let c = self.inner.lock(py);
        let x = vec_exact(x, "x", c.n_states())?;
        let u_prev = vec_exact(u_prev, "u_prev", c.n_inputs())?;
        let r = reference_arg(r, c.n_outputs(), c.prediction_horizon())?;
        let (h, f, a, b) = c.qp_matrices(&x, &u_prev, &r).py()?;
        drop(c);
        Ok((
            mat_to_py(py, &h),
            vec_to_py(py, f.as_slice()),
            mat_to_py(py, &a),
            vec_to_py(py, b.as_slice()),
        ))
    }

    /// Sample time (s).
    #[getter(Ts)]
    fn ts(&self, py: Python<'_>) -> f64 {
        self.inner.lock(py).ts()
    }

    /// Prediction horizon P.
    #[getter]
    fn prediction_horizon(&self, py: Python<'_>) -> usize {
        self.inner.lock(py).prediction_horizon()
    }

    /// Control horizon m.
    #[getter]
    fn control_horizon(&self, py: Python<'_>) -> usize {
        self.inner.lock(py).control_horizon()
    }

    /// The QP backend, ``"clarabel"`` or ``"active_set"``.
    #[getter]
    fn solver(&self, py: Python<'_>) -> &'static str {
        self.inner.lock(py).settings().solver.name()
    }

    /// Lower input bounds (nu,), ``-inf`` where unbounded.
    #[getter]
    fn u_min<'py>(&self, py: Python<'py>) -> Py1<'py> {
        vec_to_py(py, self.inner.lock(py).input_bounds().0)
    }

    /// Upper input bounds (nu,), ``inf`` where unbounded.
    #[getter]
    fn u_max<'py>(&self, py: Python<'py>) -> Py1<'py> {
        vec_to_py(py, self.inner.lock(py).input_bounds().1)
    }

    /// The current estimate :math:`\hat x[k|k]` (nx,).
    #[getter]
    fn x_hat<'py>(&self, py: Python<'py>) -> Option<Py1<'py>> {
        self.inner
            .lock(py)
            .state_estimate()
            .map(|s| vec_to_py(py, s))
    }

    /// The previous move :math:`u(k-1)` (nu,).
    #[getter]
    fn u_prev<'py>(&self, py: Python<'py>) -> Py1<'py> {
        vec_to_py(py, self.inner.lock(py).last_input())
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let c = self.inner.lock(py);
        let m = c.model();
        format!(
            "Mpc(states={}, inputs={}, outputs={}, P={}, m={}, solver={:?}, Ts={})",
            m.a.nrows(),
            m.b.ncols(),
            m.c.nrows(),
            c.prediction_horizon(),
            c.control_horizon(),
            c.settings().solver.name(),
            c.ts()
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add(
        "MAX_PREDICTION_HORIZON",
        rip_core::mpc::MAX_PREDICTION_HORIZON,
    )?;
    m.add_class::<PyMpc>()?;
    m.add_class::<PyMpcSolution>()?;
    Ok(())
}
