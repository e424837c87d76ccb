"""A joint acceleration bound as velocity bounds (as in mc_rtc and OpenSoT).

All vectors have shape (n,): positions in rad, velocities in rad/s, accelerations in rad/s^2, the period T in s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dualarm_control.limits.base import (
    ACCELERATION_PRIORITY,
    Bounds,
    Constraint,
    FloatArray,
    JointLimits,
    Limit,
)
from dualarm_control.limits.registry import LimitContext, register_limit

if TYPE_CHECKING:
    from dualarm_control.kinematics import Configuration


def acceleration_bounds(
    lower: FloatArray,
    upper: FloatArray,
    q: FloatArray,
    limits: JointLimits,
    previous: FloatArray,
    max_acceleration: FloatArray,
    period: float,
) -> tuple[FloatArray, FloatArray]:
    """Velocity bounds of eq (23) narrowed by a joint acceleration bound a_max.

    As in mc_rtc and OpenSoT, |qd_k - qd_{k-1}| <= a_max T becomes the velocity bounds
    qd_{k-1} - a_max T <= qd_k <= qd_{k-1} + a_max T. Eq (21)-(22) alone would let a joint
    run at full speed until one period before its position limit and then stop in one
    period, so the speed toward a limit is also capped at the speed from which it can
    still stop at a = a_max / 2 (commands held for T, then reduced by a T each period:
    v^2 / (2 a) + v T / 2 <= d). Planning the stop at half the bound leaves the other half
    for the difference between commanded and measured motion (the measured position at
    the next cycle is not exactly q + qd T; planned at a_max, a stop in the assembly run
    needed 10.15 rad/s^2 under a 10 rad/s^2 bound):

        v_stop(d) = -a T / 2 + sqrt((a T / 2)^2 + 2 a d),  d = distance to the limit [rad]
        upper' = min(Qd_max, qd_{k-1} + a_max T, v_stop(q_max - q))
        lower' = max(Qd_min, qd_{k-1} - a_max T, -v_stop(q - q_min))

    Priorities when the ranges do not meet: eq (23) (position limits) first, then the
    acceleration bound, then the stopping speed; the result is then the point of the
    higher-priority range nearest to the lower-priority one.

    Args:
        lower, upper: Qd_min, Qd_max of eq (23) [rad/s], (n,).
        q: joint positions [rad], (n,).
        limits: joint limits.
        previous: previous command qd_{k-1} [rad/s], (n,).
        max_acceleration: a_max [rad/s^2], (n,), > 0.
        period: control period T [s].

    Returns:
        (lower', upper') [rad/s], each (n,), lower' <= upper' wherever lower <= upper.
    """
    box = Bounds(lower, upper, None, np.zeros(0))
    box.narrow(*acceleration_box(q, limits, previous, max_acceleration, period))
    return box.lower, box.upper


def acceleration_box(q: FloatArray, limits: JointLimits, previous: FloatArray, max_acceleration: FloatArray,
                     period: float) -> tuple[FloatArray, FloatArray]:
    """The acceleration bound's own box (:func:`acceleration_bounds` without eq (23)): qd_{k-1} +- a_max T,
    capped by the stopping speeds +-v_stop toward the position limits (the acceleration bound first where the
    two do not meet). Shapes and units as :func:`acceleration_bounds`; returns (lower, upper) [rad/s]."""
    step = max_acceleration * period
    brake = 0.5 * max_acceleration
    half = 0.5 * brake * period
    stop_up = np.sqrt(half * half + 2.0 * brake * np.maximum(limits.q_max - q, 0.0)) - half
    stop_down = np.sqrt(half * half + 2.0 * brake * np.maximum(q - limits.q_min, 0.0)) - half
    acc_lower = np.minimum(np.maximum(previous - step, -stop_down), previous + step)
    acc_upper = np.maximum(np.minimum(previous + step, stop_up), previous - step)
    return acc_lower, acc_upper


@dataclass(frozen=True)
class AccelerationLimit(Limit):
    """The joint acceleration bound |qd_k - qd_{k-1}| <= a_max T with its stopping speed toward the position
    limits (:func:`acceleration_box`); narrowed after eq (23)'s box (priority 10: where the two do not meet,
    eq (23) wins). ``max_acceleration`` a_max [rad/s^2], (n,), > 0; ``period`` T [s]."""

    limits: JointLimits
    max_acceleration: FloatArray
    period: float
    name: str = "joint_acceleration"
    priority: int = ACCELERATION_PRIORITY

    def constraints(self, configuration: Configuration, previous: FloatArray) -> Constraint:
        return Constraint(*acceleration_box(configuration.q, self.limits, previous, self.max_acceleration,
                                            self.period))


@register_limit("joint_acceleration")
def joint_acceleration_limit(context: LimitContext) -> AccelerationLimit | None:
    """On when the controller's ``acceleration_limit`` is set."""
    if context.acceleration is None:
        return None
    return AccelerationLimit(context.joint_limits, context.acceleration, context.period)
