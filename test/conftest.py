"""Test session set-up: ROS traffic on localhost only, and a private ROS domain per test session;
a deliberately wrong solver for the tests that show a bound check can fail."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import bound_ignoring
import domains
import psutil
import pytest
from hypothesis import settings

from dualarm_control.ros.env import apply_localhost_default
from dualarm_control.solvers import unregister

pytest_plugins = ("durations",)  # --durations-file: every phase's duration and CPU time (test/durations.py)

apply_localhost_default()  # before rclpy.init; inherited by subprocesses
# Always a private domain (not the user's interactive one, not another test process's: a lease held for
# the session, test/domains.py), DUALARM_TEST_DOMAIN_ID if set.
SESSION_DOMAIN = domains.lease_session()
os.environ["ROS_DOMAIN_ID"] = str(SESSION_DOMAIN.domain)
os.environ.setdefault("MPLBACKEND", "Agg")
# Property tests: the same examples on every CI run (a run's verdict must not depend on the draw; a new
# counterexample found locally is kept as a regular test, e.g. test_online_trajectory's basis test).
# No per-example deadline (hypothesis's default is 200 ms): how long an example takes is the machine's
# load, not a property of the code (under stress-ng --cpu 1 the QP examples failed on it).
settings.register_profile("ci", derandomize=True, print_blob=True, deadline=None)
settings.register_profile("local", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "local")


MODULE_SECONDS = Path(__file__).with_name("module_seconds.json")
"""Each test module's seconds in a recent default run (the ``.modules.json`` that ``--durations-file``
writes beside its file; copy it here when modules change much)."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The longest modules first (order within a module kept), for a run in one process. pytest-xdist 3.6+
    hands ``--dist loadfile`` modules to its workers by their number of tests instead, which measured faster
    than this order (432.4 against 453.3 s, docs/testing.md). A module not in :data:`MODULE_SECONDS` counts 5 s."""
    seconds = json.loads(MODULE_SECONDS.read_text()) if MODULE_SECONDS.exists() else {}
    items.sort(key=lambda item: -seconds.get(item.path.name, 5.0))


PROCESS_HELPERS = ("multiprocessing.resource_tracker", "multiprocessing.forkserver")
"""Helpers of this pytest process itself (multiprocessing starts one on first use and keeps it for the
process's life): not a test's leftovers."""
LEFTOVER_GRACE_S = 10.0
"""A process started in a module may take this long to exit after its module's last fixture stopped it [s]."""


@pytest.fixture(scope="module", autouse=True)
def no_process_outlives_its_module() -> Iterator[None]:
    """No process a module started (nodes, launches, tools, servers) outlives it: those still alive when the
    module's fixtures are torn down get :data:`LEFTOVER_GRACE_S` to exit, then SIGKILL, and the module
    errors naming them (a leftover node on a domain answers the next test's nodes)."""
    me = psutil.Process()
    before = {p.pid for p in me.children(recursive=True)}
    yield

    def alive() -> list[psutil.Process]:
        out = []
        for p in me.children(recursive=True):
            try:
                if (p.pid not in before and p.status() != psutil.STATUS_ZOMBIE
                        and not any(part in " ".join(p.cmdline()) for part in PROCESS_HELPERS)):
                    out.append(p)
            except psutil.NoSuchProcess:
                pass
        return out

    left = alive()
    if not left:
        return
    _, still = psutil.wait_procs(left, timeout=LEFTOVER_GRACE_S)
    names = []
    for p in still:
        try:
            names.append(f"pid {p.pid}: {' '.join(p.cmdline())[:200]}")
            p.kill()
        except psutil.NoSuchProcess:
            pass
    if names:
        pytest.fail("processes outlived their test module (killed now):\n" + "\n".join(names), pytrace=False)


@pytest.fixture
def bound_ignoring_solver() -> Iterator[str]:
    """The name of test/bound_ignoring.py's deliberately wrong solver, in the one solver registry
    for one test."""
    name = bound_ignoring.register_it()
    try:
        yield name
    finally:
        unregister(name)
