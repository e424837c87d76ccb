"""Live obstacles between the thread that takes them in and the control thread (issue 42, part 3).

:class:`LiveScene` is the intake's state (one thread: a ROS callback or a worker): obstacles added,
moved, deleted by name, their velocity estimated from successive poses when none is given, at most
``slots`` of them (one more is refused, with a reason). After each change it hands a finished
snapshot to :class:`LiveObstacleFeed`, which the control thread reads with one attribute load
(:meth:`LiveObstacleFeed.snapshot`: the snapshot minus the obstacles whose lifetime has run out), so
the control loop never waits for the intake and its cost is bounded by ``slots``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.live import LiveObstacle

VELOCITY_MAX_GAP = 0.5
"""s: two poses of an obstacle further apart in time than this give no velocity estimate (zero)."""


class LiveObstacleFeed:
    """The control thread's view of the live obstacles: an immutable tuple swapped whole.

    Args:
        slots: the most obstacles at once (``collision.live_obstacles``), >= 0.
        clock: the time [s] lifetimes are measured on (``time.monotonic`` by default; a simulated
            run gives its own).
    """

    def __init__(self, slots: int, clock: Callable[[], float] = time.monotonic) -> None:
        if isinstance(slots, bool) or not isinstance(slots, int) or slots < 0:
            raise ValueError(f"live obstacle slots={slots!r}: expected an integer >= 0")
        self.slots = slots
        self.clock = clock
        self._state: tuple[tuple[LiveObstacle, ...], float] = ((), math.inf)  # the snapshot, its first expiry

    def publish(self, obstacles: tuple[LiveObstacle, ...]) -> None:
        """The intake's new snapshot (at most ``slots`` obstacles; ValueError otherwise)."""
        if len(obstacles) > self.slots:
            raise ValueError(f"{len(obstacles)} live obstacles for {self.slots} slots")
        self._state = (obstacles, min((o.expires for o in obstacles), default=math.inf))  # one swap

    def snapshot_now(self) -> tuple[LiveObstacle, ...]:
        """The snapshot as published (lifetimes not applied)."""
        return self._state[0]

    def snapshot(self) -> tuple[LiveObstacle, ...]:
        """The obstacles now, those past their lifetime left out (no lock: one attribute read)."""
        current, earliest = self._state
        if not current or earliest == math.inf:
            return current
        now = self.clock()
        if earliest > now:
            return current
        return tuple(o for o in current if o.expires > now)


class LiveScene:
    """The intake's obstacles by name (module docstring); every change is published to ``feed``.

    ``reasons`` collects why something was refused (the caller logs them, throttled)."""

    def __init__(self, feed: LiveObstacleFeed) -> None:
        self.feed = feed
        self.obstacles: dict[str, LiveObstacle] = {}
        self._stamps: dict[str, float] = {}
        self.refused = 0

    def add(self, obstacle: LiveObstacle, stamp: float, velocity_given: bool = False) -> str | None:
        """Add or move ``obstacle`` (pose stamped ``stamp`` [s]); its velocity estimated from its last
        pose unless ``velocity_given``. Returns the reason it was refused, or None."""
        old = self.obstacles.get(obstacle.name)
        if old is None and len(self.obstacles) >= self.feed.slots:
            self.refused += 1
            return (f"obstacle {obstacle.name!r} refused: all {self.feed.slots} live obstacle slots are taken "
                    "(collision.live_obstacles)")
        if old is not None and not velocity_given:
            obstacle = obstacle.moved(obstacle.position, estimated_velocity(
                old.position, self._stamps[obstacle.name], obstacle.position, stamp))
        self.obstacles[obstacle.name] = obstacle
        self._stamps[obstacle.name] = stamp
        return None

    def delete(self, name: str) -> None:
        """Remove the obstacle ``name`` (nothing when there is none)."""
        self.obstacles.pop(name, None)
        self._stamps.pop(name, None)

    def clear(self) -> None:
        """Remove every obstacle."""
        self.obstacles.clear()
        self._stamps.clear()

    def publish(self) -> tuple[LiveObstacle, ...]:
        """Hand the current obstacles to the control thread (those past their lifetime dropped here too);
        returns the snapshot it replaced (the caller drops it when it likes: freeing an octree takes about a
        millisecond, which need not delay the new snapshot)."""
        now = self.feed.clock()
        for name in [n for n, o in self.obstacles.items() if o.expires <= now]:
            self.delete(name)
        previous = self.feed.snapshot_now()
        self.feed.publish(tuple(self.obstacles.values()))
        return previous


def estimated_velocity(before: FloatArray, before_stamp: float, after: FloatArray, after_stamp: float) -> FloatArray:
    """(p_after - p_before) / (t_after - t_before) [m/s], (3,), from two positions [m] at two times
    [s]; zero when the gap is not in (0, :data:`VELOCITY_MAX_GAP`] or the result is not finite."""
    gap = after_stamp - before_stamp
    if not 0.0 < gap <= VELOCITY_MAX_GAP:
        return np.zeros(3)
    velocity: FloatArray = (np.asarray(after, dtype=float) - np.asarray(before, dtype=float)) / gap
    return velocity if math.isfinite(float(velocity.sum())) else np.zeros(3)
