"""Waiting in the tests: for a condition, with a deadline, failing with what was seen.

A test that needs something to have happened (a process up, a log line, N messages received)
waits for exactly that, polling, and goes on the moment it holds. The deadline bounds how long
it waits for a thing that must happen, on a loaded machine too; it is not a verdict on speed: a
condition met after 59 s passes like one met at once. When the deadline passes, or the process
that should make it happen has exited, the wait fails (AssertionError) saying what it waited
for and what it saw, never returns as if done.
"""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Callable, Sequence
from typing import TypeVar

T = TypeVar("T")

DEADLINE_S = 60.0
"""The default deadline [s]: start-up and discovery take seconds on a busy 2-core machine."""
GRACE_S = 1.0
"""After ``gone``: one more look at the condition this much later [s] (a reader thread drains the pipe)."""


def node_env() -> dict[str, str]:
    """The environment for a node a test starts itself: the node gets SIGTERM when this pytest process
    dies (``ros.env.stop_with_launcher``, as under ``dualarm launch``), so that a killed test run leaves
    no node publishing on its domain into the next run's tests."""
    from dualarm_control.ros.env import LAUNCHER_PID_VARIABLE

    return {**os.environ, LAUNCHER_PID_VARIABLE: str(os.getpid())}


def wait_until(condition: Callable[[], T | None], seen: Callable[[], object], *, what: str,
               timeout: float = DEADLINE_S, step: Callable[[], object] | None = None, interval: float = 0.05,
               gone: Callable[[], str | None] | None = None) -> T:
    """The first truthy value of ``condition()``, polled until ``timeout`` [s].

    Between polls ``step()`` runs (an executor's ``spin_once``, say), else a sleep of ``interval``
    [s]. ``gone()``, when given, says why the condition can no longer come (a process exited) or
    returns None. On the deadline or ``gone``: AssertionError naming ``what`` and ``seen()``.
    """
    start = time.monotonic()
    while True:
        value = condition()
        if value:
            return value
        reason = gone() if gone is not None else None
        if reason is not None:  # what it printed before it exited may still be on its way to a reader thread
            time.sleep(GRACE_S)
            value = condition()
            if value:
                return value
        waited = time.monotonic() - start
        if reason is None and waited > timeout:
            reason = f"not within {timeout:g} s"
        if reason is not None:
            raise AssertionError(f"waited {waited:.1f} s for {what}: {reason}; seen:\n{seen()}")
        if step is not None:
            step()
        else:
            time.sleep(interval)


def exited(popen: subprocess.Popen[str] | subprocess.Popen[bytes], name: str = "the process"
           ) -> Callable[[], str | None]:
    """A ``gone`` for :func:`wait_until`: why ``popen`` can no longer deliver (its exit code), or None."""
    def reason() -> str | None:
        code = popen.poll()
        return None if code is None else f"{name} exited with {code}"
    return reason


def tail(lines: Sequence[str], n: int = 30) -> str:
    """The last ``n`` of ``lines`` as text (what a failed wait shows)."""
    return "\n".join(lines[-n:])


def wait_for_line(lines: Sequence[str], text: str, popen: subprocess.Popen[str] | None = None, *,
                  timeout: float = DEADLINE_S, start: int = 0, name: str = "the process") -> int:
    """Index of the first of ``lines`` (from ``start``; a list a reader thread appends to) that contains
    ``text``; fails with the last lines when ``timeout`` passes or ``popen`` exits first."""
    def found() -> int | None:  # the index + 1: line 0 is a hit too
        return next((i + 1 for i, line in enumerate(lines[start:], start) if text in line), None)

    return wait_until(found, lambda: tail(lines), what=f"'{text}' from {name}", timeout=timeout,
                      gone=exited(popen, name) if popen is not None else None) - 1


class NodeProcess:
    """``dualarm run NODE --ros-args ARGS`` in the background (real scheduling: thread_priority 0), its
    output collected line by line in :attr:`lines`; ``env`` adds to :func:`node_env` (a ROS domain)."""

    def __init__(self, node: str, *ros_args: str, env: dict[str, str] | None = None) -> None:
        import sys
        import threading
        from pathlib import Path

        self.name = node
        self.popen = subprocess.Popen(
            [sys.executable, "-u", "-m", "dualarm_control.app.cli", "run", node, "--ros-args",
             "-p", "thread_priority:=0", *ros_args], cwd=Path(__file__).parents[1], stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, env={**node_env(), **(env or {})})
        self.lines: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, text: str, start: int = 0, timeout: float = DEADLINE_S) -> int:
        """Index of the first line (from ``start``) containing ``text`` (:func:`wait_for_line`)."""
        return wait_for_line(self.lines, text, self.popen, timeout=timeout, start=start, name=self.name)

    def stop(self) -> int:
        """SIGINT, then its exit code (SIGKILL and -9 after 30 s)."""
        import signal

        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGINT)
        try:
            return self.popen.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait()
            return -9
