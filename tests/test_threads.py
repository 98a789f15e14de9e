"""Controllers shared between Python threads: no panic, no borrow error, and each call sees a
consistent controller (a simulation runs on its own copy, so the object's own steps are
exactly those of an unshared controller)."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import pytest
from threads import run_threads

import riprs
from riprs import Lqg, Lqr, Mpc, Plant, simulate, simulate_batch, simulate_metrics

MAKERS: list[Callable[[], Any]] = [
    Lqr.paper,
    Lqg.paper,
    lambda: Mpc.paper(solver="clarabel"),
]


def _inputs(n: int) -> np.ndarray:
    k = np.arange(n)
    return np.column_stack([0.2 * np.sin(0.05 * k), 0.05 * np.cos(0.2 * k)])


@pytest.mark.parametrize("make", MAKERS)
def test_stepping_while_another_thread_simulates_it(make) -> None:
    shared = make()
    ys = _inputs(300)
    steps: list[np.ndarray] = []
    sims: list[riprs.SimResult] = []
    batches: list[list[riprs.SimResult]] = []

    def stepper() -> None:
        for y in ys:
            steps.append(shared.step(y, [0.5, 0.0]).copy())
            _ = shared.x_hat

    def simulator() -> None:
        for _ in range(3):
            sims.append(simulate(Plant.paper(), shared, 1.0, x0=[0, 0, 0.05, 0]))
            batches.append(simulate_batch(Plant.paper(), shared, 2, 0.5))
            simulate_metrics(Plant.paper(), shared, 2, 0.5)

    errors = run_threads(stepper, simulator)
    assert not errors, errors
    # The object's own steps equal an unshared controller's: the simulations never touched it.
    alone = make()
    expected = [alone.step(y, [0.5, 0.0]) for y in ys]
    np.testing.assert_array_equal(np.array(steps), np.array(expected))
    # And each simulation equals one of a fresh controller (it copies and resets).
    reference = simulate(Plant.paper(), make(), 1.0, x0=[0, 0, 0.05, 0])
    for res in sims:
        np.testing.assert_array_equal(res.x, reference.x)


@pytest.mark.parametrize("make", MAKERS)
def test_two_threads_stepping_one_controller(make) -> None:
    shared = make()
    ys = _inputs(200)
    outputs: list[float] = []

    def stepper() -> None:
        for y in ys:
            u = shared.step(y)
            outputs.append(float(u[0]))
            shared.reset() if len(outputs) % 97 == 0 else None
            repr(shared)

    errors = run_threads(stepper, stepper, stepper)
    assert not errors, errors
    assert len(outputs) == 3 * len(ys)
    assert all(np.isfinite(outputs)) and max(map(abs, outputs)) <= 12.0


def test_mpc_solve_and_qp_matrices_alongside_steps() -> None:
    mpc = Mpc.paper(solver="clarabel")
    x = np.zeros(mpc.model[0].shape[0])

    def solver() -> None:
        for _ in range(50):
            sol = mpc.solve(x, [0.0], [1.0, 0.0])
            assert sol.status in ("solved", "almost_solved")
            mpc.qp_matrices(x, [0.0])
            _ = mpc.last_solution

    def stepper() -> None:
        for y in _inputs(100):
            mpc.step(y)

    assert not run_threads(solver, stepper)
