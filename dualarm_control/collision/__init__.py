"""Collision distances between the robot's links and the velocity damper that keeps them apart.

The ROS-free core of collision avoidance (issue 27; docs/collision.md): :func:`velocity_damper` gives
the rows ``A qd <= b`` that :class:`~dualarm_control.limits.collision.CollisionLimit` adds to every solver's QP.

Modules, one job each (their docstrings have the equations and the measured accuracy):

* :mod:`~dualarm_control.collision.params`: the constants (tolerances, margins), :class:`CollisionParams`,
  :class:`CollisionError`, the coal request of every distance.
* :mod:`~dualarm_control.collision.shapes`: the robot's collision shapes from its URDF (reduced like
  its kinematic model, meshes as convex hulls) and their extents (farthest points, bounding spheres).
* :mod:`~dualarm_control.collision.model`: :class:`CollisionModel`: the links, the pairs checked
  (the rules, the allowed pairs), the broadphase lower bounds, the shapes' placements.
* :mod:`~dualarm_control.collision.distances`: d = n^T (p_b - p_a) and its row dd_dq = n^T (J_pb - J_pa)
  (:class:`PairDistance`, :class:`NearPairs`, :func:`witness_rows`, :func:`sphere_plane_distances`).
* :mod:`~dualarm_control.collision.features`: GJK's witness points refined on the shapes' closest
  features (``polish=True``).
* :mod:`~dualarm_control.collision.damper`: the velocity damper -dd_dq qd <= xi (d - d_s) / (d_i - d_s).

Every name other modules use is importable from here.
"""

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.damper import (
    velocity_damper,
    velocity_damper_bound,
    velocity_damper_rows,
)
from dualarm_control.collision.distances import (
    NearPairs,
    PairDistance,
    sphere_plane_distances,
    witness_rows,
)
from dualarm_control.collision.model import CollisionModel
from dualarm_control.collision.params import (
    DEFAULT_GJK_TOLERANCE,
    DEFAULT_MARGIN,
    EPA_TOLERANCE,
    FALLBACK_GJK_TOLERANCES,
    GJK_MAX_ITERATIONS,
    KNOWN_MARGIN,
    SAME_ARM_JOINT_DISTANCE,
    SPHERE_BROADPHASE_MIN,
    TOOL_FRAMES,
    WITNESS_FEATURE_TOLERANCE,
    WITNESS_POLISH_LIMIT,
    WORLD,
    WORLD_JOINT_DISTANCE,
    CollisionError,
    CollisionParams,
)

__all__ = [
    "DEFAULT_GJK_TOLERANCE",
    "DEFAULT_MARGIN",
    "EPA_TOLERANCE",
    "FALLBACK_GJK_TOLERANCES",
    "GJK_MAX_ITERATIONS",
    "KNOWN_MARGIN",
    "SAME_ARM_JOINT_DISTANCE",
    "SPHERE_BROADPHASE_MIN",
    "TOOL_FRAMES",
    "WITNESS_FEATURE_TOLERANCE",
    "WITNESS_POLISH_LIMIT",
    "WORLD",
    "WORLD_JOINT_DISTANCE",
    "CollisionError",
    "CollisionModel",
    "CollisionParams",
    "FloatArray",
    "NearPairs",
    "PairDistance",
    "sphere_plane_distances",
    "velocity_damper",
    "velocity_damper_bound",
    "velocity_damper_rows",
    "witness_rows",
]
