"""A control cycle's solver status: one Enum, the same strings on the wire (bags, /diagnostics, metrics.json)."""

from __future__ import annotations

from enum import Enum


class Status(str, Enum):
    """What a solver (or a QP back-end) made of a cycle's problem.

    A ``str``: ``Status.SOLVED == "solved"``, and bags, /diagnostics and metrics.json carry the value.
    """

    SOLVED = "solved"
    """The problem's optimum (within the back-end's tolerances)."""
    SCALED = "scaled"
    """The pseudo-inverse step shrunk into the bounds (direction kept)."""
    FALLBACK = "fallback"
    """The solver failed; the bounded least-squares step was used (the reason in the result's detail)."""
    INFEASIBLE = "infeasible"
    """No point meets the constraints (or the back-end says so)."""
    MAX_ITER = "max_iter"
    """The back-end ran out of iterations."""
    FAILED = "failed"
    """The solver raised, or returned a non-finite or wrongly shaped result."""
    INVALID_INPUT = "invalid_input"
    """Non-finite or inconsistent inputs: the safe command, nothing solved."""
    BOUNDS_VIOLATED = "bounds_violated"
    """The solver's result broke a bound by more than its tolerance (a failure of its own)."""

    def __str__(self) -> str:
        return self.value


FAILURE_STATUSES = frozenset({Status.INFEASIBLE, Status.FAILED, Status.INVALID_INPUT, Status.BOUNDS_VIOLATED})
"""Statuses counted as solver failures (reports, /diagnostics level ERROR)."""

FALLBACK_TRIGGERS = frozenset({Status.INFEASIBLE, Status.FAILED, Status.MAX_ITER})
"""Solver statuses whose result is replaced by the bounded least-squares step."""
