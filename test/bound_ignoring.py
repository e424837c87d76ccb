"""A deliberately wrong solver, for the tests that show a bound check can fail.

Registered for one test at a time by the ``bound_ignoring_solver`` fixture (conftest.py), or
by a node process a test starts (``python -m bound_ignoring --ros-args ...``: the controller
node with this solver in its registry).
"""

from __future__ import annotations

import sys

import numpy as np

from dualarm_control.solvers import ControlProblem, Solver, register

NAME = "bound_ignoring_test_solver"


class BoundIgnoringSolver(Solver):
    """Ignores the bounds it is given: commands 1.5 times the upper bound of every joint (beyond
    it wherever that bound is > 0), with status "solved"."""

    def _solve(self, problem: ControlProblem) -> tuple[np.ndarray | None, str, int, str]:
        return 1.5 * problem.upper, "solved", 0, ""


def register_it() -> str:
    """Add the solver to the registry under :data:`NAME`; returns the name."""
    register(NAME)(BoundIgnoringSolver)
    return NAME


if __name__ == "__main__":  # controller_node with this solver registered
    from dualarm_control.nodes.controller_node import main

    register_it()
    sys.exit(main())
