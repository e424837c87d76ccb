"""QP back-ends behind one registry: daqp (default), proxsuite (reference) and qpsolvers solvers.

Every back-end solves

    min_x 1/2 x^T H x + g^T x   s.t.  A x = b,  l <= C x <= u,  lb <= x <= ub

and returns one :class:`QPSolution`. A back-end object keeps its own warm-start memory,
so one object serves one QP of fixed dimensions across control cycles.

A back-end says whether it needs a positive definite H (``needs_positive_definite``); a
solver whose QP is only positive semi-definite (the lasso of eq 19) refuses such a
back-end when it is built (:func:`check_backend`), instead of failing at every cycle.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import ParameterError, UnknownSolverError
from dualarm_control.status import Status

DEFAULT_MAX_ITER = 1_000
"""The QP iteration cap (``qp_max_iter``). The documented runs need at most 34 (the assembly's 10,438 solves per
solver and back-end: daqp 33, proxsuite 34) and 48 (collision_demo, daqp); a cap of 10,000 let one
proxsuite solve that never converged take 0.1 s on a quiet machine (20 control periods) and one
property test of the suite 46-150 s instead of 0.5 s (issue 38). A solve that reaches the cap falls
back (docs/safety.md)."""


@dataclass(frozen=True)
class QPSettings:
    """Numerical settings shared by all back-ends.

    Attributes:
        eps_abs: absolute primal/dual residual tolerance. Small (1e-9) because the l1 weight
            of the sparse QP is 1e-6: a coarser tolerance would stop before sparsity shows.
        max_iter: iteration cap (:data:`DEFAULT_MAX_ITER`); reaching it is reported, not raised.
        warm_start: reuse the previous cycle's primal/dual solution (proxsuite).
    """

    eps_abs: float = 1e-9
    max_iter: int = DEFAULT_MAX_ITER
    warm_start: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.eps_abs) and self.eps_abs > 0):
            raise ValueError(f"eps_abs must be a positive number, got {self.eps_abs}")
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")


@dataclass(slots=True)
class QPProblem:
    """A dense QP; optional blocks are None. Shapes: H (n,n), g (n,), A (m,n), C (p,n).

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by convention.
    """

    H: FloatArray
    g: FloatArray
    A: FloatArray | None = None
    b: FloatArray | None = None
    C: FloatArray | None = None
    l: FloatArray | None = None
    u: FloatArray | None = None
    lb: FloatArray | None = None
    ub: FloatArray | None = None


@dataclass(slots=True)
class QPSolution:
    """Outcome of one QP solve.

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by convention.

    Attributes:
        x: primal solution (n,), or None when the back-end found none.
        status: "solved", "max_iter", "infeasible" or "failed".
        iterations: back-end iterations (0 if unknown).
        solve_time: wall time of the solve call [s] (perf_counter).
        multipliers: Lagrange multipliers z (p,) of the rows l <= C x <= u, with the sign of
            H x + g + A^T y + C^T z = 0 (z_i > 0 where the upper bound u_i is active, < 0 at
            l_i), or None (no C rows, no solution, or a qpsolvers back-end, which does not
            report them; daqp and proxsuite do).
    """

    x: FloatArray | None
    status: Status
    iterations: int
    solve_time: float
    multipliers: FloatArray | None = None

    @property
    def ok(self) -> bool:
        return self.status == Status.SOLVED and self.x is not None


BOUND_TOLERANCE_FACTOR = 5.0
"""How many ``eps_abs`` a back-end's solution may lie beyond a simple bound. Measured on an AMD EPYC with AVX-512
(2026-12-05; numpy's AVX-512 kernels there build the QPs): daqp's lasso (the sparse QPs, qd = qd+ - qd-) ended
"solved" up to 4.6 eps_abs beyond the box without limit rows (the LWR4 at its singular q = 0 asked for a 40 m/s
twist) and 14 eps_abs with collision rows (3,600 extreme cycles, p99 7.6), proxsuite's l1 second level 3.1;
on the AVX2 machines before, within 1 eps_abs. Past this (times the rows' factor, :meth:`Solver.box_tolerance`),
a result is "bounds_violated". 5e-9 rad/s moves a joint 2.5e-11 rad in a 5 ms period. daqp's own tolerance in x
is larger where H is ill-conditioned (:meth:`DaqpBackend.onto_box`)."""


class QPBackend:
    """Interface of a QP back-end."""

    name = "base"
    needs_positive_definite = False
    """True when the back-end only solves QPs whose H is positive definite."""
    active_set = False
    """True for an active-set method that reports the multipliers of the C rows: the solution is a
    vertex of the active constraints, exact to round-off, rather than an iterate that meets a
    tolerance (proxsuite, interior-point solvers)."""

    def __init__(self, settings: QPSettings) -> None:
        self.settings = settings

    @property
    def bound_tolerance(self) -> float:
        """How far a "solved" x may lie beyond a bound lb/ub [units of x]: :data:`BOUND_TOLERANCE_FACTOR` times
        the configured ``eps_abs``, the primal feasibility tolerance the back-end is run with (daqp's
        ``primal_tol``, proxsuite's ``eps_abs`` on the primal residual, box rows included)."""
        return BOUND_TOLERANCE_FACTOR * self.settings.eps_abs

    def solve(self, problem: QPProblem) -> QPSolution:
        raise NotImplementedError

    def reset(self) -> None:
        """Forget the warm-start memory."""


class ProxsuiteBackend(QPBackend):
    """proxsuite dense ProxQP with box constraints, re-initialised when the dimensions change
    and otherwise updated in place with the previous result as warm start."""

    name = "proxsuite"

    def __init__(self, settings: QPSettings) -> None:
        super().__init__(settings)
        self._qp: object | None = None
        self._dims: tuple[int, int, int, bool] | None = None

    def reset(self) -> None:
        self._qp = None
        self._dims = None

    def solve(self, problem: QPProblem) -> QPSolution:
        import proxsuite

        n = problem.H.shape[0]
        n_eq = 0 if problem.A is None else problem.A.shape[0]
        n_in = 0 if problem.C is None else problem.C.shape[0]
        box = problem.lb is not None
        dims = (n, n_eq, n_in, box)
        start = time.perf_counter()
        args = (problem.H, problem.g, problem.A, problem.b, problem.C, problem.l, problem.u)
        box_args = (problem.lb, problem.ub) if box else ()
        if self._qp is None or dims != self._dims or not self.settings.warm_start:
            qp = proxsuite.proxqp.dense.QP(n, n_eq, n_in, box)
            qp.settings.eps_abs = self.settings.eps_abs
            qp.settings.eps_rel = 0.0
            qp.settings.max_iter = self.settings.max_iter
            qp.settings.verbose = False
            # Without a duality-gap test "solved" only means small primal/dual residuals; with
            # active bounds (and after a warm start from another problem) that accepted
            # iterates whose objective was up to 1e-3 above the optimum.
            qp.settings.check_duality_gap = True
            qp.settings.eps_duality_gap_abs = self.settings.eps_abs
            qp.settings.eps_duality_gap_rel = 0.0
            qp.init(*args, *box_args)
            self._qp, self._dims = qp, dims
        else:
            qp = self._qp
            qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT  # type: ignore[attr-defined]
            qp.update(*args, *box_args)  # type: ignore[attr-defined]
        qp.solve()  # type: ignore[attr-defined]
        elapsed = time.perf_counter() - start
        info = qp.results.info  # type: ignore[attr-defined]
        out = proxsuite.proxqp.QPSolverOutput
        status = {
            out.PROXQP_SOLVED: Status.SOLVED,
            out.PROXQP_MAX_ITER_REACHED: Status.MAX_ITER,
            out.PROXQP_PRIMAL_INFEASIBLE: Status.INFEASIBLE,
            out.PROXQP_DUAL_INFEASIBLE: Status.INFEASIBLE,
        }.get(info.status, Status.FAILED)
        x = np.array(qp.results.x, dtype=float) if status in (Status.SOLVED, Status.MAX_ITER) else None  # type: ignore[attr-defined]
        z = np.array(qp.results.z[:n_in], dtype=float) if status == Status.SOLVED and n_in else None  # type: ignore[attr-defined]
        if status != Status.SOLVED:
            self.reset()  # never warm-start from a failed solve
        return QPSolution(x=x, status=status, iterations=int(info.iter), solve_time=elapsed, multipliers=z)


class DaqpBackend(QPBackend):
    """daqp, a dual active-set method (Arnström et al. 2022): exact up to round-off.

    A positive semi-definite H (the lasso of eq 19) is handled by daqp's proximal-point
    outer loop (``eps_prox < 0``: regularise only when the factorisation is singular),
    iterated until two outer iterates differ by less than ``ETA_PROX``; with daqp's
    default (1e-6) the lasso objective was up to 18 % above the optimum, with 1e-14 it
    matches proxsuite at eps 1e-13 to 1.4e-12 relative (docs/bench.md). Equality rows are
    passed as daqp equality constraints, the box as daqp simple bounds. With ``warm_start``
    the previous solution seeds the initial active set (``primal_start``).
    """

    name = "daqp"
    active_set = True
    ETA_PROX = 1e-14
    """Proximal-point stopping tolerance (change of the iterate between outer iterations)."""
    EQUALITY, INEQUALITY = 5, 0
    """daqp constraint kinds (``sense``)."""
    STATUS: ClassVar[Mapping[int, Status]] = MappingProxyType(
        {1: Status.SOLVED, 2: Status.SOLVED, -1: Status.INFEASIBLE, -3: Status.INFEASIBLE, -4: Status.MAX_ITER})
    """daqp exit flags: 1 optimal, 2 soft optimal, -1 infeasible, -2 cycling, -3 unbounded,
    -4 iteration limit, -5 non-convex, -6 initial point infeasible (the others: "failed")."""

    def __init__(self, settings: QPSettings) -> None:
        import daqp  # imported here: a back-end's package is only needed when it is chosen

        super().__init__(settings)
        self._daqp = daqp
        self._previous: FloatArray | None = None
        self._constants: dict[tuple[str, int], npt.NDArray[np.generic]] = {}
        self._senses: dict[int, npt.NDArray[np.int32]] = {}

    def reset(self) -> None:
        self._previous = None

    def _box_only(self, n: int) -> FloatArray:
        """The empty (0, n) constraint matrix of a box-only QP, built once per n."""
        key = ("empty", n)
        if key not in self._constants:
            self._constants[key] = np.zeros((0, n))
        return self._constants[key]  # type: ignore[return-value]

    def _sense(self, n: int) -> npt.NDArray[np.int32]:
        """All-inequality ``sense`` of n rows or box bounds, built once per n (daqp does not modify it)."""
        sense = self._senses.get(n)
        if sense is None:
            sense = self._senses[n] = np.full(n, self.INEQUALITY, dtype=np.int32)
        return sense

    def _stack(self, problem: QPProblem, n: int) -> tuple[FloatArray, FloatArray, FloatArray, npt.NDArray[np.int32]]:
        """daqp's (A, bupper, blower, sense): box first (simple bounds), then equalities, then C rows."""
        rows: list[FloatArray] = []
        upper: list[FloatArray] = []
        lower: list[FloatArray] = []
        sense: list[npt.NDArray[np.int32]] = []
        if problem.lb is not None and problem.ub is not None:
            upper.append(problem.ub)
            lower.append(problem.lb)
            sense.append(self._sense(n))
        if problem.A is not None and problem.b is not None:
            rows.append(problem.A)
            upper.append(problem.b)
            lower.append(problem.b)
            sense.append(np.full(problem.A.shape[0], self.EQUALITY, dtype=np.int32))
        if problem.C is not None and problem.l is not None and problem.u is not None:
            rows.append(problem.C)
            upper.append(problem.u)
            lower.append(problem.l)
            sense.append(np.full(problem.C.shape[0], self.INEQUALITY, dtype=np.int32))
        a = np.vstack(rows) if rows else self._box_only(n)
        return a, np.concatenate(upper), np.concatenate(lower), np.concatenate(sense)

    def solve(self, problem: QPProblem) -> QPSolution:
        n = problem.H.shape[0]
        if problem.A is None and problem.C is None and problem.lb is not None and problem.ub is not None:
            a, upper, lower, sense = self._box_only(n), problem.ub, problem.lb, self._sense(n)
        elif problem.A is None and problem.lb is None and problem.C is not None \
                and problem.l is not None and problem.u is not None:
            a, upper, lower, sense = problem.C, problem.u, problem.l, self._sense(problem.C.shape[0])
        else:
            a, upper, lower, sense = self._stack(problem, n)
        n_c = 0 if problem.C is None else problem.C.shape[0]
        x, status, iterations, elapsed, z = self.solve_arrays(problem.H, problem.g, a, upper, lower, sense, n_c)
        if x is not None and problem.lb is not None and problem.ub is not None:
            x = self.onto_box(problem.H, x, problem.lb, problem.ub)
        return QPSolution(x, status, iterations, elapsed, z)

    def onto_box(self, h: FloatArray, x: FloatArray, lower: FloatArray, upper: FloatArray) -> FloatArray:
        """daqp's x moved onto the simple bounds it meets to daqp's own tolerance (x itself when within
        :attr:`bound_tolerance` of them, the common case: one excess test, 2.1 us, about one a cycle with the
        sparse and hierarchical QPs; the Cholesky factor only beyond it).

        daqp tests a bound x_i <= u_i in its normalised dual space: the row e_i^T R^-1 (H = R^T R) scaled to
        unit norm (daqp's ``daqp_normalize_Rinv``), so in x the bound holds to primal_tol ||R^-T e_i|| =
        primal_tol sqrt((H^-1)_ii), more than primal_tol where H is ill-conditioned: the sparse QPs' lasso
        H = B^T B + mu I (mu 1e-6) has sqrt((H^-1)_ii) up to about 1e3, and a "solved" x was 1.04e-8 beyond the
        box at eps_abs 1e-9 (the LWR4 stretched at q = 0, a target 6.6 m away). Each entry is held to
        :attr:`bound_tolerance` times max(1, sqrt((H^-1)_ii)); beyond that, or when H is not positive definite
        (the proximal loop's lasso), x is returned as it is, for the solver's bounds check to report.

        Args:
            h: the QP's H (n, n); x: daqp's solution (n,); lower, upper: the simple bounds (n,).
        """
        over = np.maximum(lower - x, x - upper)
        if over.max(initial=0.0) <= self.bound_tolerance:
            return x
        try:
            inverse = np.linalg.inv(np.linalg.cholesky(h))  # L^-1 with H = L L^T: (H^-1)_ii = ||L^-1 e_i||^2
        except np.linalg.LinAlgError:
            return x
        scale = np.sqrt(np.einsum("ij,ij->j", inverse, inverse))
        if np.all(over <= self.bound_tolerance * np.maximum(scale, 1.0)):
            return np.minimum(np.maximum(x, lower), upper)
        return x

    def solve_rows(self, h: FloatArray, g: FloatArray, c: FloatArray, lower: FloatArray, upper: FloatArray
                   ) -> tuple[FloatArray | None, Status, int, float, FloatArray | None]:
        """The QP with rows only, ``lower <= c x <= upper`` (no box, no equality), without the
        :class:`QPProblem` and :class:`QPSolution` records (:meth:`solve_arrays`'s tuple): the lasso's dual
        (:class:`~dualarm_control.solvers.lasso_dual.LassoDual`) every cycle."""
        return self.solve_arrays(h, g, c, upper, lower, self._sense(c.shape[0]), c.shape[0])

    def solve_arrays(self, h: FloatArray, g: FloatArray, a: FloatArray, upper: FloatArray, lower: FloatArray,
                     sense: npt.NDArray[np.int32], n_c: int
                     ) -> tuple[FloatArray | None, Status, int, float, FloatArray | None]:
        """daqp on its own arrays (:meth:`_stack`'s order; ``n_c`` C rows last): (x or None, status,
        iterations, solve time [s], the C rows' multipliers or None), :class:`QPSolution`'s fields."""
        start = time.perf_counter()
        previous = self._previous
        warm = previous if previous is not None and self.settings.warm_start \
            and previous.shape[0] == h.shape[0] else None
        x, _, flag, info = self._daqp.solve(
            h, g, a, upper, lower, sense,
            primal_tol=self.settings.eps_abs, eta_prox=self.ETA_PROX, iter_limit=self.settings.max_iter,
            primal_start=warm,
        )
        elapsed = time.perf_counter() - start
        status = self.STATUS.get(int(flag), Status.FAILED)
        x = np.asarray(x)  # a new array per call: shared by the result and the warm start (neither is modified)
        solved = status is Status.SOLVED
        # a Python sum of the (n,) floats: 4x cheaper than numpy's reduction on so few, the same NaN and inf
        usable = (solved or status is Status.MAX_ITER) and math.isfinite(sum(x.tolist()))
        self._previous = x if solved else None
        z = np.asarray(info["lam"][-n_c:]) if n_c and solved else None  # daqp's lam: box, equalities, C rows
        return x if usable else None, status, int(info["iterations"]), elapsed, z


class QpsolversBackend(QPBackend):
    """Any solver of the ``qpsolvers`` package (e.g. quadprog, osqp, clarabel); no warm start."""

    POSITIVE_DEFINITE_ONLY = frozenset({"quadprog", "ecos", "qpswift", "hpipm", "kvxopt", "cvxopt"})
    """qpsolvers back-ends that factorise H (Cholesky or equivalent) and so need it definite;
    quadprog returns no solution on the lasso of eq (19) instead of an error."""

    def __init__(self, settings: QPSettings, solver: str) -> None:
        super().__init__(settings)
        self.name = solver
        self.needs_positive_definite = solver in self.POSITIVE_DEFINITE_ONLY

    def solve(self, problem: QPProblem) -> QPSolution:
        import qpsolvers

        G: FloatArray | None = None
        h: FloatArray | None = None
        if problem.C is not None and problem.l is not None and problem.u is not None:
            G = np.vstack((problem.C, -problem.C))  # l <= C x <= u  ->  [C; -C] x <= [u; -l]
            h = np.concatenate((problem.u, -problem.l))
        start = time.perf_counter()
        try:
            x = qpsolvers.solve_qp(
                problem.H, problem.g, G, h, problem.A, problem.b, problem.lb, problem.ub, solver=self.name
            )
        except Exception:  # noqa: BLE001 - a back-end error is reported as a failed solve
            x = None
        elapsed = time.perf_counter() - start
        status = Status.SOLVED if x is not None and np.all(np.isfinite(x)) else Status.FAILED
        return QPSolution(x=None if status != Status.SOLVED else np.asarray(x, float), status=status,
                          iterations=0, solve_time=elapsed)


DEFAULT_BACKEND = "daqp"
_NATIVE: dict[str, type[QPBackend]] = {"daqp": DaqpBackend, "proxsuite": ProxsuiteBackend}
_NATIVE_IN_QPSOLVERS = {"daqp", "proxqp"}  # qpsolvers names of the back-ends wrapped natively above


def available_backends() -> list[str]:
    """Names accepted by :func:`make_backend`: daqp, proxsuite, then the other installed qpsolvers solvers."""
    import qpsolvers

    return [*_NATIVE, *sorted(s for s in qpsolvers.available_solvers if s not in _NATIVE_IN_QPSOLVERS)]


def is_backend(name: str) -> bool:
    """Whether :func:`make_backend` knows ``name`` (daqp and proxsuite without importing qpsolvers: it imports
    scipy.sparse, 0.1-0.2 s that a node using them need not pay at start)."""
    return name in _NATIVE or name in available_backends()


def make_backend(name: str, settings: QPSettings | None = None) -> QPBackend:
    """Create a QP back-end by name; raises UnknownSolverError listing the valid names."""
    settings = settings or QPSettings()
    if name in _NATIVE:
        return _NATIVE[name](settings)
    factories: dict[str, Callable[[], QPBackend]] = {
        key: (lambda cls=cls: cls(settings)) for key, cls in _NATIVE.items()  # type: ignore[misc]
    }
    for other in available_backends()[len(_NATIVE):]:
        factories[other] = lambda other=other: QpsolversBackend(settings, other)  # type: ignore[misc]
    if name not in factories:
        raise UnknownSolverError(name, list(factories))
    return factories[name]()


def check_backend(backend: QPBackend, positive_definite: bool, what: str) -> None:
    """Refuse a back-end that cannot solve a QP whose H is only semi-definite.

    Args:
        backend: the back-end a solver is about to use.
        positive_definite: whether the solver's H is positive definite.
        what: the QP, for the message (e.g. "sparse_qp's lasso QP, eq (19)").

    Raises:
        ParameterError on ``qp_backend`` naming the back-ends that can.
    """
    if backend.needs_positive_definite and not positive_definite:
        able = [n for n in available_backends() if n not in QpsolversBackend.POSITIVE_DEFINITE_ONLY]
        raise ParameterError(
            "qp_backend", backend.name,
            f"a back-end for a positive semi-definite H ({what}): one of {', '.join(able)}",
        )
