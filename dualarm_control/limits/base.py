"""What a limit is and how one cycle's limits are put together (issue 39; docs/limits.md).

A limit (:class:`Limit`) looks at one cycle's :class:`~dualarm_control.kinematics.Configuration` and the
previous command and returns a :class:`Constraint` on the joint velocities qd [rad/s], (n,): a box
``lower <= qd <= upper`` and/or hard rows ``A qd <= b``. :func:`apply_limits` intersects what the limits
give, whatever order they are listed in: the boxes are narrowed in the order of the limits' ``priority``
(where two boxes do not meet, the higher-priority one wins: the result is its point nearest to the other),
the rows are stacked. Every solver and every tracker takes the result as hard constraints.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from dualarm_control.arrays import FloatArray

if TYPE_CHECKING:
    from dualarm_control.kinematics import Configuration


ROW_SPEED_MARGIN = 1e-6
"""m/s: how far below its bound b a row's speed bound C |qd| must lie for :meth:`DeferredRows.meets`
to vouch for qd (witness points within 1e-9 m of their shapes, rounding; the collision report's
"active" tolerance is the same)."""

POSITION_PRIORITY = 0
"""Priority of the joint position and velocity limits of eq (21)-(23): narrowed first, never given up."""

ACCELERATION_PRIORITY = 10
"""Priority of the acceleration bound: given up (clipped into eq (23)'s box) where it meets no position bound."""

ROW_PRIORITY = 20
"""Priority of the collision limit (rows only: the priority orders its rows among the other limits' rows)."""

USER_PRIORITY = 100
"""Default priority of a limit that does not say: after every built-in one."""


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

    __slots__ = ("_below", "_build", "_excess", "_matrix", "_met", "_parts", "bound", "speed")

    def __init__(self, speed: FloatArray, bound: FloatArray, build: Callable[[], FloatArray],
                 parts: tuple[DeferredRows, ...] = ()) -> None:
        self.speed = speed
        self.bound = bound
        self._below: FloatArray | None = None  # b - ROW_SPEED_MARGIN, made by the first meets()
        self._build: Callable[[], FloatArray] | None = build
        self._matrix: FloatArray | None = None
        self._met = b""  # the bytes of the last qd that met the bound (a cycle checks the same qd up to 3 times)
        self._parts = parts  # the rows stacked into these (:meth:`stacked`), () for rows of one limit
        self._excess: tuple[bytes, float] = (b"", 0.0)  # the last qd's bytes and excess (a cycle asks 2-3 times)

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
        below = self._below
        if below is None:
            below = self._below = self.bound - ROW_SPEED_MARGIN
        met = bool((self.speed @ np.abs(qd) <= below).all())
        if met:
            self._met = key
        return met

    def excess(self, qd: FloatArray) -> float:
        """max(A qd - b, 0) [m/s] at qd (n,) [rad/s], building only the matrices of the stacked parts whose
        speed bound does not vouch for qd (a vouched part's rows are below their bounds: they add nothing).
        The same value whether A is built or not (a vouched qd's rows are all below b: 0.0), so the last qd's
        is kept."""
        key = qd.tobytes()
        if key == self._excess[0]:
            return self._excess[1]
        if self._matrix is None and self._parts:
            worst = 0.0
            for part in self._parts:
                excess = part.excess(qd)
                worst = max(worst, excess)
        elif self._matrix is None and self.meets(qd):
            worst = 0.0
        else:
            worst = float((self.matrix @ qd - self.bound).max(initial=0.0))
        self._excess = (key, worst)
        return worst

    def stacked(self, other: DeferredRows) -> DeferredRows:
        """These rows, then ``other``'s (each part built only when needed: :meth:`excess`)."""
        parts = (self._parts or (self,)) + (other._parts or (other,))
        # concatenate, not vstack: both are (m, n) already, and vstack's Python layer costs 2 us a cycle
        return DeferredRows(np.concatenate((self.speed, other.speed)), np.concatenate((self.bound, other.bound)),
                            lambda: np.concatenate([part.matrix for part in parts]), parts)


@dataclass(slots=True)
class Constraint:
    """What one limit gives one cycle: a box on qd [rad/s] (``lower``, ``upper``, (n,) each, None for no
    bound on that side) and/or rows ``A qd <= b`` (``rows``, m of them, one label each naming what the row
    keeps apart: ``labels``, m strings). :data:`NONE` gives nothing (e.g. no collision pair in range)."""

    lower: FloatArray | None = None
    upper: FloatArray | None = None
    rows: DeferredRows | None = None
    labels: tuple[str, ...] = ()

    @classmethod
    def of_rows(cls, matrix: FloatArray, bound: FloatArray, labels: tuple[str, ...]) -> Constraint:
        """Rows ``matrix @ qd <= bound`` (A (m, n) [units of b per rad/s], b (m,)), one label each."""
        if matrix.shape[0] != bound.shape[0] or len(labels) != bound.shape[0]:
            raise ValueError(f"rows: {matrix.shape[0]} rows, {bound.shape[0]} bounds, {len(labels)} labels")
        return cls(rows=DeferredRows.of(matrix, bound), labels=labels)


NONE = Constraint()
"""The constraint that constrains nothing (shared: never modified)."""


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

    def narrow(self, lower: FloatArray | None, upper: FloatArray | None) -> None:
        """Intersect the box with [lower, upper] (:func:`narrowed`)."""
        new_lower, new_upper = narrowed(self.lower, self.upper, lower, upper)
        assert new_lower is not None and new_upper is not None  # the box had both sides
        self.lower, self.upper = new_lower, new_upper

    def add_rows(self, rows: DeferredRows, labels: tuple[str, ...]) -> None:
        """Append m rows ``A qd <= b`` (``rows``, m labels) after those already given."""
        self.rows = rows if self.rows is None else self.rows.stacked(rows)
        self.bound, self.labels = self.rows.bound, self.labels + labels


def narrowed(lower: FloatArray | None, upper: FloatArray | None, new_lower: FloatArray | None,
             new_upper: FloatArray | None) -> tuple[FloatArray | None, FloatArray | None]:
    """The box [lower, upper] intersected with [new_lower, new_upper] (None: no bound on that side; (n,) [rad/s]),
    keeping the first box's range where the two do not meet: per joint the result is the point of the first box
    nearest to the new range,

        lower' = min(max(lower, new_lower), upper),   upper' = max(min(upper, new_upper), lower').

    A side without a bound yet takes the new one as it is (no arithmetic: the first limit's box costs nothing)."""
    if new_lower is not None:
        lower = new_lower if lower is None else np.maximum(lower, new_lower)
        if upper is not None:
            lower = np.minimum(lower, upper)
    if new_upper is not None:
        upper = new_upper if upper is None else np.minimum(upper, new_upper)
        if lower is not None:
            upper = np.maximum(upper, lower)
    return lower, upper


class LimitReport(Protocol):
    """What a limit saw in one cycle, for the cycle's record and /diagnostics."""

    def values(self) -> dict[str, str]:
        """/diagnostics key-value pairs (strings, as diagnostic_msgs/KeyValue holds them)."""
        ...

    def text(self) -> str:
        """One line for a log or a stall verdict."""
        ...


class Limit:
    """One limit of every cycle's QP (as pink's and mink's limits): subclass it and write
    :meth:`constraints` (docs/limits.md has a worked example).

    Attributes:
        name: what the limit is called (reports, labels, ``limits`` parameter); unique per controller.
        priority: the order in which boxes are narrowed (lower first; :func:`apply_limits`). A limit
            that only adds rows keeps the default; its priority orders its rows among the others'.
    """

    name: str = "limit"
    priority: int = USER_PRIORITY

    def constraints(self, configuration: Configuration, previous: FloatArray) -> Constraint:
        """This cycle's constraint at ``configuration`` (its joint positions ``configuration.q`` [rad],
        (n,), frames and Jacobians) given the previous command ``previous`` [rad/s], (n,)."""
        raise NotImplementedError

    def report(self, velocities: FloatArray) -> LimitReport | None:
        """What the limit saw in the cycle whose command is ``velocities`` [rad/s], (n,); None: nothing to say."""
        return None

    def reset(self) -> None:
        """Forget what earlier cycles left (a new run from rest): nothing by default."""

    def continue_from(self, old: Limit) -> None:
        """Take over what ``old``, the limit of the same name in the controller before a live parameter
        change (:meth:`~dualarm_control.controller.RelativeController.continue_from`), carries from one
        cycle to the next: nothing by default."""


def _priority(limit: Limit) -> int:
    return limit.priority


def ordered(limits: Iterable[Limit]) -> tuple[Limit, ...]:
    """``limits`` by priority, equal priorities in the order given; ValueError on a name given twice."""
    out = tuple(sorted(limits, key=_priority))
    names = [limit.name for limit in out]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise ValueError(f"limit names must be unique, got {', '.join(twice)} more than once")
    return out


def apply_limits(limits: Iterable[Limit], configuration: Configuration, previous: FloatArray) -> Bounds:
    """One cycle's constraints: every limit's :class:`Constraint` intersected, in the order of their priority
    whatever the order given (boxes by :func:`narrowed`, rows stacked); n = configuration.q.shape[0],
    ``previous`` [rad/s], (n,). A side no limit bounds is infinite."""
    lower: FloatArray | None = None
    upper: FloatArray | None = None
    rows: DeferredRows | None = None
    labels: tuple[str, ...] = ()
    for limit in sorted(limits, key=_priority):
        constraint = limit.constraints(configuration, previous)
        if constraint.lower is not None or constraint.upper is not None:
            lower, upper = narrowed(lower, upper, constraint.lower, constraint.upper)
        if constraint.rows is not None:
            rows = constraint.rows if rows is None else rows.stacked(constraint.rows)
            labels += constraint.labels
    n = configuration.q.shape[0]
    return Bounds(np.full(n, -np.inf) if lower is None else lower, np.full(n, np.inf) if upper is None else upper,
                  rows, np.zeros(0) if rows is None else rows.bound, labels)
