"""The second priority of a control problem (issue 41: the absolute pose under the relative pose), in every solver.

The first priority's task (J_1 (m, n), r_1) is solved as the solver always does: qd_1. The second priority's
(J_2 (m_2, n), r_2, :attr:`~dualarm_control.solvers.problem.ControlProblem.secondary_jacobian`) is then realised
in the set of the first priority's optima. The first level's objective depends on qd through J_1 qd, strictly
convexly (1/2 ||J_1 qd - r_1||^2), plus a term on qd (eps/2 ||qd||^2, lambda ||qd||_1): every optimum without
that term has the same task velocity J_1 qd_1, so the set is

    S_1 = {qd : J_1 qd = J_1 qd_1,  lower <= qd <= upper,  A qd <= b}          (bounds and rows of every limit)

and the second level (a lexicographic least-squares QP, Kanoun et al.; the first level's small term moves to the
last level as its tie-break) is

    least squares:  qd* = argmin_{qd in S_1} 1/2 ||J_2 qd - r_2||^2 + eps/2 ||qd||^2                   (eq P2)
    sparse:         qd* = argmin_{qd in S_1} 1/2 ||J_2 qd - r_2||^2 + lambda ||qd||_1                  (eq P2s)

(eq P2s on z = [qd+; qd-] (2n), as eq (19) of paper 000). The closed-loop pseudo-inverse takes the classical
task-priority form, qd = J_1^+ r_1 + (J_2 N_1)^+ (r_2 - J_2 J_1^+ r_1), N_1 = I - J_1^+ J_1 (Siciliano and
Slotine 1991), the second part shrunk first into the bounds. The constraint-based QP (paper 001) keeps its
inequality rows at the first level's slack: A_ie qd <= max(h, A_ie qd_1).

Units: rad/s for qd, m/s and rad/s for the task rows.
"""

from __future__ import annotations

import numpy as np

from dualarm_control.arrays import FloatArray, add_diagonal, split_columns
from dualarm_control.qp import QPProblem
from dualarm_control.solvers.problem import ControlProblem
from dualarm_control.solvers.slack_qp import INFINITY

RANK_TOLERANCE = 1e-9
"""Singular values of J_1 below this times the largest span no task direction: their right singular vectors
belong to the null space [-]."""


def null_space_basis(jacobian: FloatArray) -> FloatArray:
    """An orthonormal basis Z (n, n - r) of the null space of J (m, n): J Z = 0, Z^T Z = I (r = rank J, from
    the SVD with :data:`RANK_TOLERANCE`)."""
    _, s, vt = np.linalg.svd(jacobian)
    rank = int(np.count_nonzero(s > RANK_TOLERANCE * (s[0] if s.size else 0.0)))
    out: FloatArray = vt[rank:].T
    return out


def unbounded_second_level(problem: ControlProblem, qd1: FloatArray, eps: float) -> FloatArray:
    """Eq (P2) without bounds and rows: qd = qd_1 + Z y, y = (Z^T J_2^T J_2 Z + eps I)^-1 (Z^T J_2^T (r_2 - J_2 qd_1)
    - eps Z^T qd_1), Z = :func:`null_space_basis` of J_1 (the minimum-norm y by least squares when eps = 0).

    Args:
        problem: J_1, J_2 (m, n), (m_2, n); r_2 (m_2,). qd1: the first level's qd [rad/s] (n,). eps: >= 0.

    Returns:
        qd [rad/s] (n,), with J_1 qd = J_1 qd_1 to round-off.
    """
    j2, r2 = problem.secondary_jacobian, problem.secondary_reference
    assert j2 is not None and r2 is not None
    z = null_space_basis(problem.jacobian)
    if z.shape[1] == 0:
        return qd1.copy()
    j2z = j2 @ z
    residual = r2 - j2 @ qd1
    if eps > 0.0:
        gram = j2z.T @ j2z
        add_diagonal(gram, eps)
        y = np.linalg.solve(gram, j2z.T @ residual - eps * (z.T @ qd1))
    else:
        y = np.linalg.lstsq(j2z, residual, rcond=None)[0]
    out: FloatArray = qd1 + z @ y
    return out


def kept_inequalities(problem: ControlProblem, qd1: FloatArray) -> tuple[FloatArray, FloatArray] | None:
    """The first level's inequality rows at its slack, (A_ie (m_ie, n), max(h, A_ie qd_1) (m_ie,)), or None
    without inequality rows: the second level may not relax them further."""
    a, h = problem.inequality_jacobian, problem.inequality_bound
    if a is None or h is None or a.shape[0] == 0:
        return None
    return a, np.maximum(h, a @ qd1)


def rows_of(problem: ControlProblem, qd1: FloatArray, columns: int = 1) -> dict[str, FloatArray]:
    """The hard rows of the second level as a QP's C, l, u: the limits' rows and :func:`kept_inequalities`;
    ``columns`` 2 writes them on z = [qd+; qd-]. Empty without rows."""
    blocks, bounds = [], []
    kept = kept_inequalities(problem, qd1)
    if kept is not None:
        blocks.append(kept[0])
        bounds.append(kept[1])
    if problem.has_limit_rows:
        matrix = problem.limit_matrix()
        assert matrix is not None and problem.limit_bound is not None
        blocks.append(matrix)
        bounds.append(problem.limit_bound)
    if not blocks:
        return {}
    c = np.vstack(blocks)
    c = c if columns == 1 else split_columns(c)
    return {"C": c, "l": np.full(c.shape[0], -INFINITY), "u": np.concatenate(bounds)}


def least_squares_level(problem: ControlProblem, qd1: FloatArray, eps: float) -> QPProblem:
    """Eq (P2) as a QP over qd (n): H = J_2^T J_2 + eps I, g = -J_2^T r_2, A = J_1, b = J_1 qd_1, the box and
    :func:`rows_of`."""
    j2, r2 = problem.secondary_jacobian, problem.secondary_reference
    assert j2 is not None and r2 is not None
    h = j2.T @ j2
    add_diagonal(h, eps)
    return QPProblem(H=h, g=-(j2.T @ r2), A=problem.jacobian, b=problem.jacobian @ qd1, lb=problem.lower,
                     ub=problem.upper, **rows_of(problem, qd1))


def sparse_level(problem: ControlProblem, qd1: FloatArray, l1_weight: float, box: tuple[FloatArray, FloatArray]
                 ) -> QPProblem:
    """Eq (P2s) as a QP over z = [qd+; qd-] (2n): H = B_2^T B_2, B_2 = [J_2, -J_2], g = lambda 1 - B_2^T r_2,
    [J_1, -J_1] z = J_1 qd_1, ``box`` the lasso box of the bounds (:func:`~dualarm_control.solvers.methods.lasso_box`)
    and :func:`rows_of` on z."""
    j2, r2 = problem.secondary_jacobian, problem.secondary_reference
    assert j2 is not None and r2 is not None
    b2 = split_columns(j2)
    j1 = problem.jacobian
    return QPProblem(H=b2.T @ b2, g=l1_weight - b2.T @ r2, A=split_columns(j1), b=j1 @ qd1, lb=box[0],
                     ub=box[1], **rows_of(problem, qd1, 2))


def task_priority_step(problem: ControlProblem, qd1: FloatArray) -> FloatArray:
    """The pseudo-inverse's second priority: d = (J_2 N_1)^+ (r_2 - J_2 qd_1), N_1 = I - J_1^+ J_1, (n,) [rad/s]
    (J_1 d = 0: d lies in the row space of J_2 N_1, inside the null space of J_1)."""
    j2, r2 = problem.secondary_jacobian, problem.secondary_reference
    assert j2 is not None and r2 is not None
    j1 = problem.jacobian
    projector = np.eye(j1.shape[1]) - np.linalg.pinv(j1, rcond=1e-6) @ j1
    out: FloatArray = np.linalg.pinv(j2 @ projector, rcond=1e-6) @ (r2 - j2 @ qd1)
    return out


def largest_step(start: FloatArray, direction: FloatArray, problem: ControlProblem) -> float:
    """The largest s in [0, 1] with start + s direction inside the bounds and the limits' rows, for a ``start``
    (n,) inside them [rad/s]; 0 when ``start`` is not."""
    scale = 1.0
    for value, step, lo, hi in zip(start, direction, problem.lower, problem.upper, strict=True):
        if value < lo or value > hi:
            return 0.0
        if value + step > hi:
            scale = min(scale, (hi - value) / step)
        elif value + step < lo:
            scale = min(scale, (lo - value) / step)
    if problem.has_limit_rows:
        matrix = problem.limit_matrix()
        assert matrix is not None and problem.limit_bound is not None
        room, rate = problem.limit_bound - matrix @ start, matrix @ direction
        if np.any(room < 0.0):
            return 0.0
        over = rate > room
        if over.any():
            scale = min(scale, float(np.min(room[over] / rate[over])))
    return max(scale, 0.0)
