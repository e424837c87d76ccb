"""The limits of every control cycle, one module each (issue 39; docs/limits.md).

* :mod:`.base`: what a limit is (:class:`Limit`, :class:`Constraint`) and how a cycle's limits are
  intersected (:func:`apply_limits`);
* :mod:`.joint`: the joint position and velocity limits, eq (20)-(23) of paper 000;
* :mod:`.acceleration`: the joint acceleration bound;
* :mod:`.collision`: the collision limit (the velocity damper's rows);
* :mod:`.live`: the live obstacles' velocity damper rows (with the obstacles' velocities);
* :mod:`.repulsive`: the repulsive joint-limit velocity of eq (24)-(25) (the hierarchical solvers'
  secondary task, not a constraint);
* :mod:`.registry`: limits by name (``limits`` parameter), a user's own from their own file.

A new limit is one file here plus its import below (the import registers it).
"""

from dualarm_control.limits.acceleration import AccelerationLimit, acceleration_bounds
from dualarm_control.limits.base import (
    NONE,
    Bounds,
    Constraint,
    DeferredRows,
    Limit,
    LimitReport,
    apply_limits,
    ordered,
)
from dualarm_control.limits.collision import (
    CollisionLimit,
    CollisionReport,
    allowed_pairs,
)
from dualarm_control.limits.joint import JointLimits, VelocityLimit, velocity_bounds
from dualarm_control.limits.live import LiveObstacleLimit, LiveReport
from dualarm_control.limits.registry import (
    DEFAULT_LIMITS,
    LimitContext,
    limit_names,
    make_limits,
    register_limit,
)
from dualarm_control.limits.repulsive import RepulsiveField, repulsive_velocity

__all__ = [
    "DEFAULT_LIMITS",
    "NONE",
    "AccelerationLimit",
    "Bounds",
    "CollisionLimit",
    "CollisionReport",
    "Constraint",
    "DeferredRows",
    "JointLimits",
    "Limit",
    "LimitContext",
    "LimitReport",
    "LiveObstacleLimit",
    "LiveReport",
    "RepulsiveField",
    "VelocityLimit",
    "acceleration_bounds",
    "allowed_pairs",
    "apply_limits",
    "limit_names",
    "make_limits",
    "ordered",
    "register_limit",
    "repulsive_velocity",
    "velocity_bounds",
]
