"""No process outlives the one it works for (dualarm_control/lifetime.py): the planner's pool workers when
``dualarm plan`` is killed mid-plan (they had kept computing for nobody, seen after a Ctrl-C of ``make test``),
and the helper's own two cases. No ROS node, no wall-clock verdict (the deadlines are hang guards)."""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import psutil
import pytest

pytestmark = pytest.mark.background

HANG_GUARD_S = 60.0
T = TypeVar("T")

STOP_AT_ONCE = ("import signal; from dualarm_control.lifetime import stop_with_parent; stop_with_parent(1); "
                "signal.pause(); print('outlived')")
"""A child asking to stop with pid 1, which is not its parent (as if its parent had died before the request)."""
CHILD = ("import os, signal; from dualarm_control.lifetime import stop_with_parent; stop_with_parent(os.getppid()); "
         "print(os.getpid(), flush=True); signal.pause()")
PARENT = f"import signal, subprocess, sys; subprocess.Popen([sys.executable, '-c', {CHILD!r}]); signal.pause()"
"""A parent that starts :data:`CHILD` (which prints its pid once it has asked to stop with its parent) and waits."""


def wait_for(what: str, condition: Callable[[], T], deadline_s: float = HANG_GUARD_S,
             seen: Callable[[], str] = lambda: "") -> T:
    """``condition()``'s first truthy value, polled until ``deadline_s``; fails naming ``what`` and ``seen()``."""
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    pytest.fail(f"{what} not within {deadline_s:.0f} s; seen: {seen()}")


def test_a_child_whose_parent_is_gone_stops_at_once() -> None:
    """Asked to stop with a parent that is not its parent (the parent died before the request): SIGTERM now."""
    child = subprocess.run([sys.executable, "-c", STOP_AT_ONCE], capture_output=True, text=True, timeout=HANG_GUARD_S,
                           check=False)
    assert child.returncode == -signal.SIGTERM and "outlived" not in child.stdout, child


def test_a_child_stops_when_its_parent_is_killed() -> None:
    """A parent that starts a child asking to stop with it, then is SIGKILLed: the child gets SIGTERM."""
    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout is not None
        child = psutil.Process(int(parent.stdout.readline()))  # its pid once it has asked
        parent.kill()
        parent.wait(timeout=HANG_GUARD_S)
        wait_for("the child's exit", lambda: not child.is_running() or child.status() == psutil.STATUS_ZOMBIE,
                 seen=lambda: f"pid {child.pid} {child.status()}")
    finally:
        parent.kill()


def test_the_planners_workers_stop_when_the_planner_is_killed(tmp_path: Path) -> None:
    """``dualarm plan`` SIGKILLed while its pool computes: every worker process exits (before, they went on for
    minutes after a Ctrl-C of the test run that had started the planner)."""
    plan = subprocess.Popen([sys.executable, "-m", "dualarm_control.app.cli", "plan", "corner_path", "--starts", "400",
                             "--workers", "2", "--no-execute", "--output", str(tmp_path)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    me = psutil.Process(plan.pid)
    pool: list[psutil.Process] = []
    try:
        def workers() -> list[psutil.Process]:
            return [p for p in me.children(recursive=True) if "multiprocessing.spawn" in " ".join(p.cmdline())]

        def computing() -> list[psutil.Process]:  # both workers started and past their initializer's imports
            found = workers()
            return found if len(found) == 2 and sum(p.cpu_times().user for p in found) > 1.0 else []

        pool = wait_for("two computing workers", computing, seen=lambda: str(workers()))
        plan.kill()
        plan.wait(timeout=HANG_GUARD_S)
        alive = psutil.wait_procs(pool, timeout=HANG_GUARD_S)[1]
        assert not alive, f"workers alive {HANG_GUARD_S:.0f} s after the planner's SIGKILL: {[p.pid for p in alive]}"
    finally:
        plan.kill()
        for p in pool:  # re-parented to init when the check failed
            with contextlib.suppress(psutil.NoSuchProcess):
                p.kill()
