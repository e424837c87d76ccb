"""Table I metrics of paper 000 and summary statistics of a run.

Table I lists int ||qd||_p dt for p = 0, 1, 2, but its l0 value (13.385 for a 14-joint
robot) is a time average; both the time average (1/T) int ||qd||_p dt and the raw integral
are reported. Commands are held over each period (zero-order hold), so with N samples
of period dt the integral is exactly sum_k ||qd_k||_p dt.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dualarm_control.arrays import FloatArray

ACTIVITY_THRESHOLD = 1e-3
"""A joint is active when |qd_i| > 1e-3 rad/s (paper 000, Fig. 5 and Table I)."""


def l0_norms(qd: FloatArray, threshold: float = ACTIVITY_THRESHOLD) -> FloatArray:
    """Active-joint count per sample, |qd_i| > threshold [rad/s]. (N, n) -> (N,)."""
    return np.count_nonzero(np.abs(qd) > threshold, axis=1).astype(float)


@dataclass(frozen=True)
class NormMetrics:
    """Time averages ``l*_mean`` and integrals ``l*_integral`` [rad for l1/l2, joint*s for l0]."""

    l0_mean: float
    l1_mean: float
    l2_mean: float
    l0_integral: float
    l1_integral: float
    l2_integral: float
    duration_s: float


def velocity_norm_metrics(qd: FloatArray, period: float, threshold: float = ACTIVITY_THRESHOLD) -> NormMetrics:
    """Table I norms of joint velocities ``qd`` (N, n) [rad/s] held for ``period`` [s] each."""
    qd = np.asarray(qd, dtype=float)
    if qd.ndim != 2 or qd.shape[0] == 0:
        raise ValueError(f"qd must be a non-empty (N, n) array, got shape {qd.shape}")
    duration = qd.shape[0] * period
    norms = (l0_norms(qd, threshold), np.abs(qd).sum(axis=1), np.linalg.norm(qd, axis=1))
    integrals = [float(v.sum() * period) for v in norms]
    return NormMetrics(
        l0_mean=integrals[0] / duration,
        l1_mean=integrals[1] / duration,
        l2_mean=integrals[2] / duration,
        l0_integral=integrals[0],
        l1_integral=integrals[1],
        l2_integral=integrals[2],
        duration_s=duration,
    )


def max_joint_acceleration(qd: FloatArray, period: float) -> float:
    """Largest commanded joint acceleration max_k,i |qd_k,i - qd_k-1,i| / T [rad/s^2].

    Args:
        qd: commanded joint velocities (N, n) [rad/s], one row per period.
        period: control period T [s].

    Returns:
        The largest finite difference of one joint's command between two consecutive
        cycles, divided by T; 0 for fewer than two samples.
    """
    qd = np.asarray(qd, dtype=float)
    if qd.shape[0] < 2:
        return 0.0
    return float(np.max(np.abs(np.diff(qd, axis=0))) / period)


def active_set_switches_per_s(qd: FloatArray, period: float, threshold: float = ACTIVITY_THRESHOLD) -> float:
    """Chatter of the active set: joints entering or leaving it, per second.

    A joint is active when |qd_i| > threshold (Table I's rule). Each cycle adds the size of
    the symmetric difference of the active sets of cycles k-1 and k; the sum is divided
    by the duration N T [s].

    Args:
        qd: commanded joint velocities (N, n) [rad/s].
        period: control period T [s].
        threshold: activity threshold [rad/s].
    """
    qd = np.asarray(qd, dtype=float)
    if qd.shape[0] < 2:
        return 0.0
    active = np.abs(qd) > threshold
    switches = np.count_nonzero(active[1:] != active[:-1])
    return float(switches / (qd.shape[0] * period))


def limit_violations(values: FloatArray, lower: FloatArray, upper: FloatArray, tolerance: float) -> int:
    """Number of samples (rows of ``values`` (N, n)) with any joint outside [lower - tol, upper + tol]."""
    values = np.asarray(values, dtype=float)
    outside = (values < lower - tolerance) | (values > upper + tolerance)
    return int(np.count_nonzero(outside.any(axis=1)))


@dataclass(frozen=True)
class JointLimitMetrics:
    """How close a run came to the joint position limits (issue 43), from the normalised margin

        m_ki = min(q_ki - q_min_i, q_max_i - q_ki) / (q_max_i - q_min_i)

    of joint i at sample k (0.5 at mid-range, 0 at a limit, negative beyond it). Eq (24)'s repulsive zone
    of share alpha is m < alpha / 2 (q below q*_min = q_min + alpha (q_max - q_min) / 2, or above q*_max):
    where the repulsive velocity of eq (25) is non-zero.

    Attributes:
        min_margin: min over the samples and joints of m (the closest approach, as a share of the range).
        final_margin: min over the joints of m at the final sample.
        zone_joint_seconds: sum over the cycles and joints in the zone of the period [joint s].
        zone_joints: how many joints are in the zone at some cycle.
        zone_depth_seconds: sum over the cycles and joints of the depth in the zone, (alpha/2 - m)+ / (alpha/2)
            (0 at the zone's edge, 1 at the limit), times the period [joint s]. Eq (25)'s repulsion vanishes at
            the edge, so a joint pushed out approaches it without crossing: the time in the zone cannot tell
            it from a joint left deep inside; the depth can.
        alpha: the share the zone was measured with.
    """

    min_margin: float
    final_margin: float
    zone_joint_seconds: float
    zone_joints: int
    zone_depth_seconds: float
    alpha: float


def joint_limit_margins(q: FloatArray, q_min: FloatArray, q_max: FloatArray) -> FloatArray:
    """m_ki of :class:`JointLimitMetrics` for joint positions q (N, n) [rad] and limits (n,) [rad]: (N, n)."""
    q = np.asarray(q, dtype=float)
    return np.minimum(q - q_min, q_max - q) / (q_max - q_min)


def joint_limit_metrics(cycles: FloatArray, final: FloatArray, q_min: FloatArray, q_max: FloatArray, alpha: float,
                        period: float) -> JointLimitMetrics:
    """:class:`JointLimitMetrics` of a run: the joint positions of its cycles (N, n) [rad] (each held for
    ``period`` [s]) and its final positions (n,) [rad]; ``alpha`` the share of eq (24)."""
    margins = joint_limit_margins(cycles, q_min, q_max).reshape(-1, len(q_min))
    final_margins = joint_limit_margins(np.asarray(final, dtype=float)[None, :], q_min, q_max)[0]
    inside = margins < alpha / 2.0
    depth = np.maximum(alpha / 2.0 - margins, 0.0) / (alpha / 2.0) if alpha > 0 else np.zeros_like(margins)
    return JointLimitMetrics(
        min_margin=float(min(margins.min(initial=np.inf), final_margins.min(initial=np.inf))),
        final_margin=float(final_margins.min(initial=np.inf)),
        zone_joint_seconds=float(np.count_nonzero(inside) * period),
        zone_joints=int(np.count_nonzero(inside.any(axis=0))),
        zone_depth_seconds=float(depth.sum() * period),
        alpha=float(alpha),
    )


def percentiles(samples: FloatArray, qs: tuple[float, ...] = (50.0, 99.0)) -> tuple[float, ...]:
    """Percentiles of ``samples`` (NaN-free), e.g. (p50, p99)."""
    arr = np.asarray(samples, dtype=float)
    if arr.size == 0:
        return tuple(float("nan") for _ in qs)
    return tuple(float(v) for v in np.percentile(arr, qs))
