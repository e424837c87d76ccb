"""QP back-ends behind one registry: proxsuite (default, warm-started) and any qpsolvers solver.

Every back-end solves

    min_x 1/2 x^T H x + g^T x   s.t.  A x = b,  l <= C x <= u,  lb <= x <= ub

and returns one :class:`QPSolution`. A back-end object keeps its own warm-start memory,
so one object serves one QP of fixed dimensions across control cycles.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from dualarm_control.errors import UnknownSolverError

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class QPSettings:
    """Numerical settings shared by all back-ends.

    Attributes:
        eps_abs: absolute primal/dual residual tolerance. Small (1e-9) because the l1 weight
            of the sparse QP is 1e-6: a coarser tolerance would stop before sparsity shows.
        max_iter: iteration cap; reaching it is reported, not raised.
        warm_start: reuse the previous cycle's primal/dual solution (proxsuite).
    """

    eps_abs: float = 1e-9
    max_iter: int = 10_000
    warm_start: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.eps_abs) and self.eps_abs > 0):
            raise ValueError(f"eps_abs must be a positive number, got {self.eps_abs}")
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")


@dataclass(frozen=True)
class QPProblem:
    """A dense QP; optional blocks are None. Shapes: H (n,n), g (n,), A (m,n), C (p,n)."""

    H: FloatArray
    g: FloatArray
    A: FloatArray | None = None
    b: FloatArray | None = None
    C: FloatArray | None = None
    l: FloatArray | None = None
    u: FloatArray | None = None
    lb: FloatArray | None = None
    ub: FloatArray | None = None


@dataclass(frozen=True)
class QPSolution:
    """Outcome of one QP solve.

    Attributes:
        x: primal solution (n,), or None when the back-end found none.
        status: "solved", "max_iter", "infeasible" or "failed".
        iterations: back-end iterations (0 if unknown).
        solve_time: wall time of the solve call [s] (perf_counter).
    """

    x: FloatArray | None
    status: str
    iterations: int
    solve_time: float

    @property
    def ok(self) -> bool:
        return self.status == "solved" and self.x is not None


class QPBackend:
    """Interface of a QP back-end."""

    name = "base"

    def __init__(self, settings: QPSettings) -> None:
        self.settings = settings

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
            out.PROXQP_SOLVED: "solved",
            out.PROXQP_MAX_ITER_REACHED: "max_iter",
            out.PROXQP_PRIMAL_INFEASIBLE: "infeasible",
            out.PROXQP_DUAL_INFEASIBLE: "infeasible",
        }.get(info.status, "failed")
        x = np.array(qp.results.x, dtype=float) if status in ("solved", "max_iter") else None  # type: ignore[attr-defined]
        if status != "solved":
            self.reset()  # never warm-start from a failed solve
        return QPSolution(x=x, status=status, iterations=int(info.iter), solve_time=elapsed)


class QpsolversBackend(QPBackend):
    """Any solver of the ``qpsolvers`` package (e.g. quadprog, osqp, clarabel); no warm start."""

    def __init__(self, settings: QPSettings, solver: str) -> None:
        super().__init__(settings)
        self.name = solver

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
        status = "solved" if x is not None and np.all(np.isfinite(x)) else "failed"
        return QPSolution(x=None if status != "solved" else np.asarray(x, float), status=status,
                          iterations=0, solve_time=elapsed)


def available_backends() -> list[str]:
    """Names accepted by :func:`make_backend`: proxsuite plus the installed qpsolvers solvers."""
    import qpsolvers

    return ["proxsuite", *sorted(s for s in qpsolvers.available_solvers if s != "proxqp")]


def make_backend(name: str, settings: QPSettings | None = None) -> QPBackend:
    """Create a QP back-end by name; raises UnknownSolverError listing the valid names."""
    settings = settings or QPSettings()
    factories: dict[str, Callable[[], QPBackend]] = {"proxsuite": lambda: ProxsuiteBackend(settings)}
    for other in available_backends()[1:]:
        factories[other] = lambda other=other: QpsolversBackend(settings, other)  # type: ignore[misc]
    if name not in factories:
        raise UnknownSolverError(name, list(factories))
    return factories[name]()
