"""What every kinematic solver takes and returns: :class:`Solver`, its parameters and its result.

A solver is a pure function of the problem (Jacobian, reference twist, velocity bounds,
repulsive velocity) to joint velocities, plus its own warm-start memory. The same object
serves the in-process experiment, the controller node and the benchmark.

The failure policy the base class applies around each solver (docs/safety.md, "Input validation
and solver failure") is in :mod:`dualarm_control.solvers.policy`; the problem in
:mod:`dualarm_control.solvers.problem`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from dualarm_control.metrics import ACTIVITY_THRESHOLD
from dualarm_control.qp import DEFAULT_BACKEND, QPSettings, QPSolution, make_backend
from dualarm_control.solvers import priority
from dualarm_control.solvers.lapack import dposv
from dualarm_control.solvers.policy import (
    ROUND_OFF,
    bound_excess,
    fallback,
    inside,
    load_fallback,
    row_violation_text,
    violation_text,
)
from dualarm_control.solvers.problem import ControlProblem, FloatArray
from dualarm_control.status import FAILURE_STATUSES, FALLBACK_TRIGGERS, Status


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
    second_priority_in_solve = False
    """Whether ``_solve`` itself realises the problem's second priority (the hierarchical solvers: as their
    second level); otherwise :meth:`_second_priority` runs on ``_solve``'s result."""

    def __init__(self, params: SolverParams | None = None) -> None:
        self.params = params or SolverParams()
        load_fallback()  # the imports now, never inside the control loop
        dposv()

    def reset(self) -> None:
        """Forget every warm-start memory (e.g. after a discontinuity, or a failed solve): the second
        priority's back-end's here, the solver's own in the subclass (which calls this). After it the
        next result depends on the problem alone, as a new solver's would (``test_priority.py``)."""
        if self._priority_qp is not None:
            self._priority_qp.reset()

    def seed(self, velocities: FloatArray) -> None:
        """Start from ``velocities`` [rad/s], (n,), the command of the cycle before, as if this
        solver had produced it (a live change of solver; :meth:`RelativeController.continue_from`).

        Default: nothing, for a solver whose result does not depend on its memory (a closed form,
        or a strictly convex QP whose warm start only changes the iteration count). The sparse QPs
        take it as the centre z_prev of their proximal term."""

    def _backend(self):
        return make_backend(self.params.qp_backend, self.params.qp)

    _priority_qp = None
    """The second priority's QP back-end, made on first use (:meth:`_priority_backend`)."""

    def _priority_backend(self):
        """The QP back-end of the second priority (its own warm start: its QP differs from the first's)."""
        if self._priority_qp is None:
            self._priority_qp = self._backend()
        return self._priority_qp

    def _second_priority(self, problem: ControlProblem, qd1: FloatArray, status: Status, iters: int,
                         detail: str) -> tuple[FloatArray | None, Status, int, str]:
        """The problem's second priority in the optimal set of the first (``qd1``, inside the bounds):
        eq (P2) of :mod:`dualarm_control.solvers.priority` with eps = ``regularization``, its unbounded
        minimiser when that meets the bounds and rows, else its QP; when that QP fails, ``qd1`` (the first
        priority kept) and ``detail`` says so."""
        eps = self.params.regularization
        qd = priority.unbounded_second_level(problem, qd1, eps)
        kept = priority.kept_inequalities(problem, qd1)
        if inside(qd, problem.lower, problem.upper) and problem.limit_excess(qd) <= 0.0 \
                and (kept is None or bool(np.all(kept[0] @ qd <= kept[1]))):
            return qd, status, iters, detail
        solution = self._priority_backend().solve(priority.least_squares_level(problem, qd1, eps))
        return self._second_result(solution, qd1, status, iters, detail)

    @staticmethod
    def _second_result(solution: QPSolution, qd1: FloatArray, status: Status, iters: int, detail: str,
                       transform=None) -> tuple[FloatArray | None, Status, int, str]:
        """The second level's QP ``solution`` (x, or ``transform`` of x) as the ``_solve`` tuple; ``qd1`` with a
        note when it failed."""
        if not solution.ok or solution.x is None:
            note = f"second priority QP {solution.status}; first priority only"
            return qd1, status, iters + solution.iterations, (detail + "; " if detail else "") + note
        x = solution.x if transform is None else transform(solution.x)
        return x, status, iters + solution.iterations, detail

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
            if problem.has_secondary and not self.second_priority_in_solve and qd is not None \
                    and status not in FALLBACK_TRIGGERS and bound_excess(qd, problem.lower, problem.upper) \
                    <= self.box_tolerance(problem):
                qd1 = np.minimum(np.maximum(qd, problem.lower), problem.upper)  # absorbs the first level's tolerance
                qd, status, iters, detail = self._second_priority(problem, qd1, status, iters, detail)
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


LIMIT_ROWS_TOLERANCE_FACTOR = 4.0
"""Factor on a solver's bound tolerance for a problem with limit rows (:meth:`Solver.box_tolerance`)."""


def from_qp(solution: QPSolution, transform=None) -> tuple[FloatArray | None, Status, int, str]:
    """Map a QP solution to the ``_solve`` tuple, applying ``transform`` to x when usable."""
    if solution.x is None:
        return None, solution.status, solution.iterations, f"QP {solution.status}"
    x = solution.x if transform is None else transform(solution.x)
    detail = "" if solution.status == Status.SOLVED else f"QP {solution.status}"
    return x, solution.status, solution.iterations, detail
