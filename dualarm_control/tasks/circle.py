"""The tool tip on a circle relative to the pan, paper 001 eq (8)-(9) (scenario task type ``circle``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.kinematics import Configuration, FloatArray, skew
from dualarm_control.tasks.base import (
    DEFAULT_EQUALITY_WEIGHT,
    EQUALITY,
    Kind,
    TaskRows,
    check_gain_weight,
)
from dualarm_control.tasks.registry import TaskContext, TaskSpec, register_task


@dataclass(frozen=True)
class CircleTask:
    """Tool tip on a circle relative to the pan, paper 001 eq (8) (eq (9) with ``normal_offset``).

        f_1-3 = p_1 - p_2 - d(t) - f_F N = p_1 - p_2 + R_1 c(t),   b = 0  (equality, 3 rows)
        c(t) = [D cos(L t), D sin(L t), h - f_F]  in the pan frame,

    i.e. d(t) = -R_1 [D cos Lt, D sin Lt, h] (the circle of radius D in the pan's x-y plane,
    height h above it; the paper's handle terms 2D(z_1 + x_2) are zero here because the
    frames are at the pan centre and the tool tip) and N = z_1, the pan normal; f_F is the
    force controller's output [m] (eq 9; 0 without force feedback). With w_1 the angular
    velocity of the pan frame, d(R_1 c)/dt = w_1 x R_1 c, so (eq 18)

        df/dq = J_p1 - J_p2 - S(R_1 c) J_w1,   df/dt = R_1 c'(t) = R_1 [-D L sin Lt, D L cos Lt, 0].

    Attributes:
        pan_frame, tool_frame: frames 1 (pan centre, z = normal) and 2 (tool tip).
        radius: D [m], >= 0. rate: L [rad/s]. height: h [m]. normal_offset: f_F [m].
    """

    pan_frame: str
    tool_frame: str
    radius: float
    rate: float
    gain: float
    height: float = 0.0
    normal_offset: float = 0.0
    weight: float = DEFAULT_EQUALITY_WEIGHT
    name: str = "circle"
    kind: Kind = EQUALITY

    def __post_init__(self) -> None:
        check_gain_weight(self.name, self.gain, self.weight)
        if not (math.isfinite(self.radius) and self.radius >= 0):
            raise ValueError(f"task {self.name!r}: radius must be >= 0 [m], got {self.radius}")
        for key in ("rate", "height", "normal_offset"):
            if not math.isfinite(getattr(self, key)):
                raise ValueError(f"task {self.name!r}: {key} must be finite, got {getattr(self, key)}")

    def offset(self, t: float) -> FloatArray:
        """c(t): desired tip position in the pan frame [m], (3,)."""
        a = self.rate * t
        return np.array((self.radius * math.cos(a), self.radius * math.sin(a), self.height - self.normal_offset))

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        pan, tool = conf.frame(self.pan_frame), conf.frame(self.tool_frame)
        rc = pan.rotation @ self.offset(t)
        value = pan.position - tool.position + rc
        jac = pan.jacobian[:3] - tool.jacobian[:3] - skew(rc) @ pan.jacobian[3:]
        a = self.rate * t
        dc = np.array((-self.radius * self.rate * math.sin(a), self.radius * self.rate * math.cos(a), 0.0))
        return TaskRows(self.name, self.kind, value, np.zeros(3), jac, pan.rotation @ dc, self.gain, self.weight)


@register_task("circle")
def circle(spec: TaskSpec, context: TaskContext) -> CircleTask:
    """``pan_frame``, ``tool_frame``, ``radius`` [m], ``period`` [s] (L = 2 pi / period), ``height`` [m]."""
    return CircleTask(spec.value("pan_frame", str), spec.value("tool_frame", str),
                      radius=spec.value("radius", float), rate=2 * math.pi / spec.value("period", float),
                      height=spec.value("height", float, 0.0) + context.height_offset, gain=context.gain,
                      weight=spec.value("weight", float, DEFAULT_EQUALITY_WEIGHT), name=spec.name)
