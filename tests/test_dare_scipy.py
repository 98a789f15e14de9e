"""scipy's own ``solve_discrete_are`` test cases (DAREX, Benner, Laub & Mehrmann 1995), run
against riprs.dare: the stabilizing solution must agree with scipy's and satisfy the equation.
The cases and their residual tolerances are a fixed copy (``darex_cases.py``), not whatever the
installed scipy's own tests hold.

The complex cases (scipy's 0-2) are out of scope: riprs is real-valued and refuses complex input.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from darex_cases import CASES
from darex_cases import MAX_TOL as TOLERANCES

import riprs


def _residual(a, b, q, r, x, e=None, s=None):
    e = np.eye(a.shape[0]) if e is None else e
    s = np.zeros_like(b) if s is None else s
    cross = a.T @ x @ b + s
    return a.T @ x @ a - e.T @ x @ e - cross @ np.linalg.solve(r + b.T @ x @ b, cross.T) + q


@pytest.mark.parametrize("j", range(len(CASES)))
def test_darex_case(j: int) -> None:
    a, b, q, r, _ = CASES[j]
    if any(np.iscomplexobj(m) for m in (a, b, q, r)):
        with pytest.raises(TypeError, match="real"):
            riprs.dare(a, b, q, r)
        return
    a, b, q, r = (np.asarray(m, dtype=float) for m in (a, b, q, r))
    x, poles, _ = riprs.dare(a, b, q, r)
    x_ref = scipy.linalg.solve_discrete_are(a, b, q, r)
    rel = np.linalg.norm(x - x_ref) / max(np.linalg.norm(x_ref), 1e-300)
    print(f"DAREX case {j}: relative error against scipy {rel:.2e}")
    assert np.all(np.abs(poles) < 1.0)
    # scipy's own acceptance test on the residual, with its per-case tolerance.
    np.testing.assert_allclose(_residual(a, b, q, r, x), 0.0, atol=TOLERANCES[j])
    if j in (15, 16, 17):
        # The ill-conditioned examples (#12-#14), where scipy itself is accurate only to its
        # residual tolerance: riprs must do at least as well on the equation.
        ours = np.abs(_residual(a, b, q, r, x)).max()
        theirs = np.abs(_residual(a, b, q, r, x_ref)).max()
        assert ours <= max(theirs, 1e-12 * np.abs(x).max()), (ours, theirs)
        assert rel < 1e-4
    else:
        assert rel < 1e-9


def test_generalized_cases_with_e_and_s() -> None:
    # scipy's test_solve_generalized_discrete_are, first two cases (E and S given).
    a = np.array([[2.769230e-01, 8.234578e-01, 9.502220e-01],
                  [4.617139e-02, 6.948286e-01, 3.444608e-02],
                  [9.713178e-02, 3.170995e-01, 4.387444e-01]])  # fmt: skip
    b = np.array([[3.815585e-01, 1.868726e-01],
                  [7.655168e-01, 4.897644e-01],
                  [7.951999e-01, 4.455862e-01]])  # fmt: skip
    e = np.array([[6.463130e-01, 2.760251e-01, 1.626117e-01],
                  [7.093648e-01, 6.797027e-01, 1.189977e-01],
                  [7.546867e-01, 6.550980e-01, 4.983641e-01]])  # fmt: skip
    q, r = np.eye(3), np.eye(2)
    for s in (np.zeros((3, 2)), np.ones((3, 2))):
        x, _, _ = riprs.dare(a, b, q, r, s, e)
        x_ref = scipy.linalg.solve_discrete_are(a, b, q, r, e, s)
        rel = np.linalg.norm(x - x_ref) / np.linalg.norm(x_ref)
        print(f"generalized case (S = {s[0, 0]}): relative error against scipy {rel:.2e}")
        np.testing.assert_allclose(_residual(a, b, q, r, x, e, s), 0.0, atol=1.5e-11)
        assert rel < 1e-9


def test_python_control_dare_agrees() -> None:
    control = pytest.importorskip("control")
    a = np.array([[-0.6, 0], [-0.1, -0.4]])
    b = np.array([[2.0, 1.0], [0.0, 1.0]])
    q = np.array([[2.0, 1.0], [1.0, 2.0]])
    r = np.array([[1.0, 0.0], [0.0, 1.0]])
    x, poles, g = riprs.dare(a, b, q, r)
    x_ref, poles_ref, g_ref = control.dare(a, b, q, r)
    np.testing.assert_allclose(x, x_ref, rtol=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.sort_complex(poles), np.sort_complex(poles_ref), atol=1e-10)
