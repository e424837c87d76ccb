"""The absolute pose of the two tools (the cooperative task space: Chiacchio, Chiaverini and Siciliano 1996;
issue 41) and a task that drives it to a target.

For the tool frames T1 (left) and T2 (right), world poses (p1, R1), (p2, R2):

    p_a = (p1 + p2) / 2,      R_a = R1 exp(1/2 log(R1^T R2))        (halfway along the relative rotation)

Twists (world axes; J1, J2 the tools' LOCAL_WORLD_ALIGNED Jacobians, (6, n) each, [J_v; J_w]):

    v_a = (v1 + v2) / 2                                              exact
    w_a = w1 + R_a Jexp(phi/2) 1/2 Jlog(R_r) R2^T (w2 - w1)          exact, phi = log(R_r), R_r = R1^T R2

(R_r's body angular velocity is R2^T (w2 - w1); d phi = Jlog(R_r) of it; R_h = exp(phi/2) moves with body
angular velocity Jexp(phi/2) d phi / 2; R_a = R1 R_h. pinocchio's Jexp3, Jlog3.) At phi = 0 this is
w_a = (w1 + w2) / 2, the first-order form. The halfway frame is undefined where the tools' relative rotation
is a half turn (|phi| = pi: the assembly's tools face each other); there the absolute frame is an object
frame fixed to the left tool's grasp, ``grasp`` (p_o = p1 + R1 p_g, R_o = R1 R_g: the frame of a held
object), with the left tool's Jacobian moved to it.

Units: m, rad, s; joint order of :class:`~dualarm_control.kinematics.DualArmModel`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dualarm_control.kinematics import (
    LEFT_TOOL,
    RIGHT_TOOL,
    Configuration,
    FloatArray,
    luh_components,
    skew,
)
from dualarm_control.tasks.base import (
    DEFAULT_EQUALITY_WEIGHT,
    EQUALITY,
    Kind,
    TaskRows,
    check_gain_weight,
)
from dualarm_control.tasks.registry import TaskContext, TaskSpec, register_task

HALF_TURN_MARGIN = 1e-3
"""rad: how close to a half turn the tools' relative rotation may come before the halfway frame is refused."""


@dataclass(frozen=True)
class AbsoluteState:
    """The absolute frame at one configuration: position [m] (3,), rotation (3, 3), Jacobian (6, n) [J_v; J_w]."""

    position: FloatArray
    rotation: FloatArray
    jacobian: FloatArray


def halfway_state(conf: Configuration) -> AbsoluteState:
    """The halfway frame of the two tools and its exact Jacobian (module docstring); ValueError at a half turn."""
    s1, s2 = conf.frame(LEFT_TOOL), conf.frame(RIGHT_TOOL)
    r_r = s1.rotation.T @ s2.rotation
    phi = pin.log3(r_r)
    if np.linalg.norm(phi) > math.pi - HALF_TURN_MARGIN:
        raise ValueError(f"the tools' relative rotation is a half turn ({np.linalg.norm(phi):.4f} rad): the halfway "
                         "frame is undefined; use an object frame fixed to the grasp")
    r_a = s1.rotation @ pin.exp3(0.5 * phi)
    j1, j2 = s1.jacobian, s2.jacobian
    spread = r_a @ pin.Jexp3(0.5 * phi) @ (0.5 * pin.Jlog3(r_r)) @ s2.rotation.T
    jacobian = np.vstack((0.5 * (j1[:3] + j2[:3]), j1[3:] + spread @ (j2[3:] - j1[3:])))
    return AbsoluteState(0.5 * (s1.position + s2.position), r_a, jacobian)


def grasp_state(conf: Configuration, offset: pin.SE3) -> AbsoluteState:
    """An object frame fixed to the left tool at ``offset`` (the object in the tool frame): p_o = p1 + R1 p_g,
    R_o = R1 R_g, J_v = J_v1 - S(R1 p_g) J_w1, J_w = J_w1."""
    s1 = conf.frame(LEFT_TOOL)
    lever = s1.rotation @ offset.translation
    jac = s1.jacobian
    return AbsoluteState(s1.position + lever, s1.rotation @ offset.rotation,
                         np.vstack((jac[:3] - skew(lever) @ jac[3:], jac[3:])))


@dataclass(frozen=True)
class AbsolutePoseTask:
    """The absolute frame (halfway, or fixed to the grasp with ``grasp``) at a target pose: 6 equality rows,
    f = [p_a - p*; -e_o(R_a, R*)] (Luh's error, as paper 000's eq 10 for the relative pose), b = 0,
    df/dq = J_a, df/dt = -[v*; w*] (a fixed target: 0). Exact Jacobian for the position rows; for the
    orientation rows exact at zero error, as :class:`~dualarm_control.tasks.relative_pose.RelativePoseTask`.

    Attributes:
        position: p* [m] (3,), world. rotation: R* (3, 3), world. grasp: None (halfway) or the object in the
        left tool frame. gain: k [1/s]. weight: slack weight. linear_velocity, angular_velocity: the target's
        twist v* [m/s], w* [rad/s] (3,) each, world axes (a moving target: df/dt = -[v*; w*]); None: at rest.
    """

    position: FloatArray
    rotation: FloatArray
    gain: float
    grasp: pin.SE3 | None = None
    weight: float = DEFAULT_EQUALITY_WEIGHT
    name: str = "absolute_pose"
    kind: Kind = EQUALITY
    linear_velocity: FloatArray | None = None
    angular_velocity: FloatArray | None = None

    def __post_init__(self) -> None:
        check_gain_weight(self.name, self.gain, self.weight)
        if np.asarray(self.position).shape != (3,) or not np.all(np.isfinite(self.position)):
            raise ValueError(f"task {self.name!r}: position must be 3 finite numbers [m], got {self.position}")

    def state(self, conf: Configuration) -> AbsoluteState:
        return halfway_state(conf) if self.grasp is None else grasp_state(conf, self.grasp)

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        state = self.state(conf)
        ox, oy, oz = luh_components(state.rotation, np.asarray(self.rotation, float))
        value = np.concatenate((state.position - self.position, (-ox, -oy, -oz)))
        twist = np.zeros(6)
        if self.linear_velocity is not None:
            twist[:3] = self.linear_velocity
        if self.angular_velocity is not None:
            twist[3:] = self.angular_velocity
        return TaskRows(self.name, self.kind, value, np.zeros(6), state.jacobian, -twist, self.gain, self.weight)


def _pose(spec: TaskSpec, prefix: str, required: bool) -> pin.SE3 | None:
    """``<prefix>position`` [m] and ``<prefix>rpy_deg`` of a task spec as an SE3 (None when absent and not required)."""
    if not required and f"scenario.{spec.name}.{prefix}position" not in spec.values:
        return None
    position = [float(v) for v in spec.value(f"{prefix}position", list)]
    rpy = [math.radians(float(v)) for v in spec.value(f"{prefix}rpy_deg", list, [0.0, 0.0, 0.0])]
    if len(position) != 3 or len(rpy) != 3 or not all(map(math.isfinite, position + rpy)):
        raise ValueError(f"{prefix}position and {prefix}rpy_deg must be 3 finite numbers each")
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(position))


@register_task("absolute_pose")
def absolute_pose(spec: TaskSpec, context: TaskContext) -> AbsolutePoseTask:
    """``position`` [m] and ``rpy_deg`` (world); optional ``grasp_position`` [m] and ``grasp_rpy_deg`` (the
    object in the left tool frame; without them the halfway frame)."""
    target = _pose(spec, "", True)
    assert target is not None
    return AbsolutePoseTask(target.translation, target.rotation, context.gain, _pose(spec, "grasp_", False),
                            weight=spec.value("weight", float, DEFAULT_EQUALITY_WEIGHT), name=spec.name)
