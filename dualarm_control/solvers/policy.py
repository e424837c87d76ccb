"""The solver failure policy: what a result beyond its bounds is, and what is commanded instead.

Failure policy (docs/safety.md, "Input validation and solver failure"): when a solver's QP
is infeasible, stops at its iteration cap, fails numerically, raises, or returns a
non-finite vector, the command is the best bounded least-squares step
(:func:`bounded_least_squares`), status "fallback" with the reason in ``detail``; if that
fails too, the bounded command nearest to rest (:func:`rest_command`). A result beyond a
velocity bound by more than the solver's ``bound_tolerance`` (its QP back-end's tolerance,
:attr:`~dualarm_control.solvers.base.Solver.bound_tolerance`) is a failure of its own, status "bounds_violated", with the
same command; within that tolerance the clip into the bounds absorbs the overshoot. Every
command is finite and inside the velocity bounds of eq (23).

:class:`~dualarm_control.solvers.base.Solver` applies it around every solver's ``_solve``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from dualarm_control.arrays import add_diagonal
from dualarm_control.qp import QPProblem, make_backend
from dualarm_control.solvers.problem import ControlProblem, FloatArray
from dualarm_control.solvers.slack_qp import slack_qp
from dualarm_control.status import FALLBACK_TRIGGERS, Status

ROUND_OFF = 1e-12
"""Bound tolerance of a closed form [rad/s]: floating-point round-off only (a pseudo-inverse
shrunk onto a bound, a sum of two bounded parts); bounds are at most a few rad/s, so this is
some 1e3 ulp of them."""
FALLBACK_DAMPING = 1e-6
"""Damping of :func:`bounded_least_squares` [(m/s)^2 per (rad/s)^2]: selects a small step
among the least-squares ones and keeps the problem well posed at singular configurations."""
FIXED_WIDTH = 1e-12
"""A joint's box narrower than this [rad/s] is a single speed: :func:`fixed_joints` fixes it before a fallback QP."""


SEPARATING_BACKENDS = ("daqp", "proxsuite")
"""The back-ends :func:`separating_step` tries in turn, then quadprog called directly (:func:`quadprog_solve`; no
qpsolvers import). The slack QP is badly conditioned (rho = 1e3 against a slack curvature of 1e-6) and degenerate
where the rows just touch a narrow box: on cases of ``test_properties.py`` daqp's dual active set failed (144-154
iterations), proxsuite called one "infeasible" (it is always feasible), and quadprog solved both."""


def load_fallback() -> None:
    """Import what :func:`bounded_least_squares` and :func:`separating_step` need (their back-ends).

    Called when a solver is built (:class:`~dualarm_control.solvers.base.Solver`), so that a
    first fallback inside the control loop never pays an import. The fallback needs no scipy:
    scipy.optimize cost every controller process 0.45-0.5 s of CPU to import (issue 38)."""
    for name in SEPARATING_BACKENDS:
        make_backend(name)
    import quadprog  # noqa: F401  (0.6 ms)


def fallback(problem: ControlProblem, qd: FloatArray | None, status: Status, detail: str) -> tuple[FloatArray, Status, str]:
    """The failure policy for a valid problem whose solver gave no usable result.

    Returns (velocities, status, detail): the bounded least-squares step with status
    "fallback" ("bounds_violated" for a result beyond its bounds), or :func:`rest_command`
    with the original failure status ("failed" for a "max_iter", non-finite or wrongly shaped
    result) when the least-squares step fails too.

    With hard limit rows (the collision limit), a least-squares step that breaks them is not
    commanded: :func:`separating_step` is (the rows relaxed as little as the box allows: it moves
    the pairs apart as fast as the bounds let it, or stops), and ``detail`` says by how much the
    rows were relaxed; when that fails too, the command nearest to rest. A solver that found its QP
    with rows infeasible goes to the separating step at once: the least-squares step lies in the box,
    which meets no point of the rows then (it cost 0.1-0.2 ms in every such cycle, e.g. the random
    set's worst cases, whose pairs are inside d_s).
    """
    if qd is not None and status not in FALLBACK_TRIGGERS and status != Status.BOUNDS_VIOLATED:
        status, detail = Status.FAILED, detail or f"solver returned non-finite velocities or shape {qd.shape}"
    reason = f"{status}: {detail or 'no solution'}"
    final_status = status if status == Status.BOUNDS_VIOLATED else Status.FALLBACK
    rows_infeasible = status == Status.INFEASIBLE and problem.has_limit_rows
    step = None if rows_infeasible else bounded_least_squares(problem.jacobian, problem.reference, problem.lower,
                                                              problem.upper)
    if step is not None and problem.limit_excess(step) <= ROUND_OFF:
        return step, final_status, f"{reason}; bounded least-squares step used"
    if problem.has_limit_rows:
        separated = separating_step(problem)
        if separated is not None:
            velocities, slack = separated
            relaxed = f", limit rows relaxed by up to {slack:.3g} m/s" if slack > ROUND_OFF else ""
            return velocities, final_status, f"{reason}; separating step used (limit rows hard{relaxed})"
    final = Status.FAILED if status == Status.MAX_ITER else status
    return rest_command(problem.lower, problem.upper), final, f"{reason}; bounded least squares failed, nearest-to-rest command"


SEPARATING_WEIGHT = 1e3
"""rho of :func:`separating_step`: the linear cost of a limit row's slack [per m/s], an exact penalty
(no slack while the rows are feasible with multipliers below rho)."""


def separating_step(problem: ControlProblem) -> tuple[FloatArray, float] | None:
    """The fallback when the limit rows conflict with the box (a pair already inside d_s that the
    box does not let move apart fast enough, or a solver that failed with rows):

        min 1/2 ||J qd - r||^2 + eps ||qd||^2 + rho 1^T s + mu/2 ||s||^2
        s.t. lower <= qd <= upper,  A qd - s <= b,  s >= 0

    (paper 001's slack QP, :func:`~dualarm_control.solvers.slack_qp.slack_qp`, with the
    limit rows as its inequality rows and rho = :data:`SEPARATING_WEIGHT`): where the rows can be
    met inside the box, s = 0 and this is the task's best step that meets them; where they cannot,
    the rows are relaxed by the least slack: the pair moves apart as fast as the box allows (zero
    approach where zero is all it allows: a stop). Joints whose box is a single speed are fixed at it
    first (:func:`fixed_joints`). Solved by daqp, or where daqp fails by the next of
    :data:`SEPARATING_BACKENDS`, then by quadprog (:func:`quadprog_solve`).

    Returns:
        (qd [rad/s] (n,), inside the box, the largest slack [m/s]); None when every back-end fails.
    """
    rows = problem.limit_matrix()
    assert rows is not None and problem.limit_bound is not None
    qd, free = fixed_joints(problem.lower, problem.upper)
    if not free.any():
        return qd, float(np.maximum(rows @ qd - problem.limit_bound, 0.0).max(initial=0.0))
    fixed = ~free
    bound = problem.limit_bound - rows[:, fixed] @ qd[fixed]
    jacobian = problem.jacobian[:, free]
    reference = problem.reference - problem.jacobian[:, fixed] @ qd[fixed]
    m = rows.shape[0]
    qp = slack_qp(jacobian, reference, problem.equality_weights, problem.lower[free], problem.upper[free],
                  FALLBACK_DAMPING, rows[:, free], bound, np.full(m, SEPARATING_WEIGHT))
    k = int(free.sum())
    for name in SEPARATING_BACKENDS:
        x = make_backend(name).solve(qp).x
        if x is not None and math.isfinite(float(x.sum())):
            break
    else:
        x = quadprog_solve(qp)
        if x is None:
            return None
    qd[free] = x[:k]
    return np.minimum(np.maximum(qd, problem.lower), problem.upper), float(x[k:].max(initial=0.0))


def fixed_joints(lower: FloatArray, upper: FloatArray) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """The joints whose bounds (nearly) coincide, fixed before a fallback QP: (the command nearest to
    rest, which holds those joints at their bounds [rad/s] (n,); the mask of the others, (n,)).

    A box of zero width is two opposite rows on the same point: quadprog's dual active set calls them
    inconsistent, and daqp and proxsuite failed such slack QPs too (a joint beyond its range whose box is
    the single speed back); with those joints substituted, the QP has only the free ones."""
    return rest_command(lower, upper), upper - lower > FIXED_WIDTH


def quadprog_solve(qp: QPProblem) -> FloatArray | None:
    """``qp`` (H positive definite) by quadprog's dual active set (Goldfarb-Idnani), called directly:
    min 1/2 x^T H x + g^T x s.t. M^T x >= c, M's columns the equality rows A (the first ``meq``), then the rows C,
    -C and the bounds +-I on their finite sides. None when quadprog refuses (ValueError: infeasible, H not
    positive definite) or gives a non-finite x."""
    import quadprog

    n = qp.H.shape[0]
    blocks, sides = [], []
    if qp.A is not None and qp.b is not None:
        blocks.append(qp.A)
        sides.append(qp.b)
    meq = 0 if not blocks else qp.A.shape[0]  # type: ignore[union-attr]
    eye = np.eye(n)
    for rows, low, high in ((qp.C, qp.l, qp.u), (eye, qp.lb, qp.ub)):
        if rows is None:
            continue
        for sign, side in ((1.0, low), (-1.0, high)):
            if side is not None:
                finite = np.isfinite(side)
                blocks.append(sign * rows[finite])
                sides.append(sign * side[finite])
    try:
        x = quadprog.solve_qp(qp.H, -qp.g, np.vstack(blocks).T, np.concatenate(sides), meq)[0]
    except ValueError:
        return None
    return x if np.isfinite(x).all() else None


def row_violation_text(problem: ControlProblem, qd: FloatArray, tolerance: float) -> str:
    """The worst limit row broken by qd (n,) [rad/s], for a "bounds_violated" detail."""
    rows = problem.limit_matrix()
    assert rows is not None and problem.limit_bound is not None
    over = rows @ qd - problem.limit_bound
    i = int(np.argmax(over))
    label = problem.limit_labels[i] if i < len(problem.limit_labels) else f"row {i}"
    return f"limit row {label} broken by {over[i]:.3g} m/s (tolerance {tolerance:.3g} m/s)"


def bound_excess(x: FloatArray, lower: FloatArray, upper: FloatArray) -> float:
    """How far x lies beyond [lower, upper] at its worst entry: max(lower - x, x - upper, 0).

    Args:
        x, lower, upper: (n,) [rad/s].

    Returns:
        The excess [rad/s], 0 when x is inside; NaN or inf when x is not finite, NaN when its
        shape is not (n,).
    """
    if x.shape != lower.shape:
        return math.nan
    return float(np.maximum(lower - x, x - upper).max(initial=0.0))


def violation_text(x: FloatArray, lower: FloatArray, upper: FloatArray, tolerance: float) -> str:
    """The worst bound violation of x, for a "bounds_violated" detail (shapes (n,), rad/s)."""
    below, above = lower - x, x - upper
    i = int(np.argmax(np.maximum(below, above)))
    side, bound = ("lower", lower[i]) if below[i] >= above[i] else ("upper", upper[i])
    return (f"joint {i} at {x[i]:.6g} rad/s beyond its {side} bound {bound:.6g} by {max(below[i], above[i]):.3g} "
            f"(tolerance {tolerance:.3g} rad/s)")


def inside(x: FloatArray, lower: FloatArray, upper: FloatArray) -> bool:
    """True when lower <= x <= upper everywhere (False for any NaN), shapes (n,).

    One pass (max(lower - x, x - upper) <= 0): twice as cheap as two np.all tests, and a
    closed form's result is tested this way every cycle."""
    return bool(np.maximum(lower - x, x - upper).max() <= 0.0)


def rest_command(lower: FloatArray, upper: FloatArray) -> FloatArray:
    """The command inside [lower, upper] nearest to rest: clip(0, lower, upper) [rad/s], (n,).

    Zero velocity while every joint is inside its position range (eq 23 contains 0); for a
    joint beyond a limit, the slowest motion back toward the range (:func:`velocity_bounds`).
    """
    return np.minimum(np.maximum(0.0, lower), upper)


def bounded_least_squares(jacobian: FloatArray, reference: FloatArray, lower: FloatArray, upper: FloatArray,
                          damping: float = FALLBACK_DAMPING) -> FloatArray | None:
    """The fallback step: argmin ||J qd - r||^2 + damping ||qd||^2  s.t.  lower <= qd <= upper.

    Eq (14) with its bounds (eq 23): the box QP min 1/2 qd^T (J^T J + damping I) qd - (J^T r)^T qd,
    solved by daqp (an active-set method, as BVLS; ``test_solvers.py`` checks it against scipy's
    ``lsq_linear``). The damping keeps H positive definite even where J is singular. Joints whose
    bounds (nearly) coincide are fixed at them first.

    Args:
        jacobian: J (m, n); reference: r (m,) [m/s; rad/s]; lower, upper: bounds [rad/s], (n,).
        damping: weight of ||qd||^2, > 0.

    Returns:
        qd [rad/s], (n,), finite and inside the bounds; None when the solve fails.
    """
    qd, free = fixed_joints(lower, upper)
    if not free.any():
        return qd
    j = jacobian[:, free]
    r = reference - jacobian[:, ~free] @ qd[~free]
    h = j.T @ j
    add_diagonal(h, damping)
    if not (math.isfinite(float(h.sum())) and math.isfinite(float(r.sum()))):
        return None
    solution = make_backend("daqp").solve(QPProblem(H=h, g=-(j.T @ r), lb=lower[free], ub=upper[free]))
    if not solution.ok or solution.x is None or solution.x.shape != (int(free.sum()),) \
            or not math.isfinite(float(solution.x.sum())):
        return None
    qd[free] = solution.x
    return np.minimum(np.maximum(qd, lower), upper)
