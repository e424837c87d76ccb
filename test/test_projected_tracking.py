"""Issue 39: a plan's joint-space tracking under every limit (``joint_tracking.projected_tracking``).

The command is argmin 1/2 ||qd - qd_des||^2 over the box and the rows A qd <= b: checked against scipy's
SLSQP on the same problem (an independent solver), against the clip where no row is broken, and the
infeasible case's safe answer.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from dualarm_control.joint_tracking import projected_tracking
from dualarm_control.limits import Bounds, DeferredRows
from dualarm_control.qp import make_backend


def bounds_of(lower: np.ndarray, upper: np.ndarray, matrix: np.ndarray | None, b: np.ndarray | None) -> Bounds:
    rows = None if matrix is None or b is None else DeferredRows.of(matrix, b)
    return Bounds(lower, upper, rows, np.zeros(0) if b is None else b)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.integers(2, 14), st.integers(1, 4), st.integers(0, 2**31 - 1))
def test_the_projection_equals_an_independent_solver(n: int, m: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    upper = rng.uniform(0.2, 2.0, n)
    lower = -rng.uniform(0.2, 2.0, n)
    matrix = rng.normal(size=(m, n))
    b = rng.uniform(0.0, 0.5, m)  # qd = 0 meets every row: feasible
    desired = rng.normal(scale=2.0, size=n)
    got, status = projected_tracking(desired, bounds_of(lower, upper, matrix, b), make_backend("daqp"))
    assert status == "solved"
    ref = minimize(lambda x: 0.5 * float((x - desired) @ (x - desired)), np.zeros(n), jac=lambda x: x - desired,
                   bounds=list(zip(lower, upper, strict=True)), method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda x: b - matrix @ x, "jac": lambda x: -matrix}],
                   options={"ftol": 1e-12, "maxiter": 500})
    assert ref.success, ref.message
    np.testing.assert_allclose(got, ref.x, atol=1e-5)
    assert np.all(got >= lower - 1e-12) and np.all(got <= upper + 1e-12)
    assert np.all(matrix @ got <= b + 1e-8)


def test_without_a_broken_row_the_command_is_the_clip() -> None:
    desired = np.array([3.0, -3.0, 0.1])
    lower, upper = np.full(3, -1.0), np.full(3, 1.0)
    got, status = projected_tracking(desired, bounds_of(lower, upper, None, None), make_backend("daqp"))
    assert status == "solved"
    np.testing.assert_array_equal(got, [1.0, -1.0, 0.1])
    loose = np.array([[0.0, 0.0, 1.0]])  # qd_3 <= 0.5 holds at the clip: no QP
    got_rows, _ = projected_tracking(desired, bounds_of(lower, upper, loose, np.array([0.5])), make_backend("daqp"))
    np.testing.assert_array_equal(got_rows, got)


def test_a_row_that_cannot_hold_in_the_box_gives_the_box_point_nearest_to_rest() -> None:
    """qd_1 >= 2 (as -qd_1 <= -2) against the box |qd_1| <= 1: infeasible, reported, never a wild command."""
    lower, upper = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    got, status = projected_tracking(np.array([0.5, 0.5]), bounds_of(lower, upper, np.array([[-1.0, 0.0]]),
                                                                     np.array([-2.0])), make_backend("daqp"))
    assert status == "infeasible"
    np.testing.assert_array_equal(got, [0.0, 0.0])


@pytest.mark.parametrize("backend", ["daqp", "proxsuite"])
def test_both_back_ends_agree(backend: str) -> None:
    rng = np.random.default_rng(7)
    n, m = 14, 3
    matrix, b = rng.normal(size=(m, n)), np.full(m, 0.05)
    desired = rng.normal(size=n)
    box = np.full(n, 1.5)
    got, status = projected_tracking(desired, bounds_of(-box, box, matrix, b), make_backend(backend))
    ref, _ = projected_tracking(desired, bounds_of(-box, box, matrix, b), make_backend("daqp"))
    assert status == "solved"
    np.testing.assert_allclose(got, ref, atol=1e-6)
