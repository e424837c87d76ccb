"""Kinematic solvers of papers 000 and 001 behind one registry: ``make_solver("sparse_qp")``."""

from __future__ import annotations

from dualarm_control.solvers import constraint_based as _constraint_based  # noqa: F401 - fills the registry
from dualarm_control.solvers import methods as _methods  # noqa: F401 - fills the registry
from dualarm_control.solvers.base import (
    ACTIVITY_THRESHOLD,
    Solver,
    SolverParams,
    SolverResult,
)
from dualarm_control.solvers.problem import ControlProblem
from dualarm_control.solvers.registry import (
    register,
    solver_class,
    solver_names,
    unregister,
)


def make_solver(name: str, params: SolverParams | None = None) -> Solver:
    """Instantiate the solver registered under ``name`` (UnknownSolverError otherwise)."""
    solver: Solver = solver_class(name)(params)
    return solver


__all__ = [
    "ACTIVITY_THRESHOLD",
    "ControlProblem",
    "Solver",
    "SolverParams",
    "SolverResult",
    "make_solver",
    "register",
    "solver_class",
    "solver_names",
    "unregister",
]
