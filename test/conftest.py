"""Test session set-up: ROS traffic on localhost only, and a private ROS domain per test session;
a deliberately wrong solver for the tests that show a bound check can fail."""

from __future__ import annotations

import os
import random
from collections.abc import Iterator

import bound_ignoring
import pytest
from hypothesis import settings

from dualarm_control.ros.env import apply_localhost_default
from dualarm_control.solvers import unregister

apply_localhost_default()  # before rclpy.init; inherited by subprocesses
# Always a private domain (not the user's interactive one), unless DUALARM_TEST_DOMAIN_ID says which.
os.environ["ROS_DOMAIN_ID"] = os.environ.get("DUALARM_TEST_DOMAIN_ID") or str(random.SystemRandom().randint(1, 101))
os.environ.setdefault("MPLBACKEND", "Agg")
# Property tests: the same examples on every CI run (a run's verdict must not depend on the draw; a new
# counterexample found locally is kept as a regular test, e.g. test_online_trajectory's basis test).
# No per-example deadline (hypothesis's default is 200 ms): how long an example takes is the machine's
# load, not a property of the code (under stress-ng --cpu 1 the QP examples failed on it).
settings.register_profile("ci", derandomize=True, print_blob=True, deadline=None)
settings.register_profile("local", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "local")


@pytest.fixture
def bound_ignoring_solver() -> Iterator[str]:
    """The name of test/bound_ignoring.py's deliberately wrong solver, in the one solver registry
    for one test."""
    name = bound_ignoring.register_it()
    try:
        yield name
    finally:
        unregister(name)
