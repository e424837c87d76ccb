"""The repulsive joint-limit velocity of eq (24)-(25) (paper 000, Sect. IV): the secondary task of the
hierarchical solvers (eq 26-27), not a constraint.

All vectors have shape (n,): positions in rad, velocities in rad/s.
"""

from __future__ import annotations

import numpy as np

from dualarm_control.limits.base import FloatArray, JointLimits


def repulsive_velocity(q: FloatArray, limits: JointLimits, alpha: float) -> FloatArray:
    """Repulsive joint-limit velocity of eq (24)-(25) (see :class:`RepulsiveField`).

    Args:
        q: joint positions [rad], (n,).
        limits: joint limits.
        alpha: share of the range where the repulsion acts, in [0, 1].

    Returns:
        qd_r [rad/s], (n,).
    """
    return RepulsiveField(limits, alpha)(q)


class RepulsiveField:
    """Repulsive joint-limit velocity of eq (24)-(25) with its thresholds computed once.

    Thresholds q*_min = q_min + alpha (q_max - q_min)/2 and q*_max = q_max - alpha (q_max - q_min)/2.
    Inside ]q*_min, q*_max[ the value is 0; in [q_min, q*_min] it is
    ((q - q*_min)/(q_min - q*_min))^2 * qd_max (pushing up); in [q*_max, q_max] it is
    ((q - q*_max)/(q_max - q*_max))^2 * (-qd_max) (pushing down). Beyond the limits the
    value saturates at +-qd_max. Vectorised: with h = alpha (q_max - q_min)/2 the two
    ratios clip((q*_min - q)/h, 0, 1) and clip((q - q*_max)/h, 0, 1) are never both
    non-zero (q*_min <= q*_max), so qd_r = qd_max (ratio_low^2 - ratio_high^2). A controller
    builds one field and calls it every cycle (q*_min, q*_max and h are constants).
    """

    def __init__(self, limits: JointLimits, alpha: float) -> None:
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], got {alpha}")
        self.alpha = alpha
        self._qd_max = limits.qd_max
        half = alpha * limits.half_range
        self._thresholds = np.stack((limits.q_min + half, limits.q_max - half))  # q*_min, q*_max
        self._scale = np.stack((-half, half))  # ratio_low = (q - q*_min) / -h, ratio_high = (q - q*_max) / h

    def __call__(self, q: FloatArray) -> FloatArray:
        """qd_r [rad/s], (n,), at joint positions q [rad], (n,)."""
        if self.alpha == 0.0:
            return np.zeros_like(q, dtype=float)
        # both ratios in one (2, n) array; np.minimum(np.maximum(.)) instead of np.clip (3x cheaper)
        ratios = np.minimum(np.maximum((q - self._thresholds) / self._scale, 0.0), 1.0)
        ratios *= ratios
        return self._qd_max * (ratios[0] - ratios[1])
