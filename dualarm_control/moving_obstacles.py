"""Moving obstacles of a scenario: a shape that comes in along a straight line and goes out again
(issue 42, part 4: the hand of ``busy_cell``; docs/obstacles.md).

A scenario lists them by name under ``moving_obstacles``, each one's keys under its name::

    moving_obstacles: [hand]
    hand:
      type: sphere              # or cylinder (radius, length: a forearm), as a static obstacle's
      radius: 0.05
      from: [0.53, 0.17, 1.95]  # [m], world frame: where it waits, out of the way
      to: [0.53, 0.17, 1.36]    # [m]: how far it reaches in
      speed: 0.4                # [m/s] along the line, > 0
      start_time: 15.0          # [s] when it starts coming in
      dwell: 0.5                # [s] at `to` before it goes back

Its path p(t) [m] and velocity v(t) [m/s] (:meth:`MovingObstacle.state`): at ``from`` until
``start_time``, then ``from`` + u s t' (u the unit vector to ``to``, s the speed) until it reaches
``to`` after L / s (L = |to - from|), ``dwell`` there, back at the same speed, then at ``from``.
The controller gets its pose and its velocity every cycle as a live obstacle
(:mod:`dualarm_control.collision.live`: in one process straight from this path, over ROS as a
marker the simulator publishes on ``/collision_objects``); the simulator moves a body of its shape.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import ScenarioError
from dualarm_control.obstacles import (
    _NAME,
    RESERVED,
    Cylinder,
    Obstacle,
    Sphere,
    _positive,
    _vector,
)

MOVING_KEY = "moving_obstacles"
"""The scenario key that lists the moving obstacles' names."""
_KEYS = {"sphere": ("radius",), "cylinder": ("radius", "length")}
_PATH = ("from", "to", "speed", "start_time", "dwell")


@dataclass(frozen=True)
class MovingObstacle:
    """A shape moving in and out along a line (module docstring).

    Attributes:
        shape: its shape and name (a :class:`~dualarm_control.obstacles.Sphere` or ``Cylinder`` at ``start``).
        start, end: ``from`` and ``to`` [m], (3,). speed: [m/s]. start_time, dwell: [s].
    """

    shape: Obstacle
    start: tuple[float, float, float]
    end: tuple[float, float, float]
    speed: float
    start_time: float
    dwell: float

    @property
    def name(self) -> str:
        return self.shape.name

    @property
    def travel(self) -> float:
        """L / s [s]: the time to come in (and to go out)."""
        return float(np.linalg.norm(np.subtract(self.end, self.start))) / self.speed

    @property
    def end_time(self) -> float:
        """[s] when it is back at ``from``."""
        return self.start_time + 2.0 * self.travel + self.dwell

    def state(self, t: float) -> tuple[FloatArray, FloatArray]:
        """p(t) [m] (3,) and v(t) [m/s] (3,) at time t [s] (module docstring)."""
        a, b = np.array(self.start), np.array(self.end)
        direction = (b - a) / max(float(np.linalg.norm(b - a)), 1e-12)
        travel, s = self.travel, t - self.start_time
        if s <= 0.0 or t >= self.end_time:
            return a, np.zeros(3)
        if s < travel:
            return a + direction * self.speed * s, direction * self.speed
        if s < travel + self.dwell:
            return b, np.zeros(3)
        back = s - travel - self.dwell
        return b - direction * self.speed * back, -direction * self.speed

    def positions(self, times: FloatArray) -> FloatArray:
        """p(t) [m], (k, 3), at each of ``times`` [s], (k,)."""
        return np.array([self.state(float(t))[0] for t in times]).reshape(-1, 3)


def parse_moving_obstacles(flat: Mapping[str, Any], static: tuple[Obstacle, ...] = (),
                           prefix: str = "scenario.") -> tuple[MovingObstacle, ...]:
    """The moving obstacles of flattened scenario parameters; () without ``moving_obstacles``. ScenarioError
    naming the key and the value (a name taken by a static obstacle, a size or speed <= 0, NaN, a time < 0,
    ``from`` = ``to``, an unknown type or key)."""
    key = prefix + MOVING_KEY
    names = flat.get(key, [])
    if names in ([], [""], (), ""):
        return ()
    if not isinstance(names, list | tuple) or not all(isinstance(n, str) for n in names):
        raise ScenarioError(f"scenario parameter '{key}': got {names!r}, expected a list of obstacle names")
    taken = {o.name for o in static}
    out: list[MovingObstacle] = []
    for name in names:
        if not _NAME.match(name) or name in RESERVED or name in taken or name in (o.name for o in out):
            raise ScenarioError(f"scenario parameter '{key}': {name!r} is not a valid moving obstacle name (an "
                                "identifier, not a scenario key nor another obstacle's name)")
        out.append(_moving(flat, prefix + name + ".", name))
    return tuple(out)


def _time(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
        raise ScenarioError(f"scenario parameter '{key}': got {value!r}, expected a time >= 0 [s]")
    return float(value)


def _moving(flat: Mapping[str, Any], sub: str, name: str) -> MovingObstacle:
    values = {k[len(sub):]: v for k, v in flat.items() if k.startswith(sub)}
    kind = values.pop("type", None)
    if kind not in _KEYS:
        raise ScenarioError(f"scenario parameter '{sub}type': got {kind!r}, expected one of: {', '.join(_KEYS)}")
    valid = _KEYS[kind] + _PATH
    unknown = sorted(set(values) - set(valid))
    if unknown:
        raise ScenarioError(f"scenario parameter '{sub}{unknown[0]}': unknown key of a moving {kind} (got "
                            f"{values[unknown[0]]!r}); valid: type, {', '.join(valid)}")
    missing = [k for k in _KEYS[kind] + ("from", "to", "speed") if k not in values]
    if missing:
        raise ScenarioError(f"scenario parameter '{sub}{missing[0]}' is missing (a moving {kind})")
    start, end = _vector(sub + "from", values["from"]), _vector(sub + "to", values["to"])
    if np.linalg.norm(np.subtract(end, start)) < 1e-6:
        raise ScenarioError(f"scenario parameter '{sub}to': got {list(end)}, the same point as 'from'")
    radius = _positive(sub + "radius", values["radius"])
    shape: Obstacle = (Sphere(name, position=start, radius=radius) if kind == "sphere" else
                       Cylinder(name, position=start, radius=radius, length=_positive(sub + "length", values["length"])))
    return MovingObstacle(shape, start, end, _positive(sub + "speed", values["speed"]),
                          _time(sub + "start_time", values.get("start_time", 0.0)),
                          _time(sub + "dwell", values.get("dwell", 0.0)))
