"""The tool axis inside a cone about the reversed pan normal, paper 001 f_4 (scenario task type ``cone``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.kinematics import Configuration
from dualarm_control.tasks.base import (
    DEFAULT_INEQUALITY_WEIGHT,
    INEQUALITY,
    Kind,
    TaskRows,
    check_gain_weight,
)
from dualarm_control.tasks.registry import TaskContext, TaskSpec, register_task


@dataclass(frozen=True)
class ConeTask:
    """Tool axis inside a cone about the reversed pan normal, paper 001 f_4 (1 inequality row).

        f_4 = z_1^T z_2 <= b_4 = -cos(max_angle),

    z_1 the pan normal, z_2 the tool axis (both frames' z): the tool points into the pan
    within ``max_angle`` of -z_1. With z_i' = w_i x z_i,
    df/dq = (z_1 x z_2)^T (J_w1 - J_w2), df/dt = 0.

    Attributes:
        max_angle: cone half-angle [rad], in (0, pi).
    """

    pan_frame: str
    tool_frame: str
    max_angle: float
    gain: float
    weight: float = DEFAULT_INEQUALITY_WEIGHT
    name: str = "cone"
    kind: Kind = INEQUALITY

    def __post_init__(self) -> None:
        check_gain_weight(self.name, self.gain, self.weight)
        if not 0.0 < self.max_angle < math.pi:
            raise ValueError(f"task {self.name!r}: max_angle must be in (0, pi) [rad], got {self.max_angle}")

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        pan, tool = conf.frame(self.pan_frame), conf.frame(self.tool_frame)
        z1, z2 = pan.rotation[:, 2], tool.rotation[:, 2]
        jac = np.cross(z1, z2) @ (pan.jacobian[3:] - tool.jacobian[3:])
        return TaskRows(self.name, self.kind, np.array([z1 @ z2]), np.array([-math.cos(self.max_angle)]),
                        jac[None, :], np.zeros(1), self.gain, self.weight)


@register_task("cone")
def cone(spec: TaskSpec, context: TaskContext) -> ConeTask:
    """``pan_frame``, ``tool_frame``, ``max_angle_deg``."""
    return ConeTask(spec.value("pan_frame", str), spec.value("tool_frame", str),
                    max_angle=math.radians(spec.value("max_angle_deg", float)), gain=context.gain,
                    weight=spec.value("weight", float, DEFAULT_INEQUALITY_WEIGHT), name=spec.name)
