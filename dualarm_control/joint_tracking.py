"""Joint-space tracking of a planned joint trajectory (the execution of a paper-003 plan)."""

from __future__ import annotations

import numpy as np

from dualarm_control.kinematics import FloatArray


def joint_tracking_velocity(q: FloatArray, q_ref: FloatArray, qd_ref: FloatArray, gain: float,
                            lower: FloatArray, upper: FloatArray) -> FloatArray:
    """qd = qd_ref + K (q_ref - q), clipped into the velocity bounds of paper 000 eq (23).

    Args:
        q: measured joint positions [rad], (n,).
        q_ref, qd_ref: reference positions [rad] and velocities [rad/s], (n,).
        gain: K [1/s], >= 0.
        lower, upper: Qd_min, Qd_max of eq (23) [rad/s], (n,).

    Returns:
        The command [rad/s], (n,), inside [lower, upper].
    """
    return np.clip(qd_ref + gain * (q_ref - q), lower, upper)
