"""The collision limit: the velocity damper's rows as a :class:`~dualarm_control.limits.base.Limit`.

Each cycle, the pairs of the robot's :class:`~dualarm_control.collision.CollisionModel` closer
than the influence distance d_i give one hard row each (:func:`~dualarm_control.collision.velocity_damper`):

    -dd_dq qd <= xi (d - d_s') / (d_i' - d_s')        [m/s]

with d_s' = d_s + 2 m and d_i' = d_i + 2 m, m the shape margin (``collision.shape_margin``, 1 mm:
pybullet's collision margin; the limit keeps d_s between the shapes as the simulator grows them).

which every solver takes in its own variables (docs/collision.md, "Limits"). The rows' matrix is
deferred (:class:`~dualarm_control.limits.base.DeferredRows`): it is built only when a solver's result
is not vouched for by how fast the pairs' distances can change at most (the reach of their links
about each joint), which in most cycles with pairs in range it is. What the limit saw
is kept for the cycle's report (:class:`CollisionReport`: the closest pair, its distance, the rows
and how many of them are at their bound).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.collision import (
    CollisionModel,
    CollisionParams,
    NearPairs,
    PairDistance,
    velocity_damper,
    velocity_damper_bound,
)
from dualarm_control.kinematics import Configuration, DualArmModel, FloatArray
from dualarm_control.limits.base import (
    NONE,
    ROW_PRIORITY,
    Constraint,
    DeferredRows,
)
from dualarm_control.limits.registry import LimitContext, register_limit
from dualarm_control.limits.stall import BrakedLimit, StallBrake

ACTIVE_TOLERANCE = 1e-6
"""A row is active (at its bound) when A qd >= b - 1e-6 m/s."""


@dataclass(slots=True)
class CollisionReport:
    """What the collision limit saw in one cycle (a per-cycle record: slotted, not frozen, cheaper
    to build; not modified once made).

    Attributes:
        distance: the smallest distance d [m] of the pairs closer than d_i (inf: none that close).
        pair: its links ``(link_a, link_b)``, or None.
        rows: how many pairs gave a row (d < d_i).
        active: how many rows the command holds at their bound (A qd >= b - :data:`ACTIVE_TOLERANCE`).
        influence_distance: d_i [m] of the cycle (what "inf" means).
    """

    distance: float
    pair: tuple[str, str] | None
    rows: int
    active: int
    influence_distance: float

    def values(self) -> dict[str, str]:
        """The /diagnostics keys (strings, as diagnostic_msgs/KeyValue holds them): ``collision_distance_m``
        (the closest pair's d, or ``inf`` beyond d_i), ``collision_pair`` ("link_a – link_b" or ""),
        ``collision_rows`` and ``collision_active``."""
        return {"collision_distance_m": f"{self.distance:.6f}" if self.pair is not None else "inf",
                "collision_pair": f"{self.pair[0]} – {self.pair[1]}" if self.pair is not None else "",
                "collision_rows": str(self.rows), "collision_active": str(self.active)}

    def text(self) -> str:
        """One line, e.g. ``left_flange – right_link_5 at 0.030 m (2 rows, 1 active)``."""
        if self.pair is None:
            return f"no pair closer than {self.influence_distance:.3f} m"
        return (f"{self.pair[0]} – {self.pair[1]} at {self.distance:.3f} m ({self.rows} rows, "
                f"{self.active} active)")


def allowed_pairs(model: DualArmModel, params: CollisionParams) -> tuple[tuple[str, str], ...]:
    """The robot's ``collision_allowed`` pairs and the parameters' own, in that order."""
    return tuple(model.description.collision_allowed) + tuple(params.allowed)


class CollisionLimit(BrakedLimit):
    """The velocity damper of every pair closer than d_i, as hard rows (module docstring).

    Args:
        collision: the robot's collision model (its allowed pairs already removed).
        params: d_i, d_s, xi (``enabled`` is the controller's business: it adds this limit or not).
        brake: the acceleration box added while the rows hold the command (:mod:`~dualarm_control.limits.stall`);
            None: none.
    """

    name = "collision"
    priority = ROW_PRIORITY

    def __init__(self, collision: CollisionModel, params: CollisionParams, brake: StallBrake | None = None) -> None:
        self.collision = collision
        self.params = params
        self.brake = brake
        self.last = NearPairs.empty(collision.model.nv)
        self._rows = DeferredRows.of(np.zeros((0, collision.model.nv)), np.zeros(0))
        self._labels = tuple(f"{a} – {b}" for a, b in collision.pairs)
        self._kept = params.kept_distances
        self._clear = CollisionReport(math.inf, None, 0, 0, self._kept[0])  # no pair within d_i

    @property
    def near(self) -> list[PairDistance]:
        """The pairs of the last cycle closer than d_i (one object each: for a report, not the cycle)."""
        self.last = last = self.collision.complete(self.last)
        return last.pair_distances()

    def constraints(self, configuration: Configuration, previous: FloatArray) -> Constraint:
        constraint = self._rows_at(configuration.q)
        return constraint if self.brake is None else self.brake.narrow(constraint, configuration.q, previous)

    def _rows_at(self, q: FloatArray) -> Constraint:
        """The damper's rows of the pairs within d_i at q [rad] (n,) (module docstring); NONE without any."""
        influence, safety = self._kept
        self.last = near = self.collision.near(q, within=influence, rows=False)
        if not near.index:
            return NONE
        gain, collision = self.params.gain, self.collision
        self._rows = rows = DeferredRows(near.speed, velocity_damper_bound(near.distance, influence, safety, gain),
                                         lambda: velocity_damper(collision.rows(near), near.distance, influence,
                                                                 safety, gain)[0])
        return Constraint(rows=rows, labels=tuple([self._labels[i] for i in near.index]))

    def report(self, velocities: FloatArray) -> CollisionReport:
        """The last cycle's :class:`CollisionReport` for its command ``velocities`` [rad/s] (n,)."""
        near = self.last
        if not near.index:
            return self._clear
        rows = self._rows
        # a row vouched for by its speed bound (C |qd| <= b - 1e-6) is not active; else A qd decides
        active = 0 if rows.meets(velocities) else int(np.count_nonzero(rows.matrix @ velocities
                                                                        >= rows.bound - ACTIVE_TOLERANCE))
        if self.brake is not None:
            self.brake.saw(active)
        distances = near.distance.tolist()
        closest = min(distances)
        return CollisionReport(closest, near.links[distances.index(closest)], len(distances), active, self._kept[0])


@register_limit("collision")
def collision_limit(context: LimitContext) -> CollisionLimit | None:
    """On when the controller's ``collision.enabled`` is (the controller then has a collision model)."""
    if context.collision is None:
        return None
    return CollisionLimit(context.collision, context.params.collision, StallBrake.of(context))
