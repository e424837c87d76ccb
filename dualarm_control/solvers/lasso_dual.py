"""The exact lasso of eq (17) of paper 000 without its bounds, from its 6-variable dual (:class:`LassoDual`;
:class:`~dualarm_control.solvers.methods.SparseQP`'s first try)."""

from __future__ import annotations

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.qp import DaqpBackend, QPBackend, QPProblem
from dualarm_control.status import Status


class LassoDual:
    """Exact minimiser of the lasso of eq (17) without its bounds, from its dual QP.

    min_qd 1/2 ||J qd - r||^2 + lambda ||qd||_1 (n variables) has the Lagrange dual

        min_w 1/2 ||w - r / lambda||^2   s.t.   -1 <= J^T w <= 1,

    a strictly convex QP in m (= 6) variables with n two-sided rows, scaled by lambda so
    that the back-end's tolerance is relative to the row bounds 1. Its stationarity
    condition w - r/lambda + J z = 0, with z the row multipliers, is the lasso's residual
    w = (r - J qd)/lambda for qd = lambda z, and complementarity (z_i != 0 only where
    J_i^T w = sign(z_i)) is the lasso's optimality condition J_i^T (r - J qd) = lambda sign(qd_i):
    so qd = lambda z is an exact minimiser, and an active-set back-end (daqp) returns a
    basic one, with at most m non-zero joints. Eq (19)'s 2n-variable QP has a semi-definite
    H, which daqp solves with a proximal-point outer loop: 48 us p50 (30 iterations) against
    8.8 us for this dual on the random set of docs/bench.md. When qd lies inside the bounds of eq (23) it is also the minimiser of
    eq (17) with the bounds (the optimum of a relaxation, and feasible).

    Used with an active-set back-end that reports multipliers (daqp): the dual's w is of
    order r/lambda (1e5 here), and a tolerance-based back-end's multipliers at eps 1e-9 are
    neither exact nor sparse. The back-end is owned: the QP's dimensions differ
    from eq (19)'s, so it keeps its own warm-start memory. H and the row bounds are built
    once per size (the back-ends do not modify their inputs).
    """

    def __init__(self, backend: QPBackend) -> None:
        self.backend = backend
        self._rows = backend.solve_rows if isinstance(backend, DaqpBackend) else None
        self._shape = (-1, -1)
        self._identity, self._upper, self._lower = np.eye(0), np.zeros(0), np.zeros(0)

    def reset(self) -> None:
        self.backend.reset()

    def solve(self, jacobian: FloatArray, reference: FloatArray, l1_weight: float) -> tuple[FloatArray | None, int]:
        """The minimiser for J (m, n), r (m,) [m/s; rad/s] and lambda > 0.

        Returns:
            (qd [rad/s] (n,), or None when the dual solve fails; back-end iterations).
        """
        if jacobian.shape != self._shape:
            m, n = self._shape = jacobian.shape
            self._identity, self._upper, self._lower = np.eye(m), np.ones(n), -np.ones(n)
        g = reference / -l1_weight
        if self._rows is not None:  # daqp: its arrays as they are, no QPProblem or QPSolution record per cycle
            x, status, iterations, _, z = self._rows(self._identity, g, jacobian.T, self._lower, self._upper)
        else:
            solution = self.backend.solve(QPProblem(H=self._identity, g=g, C=jacobian.T, l=self._lower,
                                                    u=self._upper))
            x, status, iterations, z = solution.x, solution.status, solution.iterations, solution.multipliers
        if x is None or status is not Status.SOLVED or z is None:
            return None, iterations
        return l1_weight * z, iterations
