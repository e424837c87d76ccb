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

Cost: per cycle, the pairs whose known lower bound (:class:`LiveDistances`) is below d_i get a
bounding-sphere test (one ``computeJointJacobians``, numpy on every such pair at once) and those
whose spheres are closer than d_i one ``coal.distance`` each (about 3-30 us for primitives at the
1e-12 GJK tolerance, more for an octree); no pair in reach costs no kinematics at all.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.distances import witness_rows
from dualarm_control.collision.params import (
    _FAILED,
    KNOWN_MARGIN,
    SPHERE_BROADPHASE_MIN,
    distance_request,
)
from dualarm_control.collision.placements import JointFrames
from dualarm_control.collision.shapes import bounding_sphere, farthest

_CHOSEN_KEPT = 64
"""Pair sets whose links, labels and speed bounds :meth:`LiveDistances.near` keeps (forgotten all at once
past this many, and at every new snapshot)."""


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
             velocity: FloatArray | None = None, expires: float = math.inf,
             sphere: tuple[FloatArray, float] | None = None) -> LiveObstacle:
        """An obstacle with its bounding sphere (centre in its frame [m], radius [m]): ``sphere``, or
        computed (:func:`shape_sphere`)."""
        centre, radius = shape_sphere(shape) if sphere is None else sphere
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
        approach: n^T v_B [m/s], (m,) (< 0: the obstacle comes closer). moving: whether any is not 0.
        speed: how fast each pair's distance can change at most, C [m/rad], (m, n): |dd_dq qd| <= C |qd|
            (the reach of the link about each joint; :class:`~dualarm_control.limits.base.DeferredRows`).
        rows: dd_dq [m/rad], (m, n). points: p_a on the link, p_b on the obstacle [m], (2, m, 3).
        normals: n, (m, 3). These three are None when the call deferred them
            (:meth:`LiveDistances.complete` makes them, until the next call).
        pairs: each pair's index in the call's (obstacle, shape) table. call: the call's number.
        labels: each pair's ``link – obstacle:<name>`` (the rows' labels).
    """

    links: tuple[tuple[str, str], ...]
    distance: FloatArray
    approach: FloatArray
    moving: bool
    speed: FloatArray
    rows: FloatArray | None = None
    points: FloatArray | None = None
    normals: FloatArray | None = None
    pairs: tuple[int, ...] = ()
    call: int = 0
    labels: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.links)

    @classmethod
    def empty(cls, n: int) -> LivePairs:
        return cls((), np.zeros(0), np.zeros(0), False, np.zeros((0, n)), np.zeros((0, n)), np.zeros((2, 0, 3)),
                   np.zeros((0, 3)))


@dataclass(slots=True)
class _Block:
    """One obstacle's entries of :class:`LiveDistances`' table, kept from one snapshot to the next while the
    obstacle keeps its name, shape (the same object) and place in the snapshot: a move only updates coal's
    transform, which the entries share, and the bounding sphere's centre.

    Attributes:
        shape: the obstacle's shape. sphere: its bounding sphere's centre (the same array object) and radius.
        index: its place j in the snapshot.
        rotation: its rotation's bytes. position: its position [m], (3,). transform: coal's transform of both.
        centre: its bounding sphere's centre in the world [m], (3,). entries: its table entries, one per arm shape.
    """

    shape: coal.CollisionGeometry
    sphere: tuple[FloatArray, float]
    index: int
    rotation: bytes
    position: FloatArray
    transform: coal.Transform3s
    centre: FloatArray
    entries: list[tuple[Any, ...]]


class LiveDistances:
    """Distances of every shape an arm joint moves to live obstacles (module docstring).

    Known bounds (temporal coherence, as the collision model's): each (shape, obstacle) pair's last
    distance less :data:`~dualarm_control.collision.params.KNOWN_MARGIN` is kept as a lower bound,
    moved to the next q by d(q) >= d(q') - sum_j c_j |q_j - q'_j| (c_j the reach of the shape about
    joint j: the joint offsets down the chain plus the shape's extent, a bound on how far a point of
    the shape moves per radian of joint j; 1 for a prismatic joint). A new snapshot (the feed swaps a new
    tuple whenever something moves or comes or goes) keeps the bounds of each obstacle that kept its
    name, shape object, place in the snapshot and rotation, less how far it moved, ||p - p'|| (a
    translation moves every point of it by that much); the others' are forgotten. A pair whose bound is
    at least the influence distance costs no kinematics and no coal call.

    Cost (issue 42): per snapshot, a table of coal's arguments for every (obstacle, shape) pair (the
    shapes' placements by reference, as the collision model's), built only for the obstacles that are new
    or changed shape or place (a moved one updates its transform: :class:`_Block`); per cycle, the known bounds moved (one
    matrix-vector product), the kinematics when a pair may be in reach (``computeJointJacobians``, 3 us),
    one ``coal.distance`` per candidate pair, and the witness points, normals and rows only when asked
    for (:meth:`complete`; a moving obstacle's normal at once, for n^T v_B).

    Args:
        model, geometry: the collision model's reduced pinocchio model and geometry
            (``CollisionModel.model`` and ``.geometry``); read, never modified.
        gjk_tolerance: coal's GJK tolerance [m^2] (the collision model's).
    """

    def __init__(self, model: pin.Model, geometry: pin.GeometryModel, gjk_tolerance: float = 1e-12) -> None:
        self.model, self.geometry = model, geometry
        self.data = model.createData()
        self._frames = JointFrames(model, self.data)
        self.geometry_data = geometry.createData()
        objects = geometry.geometryObjects
        self.shapes = [k for k, obj in enumerate(objects) if obj.parentJoint != 0]
        self.names = [model.frames[objects[k].parentFrame].name for k in self.shapes]
        self._first = [self.names.index(name) for name in self.names]  # a link's first shape: its pairs' key
        # a link's shapes next to each other: the candidates (ascending) meet the pairs' keys in ascending order
        self._keys_ascending = all(a <= b for a, b in zip(self._first, self._first[1:]))
        self._one_shape_each = self._first == list(range(len(self._first)))  # a pair is its own key (the LWR4 cell)
        self._geometries = [objects[k].geometry for k in self.shapes]
        spheres = [bounding_sphere(g) for g in self._geometries]
        self._centres = np.array([c for c, _ in spheres]).reshape(-1, 3)  # in each shape's frame
        self._radii = np.array([r for _, r in spheres])
        self._joint = np.array([objects[k].parentJoint for k in self.shapes], dtype=np.intp)
        placement = [objects[k].placement for k in self.shapes]
        rotation = np.array([pl.rotation for pl in placement]).reshape(-1, 3, 3)
        translation = np.array([pl.translation for pl in placement]).reshape(-1, 3)
        centres_joint = (rotation @ self._centres[:, :, None])[:, :, 0] + translation  # in the joint's frame
        self._centres_joint = np.hstack((centres_joint, np.ones((len(self.shapes), 1))))  # homogeneous, (shapes, 4)
        support = np.zeros((len(self.shapes), model.nv))
        reach = np.zeros((len(self.shapes), model.nv))
        for i, k in enumerate(self.shapes):
            chain = model.supports[objects[k].parentJoint].tolist()[1:]
            extent = farthest(objects[k])
            for position, j in enumerate(chain):
                columns = slice(model.idx_vs[j], model.idx_vs[j] + model.joints[j].nv)
                support[i, columns] = 1.0
                offsets = sum(float(np.linalg.norm(model.jointPlacements[o].translation)) for o in chain[position + 1:])
                prismatic = "P" in model.joints[j].shortname().replace("JointModel", "")
                reach[i, columns] = 1.0 if prismatic else extent + offsets
        self._support = support
        self._reach = reach
        self.request = distance_request(gjk_tolerance)
        self._calls = 0  # near() calls that computed kinematics (a deferred pair's call)
        self._known: FloatArray = np.zeros((0, len(self.shapes)))  # (obstacles, shapes) lower bounds [m] ...
        self._known_q: FloatArray | None = None  # ... at these joint positions ...
        self._below = np.zeros(0, dtype=bool)
        self._known_flat = self._known.reshape(-1)
        self._known_for: object = None  # ... for this snapshot (identity), whose per-obstacle values are:
        self._obstacle_centres = np.zeros((0, 3))  # bounding sphere centres in the world [m], (m, 3)
        self._obstacle_radii = np.zeros(0)
        self._table: list[tuple[Any, ...]] = []  # per (obstacle, shape), obstacle-major (_snapshot) ...
        self._moving: list[bool] = []  # ... whether the obstacle moves
        self._any_moving = False
        self._calls_table: list[tuple[Any, ...]] = []  # each entry's coal arguments, result and key
        # the last cycles' pair sets (table indices) -> their links, speed bounds (read-only) and labels
        self._chosen: dict[tuple[int, ...], tuple[tuple[tuple[str, str], ...], FloatArray, tuple[str, ...],
                                                  FloatArray]] = {}
        self._blocks: dict[str, _Block] = {}  # the last snapshot's obstacles' table entries, by name

    def _snapshot(self, obstacles: Sequence[LiveObstacle], carry: bool) -> None:
        """The per-snapshot values (class docstring): the known bounds (``carry``: those of the obstacles that
        only moved, less how far, else all forgotten), and the (obstacle, shape) table, entry j * shapes + i:
        coal's four arguments (the octree first), its result, the (obstacle, link) key, i, j, whether the
        obstacle is an octree, the pair's (link, ``obstacle:<name>``) and its label."""
        count, shapes = len(obstacles), len(self.shapes)
        shifts = np.full(count, np.inf)  # how far each obstacle moved, inf: its bounds forgotten
        blocks: list[_Block] = []
        rebuilt = count != len(self._blocks)
        for j, o in enumerate(obstacles):
            block = self._blocks.get(o.name)
            if (block is None or block.shape is not o.shape or block.index != j or block.sphere[0] is not o.centre
                    or block.sphere[1] != o.radius):
                blocks.append(self._block(o, j))
                rebuilt = True
                continue
            turned = o.rotation.tobytes() != block.rotation
            shift = math.dist(o.position.tolist(), block.position.tolist())
            if turned:
                block.transform.setRotation(o.rotation)
                block.rotation = o.rotation.tobytes()
            if shift:
                block.transform.setTranslation(o.position)
                block.position = o.position.copy()
            if turned or shift:
                block.centre = o.rotation @ o.centre + o.position
            if carry and not turned:
                shifts[j] = shift
            blocks.append(block)
        self._blocks = {o.name: block for o, block in zip(obstacles, blocks)}
        known = np.full((count, shapes), -np.inf)
        kept = min(count, self._known.shape[0])  # a reused block keeps its place j: its bounds are row j
        known[:kept] = self._known[:kept] - shifts[:kept, None]
        self._known = known
        self._known_flat = known.reshape(-1)  # a view: the updates are in place
        self._known_for = obstacles if isinstance(obstacles, tuple) else None
        self._obstacle_centres = np.array([block.centre for block in blocks])
        if rebuilt:
            self._table = [entry for block in blocks for entry in block.entries]
            self._calls_table = [entry[:6] for entry in self._table]
            self._below = np.zeros(count * shapes, dtype=bool)  # the known bounds' test, preallocated
            self._obstacle_radii = np.array([o.radius for o in obstacles])  # a reused block keeps its radius
            self._chosen = {}
        self._moving = [bool(o.velocity.any()) for o in obstacles]
        self._any_moving = any(self._moving)

    def _block(self, o: LiveObstacle, j: int) -> _Block:
        """Obstacle ``o``'s table entries at place j of the snapshot (:meth:`_snapshot`)."""
        shapes, placed = len(self.shapes), self.geometry_data.oMg  # references: they follow updateGeometryPlacements
        tf, octree, label = coal.Transform3s(o.rotation, o.position), isinstance(o.shape, coal.OcTree), o.label
        entries = []
        for i, k in enumerate(self.shapes):
            # coal answers an octree pair with the octree's point first, n from it: asked octree first, swapped back
            call = ((o.shape, tf, self._geometries[i], placed[k]) if octree
                    else (self._geometries[i], placed[k], o.shape, tf))
            entries.append((*call, coal.DistanceResult(), j * shapes + self._first[i], i, j, octree,
                            (self.names[i], label), f"{self.names[i]} – {label}"))
        return _Block(o.shape, (o.centre, o.radius), j, o.rotation.tobytes(), o.position.copy(), tf,
                      o.rotation @ o.centre + o.position, entries)

    def near(self, q: FloatArray, obstacles: Sequence[LiveObstacle], within: float, deferred: bool = False) -> LivePairs:
        """The (link, obstacle) pairs closer than ``within`` [m] at q [rad] (n,), each link's closest
        shape, obstacle by obstacle in the order given, links in the geometry's order. ``deferred``: the
        witness points, normals and rows are left for :meth:`complete` (until the next call)."""
        n = self.model.nv
        if not obstacles or not self.shapes:
            return LivePairs.empty(n)
        known_q, finite = self._known_q, math.isfinite(sum(q.tolist()))
        carry = finite and known_q is not None  # a non-finite q forgets them all, and is not kept
        if obstacles is not self._known_for:
            self._snapshot(obstacles, carry)
        elif not carry:
            self._known.fill(-np.inf)
        if carry and known_q is not None:
            moved = q - known_q
            self._known -= self._reach @ np.abs(moved, out=moved)
        self._known_q = q.copy() if finite else None
        known = self._known_flat  # a view, (obstacle, shape) obstacle-major
        np.less(known, within, out=self._below)
        candidates = self._below.nonzero()[0]  # (flatnonzero would ravel and check again: 1 us more)
        if not candidates.size:
            return LivePairs.empty(n)
        self._calls += 1  # data and the results change from here: earlier deferred pairs are gone
        pin.computeJointJacobians(self.model, self.data, q)  # data.oMi and data.J
        if candidates.size > SPHERE_BROADPHASE_MIN:  # coal on fewer costs less than the spheres
            centres = self._frames.points(self._joint, self._centres_joint)  # the shapes' sphere centres, world
            obstacle, shape = np.divmod(candidates, len(self.shapes))
            offset = centres[shape] - self._obstacle_centres[obstacle]
            gaps = (np.sqrt(np.einsum("ck,ck->c", offset, offset))
                    - self._radii[shape] - self._obstacle_radii[obstacle])  # sphere bounds, (candidates,)
            known[candidates] = np.maximum(known[candidates], gaps)
            candidates = candidates[gaps < within]
            if not candidates.size:
                return LivePairs.empty(n)
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data)
        calls, request = self._calls_table, self.request
        found: list[tuple[int, float, int]] = []  # (obstacle, link) key, d, table index of the pairs within
        for c in candidates.tolist():
            a, tf_a, b, tf_b, result, key = calls[c]
            result.clear()
            d = coal.distance(a, tf_a, b, tf_b, request, result)
            if -_FAILED < d < _FAILED:  # not NaN either; where GJK failed, the pair is left out this cycle
                known[c] = d - KNOWN_MARGIN
                if d < within:
                    found.append((key, d, c))
        if not found:
            return LivePairs.empty(n)
        if not self._one_shape_each:  # each key's closest shape, in the keys' order
            best: dict[int, tuple[int, float, int]] = {}
            for entry in found:
                if entry[0] not in best or entry[1] < best[entry[0]][1]:
                    best[entry[0]] = entry
            found = list(best.values()) if self._keys_ascending else [best[key] for key in sorted(best)]
        table = self._table
        pairs = tuple([c for _, _, c in found])
        known_pairs = self._chosen.get(pairs)
        if known_pairs is None:  # a new set of pairs (the same set is common from one cycle to the next)
            entries = [table[c] for c in pairs]
            speed = self._reach.take([entry[6] for entry in entries], axis=0)
            speed.flags.writeable = False  # shared by the cycles with the same pairs
            still = np.zeros(len(pairs))
            still.flags.writeable = False  # n^T v_B of still obstacles, shared as the speed bounds
            known_pairs = (tuple([entry[9] for entry in entries]), speed, tuple([entry[10] for entry in entries]),
                           still)
            if len(self._chosen) >= _CHOSEN_KEPT:
                self._chosen.clear()
            self._chosen[pairs] = known_pairs
        links, speed, labels, approach = known_pairs
        moving = False
        if self._any_moving:
            rows = [r for r, c in enumerate(pairs) if self._moving[table[c][7]]]
            if rows:  # n^T v_B
                approach = np.zeros(len(pairs))
                _, normals = self._witness([pairs[r] for r in rows])
                velocities = np.array([obstacles[table[pairs[r]][7]].velocity for r in rows])
                approach[rows] = np.einsum("mk,mk->m", normals, velocities)
                moving = True
        near = LivePairs(links, np.array([d for _, d, _ in found]), approach, moving, speed, pairs=pairs,
                         call=self._calls, labels=labels)
        return near if deferred else self.complete(near)

    def _witness(self, entries: Sequence[int]) -> tuple[FloatArray, FloatArray]:
        """Table entries' p_a (on the link), p_b (on the obstacle) [m], (2, m, 3), and unit n from A to B,
        (m, 3), from their coal results (an octree's swapped back: it was asked first)."""
        table = self._table
        raw = np.array([(r.getNearestPoint1(), r.getNearestPoint2(), r.normal)
                        for r in [table[c][4] for c in entries]]).reshape(-1, 3, 3)  # (m, [p1, p2, n], 3)
        swapped = [table[c][8] for c in entries]
        if any(swapped):
            flip = np.array(swapped)
            raw[flip] = raw[flip][:, [1, 0, 2]]
            raw[flip, 2] *= -1.0
        points = raw[:, :2].transpose(1, 0, 2).copy()
        normals = raw[:, 2]
        length = np.sqrt(np.einsum("mk,mk->m", normals, normals))
        normals = np.where(length[:, None] > 0.0, normals / np.where(length > 0.0, length, 1.0)[:, None],
                           np.array([0.0, 0.0, 1.0]))
        return points, normals

    def complete(self, pairs: LivePairs) -> LivePairs:
        """``pairs`` with the witness points, normals and rows (module docstring) it deferred: from the
        coal results and Jacobians of its call, which must be the last (ValueError otherwise)."""
        if pairs.rows is not None:
            return pairs
        if pairs.call != self._calls:
            raise ValueError(f"live pairs of call {pairs.call} completed after call {self._calls}: their coal "
                             "results are gone (complete them before the next near())")
        points, normals = self._witness(pairs.pairs)
        shapes = [self._table[c][6] for c in pairs.pairs]
        rows = -witness_rows(normals, points[0], self.data.J) * self._support[shapes]
        pairs.rows, pairs.points, pairs.normals = rows, points, normals
        return pairs


def live_damper_bound(distance: FloatArray, approach: FloatArray | None, influence: float, safety: float,
                      gain: float) -> FloatArray:
    """b = xi (d - d_s) / (d_i - d_s) + n^T v_B [m/s], (m,) (module docstring): the velocity damper's
    bound for m pairs at d [m] whose obstacle approaches at n^T v_B [m/s] (``approach``, (m,); None: all
    still, n^T v_B = 0)."""
    result: FloatArray = (distance - safety) * (gain / (influence - safety))
    if approach is not None:
        result += approach
    return result
