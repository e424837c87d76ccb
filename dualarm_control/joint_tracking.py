"""Joint-space tracking of a planned joint trajectory (the execution of a paper-003 plan), under every limit."""

from __future__ import annotations

import numpy as np

from dualarm_control.kinematics import FloatArray
from dualarm_control.limits.base import Bounds
from dualarm_control.qp import QPBackend, QPProblem
from dualarm_control.status import Status

ROW_TOLERANCE = 1e-9
"""[m/s] a clipped command that meets every row within this needs no QP (the back-ends' own tolerance)."""


class TrackingProjection:
    """:func:`projected_tracking` on one QP back-end, with the QP's Hessian I (n, n) built once per n."""

    def __init__(self, backend: QPBackend) -> None:
        self.backend = backend
        self.identity = np.eye(0)

    def __call__(self, desired: FloatArray, bounds: Bounds) -> tuple[FloatArray, Status]:
        n = desired.shape[0]
        if self.identity.shape != (n, n):
            self.identity = np.eye(n)
        return projected_tracking(desired, bounds, self.backend, self.identity)


def projected_tracking(desired: FloatArray, bounds: Bounds, backend: QPBackend,
                       identity: FloatArray | None = None) -> tuple[FloatArray, Status]:
    """The command nearest to ``desired`` that meets every limit of the cycle (issue 39):

        qd = argmin 1/2 ||qd - qd_des||^2  s.t.  lower <= qd <= upper,  A qd <= b

    with the box of eq (23) narrowed by the acceleration bound, and the collision limit's rows A qd <= b
    (``bounds``). Without rows, or when the clipped ``desired`` meets them, the clip is that minimiser
    (a box projection is exact); else the QP on ``backend``. An infeasible QP gives the command of the
    box nearest to rest and status "infeasible" (reported, never a wild command).

    Args:
        desired: qd_des [rad/s], (n,): qd_ref + K (q_ref - q) of the plan.
        bounds: the cycle's limits (:func:`~dualarm_control.limits.apply_limits`).
        backend: the QP back-end.
        identity: I (n, n), the QP's Hessian (built here when not given).

    Returns:
        (qd [rad/s] (n,), "solved" or "infeasible").
    """
    clipped = np.minimum(np.maximum(desired, bounds.lower), bounds.upper)
    rows = bounds.rows
    if rows is None or rows.meets(clipped):
        return clipped, Status.SOLVED
    matrix = rows.matrix
    if bool((matrix @ clipped <= bounds.bound + ROW_TOLERANCE).all()):
        return clipped, Status.SOLVED
    hessian = identity if identity is not None else np.eye(desired.shape[0])
    solution = backend.solve(QPProblem(H=hessian, g=-desired, C=matrix, l=np.full(matrix.shape[0], -np.inf),
                                       u=bounds.bound, lb=bounds.lower, ub=bounds.upper))
    if solution.ok and solution.x is not None and bool(np.isfinite(solution.x).all()):
        return np.minimum(np.maximum(solution.x, bounds.lower), bounds.upper), Status.SOLVED
    return np.minimum(np.maximum(0.0, bounds.lower), bounds.upper), Status.INFEASIBLE
