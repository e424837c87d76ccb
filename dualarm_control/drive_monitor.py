"""Is a goal reached by the arms, or stalled? (The interactive trajectory node's judge; no ROS.)

The online generator (:mod:`dualarm_control.online_trajectory`) says when its *target* is at
the goal (state ``reached``). The arms follow with a tracking error; when joint limits stop
them (the goal inside the reach bound but not in the arms' workspace, or only across a limit),
the target arrives and the arms do not. So, per cycle, with the measured relative pose
``(p, R)`` of the joint state and the goal ``(p_g, R_g)``:

* the goal is **reached** when the target is and ``||p - p_g|| <= position_tolerance`` [m] and
  ``angle(R_g R^T) <= angle_tolerance`` [rad] (defaults 0.5 mm, 5 mrad: inside the issue's
  1 mm / 0.01 rad);
* it is **stalled** when the target has been at the goal for ``stall_time`` [s] (default 2 s;
  the tracking error of the relative pose task decays with the task gain, e^{-k t}) without
  that: the remaining error and the joints within ``limit_margin`` [rad] of a position limit
  are reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.online_trajectory import MOVING, REACHED, STALLED, GoalProgress

POSITION_TOLERANCE = 5e-4  # m
ANGLE_TOLERANCE = 5e-3  # rad
STALL_TIME = 2.0  # s
LIMIT_MARGIN = 1e-2  # rad


def joints_at_limit(model: DualArmModel, q: FloatArray, margin: float = LIMIT_MARGIN) -> list[str]:
    """Names of the joints of q (n,) [rad] within ``margin`` [rad] of their lower or upper limit."""
    near = (q <= model.q_min + margin) | (q >= model.q_max - margin)
    return [name for name, hit in zip(model.joint_names, near, strict=True) if hit]


@dataclass(frozen=True)
class Verdict:
    """The node's view of the goal this cycle: ``state`` (``moving``, ``reached``, ``stalled``, or
    the generator's own), the measured ``distance`` [m] and ``angle`` [rad] to the goal, and a
    ``reason`` (a stall's remaining error and joints at a limit)."""

    state: str
    distance: float
    angle: float
    reason: str = ""


class GoalMonitor:
    """Judges each cycle of one goal (:meth:`reset` for a new goal); see the module docstring."""

    def __init__(self, model: DualArmModel, position_tolerance: float = POSITION_TOLERANCE,
                 angle_tolerance: float = ANGLE_TOLERANCE, stall_time: float = STALL_TIME) -> None:
        self.model = model
        self.position_tolerance = position_tolerance
        self.angle_tolerance = angle_tolerance
        self.stall_time = stall_time
        self.reset()

    def reset(self) -> None:
        """A new goal (or none): forget when the target arrived."""
        self.arrived: float | None = None  # time [s] the target reached the goal
        self.final: str | None = None  # reached / stalled: kept until the next goal

    def judge(self, progress: GoalProgress, goal: tuple[FloatArray, FloatArray] | None, q: FloatArray,
              t: float) -> Verdict:
        """The verdict at time t [s] for the generator's ``progress``, its goal ``(p_g (3,), R_g (3, 3))``
        (None: no goal) and the measured joint positions q (n,) [rad]."""
        if goal is None:
            return Verdict(progress.state, 0.0, 0.0)
        p, r = self.model.relative_pose(q)
        distance = float(np.linalg.norm(p - goal[0]))
        angle = float(np.linalg.norm(pin.log3(goal[1] @ r.T)))
        if self.final is not None:
            return Verdict(self.final, distance, angle)
        if progress.state != REACHED:
            self.arrived = None
            return Verdict(progress.state, distance, angle)
        if distance <= self.position_tolerance and angle <= self.angle_tolerance:
            self.final = REACHED
            return Verdict(REACHED, distance, angle)
        if self.arrived is None:
            self.arrived = t
        if t - self.arrived < self.stall_time:
            return Verdict(MOVING, distance, angle)
        self.final = STALLED
        joints = joints_at_limit(self.model, q)
        reason = (f"remaining error {distance * 1000:.2f} mm, {angle:.4f} rad "
                  f"{self.stall_time:g} s after the target arrived; joints at a limit: "
                  f"{', '.join(joints) if joints else 'none'}")
        return Verdict(STALLED, distance, angle, reason)
