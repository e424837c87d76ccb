"""What a commanding node sends besides its cycles: the safe state, rejections, and the counters.

:class:`CommandOutput` owns the command and /diagnostics publishers of a node that commands
the arms (docs/safety.md): a zero-velocity safe command with its reason, the watchdog fault
(logged once when it starts and when it ends), throttled log lines, and the cumulative
counters that account for every command sent (``cycles + safe_commands``). Nothing here holds
control math.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from dualarm_control.ros import convert
from dualarm_control.ros.inputs import WINDOW, CycleTiming, Throttle
from dualarm_control.status import Status

COUNTERS = ("cycles", "safe_commands", "unmatched_commands", "watchdog_trips", "solver_failures",
            "solver_fallbacks", "rejected_inputs", "bounds_violations", "parameter_switches")
"""Cumulative counts on /diagnostics (and ``missed_deadlines`` of :class:`CycleTiming`):
``cycles + safe_commands`` is every command published, ``unmatched_commands`` of them while no
subscriber was matched."""
ERROR = 2


class CommandOutput:
    """Commands, /diagnostics and the safe state of the node named ``name`` (``nq`` joints); the
    commands go out through ``sink`` (:class:`~dualarm_control.ros.hardware_io.CommandSink`: the
    hardware profile's outputs)."""

    def __init__(self, name: str, log: Any, sink: Any, pub_diag: Any, nq: int, timing: CycleTiming) -> None:
        self.name, self.log, self.sink, self.pub_diag, self.nq = name, log, sink, pub_diag, nq
        self.timing = timing
        self.solver = ""  # the running solver, named in every status
        self.count = dict.fromkeys(COUNTERS, 0)
        self.fault: tuple[str, int] | None = None  # watchdog reason and monotonic ns it started
        self.throttle = Throttle(1.0)

    def counters(self) -> dict[str, int]:
        return {**self.count, "missed_deadlines": self.timing.missed}

    def watchdog_text(self) -> str:
        return "ok" if self.fault is None else self.fault[0]

    def send(self, velocities: np.ndarray, safe: bool = False) -> None:
        """``velocities`` [rad/s] on every command output of the sink (``safe``: a safe stop, see
        :meth:`~dualarm_control.ros.hardware_io.CommandSink.send`)."""
        self.sink.send(velocities, safe)
        if self.sink.get_subscription_count() == 0:
            self.count["unmatched_commands"] += 1

    def status(self, stamp: int, level: int, message: str, values: dict[str, Any]) -> None:
        """One /diagnostics status of this node, with ``values``."""
        self.pub_diag.publish(convert.diagnostics(stamp, self.name, level, message, values))

    def warn(self, text: str) -> None:
        """Log at most once a second (with the count of suppressed lines)."""
        line = self.throttle.text(text)
        if line is not None:
            self.log.warning(line)

    def report(self, stamp: int, reason: str, status: str, level: int = 1) -> None:
        """Reason on /diagnostics (every time, WARN unless ``level`` says otherwise) and in the log
        (throttled), with the counters that account for every command sent."""
        self.warn(f"{status}: {reason}")
        self.status(stamp, level, reason, {"solver": self.solver, "status": status,
                                           "watchdog": self.watchdog_text(), **self.counters()})

    def reject(self, stamp: int, reason: str) -> None:
        """A rejected input: counted, on /diagnostics and in the throttled log; the last valid input is kept."""
        self.count["rejected_inputs"] += 1
        self.report(stamp, reason, "input_rejected")

    def safe(self, stamp: int, reason: str, level: int = 1) -> None:
        """Zero-velocity command with the reason on /diagnostics (``level``) and in the (throttled) log."""
        self.send(np.zeros(self.nq), safe=True)
        self.count["safe_commands"] += 1
        self.report(stamp, reason, "safe_command", level)

    def enter_safe_state(self, stamp: int, reason: str) -> None:
        """Watchdog fault: zero command, /diagnostics ERROR with the reason, logged once per fault."""
        if self.fault is None:
            self.fault = (reason, time.monotonic_ns())
            self.count["watchdog_trips"] += 1
            self.log.error(f"safe state: {reason}; zero-velocity commands until the inputs return")
        self.safe(stamp, reason, ERROR)

    def leave_safe_state(self) -> None:
        if self.fault is not None:
            (reason, since), self.fault = self.fault, None
            self.log.info(f"recovered after {(time.monotonic_ns() - since) / 1e9:.3f} s in the safe state "
                          f"({reason}); commands resume")

    def cycle(self, velocities: np.ndarray, result: Any) -> None:
        """A cycle's command: sent and counted with its solver outcome (failures and fallbacks logged)."""
        self.send(velocities)
        self.count["cycles"] += 1
        if result.failed:
            self.count["solver_failures"] += 1
            self.count["bounds_violations"] += result.status == Status.BOUNDS_VIOLATED
            self.warn(f"solver {result.status}: {result.detail}; safe command sent")
        elif result.fell_back:
            self.count["solver_fallbacks"] += 1
            self.warn(f"solver fallback: {result.detail}")

    def summary(self) -> str:
        """The counters and the timing percentiles, for the log line at shutdown."""
        (j50, j99), (l50, l99) = self.timing.percentiles()
        c = self.counters()
        return (f"{c['cycles']} cycles, {c['missed_deadlines']} missed deadlines, {c['solver_failures']} solver "
                f"failures, {c['solver_fallbacks']} solver fallbacks, {c['rejected_inputs']} rejected inputs, "
                f"{c['safe_commands']} safe commands, {c['unmatched_commands']} unmatched commands, "
                f"{c['watchdog_trips']} watchdog trips, {c['parameter_switches']} parameter switches, "
                f"period jitter p50/p99 {j50 * 1e3:.3f}/{j99 * 1e3:.3f} ms, state-to-command latency "
                f"p50/p99 {l50 * 1e3:.3f}/{l99 * 1e3:.3f} ms (last {WINDOW} cycles)")
