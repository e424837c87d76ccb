"""A scenario's moving obstacles given to a controller's live obstacle limit each cycle, and what the
limit did about them (ROS-free; the in-process runner's, docs/obstacles.md).

:class:`MovingFeed` publishes every moving obstacle's pose and velocity at time t
(:meth:`~dualarm_control.moving_obstacles.MovingObstacle.state`) to the controller's
:class:`~dualarm_control.collision.live_feed.LiveObstacleFeed`, and turns the limit's per-cycle
reports into events: each stretch of cycles in which the arms yielded to (or were held by) an
obstacle, with its name, its time span and the closest distance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from dualarm_control.collision.live import LiveObstacle
from dualarm_control.collision.obstacles import obstacle_placement, obstacle_shape
from dualarm_control.limits.base import LimitReport
from dualarm_control.limits.live import LiveReport
from dualarm_control.moving_obstacles import MovingObstacle


@dataclass
class ObstacleEvent:
    """A stretch of cycles in which the live obstacle limit held the command (a row at its bound)."""

    verb: str
    obstacle: str
    start: float
    end: float
    closest: float
    link: str

    def text(self) -> str:
        """E.g. ``t = 16.20-17.35 s: yielding to obstacle:hand (closest 0.034 m, left_flange)``."""
        return (f"t = {self.start:.2f}-{self.end:.2f} s: {self.verb} {self.obstacle} (closest {self.closest:.3f} m, "
                f"{self.link})")


class MovingFeed:
    """The moving obstacles of one run as live obstacles of ``follower.controller`` (its ``live_obstacles``
    limit; ``follower``: anything with a ``controller``, a follower or a tracker)."""

    def __init__(self, moving: Sequence[MovingObstacle], follower: Any) -> None:
        self.moving = tuple(moving)
        self.follower = follower
        self._live = [LiveObstacle.make(m.name, obstacle_shape(m.shape), obstacle_placement(m.shape).rotation,
                                        obstacle_placement(m.shape).translation) for m in self.moving]
        self.events: list[ObstacleEvent] = []
        self._open: ObstacleEvent | None = None

    def publish(self, t: float) -> None:
        """Every moving obstacle at time t [s] to the controller's live obstacle limit (which a live parameter
        change may have replaced: looked up each time)."""
        limit = self.follower.controller.limit("live_obstacles")
        if limit is None:
            raise ValueError("the scenario has moving obstacles but the controller has no live obstacle limit "
                             "(collision.enabled false?)")
        snapshot = []
        for m, live in zip(self.moving, self._live, strict=True):
            position, velocity = m.state(t)
            snapshot.append(live.moved(position, velocity))
        limit.feed.publish(tuple(snapshot))

    def observe(self, found: LimitReport | None, t: float) -> None:
        """One cycle's live obstacle report (:class:`~dualarm_control.limits.live.LiveReport` or None) at t [s]."""
        report = found if isinstance(found, LiveReport) else None
        text = report.text() if report is not None else ""
        verb = next((v for v in ("yielding to", "held by") if text.startswith(v)), None)
        if verb is None or report is None or report.pair is None:
            self._close()
            return
        pair, distance = report.pair, report.distance
        current = self._open
        if current is not None and (current.verb, current.obstacle) != (verb, pair[1]):
            self._close()
            current = None
        if current is None:
            self._open = ObstacleEvent(verb, pair[1], t, t, distance, pair[0])
            return
        current.end = t
        if distance < current.closest:
            current.closest, current.link = distance, pair[0]

    def _close(self) -> None:
        if self._open is not None:
            self.events.append(self._open)
            self._open = None

    def finish(self) -> tuple[str, ...]:
        """The events' texts, in time order (a stretch still open ends at its last cycle)."""
        self._close()
        return tuple(e.text() for e in self.events)
