"""What every kinematic solver takes and returns, and the solver failure policy.

A solver is a pure function of the problem (Jacobian, reference twist, velocity bounds,
repulsive velocity) to joint velocities, plus its own warm-start memory. The same object
serves the in-process experiment, the controller node and the benchmark.

Failure policy (docs/safety.md, "Input validation and solver failure"): when a solver's QP
is infeasible, stops at its iteration cap, fails numerically, raises, or returns a
non-finite vector, the command is the best bounded least-squares step
(:func:`bounded_least_squares`), status "fallback" with the reason in ``detail``; if that
fails too, the bounded command nearest to rest (:func:`rest_command`). A result beyond a
velocity bound by more than the solver's ``bound_tolerance`` (its QP back-end's tolerance,
:attr:`Solver.bound_tolerance`) is a failure of its own, status "bounds_violated", with the
same command; within that tolerance the clip into the bounds absorbs the overshoot. Every
command is finite and inside the velocity bounds of eq (23).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

# scipy.optimize imported here, not in the fallback: a first import inside the loop takes ~0.3 s
from scipy.optimize import lsq_linear

from dualarm_control.limits.base import DeferredRows
from dualarm_control.qp import DEFAULT_BACKEND, QPSettings, QPSolution, make_backend
from dualarm_control.solvers.slack_qp import slack_qp
from dualarm_control.status import FAILURE_STATUSES, FALLBACK_TRIGGERS, Status

FloatArray = npt.NDArray[np.float64]

ACTIVITY_THRESHOLD = 1e-3
"""A joint is active when |qd_i| > 1e-3 rad/s (paper 000, Fig. 5 and Table I)."""

ROUND_OFF = 1e-12
"""Bound tolerance of a closed form [rad/s]: floating-point round-off only (a pseudo-inverse
shrunk onto a bound, a sum of two bounded parts); bounds are at most a few rad/s, so this is
some 1e3 ulp of them."""
FALLBACK_DAMPING = 1e-6
"""Damping of :func:`bounded_least_squares` [(m/s)^2 per (rad/s)^2]: selects a small step
among the least-squares ones and keeps the problem well posed at singular configurations."""


@dataclass(slots=True)
class ControlProblem:
    """Inputs of one control cycle.

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by convention.

    Attributes:
        jacobian: relative Jacobian J of eq (5), (6, n); (6 k, n) for k relative tasks stacked
            (the benchmark's 3- and 4-arm chains).
        reference: closed-loop reference twist xd* + K e of eq (13)/(26) [m/s; rad/s], (6,) or (6 k,).
        lower, upper: joint velocity bounds Qd_min, Qd_max of eq (23) [rad/s], (n,).
        repulsive: repulsive joint velocity qd_r of eq (25) [rad/s], (n,); used by the
            hierarchical solver's secondary task only.
        inequality_jacobian: A_ie of paper 001 eq (13), (m_ie, n), or None (no inequality
            rows; the solvers of paper 000 ignore them).
        inequality_bound: h of ``A_ie qd <= h``, k(b - f) - df/dt of eq (13), (m_ie,).
        equality_weights: slack weight of each row of ``jacobian`` (>= 0), (m,), or None (1).
        inequality_weights: slack weight of each inequality row (> 0), (m_ie,), or None.
        limit_rows: hard rows ``limit_rows @ qd <= limit_bound`` of the limits beyond the box, (m_l, n), or
            None: the collision limit's velocity damper (:mod:`dualarm_control.limits.collision`). Every
            solver takes them as hard constraints (docs/collision.md, "Limits").
        limit_bound: their right-hand side [m/s], (m_l,).
        limit_labels: what each row keeps apart (the link pair), m_l strings, for reports.
        limit_deferred: the rows given instead as :class:`~dualarm_control.limits.DeferredRows`
            (limit_rows None): built only when a solver needs them (:meth:`limit_matrix`); where
            their speed bound vouches for a qd (:meth:`limit_excess`), they are not.
    """

    jacobian: FloatArray
    reference: FloatArray
    lower: FloatArray
    upper: FloatArray
    repulsive: FloatArray
    inequality_jacobian: FloatArray | None = None
    inequality_bound: FloatArray | None = None
    equality_weights: FloatArray | None = None
    inequality_weights: FloatArray | None = None
    limit_rows: FloatArray | None = None
    limit_bound: FloatArray | None = None
    limit_labels: tuple[str, ...] = ()
    limit_deferred: DeferredRows | None = None

    @property
    def has_limit_rows(self) -> bool:
        """Whether the problem has at least one hard limit row."""
        return (self.limit_rows is not None and self.limit_rows.shape[0] > 0) or self.limit_deferred is not None

    def limit_matrix(self) -> FloatArray | None:
        """A of the hard limit rows (m_l, n), built now when deferred; None without rows."""
        if self.limit_rows is None and self.limit_deferred is not None:
            self.limit_rows = self.limit_deferred.matrix
        return self.limit_rows

    def limit_excess(self, qd: FloatArray) -> float:
        """How far qd (n,) [rad/s] breaks the hard limit rows at their worst: max(A qd - b, 0) [m/s]
        (0 without building deferred rows where their speed bound vouches for qd)."""
        if self.limit_bound is None or not self.has_limit_rows:
            return 0.0
        if self.limit_rows is None and self.limit_deferred is not None and self.limit_deferred.meets(qd):
            return 0.0
        a = self.limit_matrix()
        assert a is not None
        return float((a @ qd - self.limit_bound).max(initial=0.0))

    def without_limit_rows(self) -> ControlProblem:
        """The same problem without the limits' rows (its relaxation: a solution of it that meets the
        rows solves the problem with them, as the QPs are convex)."""
        return ControlProblem(self.jacobian, self.reference, self.lower, self.upper, self.repulsive,
                              self.inequality_jacobian, self.inequality_bound, self.equality_weights,
                              self.inequality_weights)

    def problem_with_invalid_input(self) -> str:
        """Return a description of what is wrong with the inputs, or '' when they are usable.

        Runs every cycle, so the common case costs four reductions: shapes are compared as
        tuples, and one sum is finite only if J, the reference and the repulsive velocity are
        finite and g = max(lower - upper) is finite (a NaN or an infinite bound makes it NaN
        or +-inf). g > 1e-12 means crossing bounds. Only when a test fails are the arrays
        examined one by one to name the culprit.
        """
        m, n = self.jacobian.shape if self.jacobian.ndim == 2 else (-1, -1)
        if m < 1 or self.reference.shape != (m,):
            return f"bad shapes: J {self.jacobian.shape}, reference {self.reference.shape}"
        if self.lower.shape != (n,) or self.upper.shape != (n,) or self.repulsive.shape != (n,):
            for name in ("lower", "upper", "repulsive"):
                if getattr(self, name).shape != (n,):
                    return f"bad shape of {name}: {getattr(self, name).shape}, expected ({n},)"
        gap = (self.lower - self.upper).max()
        if not math.isfinite(self.jacobian.sum() + self.reference.sum() + self.repulsive.sum() + gap):
            for name in ("jacobian", "reference", "lower", "upper", "repulsive"):
                if not np.all(np.isfinite(getattr(self, name))):
                    return f"non-finite values in {name}"
        if self.inequality_jacobian is not None or self.inequality_bound is not None \
                or self.equality_weights is not None or self.inequality_weights is not None \
                or self.limit_rows is not None or self.limit_bound is not None or self.limit_deferred is not None:
            optional = self._problem_with_optional_rows(m, n)
            if optional:
                return optional
        if gap > 1e-12:
            i = int(np.argmax(self.lower - self.upper))
            return f"velocity bounds cross at joint {i}: lower {self.lower[i]:.4g} > upper {self.upper[i]:.4g} (joint outside its position range)"
        return ""

    def _problem_with_optional_rows(self, m: int, n: int) -> str:
        """Shapes and finiteness of the optional inequality rows and weights ('' when usable)."""
        a, h = self.inequality_jacobian, self.inequality_bound
        if (a is None) != (h is None):
            return "inequality_jacobian and inequality_bound must be given together"
        m_ie = 0
        if a is not None and h is not None:
            m_ie = a.shape[0] if a.ndim == 2 else -1
            if a.shape != (m_ie, n) or h.shape != (m_ie,):
                return f"bad shapes: inequality_jacobian {a.shape}, inequality_bound {h.shape}"
            if not math.isfinite(a.sum() + h.sum()):
                return "non-finite values in the inequality rows"
        a, h = self.limit_rows, self.limit_bound
        if a is None and self.limit_deferred is not None:  # checked without building the rows: their speed bound
            a = self.limit_deferred.speed
        if (a is None) != (h is None):
            return "limit_rows and limit_bound must be given together"
        if a is not None and h is not None:
            m_l = a.shape[0] if a.ndim == 2 else -1
            if a.shape != (m_l, n) or h.shape != (m_l,):
                return f"bad shapes: limit_rows {a.shape}, limit_bound {h.shape}"
            if not math.isfinite(a.sum() + h.sum()):
                return "non-finite values in the limit rows"
        for name, size in (("equality_weights", m), ("inequality_weights", m_ie)):
            w = getattr(self, name)
            if w is None:
                continue
            if w.shape != (size,):
                return f"bad shape of {name}: {w.shape}, expected ({size},)"
            if not math.isfinite(w.sum()) or w.min(initial=0.0) < 0:
                return f"{name} must be finite and >= 0"
        return ""


@dataclass(slots=True)
class SolverResult:
    """One solver call.

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by convention.

    Attributes:
        velocities: joint velocities to command [rad/s], (n,); always finite and inside
            the bounds (the safe command on failure).
        status: "solved", "scaled" (pseudo-inverse shrunk into the bounds), "fallback"
            (the solver failed; the bounded least-squares step is used, the reason in
            ``detail``), or a failure: "bounds_violated" (the solver's result lies beyond
            a bound by more than its ``bound_tolerance``; velocities is the fallback's
            command, ``detail`` says which and where), "infeasible", "failed" (the
            fallback failed too: velocities is :func:`rest_command`), "invalid_input"
            (zero velocities).
        solve_time: wall time of the whole call [s].
        iterations: QP iterations summed over the QPs solved (0 for closed forms).
        active_joints: count of |qd_i| > 1e-3 rad/s.
        task_residual: ||J qd - reference||_2 [m/s, rad/s mixed].
        detail: human-readable reason for a fallback or a degraded result, else ''.
        raw_velocities: what the solver itself returned [rad/s], (n,), before the clip into
            the bounds or the failure policy; None when it returned nothing (no solution,
            an exception, invalid input, or a record not made by :meth:`Solver.solve`).
        bound_excess: how far ``raw_velocities`` lies beyond [lower, upper] at its worst
            joint, max(lower - qd, qd - upper, 0) [rad/s] (:func:`bound_excess`); NaN when
            there is no raw result, NaN or inf when it is not finite. "solved"/"scaled" results have
            ``bound_excess <= solver.bound_tolerance``.
    """

    velocities: FloatArray
    status: Status
    solve_time: float
    iterations: int
    active_joints: int
    task_residual: float
    detail: str = ""
    raw_velocities: FloatArray | None = None
    bound_excess: float = math.nan

    @property
    def failed(self) -> bool:
        return self.status in FAILURE_STATUSES

    @property
    def fell_back(self) -> bool:
        """The solver failed and the bounded least-squares step was commanded."""
        return self.status == Status.FALLBACK


@dataclass(frozen=True)
class SolverParams:
    """Parameters of the kinematic solvers (validated).

    Attributes:
        l1_weight: lambda of eq (17)/(26) [ (m/s)^2 per rad/s ], > 0; paper: 1e-6.
        regularization: epsilon of the standard QP's tie-break term eps/2 ||qd||^2 that selects
            the minimum-norm solution among the least-squares ones, like J^+ (eq 13-14), >= 0.
        proximal_weight: mu of the sparse QPs' proximal term mu/2 ||z - z_prev||^2 around the
            previous lasso solution [(m/s)^2 per (rad/s)^2], >= 0; 0 = the exact lasso of eq (19)
            every cycle. Default 1e-6 (docs/bench.md: chatter vs mu).
            See :class:`dualarm_control.solvers.methods.SparseQP`.
        secondary_l1_weight: lambda_2 [rad/s] of ``hierarchical_sparse_l1_qp``'s second level, > 0: the price
            of moving a joint outside eq (24)'s repulsive zone (docs/hierarchy.md). Default 0.1.
        qp_backend: "daqp" (default), "proxsuite" or a qpsolvers solver name (see dualarm_control.qp).
        qp: numerical settings of the QP back-end.
    """

    l1_weight: float = 1e-6
    regularization: float = 1e-6
    proximal_weight: float = 1e-6
    secondary_l1_weight: float = 0.1
    qp_backend: str = DEFAULT_BACKEND
    qp: QPSettings = field(default_factory=QPSettings)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.l1_weight) and self.l1_weight > 0):
            raise ValueError(f"l1_weight must be > 0, got {self.l1_weight}")
        if not (np.isfinite(self.regularization) and self.regularization >= 0):
            raise ValueError(f"regularization must be >= 0, got {self.regularization}")
        if not (np.isfinite(self.proximal_weight) and self.proximal_weight >= 0):
            raise ValueError(f"proximal_weight must be >= 0, got {self.proximal_weight}")
        if not (np.isfinite(self.secondary_l1_weight) and self.secondary_l1_weight > 0):
            raise ValueError(f"secondary_l1_weight must be > 0, got {self.secondary_l1_weight}")


class Solver:
    """Base class: validation, timing, clipping and the failure policy around ``_solve``.

    Failure policy: a result with status in ``FALLBACK_TRIGGERS`` ("infeasible", "max_iter",
    "failed"), an exception (ValueError, LinAlgError, RuntimeError) or a non-finite vector
    (or one of the wrong shape) is replaced by :func:`bounded_least_squares` (status
    "fallback", ``detail`` names the original failure), else by :func:`rest_command` (the
    original failure status). A result beyond a bound by more than ``bound_tolerance`` gets
    the same command and status "bounds_violated" (a failure: the solver broke its
    constraints); within ``bound_tolerance`` it is clipped into the bounds. Invalid input
    (NaN, wrong shapes, crossing bounds) gives zero velocity, status "invalid_input".
    Warm-start memory is reset after any failure. The solver's own result is kept in
    ``SolverResult.raw_velocities``.
    """

    name = "base"
    bound_tolerance = ROUND_OFF
    """How far beyond a velocity bound the result of ``_solve`` may lie and still count as inside
    [rad/s]: :data:`ROUND_OFF` for a closed form; a QP solver adds its back-end's tolerance
    (:attr:`dualarm_control.qp.QPBackend.bound_tolerance`), twice for the lasso's split
    qd = qd+ - qd-. Set at construction."""
    uses_repulsive = False
    """Whether ``_solve`` reads ``ControlProblem.repulsive`` (callers may pass zeros otherwise)."""
    uses_qp = False
    """Whether the solver solves QPs (and so depends on ``qp_backend``)."""

    def __init__(self, params: SolverParams | None = None) -> None:
        self.params = params or SolverParams()

    def reset(self) -> None:
        """Forget warm-start memory (e.g. after a discontinuity)."""

    def seed(self, velocities: FloatArray) -> None:
        """Start from ``velocities`` [rad/s], (n,), the command of the cycle before, as if this
        solver had produced it (a live change of solver; :meth:`RelativeController.continue_from`).

        Default: nothing, for a solver whose result does not depend on its memory (a closed form,
        or a strictly convex QP whose warm start only changes the iteration count). The sparse QPs
        take it as the centre z_prev of their proximal term."""

    def _backend(self):
        return make_backend(self.params.qp_backend, self.params.qp)

    def _solve(self, problem: ControlProblem) -> tuple[FloatArray | None, Status, int, str]:
        """Return (velocities or None, status, iterations, detail)."""
        raise NotImplementedError

    def solve(self, problem: ControlProblem) -> SolverResult:
        """Solve one cycle; never raises on numerical trouble, never returns NaN or leaves the bounds."""
        start = time.perf_counter()
        n = problem.jacobian.shape[1] if problem.jacobian.ndim == 2 else problem.lower.shape[0]
        invalid = problem.problem_with_invalid_input()
        raw: FloatArray | None = None
        excess = math.nan
        if invalid:
            qd: FloatArray = np.zeros(max(n, 0))
            status, iters, detail, residual = Status.INVALID_INPUT, 0, invalid, float("nan")
        else:
            qd, raw, excess, status, iters, detail = self._solve_or_fall_back(problem)
            d = problem.jacobian @ qd - problem.reference
            residual = math.sqrt(float(d @ d))
        return SolverResult(
            velocities=qd,
            status=status,
            solve_time=time.perf_counter() - start,
            iterations=iters,
            active_joints=int(np.count_nonzero(np.abs(qd) > ACTIVITY_THRESHOLD)),
            task_residual=residual,
            detail=detail,
            raw_velocities=raw,
            bound_excess=excess,
        )

    def _solve_or_fall_back(self, problem: ControlProblem
                            ) -> tuple[FloatArray, FloatArray | None, float, Status, int, str]:
        """``_solve`` on a valid problem, then the clip or the failure policy.

        Returns (command, the solver's own result or None, its bound excess [rad/s], status,
        iterations, detail).
        """
        try:
            qd, status, iters, detail = self._solve(problem)
        except (ValueError, np.linalg.LinAlgError, RuntimeError) as exc:
            qd, status, iters, detail = None, Status.FAILED, 0, f"{type(exc).__name__}: {exc}"
        excess = math.nan if qd is None else bound_excess(qd, problem.lower, problem.upper)
        rows_excess = 0.0 if qd is None or not problem.has_limit_rows else problem.limit_excess(qd)
        if qd is None or status in FALLBACK_TRIGGERS or not math.isfinite(excess):
            self.reset()
            velocities, status, detail = fallback(problem, qd, status, detail)
        elif excess > self.box_tolerance(problem):
            self.reset()
            velocities, status, detail = fallback(problem, qd, Status.BOUNDS_VIOLATED,
                                                  violation_text(qd, problem.lower, problem.upper,
                                                                 self.box_tolerance(problem)))
        elif rows_excess > 0.0 and rows_excess > self.row_tolerance(problem):
            self.reset()
            velocities, status, detail = fallback(problem, qd, Status.BOUNDS_VIOLATED,
                                                  row_violation_text(problem, qd, self.row_tolerance(problem)))
        else:
            velocities = np.minimum(np.maximum(qd, problem.lower), problem.upper)  # absorbs <= bound_tolerance
        return velocities, qd, excess, status, iters, detail

    def box_tolerance(self, problem: ControlProblem) -> float:
        """How far beyond the box [rad/s] the result of ``_solve`` may lie on this problem:
        ``bound_tolerance``, times :data:`LIMIT_ROWS_TOLERANCE_FACTOR` when the problem has limit rows
        (a QP with general rows ends its iterations within the back-end's tolerance of each row, the
        box's included, but not as tightly on the box as a box-only QP: 3.5e-9 rad/s measured on
        the lasso, against its 2e-9)."""
        return self.bound_tolerance * (LIMIT_ROWS_TOLERANCE_FACTOR if problem.has_limit_rows else 1.0)

    def row_tolerance(self, problem: ControlProblem) -> float:
        """How far beyond a hard limit row the result of ``_solve`` may lie [m/s]: ``bound_tolerance``
        times (1 + the largest row 1-norm [m/rad]), the most a result within ``bound_tolerance`` of
        the rows in each joint can differ in a row (and what the clip into the box can add)."""
        rows = problem.limit_matrix()
        assert rows is not None
        return self.box_tolerance(problem) * (1.0 + float(np.abs(rows).sum(axis=1).max(initial=0.0)))


def fallback(problem: ControlProblem, qd: FloatArray | None, status: Status, detail: str) -> tuple[FloatArray, Status, str]:
    """The failure policy for a valid problem whose solver gave no usable result.

    Returns (velocities, status, detail): the bounded least-squares step with status
    "fallback" ("bounds_violated" for a result beyond its bounds), or :func:`rest_command`
    with the original failure status ("failed" for a "max_iter", non-finite or wrongly shaped
    result) when the least-squares step fails too.

    With hard limit rows (the collision limit), a least-squares step that breaks them is not
    commanded: :func:`separating_step` is (the rows relaxed as little as the box allows: it moves
    the pairs apart as fast as the bounds let it, or stops), and ``detail`` says by how much the
    rows were relaxed; when that fails too, the command nearest to rest.
    """
    if qd is not None and status not in FALLBACK_TRIGGERS and status != Status.BOUNDS_VIOLATED:
        status, detail = Status.FAILED, detail or f"solver returned non-finite velocities or shape {qd.shape}"
    reason = f"{status}: {detail or 'no solution'}"
    final_status = status if status == Status.BOUNDS_VIOLATED else Status.FALLBACK
    step = bounded_least_squares(problem.jacobian, problem.reference, problem.lower, problem.upper)
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


LIMIT_ROWS_TOLERANCE_FACTOR = 4.0
"""Factor on a solver's bound tolerance for a problem with limit rows (:meth:`Solver.box_tolerance`)."""
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
    approach where zero is all it allows: a stop). Solved by daqp.

    Returns:
        (qd [rad/s] (n,), inside the box, the largest slack [m/s]); None when the QP fails.
    """
    rows = problem.limit_matrix()
    assert rows is not None and problem.limit_bound is not None
    m = rows.shape[0]
    qp = slack_qp(problem.jacobian, problem.reference, problem.equality_weights, problem.lower, problem.upper,
                  FALLBACK_DAMPING, rows, problem.limit_bound, np.full(m, SEPARATING_WEIGHT))
    n = problem.lower.shape[0]
    solution = make_backend("daqp").solve(qp)
    if solution.x is None or not math.isfinite(float(solution.x.sum())):
        return None
    qd = np.minimum(np.maximum(solution.x[:n], problem.lower), problem.upper)
    return qd, float(solution.x[n:].max(initial=0.0))


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

    Eq (14) with its bounds (eq 23), solved by bounded-variable least squares
    (scipy.optimize.lsq_linear, BVLS) on the stacked system [J; sqrt(damping) I] qd = [r; 0],
    which is well posed even where J is singular. Joints whose bounds (nearly) coincide are
    fixed at them first (BVLS needs lower < upper).

    Args:
        jacobian: J (m, n); reference: r (m,) [m/s; rad/s]; lower, upper: bounds [rad/s], (n,).
        damping: weight of ||qd||^2, >= 0.

    Returns:
        qd [rad/s], (n,), finite and inside the bounds; None when the solve fails.
    """
    qd = rest_command(lower, upper)
    free = upper - lower > 1e-12
    if not free.any():
        return qd
    a = np.vstack((jacobian[:, free], math.sqrt(damping) * np.eye(int(free.sum()))))
    b = np.concatenate((reference - jacobian[:, ~free] @ qd[~free], np.zeros(int(free.sum()))))
    try:
        solution = lsq_linear(a, b, bounds=(lower[free], upper[free]), method="bvls")
    except (ValueError, np.linalg.LinAlgError):  # e.g. non-finite data
        return None
    x = np.asarray(solution.x, dtype=float)
    if solution.status < 0 or x.shape != (int(free.sum()),) or not math.isfinite(x.sum()):
        return None
    qd[free] = x
    return np.minimum(np.maximum(qd, lower), upper)


def from_qp(solution: QPSolution, transform=None) -> tuple[FloatArray | None, Status, int, str]:
    """Map a QP solution to the ``_solve`` tuple, applying ``transform`` to x when usable."""
    if solution.x is None:
        return None, solution.status, solution.iterations, f"QP {solution.status}"
    x = solution.x if transform is None else transform(solution.x)
    detail = "" if solution.status == Status.SOLVED else f"QP {solution.status}"
    return x, solution.status, solution.iterations, detail
