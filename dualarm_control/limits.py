"""Joint limits as velocity bounds and the repulsive joint-limit velocity (paper 000, Sect. IV).

All vectors have shape (n,): positions in rad, velocities in rad/s, the period T in s.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


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
    step = max_acceleration * period
    brake = 0.5 * max_acceleration
    half = 0.5 * brake * period
    stop_up = np.sqrt(half * half + 2.0 * brake * np.maximum(limits.q_max - q, 0.0)) - half
    stop_down = np.sqrt(half * half + 2.0 * brake * np.maximum(q - limits.q_min, 0.0)) - half
    acc_lower = np.minimum(np.maximum(previous - step, -stop_down), previous + step)
    acc_upper = np.maximum(np.minimum(previous + step, stop_up), previous - step)
    new_lower = np.minimum(np.maximum(lower, acc_lower), upper)
    new_upper = np.maximum(np.minimum(upper, acc_upper), new_lower)
    return new_lower, new_upper


# ---------------------------------------------------------------------- limits as one abstraction

ROW_SPEED_MARGIN = 1e-6
"""m/s: how far below its bound b a row's speed bound C |qd| must lie for :meth:`DeferredRows.meets`
to vouch for qd (witness points within 1e-9 m of their shapes, rounding; the collision report's
"active" tolerance is the same)."""


class DeferredRows:
    """The matrix A (m, n) of hard rows ``A qd <= b``, built on first use, and a bound that often
    makes building it unnecessary.

    ``speed`` C (m, n) >= 0 bounds every row: |A_i qd| <= C_i |qd| for every qd (the collision
    limit's rows are distance velocities, C the reach of the pair's links about each joint [m/rad]:
    no point of a link moves faster than sum_j reach_j |qd_j|). Where C |qd| <= b - margin, qd meets
    every row whatever A is (:meth:`meets`): a solver's relaxation (its QP without the rows) that
    meets the bound is the solution with them, and A is never built. A is built when a solver needs
    it (a row may be active) and then kept: the same rows, the same decisions as with A built at once.

    Args:
        speed: C [m/rad], (m, n), >= 0.
        bound: b [m/s], (m,).
        build: returns A (m, n), called at most once.
    """

    __slots__ = ("_below", "_build", "_matrix", "_met", "bound", "speed")

    def __init__(self, speed: FloatArray, bound: FloatArray, build: Callable[[], FloatArray]) -> None:
        self.speed = speed
        self.bound = bound
        self._below = bound - ROW_SPEED_MARGIN
        self._build: Callable[[], FloatArray] | None = build
        self._matrix: FloatArray | None = None
        self._met = b""  # the bytes of the last qd that met the bound (a cycle checks the same qd up to 3 times)

    @classmethod
    def of(cls, matrix: FloatArray, bound: FloatArray) -> DeferredRows:
        """Rows already built (C = |A|)."""
        rows = cls(np.abs(matrix), bound, lambda: matrix)
        rows._matrix, rows._build = matrix, None
        return rows

    @property
    def built(self) -> bool:
        """Whether A has been built."""
        return self._matrix is not None

    @property
    def matrix(self) -> FloatArray:
        """A (m, n), built on the first call."""
        if self._matrix is None:
            assert self._build is not None
            self._matrix, self._build = self._build(), None
        return self._matrix

    def meets(self, qd: FloatArray) -> bool:
        """True when C |qd| <= b - :data:`ROW_SPEED_MARGIN` in every row, so that A qd <= b (qd (n,)
        [rad/s]); False says nothing (A qd may still meet b)."""
        key = qd.tobytes()
        if key == self._met:
            return True
        met = bool((self.speed @ np.abs(qd) <= self._below).all())
        if met:
            self._met = key
        return met

    def stacked(self, other: DeferredRows) -> DeferredRows:
        """These rows, then ``other``'s."""
        return DeferredRows(np.vstack((self.speed, other.speed)), np.concatenate((self.bound, other.bound)),
                            lambda: np.vstack((self.matrix, other.matrix)))


@dataclass(slots=True)
class Bounds:
    """What the limits give one cycle's QP over the joint velocities qd [rad/s], (n,).

    The box ``lower <= qd <= upper`` (n,) and the general rows ``A qd <= bound`` (A (m, n) in
    ``rows``, built when first needed: :class:`DeferredRows`; bound (m,), m >= 0), each row labelled
    (``labels``, m strings: the collision pair it keeps apart). Every solver takes both as hard
    constraints in its own variables (docs/collision.md, "Limits").

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md).
    """

    lower: FloatArray
    upper: FloatArray
    rows: DeferredRows | None
    bound: FloatArray
    labels: tuple[str, ...] = ()

    @classmethod
    def free(cls, n: int) -> Bounds:
        """No constraint yet: the box (-inf, inf) and no row."""
        return cls(np.full(n, -np.inf), np.full(n, np.inf), None, np.zeros(0))

    def add_rows(self, rows: DeferredRows, labels: tuple[str, ...]) -> None:
        """Append m rows ``A qd <= b`` (``rows``, m labels) after those already given."""
        self.rows = rows if self.rows is None else self.rows.stacked(rows)
        self.bound, self.labels = self.rows.bound, self.labels + labels


class Limit(Protocol):
    """One limit of the QP (as pink's and mink's ``Limit``): it narrows the box or adds rows.

    ``apply`` gets the measured joint positions q [rad] (n,), the previous command [rad/s] (n,)
    and the bounds of the limits applied before it, and returns the bounds with its own added.
    Order matters where a limit narrows the box: :class:`VelocityLimit` (eq 21-23) first, then
    :class:`AccelerationLimit` (priorities of :func:`acceleration_bounds`), then the row limits.
    """

    @property
    def name(self) -> str: ...

    def apply(self, q: FloatArray, previous: FloatArray, bounds: Bounds) -> Bounds: ...


@dataclass(frozen=True)
class VelocityLimit:
    """The joint position and velocity limits as velocity bounds, eq (21)-(23) (:func:`velocity_bounds`).

    Intersects the box with eq (23)'s (issue 39: it used to overwrite it, losing a limit applied before
    it); the period T [s] is the control period."""

    limits: JointLimits
    period: float
    name: str = "joint_velocity"

    def apply(self, q: FloatArray, previous: FloatArray, bounds: Bounds) -> Bounds:
        lower, upper = velocity_bounds(q, self.limits, self.period)
        bounds.lower, bounds.upper = np.maximum(bounds.lower, lower), np.minimum(bounds.upper, upper)
        return bounds


@dataclass(frozen=True)
class AccelerationLimit:
    """The joint acceleration bound |qd_k - qd_{k-1}| <= a_max T narrowing the box
    (:func:`acceleration_bounds`, with its stopping speed toward the position limits).

    ``max_acceleration`` a_max [rad/s^2], (n,), > 0; ``period`` T [s]."""

    limits: JointLimits
    max_acceleration: FloatArray
    period: float
    name: str = "joint_acceleration"

    def apply(self, q: FloatArray, previous: FloatArray, bounds: Bounds) -> Bounds:
        bounds.lower, bounds.upper = acceleration_bounds(bounds.lower, bounds.upper, q, self.limits, previous,
                                                         self.max_acceleration, self.period)
        return bounds


def apply_limits(limits: tuple[Limit, ...], q: FloatArray, previous: FloatArray) -> Bounds:
    """Every limit in order on the free bounds: the constraints of one cycle (n = q.shape[0])."""
    bounds = Bounds.free(q.shape[0])
    for limit in limits:
        bounds = limit.apply(q, previous, bounds)
    return bounds
