"""The live obstacles' limit: the velocity damper's rows of the (arm link, live obstacle) pairs, with
the obstacle's own velocity (:mod:`dualarm_control.collision.live`; docs/obstacles.md):

    -dd_dq qd <= xi (d - d_s') / (d_i' - d_s') + n^T v_B          [m/s]

d_s', d_i' as the collision limit's (grown by twice ``collision.shape_margin``). On when
``collision.enabled`` and ``collision.live_obstacles`` (the slots) > 0; the obstacles come from the
limit's :attr:`LiveObstacleLimit.feed`, which a node's intake or an in-process runner fills.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dualarm_control.collision import CollisionModel, CollisionParams
from dualarm_control.collision.live import LiveDistances, LivePairs, live_damper_bound
from dualarm_control.collision.live_feed import LiveObstacleFeed
from dualarm_control.kinematics import Configuration, FloatArray
from dualarm_control.limits.base import (
    NONE,
    ROW_PRIORITY,
    Constraint,
    DeferredRows,
    Limit,
)
from dualarm_control.limits.collision import ACTIVE_TOLERANCE
from dualarm_control.limits.registry import LimitContext, register_limit
from dualarm_control.limits.stall import BrakedLimit, StallBrake

LIVE_LIMIT = "live_obstacles"
"""The limit's name (``Cycle.reports`` key, ``controller.limit(...)``)."""


@dataclass(slots=True)
class LiveReport:
    """What the live obstacles' limit saw in one cycle.

    Attributes:
        obstacles: how many live obstacles there were.
        distance: the closest pair's d [m] (inf: none within d_i). pair: its (link, ``obstacle:<name>``).
        approach: that pair's n^T v_B [m/s] (< 0: the obstacle comes closer).
        rows: pairs within d_i. active: rows the command holds at their bound.
    """

    obstacles: int
    distance: float
    pair: tuple[str, str] | None
    approach: float
    rows: int
    active: int

    def values(self) -> dict[str, str]:
        """/diagnostics keys: ``live_obstacles``, ``live_obstacle_distance_m``, ``live_obstacle_pair``,
        ``live_obstacle_approach_mps`` (n^T v_B of the closest pair), ``live_obstacle_rows``, ``live_obstacle_active``."""
        return {"live_obstacles": str(self.obstacles),
                "live_obstacle_distance_m": f"{self.distance:.6f}" if self.pair is not None else "inf",
                "live_obstacle_pair": f"{self.pair[0]} – {self.pair[1]}" if self.pair is not None else "",
                "live_obstacle_approach_mps": f"{self.approach:.4f}",
                "live_obstacle_rows": str(self.rows), "live_obstacle_active": str(self.active)}

    def text(self) -> str:
        """E.g. ``yielding to obstacle:hand: left_flange – obstacle:hand at 0.034 m, approaching at 0.40 m/s``."""
        if self.pair is None:
            return f"{self.obstacles} live obstacles, none within reach"
        verb = "yielding to" if self.active and self.approach < 0.0 else "held by" if self.active else "near"
        motion = f", approaching at {-self.approach:.2f} m/s" if self.approach < 0.0 else ""
        return (f"{verb} {self.pair[1]}: {self.pair[0]} – {self.pair[1]} at {self.distance:.3f} m{motion} "
                f"({self.rows} rows, {self.active} active)")


class LiveObstacleLimit(BrakedLimit):
    """The velocity damper of every (arm link, live obstacle) pair closer than d_i (module docstring).

    Args:
        collision: the robot's collision model (its reduced model and shapes are read).
        params: d_i, d_s, xi, the shape margin, and ``live_obstacles`` (the feed's slots).
        feed: where the obstacles come from (a new one with ``params.live_obstacles`` slots by default).
        brake: the acceleration box added while the rows hold the command (:mod:`~dualarm_control.limits.stall`);
            None: none.
    """

    name = LIVE_LIMIT
    priority = ROW_PRIORITY

    def __init__(self, collision: CollisionModel, params: CollisionParams, feed: LiveObstacleFeed | None = None,
                 brake: StallBrake | None = None) -> None:
        self.params = params
        self.brake = brake
        self.feed = feed if feed is not None else LiveObstacleFeed(params.live_obstacles)
        self.distances = LiveDistances(collision.model, collision.geometry, collision.request.gjk_tolerance)
        self._kept = params.kept_distances
        self.last = LivePairs.empty(collision.model.nv)
        self._count = 0
        self._rows = DeferredRows.of(np.zeros((0, collision.model.nv)), np.zeros(0))

    def constraints(self, configuration: Configuration, previous: FloatArray) -> Constraint:
        constraint = self._rows_at(configuration.q)
        return constraint if self.brake is None else self.brake.narrow(constraint, configuration.q, previous)

    def _rows_at(self, q: FloatArray) -> Constraint:
        """The damper's rows of the (link, live obstacle) pairs within d_i at q [rad] (n,); NONE without any."""
        obstacles = self.feed.snapshot()
        self._count = len(obstacles)
        influence, safety = self._kept
        self.last = pairs = self.distances.near(q, obstacles, influence, deferred=True)
        if not len(pairs):
            return NONE
        bound = live_damper_bound(pairs.distance, pairs.approach if pairs.moving else None, influence, safety,
                                  self.params.gain)
        self._rows = DeferredRows(pairs.speed, bound, lambda: self._matrix(pairs))
        return Constraint(rows=self._rows, labels=pairs.labels)

    def _matrix(self, pairs: LivePairs) -> FloatArray:
        """The rows' matrix -dd_dq (m, n) [m/rad] of this cycle's ``pairs``."""
        rows = self.distances.complete(pairs).rows
        assert rows is not None
        return -rows

    def continue_from(self, old: Limit) -> None:
        """The brake's state (:class:`~dualarm_control.limits.stall.BrakedLimit`) and ``old``'s feed: the obstacles
        a node's intake fills go on (docs/obstacles.md)."""
        super().continue_from(old)
        if isinstance(old, LiveObstacleLimit):
            self.feed = old.feed

    def report(self, velocities: FloatArray) -> LiveReport | None:
        """The last cycle's :class:`LiveReport` (None with no live obstacle)."""
        pairs = self.last
        if not len(pairs):
            return LiveReport(self._count, float("inf"), None, 0.0, 0, 0) if self._count else None
        rows = self._rows  # a row vouched for by its speed bound (C |qd| <= b - 1e-6) is not active
        active = 0 if rows.meets(velocities) else int(np.count_nonzero(rows.matrix @ velocities
                                                                        >= rows.bound - ACTIVE_TOLERANCE))
        if self.brake is not None:
            self.brake.saw(active)
        r = int(pairs.distance.argmin())
        return LiveReport(self._count, float(pairs.distance[r]), pairs.links[r], float(pairs.approach[r]),
                          len(pairs), active)


@register_limit(LIVE_LIMIT)
def live_obstacle_limit(context: LimitContext) -> LiveObstacleLimit | None:
    """On when the controller has a collision model and ``collision.live_obstacles`` > 0."""
    if context.collision is None or context.params.collision.live_obstacles <= 0:
        return None
    return LiveObstacleLimit(context.collision, context.params.collision, brake=StallBrake.of(context))
