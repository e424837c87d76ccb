"""What controller_node reports of a cycle: its /diagnostics status (level, message and values) and the
collision limit's log lines (ROS-free).

The values' keys, in this order (docs/ros2.md): ``solver``, ``status``, ``solve_time_s``, ``iterations``,
``active_joints``, ``control_period_s``, ``stamp_ns``, the cycle's own values (:func:`cycle_values`:
``scenario``, the tracker's report, every limit's report, in real time the timing), the counters,
``watchdog``, ``mode`` and ``robot``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from dualarm_control.controller import Cycle
from dualarm_control.limits.collision import CollisionReport
from dualarm_control.status import Status


def cycle_values(scenario: str, report: Mapping[str, Any], cycle: Cycle,
                 timing: Mapping[str, str] | None) -> dict[str, Any]:
    """A cycle's own values: the ``scenario`` parameter, the tracker's ``report``, every limit's report by
    name (docs/limits.md) and the ``timing`` values (real time, not for a timed tracker; else None)."""
    values = {"scenario": scenario, **report}
    for limit in cycle.reports.values():
        values.update(limit.values())
    if timing is not None:
        values.update(timing)
    return values


def cycle_status(stamp: int, cycle: Cycle, solver: str, period: float, values: Mapping[str, Any],
                 counters: Mapping[str, int], watchdog: str, lockstep: bool, robot: str) -> tuple[int, str, dict[str, Any]]:
    """(level, message, values) of the cycle of the joint state stamped ``stamp`` [ns]: ERROR (2) if the
    solver failed, WARN (1) if it did not solve exactly, else OK; ``period`` the control period [s]."""
    r = cycle.result
    return 2 if r.failed else int(r.status != Status.SOLVED), r.detail or r.status, {
        "solver": solver, "status": r.status, "solve_time_s": f"{r.solve_time:.6e}",
        "iterations": r.iterations, "active_joints": r.active_joints, "control_period_s": period,
        "stamp_ns": stamp, **values, **counters, "watchdog": watchdog,
        "mode": "lockstep" if lockstep else "realtime", "robot": robot}


class CollisionLog:
    """One log line when the collision limit starts holding a pair at its bound, one when it lets go."""

    def __init__(self, log: Any) -> None:
        self.log = log
        self.active = False

    def update(self, report: CollisionReport) -> None:
        """A cycle's collision report: logged if the limit started or stopped holding a pair."""
        active = report.active > 0
        if active != self.active:
            self.active = active
            if active:
                self.log.warning(f"collision constraint active: {report.text()}")
            else:
                self.log.info("collision constraint released")
