"""The robot's collision shapes and their extents.

Geometry: the robot's COLLISION shapes from its resolved URDF (``pin.buildGeomFromUrdf``), reduced
like :class:`~dualarm_control.kinematics.DualArmModel`'s model (``pin.buildReducedModel``, the same
locked joints at the same values, the same joint order): :func:`reduced_geometry`. Meshes are
replaced by their convex hulls (as pybullet does for the links of a multibody): coal then returns a
signed distance for every pair and the witness points are unique for strictly separated convex
shapes, except on degenerate configurations (parallel faces or edges: the tests detect them).

The extents bound the broadphase (:meth:`~dualarm_control.collision.CollisionModel.lower_bound`,
the bounding spheres of :meth:`~dualarm_control.collision.CollisionModel.near`): a shape's farthest
point from a point (:func:`farthest_from`), its bounding sphere, two shapes' distance in one frame,
shapes' distance to a sphere. And the URDF's tree of fixed joints (:func:`urdf_tree`: a tool frame's
end effector).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray
from dualarm_control.kinematics import DualArmModel
from dualarm_control.robot_files import RobotError


def shape_distance(a: pin.GeometryObject, b: pin.GeometryObject) -> float:
    """The distance [m] of two shapes placed in one frame (their ``placement``s)."""
    result = coal.DistanceResult()
    return float(coal.distance(a.geometry, coal.Transform3s(a.placement.rotation, a.placement.translation),
                               b.geometry, coal.Transform3s(b.placement.rotation, b.placement.translation),
                               coal.DistanceRequest(), result))


def sphere_distance(objects: Sequence[pin.GeometryObject], centre: FloatArray, radius: float) -> float:
    """The smallest distance [m] of shapes placed in one frame (their ``placement``s) to a sphere in it
    (centre [m], (3,); radius [m], at least 1e-9)."""
    sphere = coal.Sphere(max(radius, 1e-9))
    place = coal.Transform3s(np.eye(3), np.asarray(centre, dtype=float))
    bound = math.inf
    for obj in objects:
        result = coal.DistanceResult()
        coal.distance(obj.geometry, coal.Transform3s(obj.placement.rotation, obj.placement.translation),
                      sphere, place, coal.DistanceRequest(), result)
        bound = min(bound, float(result.min_distance))
    return bound


def farthest(obj: pin.GeometryObject) -> float:
    """max ||x|| [m] over the points x of a shape, in its parent joint's frame."""
    return farthest_from(obj.geometry, obj.placement.actInv(np.zeros(3)))


def farthest_from(shape: coal.CollisionGeometry, origin: FloatArray) -> float:
    """max ||x - origin|| [m] over the points x of a shape, all in the shape's frame (exact for
    spheres, capsules, cylinders, boxes and convex hulls; a bounding sphere of the local AABB
    otherwise)."""
    origin = np.asarray(origin, dtype=float)
    if isinstance(shape, coal.Sphere):
        return float(np.linalg.norm(origin)) + float(shape.radius)
    if isinstance(shape, coal.Capsule):
        h = float(shape.halfLength)
        return max(float(np.linalg.norm(origin - [0.0, 0.0, z])) for z in (-h, h)) + float(shape.radius)
    if isinstance(shape, coal.Cylinder):  # the farthest point lies on a rim circle
        h, radial = float(shape.halfLength), float(np.hypot(origin[0], origin[1]))
        return max(math.hypot(radial + float(shape.radius), z - float(origin[2])) for z in (-h, h))
    if isinstance(shape, coal.Box):
        corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * np.asarray(shape.halfSide)
        return float(np.max(np.linalg.norm(corners - origin, axis=1)))
    if isinstance(shape, coal.ConvexBase):
        return float(np.max(np.linalg.norm(np.asarray(shape.points()) - origin, axis=1)))
    shape.computeLocalAABB()
    return float(np.linalg.norm(np.asarray(shape.aabb_center) - origin)) + float(shape.aabb_radius)


def bounding_sphere(shape: coal.CollisionGeometry) -> tuple[FloatArray, float]:
    """A sphere holding a shape: the centre of its local AABB (shape frame) [m], (3,), and the
    farthest point's distance from it [m]; for a half-space or plane (an obstacle) the origin and inf."""
    if isinstance(shape, coal.Halfspace | coal.Plane):
        return np.zeros(3), math.inf
    shape.computeLocalAABB()
    centre = np.array(shape.aabb_center, dtype=float)
    return centre, farthest_from(shape, centre)


def reduced_geometry(model: DualArmModel) -> tuple[pin.Model, pin.GeometryModel]:
    """The collision geometry of ``model``'s robot, reduced to its arms' joints like its model.

    Meshes become their convex hulls. RobotError if the reduced model differs from ``model.model``
    (joint names, nq, joint placements).
    """
    robot = model.description
    urdf = str(model.urdf)
    full = pin.buildModelFromUrdf(urdf)
    geometry = pin.buildGeomFromUrdf(full, urdf, pin.GeometryType.COLLISION)
    for obj in geometry.geometryObjects:
        shape = obj.geometry
        if isinstance(shape, coal.BVHModelBase):
            shape.buildConvexHull(True, "Qt")
            obj.geometry = shape.convex
    locked = robot.locked_positions()
    if locked:
        q_ref = pin.neutral(full)
        for name, value in locked.items():
            joint = full.getJointId(name)
            q_ref[full.idx_qs[joint]] = value
        reduced, geometry = pin.buildReducedModel(full, geometry, [full.getJointId(n) for n in locked], q_ref)
    else:
        reduced = full
    names = [reduced.names[i] for i in range(1, reduced.njoints)]
    same = reduced.nq == model.model.nq and names == model.joint_names and all(
        reduced.jointPlacements[i].isApprox(model.model.jointPlacements[i], 1e-12) for i in range(reduced.njoints))
    if not same:
        raise RobotError(f"robot {robot.name!r}: the collision model's joints {names} (nq {reduced.nq}) differ "
                         f"from the kinematic model's {model.joint_names} (nq {model.model.nq})")
    return reduced, geometry


def urdf_tree(urdf: Path, moving: Collection[str]) -> tuple[dict[str, str], set[str]]:
    """A URDF's tree: each link's parent link, and the links whose joint to it is not among the
    ``moving`` joints (fixed, or an arm's locked joint)."""
    moving = set(moving)
    parent_of: dict[str, str] = {}
    rigid: set[str] = set()
    for joint in ET.parse(urdf).getroot().iter("joint"):
        child, parent = joint.find("child"), joint.find("parent")
        if child is None or parent is None:
            continue
        parent_of[child.get("link", "")] = parent.get("link", "")
        if joint.get("name") not in moving:
            rigid.add(child.get("link", ""))
    return parent_of, rigid


def end_effector_links(link: str, parent_of: Mapping[str, str], rigid: Collection[str],
                       shaped: Collection[str]) -> list[str]:
    """The end effector of tool frame ``link``: from ``link`` up through fixed (or locked) joints to
    the first link with collision shapes (``shaped``: the LWR4's flange, Baxter's gripper base), then
    every link hanging from it by fixed or locked joints, recursively (the tool frame, a tool set's
    bodies, locked fingers), that link first. ``[link]`` when no shaped link is rigidly above it.
    ``parent_of``, ``rigid``: the URDF's tree (:func:`urdf_tree`)."""
    top: str | None = link
    while top is not None and top not in shaped:
        top = parent_of[top] if top in rigid else None
    if top is None:
        return [link]
    group = [top]
    grown = True
    while grown:
        below = sorted(child for child in rigid if parent_of.get(child) in group and child not in group)
        group += below
        grown = bool(below)
    return group
