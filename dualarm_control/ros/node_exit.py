"""A node process's way out: exit codes, the wait for readers' acknowledgements at the end of a run
(:func:`flush_publishers`) and the watchdog that ends a process whose way out is stuck
(:class:`ExitWatchdog`). Used by :func:`dualarm_control.ros.node.run`."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_PARAMS = 2

ACK_TIMEOUT_S = 15.0
"""How long, in all, a stopping lockstep node waits for its readers to acknowledge what it published:
a deadline for a recorder starved on a busy machine (a trajectory node's flush took 5.4 s under
``stress-ng --cpu 1``, its recorder 2800 samples behind), below the launcher's grace before SIGTERM
(``app.run.launcher.STOP_GRACE_S``, 5 s more than this)."""

FINISHED_ACK_TIMEOUT_S = 2.0
"""How long, in all, a real-time node that ended by itself waits for its readers to acknowledge what it
published last: the trajectory node's "complete" status reaches a loaded recorder instead of dying with
the node's writer (a fault-matrix run under a parallel test load recorded no "complete" though the
node logged it); short, because a reader that died with its process is never acknowledged."""


EXIT_STUCK_S = ACK_TIMEOUT_S + 3.0
"""How long a node's way out (``close``, the lockstep flush, destroying the nodes, rclpy's shutdown) may take
before :class:`ExitWatchdog` ends the process: below the launcher's grace before SIGTERM
(``app.run.launcher.STOP_GRACE_S``)."""


def exit_process(code: int) -> NoReturn:
    """End a node's process with ``code`` once :func:`~dualarm_control.ros.node.run` has returned (rclpy shut down,
    the nodes destroyed): stdout and stderr flushed, then ``os._exit``, without the interpreter's finalization,
    whose C++ destructors (the middleware's) can hang with no watchdog left: in a loaded test run a lockstep
    sim_node that had logged its last line and returned was still there 20 s later, and the launcher's SIGTERM
    ended it (exit -15, the launch failed). The node modules' ``__main__`` ends with it."""
    import os

    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):  # a closed or broken stream: nothing more can be written
            pass
    os._exit(code)


class ExitWatchdog:
    """Ends a node process whose way out is stuck (started as that begins, :meth:`cancel` at its end).

    Under ``stress-ng --cpu 1`` a lockstep sim_node logged its last line ("stopping after ..."), its bag
    complete, and was still alive 20 s later, when the launcher's SIGTERM ended it (exit -15, the launch
    failed). After ``seconds`` this prints which stage was stuck and every thread's stack to stderr,
    then exits: 0 when the stage is ``teardown`` (everything published was delivered or its
    wait timed out; what is left is the middleware's own teardown), 1 otherwise.

    Attributes:
        stage: ``close``, ``flush`` or ``teardown`` (set by the caller as it goes).
    """

    def __init__(self, seconds: float, exit: Callable[[int], None] | None = None, stage: str = "close") -> None:
        import os

        self.stage = stage
        self.seconds = seconds
        self._exit = exit or os._exit
        # everything _fire reads is set before the timer starts: on a loaded machine a short timer fired
        # before _c_dump existed, its thread died of the AttributeError and nothing exited
        self._c_dump = _dump_stacks_later(seconds + C_DUMP_DELAY_S)
        self._timer = threading.Timer(seconds, self._fire)
        self._timer.daemon = True
        self._timer.start()

    def _fire(self) -> None:
        import traceback

        try:
            self._cancel_c_dump()
            stacks = "".join(f"Thread {ident:#x}:\n" + "".join(traceback.format_stack(frame))
                             for ident, frame in sys._current_frames().items())
            print(f"exit watchdog: the way out is stuck in '{self.stage}' after {self.seconds:.0f} s; every "
                  f"thread's stack:\n{stacks}", file=sys.stderr, flush=True)
        finally:
            self._exit(EXIT_OK if self.stage == "teardown" else EXIT_ERROR)

    def cancel(self) -> None:
        self._timer.cancel()
        self._cancel_c_dump()

    def _cancel_c_dump(self) -> None:
        if self._c_dump:
            import faulthandler

            faulthandler.cancel_dump_traceback_later()
            self._c_dump = False


C_DUMP_DELAY_S = 1.0
"""After the watchdog's own time, Python's faulthandler dumps every thread's stack from C and ends the process
(exit 1): it needs no GIL, so it also ends a way out stuck in a C call that holds it (then the watchdog's thread
cannot run: under stress a real-time controller_node logged its summary and was SIGTERMed 20 s later, no watchdog
line; in a loaded test run a real-time trajectory_node was still there 40 s after its SIGTERM)."""


def _dump_stacks_later(seconds: float) -> bool:
    """faulthandler's C-level dump of every stack to the process's stderr (fd 2) after ``seconds``, then exit 1;
    False when there is no such stream."""
    import faulthandler

    stream = sys.__stderr__
    if stream is None:
        return False
    try:
        faulthandler.dump_traceback_later(seconds, exit=True, file=stream)
    except (AttributeError, ValueError, OSError):  # no real stderr (closed, or no fileno)
        return False
    return True


def flush_publishers(nodes: Sequence[Any], timeout_s: float) -> bool:
    """Wait (at most ``timeout_s`` in all) until every reliable reader acknowledged every sample of the
    ``nodes``' publishers (rclpy ``Publisher.wait_for_all_acked``): a recorder lagging behind a fast
    lockstep run still receives what was queued at a node's exit, instead of losing it with the node's
    writer history. True when all were acknowledged in time."""
    from rclpy.duration import Duration

    end = time.monotonic() + timeout_s
    acked = True
    for publisher in [p for node in nodes for p in node.publishers]:
        left = max(0.0, end - time.monotonic())
        try:
            acked = publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))) and acked
        except RuntimeError:  # rclpy's RCLError / InvalidHandle: the context is gone, nothing to deliver
            acked = False
    return acked
