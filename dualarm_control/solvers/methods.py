"""The kinematic solvers of paper 000, one class each, registered by name.

Notation: J (6, n) relative Jacobian, r = xd* + K e (6,) reference twist, Qd_min/Qd_max
velocity bounds of eq (23), qd_r repulsive velocity of eq (25). Units rad/s, m/s.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from dualarm_control.arrays import add_diagonal, split_columns
from dualarm_control.qp import QPProblem, check_backend
from dualarm_control.solvers import priority
from dualarm_control.solvers.base import Solver, SolverParams, from_qp
from dualarm_control.solvers.lapack import spd_solve
from dualarm_control.solvers.lasso_dual import LassoDual
from dualarm_control.solvers.policy import ROUND_OFF, bound_excess, inside
from dualarm_control.solvers.problem import ControlProblem, FloatArray
from dualarm_control.solvers.registry import register
from dualarm_control.solvers.slack_qp import INFINITY
from dualarm_control.status import FALLBACK_TRIGGERS, Status


@register("pseudo_inverse")
class PseudoInverse(Solver):
    """Closed-loop pseudo-inverse, eq (13): qd = J^+ (xd* + K e).

    Eq (13) has no constraints; to never command beyond eq (23) the result is shrunk
    uniformly (direction kept) until it fits the bounds, and the status is then "scaled".
    Shrinking toward 0 cannot reach the bounds of a joint beyond a position limit (its bounds
    exclude 0, :func:`dualarm_control.limits.velocity_bounds`): such a joint's velocity is
    set to the nearest bound (status "scaled", ``detail`` names the joints).

    Limit rows (the collision limit, ``A qd <= b``): the same uniform shrink also fits every row
    with b >= 0 (rest meets it). A row with b < 0 (a pair inside the safety distance: it must move
    apart) cannot be met by shrinking eq (13)'s direction, which is the task's: the pseudo-inverse
    then gives up, status "infeasible" with the row named, and the failure policy's separating
    step (:func:`~dualarm_control.solvers.policy.separating_step`) is commanded.
    """

    def _solve(self, problem: ControlProblem) -> tuple[FloatArray | None, Status, int, str]:
        qd = np.linalg.pinv(problem.jacobian, rcond=1e-6) @ problem.reference
        scale = 1.0
        for value, lo, hi in zip(qd, problem.lower, problem.upper, strict=True):
            if value > hi and value > 0:
                scale = min(scale, max(hi, 0.0) / value)
            elif value < lo and value < 0:
                scale = min(scale, min(lo, 0.0) / value)
        notes = []
        if problem.has_limit_rows:  # the same shrink fits the rows with b >= 0 (rest meets them)
            matrix = problem.limit_matrix()
            assert matrix is not None and problem.limit_bound is not None
            rows, bound = matrix @ qd, problem.limit_bound
            over = (rows > bound) & (bound >= 0.0)
            if over.any():
                row_scale = float(np.min(bound[over] / rows[over]))
                if row_scale < scale:
                    scale = row_scale
                    notes.append("limited by the limit rows")
        if scale < 1.0:
            qd = qd * scale
            notes.insert(0, f"scaled by {scale:.3g} into the joint bounds")
        beyond = (problem.lower > 0.0) | (problem.upper < 0.0)  # joints beyond a position limit
        if beyond.any():
            lo, hi = problem.lower[beyond], problem.upper[beyond]
            moved = (qd[beyond] < lo) | (qd[beyond] > hi)
            if moved.any():
                qd[beyond] = np.minimum(np.maximum(qd[beyond], lo), hi)
                notes.append(f"joints {np.flatnonzero(beyond)[moved].tolist()} (beyond a position limit) "
                             "set to their nearest bound")
        if problem.has_limit_rows and problem.limit_excess(qd) > ROUND_OFF:
            matrix = problem.limit_matrix()
            assert matrix is not None and problem.limit_bound is not None
            i = int(np.argmax(matrix @ qd - problem.limit_bound))
            label = problem.limit_labels[i] if i < len(problem.limit_labels) else f"row {i}"
            return None, Status.INFEASIBLE, 0, (f"limit row {label} not met by eq (13) shrunk into the bounds "
                                           f"(b = {problem.limit_bound[i]:.3g} m/s)")
        if notes:
            return qd, Status.SCALED, 0, "; ".join(notes)
        return qd, Status.SOLVED, 0, ""

    def _second_priority(self, problem: ControlProblem, qd1: FloatArray, status: Status, iters: int,
                         detail: str) -> tuple[FloatArray | None, Status, int, str]:
        """The task-priority form (:mod:`~dualarm_control.solvers.priority`): qd_1 + s (J_2 N_1)^+ (r_2 - J_2 qd_1),
        s the largest in [0, 1] that keeps the bounds and rows (status "scaled" when s < 1); nothing when the
        first priority itself had to be shrunk."""
        if status != Status.SOLVED:
            return qd1, status, iters, detail + "; second priority dropped (the first was scaled)"
        step = priority.task_priority_step(problem, qd1)
        scale = priority.largest_step(qd1, step, problem)
        if scale < 1.0:
            return qd1 + scale * step, Status.SCALED, iters, f"second priority scaled by {scale:.3g} into the bounds"
        return qd1 + step, status, iters, detail


def _least_squares_terms(problem: ControlProblem) -> tuple[FloatArray, FloatArray]:
    """J^T J (n, n) and J^T r (n,) of 1/2 ||J qd - r||^2."""
    j = problem.jacobian
    return j.T @ j, j.T @ problem.reference


class _QPSolver(Solver):
    """A solver that owns one QP back-end (and its warm-start memory).

    ``positive_definite`` tells whether the solver's H is positive definite; a back-end
    that needs a definite H is refused here, at start-up (see :func:`check_backend`).
    ``bound_tolerance`` is round-off plus ``tolerance_factor`` times the back-end's.
    """

    positive_definite = True
    qp_description = "QP"
    uses_qp = True
    tolerance_factor = 1.0
    """Back-end tolerances in the bound tolerance: 1 when qd is the QP's x, 2 when qd = qd+ - qd-."""

    def __init__(self, params: SolverParams | None = None) -> None:
        super().__init__(params)
        self._qp = self._backend()
        check_backend(self._qp, self.positive_definite, f"{self.name}'s {self.qp_description}")
        self.bound_tolerance = ROUND_OFF + self.tolerance_factor * self._qp.bound_tolerance

    def reset(self) -> None:
        super().reset()
        self._qp.reset()


@register("standard_qp")
class StandardQP(_QPSolver):
    """Standard QP, eq (14): min 1/2 ||J qd - r||^2 + eps/2 ||qd||^2  s.t. Qd_min <= qd <= Qd_max.

    J^T J has rank 6 < n, so eq (14) alone has a whole affine set of minimisers; the tiny
    term eps (``regularization``, default 1e-6) selects the minimum-norm one, as J^+ does.
    With eps = 0, H is only semi-definite. The QP is solved only when the unbounded
    minimiser (:func:`damped_least_squares`) leaves the bounds. The limits' rows (``A qd <= b``,
    the collision limit) are the QP's constraint rows, hard.
    """

    qp_description = "QP, eq (14)"

    def __init__(self, params: SolverParams | None = None) -> None:
        self.positive_definite = (params or SolverParams()).regularization > 0
        super().__init__(params)

    def _solve(self, problem: ControlProblem) -> tuple[FloatArray | None, Status, int, str]:
        qd = damped_least_squares(problem.jacobian, problem.reference, self.params.regularization)
        if qd is not None and inside(qd, problem.lower, problem.upper) and problem.limit_excess(qd) <= 0.0:
            return qd, Status.SOLVED, 0, ""  # eq (14)'s optimum: no bound and no row is active
        jtj, jtr = _least_squares_terms(problem)
        h = jtj  # a fresh array: add eps to its diagonal in place
        add_diagonal(h, self.params.regularization)
        box = QPProblem(H=h, g=-jtr, lb=problem.lower, ub=problem.upper)
        if problem.has_limit_rows:  # the relaxation first: rows that its optimum meets are not active
            relaxed = from_qp(self._qp.solve(box))
            if relaxed[0] is not None and relaxed[1] == Status.SOLVED and problem.limit_excess(relaxed[0]) <= 0.0:
                return relaxed
        return from_qp(self._qp.solve(QPProblem(H=h, g=-jtr, lb=problem.lower, ub=problem.upper,
                                                **limit_rows_of(problem))))


def limit_rows_of(problem: ControlProblem, columns: int = 1) -> dict[str, FloatArray]:
    """The limits' rows ``A qd <= b`` as a QP's constraint rows (C, l, u), none without rows.

    ``columns`` 2 writes them on z = [qd+; qd-] (qd = qd+ - qd-): C = [A, -A].
    """
    if not problem.has_limit_rows:
        return {}
    rows = problem.limit_matrix()
    assert rows is not None and problem.limit_bound is not None
    a = rows if columns == 1 else split_columns(rows)
    return {"C": a, "l": np.full(a.shape[0], -INFINITY), "u": problem.limit_bound}


def damped_least_squares(jacobian: FloatArray, reference: FloatArray, eps: float) -> FloatArray | None:
    """Minimiser of eq (14) without bounds: (J^T J + eps I)^-1 J^T r = J^T (J J^T + eps I)^-1 r.

    The second form solves an (m, m) system instead of (n, n); for eps = 0 it is J^+ r, the
    minimum-norm least-squares solution. When it lies inside the bounds it is eq (14)'s
    optimum (convex QP, KKT with no active bound).

    Args:
        jacobian: J (m, n); reference: r (m,) [m/s; rad/s]; eps: regularization >= 0.

    Returns:
        qd [rad/s], (n,), or None when J J^T + eps I is singular.
    """
    gram = jacobian @ jacobian.T
    add_diagonal(gram, eps)
    y = spd_solve(gram, reference)
    return None if y is None else jacobian.T @ y


def lasso_box(lower: FloatArray, upper: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Box of z = [qd+; qd-] that replaces the constraints of eq (19), shapes (n,) -> (2n,).

    Eq (19) has z >= 0 and Qd_min <= qd+ - qd- <= Qd_max. At an optimum qd+_i qd-_i = 0
    (lambda > 0 makes any overlap cost lambda without changing qd), so qd_i = qd+_i or -qd-_i
    and the constraints are exactly the box
    max(Qd_min, 0) <= qd+ <= max(Qd_max, 0),  max(-Qd_max, 0) <= qd- <= max(-Qd_min, 0):
    for Qd_min <= 0 <= Qd_max it is 0 <= qd+ <= Qd_max, 0 <= qd- <= -Qd_min; for a range
    above 0 (e.g. an acceleration bound around a positive command) qd- = 0 and qd+ spans it.
    No general constraint rows remain: a 2n-variable box-constrained QP.

    Args:
        lower, upper: Qd_min, Qd_max [rad/s], (n,), lower <= upper.

    Returns:
        (lb, ub) [rad/s], (2n,).
    """
    return np.maximum(np.concatenate((lower, -upper)), 0.0), np.maximum(np.concatenate((upper, -lower)), 0.0)


@register("sparse_qp")
class SparseQP(_QPSolver):
    """Lasso QP, eq (17)-(19) with the bounds of eq (23) (QP1 of eq (26)).

    min 1/2 ||J qd - r||^2 + lambda ||qd||_1  s.t. Qd_min <= qd <= Qd_max, solved as the
    standard QP of eq (19) in 2n variables z = [qd+; qd-], qd = qd+ - qd-:
    H = [J, -J]^T [J, -J] (2n, 2n), g = lambda 1_2n - [J, -J]^T r, and the bounds as the
    equivalent box of :func:`lasso_box` (no constraint rows but the limits': ``A qd <= b`` is
    ``[A, -A] z <= b``, :func:`limit_rows_of`). H has rank 6: only positive
    semi-definite, so back-ends that need a definite H are refused.

    Tie-break: with ``proximal_weight`` mu > 0 and a previous solution z_prev (none after
    construction or ``reset``), the QP gets the proximal term mu/2 ||z - z_prev||^2:
    H + mu I, g - mu z_prev, so each control cycle is one proximal-point step on the lasso.
    The exact lasso has near-ties (two joints whose columns of J are nearly parallel cost
    almost the same) and its solution jumps from one to the other as J changes: in the
    assembly run two left-wrist joints switched on and off 34.6 times per second, with
    steps of up to 74 rad/s^2 (mu = 1e-6: 1.46 per s, 1.3 rad/s^2). The proximal term
    keeps the previous choice unless the other is better by more than mu/2 ||dz||^2, and
    bounds the excess of the lasso objective by mu/2 ||z* - z_prev||^2 (docs/bench.md).
    Without a previous solution the cycle solves the exact lasso.

    Method: without the proximal term, and with an active-set back-end that reports
    multipliers (daqp), the lasso is first solved through its 6-variable dual
    (:class:`LassoDual`); when that minimiser is inside the bounds it is eq (19)'s optimum,
    otherwise (a bound is active) the box QP above is solved. With the proximal term the box
    QP is solved (H + mu I is then definite).
    """

    positive_definite = False
    qp_description = "lasso QP, eq (19)"
    tolerance_factor = 2.0  # qd = qd+ - qd-: each part within the back-end's tolerance of its box

    def __init__(self, params: SolverParams | None = None) -> None:
        super().__init__(params)
        self._previous: FloatArray | None = None  # the previous solution qd (n,), for the proximal term
        self._dual = LassoDual(self._backend()) if self._qp.active_set else None
        self.inside_last = False
        """Whether the last ``_solve`` returned the dual's minimiser after testing it inside the bounds (so that
        a level above need not test or clip it again)."""

    def reset(self) -> None:
        super().reset()
        if self._dual is not None:
            self._dual.reset()
        self._previous = None

    def seed(self, velocities: FloatArray) -> None:
        """The proximal term's z_prev from the previous command (no effect with mu = 0)."""
        self._previous = np.array(velocities, dtype=float)

    def _solve(self, problem: ControlProblem) -> tuple[FloatArray | None, Status, int, str]:
        if problem.has_limit_rows:  # the relaxation first (the box QP): rows its optimum meets are not active
            previous = self._previous
            relaxed = self._solve(problem.without_limit_rows())
            if relaxed[0] is not None and relaxed[1] == Status.SOLVED and problem.limit_excess(relaxed[0]) <= 0.0:
                return relaxed
            self._previous = previous  # the proximal centre stays the previous cycle's solution
        self.inside_last = False
        j = problem.jacobian
        n = j.shape[1]
        mu = self.params.proximal_weight
        prev = self._previous if mu > 0 and self._previous is not None and self._previous.shape == (n,) else None
        if prev is None and self._dual is not None:
            qd, iterations = self._dual.solve(j, problem.reference, self.params.l1_weight)
            if qd is not None and inside(qd, problem.lower, problem.upper) and problem.limit_excess(qd) <= 0.0:
                self._previous = qd
                self.inside_last = True
                return qd, Status.SOLVED, iterations, ""  # eq (17)'s optimum lies inside the bounds
        b = split_columns(j)  # J [I, -I], (6, 2n)
        h = b.T @ b
        g = self.params.l1_weight - b.T @ problem.reference
        if prev is not None:  # z_prev = [max(qd, 0); max(-qd, 0)]: the split of an optimum (no overlap)
            add_diagonal(h, mu)
            g -= mu * np.maximum(np.concatenate((prev, -prev)), 0.0)
        lb, ub = lasso_box(problem.lower, problem.upper)
        solution = self._qp.solve(QPProblem(H=h, g=g, lb=lb, ub=ub, **limit_rows_of(problem, 2)))
        qd, status, iterations, detail = from_qp(solution, lambda z: z[:n] - z[n:])
        self._previous = qd if solution.ok else None
        return qd, status, iterations, detail

    def _second_priority(self, problem: ControlProblem, qd1: FloatArray, status: Status, iters: int,
                         detail: str) -> tuple[FloatArray | None, Status, int, str]:
        """Eq (P2s) of :mod:`~dualarm_control.solvers.priority`: the second priority as a lasso in the optimal
        set of the first (its task velocity J_1 qd_1 kept), on the lasso box."""
        n = qd1.shape[0]
        qp = priority.sparse_level(problem, qd1, self.params.l1_weight, lasso_box(problem.lower, problem.upper))
        return self._second_result(self._priority_backend().solve(qp), qd1, status, iters, detail,
                                   lambda z: z[:n] - z[n:])


@register("hierarchical_sparse_qp")
class HierarchicalSparseQP(Solver):
    """Hierarchical sparse QP, eq (26)-(28).

    QP1 (eq 26) is :class:`SparseQP`. QP2 (eq 27) moves in the null space of the task toward
    the repulsive velocity of eq (25):

        qd2 = argmin 1/2 ||qd - qd_r||^2  s.t.  J qd = 0,  Qd_min - qd1 <= qd <= Qd_max - qd1,

    and the command is qd1 + qd2 (eq 28). The printed eq (27) reads ||qd - qd1||, which would
    pull the secondary motion toward the primary one; the text says QP2 realises the
    repulsive vector qd_r of Sect. IV-B, so qd_r is the target here. When qd_r = 0 (every
    joint inside its activation thresholds) qd2 = 0 is the exact optimum and QP2 is skipped.
    If QP2 fails, qd1 alone is commanded (the primary task is kept) and ``detail`` says so.
    QP2 is solved only when its unbounded minimiser (:func:`null_space_projection`) leaves
    the bounds. QP2 starts from qd1 clipped into the bounds; a qd1 beyond them by more than
    QP1's tolerance is returned as it is, so that :meth:`Solver.solve` reports it
    ("bounds_violated") instead of the clip hiding it. Bound tolerance: QP1's (twice the
    back-end's); qd1 clipped + qd2 lies within one back-end tolerance of the bounds. The limits'
    rows are hard in both levels: QP1's (:class:`SparseQP`) and QP2's, ``A qd2 <= b - A qd1``.
    """

    uses_repulsive = True
    uses_qp = True
    second_priority_in_solve = True  # the problem's second priority is the second level, the repulsion the third

    def __init__(self, params: SolverParams | None = None) -> None:
        super().__init__(params)
        self._primary = SparseQP(self.params)  # refuses a back-end needing a definite H
        self._secondary = self._backend()
        self.bound_tolerance = self._primary.bound_tolerance
        self._identity = np.eye(0)  # H of eq (27), rebuilt only when n changes

    def reset(self) -> None:
        super().reset()
        self._primary.reset()  # its second priority's QP too (the hierarchy's second level is QP1's solver's)
        self._secondary.reset()

    def seed(self, velocities: FloatArray) -> None:
        """QP1's proximal memory (QP2 has none: its optimum is unique)."""
        self._primary.seed(velocities)

    def _identity_of(self, n: int) -> FloatArray:
        if self._identity.shape != (n, n):
            self._identity = np.eye(n)
        return self._identity

    def _solve(self, problem: ControlProblem) -> tuple[FloatArray | None, Status, int, str]:
        qd1, status, iters, detail = self._primary._solve(problem)
        tested = self._primary.inside_last  # QP1 gave the dual's minimiser, tested inside the bounds
        if problem.has_secondary and qd1 is not None and status not in FALLBACK_TRIGGERS \
                and bound_excess(qd1, problem.lower, problem.upper) <= self.bound_tolerance:
            qd1 = np.minimum(np.maximum(qd1, problem.lower), problem.upper)  # absorbs QP1's tolerance
            qd1, status, iters, detail = self._primary._second_priority(problem, qd1, status, iters, detail)
            problem = problem.stacked()  # the repulsive level keeps both priorities' task velocities
            tested = False
        if qd1 is None or not problem.repulsive.any():
            return qd1, status, iters, detail  # no secondary motion, or a failure for solve() to handle
        if not tested:  # (a tested qd1 is inside: the test and the clip would leave it as it is)
            if not bound_excess(qd1, problem.lower, problem.upper) <= self.bound_tolerance:
                return qd1, status, iters, detail  # a failure for solve() to handle
            qd1 = np.minimum(np.maximum(qd1, problem.lower), problem.upper)  # absorbs QP1's tolerance
        return self._second_level(problem, qd1, status, iters, detail)

    def _second_level(self, problem: ControlProblem, qd1: FloatArray, status: Status, iters: int,
                      detail: str) -> tuple[FloatArray | None, Status, int, str]:
        """Eq (27)-(28) from QP1's result ``qd1`` (inside the bounds) and its status, iterations and detail."""
        lower2, upper2 = problem.lower - qd1, problem.upper - qd1
        qd2 = null_space_projection(problem.jacobian, problem.repulsive)
        if qd2 is not None and inside(qd2, lower2, upper2):
            qd = qd1 + qd2
            if problem.limit_excess(qd) <= 0.0:
                return qd, status, iters, detail  # eq (27)'s optimum: no bound and no row is active
        n = qd1.shape[0]
        qp2 = QPProblem(
            H=self._identity_of(n), g=-problem.repulsive, A=problem.jacobian, b=np.zeros(problem.jacobian.shape[0]),
            lb=lower2, ub=upper2,
        )
        sol = self._secondary.solve(qp2)  # the relaxation first: rows its optimum meets are not active
        if problem.has_limit_rows and (not sol.ok or problem.limit_excess(qd1 + sol.x) > 0.0):
            rows2 = limit_rows_of(problem)  # hard in QP2 too: A (qd1 + qd2) <= b
            rows2["u"] = rows2["u"] - rows2["C"] @ qd1
            sol = self._secondary.solve(QPProblem(H=qp2.H, g=qp2.g, A=qp2.A, b=qp2.b, lb=lower2, ub=upper2, **rows2))
        if not sol.ok:  # "max_iter" too: its x is an iterate, maybe beyond the bounds
            return qd1, status, iters + sol.iterations, f"secondary QP {sol.status}; primary task only"
        return qd1 + sol.x, status, iters + sol.iterations, detail


@register("hierarchical_sparse_l1_qp")
class HierarchicalSparseL1QP(HierarchicalSparseQP):
    """Hierarchical sparse QP whose second level stays sparse (issue 43): eq (26) as QP1, then, in place of
    eq (27)'s least-squares projection (its ||qd - qd_r||^2 asks every joint outside the zone for qd = 0
    in the l2 sense, which spreads one joint's repulsion over all of them),

        qd = argmin 1/2 sum_{i in Z} (qd_i - qd_r,i)^2 + lambda_2 sum_{i not in Z} |qd_i|
             s.t.  J qd = J qd1,  Qd_min <= qd <= Qd_max,  A qd <= b,

    with Z the joints in the repulsive zone of eq (24) (qd_r,i != 0, eq (25)) and lambda_2 =
    ``secondary_l1_weight`` (:class:`~dualarm_control.solvers.base.SolverParams`, default 0.1 rad/s: the
    trade-off between the joints kept out of the zone and the joints moving, docs/hierarchy.md). The first level's task velocity J qd1 is kept exactly (an equality, as eq
    (27)'s J qd2 = 0), the zone joints are driven toward the repulsive velocity, and the joints outside the
    zone pay the l1 norm of the whole command: a joint that QP1 moves costs what it did, a joint it left
    at rest costs lambda_2 |qd_i| to start, so the compensation of the zone joints' motion in the task
    is carried by few joints (a basic solution: at most m = 6 beyond QP1's). Solved as a QP in
    z = [qd+; qd-] (2n), qd = qd+ - qd-, on the box of :func:`lasso_box`:

        H = [[D, -D], [-D, D]],  D = diag(1_Z);   g = [-qd_r + lambda_2 1_{not Z}; qd_r + lambda_2 1_{not Z}];
        [J, -J] z = J qd1;   [A, -A] z <= b.

    H is semi-definite (back-ends that need a definite H are refused, as for QP1). Without a joint in
    the zone the command is qd1 (QP2 skipped: bit for bit the sparse QP); if QP2 fails, qd1 alone is
    commanded and ``detail`` says so.
    """

    def __init__(self, params: SolverParams | None = None) -> None:
        super().__init__(params)
        self._zone = b""  # the zone mask H was built for
        self._hessian = np.zeros((0, 0))

    def _second_level(self, problem: ControlProblem, qd1: FloatArray, status: Status, iters: int,
                      detail: str) -> tuple[FloatArray | None, Status, int, str]:
        """The l1 second level (class docstring) from QP1's result ``qd1`` (inside the bounds)."""
        zone = problem.repulsive != 0.0
        key = zone.tobytes()
        if key != self._zone:  # H depends on the zone's joints only: rebuilt when they change
            self._zone, self._hessian = key, secondary_l1_hessian(zone)
        h, g = self._hessian, secondary_l1_gradient(problem.repulsive, self.params.secondary_l1_weight)
        j = problem.jacobian
        split = split_columns(j)
        lb, ub = lasso_box(problem.lower, problem.upper)
        n = qd1.shape[0]
        sol = self._secondary.solve(QPProblem(H=h, g=g, A=split, b=j @ qd1, lb=lb, ub=ub))
        # the relaxation first: rows its optimum meets are not active (and are never built, DeferredRows)
        if problem.has_limit_rows and (not sol.ok or problem.limit_excess(sol.x[:n] - sol.x[n:]) > 0.0):
            sol = self._secondary.solve(QPProblem(H=h, g=g, A=split, b=j @ qd1, lb=lb, ub=ub,
                                                  **limit_rows_of(problem, 2)))
        if not sol.ok:  # "max_iter" too: its x is an iterate, maybe beyond the bounds
            return qd1, status, iters + sol.iterations, f"secondary l1 QP {sol.status}; primary task only"
        return sol.x[:n] - sol.x[n:], status, iters + sol.iterations, detail


def secondary_l1_hessian(zone: npt.NDArray[np.bool_]) -> FloatArray:
    """H (2n, 2n) of :class:`HierarchicalSparseL1QP`'s second level on z = [qd+; qd-] for the joints ``zone``
    (n,) in the repulsive zone: [[D, -D], [-D, D]], D = diag(zone) (the Hessian of 1/2 sum_Z (qd+ - qd-)^2)."""
    d = np.diag(zone.astype(float))
    return np.block([[d, -d], [-d, d]])


def secondary_l1_gradient(repulsive: FloatArray, l1_weight: float) -> FloatArray:
    """g (2n,) of the same second level: 1/2 sum_{i in Z} (qd_i - qd_r,i)^2 + l1_weight sum_{i not in Z} |qd_i|
    with Z = {i: qd_r,i != 0}, on z = [qd+; qd-]: [-qd_r + price; qd_r + price], price = l1_weight outside Z."""
    price = np.where(repulsive != 0.0, 0.0, l1_weight)
    return np.concatenate((price - repulsive, price + repulsive))


def null_space_projection(jacobian: FloatArray, velocity: FloatArray) -> FloatArray | None:
    """Projection of ``velocity`` onto the null space of J: v - J^T (J J^T)^-1 J v.

    This is the minimiser of eq (27) without its bounds, min 1/2 ||qd - qd_r||^2 s.t. J qd = 0;
    when it lies inside the bounds it is eq (27)'s optimum (the QP is strictly convex), so
    the QP is solved only when a bound is active.

    Args:
        jacobian: J (m, n), full row rank.
        velocity: qd_r [rad/s], (n,).

    Returns:
        (n,) [rad/s], or None when J J^T is singular.
    """
    y = spd_solve(jacobian @ jacobian.T, jacobian @ velocity)
    return None if y is None else velocity - jacobian.T @ y
