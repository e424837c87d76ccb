"""The joint position and velocity limits as velocity bounds (paper 000, Sect. IV, eq (20)-(23)).

All vectors have shape (n,): positions in rad, velocities in rad/s, the period T in s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dualarm_control.limits.base import (
    POSITION_PRIORITY,
    Constraint,
    FloatArray,
    JointLimits,
    Limit,
)
from dualarm_control.limits.registry import LimitContext, register_limit

if TYPE_CHECKING:
    from dualarm_control.kinematics import Configuration


def velocity_bounds(q: FloatArray, limits: JointLimits, period: float) -> tuple[FloatArray, FloatArray]:
    """Velocity bounds of eq (21)-(23) that keep q_{k+1} = q_k + qd T inside the position limits.

        Qd_min = max(-qd_max, (q_min - q_k) / T),   Qd_max = min(qd_max, (q_max - q_k) / T)

    Inside the position range this is eq (23) exactly (Qd_min <= 0 <= Qd_max). At or beyond
    a limit (measurement noise, overshoot, a start outside the range) eq (21) can ask for
    more than the velocity limit and eq (23) would cross (Qd_min > Qd_max). Documented
    choice: both bounds are clipped to [-qd_max, qd_max], i.e. eq (21) is met as far as the
    velocity limit allows. A joint at q_max gets Qd_max = 0 (it may stay or move back); a
    joint d beyond q_max gets Qd_max = max(-d / T, -qd_max) < 0 (it must move back toward the
    range, by d in one step when d <= qd_max T, at the velocity limit otherwise) and
    Qd_min = -qd_max. So Qd_min <= Qd_max always, |qd| <= qd_max, and the distance from
    q + qd T to the range is max(0, d - qd_max T): it never grows.

    Args:
        q: current joint positions q_k [rad], (n,).
        limits: joint limits.
        period: control period T [s], > 0.

    Returns:
        (lower, upper) [rad/s], each (n,), lower <= upper (for finite q).
    """
    # both rows at once, and np.minimum(np.maximum(.)) instead of np.clip (3x cheaper on small arrays)
    bounds = np.minimum(np.maximum((limits.position_rows - q) / period, limits.negative_qd_max), limits.qd_max)
    return bounds[0], bounds[1]




@dataclass(frozen=True)
class VelocityLimit(Limit):
    """The joint position and velocity limits as velocity bounds, eq (21)-(23) (:func:`velocity_bounds`);
    the period T [s] is the control period. Priority 0: every other box is narrowed inside it."""

    limits: JointLimits
    period: float
    name: str = "joint_velocity"
    priority: int = POSITION_PRIORITY

    def constraints(self, configuration: Configuration, previous: FloatArray) -> Constraint:
        lower, upper = velocity_bounds(configuration.q, self.limits, self.period)
        return Constraint(lower, upper)


@register_limit("joint_velocity")
def joint_velocity_limit(context: LimitContext) -> VelocityLimit:
    """Eq (21)-(23), always on."""
    return VelocityLimit(context.joint_limits, context.period)
