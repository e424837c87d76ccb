"""Live obstacles (issue 42, part 2): shapes with a pose and a velocity that change while the arms
move, and their distances to the arm links with the rows of the velocity damper.

A live obstacle is not part of the pinocchio geometry (:class:`~dualarm_control.collision.CollisionModel`
keeps its pairs fixed at construction); its distance to every shape moved by an arm joint is computed
here, on its own pinocchio data (the model's known bounds are not disturbed), with the same coal
request and the same conventions as the robot's pairs (:mod:`~dualarm_control.collision.distances`):
A the link's shape, B the obstacle, n the unit normal from A to B, d = n^T (p_b - p_a) [m].

Moving obstacle: B's points move at v_B [m/s] (world, translation only), so

    d_dot = n^T (v_B - J_pa qd) = dd_dq qd + n^T v_B,      dd_dq = -n^T J_pa  (1, n)

and the velocity damper d_dot >= -xi (d - d_s) / (d_i - d_s) becomes the row

    -dd_dq qd <= xi (d - d_s) / (d_i - d_s) + n^T v_B            [m/s]

An approaching obstacle (n^T v_B < 0) lowers the bound below zero near d_s: the arm has to move
away (yield), not only stop. Without v_B the arm waits at d_s and the obstacle pushes through it.

Cost: per cycle, one ``computeJointJacobians`` and ``updateGeometryPlacements`` (tens of us), a
bounding-sphere test of every (link shape, obstacle) pair in numpy, and one ``coal.distance`` per
pair whose spheres are closer than d_i (about 3 us for primitives, more for an octree).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import coal
import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.distances import witness_rows
from dualarm_control.collision.params import distance_request
from dualarm_control.collision.shapes import bounding_sphere


@dataclass(frozen=True, slots=True)
class LiveObstacle:
    """One live obstacle, in the world frame of the cell.

    Attributes:
        name: its name (``obstacle:<name>`` in the pairs' labels).
        shape: its coal shape in its own frame (Box, Sphere, Cylinder, Capsule, ConvexBase or OcTree).
        rotation: its orientation, (3, 3). position: its origin [m], (3,).
        velocity: its linear velocity [m/s], (3,) (zero for a still one).
        expires: when it is gone [s, the feed's clock]; inf: never.
        centre: its bounding sphere's centre in its own frame [m], (3,). radius: that sphere's radius [m].
    """

    name: str
    shape: coal.CollisionGeometry
    rotation: FloatArray
    position: FloatArray
    velocity: FloatArray = field(default_factory=lambda: np.zeros(3))
    expires: float = math.inf
    centre: FloatArray = field(default_factory=lambda: np.zeros(3))
    radius: float = 0.0

    @classmethod
    def make(cls, name: str, shape: coal.CollisionGeometry, rotation: FloatArray, position: FloatArray,
             velocity: FloatArray | None = None, expires: float = math.inf) -> LiveObstacle:
        """An obstacle with its bounding sphere computed (:func:`shape_sphere`)."""
        centre, radius = shape_sphere(shape)
        return cls(name, shape, np.asarray(rotation, dtype=float), np.asarray(position, dtype=float),
                   np.zeros(3) if velocity is None else np.asarray(velocity, dtype=float), expires, centre, radius)

    def moved(self, position: FloatArray, velocity: FloatArray | None = None,
              rotation: FloatArray | None = None) -> LiveObstacle:
        """The same obstacle at a new ``position`` [m] (and velocity [m/s], rotation, when given)."""
        return LiveObstacle(self.name, self.shape, self.rotation if rotation is None else rotation,
                            np.asarray(position, dtype=float), self.velocity if velocity is None else velocity,
                            self.expires, self.centre, self.radius)

    @property
    def label(self) -> str:
        """``obstacle:<name>``, as a static obstacle's."""
        return "obstacle:" + self.name


def shape_sphere(shape: coal.CollisionGeometry) -> tuple[FloatArray, float]:
    """A sphere holding ``shape``: its centre in the shape's frame [m], (3,), and radius [m] (an
    octree's from its occupied cells' bounding box)."""
    if isinstance(shape, coal.OcTree):
        boxes = np.asarray(shape.toBoxes())  # (k, 6): x, y, z, side, occupancy, threshold
        if not len(boxes):
            return np.zeros(3), 0.0
        low = (boxes[:, :3] - boxes[:, 3:4] / 2).min(axis=0)
        high = (boxes[:, :3] + boxes[:, 3:4] / 2).max(axis=0)
        return (low + high) / 2, float(np.linalg.norm(high - low) / 2)
    return bounding_sphere(shape)


@dataclass(slots=True)
class LivePairs:
    """The (link, live obstacle) pairs of one cycle closer than the influence distance.

    Attributes:
        links: each pair's (link, ``obstacle:<name>``). distance: d [m], (m,).
        rows: dd_dq [m/rad], (m, n). approach: n^T v_B [m/s], (m,) (< 0: the obstacle comes closer).
        points: p_a on the link, p_b on the obstacle [m], (2, m, 3). normals: n, (m, 3).
    """

    links: tuple[tuple[str, str], ...]
    distance: FloatArray
    rows: FloatArray
    approach: FloatArray
    points: FloatArray
    normals: FloatArray

    def __len__(self) -> int:
        return len(self.links)

    @classmethod
    def empty(cls, n: int) -> LivePairs:
        return cls((), np.zeros(0), np.zeros((0, n)), np.zeros(0), np.zeros((2, 0, 3)), np.zeros((0, 3)))


class LiveDistances:
    """Distances of every shape an arm joint moves to live obstacles (module docstring).

    Args:
        model, geometry: the collision model's reduced pinocchio model and geometry
            (``CollisionModel.model`` and ``.geometry``); read, never modified.
        gjk_tolerance: coal's GJK tolerance [m^2] (the collision model's).
    """

    def __init__(self, model: pin.Model, geometry: pin.GeometryModel, gjk_tolerance: float = 1e-12) -> None:
        self.model, self.geometry = model, geometry
        self.data = model.createData()
        self.geometry_data = geometry.createData()
        objects = geometry.geometryObjects
        self.shapes = [k for k, obj in enumerate(objects) if obj.parentJoint != 0]
        self.names = [model.frames[objects[k].parentFrame].name for k in self.shapes]
        spheres = [bounding_sphere(objects[k].geometry) for k in self.shapes]
        self._centres = np.array([c for c, _ in spheres]).reshape(-1, 3)
        self._radii = np.array([r for _, r in spheres])
        support = np.zeros((len(self.shapes), model.nv))
        for i, k in enumerate(self.shapes):
            for j in model.supports[objects[k].parentJoint].tolist()[1:]:
                support[i, model.idx_vs[j]:model.idx_vs[j] + model.joints[j].nv] = 1.0
        self._support = support
        self.request = distance_request(gjk_tolerance)
        self._result = coal.DistanceResult()

    def near(self, q: FloatArray, obstacles: Sequence[LiveObstacle], within: float) -> LivePairs:
        """The (link, obstacle) pairs closer than ``within`` [m] at q [rad] (n,), each link's closest
        shape, obstacle by obstacle in the order given, links in the geometry's order."""
        n = self.model.nv
        if not obstacles or not self.shapes:
            return LivePairs.empty(n)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data)
        placed = self.geometry_data.oMg
        frames = [placed[k] for k in self.shapes]
        rotations = np.array([f.rotation for f in frames])
        origins = np.array([f.translation for f in frames])
        centres = (rotations @ self._centres[:, :, None])[:, :, 0] + origins  # (shapes, 3), world
        best: dict[tuple[int, str], tuple[float, FloatArray, FloatArray, FloatArray, int]] = {}
        order: list[tuple[int, str]] = []
        result, request = self._result, self.request
        for obstacle in obstacles:
            centre = obstacle.rotation @ obstacle.centre + obstacle.position
            gaps = np.linalg.norm(centres - centre, axis=1) - self._radii - obstacle.radius
            close = np.flatnonzero(gaps < within).tolist()
            if not close:
                continue
            tf = coal.Transform3s(obstacle.rotation, obstacle.position)
            octree = isinstance(obstacle.shape, coal.OcTree)
            for i in close:
                k = self.shapes[i]
                result.clear()
                if octree:  # coal answers an octree pair with the octree's point first, the normal from it
                    d = coal.distance(obstacle.shape, tf, self.geometry.geometryObjects[k].geometry, placed[k],
                                      request, result)
                    p_b, p_a, normal = result.getNearestPoint1(), result.getNearestPoint2(), -result.normal
                else:
                    d = coal.distance(self.geometry.geometryObjects[k].geometry, placed[k], obstacle.shape, tf,
                                      request, result)
                    p_a, p_b, normal = result.getNearestPoint1(), result.getNearestPoint2(), result.normal
                if not (math.isfinite(d) and d < within):
                    continue
                key = (i, obstacle.name)
                link_key = (self._link_index(i), obstacle.name)
                if link_key not in best:
                    order.append(link_key)
                elif best[link_key][0] <= d:
                    continue
                best[link_key] = (float(d), np.array(p_a), np.array(p_b), np.array(normal), key[0])
        if not best:
            return LivePairs.empty(n)
        m = len(order)
        distance = np.empty(m)
        points = np.empty((2, m, 3))
        normals = np.empty((m, 3))
        shape_rows = np.empty(m, dtype=np.intp)
        velocity = {o.name: o.velocity for o in obstacles}
        approach = np.empty(m)
        for r, key in enumerate(order):
            d, p_a, p_b, normal, i = best[key]
            length = float(np.linalg.norm(normal))
            normal = normal / length if length > 0.0 else np.array([0.0, 0.0, 1.0])
            distance[r], points[0, r], points[1, r], normals[r], shape_rows[r] = d, p_a, p_b, normal, i
            approach[r] = float(normal @ velocity[key[1]])
        rows = -witness_rows(normals, points[0], self.data.J) * self._support[shape_rows]
        links = tuple((self.names[shape_rows[r]], "obstacle:" + key[1]) for r, key in enumerate(order))
        return LivePairs(links, distance, rows, approach, points, normals)

    def _link_index(self, i: int) -> int:
        """The first shape index of shape i's link (a link with several shapes keeps its closest)."""
        return self.names.index(self.names[i])


def live_damper_bound(distance: FloatArray, approach: FloatArray, influence: float, safety: float,
                      gain: float) -> FloatArray:
    """b = xi (d - d_s) / (d_i - d_s) + n^T v_B [m/s], (m,) (module docstring): the velocity damper's
    bound for m pairs at d [m] whose obstacle approaches at n^T v_B [m/s] (``approach``, (m,))."""
    result: FloatArray = gain * (distance - safety) / (influence - safety) + approach
    return result
