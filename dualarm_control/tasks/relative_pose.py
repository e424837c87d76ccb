"""Paper 000's closed-loop relative pose task, eq (8)-(13): J qd = xd* + K e."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import pinocchio as pin

from dualarm_control.kinematics import Configuration, FloatArray, luh_components
from dualarm_control.tasks.base import (
    DEFAULT_EQUALITY_WEIGHT,
    EQUALITY,
    Kind,
    TaskRows,
    check_gain_weight,
)
from dualarm_control.tasks.registry import TaskContext, TaskSpec, register_task


class RelativeTarget(Protocol):
    """A desired relative pose and twist (x*, xd*) of F2 in F1 (paper 000)."""

    @property
    def position(self) -> FloatArray: ...  # (3,) m

    @property
    def rotation(self) -> FloatArray: ...  # (3, 3)

    @property
    def linear_velocity(self) -> FloatArray: ...  # (3,) m/s

    @property
    def angular_velocity(self) -> FloatArray: ...  # (3,) rad/s


@dataclass(frozen=True)
class RelativePoseTask:
    """Relative pose of F2 in F1 equal to a target, paper 000 eq (8)-(13), 6 equality rows.

    f = -e = [p - p*; -e_o(R, R*)] (Luh error, eq 10), b = 0, df/dq = J (relative Jacobian,
    eq 5), df/dt = -[v*; w*]; the rows are J qd = xd* + K e, eq (13). J is the exact Jacobian
    of the position rows; for the orientation rows it is exact at zero orientation error
    (where Luh's L matrix is the identity), the approximation of paper 000.
    """

    target: RelativeTarget
    gain: float
    weight: float = DEFAULT_EQUALITY_WEIGHT
    name: str = "relative_pose"
    kind: Kind = EQUALITY

    def __post_init__(self) -> None:
        check_gain_weight(self.name, self.gain, self.weight)

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        return relative_pose_rows(conf, self.target, self.gain, self.weight, self.name, self.kind)


def relative_pose_rows(conf: Configuration, target: RelativeTarget, gain: float,
                       weight: float = DEFAULT_EQUALITY_WEIGHT, name: str = "relative_pose",
                       kind: Kind = EQUALITY) -> TaskRows:
    """:class:`RelativePoseTask`'s rows at ``conf`` for ``target`` and gain k [1/s] (> 0, not checked here: the
    task checks it once; :meth:`RelativeController.step <dualarm_control.controller.RelativeController.step>`
    calls this every cycle with its validated gain): f = [p - p*; -e_o] (6,) [m; rad], b = 0, df/dq = J (6, n),
    df/dt = -[v*; w*] (6,) [m/s; rad/s]."""
    state = conf.relative()
    px, py, pz = state.position.tolist()
    tx, ty, tz = np.asarray(target.position, float).tolist()
    ox, oy, oz = luh_components(state.rotation, np.asarray(target.rotation, float))
    value = np.array((px - tx, py - ty, pz - tz, -ox, -oy, -oz))  # f = -e = [p - p*; -e_o]
    vx, vy, vz = np.asarray(target.linear_velocity, float).tolist()
    wx, wy, wz = np.asarray(target.angular_velocity, float).tolist()
    time_derivative = np.array((-vx, -vy, -vz, -wx, -wy, -wz))  # df/dt = -[v*; w*]
    return TaskRows(name, kind, value, np.zeros(6), state.jacobian, time_derivative, gain, weight)


@dataclass(frozen=True)
class FixedTarget:
    """A relative target at rest: p* [m] (3,) and R* (3, 3) of F2 in F1, zero twist."""

    position: FloatArray
    rotation: FloatArray
    linear_velocity: FloatArray = field(default_factory=lambda: np.zeros(3))
    angular_velocity: FloatArray = field(default_factory=lambda: np.zeros(3))


@register_task("relative_pose")
def relative_pose(spec: TaskSpec, context: TaskContext) -> RelativePoseTask:
    """``position`` [m] and ``rpy_deg`` of the right tool in the left tool's frame F1, held (zero twist)."""
    position = [float(v) for v in spec.value("position", list)]
    rpy = [math.radians(float(v)) for v in spec.value("rpy_deg", list, [0.0, 0.0, 0.0])]
    if len(position) != 3 or len(rpy) != 3 or not all(map(math.isfinite, position + rpy)):
        raise ValueError("position and rpy_deg must be 3 finite numbers each")
    target = FixedTarget(np.array(position), pin.rpy.rpyToMatrix(*rpy))
    return RelativePoseTask(target, context.gain, spec.value("weight", float, DEFAULT_EQUALITY_WEIGHT), spec.name)
