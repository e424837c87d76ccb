"""A scenario's static obstacles (:mod:`dualarm_control.obstacles`) as pybullet bodies of the cell.

Each obstacle is one static body (mass 0: it never moves) with a collision shape and a visual shape
of the same geometry at the obstacle's pose: ``GEOM_BOX`` (half extents), ``GEOM_SPHERE``,
``GEOM_CYLINDER`` (axis z, as coal's), ``GEOM_PLANE`` (an infinite plane, its normal out of the
obstacle: the bodies below it are pushed out, as by coal's half-space) and ``GEOM_MESH`` (a
static mesh is its convex hull, as in coal). Every body collides with every link of the robot
(pybullet's default between two bodies); :meth:`~dualarm_sim.cell.DualArmCell.obstacle_distances`
and :func:`~dualarm_sim.contacts.obstacle_min_distances` measure the links' distances to them with
``getClosestPoints``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pybullet as p

from dualarm_control.obstacles import Box, Cylinder, Mesh, Obstacle, Plane, Sphere

COLOUR = (0.55, 0.55, 0.6, 1.0)
"""The obstacles' colour in the cell's camera images (a table: :data:`TABLE_COLOUR`)."""
TABLE_COLOUR = (0.6, 0.45, 0.3, 1.0)
PLANE_TILE = (2.0, 2.0, 0.0005)
"""Half extents [m] of the box that draws a plane (its collision shape is the infinite plane)."""


def _z_to(normal: Sequence[float]) -> tuple[float, float, float, float]:
    """The quaternion (x, y, z, w) that turns the z axis onto the unit vector ``normal``."""
    n = np.asarray(normal, dtype=float)
    axis = np.cross((0.0, 0.0, 1.0), n)
    s, c = float(np.linalg.norm(axis)), float(n[2])
    if s < 1e-12:
        return (0.0, 0.0, 0.0, 1.0) if c > 0 else (1.0, 0.0, 0.0, 0.0)
    half = 0.5 * np.arctan2(s, c)
    x, y, z = axis / s * np.sin(half)
    return float(x), float(y), float(z), float(np.cos(half))


def _shapes(obstacle: Obstacle, client: int) -> tuple[int, int]:
    """pybullet's collision and visual shape ids of an obstacle."""
    colour = TABLE_COLOUR if obstacle.name == "table" else COLOUR
    if isinstance(obstacle, Box):
        half = tuple(s / 2.0 for s in obstacle.size)
        return (p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client),
                p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=colour, physicsClientId=client))
    if isinstance(obstacle, Sphere):
        return (p.createCollisionShape(p.GEOM_SPHERE, radius=obstacle.radius, physicsClientId=client),
                p.createVisualShape(p.GEOM_SPHERE, radius=obstacle.radius, rgbaColor=colour, physicsClientId=client))
    if isinstance(obstacle, Cylinder):
        return (p.createCollisionShape(p.GEOM_CYLINDER, radius=obstacle.radius, height=obstacle.length,
                                       physicsClientId=client),
                p.createVisualShape(p.GEOM_CYLINDER, radius=obstacle.radius, length=obstacle.length, rgbaColor=colour,
                                    physicsClientId=client))
    if isinstance(obstacle, Plane):  # pybullet draws no plane: a 4 x 4 m tile of it, 1 mm below
        return (p.createCollisionShape(p.GEOM_PLANE, planeNormal=obstacle.normal, physicsClientId=client),
                p.createVisualShape(p.GEOM_BOX, halfExtents=PLANE_TILE, visualFramePosition=tuple(-PLANE_TILE[2] * np.asarray(obstacle.normal)),
                                    visualFrameOrientation=_z_to(obstacle.normal), rgbaColor=colour,
                                    physicsClientId=client))
    if isinstance(obstacle, Mesh):
        return (p.createCollisionShape(p.GEOM_MESH, fileName=str(obstacle.file), meshScale=obstacle.scale,
                                       physicsClientId=client),
                p.createVisualShape(p.GEOM_MESH, fileName=str(obstacle.file), meshScale=obstacle.scale,
                                    rgbaColor=colour, physicsClientId=client))
    raise TypeError(f"obstacle {obstacle.name!r}: unknown type {type(obstacle).__name__}")


def add_obstacle_bodies(obstacles: Sequence[Obstacle], client: int) -> dict[str, int]:
    """One static body per obstacle in ``client``, at its pose (a plane: at normal * offset, unrotated);
    their body ids by obstacle name. RuntimeError naming an obstacle pybullet could not load."""
    out: dict[str, int] = {}
    for obstacle in obstacles:
        shape, visual = _shapes(obstacle, client)
        if shape < 0:
            raise RuntimeError(f"pybullet could not make the collision shape of obstacle {obstacle.name!r}")
        if isinstance(obstacle, Plane):
            position = tuple(float(v) for v in np.array(obstacle.normal) * obstacle.offset)
            orientation: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)
        else:
            position = obstacle.position
            orientation = tuple(p.getQuaternionFromEuler(obstacle.rpy))
        out[obstacle.name] = int(p.createMultiBody(0.0, shape, visual if visual >= 0 else -1, basePosition=position,
                                                   baseOrientation=orientation, physicsClientId=client))
    return out


def add_table(height: float, client: int) -> int:
    """A static 1.2 x 1.6 x 0.05 m box in front of the torso (centre at x = 0.7 m) whose top is at world
    z = ``height`` [m] (``CellConfig.table_height``); its body id."""
    half = (0.6, 0.8, 0.025)
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    visual = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=(0.6, 0.45, 0.3, 1), physicsClientId=client)
    return int(p.createMultiBody(0.0, shape, visual, basePosition=(0.7, 0.0, height - half[2]), physicsClientId=client))
