"""A scenario's obstacles (:mod:`dualarm_control.obstacles`) as world geometry of the collision model.

Each obstacle becomes a frame ``obstacle:<name>`` on pinocchio's universe joint (joint 0: no arm
joint moves it) at its pose, and a ``pin.GeometryObject`` of that name on it: a coal ``Box``,
``Sphere``, ``Cylinder`` (axis z, as coal's), ``Halfspace`` (a plane: the obstacle is n.x <= offset)
or, for a mesh, its convex hull (as the robot's meshes, :func:`~dualarm_control.collision.shapes.reduced_geometry`).
:class:`~dualarm_control.collision.CollisionModel` then checks every link moved by an arm joint
(the arms' first links too) against every obstacle (docs/obstacles.md).
"""

from __future__ import annotations

from collections.abc import Sequence

import coal
import numpy as np
import pinocchio as pin

from dualarm_control.obstacles import (
    AttachedBox,
    Box,
    Cylinder,
    Mesh,
    Obstacle,
    Plane,
    Sphere,
)


def obstacle_shape(obstacle: Obstacle) -> coal.CollisionGeometry:
    """The coal shape of an obstacle, in its own frame (a plane's in the world's)."""
    if isinstance(obstacle, Box):
        return coal.Box(*obstacle.size)
    if isinstance(obstacle, Sphere):
        return coal.Sphere(obstacle.radius)
    if isinstance(obstacle, Cylinder):
        return coal.Cylinder(obstacle.radius, obstacle.length)
    if isinstance(obstacle, Plane):
        return coal.Halfspace(np.array(obstacle.normal), obstacle.offset)
    if isinstance(obstacle, Mesh):
        mesh = coal.MeshLoader().load(str(obstacle.file), np.array(obstacle.scale))
        mesh.buildConvexHull(True, "Qt")
        return mesh.convex
    raise TypeError(f"obstacle {obstacle.name!r}: unknown type {type(obstacle).__name__}")


def obstacle_placement(obstacle: Obstacle) -> pin.SE3:
    """The obstacle's pose in the world (identity for a plane: its normal and offset are the world's)."""
    if isinstance(obstacle, Plane):
        return pin.SE3.Identity()
    return pin.SE3(obstacle.rotation, np.array(obstacle.position, dtype=float))


def add_obstacles(model: pin.Model, geometry: pin.GeometryModel, obstacles: Sequence[Obstacle]) -> list[str]:
    """Add each obstacle to ``model`` (a frame on the universe joint) and ``geometry`` (its shape on
    that frame); returns the world obstacles' names in the model (``obstacle:<name>``). An
    :class:`~dualarm_control.obstacles.AttachedBox` (a held object) is added on its frame's joint instead,
    at the frame's placement times its own: a link of that arm (``held:<name>``, not returned). ValueError
    for a name the model already has, or an attached box's unknown frame."""
    names = []
    for obstacle in obstacles:
        name = obstacle.label
        if model.existFrame(name):
            raise ValueError(f"obstacle {obstacle.name!r}: the model already has a frame {name!r}")
        joint, parent, placement = 0, 0, obstacle_placement(obstacle)
        if isinstance(obstacle, AttachedBox):
            if not model.existFrame(obstacle.frame):
                raise ValueError(f"held object {obstacle.name!r}: the model has no frame {obstacle.frame!r}")
            parent = model.getFrameId(obstacle.frame)
            joint = model.frames[parent].parentJoint
            placement = model.frames[parent].placement * placement
        frame = model.addFrame(pin.Frame(name, joint, parent, placement, pin.FrameType.BODY))
        geometry.addGeometryObject(pin.GeometryObject(name, joint, frame, placement, obstacle_shape(obstacle)))
        if not isinstance(obstacle, AttachedBox):
            names.append(name)
    return names


def is_unbounded(shape: coal.CollisionGeometry) -> bool:
    """A shape without a bounding sphere (a half-space, a plane)."""
    return isinstance(shape, coal.Halfspace | coal.Plane)
