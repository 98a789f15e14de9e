"""riprs.Mpc against independent references.

The references never use riprs' condensed matrices: the QP is rebuilt here by simulating the
augmented model step by step in numpy (the cost as a stacked residual, the constraints as a
stacked vector, both affine in ``z = [du, eps]`` and read off by evaluating at basis vectors),
then solved by cvxpy and polished by a dense KKT solve on the active set cvxpy identifies.
"""

from __future__ import annotations

import math

import control
import cvxpy as cp
import numpy as np
import pytest
import scipy.linalg

import riprs

BACKENDS = ["clarabel", "active_set"]
# Each backend is held to the exact QP solution (Reference.solve), at its own accuracy as
# measured against a 50-digit KKT solve (docs/design.md, "Accuracy of the two QP backends").
# On this file's 40 random instances x 3 states the active set's moves are within 4e-13 of it,
# its slack within 2e-14 and its relative cost excess below 2e-14; Clarabel, stopped by its
# default tolerances without iterative refinement, is within 3.4e-7 (first move), 1.0e-6
# (whole plan), 2.8e-8 (slack) and 1.5e-9 (relative cost). Over 1800 random QPs Clarabel's
# first move reached 7.7e-6 and, at one degenerate vertex, its plan 2.5e-4 with the cost within
# 6e-9: its tolerances hold these fixed instances, not every QP.
U_TOL = {"clarabel": 2e-6, "active_set": 1e-8}
PLAN_TOL = {"clarabel": 5e-6, "active_set": 1e-8}
SLACK_TOL = {"clarabel": 1e-6, "active_set": 1e-8}
COST_TOL = {"clarabel": 1e-8, "active_set": 1e-12}


# --------------------------------------------------------------------------------------------
# Independent reference formulation
# --------------------------------------------------------------------------------------------


class Reference:
    """The MPC problem of DESIGN.md written out by simulation, for one instance."""

    def __init__(self, A, B, C, cfg):
        self.cfg = cfg
        n, nu = B.shape
        ny = C.shape[0]
        A_od, _, C_od = cfg["output_disturbance"]
        nd = A_od.shape[0]
        sy = np.asarray(cfg["output_scales"], float)
        self.A = scipy.linalg.block_diag(A, A_od)
        self.B = np.vstack([B, np.zeros((nd, nu))])
        self.C = np.hstack([C / sy[:, None], C_od])
        self.n, self.nu, self.ny, self.nd = n, nu, ny, nd
        self.P = cfg["prediction_horizon"]
        self.m = cfg["control_horizon"]
        self.nz = self.m * nu + 1

    def _simulate(self, z, x0, u_prev, R):
        c = self.cfg
        su = np.asarray(c["input_scales"], float)
        sy = np.asarray(c["output_scales"], float)
        wy, wu, wdu = (np.asarray(c[k], float) for k in
                       ("output_weights", "input_weights", "input_rate_weights"))
        du = z[: self.m * self.nu].reshape(self.m, self.nu)
        eps = z[-1]
        x = x0.copy()
        u = u_prev.copy()
        res, cons = [], []
        for i in range(self.P):
            if i < self.m:
                u = u + du[i]
                res.extend(wdu * du[i] / su)
            res.extend(wu * u / su)  # input target 0
            for j, (lo, hi) in enumerate(c["input_bounds"]):
                cons.extend([u[j] - hi, lo - u[j]])
            x = self.A @ x + self.B @ u
            y = self.C @ x
            res.extend(wy * (R[i] / sy - y))
            for j, bound in enumerate(c["output_bounds"]):
                if bound is not None:
                    lo, hi = bound
                    cons.extend([y[j] - hi / sy[j] - eps, lo / sy[j] - y[j] - eps])
        res.append(math.sqrt(c["ecr_weight"]) * eps)
        cons.append(-eps)
        return np.array(res), np.array(cons)

    def cost(self, z, x0, u_prev, R):
        """The objective at ``z``, the squared norm of the simulated residual."""
        res, _ = self._simulate(z, x0, u_prev, R)
        return float(res @ res)

    def affine(self, x0, u_prev, R):
        """``(E, e, G, h)`` with residual ``E z + e`` and constraints ``G z <= h``."""
        r0, c0 = self._simulate(np.zeros(self.nz), x0, u_prev, R)
        E = np.empty((r0.size, self.nz))
        G = np.empty((c0.size, self.nz))
        for j in range(self.nz):
            ej = np.zeros(self.nz)
            ej[j] = 1.0
            r1, c1 = self._simulate(ej, x0, u_prev, R)
            E[:, j] = r1 - r0
            G[:, j] = c1 - c0
        return E, r0, G, -c0

    def solve(self, x0, u_prev, R):
        """Exact solution: cvxpy finds the active set, a dense KKT solve polishes it."""
        E, e, G, h = self.affine(x0, u_prev, R)
        z = cp.Variable(self.nz)
        prob = cp.Problem(cp.Minimize(cp.sum_squares(E @ z + e)), [G @ z <= h])
        prob.solve(solver=cp.CLARABEL)
        assert prob.status == cp.OPTIMAL
        H, f = 2 * E.T @ E, 2 * E.T @ e
        # Duplicate rows (blocked inputs repeat) would make the KKT matrix singular.
        _, first = np.unique(np.column_stack([G, h]).round(12), axis=0, return_index=True)
        Gu, hu = G[first], h[first]
        scale = 1 + np.abs(hu).max()
        active = list(np.nonzero(Gu @ z.value - hu > -1e-6 * scale)[0])
        for _ in range(20):
            k = len(active)
            Ga, ha = Gu[active], hu[active]
            kkt = np.block([[H, Ga.T], [Ga, np.zeros((k, k))]])
            rhs = np.concatenate([-f, ha])
            try:
                sol = np.linalg.solve(kkt, rhs)
            except np.linalg.LinAlgError:
                # Active rows that depend on each other (the nearly parallel output bounds late
                # in a horizon, which the interior-point solver can report active together)
                # leave the multipliers undetermined: the least-norm ones, z still unique.
                sol = np.linalg.lstsq(kkt, rhs, rcond=None)[0]
            z_kkt, lam = sol[: self.nz], sol[self.nz:]
            viol = Gu @ z_kkt - hu
            if k and lam.min() < -1e-9:
                active.pop(int(np.argmin(lam)))
            elif viol.max() > 1e-10 * scale:
                active.append(int(np.argmax(viol)))
            else:
                return z_kkt, (H, f, G, h)
        raise AssertionError("the dense KKT polish did not converge")


def random_instance(rng):
    n = int(rng.integers(2, 5))
    nu = int(rng.integers(1, 3))
    ny = 2
    A = rng.standard_normal((n, n))
    A *= rng.uniform(0.8, 1.1) / max(abs(np.linalg.eigvals(A)))
    B = rng.standard_normal((n, nu))
    C = rng.standard_normal((ny, n))
    P = int(rng.integers(4, 12))
    m = int(rng.integers(1, min(P, 4) + 1))
    bounded = int(rng.integers(0, 2))
    output_bounds = [None, None]
    output_bounds[bounded] = (-rng.uniform(0.2, 1.0), rng.uniform(0.2, 1.0))
    cfg = dict(
        prediction_horizon=P,
        control_horizon=m,
        output_weights=rng.uniform(0.2, 3.0, ny),
        input_weights=rng.uniform(0.0, 0.5, nu),
        input_rate_weights=rng.uniform(0.1, 1.0, nu),
        input_scales=rng.uniform(0.5, 3.0, nu),
        output_scales=rng.uniform(0.5, 2.0, ny),
        input_bounds=[(-rng.uniform(0.3, 1.5), rng.uniform(0.3, 1.5)) for _ in range(nu)],
        output_bounds=output_bounds,
        ecr_weight=float(rng.uniform(1.0, 100.0)),
        output_disturbance=(np.eye(1), np.array([[0.1]]), np.ones((ny, 1))),
    )
    return A, B, C, cfg


def random_data(rng, ref):
    x0 = rng.standard_normal(ref.n + ref.nd)
    u_prev = rng.uniform(-1.0, 1.0, ref.nu)
    return x0, u_prev


@pytest.mark.parametrize("solver", BACKENDS)
def test_first_move_matches_independent_qp_on_random_instances(solver):
    rng = np.random.default_rng(2024)
    input_active = slack_positive = 0
    for _ in range(40):
        A, B, C, cfg = random_instance(rng)
        ref = Reference(A, B, C, cfg)
        mpc = riprs.Mpc(A, B, C, 0.1, solver=solver, **cfg)
        A_m, B_m, C_m = mpc.model
        np.testing.assert_allclose(A_m, ref.A, atol=1e-15)
        np.testing.assert_allclose(B_m, ref.B, atol=1e-15)
        np.testing.assert_allclose(C_m, ref.C, atol=1e-15)
        for _ in range(3):
            x0, u_prev = random_data(rng, ref)
            r = rng.uniform(-1.5, 1.5, ref.ny)
            R = np.tile(r, (ref.P, 1))
            z_ref, (H, f, _, _) = ref.solve(x0, u_prev, R)
            sol = mpc.solve(x0, u_prev, r)
            assert sol.status == "solved" and not sol.fallback
            u_ref = u_prev + z_ref[: ref.nu]
            np.testing.assert_allclose(sol.u, u_ref, atol=U_TOL[solver], rtol=0)
            np.testing.assert_allclose(sol.du.ravel(), z_ref[:-1], atol=PLAN_TOL[solver], rtol=0)
            np.testing.assert_allclose(sol.slack, max(z_ref[-1], 0.0), atol=SLACK_TOL[solver])
            z_sol = np.append(sol.du.ravel(), sol.slack)
            best = ref.cost(z_ref, x0, u_prev, R)
            assert ref.cost(z_sol, x0, u_prev, R) - best <= COST_TOL[solver] * best
            # The condensed Hessian and linear term equal the simulated least-squares ones.
            H_m, f_m, _, _ = mpc.qp_matrices(x0, u_prev, r)
            np.testing.assert_allclose(H_m, H, rtol=1e-9, atol=1e-9 * np.abs(H).max())
            np.testing.assert_allclose(f_m, f, rtol=1e-9, atol=1e-9 * np.abs(f).max())
            lo = np.array([b[0] for b in cfg["input_bounds"]])
            hi = np.array([b[1] for b in cfg["input_bounds"]])
            input_active += bool(np.any(np.minimum(u_ref - lo, hi - u_ref) < 1e-9))
            slack_positive += bool(z_ref[-1] > 1e-6)
    assert input_active >= 10, input_active
    assert slack_positive >= 10, slack_positive


@pytest.mark.parametrize("solver", BACKENDS)
def test_reference_preview_matches_independent_qp(solver):
    rng = np.random.default_rng(5)
    A, B, C, cfg = random_instance(rng)
    ref = Reference(A, B, C, cfg)
    mpc = riprs.Mpc(A, B, C, 0.1, solver=solver, **cfg)
    for q in (1, 2, ref.P):
        x0, u_prev = random_data(rng, ref)
        preview = rng.uniform(-1, 1, (q, ref.ny))
        R = np.vstack([preview, np.tile(preview[-1], (ref.P - q, 1))])
        z_ref, _ = ref.solve(x0, u_prev, R)
        sol = mpc.solve(x0, u_prev, preview)
        np.testing.assert_allclose(sol.u, u_prev + z_ref[: ref.nu], atol=U_TOL[solver])


# The paper's MPC (riprs.paper.mpc) written out for Reference.
PAPER_CFG = dict(
    prediction_horizon=50, control_horizon=3, output_weights=[25, 50],
    input_weights=[0], input_rate_weights=[1], input_scales=[10], output_scales=[1, 1],
    input_bounds=[(-12, 12)], output_bounds=[None, (-math.pi / 6, math.pi / 6)],
    ecr_weight=100, output_disturbance=(np.eye(1), np.array([[0.01]]), np.ones((2, 1))),
)


@pytest.mark.parametrize("solver", BACKENDS)
def test_paper_settings_match_independent_qp(solver):
    """The paper's size (P = 50, m = 3) from states with the bounds active.

    This QP is conditioned (cond H ~ 2e6) so that its exact solutions for the data rounded two
    ways, simulated here and condensed in riprs, differ by up to 1.7e-9 V: over 600 such states
    the active set, within 1.6e-9 V (first move) and 3.4e-9 V (plan) of a 50-digit solve, is as
    exact as the data allow, and Reference.solve's float64 polish was within 6e-10 V of that
    solve. Clarabel's moves were within 5.3e-8 V (first) and 2.1e-6 V (plan)."""
    plant = riprs.paper.discrete_model()
    mpc = riprs.paper.mpc(solver)
    ref = Reference(plant.A, plant.B, plant.C, PAPER_CFG)
    rng = np.random.default_rng(11)
    saturated = softened = 0
    for _ in range(12):
        x0 = np.array([rng.uniform(-1, 1), rng.uniform(-2, 2), rng.uniform(-0.6, 0.6),
                       rng.uniform(-2, 2), rng.uniform(-0.1, 0.1)])
        u_prev = rng.uniform(-12, 12, 1)
        r = np.array([rng.uniform(-1, 1), 0.0])
        z_ref, _ = ref.solve(x0, u_prev, np.tile(r, (50, 1)))
        sol = mpc.solve(x0, u_prev, r)
        u_ref = u_prev + z_ref[0]
        np.testing.assert_allclose(sol.u, u_ref, atol=U_TOL[solver] * 10)
        np.testing.assert_allclose(sol.du.ravel(), z_ref[:-1], atol=PLAN_TOL[solver] * 10)
        saturated += bool(abs(abs(u_ref[0]) - 12) < 1e-7)
        softened += bool(z_ref[-1] > 1e-6)
    assert saturated >= 2 and softened >= 2, (saturated, softened)


# --------------------------------------------------------------------------------------------
# Equivalence with LQR (the paper's starting point)
# --------------------------------------------------------------------------------------------


def mpc_gain(mpc, nx, nu_prev):
    """The linear map (x, u_prev) -> u(k) of an unconstrained MPC, column by column."""
    cols = []
    for j in range(nx + nu_prev):
        e = np.zeros(nx + nu_prev)
        e[j] = 1.0
        cols.append(mpc.solve(e[:nx], e[nx:], [0.0, 0.0]).u)
    return -np.column_stack(cols)


def test_unconstrained_long_horizon_input_weight_gives_dlqr_gain():
    """w^y = (5, sqrt 50), w^u = sqrt 0.1 is eq. (13): Q = C^T diag(w^y)^2 C, R = 0.1.

    The paper's closed loop has a slow pole, so the finite-horizon gain converges slowly; the
    condensed Hessian of an unstable plant also grows like A^P, which bounds useful P."""
    plant = riprs.paper.discrete_model()
    Q = plant.C.T @ np.diag([25.0, 50.0]) @ plant.C
    K_lqr, _, _ = control.dlqr(plant.A, plant.B, Q, 0.1)
    errors = []
    for P in (20, 60, 120):
        mpc = riprs.Mpc(plant.A, plant.B, plant.C, 0.01, prediction_horizon=P,
                        control_horizon=P, output_weights=[5, math.sqrt(50)],
                        input_weights=[math.sqrt(0.1)], input_rate_weights=[0],
                        solver="active_set")
        K = mpc_gain(mpc, 4, 1)
        assert abs(K[0, 4]) < 1e-6  # u(k-1) does not matter without w^du
        errors.append(np.abs(K[:, :4] - K_lqr).max() / np.abs(K_lqr).max())
    assert errors[0] > errors[1] > 100 * errors[2], errors
    assert errors[2] < 5e-4, errors


@pytest.mark.parametrize("solver", BACKENDS)
def test_unconstrained_long_horizon_matches_dlqr_on_stable_mimo_plant(solver):
    rng = np.random.default_rng(8)
    A = rng.standard_normal((4, 4))
    A *= 0.85 / max(abs(np.linalg.eigvals(A)))
    B = rng.standard_normal((4, 2))
    C = rng.standard_normal((2, 4))
    wy, wu, su = np.array([2.0, 0.5]), np.array([0.3, 0.7]), np.array([2.0, 0.5])
    K_lqr, _, _ = control.dlqr(A, B, C.T @ np.diag(wy**2) @ C, np.diag((wu / su) ** 2))
    mpc = riprs.Mpc(A, B, C, 0.1, prediction_horizon=150, control_horizon=150,
                    output_weights=wy, input_weights=wu, input_rate_weights=[0, 0],
                    input_scales=su, solver=solver)
    cols = [mpc.solve(e, [0.0, 0.0], [0.0, 0.0]).u for e in np.eye(4)]
    K = -np.column_stack(cols)
    np.testing.assert_allclose(K, K_lqr, atol={"clarabel": 1e-6, "active_set": 1e-9}[solver])


def test_unconstrained_long_horizon_rate_weight_gives_dlqr_gain_of_rate_form():
    """With w^u = 0 the MPC is an LQR on [x; u(k-1)] with input du and R = (w^du / s^u)^2."""
    plant = riprs.paper.discrete_model()
    A, B, C = plant.A, plant.B, plant.C
    Aa = np.block([[A, B], [np.zeros((1, 4)), np.eye(1)]])
    Ba = np.vstack([B, np.eye(1)])
    Qa = scipy.linalg.block_diag(C.T @ np.diag([25.0**2, 50.0**2]) @ C, 0.0)
    K_lqr, _, _ = control.dlqr(Aa, Ba, Qa, (1.0 / 10.0) ** 2)
    # u(k) = u(k-1) + du(k) = u(k-1) - K_lqr [x; u(k-1)]
    K_expected = K_lqr - np.array([[0, 0, 0, 0, 1.0]])
    errors = []
    for P in (60, 140):
        mpc = riprs.Mpc(A, B, C, 0.01, prediction_horizon=P, control_horizon=P,
                        output_weights=[25, 50], input_weights=[0], input_rate_weights=[1],
                        input_scales=[10], solver="active_set")
        K = mpc_gain(mpc, 4, 1)
        errors.append(np.abs(K - K_expected).max() / np.abs(K_expected).max())
    assert errors[1] < errors[0] / 100 and errors[1] < 2e-4, errors


# --------------------------------------------------------------------------------------------
# The built-in Kalman filter
# --------------------------------------------------------------------------------------------


def test_paper_mpc_kalman_gains_are_eq_12():
    mpc = riprs.paper.mpc()
    # Eqs. (3) and (8)-(11) built here from the plant: the augmented model with the output
    # disturbance of eq. (1), the input as unit noise scaled by L_su, unit measurement noise.
    plant = riprs.paper.discrete_model()
    Ad, Bd, Cp = plant.A, plant.B, plant.C
    A = scipy.linalg.block_diag(Ad, [[1.0]])
    C = np.hstack([Cp, np.ones((2, 1))])
    Bn = np.zeros((5, 4))
    Bn[:4, 0] = Bd[:, 0] * riprs.paper.INPUT_SCALE
    Bn[4, 1] = 0.01
    Dn = np.hstack([np.zeros((2, 2)), np.eye(2)])
    Q, R, N = Bn @ Bn.T, Dn @ Dn.T, Bn @ Dn.T
    P = scipy.linalg.solve_discrete_are(A.T, C.T, Q, R, s=N)
    S = C @ P @ C.T + R
    L = (A @ P @ C.T + N) @ np.linalg.inv(S)
    M = P @ C.T @ np.linalg.inv(S)
    np.testing.assert_allclose(mpc.L, L, atol=1e-9)
    np.testing.assert_allclose(mpc.M, M, atol=1e-9)
    printed_L, printed_M = riprs.paper.PRINTED["L"], riprs.paper.PRINTED["M"]
    np.testing.assert_array_equal(np.round(mpc.L, 4), printed_L)
    digits = np.full(printed_M.shape, 4)
    digits[0, 1] = 3  # printed 0.029
    for (i, j), d in np.ndenumerate(digits):
        assert round(mpc.M[i, j], d) == printed_M[i, j], (i, j)
    A, B, C = mpc.model
    aug = riprs.paper.augmented_model()
    np.testing.assert_array_equal(A, aug.A)
    np.testing.assert_array_equal(C, aug.C)
    # aug.B holds B * INPUT_SCALE: dividing back is exact only to an ulp.
    np.testing.assert_allclose(B[:, 0], aug.B[:, 0] / riprs.paper.INPUT_SCALE, rtol=1e-15, atol=0)


def test_kalman_gains_match_scipy_dare_on_a_general_model():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((3, 3)) * 0.4
    B = rng.standard_normal((3, 2))
    C = rng.standard_normal((2, 3))
    A_od = np.diag([1.0, 0.9])
    B_od = np.array([[0.2, 0.0], [0.1, 0.3]])
    C_od = np.array([[1.0, 0.0], [0.5, 1.0]])
    Dn = np.array([[0.5, 0.1, 0.0], [0.0, 0.2, 0.3]])
    su, sy = np.array([2.0, 0.5]), np.array([1.5, 3.0])
    mpc = riprs.Mpc(A, B, C, 0.05, input_scales=su, output_scales=sy,
                    output_disturbance=(A_od, B_od, C_od), measurement_noise=Dn)
    Aa = scipy.linalg.block_diag(A, A_od)
    Ca = np.hstack([C / sy[:, None], C_od])
    Bn = scipy.linalg.block_diag(B * su, B_od)
    Q, R = Bn @ Bn.T, Dn @ Dn.T
    X = scipy.linalg.solve_discrete_are(Aa.T, Ca.T, Q, R)
    S = Ca @ X @ Ca.T + R
    np.testing.assert_allclose(mpc.L, Aa @ X @ Ca.T @ np.linalg.inv(S), atol=1e-9)
    np.testing.assert_allclose(mpc.M, X @ Ca.T @ np.linalg.inv(S), atol=1e-9)
    L_ctrl, _, _ = control.dlqe(Aa, np.eye(5), Ca, Q, R)
    np.testing.assert_allclose(mpc.L, L_ctrl, atol=1e-8)


def test_step_runs_the_current_estimator_then_the_move():
    """step(y) = solve(x[k|k], u[k-1]) with x[k|k] from eqs. (4)-(6), done by hand."""
    mpc = riprs.paper.mpc("active_set")
    twin = riprs.paper.mpc("active_set")
    A, B, C = mpc.model
    L, M = mpc.L, mpc.M
    prior = np.zeros(5)
    u_prev = np.zeros(1)
    rng = np.random.default_rng(0)
    for k in range(30):
        y = rng.normal(0, 0.05, 2)
        r = np.array([0.5 if k > 10 else 0.0, 0.0])
        u = mpc.step(y, r)
        e = y - C @ prior
        post = prior + M @ e
        np.testing.assert_allclose(mpc.x_hat, post, atol=1e-12)
        np.testing.assert_allclose(u, twin.solve(post, u_prev, r).u, atol=1e-12)
        prior = A @ prior + B @ u + L @ e
        u_prev = u


# --------------------------------------------------------------------------------------------
# Closed loop on the nonlinear plant
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("solver", BACKENDS)
def test_paper_experiment_on_nonlinear_plant_respects_input_bounds(solver):
    # The simulator's actuator limit is lifted so that only the MPC bounds the input.
    res = riprs.simulate(riprs.paper.plant(), riprs.paper.mpc(solver), duration=5.0,
                         reference=1.0, reference_time=1.0, x0=[0, 0, 0.2, 0],
                         encoder_counts=2048, noise_std=1e-3, u_limit=1e3, seed=1)
    assert not res.fell
    assert res.fallbacks == 0
    assert np.all(np.abs(res.u) <= 12.0 + 1e-9)
    assert np.any(np.abs(res.u) > 11.9), "the scenario should reach the input bound"
    assert abs(res.x[-1, 0] - 1.0) < 0.05 and abs(res.x[-1, 2]) < 0.02


# The arm reference steps to 1 rad at 0.5 s, given per sample so that the reference loop below
# reads the same sequence.
CLOSED_LOOP = dict(duration=3.0, reference=np.where(np.arange(300) >= 50, 1.0, 0.0),
                   x0=[0, 0, 0.2, 0], u_limit=1e3)


class ExactQpMpc:
    """The paper's MPC as a ``simulate`` callable whose every move is the exact QP solution:
    riprs's current-form estimator (its gains are checked against eq. (12) above) written out
    as in ``test_step_runs_the_current_estimator_then_the_move``, the move from Reference."""

    def __init__(self):
        mpc = riprs.paper.mpc()
        self.A, self.B, self.C = mpc.model
        self.L, self.M = mpc.L, mpc.M
        plant = riprs.paper.discrete_model()
        self.ref = Reference(plant.A, plant.B, plant.C, PAPER_CFG)
        self.prior, self.u_prev, self.k = np.zeros(5), np.zeros(1), 0

    def __call__(self, y):
        r = np.array([CLOSED_LOOP["reference"][self.k], 0.0])
        e = y - self.C @ self.prior
        post = self.prior + self.M @ e
        z, _ = self.ref.solve(post, self.u_prev, np.tile(r, (self.ref.P, 1)))
        u = self.u_prev + z[:1]
        self.prior = self.A @ self.prior + self.B @ u + self.L @ e
        self.u_prev, self.k = u, self.k + 1
        return float(u[0])


@pytest.fixture(scope="module")
def exact_closed_loop():
    return riprs.simulate(riprs.paper.plant(), ExactQpMpc(), **CLOSED_LOOP)


# Against the exact-QP loop, the active set's input was within 1.3e-9 V and its state within
# 7.3e-11 (the written-out estimator alone accounts for 7e-10 V: with riprs's own QP in it the
# loop differs from riprs's by that much); Clarabel's within 6.3e-8 V and 2.4e-9.
CLOSED_LOOP_TOL = {"clarabel": (2e-6, 1e-7), "active_set": (1e-7, 1e-8)}


@pytest.mark.parametrize("solver", BACKENDS)
def test_closed_loop_follows_the_exact_qp_closed_loop(solver, exact_closed_loop):
    res = riprs.simulate(riprs.paper.plant(), riprs.paper.mpc(solver), **CLOSED_LOOP)
    assert not exact_closed_loop.fell and res.fallbacks == 0
    u_tol, x_tol = CLOSED_LOOP_TOL[solver]
    np.testing.assert_allclose(res.u, exact_closed_loop.u, atol=u_tol, rtol=0)
    np.testing.assert_allclose(res.x, exact_closed_loop.x, atol=x_tol, rtol=0)


@pytest.mark.parametrize("solver", BACKENDS)
def test_soft_bound_is_violated_only_as_the_slack_says(solver):
    """Released at 0.25 rad with a zero initial estimate, the first plans predict the pendulum
    beyond +-pi/6: each step's plan violates the bound by exactly the reported slack (the
    prediction recomputed here from the model), and the slack vanishes once settled."""
    plant = riprs.paper.plant()
    mpc = riprs.paper.mpc(solver)
    A, B, C = mpc.model
    bound = math.pi / 6
    x = np.array([0.0, 0.0, 0.25, 0.0])
    slacks, alphas = [], []
    tol = 1e-7 if solver == "active_set" else 1e-4
    for _ in range(300):
        y = x[[0, 2]]
        u_prev = mpc.u_prev
        u = mpc.step(y, [0.0, 0.0])
        sol = mpc.last_solution
        assert sol.status == "solved" and abs(u[0]) <= 12.0
        xp, up, worst = mpc.x_hat.copy(), u_prev.copy(), -np.inf
        for i in range(mpc.prediction_horizon):
            if i < mpc.control_horizon:
                up = up + sol.du[i]
            xp = A @ xp + B @ up
            worst = max(worst, abs((C @ xp)[1]) - bound)
        assert worst <= sol.slack + tol
        if sol.slack > tol:
            assert worst == pytest.approx(sol.slack, abs=tol)
        slacks.append(sol.slack)
        alphas.append(x[2])
        x = plant.step(x, float(u[0]), 0.01, 10)
    slacks, alphas = np.array(slacks), np.array(alphas)
    assert slacks.max() > 0.05
    assert np.abs(alphas).max() < bound  # the real pendulum stays inside
    assert np.all(slacks[-100:] < tol) and abs(alphas[-1]) < 0.01


# --------------------------------------------------------------------------------------------
# Failures, fallback and bad input
# --------------------------------------------------------------------------------------------


def test_max_iterations_applies_a_finite_bounded_fallback():
    plant = riprs.paper.discrete_model()
    # The paper's controller with a 1-iteration limit: Clarabel cannot finish.
    starved = riprs.Mpc(plant.A, plant.B, plant.C, 0.01, prediction_horizon=50,
                        control_horizon=3, output_weights=[25, 50], input_rate_weights=[1],
                        input_weights=[0], input_bounds=[(-12, 12)],
                        output_bounds=[None, (-math.pi / 6, math.pi / 6)], ecr_weight=100,
                        input_scales=[10], output_scales=[1, 1],
                        output_disturbance=(np.eye(1), [[0.01]], np.ones((2, 1))),
                        solver="clarabel", max_iterations=1)
    u = starved.step([0.0, 0.2], [0.0, 0.0])
    sol = starved.last_solution
    assert sol.status == "max_iterations" and sol.fallback
    assert sol.slack is None  # no solution, so no slack: never a NaN returned as a number
    np.testing.assert_array_equal(u, [0.0])  # no successful plan yet: the initial hold
    sol = starved.solve(np.zeros(5), [30.0], [1.0, 0.0])
    assert sol.fallback and np.all(np.isfinite(sol.u)) and abs(sol.u[0]) <= 12.0
    assert sol.slack is None
    assert sol.y_pred is None


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        (dict(prediction_horizon=3, control_horizon=4), "control_horizon"),
        (dict(prediction_horizon=0), "prediction_horizon"),
        (dict(prediction_horizon=10**9), "prediction_horizon"),
        (dict(prediction_horizon=10_000, control_horizon=10_000), "prediction_horizon"),
        (dict(output_weights=[1, -1]), "output_weights"),
        (dict(input_rate_weights=[-0.1]), "input_rate_weights"),
        (dict(input_weights=[float("nan")]), "input_weights"),
        (dict(output_weights=[1, 2, 3]), "output_weights"),
        (dict(input_bounds=[(1, -1)]), "input_bounds"),
        (dict(input_bounds=[(-1, 1), (-1, 1)]), "input_bounds"),
        (dict(output_bounds=[(float("nan"), 1), None]), "output_bounds"),
        (dict(output_bounds=[(math.inf, math.inf), None]), "output_bounds"),
        (dict(ecr_weight=-1.0), "ecr_weight"),
        (dict(ecr_weight=float("nan")), "ecr_weight"),
        (dict(input_scales=[0.0]), "input_scales"),
        (dict(output_scales=[1.0]), "output_scales"),
        (dict(output_disturbance=(np.eye(1), [[0.1]], np.ones((3, 1)))), "C_od"),
        (dict(output_disturbance=(np.eye(2), [[0.1]], np.ones((2, 2)))), "B_od"),
        (dict(measurement_noise=np.zeros((2, 2))), "measurement_noise"),
        (dict(solver="osqp"), "solver"),
    ],
)
def test_bad_settings_raise_value_error_naming_the_argument(kwargs, name):
    plant = riprs.paper.discrete_model()
    with pytest.raises(ValueError, match=name):
        riprs.Mpc(plant.A, plant.B, plant.C, 0.01, **kwargs)


def test_huge_horizon_is_refused_before_anything_is_allocated():
    plant = riprs.paper.discrete_model()
    with pytest.raises(riprs.InvalidParameterError, match=r"prediction_horizon.*10000"):
        riprs.Mpc(plant.A, plant.B, plant.C, 0.01, prediction_horizon=10**9,
                  control_horizon=2)
    with pytest.raises(riprs.InvalidParameterError, match="prediction_horizon"):
        riprs.Mpc(plant.A, plant.B, plant.C, 0.01, prediction_horizon=5000,
                  control_horizon=5000)
    # The largest horizon itself is accepted with a short control horizon on a stable plant...
    mpc = riprs.Mpc([[0.9, 0.0], [0.1, 0.95]], [[1.0], [0.0]], [[0.0, 1.0]], 0.01,
                    prediction_horizon=10_000, control_horizon=1, solver="active_set")
    assert mpc.prediction_horizon == 10_000
    assert np.isfinite(mpc.solve([1.0, -1.0], [0.0], [0.5]).u).all()
    # ...while the upright pendulum's unstable pole (|z| = 1.07) overflows 10⁴ steps ahead.
    with pytest.raises(riprs.InvalidParameterError, match="overflow"):
        riprs.Mpc(plant.A, plant.B, plant.C, 0.01, prediction_horizon=10_000,
                  control_horizon=1, solver="active_set")


def test_bad_model_shapes_and_values_raise():
    plant = riprs.paper.discrete_model()
    with pytest.raises(ValueError, match="B"):
        riprs.Mpc(plant.A, plant.B[:3], plant.C, 0.01)
    with pytest.raises(ValueError, match="C"):
        riprs.Mpc(plant.A, plant.B, plant.C[:, :3], 0.01)
    A = plant.A.copy()
    A[0, 0] = np.nan
    with pytest.raises(ValueError, match="A"):
        riprs.Mpc(A, plant.B, plant.C, 0.01)
    with pytest.raises(ValueError, match="Ts"):
        riprs.Mpc(plant.A, plant.B, plant.C, -0.01)
    with pytest.raises(riprs.NotDetectableError):
        # Two integrating disturbances on the same output direction cannot be told apart.
        riprs.Mpc(plant.A, plant.B, plant.C, 0.01,
                  output_disturbance=(np.eye(2), np.eye(2), np.ones((2, 2))))


def test_bad_call_arguments_raise_and_change_nothing():
    mpc = riprs.paper.mpc("active_set")
    mpc.step([0.01, 0.05], [0.0, 0.0])
    x_hat, u_prev = mpc.x_hat.copy(), mpc.u_prev.copy()
    bad_calls = [
        (lambda: mpc.step([0.0], [0.0, 0.0]), "y"),
        (lambda: mpc.step([0.0, np.nan], [0.0, 0.0]), "y"),
        (lambda: mpc.step([0.0, 0.0], [np.inf, 0.0]), "r"),
        (lambda: mpc.step([0.0, 0.0], np.zeros((51, 2))), "r"),
        (lambda: mpc.solve(np.zeros(4), [0.0], [0.0, 0.0]), "x"),
        (lambda: mpc.solve(np.zeros(5), [0.0, 1.0], [0.0, 0.0]), "u_prev"),
        (lambda: mpc.solve(np.zeros(5), [0.0], [0.0, 0.0, 0.0]), "r"),
        (lambda: mpc.solve(np.zeros(5), [0.0], np.zeros((1, 1, 2))), r"r: .*got \(1, 1, 2\)"),
        (lambda: mpc.step([0.0, 0.0], np.zeros((2, 3, 2))), r"r: .*got \(2, 3, 2\)"),
        (lambda: mpc.step(np.zeros((2, 1)), [0.0, 0.0]), r"y: .*got \(2, 1\)"),
    ]
    for call, name in bad_calls:
        with pytest.raises(ValueError, match=name):
            call()
    np.testing.assert_array_equal(mpc.x_hat, x_hat)
    np.testing.assert_array_equal(mpc.u_prev, u_prev)


def test_reset_restores_the_initial_behaviour():
    mpc = riprs.paper.mpc("active_set")
    first = [mpc.step([0.0, 0.1 * k], [0.0, 0.0]).copy() for k in range(5)]
    mpc.reset()
    again = [mpc.step([0.0, 0.1 * k], [0.0, 0.0]).copy() for k in range(5)]
    np.testing.assert_array_equal(first, again)


@pytest.mark.parametrize("name", ["prediction_horizon", "control_horizon", "max_iterations"])
def test_negative_counts_are_named_value_errors(name):
    with pytest.raises(riprs.InvalidParameterError, match=name):
        riprs.Mpc(np.eye(1) * 0.9, [[1.0]], [[1.0]], 0.1, **{name: -1})


@pytest.mark.parametrize("solver", BACKENDS)
def test_nearly_dependent_constraints_are_solved_exactly(solver):
    # Two inputs, one slow output: the late output rows of the horizon are almost parallel, so
    # the active-set working-set systems turn singular; the answer must still be the optimum.
    # Measured: the active set within 3e-15 of the exact solution, Clarabel within 8e-11.
    kw = dict(prediction_horizon=8, control_horizon=3, output_weights=[1.0],
              input_rate_weights=[0.7, 0.7], input_bounds=[(-1, 1), (-1, 1)],
              output_bounds=[(-0.5, 0.5)], ecr_weight=1.0)
    A, B, C = np.array([[0.6]]), np.array([[1.4, -0.1]]), np.array([[1.0]])
    # The Mpc's defaults written out: no input weight, unit scales, no disturbance model.
    ref = Reference(A, B, C, dict(
        kw, input_weights=[0.0, 0.0], input_scales=[1.0, 1.0], output_scales=[1.0],
        output_disturbance=(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((1, 0)))))
    x0, u_prev, r = np.array([0.4]), np.array([-0.2, 0.1]), np.array([1.3])
    z_ref, _ = ref.solve(x0, u_prev, np.tile(r, (ref.P, 1)))
    sol = riprs.Mpc(A, B, C, 0.1, solver=solver, **kw).solve(x0, u_prev, r)
    assert sol.status == "solved" and not sol.fallback
    np.testing.assert_allclose(sol.u, u_prev + z_ref[: ref.nu], atol=U_TOL[solver], rtol=0)
    np.testing.assert_allclose(sol.du.ravel(), z_ref[:-1], atol=PLAN_TOL[solver], rtol=0)


def test_complex_state_is_a_type_error():
    mpc = riprs.paper.mpc()
    with pytest.raises(TypeError, match="x"):
        mpc.solve(np.zeros(5, dtype=complex), [0.0], [0.0, 0.0])
