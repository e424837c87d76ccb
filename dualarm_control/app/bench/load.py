"""Load on the machine during a benchmark: one core kept busy (``--load busy``).

Used by the launches of :mod:`dualarm_control.app.bench.realtime` and the probes of
:mod:`dualarm_control.app.bench.floor`, so that a launch and its floor run under the same load.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager


def busy_command() -> list[str]:
    """A process keeping one core busy: ``stress-ng --cpu 1`` if installed, else a Python spin loop."""
    if shutil.which("stress-ng"):
        return ["stress-ng", "--cpu", "1", "--quiet"]
    return [sys.executable, "-S", "-c", "while True: pass"]


@contextmanager
def busy_core(on: bool) -> Iterator[None]:
    """While in the block, :func:`busy_command` runs at normal priority (when ``on``); killed after."""
    if not on:
        yield
        return
    proc = subprocess.Popen(busy_command(), stdout=subprocess.DEVNULL, start_new_session=True)
    try:
        yield
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
