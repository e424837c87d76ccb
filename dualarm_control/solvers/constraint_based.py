"""Constraint-based programming with bound margins (paper 001, Wang et al., eq (3)-(6), (12)-(17)).

The QP of Lemma 1 over the joint velocities u = qd (n,):

    min  c^T u + u^T Q u
    s.t. A_ie u <= k_ie (b_ie - f_ie) - h_ie     (eq 13, inequality tasks)
         A_e  u  = k_e  (b_e  - f_e)  - h_e      (eq 14, equality tasks)

with each row given by a task (:mod:`dualarm_control.tasks`). Sect. 2 of the paper weights
a slack variable per constraint so that the QP stays solvable when constraints conflict.
Here, per row, with the weights of the tasks:

* equality rows: A_e u + s_e = r_e with cost 1/2 w_e s_e^2 (cheap): eliminated, this is the
  weighted least-squares term 1/2 ||W_e^(1/2) (A_e u - r_e)||^2;
* inequality rows: A_ie u - s_ie <= h, s_ie >= 0 with cost rho s_ie + 1/2 mu s_ie^2
  (expensive: rho = the row's weight, 1e3 by default). The linear term is an exact
  penalty: s_ie = 0 whenever the hard constraints are feasible with multipliers below rho;
  mu = ``SLACK_CURVATURE`` keeps H definite;
* the joint velocity/position limits of eq (21)-(23) are hard bounds lower <= u <= upper, and
  the limits' rows (the collision limit's velocity damper) hard rows ``A_l u <= b_l``.

Q = eps I with eps = ``regularization`` (paper's small cost on u against chattering) and
c = 0: the paper takes j = 1, an equality task, whose derivative is fixed by eq (14) on the
feasible set, so its linear term does not change the solution.

QP variables x = [u (n); s_ie (m_ie)]:

    H = [[2 eps I + A_e^T W_e A_e, 0], [0, mu I]],  g = [-A_e^T W_e r_e; rho],
    C = [[A_ie, -I], [A_l, 0]],  -inf <= C x <= [h; b_l],   [lower; 0] <= x <= [upper; +inf].

(:func:`~dualarm_control.solvers.slack_qp.slack_qp` builds it; the failure policy's separating
step uses the same QP.)
"""

from __future__ import annotations

import numpy as np

from dualarm_control.qp import QPProblem, check_backend
from dualarm_control.solvers.base import Solver, SolverParams, from_qp
from dualarm_control.solvers.methods import damped_least_squares
from dualarm_control.solvers.policy import ROUND_OFF, inside
from dualarm_control.solvers.problem import ControlProblem, FloatArray
from dualarm_control.solvers.registry import register
from dualarm_control.solvers.slack_qp import slack_qp
from dualarm_control.status import Status

SLACK_REPORT_THRESHOLD = 1e-9
"""An inequality slack above this is reported in ``detail`` [units of the row]."""


def constraint_qp(problem: ControlProblem, regularization: float) -> QPProblem:
    """The QP of the module docstring for one control problem (:func:`slack_qp`).

    Args:
        problem: equality rows (jacobian, reference, equality_weights), optional inequality
            rows (inequality_jacobian, inequality_bound, inequality_weights), bounds, and the
            limits' hard rows (limit_rows, limit_bound: no slack, as the joint bounds).
        regularization: eps of Q = eps I, >= 0.

    Returns:
        QPProblem over x = [u; s_ie], (n + m_ie) variables.
    """
    return slack_qp(problem.jacobian, problem.reference, problem.equality_weights, problem.lower, problem.upper,
                    regularization, problem.inequality_jacobian, problem.inequality_bound,
                    problem.inequality_weights, problem.limit_matrix(), problem.limit_bound)


@register("constraint_based")
class ConstraintBased(Solver):
    """Paper 001's bound-margin QP with weighted slacks (see the module docstring).

    Without inequality rows and with the unbounded minimiser inside the joint bounds, the
    solution is the weighted damped least squares (:func:`damped_least_squares` on
    W_e^(1/2) A_e, damping 2 eps) and no QP is solved.
    """

    uses_qp = True
    supports_inequalities = True
    """Reads ``ControlProblem.inequality_*`` (the solvers of paper 000 ignore them)."""

    def __init__(self, params: SolverParams | None = None) -> None:
        super().__init__(params)
        self._qp = self._backend()
        check_backend(self._qp, self.params.regularization > 0, f"{self.name}'s QP (eq 12-14)")
        self.bound_tolerance = ROUND_OFF + self._qp.bound_tolerance  # u = x[:n], within the box to eps_abs

    def reset(self) -> None:
        super().reset()
        self._qp.reset()

    def _solve(self, problem: ControlProblem) -> tuple[FloatArray | None, Status, int, str]:
        n = problem.jacobian.shape[1]
        a_ie = problem.inequality_jacobian
        if a_ie is None or a_ie.shape[0] == 0:
            scale = 1.0 if problem.equality_weights is None else np.sqrt(problem.equality_weights)
            qd = damped_least_squares(problem.jacobian * np.reshape(scale, (-1, 1)), problem.reference * scale,
                                      2.0 * self.params.regularization)
            if qd is not None and inside(qd, problem.lower, problem.upper) and problem.limit_excess(qd) <= 0.0:
                return qd, Status.SOLVED, 0, ""
        if problem.has_limit_rows:  # the relaxation first: rows its optimum meets are not active
            relaxed = self._solve(problem.without_limit_rows())
            if relaxed[0] is not None and relaxed[1] == Status.SOLVED and problem.limit_excess(relaxed[0]) <= 0.0:
                return relaxed
        solution = self._qp.solve(constraint_qp(problem, self.params.regularization))
        qd, status, iters, detail = from_qp(solution, lambda x: x[:n])
        if solution.x is not None and solution.x.shape[0] > n:
            slack = float(solution.x[n:].max())
            if slack > SLACK_REPORT_THRESHOLD:
                detail = (detail + "; " if detail else "") + f"inequality relaxed: max slack {slack:.3g}"
        return qd, status, iters, detail
