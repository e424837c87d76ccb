"""The task time of controller_node's timed tracker (a task scenario, paper 001) and the gate before its start (ROS-free).

t = joint-state stamp - the first stamp (lockstep: t = k T, as the in-process runner); in real time the
task starts only once /diagnostics has ``readers`` readers (``task_start_readers``: a recorder, so that
its bag holds the run from t = 0); after ``steps`` cycles the task is over.
"""

from __future__ import annotations

from collections.abc import Callable


class TaskClock:
    """Task time [s] of a tracker of ``steps`` cycles of ``period`` [s]; ``readers``: the /diagnostics
    readers awaited before the start in real time (0: none)."""

    def __init__(self, steps: int, period: float, lockstep: bool, readers: int) -> None:
        self.steps, self.period, self.lockstep, self.readers = steps, period, lockstep, readers
        self.first_stamp: int | None = None
        """Stamp [ns] of the first joint state of the task (t = 0); None before the start."""

    def waiting(self, reader_count: Callable[[], int]) -> str:
        """Why the task does not start yet ('' once it started or may start): real time, fewer than
        ``readers`` /diagnostics readers (``reader_count()``, asked only before the start)."""
        if self.first_stamp is None and not self.lockstep and reader_count() < self.readers:
            return f"waiting for {self.readers} /diagnostics reader(s) before the task starts"
        return ""

    def time(self, stamp: int) -> float | None:
        """t [s] at the joint state stamped ``stamp`` [ns] (the first call starts the task; lockstep: k T),
        or None once its steps are done."""
        if self.first_stamp is None:
            self.first_stamp = stamp
        elapsed = stamp - self.first_stamp
        step = round(elapsed / (self.period * 1e9))
        if step >= self.steps:
            return None
        return step * self.period if self.lockstep else elapsed * 1e-9
