"""The joint position and velocity limits as velocity bounds (paper 000, Sect. IV, eq (20)-(23)).

All vectors have shape (n,): positions in rad, velocities in rad/s, the period T in s.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dualarm_control.limits.base import POSITION_PRIORITY, Constraint, FloatArray, Limit
from dualarm_control.limits.registry import LimitContext, register_limit

if TYPE_CHECKING:
    from dualarm_control.kinematics import Configuration


@dataclass(frozen=True)
class JointLimits:
    """Position and velocity limits of eq (20); velocities are symmetric as on the LWR4.

    Attributes:
        q_min, q_max: position limits [rad], (n,).
        qd_max: velocity limit magnitude [rad/s], (n,); the lower limit is -qd_max.
    """

    q_min: FloatArray
    q_max: FloatArray
    qd_max: FloatArray

    def __post_init__(self) -> None:
        n = self.q_min.shape
        if self.q_max.shape != n or self.qd_max.shape != n:
            raise ValueError(f"limit shapes differ: {n}, {self.q_max.shape}, {self.qd_max.shape}")
        if np.any(self.q_min >= self.q_max):
            raise ValueError(f"q_min must be < q_max, got {self.q_min} and {self.q_max}")
        if np.any(self.qd_max <= 0):
            raise ValueError(f"qd_max must be > 0, got {self.qd_max}")

    @functools.cached_property
    def half_range(self) -> FloatArray:
        """(q_max - q_min) / 2 [rad], (n,); computed once (the limits are constant)."""
        return (self.q_max - self.q_min) / 2.0

    @functools.cached_property
    def position_rows(self) -> FloatArray:
        """[q_min; q_max] [rad], (2, n): both bounds of eq (21)-(22) in one array operation."""
        return np.stack((self.q_min, self.q_max))

    @functools.cached_property
    def negative_qd_max(self) -> FloatArray:
        """-qd_max [rad/s], (n,)."""
        return -self.qd_max

    def scaled_velocity(self, factor: float) -> JointLimits:
        """Same limits with the velocity limits multiplied by ``factor`` in (0, 1]."""
        if not 0.0 < factor <= 1.0:
            raise ValueError(f"velocity scale factor must be in (0, 1], got {factor}")
        return JointLimits(self.q_min, self.q_max, self.qd_max * factor)


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
