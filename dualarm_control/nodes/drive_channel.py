"""One online generator's goal judging and ``/diagnostics`` status in the interactive drive: the relative pose's
(status ``trajectory_node``), or the absolute frame's (issue 41: status ``trajectory_node/absolute``).

Each cycle :meth:`DriveChannel.status` judges the generator's goal on the measured joints
(:class:`~dualarm_control.drive_monitor.GoalMonitor`, on the channel's pose: relative or absolute), logs a change
of state, holds where the arms are after a stall, and reports a refused command for :data:`REJECTED_HOLD_S`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from dualarm_control.drive_monitor import GoalMonitor
from dualarm_control.drive_status import REACHED, REJECTED, STALLED, status_values
from dualarm_control.kinematics import FloatArray
from dualarm_control.online_trajectory import OnlineTrajectory
from dualarm_control.ros import convert

REJECTED_HOLD_S = 1.0  # s a rejection stays the reported state (unless a command is accepted)

Pose = Callable[[FloatArray], tuple[FloatArray, FloatArray]]
"""The channel's measured pose at q (n,) [rad]: position [m] (3,), rotation (3, 3)."""


@dataclass
class DriveChannel:
    """A generator with its judge and its reported state.

    Attributes:
        name: ``/diagnostics`` status name. label: what a goal is called in log lines ("goal", "absolute goal").
        monitor: the goal's judge (on ``pose``). pose: the measured pose the generator drives.
        generator: None until the first joint state. rejected: the last refused command (goal stamp, reason,
        generator time), reported for :data:`REJECTED_HOLD_S`. last_state: the last judged state.
    """

    name: str
    label: str
    monitor: GoalMonitor
    pose: Pose
    generator: OnlineTrajectory | None = None
    rejected: tuple[float | None, str, float] | None = None
    last_state: str = ""

    def reject(self, stamp: float | None, reason: str) -> None:
        gen = self.generator
        self.rejected = (stamp, reason, gen.time if gen is not None else 0.0)

    def status(self, stamp_ns: int, q: FloatArray, log: Any) -> bytes | None:
        """The cycle's judgement of the goal at q (n,) [rad] as a DiagnosticArray (CDR); None before the start."""
        gen = self.generator
        if gen is None:
            return None
        progress = gen.progress()
        goal = (gen.goal.position, gen.goal.rotation) if gen.goal is not None else None
        verdict = self.monitor.judge(progress, goal, q, gen.time)
        state, reason, goal_stamp = verdict.state, verdict.reason, None
        if verdict.state != self.last_state:
            self._log_state(log, verdict.state, verdict.distance, verdict.angle, reason, progress.goal_stamp)
            self.last_state = verdict.state
            if verdict.state == STALLED:  # hold where the arms are: the controller stops pushing
                gen.hold(*self.pose(q))
        if self.rejected is not None:
            if gen.time - self.rejected[2] <= REJECTED_HOLD_S:
                goal_stamp, reason, state = self.rejected[0], self.rejected[1], REJECTED
            else:
                self.rejected = None
        values = status_values(dataclasses.replace(progress, distance=verdict.distance, angle=verdict.angle),
                               state=state, reason=reason, goal_stamp=goal_stamp)
        level = 1 if state in (STALLED, REJECTED) else 0
        return convert.diagnostics(stamp_ns, self.name, level, state, values)

    def _log_state(self, log: Any, state: str, distance: float, angle: float, reason: str,
                   stamp: float | None) -> None:
        if state == REACHED and stamp is not None:
            log.info(f"{self.label} reached (stamp {stamp:.9f}): error {distance * 1000:.3f} mm, {angle:.5f} rad")
        elif state == STALLED:
            log.warning(f"{self.label} stalled (stamp {stamp:.9f}): {reason}")
