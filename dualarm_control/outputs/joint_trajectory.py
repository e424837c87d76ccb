"""``joint_trajectory``: a one-point trajectory_msgs/JointTrajectory reached one control period from now,
MoveIt Servo's form (what joint_trajectory_controller takes from it)."""

from __future__ import annotations

from typing import Any

import numpy as np

from dualarm_control.errors import InputRejected
from dualarm_control.outputs.base import (
    FloatArray,
    OutputSpec,
    OutputType,
    by_name,
    register,
)
from dualarm_control.ros import cdr

_EMPTY = np.zeros(0)


@register
class JointTrajectoryOutput(OutputType):
    """``joint_names`` the output's joints; one point whose ``positions`` or ``velocities`` (per the
    interface; the other field empty) are the values [rad or rad/s], ``time_from_start`` one period;
    header stamp zero (start now). Read back by joint name; exactly one point."""

    key = "joint_trajectory"
    type_name = "trajectory_msgs/msg/JointTrajectory"

    def encode(self, spec: OutputSpec, values: FloatArray, period: float) -> bytes:
        return cdr.joint_trajectory_point(spec.joints, values if spec.position else _EMPTY,
                                          _EMPTY if spec.position else values, round(period * 1e9))

    def decode(self, spec: OutputSpec, msg: Any) -> FloatArray:
        if len(msg.points) != 1:
            raise InputRejected(f"trajectory command with {len(msg.points)} points rejected: expected 1", "points",
                                len(msg.points))
        point = msg.points[0]
        return by_name(spec, msg.joint_names, point.positions if spec.position else point.velocities,
                       "trajectory command")
