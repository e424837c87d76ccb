"""A user's own limits and task, in the user's own file (docs/limits.md's worked example).

Loaded with the controller parameter ``plugins: [path/to/keep_above.py]`` (limits) or the scenario key
``scenario.plugins`` (task types); nothing in the package changes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dualarm_control.kinematics import Configuration
from dualarm_control.limits import Constraint, Limit, LimitContext, register_limit
from dualarm_control.tasks import (
    EQUALITY,
    TaskContext,
    TaskRows,
    TaskSpec,
    register_task,
)

FLOOR = 1.25
"""m: the lowest world height the left tool may reach (keep_above)."""

CAP = 0.3
"""rad/s: every joint's speed cap (joint_speed_cap)."""


@dataclass(frozen=True)
class KeepAbove(Limit):
    """The frame's origin stays above a height z_min [m]: one row, a velocity damper on its height,

        z_dot >= -gain (z - z_min)   i.e.   -J_z qd <= gain (z - z_min)   [m/s],

    J_z (1, n) the frame's linear Jacobian's z row (world axes)."""

    frame: str
    floor: float
    gain: float = 5.0
    name: str = "keep_above"

    def constraints(self, configuration: Configuration, previous: np.ndarray) -> Constraint:
        state = configuration.frame(self.frame)
        row = -state.jacobian[2:3]
        bound = np.array([self.gain * (state.position[2] - self.floor)])
        return Constraint.of_rows(row, bound, (f"{self.frame} above {self.floor} m",))


@dataclass(frozen=True)
class SpeedCap(Limit):
    """Every joint's speed at most ``cap`` [rad/s] (a box)."""

    cap: float
    name: str = "joint_speed_cap"

    def constraints(self, configuration: Configuration, previous: np.ndarray) -> Constraint:
        upper = np.full(configuration.q.shape[0], self.cap)
        return Constraint(-upper, upper)


@register_limit("keep_above")
def keep_above(context: LimitContext) -> KeepAbove:
    return KeepAbove("left_tool", FLOOR)


@register_limit("joint_speed_cap")
def joint_speed_cap(context: LimitContext) -> SpeedCap:
    return SpeedCap(CAP)


@dataclass(frozen=True)
class ToolHeight:
    """The frame's origin at height z* [m]: f = z - z*, b = 0, df/dq = J_z, one equality row."""

    frame: str
    height: float
    gain: float
    weight: float = 1.0
    name: str = "tool_height"
    kind: str = EQUALITY

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        state = conf.frame(self.frame)
        return TaskRows(self.name, EQUALITY, np.array([state.position[2] - self.height]), np.zeros(1),
                        state.jacobian[2:3].copy(), np.zeros(1), self.gain, self.weight)


@register_task("tool_height")
def tool_height(spec: TaskSpec, context: TaskContext) -> ToolHeight:
    """``frame``, ``height`` [m]."""
    return ToolHeight(spec.value("frame", str), spec.value("height", float), context.gain, name=spec.name)
